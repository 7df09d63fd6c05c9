"""The two baselines on padded pair tensors: naive DOF replacement and CPMC differencing.

Both return :class:`~torchsplice.splice.clips.ClipTensors` of spliced clips (local rotations
and translations; no FK) plus the time mapping used (for each result frame, the action frame it took its upper body from).

**Rotation difference (CPMC).** For each upper-body joint (the pelvis and everything above)
the difference between the action ``q_act`` and its time-aligned plain-locomotion reference
``q_ref`` is taken in the joint's own frame, ``d = q_ref^-1 * q_act``, and added onto the new
base the same way, ``q = q_base * d``. Frame by frame, ``q_base = q_ref`` gives back the action;
over a clip, the two time alignments may pair a base frame with a reference frame one gait
cycle later, so the result then carries the walk's cycle-to-cycle variation.
This is how game engines apply local-space additive layers.
"""

from __future__ import annotations

import torch

from ..core.rotations import quat_conj, quat_mul
from ..core.skeleton import Skeleton
from ..specs import SkeletonRoles
from ..align.curve import slerp_frames
from .clips import ClipTensors, shift_frames, without_fk
from .heck import TimeAlignment, time_align
from .options import AlignOptions
from .registry import MethodInput, MethodOutput

__all__ = ["naive_tensors", "cpmc_tensors", "upper_mask", "run_naive", "run_cpmc"]


def upper_mask(roles: SkeletonRoles, J: int, device) -> torch.Tensor:
    """``(J,)`` bool, True on the upper body (the pelvis and its descendants)."""
    m = torch.zeros(J, dtype=torch.bool, device=device)
    m[list(roles.upper_body)] = True
    return m


def naive_tensors(loco: ClipTensors, act: ClipTensors, roles: SkeletonRoles, skeleton: Skeleton):
    """Naive DOF replacement: upper-body local rotations and translations copied frame by frame.

    No timewarp: result frame ``t`` takes the action's frame ``t``; the shorter clip sets the
    length. Returns ``(clips, times)`` with ``times`` ``(B, T)`` the action frames used.
    """
    lengths = torch.minimum(loco.lengths, act.lengths)
    T = int(lengths.max())
    upper = upper_mask(roles, skeleton.num_joints, loco.rotations.device)
    rot = torch.where(upper[:, None], act.rotations[:, :T], loco.rotations[:, :T])
    trans = torch.where(upper[:, None], act.translations[:, :T], loco.translations[:, :T])
    trans[:, :, roles.pelvis] = loco.translations[:, :T, roles.pelvis]
    times = torch.arange(T, dtype=torch.float64, device=lengths.device)[None].expand(lengths.shape[0], T)
    return without_fk(rot, trans, lengths), torch.minimum(times, (lengths - 1)[:, None].to(times.dtype))


def cpmc_tensors(loco: ClipTensors, act: ClipTensors, ref: ClipTensors, roles: SkeletonRoles,
                 skeleton: Skeleton, options: AlignOptions, fps: float):
    """Differencing of Combined Partial Motion Clips (Al-Ghreimil & Hahn 2003).

    The reference (a plain locomotion of the action's performer) is time-aligned to the
    action on the lower bodies; per-joint rotation differences of the upper body are taken
    along the action; the action is time-aligned to the new base ``loco``; the differences,
    resampled there (slerp), are added to the base's upper body.

    Returns ``(clips, to_action, to_base)``: the spliced clips, the alignment of the action to
    the base (its ``curve`` gives the action frame of every result frame, after its crop), and
    the alignment of the reference to the action.
    """
    ref_to_act: TimeAlignment = time_align(act, ref, roles, options, fps)
    n_act = ref_to_act.frames  # action frames that have a reference frame
    Ta = int(n_act.max())
    ref_r = ref.shift(ref_to_act.crop).at_times(ref_to_act.curve.to(ref.rotations.dtype), n_act, skeleton)
    upper = upper_mask(roles, skeleton.num_joints, loco.rotations.device)
    diff = quat_mul(quat_conj(ref_r.rotations), act.rotations[:, :Ta])  # (B, Ta, J, 4)

    act_part = act.first_frames(Ta)
    act_part.lengths = n_act
    act_to_base: TimeAlignment = time_align(loco, act_part, roles, options, fps)
    frames = act_to_base.frames
    T = int(frames.max())
    diff = shift_frames(diff, act_to_base.crop, n_act)
    d = slerp_frames(diff, act_to_base.curve.to(diff.dtype), n_act - act_to_base.crop)
    base = loco.rotations[:, :T]
    rot = torch.where(upper[:, None], quat_mul(base, d), base)
    return without_fk(rot, loco.translations[:, :T], frames), act_to_base, ref_to_act


def run_naive(inp: MethodInput) -> MethodOutput:
    """The built-in ``naive`` method on a batch (:func:`naive_tensors`, as the registry runs it)."""
    clips, times = naive_tensors(inp.loco, inp.act, inp.roles, inp.skeleton)
    return MethodOutput(clips=clips, times=times)


def run_cpmc(inp: MethodInput) -> MethodOutput:
    """The built-in ``cpmc`` method on a batch (:func:`cpmc_tensors`, as the registry runs it)."""
    clips, al, _ = cpmc_tensors(inp.loco, inp.act, inp.ref, inp.roles, inp.skeleton, inp.options.align, inp.fps)
    B = inp.loco.lengths.shape[0]
    return MethodOutput(clips=clips, times=al.curve + al.crop[:, None], cost=al.cost, crop=al.crop,
                        paths=[al.cells[b, : int(al.path_length[b])] for b in range(B)])
