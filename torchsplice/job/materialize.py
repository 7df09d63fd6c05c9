"""``torchsplice materialize IN -o OUT``: the motion store of an alignment store.

Every clip's frames assembled (:mod:`torchsplice.store.assembly`) and written as an ordinary
motion database with the same skeletons, clip table, per-frame columns and run record, in
row order and in batches of about :data:`BATCH_FRAMES` frames, so memory stays bounded
whatever the number of clips. The frames are bit for bit those ``splice-all --store motion``
writes for the same job. The output is written beside its target and renamed into place.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import TorchspliceError
from ..core.progress import progress_bar
from ..formats.index import refresh_database_index
from ..store.atomic import same_file
from ..store.database import MotionDatabase
from .defaults import DEFAULT_INDEX, usable_cores

__all__ = ["materialize", "BATCH_FRAMES"]

BATCH_FRAMES = 1 << 16
"""Frames assembled and written at a time."""


def materialize(source, output, overwrite: bool = False, progress: bool = False, index: bool = DEFAULT_INDEX) -> int:
    """Write the motion store of the alignment store ``source`` to ``output`` (and, with
    ``index``, ``NAME.h5.index.csv`` beside it, as the job does); returns the number of clips."""
    source, output = Path(source), Path(output)
    if output.suffix.lower() not in (".h5", ".hdf5"):
        raise TorchspliceError(f"{output}: the output is a database, so its name must end in .h5 or .hdf5")
    if output.exists() and same_file(source, output):
        raise TorchspliceError(f"{output}: is the input; write the motions to another file")
    with MotionDatabase.open(source) as db:
        if db.store != "alignment":
            raise TorchspliceError(f"{source}: is a motion store already (its clips' frames are stored); "
                                   "materialize reads an alignment store (written with {store} alignment)", options=("store",))
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in db.attrs.items()}
        run = attrs.get("run", "")
        ct = db.clip_table()
        with MotionDatabase.create(output, overwrite=overwrite, columns=db.columns, frame_columns=db.frame_columns,
                                   chunk_frames=int(attrs.get("chunk_frames", 256)),
                                   compression=str(attrs.get("compression", "")) or None,
                                   attrs={"run": run} if run else None) as out:
            for k, sk in enumerate(db.skeletons):
                out.add_skeleton(sk, db.stored_spec(k))
            rows = np.arange(len(ct))
            threads = usable_cores()  # the kernels share each batch's clips (the same bits)
            bar = _bar(len(rows), progress)
            at = 0
            while at < len(rows):
                k = int(ct.skeleton[at])
                stop = at + 1  # rows of one skeleton, about BATCH_FRAMES frames
                frames = int(ct.length[at])
                while stop < len(rows) and int(ct.skeleton[stop]) == k and frames + int(ct.length[stop]) <= BATCH_FRAMES:
                    frames += int(ct.length[stop])
                    stop += 1
                r = rows[at:stop]
                f = db.assembled(k, ct.start[r], ct.length[r], threads=threads)
                out.append_packed(db.skeletons[k], f["rotations"], f["root_translation"], f.get("translations"),
                                  ct.length[r], ct.name[r], ct.fps[r], spec=db.stored_spec(k), sources=ct.source[r],
                                  roles=ct.role[r], labels=ct.labels_json[r],
                                  extra={c: ct.extra[c][r] for c in db.columns},
                                  frame_extra={c: f[c] for c in db.frame_columns}, check=False)
                bar.update(len(r))
                at = stop
            bar.close()
            if run and isinstance(db.run_record(), dict):
                out.update_run_record({"materialized_from": str(source)})
        n = len(ct)
    if index:
        refresh_database_index(output, write=True)
    return n


def _bar(total: int, progress: bool):
    return progress_bar(total=total, desc="materialize", unit="clip", show=bool(progress))
