"""Is a clip locomoting? The method's stated limit, detected before splicing.

Time alignment matches the lower bodies of two *locomoting* characters; a clip performed
standing still has no gait cycle to align (Heck et al. 2006, Section 5). A clip counts as
locomoting when both feet take at least one step (a swing between two ground contacts) and
the root travels at least one leg length along its floor path.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..specs import SkeletonRoles
from ..kinematics.contacts import gait_summary
from .clips import ClipTensors

__all__ = ["LocomotionCheck", "check_locomotion"]

MIN_TRAVEL_LEGS = 1.0


@dataclass(frozen=True)
class LocomotionCheck:
    """Verdict for one clip: ``locomoting``, and ``reason`` (empty when locomoting).

    ``swings`` are the (left, right) steps counted, ``travel`` the root's floor path in leg
    lengths, ``duration`` in seconds. ``finite`` is false for a damaged clip (NaN or infinite
    joint positions), which cannot be spliced at all (``reason`` then says so).
    """

    locomoting: bool
    reason: str
    swings: tuple[int, int]
    travel: float
    duration: float
    finite: bool = True


def check_locomotion(clips: ClipTensors, roles: SkeletonRoles, fps: float) -> list[LocomotionCheck]:
    """One :class:`LocomotionCheck` per clip of the batch (computed batched)."""
    pos, lengths = clips.positions, clips.lengths
    valid = torch.arange(pos.shape[1], device=pos.device)[None, :] < lengths.to(pos.device)[:, None]  # (B, T)
    bad = (~torch.isfinite(pos).all(dim=(-1, -2))) & valid
    first_bad = torch.where(bad.any(1), bad.float().argmax(1), torch.full_like(lengths, -1, device=pos.device))
    g = gait_summary(clips.positions, clips.lengths, fps, roles.feet, roles.hips, roles.root, roles.up_axis)
    out = []
    for swings, travel, duration, f in zip(g.swings.tolist(), g.travel.tolist(), g.duration.tolist(), first_bad.tolist()):
        if f >= 0:
            out.append(LocomotionCheck(False, f"has non-finite values (NaN or infinity) from frame {f}; the clip is "
                                       "damaged: import it again", tuple(swings), float("nan"), duration, finite=False))
            continue
        reasons = []
        if min(swings) < 1:
            reasons.append(f"no alternating steps (left {swings[0]}, right {swings[1]} in {duration:.1f} s)")
        if travel < MIN_TRAVEL_LEGS:
            reasons.append(f"little travel ({travel:.2f} leg lengths)")
        out.append(LocomotionCheck(not reasons, "; ".join(reasons), tuple(swings), travel, duration))
    return out
