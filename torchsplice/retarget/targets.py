"""What a clip is retargeted onto: :func:`resolve_target` turns ``--to``'s text into a
:class:`RetargetTarget` (a skeleton, its spec, and how high its feet stand on the floor).

Accepted: ``smpl22`` (the built-in SMPL body, :mod:`torchsplice.specs.smpl`); ``DB.h5`` (its
only skeleton) or ``DB.h5:K`` (skeleton ``K`` as ``torchsplice info`` lists it); ``RIG.bvh``
(the file's skeleton and spec, detected as on import). Anything else is one line saying what
is accepted. A target that is not a humanoid (no hips, knees, shoulders...) is refused when
the map is built (:func:`torchsplice.specs.canonical.canonical_joints`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..core.errors import SpecError, TorchspliceError
from ..core.skeleton import Skeleton
from ..formats.bvh import read_bvh
from ..formats.importer import DATABASE_SUFFIXES
from ..ops.feet import rig_heights
from ..specs import DatasetSpec, detect_spec, load_spec
from ..specs.canonical import canonical_joints, canonical_legs
from ..specs.smpl import SMPL22, smpl22_skeleton
from ..store.database import MotionDatabase

__all__ = ["RetargetTarget", "resolve_target", "database_target", "BUILTIN_TARGETS", "HEIGHT_CLIPS"]

BUILTIN_TARGETS = (SMPL22,)
"""The built-in targets, by name."""

HEIGHT_CLIPS = 16
"""How many of a database target's clips (its longest) say how high its feet stand."""


@dataclass(frozen=True)
class RetargetTarget:
    """A retargeting target.

    Attributes:
        name: what the results' labels call it (``smpl22``, ``bandai.h5:0``, ``rig.bvh``).
        skeleton: its skeleton; spec: its dataset spec (roles, units, up axis).
        heights: ``(2, 2)`` how high its (ankle, toe) stand above the floor when a foot rests,
            per leg (left, right), in its units, measured on its own clips; ``None`` where it
            has none (the source's heights are scaled instead).
        path: the file it was read from (a database or a BVH file), ``None`` for a built-in.
    """

    name: str
    skeleton: Skeleton
    spec: DatasetSpec
    heights: torch.Tensor | None = None
    path: Path | None = None


def _split_db(text: str) -> tuple[Path, int | None] | None:
    """``(path, K)`` of ``DB.h5:K`` / ``(path, None)`` of ``DB.h5``; ``None`` for other text."""
    head, sep, tail = text.rpartition(":")
    if sep and Path(head).suffix.lower() in DATABASE_SUFFIXES and tail.strip().lstrip("-").isdigit():
        return Path(head), int(tail)
    if Path(text).suffix.lower() in DATABASE_SUFFIXES:
        return Path(text), None
    return None


def _measured(motions, skeleton: Skeleton, spec: DatasetSpec) -> torch.Tensor | None:
    roles = spec.bind(skeleton)
    legs = canonical_legs(canonical_joints(roles, skeleton))
    return rig_heights([m for m in motions if m.num_frames >= 3], legs, int(roles.up_axis))


def resolve_target(to, what: str = "the target") -> RetargetTarget:
    """The :class:`RetargetTarget` named by ``to`` (see the module docstring); a
    :class:`RetargetTarget` is returned as it is. Errors are one line naming ``to``."""
    if isinstance(to, RetargetTarget):
        return to
    text = str(to)
    if text in BUILTIN_TARGETS:
        return RetargetTarget(SMPL22, smpl22_skeleton(), load_spec(SMPL22))
    db = _split_db(text)
    if db is not None:
        return _database_target(text, *db)
    path = Path(text)
    if path.suffix.lower() == ".bvh":
        return _bvh_target(path)
    raise TorchspliceError(f"{text}: not a retargeting target: give a database (.h5, or .h5:K for its skeleton K), a "
                           f"BVH file, or a built-in skeleton ({', '.join(BUILTIN_TARGETS)})")


def _database_target(text: str, path: Path, k: int | None) -> RetargetTarget:
    if not path.is_file():
        raise TorchspliceError(f"{path}: no such database (the retargeting target)")
    with MotionDatabase.open(path) as db:
        n = len(db.skeletons)
        if k is None and n != 1:
            raise TorchspliceError(f"{path}: holds {n} skeletons; name one as {path}:K, K from 0 to {n - 1} "
                                   "({info} lists them)", options=("info",))
        k = 0 if k is None else k
        if not 0 <= k < n:
            raise TorchspliceError(f"{text}: {path} has no skeleton {k} (it has {n}: 0 to {n - 1})")
        return database_target(db, path, k)


def database_target(db, path, k: int) -> RetargetTarget:
    """Skeleton ``k`` of the open database ``db`` (read from ``path``) as a target, its feet's
    resting heights measured on its :data:`HEIGHT_CLIPS` longest clips."""
    path = Path(path)
    try:
        spec = db.spec(k)
        table = db.clip_table()
        rows = np.flatnonzero(np.asarray(table.skeleton) == k)
        rows = rows[np.argsort(-np.asarray(table.length)[rows], kind="stable")][:HEIGHT_CLIPS].tolist()
        motions = db.read_many(rows, dtype=torch.float64) if rows else []
        heights = _measured(motions, db.skeletons[k], spec) if motions else None
    except SpecError as exc:  # its stored spec names joints it lacks, or it is not a humanoid
        raise SpecError(f"{path}: skeleton {k}: {exc}") from None
    return RetargetTarget(f"{path.name}:{k}", db.skeletons[k], spec, heights, path)


def _bvh_target(path: Path) -> RetargetTarget:
    if not path.is_file():
        raise TorchspliceError(f"{path}: no such BVH file (the retargeting target)")
    motion = read_bvh(path, dtype=torch.float64)  # a malformed file: one BVHError line naming it
    try:
        spec = detect_spec(motion.skeleton, path.name)
        heights = _measured([motion], motion.skeleton, spec) if motion.num_frames >= 3 else None
    except SpecError as exc:
        raise SpecError(f"{path}: {exc}") from None
    return RetargetTarget(path.name, motion.skeleton, spec, heights, path)
