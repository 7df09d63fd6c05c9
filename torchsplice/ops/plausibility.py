"""What a person would reject in a clip, measured on its joint positions, batched over clips.

- :func:`penetration`: the share of frames in which a hand or forearm is inside another body
  part (the capsules of :mod:`.body`), and how deep it goes at worst;
- :func:`skate_ratio`: foot skating in GMD's convention (Guided Motion Diffusion, Karunratanakul
  et al. 2023): at 20 fps, a foot joint (SMPL's toes) in contact when it is within 5 cm of the
  floor in two consecutive frames, skating when in contact and faster than 0.5 m/s both in that
  step and averaged over 5 steps (a box filter, zeros beyond the clip); the share of steps in
  which either foot skates;
- :func:`foot_slide`: the mean horizontal speed of a foot in contact (GMD's contact rule at the
  clip's own rate), in units per second: a second, rate-independent measure of sliding;
- :func:`floor_height`: the lowest a foot goes over the clip, along the up axis from the
  ground plane (up = 0): below 0 the foot is under the ground;
- :func:`jerk`: the largest third difference of the upper body's joints in the chest's frame
  (a loop seam or a timewarp kink shows as a spike), in units per second cubed.

:func:`figure_joints` picks a humanoid's feet, upper-body joints and chest for them, and
:func:`clip_figures` computes all four of packed clips (the job's columns ``foot_skate``,
``foot_slide``, ``floor`` and ``jerk``; the compiled splicer computes the same in
``torchsplice/cpu/figures.py``).

Conventions: positions ``(B, T, J, 3)`` in the skeleton's units (``per_metre`` of them to a
metre, where a figure is in metres), padded past each clip's ``lengths`` ``(B,)``; fps ``(B,)``;
the up axis an index (Y = 1); quaternions WXYZ.
"""

from __future__ import annotations

import torch

from ..core.rotations import quat_apply, quat_conj
from ..specs.canonical import canonical_joints
from .body import Body, inside_depth

__all__ = ["penetration", "penetration_packed", "penetration_of_frames", "skate_ratio", "foot_slide", "floor_height", "jerk", "resample_positions",
           "figure_joints", "clip_figures", "FRAME_FLOOR", "GMD_FPS", "GMD_HEIGHT", "GMD_SPEED", "GMD_WINDOW"]

GMD_FPS, GMD_HEIGHT, GMD_SPEED, GMD_WINDOW = 20.0, 0.05, 0.5, 5
"""GMD's skate convention: frame rate, contact height (m), skating speed (m/s), averaging window (steps)."""

FRAME_FLOOR = 0.5
"""Each frame's deepest (``Backend.inside_body(per_frame=True)``, what :func:`penetration_of_frames`
reads) is exact from this share of the body's margin up: deep enough for the hands' correction
(:mod:`.hands`), whose least target is ``CLEARANCE`` (a half) of the margin."""


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
    return penetration_of_frames(inside_depth(positions, body).flatten(-2).amax(-1), lengths, body.margin)


def penetration_of_frames(deepest: torch.Tensor, lengths, margin: float) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`penetration_packed` from each packed frame's deepest probe-obstacle depth ``(N,)``
    (where it is deeper than ``margin``; what a frame's value is below that does not count), so
    that the frames of a clip that changed can be measured again alone."""
    lengths = torch.as_tensor(lengths, dtype=torch.long)
    B = len(lengths)
    clip = torch.repeat_interleave(torch.arange(B), lengths)
    inside = deepest > margin
    zero = torch.zeros(B, dtype=deepest.dtype)
    share = zero.index_add(0, clip, inside.to(deepest.dtype)) / lengths.clamp_min(1).to(deepest.dtype)
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
    toes; another rig's toes, else its ankles), its floor the lowest point of those feet over
    the clip (GMD's clips, HumanML3D's, stand on their lowest joint: a foot)."""
    low = _lowest(positions[:, :, list(feet)], lengths, up_axis)
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


def _lowest(feet: torch.Tensor, lengths: torch.Tensor, up_axis: int) -> torch.Tensor:
    """``(B,)`` the lowest point along the up axis of ``feet`` ``(B, T, F, 3)`` over each clip."""
    valid = _valid(lengths, feet.shape[1])
    return torch.where(valid[..., None], feet[..., up_axis], torch.inf).flatten(1).amin(1)


def foot_slide(positions: torch.Tensor, lengths: torch.Tensor, fps: torch.Tensor, feet, up_axis: int,
               per_metre: float) -> torch.Tensor:
    """``(B,)`` the mean horizontal speed (the skeleton's units per second) of the ``feet`` over
    the steps between frames in which a foot is in contact (GMD's rule: within 5 cm of the
    clip's lowest foot point in both frames), at the clip's own rate; 0 with no contact."""
    p = positions[:, :, list(feet)]
    B, T = p.shape[:2]
    low = _lowest(p, lengths, up_axis)
    height = p[..., up_axis] - low[:, None, None]
    flat = p.clone()
    flat[..., up_axis] = 0.0
    speed = (flat[:, 1:] - flat[:, :-1]).norm(dim=-1) * torch.as_tensor(fps, dtype=p.dtype).expand(B)[:, None, None]
    contact = (height[:, :-1] < GMD_HEIGHT * per_metre) & (height[:, 1:] < GMD_HEIGHT * per_metre)
    contact &= _valid(lengths - 1, T - 1)[..., None]
    steps = contact.flatten(1).sum(1)
    total = torch.where(contact, speed, torch.zeros_like(speed)).flatten(1).sum(1)
    return torch.where(steps > 0, total / steps.clamp_min(1).to(p.dtype), torch.zeros_like(total))


def floor_height(positions: torch.Tensor, lengths: torch.Tensor, feet, up_axis: int) -> torch.Tensor:
    """``(B,)`` the lowest a foot joint goes over each clip along the up axis, from the ground
    plane (up = 0), in the skeleton's units: below 0 it is under the ground."""
    return _lowest(positions[:, :, list(feet)], lengths, up_axis)


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


def figure_joints(skeleton, roles) -> tuple[tuple[int, ...], tuple[int, ...], int]:
    """``(feet, upper, chest)`` of a humanoid for :func:`clip_figures`: its toes (its ankles
    where it has none), its elbows, wrists and head, and the joint its arms hang from."""
    j = canonical_joints(roles, skeleton)
    feet = (j["toe_l"], j["toe_r"]) if "toe_l" in j else (j["ankle_l"], j["ankle_r"])
    upper = (j["elbow_l"], j["elbow_r"], j["wrist_l"], j["wrist_r"], j.get("head", j["spine"][-1]))
    chest = skeleton.parents[j["clavicle_l"] if "clavicle_l" in j else j["shoulder_l"]]
    return tuple(int(x) for x in feet), tuple(int(x) for x in upper), int(chest)


def clip_figures(positions: torch.Tensor, global_rotations: torch.Tensor, lengths: torch.Tensor, fps, joints: tuple,
                 up_axis: int, per_metre: float) -> dict[str, torch.Tensor]:
    """The job's figures of padded clips ``(B, T, J, 3)`` (their global rotations ``(B, T, J, 4)``;
    ``joints`` :func:`figure_joints`'s): ``foot_skate`` (GMD's ratio), ``foot_slide`` (cm/s),
    ``floor`` (cm) and ``jerk`` (m/s^3), each ``(B,)``."""
    feet, upper, chest = joints
    fps = torch.as_tensor(fps, dtype=positions.dtype).expand(positions.shape[0])
    cm = 100.0 / per_metre
    return {"foot_skate": skate_ratio(positions, lengths, fps, feet, up_axis, per_metre),
            "foot_slide": foot_slide(positions, lengths, fps, feet, up_axis, per_metre) * cm,
            "floor": floor_height(positions, lengths, feet, up_axis) * cm,
            "jerk": jerk(positions, global_rotations[:, :, chest], lengths, fps, upper, chest) / per_metre}
