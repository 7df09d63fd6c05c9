"""The splice of Heck, Kovar & Gleicher 2006 on batches of (locomotion, action) pairs.

Every step works on padded tensors of ``B`` pairs (see :mod:`torchsplice.splice.clips`):

1. frame distances on lower-body point clouds (root and knees by default), heading-restricted
   so that a pose never matches its mirror half a stride later (:mod:`torchsplice.align.distance`);
2. phase cropping of the action at the first clear local minimum of its distance to the
   locomotion's start, compared over half-second windows (single frames are ambiguous);
3. the slope-limited dynamic-programming timewarp (:mod:`torchsplice.align.timewarp`);
4. the alignment curve ``lambda(t)``, a strictly increasing B-spline, and the action resampled
   there (:mod:`torchsplice.align.curve`);
5. spatial alignment: per frame, Horn's rotation ``q_A`` between the pelvis-frame clouds of
   pelvis, spine and shoulders; spliced local pelvis rotation ``q_LP * q_A``;
6. posture transfer: Horn's rotation ``q_G`` between frame-averaged shoulder clouds in heading
   frames (pelvis at the origin, hips along x), applied about the pelvis **in the heading
   frame**: the local pelvis rotation becomes ``Q_par^-1 (H q_G H^-1) Q_par q_P``, where
   ``Q_par`` is the pelvis's parent's global rotation and ``H`` the heading frame. (The
   paper's ``q_P * q_G`` is the same only when the pelvis's local axes match the heading
   frame's; on Bandai Namco and LAFAN1 skeletons they do not.)
   With ``twist`` ``a > 0`` the target posture also takes a share ``a`` of the locomotion's
   torso twist: the action's mean shoulder cloud is turned about the up axis by ``a`` times
   the difference between the yaw of the locomotion's mean shoulder line and the action's (both
   in heading frames: the twist of the shoulders against the hips; a side step twists it by
   about 16 degrees on Bandai Namco, a straight walk by 0 to 4). See :func:`twist_target`.
7. the result: root and lower body from the locomotion, the pelvis computed, the upper body
   from the resampled action.

Quaternions are unit WXYZ; the up axis comes from the dataset spec.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from ..align.curve import fit_alignment_curve
from ..align.distance import distance_grid
from ..align.horn import horn_rotation
from ..align.timewarp import timewarp
from ..core.rotations import quat_apply, quat_conj, quat_mul
from ..core.skeleton import Skeleton
from ..specs import SkeletonRoles
from ..specs.roles import landmark_indices
from ..kinematics.heading import heading_from_hips, heading_points, lateral_axis, third_axis
from .clips import ClipTensors, shift_frames, with_fk, without_fk
from .options import AlignOptions
from .registry import MethodInput, MethodOutput

__all__ = ["AlignOptions", "TimeAlignment", "time_align", "alignment_grid", "phase_crop", "splice_tensors",
           "SplicedTensors", "shoulder_yaw", "twist_target", "run_method"]


def _clouds_and_headings(c: ClipTensors, roles: SkeletonRoles, options: AlignOptions):
    idx = landmark_indices(roles, options.landmarks)
    cloud = c.positions[:, :, idx]
    heading = None
    if options.heading_window_deg is not None:
        heading = heading_from_hips(c.positions[:, :, roles.hips[0]], c.positions[:, :, roles.hips[1]], roles.up_axis)
    return cloud, heading


def alignment_grid(a: ClipTensors, b: ClipTensors, roles: SkeletonRoles, options: AlignOptions) -> torch.Tensor:
    """``(B, Ta, Tb)`` the frame distances the alignment of clips ``a`` to clips ``b`` uses: the
    lower-body landmark clouds compared under the best rotation about the up axis, matches
    restricted to turns within ``options.heading_window_deg`` of the clips' relative heading."""
    ca, ha = _clouds_and_headings(a, roles, options)
    cb, hb = _clouds_and_headings(b, roles, options)
    window = math.radians(options.heading_window_deg) if options.heading_window_deg is not None else math.pi
    return distance_grid(ca, cb, up_axis=roles.up_axis, heading_a=ha, heading_b=hb, max_heading_deviation=window)


def phase_crop(grid: torch.Tensor, lengths_a: torch.Tensor, lengths_b: torch.Tensor, context: int, window: int,
               depth: float = 0.25) -> torch.Tensor:
    """Frames ``(B,)`` to crop from the start of clip b so that it starts in phase with clip a.

    ``grid`` ``(B, Ta, Tb)`` holds frame distances. Root and knees alone cannot tell a frame
    from its mirror half a stride later around the moments the knees pass each other, so the
    crop compares *windows*: ``d(j)`` is the mean distance of a's first ``context`` frames to
    b's frames ``j .. j + context - 1``. The crop is the first ``j`` that is a local minimum
    of ``d``, the smallest within ``window`` frames on either side (robust to small noise),
    and within ``depth`` of the way from the lowest to the highest ``d`` (a real match, not a
    shallow dip); it leaves at least half of b.
    """
    B, Ta, Tb = grid.shape
    dev = grid.device
    Wb = torch.minimum(torch.minimum(lengths_a, lengths_b // 2), torch.full_like(lengths_a, context)).clamp_min(1)  # per pair
    W = int(Wb.max())
    k = torch.arange(W, device=dev)
    j = torch.arange(Tb, device=dev)
    cols = (j[None, :] + k[:, None]).clamp(max=Tb - 1)  # (W, Tb)
    diag = torch.gather(grid[:, :W], 2, cols[None].expand(B, W, Tb))  # grid[b, k, j + k]
    inside = (k[None, :] < Wb[:, None]).to(grid.dtype)  # (B, W)
    d = (diag * inside[:, :, None]).sum(1) / Wb[:, None].to(grid.dtype)  # (B, Tb)
    allowed = (j[None, :] + Wb[:, None] <= lengths_b[:, None]) & (j[None, :] <= (lengths_b[:, None] - 1) // 2)
    d = torch.where(allowed, d, torch.full_like(d, float("inf")))
    nb_min = -torch.nn.functional.max_pool1d(-d[:, None], 2 * window + 1, stride=1, padding=window)[:, 0]
    lo = d.min(1, keepdim=True).values
    hi = torch.where(allowed, d, torch.full_like(d, -float("inf"))).max(1, keepdim=True).values
    deep = d <= lo + depth * (hi - lo)  # a real match, not a shallow dip between strides
    ok = (d <= nb_min) & allowed & deep
    return torch.where(ok.any(1), ok.to(torch.int8).argmax(1), torch.zeros(B, dtype=torch.long, device=dev))


@dataclass
class TimeAlignment:
    """The time alignment of ``B`` pairs.

    Attributes:
        crop: ``(B,)`` frames cropped from the start of the second clip.
        cells, path_length: the DP paths (see :class:`~torchsplice.align.timewarp.WarpPath`),
            in cropped frames.
        cost: ``(B,)`` average frame distance along each path (file units squared).
        curve: ``(B, T)`` float64: for each frame ``t`` of the first clip, the matching
            fractional frame of the cropped second clip (padded with the last value).
        frames: ``(B,)`` number of frames of the first clip covered (``T`` of the result).
    """

    crop: torch.Tensor
    cells: torch.Tensor
    path_length: torch.Tensor
    cost: torch.Tensor
    curve: torch.Tensor
    frames: torch.Tensor


def time_align(base: ClipTensors, other: ClipTensors, roles: SkeletonRoles, options: AlignOptions, fps: float) -> TimeAlignment:
    """Align ``other`` in time to ``base`` (both at ``fps``): grid, phase crop, DP, curve."""
    B = base.lengths.shape[0]
    grid = alignment_grid(base, other, roles, options)
    crop = torch.zeros(B, dtype=torch.long, device=grid.device)
    if options.crop:
        crop = phase_crop(grid, base.lengths, other.lengths, int(round(options.crop_context_s * fps)),
                          max(1, int(round(options.crop_window_s * fps))))
    grid = shift_frames(grid.transpose(1, 2), crop, other.lengths).transpose(1, 2)
    path = timewarp(grid, base.lengths, other.lengths - crop, options.max_run, backend=options.dp_backend)
    curve, frames = fit_alignment_curve(path.cells, path.length, knot_spacing=options.knot_spacing_s * fps)
    return TimeAlignment(crop, path.cells, path.length, path.cost, curve, frames)


@dataclass
class SplicedTensors:
    """Spliced clips ``(B, T, ...)`` with per-pair diagnostics.

    Attributes:
        clips: the spliced :class:`ClipTensors` (``lengths`` = frames of each result; local
            rotations and translations only, no FK).
        alignment: the :class:`TimeAlignment` of action to locomotion.
        pelvis_correction: ``(B, T)`` angle of ``q_A`` per frame, radians.
        posture_rotation: ``(B, 4)`` ``q_G`` (identity without posture transfer).
    """

    clips: ClipTensors
    alignment: TimeAlignment
    pelvis_correction: torch.Tensor
    posture_rotation: torch.Tensor


def _assemble(loco: ClipTensors, act: ClipTensors, pelvis_rot: torch.Tensor, roles: SkeletonRoles,
              lengths: torch.Tensor, skeleton: Skeleton, fk: bool = True) -> ClipTensors:
    """Root and lower body from ``loco``, pelvis from ``pelvis_rot`` ``(B, T, 4)``, upper body from
    ``act``; with its FK when ``fk`` (needed for the alignment clouds, not for the final result)."""
    T = act.rotations.shape[1]
    upper = torch.zeros(skeleton.num_joints, dtype=torch.bool, device=loco.rotations.device)
    upper[list(roles.upper_body)] = True
    rot = torch.where(upper[:, None], act.rotations, loco.rotations[:, :T])
    rot[:, :, roles.pelvis] = pelvis_rot
    trans = torch.where(upper[:, None], act.translations, loco.translations[:, :T])
    trans[:, :, roles.pelvis] = loco.translations[:, :T, roles.pelvis]
    return with_fk(rot, trans, lengths, skeleton) if fk else without_fk(rot, trans, lengths)


def _pelvis_clouds(c: ClipTensors, roles: SkeletonRoles) -> torch.Tensor:
    """``(B, T, K, 3)`` spine joints and shoulders in the pelvis's own frame."""
    idx = [j for j in roles.spine if j != roles.pelvis] + list(roles.shoulders)
    p, q = c.positions[:, :, roles.pelvis], c.global_rotations[:, :, roles.pelvis]
    return quat_apply(quat_conj(q)[:, :, None], c.positions[:, :, idx] - p[:, :, None])


def _posture_clouds(c: ClipTensors, roles: SkeletonRoles, lengths: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-frame heading frames ``(B, T, 4)`` and the frame-averaged shoulder cloud ``(B, 2, 3)``."""
    pos = c.positions
    H, local = heading_points(pos, roles.hips, roles.pelvis, roles.shoulders, roles.up_axis)  # (B, T, 4), (B, T, 2, 3)
    valid = (torch.arange(pos.shape[1], device=pos.device)[None, :] < lengths[:, None]).to(pos.dtype)
    mean = (local * valid[..., None, None]).sum(1) / valid.sum(1)[:, None, None]
    return H, mean


def _plane_axes(up_axis: int) -> tuple[int, int]:
    """Heading-frame axes ``(lateral, third)`` spanning the floor plane (see :mod:`torchsplice.kinematics.heading`)."""
    return lateral_axis(up_axis), third_axis(up_axis)


def shoulder_yaw(cloud: torch.Tensor, up_axis: int) -> torch.Tensor:
    """``(...)`` yaw (radians) of the shoulder line of ``(..., 2, 3)`` clouds (left, right) in
    heading frames: the angle of ``left - right`` in the floor plane, from the lateral axis
    towards the third axis (0 when the shoulders are square to the hips). Not a heading: the
    twist of the shoulders against the hips, measured inside the heading frame."""
    lat, third = _plane_axes(up_axis)
    d = cloud[..., 0, :] - cloud[..., 1, :]
    return torch.atan2(d[..., third], d[..., lat])


def twist_target(mean_action: torch.Tensor, mean_loco: torch.Tensor, share: float, up_axis: int) -> torch.Tensor:
    """The posture-transfer target ``(B, 2, 3)`` with a ``share`` of the locomotion's twist.

    ``mean_action`` and ``mean_loco`` are frame-averaged shoulder clouds ``(B, 2, 3)`` in heading
    frames. The action's cloud is turned about the up axis by ``share * (yaw_loco - yaw_action)``
    (:func:`shoulder_yaw`): with ``share`` 0 it is returned as it is, with 1 its shoulder line
    has the locomotion's yaw.
    """
    if share == 0:
        return mean_action
    lat, third = _plane_axes(up_axis)
    angle = share * (shoulder_yaw(mean_loco, up_axis) - shoulder_yaw(mean_action, up_axis))
    c, s = torch.cos(angle)[:, None], torch.sin(angle)[:, None]
    out = mean_action.clone()
    out[..., lat] = c * mean_action[..., lat] - s * mean_action[..., third]
    out[..., third] = s * mean_action[..., lat] + c * mean_action[..., third]
    return out


def splice_tensors(loco: ClipTensors, act: ClipTensors, roles: SkeletonRoles, skeleton: Skeleton,
                   options: AlignOptions, fps: float, posture: bool = True, twist: float = 0.0) -> SplicedTensors:
    """Splice the upper body of each ``act`` clip onto the lower body of each ``loco`` clip.

    ``loco`` and ``act`` are pairs (clip ``b`` with clip ``b``) on ``skeleton``, both at ``fps``.
    ``twist``: the share of the locomotion's torso twist the posture takes (step 6; 0: the
    paper's posture transfer).
    """
    align = time_align(loco, act, roles, options, fps)
    frames = align.frames
    T = int(frames.max())
    act_c = act.shift(align.crop)
    times = align.curve.to(act_c.rotations.dtype)
    act_r = act_c.at_times(times, frames, skeleton)  # the action resampled at lambda(t), (B, T)

    # spatial alignment: q_A per frame, pelvis := q_LP * q_A
    q_lp = loco.rotations[:, :T, roles.pelvis]
    first = _assemble(loco, act_r, q_lp, roles, frames, skeleton)
    q_a = horn_rotation(_pelvis_clouds(first, roles), _pelvis_clouds(loco.first_frames(T), roles))
    pelvis = quat_mul(q_lp, q_a)
    correction = 2 * torch.atan2(q_a[..., 1:].norm(dim=-1), q_a[..., 0].abs())

    B = frames.shape[0]
    q_g = torch.zeros(B, 4, dtype=pelvis.dtype, device=pelvis.device)
    q_g[:, 0] = 1
    if posture:
        spliced = _assemble(loco, act_r, pelvis, roles, frames, skeleton)
        H, mean_s = _posture_clouds(spliced, roles, frames)
        _, mean_u = _posture_clouds(act_r, roles, frames)
        if twist != 0:
            _, mean_l = _posture_clouds(loco.first_frames(T), roles, frames)
            mean_u = twist_target(mean_u, mean_l, twist, roles.up_axis)
        q_g = horn_rotation(mean_s, mean_u)
        parent = skeleton.parents[roles.pelvis]
        q_par = spliced.global_rotations[:, :, parent]
        world = quat_mul(quat_mul(H, q_g[:, None].expand_as(H)), quat_conj(H))  # q_G in world coordinates
        local = quat_mul(quat_mul(quat_conj(q_par), world), q_par)  # ... in the pelvis's parent frame
        pelvis = quat_mul(local, pelvis)
    spliced = _assemble(loco, act_r, pelvis, roles, frames, skeleton, fk=False)
    return SplicedTensors(spliced, align, correction, q_g)


def run_method(inp: MethodInput) -> MethodOutput:
    """The built-in ``splice`` method on a batch (:func:`splice_tensors`, as the registry runs it)."""
    out = splice_tensors(inp.loco, inp.act, inp.roles, inp.skeleton, inp.options.align, inp.fps,
                         posture=inp.options.posture, twist=inp.options.twist)
    al = out.alignment
    B = inp.loco.lengths.shape[0]
    q = out.posture_rotation
    return MethodOutput(
        clips=out.clips, times=al.curve + al.crop[:, None], cost=al.cost, crop=al.crop,
        paths=[al.cells[b, : int(al.path_length[b])] for b in range(B)],
        pelvis_correction=torch.rad2deg(out.pelvis_correction).to(torch.float64),
        posture_deg=torch.rad2deg(2 * torch.atan2(q[:, 1:].norm(dim=-1), q[:, 0].abs())),
    )
