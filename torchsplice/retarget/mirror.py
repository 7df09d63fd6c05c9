"""``mirror_clips``: clips of a database and their mirror images, written as a new database
(the ``torchsplice mirror`` command as one function): data augmentation on any skeleton with a
left/right map, like HumanML3D's ``M`` copies.

Each clip is mirrored on its own skeleton (:func:`~torchsplice.ops.mirror.mirror_motion`: the
world reflection that swaps the character's left and right, exact in positions for any rest
pose whose two sides are congruent), named ``NAME.mirror``, with its labels' left and right
swapped (``wave-right-hand`` -> ``wave-left-hand``; labels that name clips or files kept) and a
``mirror_of`` label naming the original's take, so that splits keep a copy with its original
and with the other windows of its take (:mod:`torchsplice.data.splits`). The clip table's
extra columns (a spliced clip's cost, flags, coverage, locomotion, action ...) are carried
over to both. With
``originals`` (the default) the output holds every original followed by its mirror, else the
mirrors only. Every export, the dataset and ``splice-all`` then read it as any database. The
output appears when complete (an error or an interrupt leaves no file); a skeleton that has
no left/right map is refused in one line naming the joint, before anything is written.

    from torchsplice.retarget.mirror import mirror_clips
    report = mirror_clips("spliced.h5", out="spliced_mirrored.h5")
"""

from __future__ import annotations

import datetime
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import torch

from ..core.errors import TorchspliceError
from ..core.version import __version__
from ..formats.exporters import selected_names
from ..formats.importer import DATABASE_SUFFIXES
from ..ops.mirror import mirror_motion, mirror_rig
from ..store.atomic import check_output
from ..store.database import MotionDatabase
from .defaults import DEFAULT_ORIGINALS

__all__ = ["mirror_clips", "MirrorReport", "MIRROR_SUFFIX"]

MIRROR_SUFFIX = ".mirror"
"""A mirrored copy's name: the original's and this."""

CHUNK_CLIPS = 64
"""Clips read, mirrored and written together."""


@dataclass
class MirrorReport:
    """What :func:`mirror_clips` wrote: the output, the clips mirrored, the clips and frames written."""

    output: Path
    mirrored: int = 0
    clips: int = 0
    frames: int = 0

    def summary(self) -> str:
        return (f"{self.output}: {self.clips} clip{'s' if self.clips != 1 else ''} ({self.frames} frames), "
                f"{self.mirrored} of them mirror images")


def mirror_clips(database, clips: Sequence[str] | None = None, *, out, select=None, originals: bool = DEFAULT_ORIGINALS,
                 overwrite: bool = False, command: str = "", progress: Callable | None = None) -> MirrorReport:
    """Write clips of ``database`` and their mirror images to the database ``out``.

    Args:
        database: the motion database to read.
        clips: clip names (repeats dropped); ``None`` for every clip (or every one ``select`` selects).
        out: the database to write (``.h5``).
        select: selectors of the selection language (:mod:`torchsplice.store.select`).
        originals: write each original before its mirror image (else the mirror images only).
        overwrite: replace an existing ``out``.
        command: what the run record says made it.
        progress: ``progress(iterable, total, description)`` wrapping the chunks, or ``None``.
    """
    out = check_output(out, DATABASE_SUFFIXES, "a database", inputs=[database], overwrite=overwrite)
    if select is not None:
        clips = selected_names(database, select, clips)
    with MotionDatabase.open(database) as db:
        table = db.clip_table()
        rows = list(range(len(table.names))) if clips is None else list(dict.fromkeys(db.index(c) for c in clips))
        if not rows:
            raise TorchspliceError(f"{database}: no clip to mirror")
        taken = set(table.names) if originals else set()  # the mirrors alone: their names are new to the output
        for r in rows:
            if table.names[r] + MIRROR_SUFFIX in taken:
                raise TorchspliceError(f"{database}: clip {table.names[r] + MIRROR_SUFFIX!r} exists already; mirror "
                                       "the database's clips that are not mirrors (select them)")
        specs, rigs = {}, {}
        for k in sorted({int(table.skeleton[r]) for r in rows}):  # once per skeleton, refused before any work
            specs[k] = db.spec(k)
            rigs[k] = mirror_rig(db.skeletons[k], specs[k].up_axis, where=f"{database}: skeleton {k} ({specs[k].name})")
        columns = dict(db.columns)
        record = {"command": command or "mirror_clips", "tool": f"torchsplice {__version__}",
                  "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                  "source": str(database), "mirror": "originals and mirrors" if originals else "mirrors"}
        chunks = [rows[i:i + CHUNK_CLIPS] for i in range(0, len(rows), CHUNK_CLIPS)]
        report = MirrorReport(Path(out))
        with MotionDatabase.create(out, overwrite=overwrite, columns=columns, attrs={"run": json.dumps(record)}) as new:
            for chunk in (progress(chunks, len(chunks), "mirroring") if progress else chunks):
                motions = db.read_many([table.names[r] for r in chunk], dtype=torch.float64)
                for r, m in zip(chunk, motions):
                    k = int(table.skeleton[r])
                    extra = {c: table.extra[c][r] for c in columns}
                    if originals:
                        new.append(m, spec=specs[k], extra=extra)
                        report.clips += 1
                        report.frames += m.num_frames
                    new.append(mirror_motion(m, specs[k].up_axis, name=m.name + MIRROR_SUFFIX, rig=rigs[k],
                                             where=f"{database}: clip {m.name!r}"),
                               spec=specs[k], extra=extra)
                    report.clips += 1
                    report.mirrored += 1
                    report.frames += m.num_frames
    return report
