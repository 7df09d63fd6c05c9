"""Measures for standing actions spliced onto locomotion (see :mod:`torchsplice.splice.standing`).

- **action kept**: how much of the action's motion the result shows. The acting wrists' range
  of motion in the chest's frame (:func:`wrist_range`: the extent between their 5th and 95th
  percentile positions, per axis; the mean over the acting arms, both when none acts), over
  the same range in the whole captured action (``range_kept``), and over the action's best
  window of the result's length (``window_kept``: the largest range any run of that many
  consecutive action frames has; the whole action when the result is as long or longer).
  About 1 when the result plays the whole gesture; a result that plays only the action's still
  start scores near 0 on both.
- **wrist error**: the acting arms' wrists, in the chest's frame, against the action's at the
  same action frame (the ``action_frame`` column): mean distance (file units). Zero when the
  acting arms carry the frames they play exactly; loop fades and the ``cpmc`` additive layer
  add to it. It does not see which frames play: see *action kept*.
- **idle arms natural**: the arm-leg lag of the idle arms (an arm the action does not use
  should swing with the opposite leg, as in the captured walks), see
  :func:`~torchsplice.evaluation.metrics.arm_leg_phase_stats`.
- **seams**: the largest joint-velocity jump (``|v(t) - v(t-1)|`` of the acting wrists in the
  chest frame) at the frames around each loop point, over the 99th percentile of the same
  jumps in the captured action: at most about 1 for a seam as smooth as the capture.

Batched over clips; positions in file units; quaternions WXYZ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from ..core.motion import Motion
from ..core.rotations import quat_apply, quat_conj
from ..specs import SkeletonRoles
from ..splice.clips import clips_to_tensors, resample_motion
from ..splice.standing import LIMBS, arm_chains
from .metrics import arm_leg_phase_stats

__all__ = ["StandingMeasures", "standing_measures", "wrist_range", "best_window_range"]


@dataclass
class StandingMeasures:
    """Per clip ``(B,)`` float64: ``range_kept`` and ``window_kept`` (ratios), ``wrist_error``
    (units), ``idle_lag`` (gait cycles, NaN when both arms act), ``seam_ratio`` (NaN without a
    loop seam)."""

    range_kept: torch.Tensor
    window_kept: torch.Tensor
    wrist_error: torch.Tensor
    idle_lag: torch.Tensor
    seam_ratio: torch.Tensor


def wrist_range(x: torch.Tensor) -> torch.Tensor:
    """Range of motion of paths ``x`` ``(..., T, 3)``: the norm of the per-axis extent between
    the 5th and 95th percentile positions, ``(...)``."""
    q = torch.quantile(x.to(torch.float64), torch.tensor([0.05, 0.95], dtype=torch.float64, device=x.device), dim=-2)
    return (q[1] - q[0]).norm(dim=-1)


def best_window_range(x: torch.Tensor, n: int) -> torch.Tensor:
    """The largest :func:`wrist_range` of any ``n`` consecutive frames of ``x`` ``(T, S, 3)``
    (``S`` paths moving together, their ranges averaged), by brute force; the whole path's when
    ``n >= T``."""
    T = x.shape[0]
    if n >= T:
        return wrist_range(x.movedim(0, -2)).mean()
    windows = x.unfold(0, n, 1)  # (T - n + 1, S, 3, n)
    return wrist_range(windows.movedim(-1, -2)).mean(-1).max()


def _wrists_in_chest(C, roles: SkeletonRoles, chest: int) -> torch.Tensor:
    """``(B, T, 2, 3)`` both wrists in the chest's frame."""
    hands = list(roles.hands) if roles.hands is not None else list(roles.shoulders)
    return quat_apply(quat_conj(C.global_rotations[:, :, chest:chest + 1]), C.positions[:, :, hands] - C.positions[:, :, chest:chest + 1])


def _jumps(x: torch.Tensor) -> torch.Tensor:
    """``(B, T, ...)`` positions -> ``(B, T, ...)`` acceleration magnitude ``|x[t+1] - 2 x[t] + x[t-1]|`` (0 at the ends)."""
    a = (x[:, 2:] - 2 * x[:, 1:-1] + x[:, :-2]).norm(dim=-1)
    return torch.nn.functional.pad(a.movedim(1, -1), (1, 1)).movedim(-1, 1)


def standing_measures(results: list[Motion], actions: list[Motion], curves: list[torch.Tensor],
                      acting: list[tuple[str, ...]], roles: SkeletonRoles) -> StandingMeasures:
    """The measures of the module docstring for spliced ``results`` of standing ``actions``.

    ``curves[b]`` ``(T_b,)`` is result ``b``'s action frame per frame (the action's own rate),
    ``acting[b]`` the arms taken from the action.
    """
    sk = results[0].skeleton
    fps = results[0].fps
    R = clips_to_tensors(results, sk, dtype=torch.float64)
    A_full = clips_to_tensors([resample_motion(a, fps) for a in actions], sk, dtype=torch.float64)
    T = R.rotations.shape[1]
    times = torch.stack([torch.nn.functional.pad(c.to(torch.float64) * (fps / a.fps), (0, T - len(c)), value=float(c[-1]) * (fps / a.fps))
                         for c, a in zip(curves, actions)])
    A = A_full.at_times(times, R.lengths, sk)
    chest = arm_chains(roles, sk)[LIMBS[0]][0]
    wr, wa = _wrists_in_chest(R, roles, chest), _wrists_in_chest(A, roles, chest)  # (B, T, 2, 3)
    valid = (torch.arange(T)[None, :] < R.lengths[:, None]).to(torch.float64)
    act_mask = torch.tensor([[n in a for n in LIMBS] for a in acting], dtype=torch.float64)  # (B, 2)
    dist = (wr - wa).norm(dim=-1)  # (B, T, 2)
    n = (valid[:, :, None] * act_mask[:, None, :]).sum((1, 2))
    kept = (dist * valid[:, :, None] * act_mask[:, None, :]).sum((1, 2)) / n.clamp(min=1)
    kept = torch.where(n > 0, kept, torch.full_like(kept, math.nan))

    st = arm_leg_phase_stats(R, roles, fps)
    sides = torch.stack([st.left, st.right], 1).to(torch.float64)  # (B, 2)
    idle = 1 - act_mask
    idle_lag = torch.where(idle.sum(1) > 0, (torch.nan_to_num(sides) * idle).sum(1) / idle.sum(1).clamp(min=1),
                           torch.full((len(results),), math.nan, dtype=torch.float64))
    idle_lag = torch.where(torch.isfinite(sides).all(1) | (idle.sum(1) == 0), idle_lag, torch.full_like(idle_lag, math.nan))

    own = _wrists_in_chest(A_full, roles, chest)
    own_valid = torch.arange(own.shape[1])[None, :] < A_full.lengths[:, None]
    seam = torch.full((len(results),), math.nan, dtype=torch.float64)
    range_kept = torch.full((len(results),), math.nan, dtype=torch.float64)
    window_kept = torch.full((len(results),), math.nan, dtype=torch.float64)
    jr, ja = _jumps(wr), _jumps(own)  # (B, T, 2)
    for b in range(len(results)):  # per clip: its own lengths, windows and seams
        n, na = int(R.lengths[b]), int(A_full.lengths[b])
        measured = [s for s in range(2) if act_mask[b, s] > 0] or [0, 1]
        got = wrist_range(wr[b, :n, measured].movedim(0, -2)).mean()
        whole = wrist_range(own[b, :na, measured].movedim(0, -2)).mean()
        best = best_window_range(own[b, :na, measured], n)
        range_kept[b] = got / whole.clamp(min=1e-9)
        window_kept[b] = got / best.clamp(min=1e-9)
        sides_b = [s for s in range(2) if act_mask[b, s] > 0]
        c = times[b, :n]
        back = torch.nonzero(c[1:] < c[:-1]).flatten() + 1
        if not sides_b or len(back) == 0:
            continue
        cap = torch.quantile(ja[b][own_valid[b]][:, sides_b].flatten(), 0.99)
        around = torch.cat([torch.arange(int(t) - 1, int(t) + 2) for t in back]).clamp(0, n - 1)
        seam[b] = float(jr[b, around][:, sides_b].max() / cap.clamp(min=1e-9))
    return StandingMeasures(range_kept, window_kept, kept, idle_lag, seam)
