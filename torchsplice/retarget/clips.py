"""``retarget_clips``: clips of a database played on another skeleton, written as a new database.

Each source skeleton's map to the target is built once (:func:`~torchsplice.ops.retarget.retarget_map`:
a skeleton that is not a humanoid is refused in one line naming what it lacks, before anything
is written); the clips are read and retargeted in chunks (:func:`~torchsplice.ops.retarget.retarget_motions`)
and appended on the target skeleton, with its spec, units and up axis. Each result keeps its
name, role, frame rate and labels, and gains two labels: ``retargeted_from`` (``DB:K (spec)``)
and ``retargeted_to`` (the target's name). The output appears when complete (an error or an
interrupt leaves no file), and its run record says what was done.
"""

from __future__ import annotations

import datetime
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import torch

from ..core.errors import SpecError, TorchspliceError
from ..core.version import __version__
from ..formats.exporters import selected_names
from ..formats.importer import DATABASE_SUFFIXES
from ..ops.retarget import RetargetMap, retarget_map, retarget_motions
from ..store.atomic import check_output
from ..store.database import MotionDatabase
from .defaults import DEFAULT_FIX_FEET
from .targets import database_target, resolve_target

__all__ = ["retarget_clips", "RetargetReport", "Retargeter", "needs_retargeting", "onto_skeleton", "CHUNK_CLIPS"]

CHUNK_CLIPS = 64
"""Clips read, retargeted and written together."""


@dataclass
class RetargetReport:
    """What :func:`retarget_clips` did: the output, the target's name, the clips and frames
    written, and per source skeleton (``DB:K (spec)``) its map's held and folded joints (names)."""

    output: Path
    target: str
    clips: int = 0
    frames: int = 0
    maps: dict[str, dict[str, list[str]]] = field(default_factory=dict)

    def summary(self) -> str:
        return (f"{self.output}: {self.clips} clip{'s' if self.clips != 1 else ''} ({self.frames} frames) retargeted onto "
                f"{self.target}")


def source_label(database, k: int, spec_name: str) -> str:
    """How results name where they came from: ``DB:K (spec)``."""
    return f"{Path(database).name}:{k} ({spec_name or 'no spec'})"


def map_notes(rmap: RetargetMap) -> dict[str, list[str]]:
    """A map's held target joints and folded source joints, by name."""
    return {"held": [rmap.target.names[j] for j in rmap.held], "folded": [rmap.source.names[j] for j in rmap.folded]}


def needs_retargeting(skeleton, units: str, onto, onto_units: str, up: str = "", onto_up: str = "") -> bool:
    """Whether clips on ``skeleton`` (stored in ``units``, up axis ``up``) must be retargeted to
    splice with clips on ``onto``: other joints, or other units or up axes where both are
    recorded. The one rule of ``splice-all``, ``splice``, ``plot-alignment`` and ``evaluate``."""
    return (not skeleton.same_topology(onto) or bool(units and onto_units and units != onto_units)
            or bool(up and onto_up and up != onto_up))


def onto_skeleton(db, path, clips, skeleton: int, fix_feet: bool = True) -> list | None:
    """``clips`` (of one skeleton of the open database ``db`` at ``path``) retargeted onto its
    skeleton ``skeleton`` when :func:`needs_retargeting` says so, as ``splice-all`` does; ``None``
    when they are on it already."""
    k = db.clip_info(clips[0].name)["skeleton"]
    mine, onto = db.skeleton_info(k), db.skeleton_info(skeleton)
    if not needs_retargeting(db.skeletons[k], mine.units or "", db.skeletons[skeleton], onto.units or "",
                             mine.up_axis or "", onto.up_axis or ""):
        return None
    spec = db.spec(k)
    return Retargeter(db.skeletons[k], spec, source_label(path, k, spec.name), database_target(db, path, skeleton),
                      fix_feet, what=f"{path}: skeleton {k} ({spec.name})")(clips)


class Retargeter:
    """Clips of one source skeleton played on one target: the map, the target's foot heights
    and the results' labels made once; calling it retargets a list of clips (batched), each
    result in its clip's dtype with ``retargeted_from`` and ``retargeted_to`` labels.

    Args:
        skeleton, spec: the source skeleton and its dataset spec.
        source: what the labels call the source (:func:`source_label`: ``DB:K (spec)``).
        target: a :class:`~torchsplice.retarget.RetargetTarget` (or what
            :func:`~torchsplice.retarget.resolve_target` takes).
        fix_feet: hold the feet where the source's stand.
        what: what errors call the source skeleton (default ``source``).
    """

    def __init__(self, skeleton, spec, source: str, target, fix_feet: bool = True, what: str | None = None):
        self.target = resolve_target(target)
        roles = []
        for sk, sp, name in ((skeleton, spec, what or source), (self.target.skeleton, self.target.spec, self.target.name)):
            try:
                roles.append(sp.bind(sk))
            except SpecError as exc:  # a spec naming joints the skeleton lacks: say whose
                raise SpecError(f"{name}: {exc}") from None
        self.map = retarget_map(skeleton, roles[0], self.target.skeleton, roles[1], source_name=what or source,
                                target_name=self.target.name)
        self.labels = {"retargeted_from": source, "retargeted_to": self.target.name}
        self.fix_feet = fix_feet

    def __call__(self, motions) -> list:
        motions = list(motions)
        done = retarget_motions([m.to(torch.float64) for m in motions], self.map, self.fix_feet, self.target.heights)
        out = []
        for m, r in zip(motions, done):
            r = r.to(m.rotations.dtype)
            r.labels.update(self.labels)
            out.append(r)
        return out


def retarget_clips(database, clips: Sequence[str] | None = None, *, to, out, select=None, fix_feet: bool = DEFAULT_FIX_FEET,
                   overwrite: bool = False, command: str = "", progress: Callable | None = None) -> RetargetReport:
    """Retarget clips of ``database`` onto ``to`` and write them to the database ``out``.

    Args:
        database: the motion database to read.
        clips: clip names (repeats dropped); ``None`` for every clip (or every one ``select`` selects).
        to: the target: ``"smpl22"``, ``"other.h5"``, ``"other.h5:K"``, ``"rig.bvh"`` or a
            :class:`~torchsplice.retarget.RetargetTarget` (:func:`~torchsplice.retarget.resolve_target`).
        out: the database to write (``.h5``).
        select: selectors of the selection language (:mod:`torchsplice.store.select`).
        fix_feet: hold the feet where the source's stand (:mod:`torchsplice.ops.feet`).
        overwrite: replace an existing ``out``.
        command: what the run record says made it.
        progress: ``progress(iterable, total, description)`` wrapping the chunks (of
            :data:`CHUNK_CLIPS` clips), or ``None``.
    """
    target = resolve_target(to)
    inputs = [database] + ([target.path] if target.path is not None else [])
    out = check_output(out, DATABASE_SUFFIXES, "a database", inputs=inputs, overwrite=overwrite)
    if select is not None:
        clips = selected_names(database, select, clips)
    with MotionDatabase.open(database) as db:
        table = db.clip_table()
        if clips is None:
            rows = list(range(len(table.names)))
        else:
            rows = list(dict.fromkeys(db.index(c) for c in clips))  # an unknown name: one line naming it
        if not rows:
            raise TorchspliceError(f"{database}: no clip to retarget")
        by_skeleton: dict[int, list[int]] = {}
        for r in rows:
            by_skeleton.setdefault(int(table.skeleton[r]), []).append(r)
        movers: dict[int, Retargeter] = {}
        report = RetargetReport(Path(out), target.name)
        for k in sorted(by_skeleton):
            try:
                spec = db.spec(k)
            except SpecError as exc:
                raise SpecError(f"{database}: skeleton {k}: {exc}") from None
            label = source_label(database, k, spec.name)
            movers[k] = Retargeter(db.skeletons[k], spec, label, target, fix_feet,
                                   what=f"{database}: skeleton {k} ({spec.name})")
            report.maps[label] = map_notes(movers[k].map)
        record = {"command": command or "retarget_clips", "tool": f"torchsplice {__version__}",
                  "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                  "retargeted_to": target.name, "source": str(database)}
        chunks = [(k, rs[i:i + CHUNK_CLIPS]) for k, rs in sorted(by_skeleton.items()) for i in range(0, len(rs), CHUNK_CLIPS)]
        with MotionDatabase.create(out, overwrite=overwrite, attrs={"run": json.dumps(record)}) as new:
            for k, chunk in (progress(chunks, len(chunks), "retargeting") if progress else chunks):
                for m in movers[k](db.read_many([table.names[r] for r in chunk], dtype=torch.float64)):
                    new.append(m, spec=target.spec)
                    report.clips += 1
                    report.frames += m.num_frames
    return report
