"""Measures for standing actions spliced onto locomotion (see :mod:`torchsplice.splice.standing`).

- **action kept**: the acting arms' wrists, in the chest's frame, against the action's at the
  same action frame (the ``action_frame`` column): mean distance (file units). Zero when the
  acting arms carry the action exactly; loop fades and the ``cpmc`` additive layer add to it.
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

__all__ = ["StandingMeasures", "standing_measures"]


@dataclass
class StandingMeasures:
    """Per clip ``(B,)`` float64: ``action_kept`` (units), ``idle_lag`` (gait cycles, NaN when
    both arms act), ``seam_ratio`` (NaN without a loop seam)."""

    action_kept: torch.Tensor
    idle_lag: torch.Tensor
    seam_ratio: torch.Tensor


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
    jr, ja = _jumps(wr), _jumps(own)  # (B, T, 2)
    for b in range(len(results)):  # per clip: its seams are where its own curve jumps back
        sides_b = [s for s in range(2) if act_mask[b, s] > 0]
        c = times[b, : int(R.lengths[b])]
        back = torch.nonzero(c[1:] < c[:-1]).flatten() + 1
        if not sides_b or len(back) == 0:
            continue
        cap = torch.quantile(ja[b][own_valid[b]][:, sides_b].flatten(), 0.99)
        around = torch.cat([torch.arange(int(t) - 1, int(t) + 2) for t in back]).clamp(0, int(R.lengths[b]) - 1)
        seam[b] = float(jr[b, around][:, sides_b].max() / cap.clamp(min=1e-9))
    return StandingMeasures(kept, idle_lag, seam)
