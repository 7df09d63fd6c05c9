"""The features a :class:`~torchsplice.data.dataset.MotionDataset` derives from stored frames:
positions and global rotations by forward kinematics, 6D rotations, velocities, the
trajectory. Shapes ``(N, ...)`` over ``N`` packed frames; quaternions WXYZ; lengths in the
database's units; velocities per second."""

from __future__ import annotations

from typing import Sequence

import torch

from ..core.errors import TorchspliceError
from ..core.fk import forward_kinematics
from ..core.rotations import quat_to_6d
from ..core.skeleton import Skeleton
from ..store import MotionDatabase

__all__ = ["BUILTIN_FEATURES", "NEEDS_FK", "VELOCITY", "NOT_PER_FRAME", "velocities", "trajectory_joint", "derive_features"]

BUILTIN_FEATURES = ("rotations", "root_translation", "trajectory", "translations", "positions", "global_rotations",
                    "velocities", "rotations_6d", "trajectory_velocity", "root_velocity", "labels")
"""The features every database offers (its per-frame columns come on top)."""

NEEDS_FK = {"positions", "global_rotations", "velocities", "trajectory", "trajectory_velocity"}
VELOCITY = {"velocities", "trajectory_velocity", "root_velocity"}  # need the frame before a window
NOT_PER_FRAME = {"labels"}  # features that are clip metadata, not tensors


def velocities(pos: torch.Tensor, fps: torch.Tensor, clip_first: torch.Tensor, seg_first: torch.Tensor) -> torch.Tensor:
    """``(N, J, 3)`` finite-difference velocities of ``pos`` ``(N, J, 3)``: segments of frames, concatenated.

    ``fps`` ``(N,)`` per frame. ``seg_first`` ``(N,)`` bool marks the first row of each segment
    (an item, or a preloaded clip); ``clip_first`` marks rows that are a clip's first frame:
    those copy the next row of their segment (zero when the segment has no next row). Any
    other row uses the row before it; a segment's first row that is not a clip's first frame
    is a context frame whose own value is meaningless (the caller drops it).
    """
    vel = torch.zeros_like(pos)
    if pos.shape[0] > 1:
        vel[1:] = (pos[1:] - pos[:-1]) * fps[1:, None, None]
    f = clip_first.nonzero().flatten()
    if f.numel():
        nxt = f + 1
        ok = nxt < pos.shape[0]
        inside = ok.nonzero().flatten()
        ok[inside] = ~seg_first[nxt[inside]]  # a one-frame segment's next row belongs to another
        vel[f[ok]] = vel[nxt[ok]]
        vel[f[~ok]] = 0
    return vel


def trajectory_joint(db: MotionDatabase, k: int, skeleton: Skeleton) -> int:
    """Index of the joint carrying skeleton ``k``'s world trajectory: its spec's ``root`` role
    (Bandai Namco: ``Hips``, under a ``joint_Root`` that stands still), else joint 0."""
    try:
        return int(db.spec(k).bind(skeleton).root)
    except TorchspliceError:  # no spec fits: the BVH root
        return 0


def derive_features(raw: dict[str, torch.Tensor], features: Sequence[str], skeleton: Skeleton,
            fps: torch.Tensor, clip_first: torch.Tensor, seg_first: torch.Tensor,
            trajectory_joint: int = 0) -> dict[str, torch.Tensor]:
    """The asked ``features`` of ``N`` frames from the raw stored arrays ``raw`` (see the module table).

    ``raw`` holds ``rotations`` (N, J, 4), ``root_translation`` (N, 3) and, where stored,
    ``translations`` (N, J, 3) and per-frame columns (N,); ``fps``, ``clip_first`` and
    ``seg_first`` are as in :func:`velocities`. Every feature is computed frame by frame
    (velocities from the row before), so rows of several items can go through in one call.
    """
    out: dict[str, torch.Tensor] = {}
    fk = None
    if NEEDS_FK & set(features):
        offsets = skeleton.offsets.to(raw["rotations"])
        fk = forward_kinematics(raw["rotations"], raw["root_translation"], offsets, skeleton.parents,
                                raw.get("translations"))
    for f in features:
        if f in ("rotations", "root_translation"):
            out[f] = raw[f]
        elif f == "translations":
            if "translations" in raw:
                t = raw["translations"].clone()
            else:
                rot = raw["rotations"]
                t = skeleton.offsets.to(rot).expand(rot.shape[0], -1, -1).clone()
            t[:, 0] = raw["root_translation"]
            out[f] = t
        elif f == "positions":
            out[f] = fk[0]
        elif f == "global_rotations":
            out[f] = fk[1]
        elif f == "trajectory":
            out[f] = fk[0][:, trajectory_joint]
        elif f == "velocities":
            out[f] = velocities(fk[0], fps, clip_first, seg_first)
        elif f == "rotations_6d":
            out[f] = quat_to_6d(raw["rotations"])
        elif f == "trajectory_velocity":
            out[f] = velocities(fk[0][:, trajectory_joint:trajectory_joint + 1], fps, clip_first, seg_first)[:, 0]
        elif f == "root_velocity":
            out[f] = velocities(raw["root_translation"][:, None], fps, clip_first, seg_first)[:, 0]
        elif f in NOT_PER_FRAME:
            continue
        else:  # a per-frame column
            out[f] = raw[f]
    return out
