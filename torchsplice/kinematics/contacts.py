"""Foot contacts, steps and travel from joint positions, batched over clips.

Thresholds are relative to the character's leg length (hip to ankle), so they work in any
unit. Shapes: positions ``(B, T, J, 3)``, lengths ``(B,)`` valid frames per clip, fps ``(B,)``
or a float. The up axis is an index (Y = 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = ["foot_contacts", "count_runs", "GaitSummary", "gait_summary"]


def floor_speed(p: torch.Tensor, fps: torch.Tensor, up_axis: int, lengths: torch.Tensor) -> torch.Tensor:
    """Horizontal speed ``(B, T, ...)`` of points ``(B, T, ..., 3)``: central differences, one-sided
    at each clip's first and last real frame (so padding never changes a clip's values)."""
    v = torch.zeros_like(p)
    v[:, 1:-1] = (p[:, 2:] - p[:, :-2]) / 2
    v[:, :1] = p[:, 1:2] - p[:, :1]
    back = torch.zeros_like(p)
    back[:, 1:] = p[:, 1:] - p[:, :-1]
    last = torch.arange(p.shape[1], device=p.device)[None, :] == (lengths - 1)[:, None]
    v = torch.where(last.reshape(last.shape + (1,) * (p.dim() - 2)), back, v)
    v[..., up_axis] = 0
    return v.norm(dim=-1) * fps.reshape((-1,) + (1,) * (p.dim() - 2))


def foot_contacts(
    feet: torch.Tensor,
    lengths: torch.Tensor,
    fps,
    leg_length: torch.Tensor,
    up_axis: int = 1,
    height_ratio: float = 0.12,
    speed_ratio: float = 0.6,
) -> torch.Tensor:
    """Which feet touch the ground, ``(B, T, F)`` bool (False on padding).

    A foot (an ankle joint, ``feet`` ``(B, T, F, 3)``) is in contact when it is within
    ``height_ratio`` leg lengths of its lowest height in the clip and moves horizontally slower
    than ``speed_ratio`` leg lengths per second.
    """
    B, T = feet.shape[:2]
    fps = torch.as_tensor(fps, dtype=feet.dtype, device=feet.device).expand(B)
    valid = torch.arange(T, device=feet.device)[None, :] < lengths[:, None]
    h = feet[..., up_axis]
    low = torch.where(valid[..., None], h, torch.full_like(h, float("inf"))).min(dim=1, keepdim=True).values
    leg = leg_length.reshape(B, 1, 1).to(feet.dtype)
    near_floor = (h - low) < height_ratio * leg
    slow = floor_speed(feet, fps, up_axis, lengths) < speed_ratio * leg
    return near_floor & slow & valid[..., None]


def count_runs(mask: torch.Tensor, min_length: int = 1, interior: bool = False) -> torch.Tensor:
    """Number of runs of True along dim 1 of ``mask`` ``(B, T, ...)`` lasting ``min_length``+ frames.

    With ``interior``, runs touching the first or last frame are not counted. Returns ``(B, ...)``.
    """
    m = mask.to(torch.int64)
    pad = torch.zeros_like(m[:, :1])
    edges = torch.diff(torch.cat((pad, m, pad), dim=1), dim=1)  # +1 at starts, -1 one past ends
    T = mask.shape[1]
    pos = torch.arange(T + 1, device=mask.device).reshape((1, T + 1) + (1,) * (mask.dim() - 2))
    starts = torch.where(edges == 1, pos, torch.zeros_like(pos))
    ends = torch.where(edges == -1, pos, torch.zeros_like(pos))
    # pair the k-th start with the k-th end: sort positions of each kind (zeros sort first)
    s = torch.sort(starts + (edges != 1) * (2 * T + 2), dim=1).values
    e = torch.sort(ends + (edges != -1) * (2 * T + 2), dim=1).values
    real = s <= T
    long_enough = (e - s) >= min_length
    if interior:
        long_enough &= (s > 0) & (e < T)
    return (real & long_enough).sum(dim=1)


@dataclass
class GaitSummary:
    """Per clip ``(B,)``: swing phases per foot ``(B, 2)``, travel of the root along its floor
    path in leg lengths, and the clip's duration in seconds."""

    swings: torch.Tensor
    travel: torch.Tensor
    duration: torch.Tensor


def gait_summary(positions, lengths, fps, feet, hips, root, up_axis: int = 1) -> GaitSummary:
    """Swings, travel and duration of clips from joint ``positions`` ``(B, T, J, 3)``.

    ``feet`` and ``hips`` are ``(left, right)`` joint indices, ``root`` the trajectory joint. A
    swing is an interior run of at least 0.1 s without ground contact between two contacts.
    """
    B, T = positions.shape[:2]
    fps = torch.as_tensor(fps, dtype=positions.dtype, device=positions.device).expand(B)
    valid = torch.arange(T, device=positions.device)[None, :] < lengths[:, None]
    leg = (positions[:, 0, list(hips)] - positions[:, 0, list(feet)]).norm(dim=-1).mean(-1)
    contact = foot_contacts(positions[:, :, list(feet)], lengths, fps, leg, up_axis)
    swing = ~contact & valid[..., None]
    min_len = max(1, int(round(0.1 * float(fps.min()))))
    # a swing counts only between two contacts: it must not touch the clip's ends
    padded = torch.where(valid[..., None], swing, torch.ones_like(swing))
    swings = count_runs(padded, min_len, interior=True)
    step = positions[:, 1:, root] - positions[:, :-1, root]
    step[..., up_axis] = 0
    travel = (step.norm(dim=-1) * valid[:, 1:]).sum(1) / leg
    return GaitSummary(swings=swings, travel=travel, duration=lengths.to(positions.dtype) / fps)
