"""What a person would reject in a clip, measured on its joint positions, batched over clips.

- :func:`penetration`: the share of frames in which a hand or forearm is inside another body
  part (the capsules of :mod:`.body`), and how deep it goes at worst;
- :func:`skate_ratio`: foot skating in GMD's convention (Guided Motion Diffusion, Karunratanakul
  et al. 2023): at 20 fps, a foot joint (SMPL's toes) in contact when it is within 5 cm of the
  floor in two consecutive frames, skating when in contact and faster than 0.5 m/s both in that
  step and averaged over 5 steps (a box filter, zeros beyond the clip); the share of steps in
  which either foot skates;
- :func:`jerk`: the largest third difference of the upper body's joints in the chest's frame
  (a loop seam or a timewarp kink shows as a spike), in units per second cubed.

Conventions: positions ``(B, T, J, 3)`` in the skeleton's units (``per_metre`` of them to a
metre, where a figure is in metres), padded past each clip's ``lengths`` ``(B,)``; fps ``(B,)``;
the up axis an index (Y = 1); quaternions WXYZ.
"""

from __future__ import annotations

import torch

from ..core.rotations import quat_apply, quat_conj
from .body import Body, inside_depth

__all__ = ["penetration", "penetration_packed", "skate_ratio", "jerk", "resample_positions", "GMD_FPS", "GMD_HEIGHT", "GMD_SPEED",
           "GMD_WINDOW"]

GMD_FPS, GMD_HEIGHT, GMD_SPEED, GMD_WINDOW = 20.0, 0.05, 0.5, 5
"""GMD's skate convention: frame rate, contact height (m), skating speed (m/s), averaging window (steps)."""


def _valid(lengths: torch.Tensor, T: int) -> torch.Tensor:
    return torch.arange(T, device=lengths.device)[None, :] < lengths[:, None]


def penetration(positions: torch.Tensor, lengths: torch.Tensor, body: Body) -> tuple[torch.Tensor, torch.Tensor]:
    """``(share, depth)`` per clip ``(B,)``: the share of its frames in which a probe's axis (a
    forearm with its hand) is inside an obstacle's capsule deeper than the body's margin
    (:func:`~.body.inside_depth`), and the deepest it goes then (the skeleton's units, from the
    capsule's surface; 0 where never inside). Padded clips; :func:`penetration_packed` is the
    same of clips packed along frames."""
    return penetration_packed(positions[_valid(lengths, positions.shape[1])], lengths, body)


def penetration_packed(positions: torch.Tensor, lengths, body: Body) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`penetration` of clips packed along frames: ``positions`` ``(N, J, 3)``, the clips'
    frames one after another, ``lengths`` ``(B,)`` summing to ``N``. One segment reduction
    per figure, no loop over clips or frames."""
    lengths = torch.as_tensor(lengths, dtype=torch.long)
    B = len(lengths)
    clip = torch.repeat_interleave(torch.arange(B), lengths)
    deepest = inside_depth(positions, body).flatten(-2).amax(-1)  # (N,)
    inside = deepest > body.margin
    zero = torch.zeros(B, dtype=positions.dtype)
    share = zero.index_add(0, clip, inside.to(positions.dtype)) / lengths.clamp_min(1).to(positions.dtype)
    depth = zero.scatter_reduce(0, clip, torch.where(inside, deepest, 0.0), reduce="amax", include_self=True)
    return share, depth


def resample_positions(positions: torch.Tensor, lengths: torch.Tensor, fps: torch.Tensor,
                       rate: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``(positions, lengths)`` at ``rate`` frames a second: each clip's points linearly
    interpolated at ``k / rate`` seconds for every ``k`` within it (its first frame kept)."""
    B, T = positions.shape[:2]
    fps = torch.as_tensor(fps, dtype=torch.float64, device=positions.device).expand(B)
    duration = (lengths.to(torch.float64) - 1).clamp_min(0) / fps
    new_lengths = torch.floor(duration * rate + 1e-9).long() + 1
    K = int(new_lengths.max()) if B else 0
    t = torch.arange(K, dtype=torch.float64, device=positions.device)[None, :] / rate * fps[:, None]  # source frames
    t = torch.minimum(t, (lengths - 1).clamp_min(0)[:, None].to(torch.float64))
    lo = t.floor().long()
    hi = torch.minimum(lo + 1, (lengths - 1).clamp_min(0)[:, None])
    w = (t - lo).to(positions.dtype)[..., None, None]
    pick = lambda i: torch.gather(positions, 1, i[..., None, None].expand(B, K, *positions.shape[2:]))  # noqa: E731
    return pick(lo) * (1 - w) + pick(hi) * w, new_lengths


def skate_ratio(positions: torch.Tensor, lengths: torch.Tensor, fps: torch.Tensor, feet, up_axis: int,
                per_metre: float) -> torch.Tensor:
    """``(B,)`` GMD's skate ratio (see the module docstring) of each clip's ``feet`` joints (SMPL's
    toes; another rig's toes, else its ankles), its floor the lowest point of any joint over
    the clip (GMD's clips, HumanML3D's, stand on their lowest joint)."""
    valid = _valid(lengths, positions.shape[1])
    low = torch.where(valid[..., None], positions[..., up_axis], torch.inf).flatten(1).amin(1)
    p, n = resample_positions(positions[:, :, list(feet)] / per_metre, lengths, fps, GMD_FPS)
    B, K = p.shape[:2]
    height = p[..., up_axis] - (low / per_metre)[:, None, None]
    flat = p.clone()
    flat[..., up_axis] = 0.0
    speed = (flat[:, 1:] - flat[:, :-1]).norm(dim=-1) * GMD_FPS  # (B, K - 1, F)
    steps = _valid(n - 1, K - 1)
    speed = torch.where(steps[..., None], speed, torch.zeros_like(speed))
    half = GMD_WINDOW // 2
    padded = torch.nn.functional.pad(speed.transpose(1, 2), (half, half))  # zeros beyond the clip, as GMD's filter
    average = padded.unfold(-1, GMD_WINDOW, 1).mean(-1).transpose(1, 2)
    contact = (height[:, :-1] < GMD_HEIGHT) & (height[:, 1:] < GMD_HEIGHT)
    skating = (contact & (speed > GMD_SPEED) & (average > GMD_SPEED)).any(-1) & steps
    return skating.sum(1).to(positions.dtype) / (n - 1).clamp_min(1).to(positions.dtype)


def jerk(positions: torch.Tensor, chest_rotations: torch.Tensor, lengths: torch.Tensor, fps: torch.Tensor,
         joints, chest: int) -> torch.Tensor:
    """``(B,)`` the largest magnitude over frames of the third difference of ``joints`` (the
    upper body's) in the frame of joint ``chest`` (its world rotations ``chest_rotations``
    ``(B, T, 4)``), mean over the joints, times fps cubed: units per second cubed."""
    B, T = positions.shape[:2]
    if T < 4:
        return torch.zeros(B, dtype=positions.dtype)
    rel = positions[:, :, list(joints)] - positions[:, :, chest:chest + 1]
    inv = quat_conj(chest_rotations)[:, :, None, :].expand(*rel.shape[:-1], 4)
    local = quat_apply(inv, rel)
    third = local[:, 3:] - 3 * local[:, 2:-1] + 3 * local[:, 1:-2] - local[:, :-3]  # (B, T - 3, K, 3)
    size = third.norm(dim=-1).mean(-1)
    size = torch.where(_valid(lengths - 3, T - 3), size, torch.zeros_like(size))
    fps = torch.as_tensor(fps, dtype=positions.dtype, device=positions.device).expand(B)
    return size.amax(1) * fps ** 3
