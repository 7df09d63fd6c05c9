"""Standing actions onto locomotion: past the method's stated limit.

Heck et al. (2006) align two *locomoting* clips by their gait; most action libraries are
captured standing (a wave, a bow, a punch), with no gait to align. For such an action the
result lasts as long as the locomotion, and:

- **timing**: the action plays at its own speed, ``"loop"``-ed with a seamless blend (the
  default: it loops between the two frames whose neighbourhoods match best, as motion graphs
  pick transitions, and cross-fades there), ``"hold"``-ing its last frame, or ``"fit"``-ted
  (time-scaled) to the locomotion;
- **acting limbs** (the arms the action really uses, e.g. the waving one) come from the action;
- **idle limbs** keep the locomotion's motion, so the free arm swings in phase with the legs;
- **the spine** carries the action's posture with the locomotion's secondary motion on top
  (twist, sway, bob): per spine joint ``q = q_action(t) * (mean(q_loco)^-1 * q_loco(t))``, the
  locomotion's deviation from its own mean posture, applied in the joint's frame;
- the root and lower body are the locomotion's, unchanged.

Which arms act is found from the data, per action clip (:func:`acting_limbs`): an arm acts
when its hand moves, in the chest's frame, more than :data:`ACTING_THRESHOLD` arm lengths from
its median position over 10% of the clip or more (the 90th percentile of the distance). On
Bandai Namco's standing actions an idle arm stays under 0.15, an acting one over 0.45.

The baselines handle standing actions too: ``naive`` copies the action's whole upper body as
it is (on the same timing), and ``cpmc`` adds the action's motion relative to its first frame
onto the locomotion's upper body (an additive layer over the walk).

Everything is batched over pairs on padded tensors ``(B, T, J, ...)``; quaternions WXYZ.
"""

from __future__ import annotations

import math

import torch

from ..core.rotations import axis_angle_to_quat, quat_apply, quat_conj, quat_mul, quat_normalize, quat_to_axis_angle
from ..core.skeleton import Skeleton
from ..specs import SkeletonRoles
from ..align.curve import interpolate_frames, slerp_frames
from .clips import ClipTensors, without_fk
from .methods import upper_mask

__all__ = ["TIMINGS", "LIMBS", "ACTING_THRESHOLD", "LOOP_BLEND_SECONDS", "arm_chains", "acting_limbs",
           "blend_frames", "loop_points", "action_times", "standing_tensors", "parse_limbs"]

TIMINGS = ("loop", "hold", "fit")
"""How a standing action fills a longer (or shorter) locomotion."""

LIMBS = ("left_arm", "right_arm")
"""Limbs an action may act with (the legs always come from the locomotion)."""

ACTING_THRESHOLD = 0.3
"""An arm acts when the 90th percentile of its hand's distance from the hand's median position,
in the chest's frame, exceeds this many arm lengths."""

LOOP_BLEND_SECONDS = 0.5
"""Length of the fade at each loop point (at most a third of the action)."""

MATCH_SECONDS = 0.1
"""Length of the windows compared to choose the loop points (pose and velocity)."""


def parse_limbs(text: str | None) -> tuple[str, ...] | None:
    """``"auto"``/``None`` -> ``None`` (found from the data); ``"none"`` -> ``()``; ``"both"``
    -> both arms; else a comma-separated list of :data:`LIMBS`."""
    if text is None or text.strip().lower() == "auto":
        return None
    if text.strip().lower() == "none":
        return ()
    if text.strip().lower() == "both":
        return LIMBS
    limbs = tuple(x.strip() for x in text.split(",") if x.strip())
    bad = [x for x in limbs if x not in LIMBS]
    if bad:
        raise ValueError(f"unknown limb {bad[0]!r}; choose from {', '.join(LIMBS)}, or auto, both or none")
    return limbs


def arm_chains(roles: SkeletonRoles, skeleton: Skeleton) -> dict[str, tuple[int, tuple[int, ...]]]:
    """Per arm: ``(chest, joints)``: the spine joint it hangs from, and every joint of the arm
    (from the joint that leaves the spine, e.g. the clavicle, down to the fingers)."""
    spine = set(roles.spine)
    out = {}
    for name, shoulder in zip(LIMBS, roles.shoulders):
        j = shoulder
        while skeleton.parents[j] >= 0 and skeleton.parents[j] not in spine:
            j = skeleton.parents[j]
        chest = skeleton.parents[j]
        out[name] = (chest, tuple(skeleton.descendants(j)))
    return out


def _arm_length(roles: SkeletonRoles, skeleton: Skeleton, side: int) -> float:
    """Shoulder-to-hand bone length (offset norms), file units."""
    hand = roles.hands[side] if roles.hands is not None else None
    j, total = (hand if hand is not None else roles.shoulders[side]), 0.0
    while j not in (roles.shoulders[side], -1):
        total += float(skeleton.offsets[j].norm())
        j = skeleton.parents[j]
    return max(total, 1e-9)


def acting_limbs(clips: ClipTensors, roles: SkeletonRoles, skeleton: Skeleton) -> list[tuple[tuple[str, ...], dict]]:
    """Per clip of ``clips`` (with FK): the arms it acts with, and the measure per arm.

    Returns ``[(limbs, {"left_arm": m, "right_arm": m}), ...]`` with ``m`` the 90th percentile
    of the hand's distance from its median position in the chest frame, in arm lengths.
    """
    if roles.hands is None:
        return [(LIMBS, {}) for _ in range(clips.lengths.shape[0])]
    pos, grot, lengths = clips.positions, clips.global_rotations, clips.lengths
    T = pos.shape[1]
    valid = torch.arange(T, device=pos.device)[None, :] < lengths[:, None].to(pos.device)  # (B, T)
    chains = arm_chains(roles, skeleton)
    measures = []
    for side, name in enumerate(LIMBS):
        chest = chains[name][0]
        rel = quat_apply(quat_conj(grot[:, :, chest]), pos[:, :, roles.hands[side]] - pos[:, :, chest])  # (B, T, 3)
        big = torch.finfo(rel.dtype).max
        med = torch.nanmedian(torch.where(valid[..., None], rel, torch.nan), dim=1).values  # (B, 3)
        dist = (rel - med[:, None]).norm(dim=-1)
        dist = torch.where(valid, dist, torch.nan)
        q90 = torch.nanquantile(dist, 0.9, dim=1) if T > 0 else torch.zeros(len(lengths))
        measures.append(torch.nan_to_num(q90, nan=0.0, posinf=big) / _arm_length(roles, skeleton, side))
    out = []
    for b in range(lengths.shape[0]):
        m = {name: float(measures[s][b]) for s, name in enumerate(LIMBS)}
        out.append((tuple(n for n in LIMBS if m[n] > ACTING_THRESHOLD), m))
    return out


def blend_frames(act_lengths: torch.Tensor, fps: float) -> torch.Tensor:
    """``(B,)`` frames of each loop fade: :data:`LOOP_BLEND_SECONDS`, at most a third of the action."""
    return torch.minimum(torch.full_like(act_lengths, round(LOOP_BLEND_SECONDS * fps)), act_lengths // 3).clamp(min=1)


def loop_points(act: ClipTensors, roles: SkeletonRoles, skeleton: Skeleton, fps: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``(start, end)`` ``(B,)`` frames where each action loops back: after frame ``end`` it plays
    from ``start`` again, cross-fading over :func:`blend_frames` frames.

    Chosen as motion graphs choose transitions: the pair whose following windows of
    :data:`MATCH_SECONDS` look most alike (upper-body joint positions in the chest frame, the
    distance over the window, so that velocities match too), with ``start`` in the first third
    of the action and ``end`` in the last third, so that the loop keeps most of the action (a
    fade that runs past the clip's end holds its last frame). Batched over clips.
    """
    pos, grot, lengths = act.positions, act.global_rotations, act.lengths
    Bn, T = pos.shape[:2]
    chest = arm_chains(roles, skeleton)[LIMBS[0]][0]
    upper = [j for j in roles.upper_body if j != chest]
    feat = quat_apply(quat_conj(grot[:, :, chest:chest + 1]), pos[:, :, upper] - pos[:, :, chest:chest + 1]).reshape(Bn, T, -1)
    W = max(2, round(MATCH_SECONDS * fps))
    if T < W + 2:
        return torch.zeros_like(lengths), (lengths - 1).clamp(min=1)
    windows = feat.unfold(1, W, 1).reshape(Bn, T - W + 1, -1)  # (B, T', F*W): frames t..t+W-1
    d = torch.cdist(windows, windows)  # (B, T', T'): d[b, i, j] between the windows at end i and start j
    i = torch.arange(T - W + 1, device=pos.device)
    L = lengths[:, None, None]
    ok = ((i[None, None, :] * 3 <= L) & (i[None, :, None] * 3 >= 2 * L)  # start in the first third, end in the last
          & (i[None, :, None] + W <= L))  # the end's window inside the clip (past its end, the fade holds the last frame)
    d = torch.where(ok, d, torch.full_like(d, float("inf")))
    best = d.reshape(Bn, -1).argmin(1)
    end, start = best // (T - W + 1), best % (T - W + 1)
    fallback = ~torch.isfinite(d.reshape(Bn, -1).min(1).values)  # too short to choose: loop the whole clip
    start = torch.where(fallback, torch.zeros_like(start), start)
    end = torch.where(fallback, (lengths - 1).clamp(min=1), end)
    return start, end


def action_times(loco_lengths: torch.Tensor, act_lengths: torch.Tensor, timing: str, fps: float,
                 T: int | None = None, loop: tuple[torch.Tensor, torch.Tensor] | None = None
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """For every result frame, where in the action it plays: ``(times, blend_from, phase)``.

    All ``(B, T)`` with ``T`` the longest locomotion. ``times`` are action frames (float64).
    ``"hold"`` plays the action once, then holds its last frame; ``"fit"`` scales the action's
    time to the locomotion's length. ``"loop"`` plays the action up to its loop ``end``, then
    from its loop ``start`` again (``loop``, see :func:`loop_points`; default: the whole clip),
    again and again. Each jump back is smoothed by inertialization (as game engines blend, see
    :func:`_sample`) over :func:`blend_frames` frames: ``blend_from`` holds ``end`` during
    those frames, and ``phase`` goes from 0 at the jump to 1 at the end of the fade (it is 1
    everywhere else).
    """
    if timing not in TIMINGS:
        raise ValueError(f"unknown timing {timing!r}; choose from {', '.join(TIMINGS)}")
    T = int(loco_lengths.max()) if T is None else T
    dev = loco_lengths.device
    t = torch.arange(T, dtype=torch.float64, device=dev)[None, :].expand(loco_lengths.shape[0], T)
    Ta = act_lengths.to(torch.float64)[:, None]
    Tl = loco_lengths.to(torch.float64)[:, None]
    ones = torch.ones_like(t)
    if timing == "hold":
        return torch.minimum(t, Ta - 1), t.clone(), ones
    if timing == "fit":
        return t * (Ta - 1) / (Tl - 1).clamp(min=1), t.clone(), ones
    blend = blend_frames(act_lengths, fps).to(torch.float64)[:, None]
    if loop is None:
        start, end = torch.zeros_like(Ta), (Ta - blend).clamp(min=1)
    else:
        start, end = loop[0].to(torch.float64)[:, None], loop[1].to(torch.float64)[:, None]
    period = (end - start).clamp(min=1)
    after = (t - end).clamp(min=0)
    cycle = torch.floor(after / period)
    u = after - cycle * period
    looping = t >= end
    fading = looping & (u < blend)
    phase = torch.where(fading, (u / blend).clamp(0, 1), ones)
    times = torch.where(looping, start + u, t)
    return times, torch.where(fading, end.expand_as(t), times), phase


def _sample(act: ClipTensors, times: torch.Tensor, blend_from: torch.Tensor, phase: torch.Tensor,
            loop_start: torch.Tensor | None, blend: torch.Tensor | None):
    """Action rotations and translations at ``times``, with each loop's jump back smoothed.

    Inertialization: at a jump from frame ``end`` (``blend_from``) to ``start`` (``loop_start``
    ``(B,)``), the new pass ``q(t)`` is shifted by an offset that starts as the pose difference
    ``r = log(q[end] q[start]^-1)`` and the velocity difference ``w`` (angular velocity at
    ``end`` minus at ``start``, per frame) and decays over ``blend`` ``(B,)`` frames:
    ``exp(r f(u) + w g(u)) q(t)``, with ``f = 1 - smoothstep(u / blend)`` and
    ``g = u (1 - u / blend)^2`` (translations alike). Pose and velocity are continuous at the
    jump, and the offset fades with zero velocity: the new pass goes on with its own motion.
    """
    rot = slerp_frames(act.rotations, times, act.lengths)
    trans = interpolate_frames(act.translations, times, act.lengths)
    if loop_start is None or not bool((phase < 1).any()):
        return rot, trans
    L = act.lengths
    start = loop_start.to(times.dtype)[:, None].expand_as(times)
    at = lambda x: slerp_frames(act.rotations, x, L)  # noqa: E731
    lin = lambda x: interpolate_frames(act.translations, x, L)  # noqa: E731
    r = quat_to_axis_angle(quat_mul(at(blend_from), quat_conj(at(start))))
    w = (quat_to_axis_angle(quat_mul(at(blend_from), quat_conj(at(blend_from - 1))))
         - quat_to_axis_angle(quat_mul(at(start + 1), quat_conj(at(start)))))
    tr = lin(blend_from) - lin(start)
    tw = (lin(blend_from) - lin(blend_from - 1)) - (lin(start + 1) - lin(start))
    s = phase.to(rot.dtype)
    u = s * blend.to(rot.dtype)[:, None]
    f = (1 - s * s * (3 - 2 * s))[..., None, None]
    g = (u * (1 - s) ** 2)[..., None, None]
    rot = quat_normalize(quat_mul(axis_angle_to_quat(r * f + w * g), rot))
    return rot, trans + tr * f + tw * g



def _mean_rotation(q: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    """Per clip and joint, the normalised mean of ``q`` ``(B, T, J, 4)`` over valid frames
    (signs aligned with the first frame): ``(B, J, 4)``."""
    valid = (torch.arange(q.shape[1], device=q.device)[None, :] < lengths[:, None]).to(q.dtype)
    sign = torch.where((q * q[:, :1]).sum(-1, keepdim=True) < 0, -1.0, 1.0).to(q.dtype)
    return quat_normalize((q * sign * valid[..., None, None]).sum(1))


def standing_tensors(loco: ClipTensors, act: ClipTensors, roles: SkeletonRoles, skeleton: Skeleton, fps: float,
                     method: str = "splice", timing: str = "loop", acting: list[tuple[str, ...]] | None = None):
    """Splice standing actions onto locomotions: ``(clips, times)``.

    ``loco`` and ``act`` are pairs (row ``b`` of each), at the same frame rate ``fps``.
    ``acting`` gives, per pair, the limbs the action acts with (``None``: every arm acts).
    ``method`` is ``"splice"`` (see the module docstring), ``"naive"`` (the action's whole upper
    body) or ``"cpmc"`` (the action's motion since its first frame, added to the locomotion's
    upper body). Returns the spliced clips (as long as their locomotions; no FK) and the action
    frame of every result frame ``(B, T)`` (float64).
    """
    B, T, J = loco.rotations.shape[0], int(loco.lengths.max()), skeleton.num_joints
    dev = loco.rotations.device
    loop = loop_points(act, roles, skeleton, fps) if timing == "loop" else None
    times, blend_from, phase = action_times(loco.lengths, act.lengths, timing, fps, T, loop)
    a_rot, a_trans = _sample(act, times, blend_from, phase, loop[0] if loop is not None else None,
                             blend_frames(act.lengths, fps))  # (B, T, J, 4), (B, T, J, 3)
    l_rot, l_trans = loco.rotations[:, :T], loco.translations[:, :T]
    upper = upper_mask(roles, J, dev)
    if method == "naive":
        rot = torch.where(upper[:, None], a_rot, l_rot)
    elif method == "cpmc":
        first = act.rotations[:, :1]  # (B, 1, J, 4): the action's own reference pose
        delta = quat_mul(quat_conj(first).expand_as(a_rot), a_rot)
        rot = torch.where(upper[:, None], quat_normalize(quat_mul(l_rot, delta)), l_rot)
    elif method == "splice":
        rot = torch.where(upper[:, None], a_rot, l_rot)
        spine = [j for j in roles.spine if upper[j]]
        if spine:
            mean = _mean_rotation(l_rot[:, :, spine], loco.lengths)  # (B, S, 4)
            dev_loco = quat_mul(quat_conj(mean)[:, None].expand_as(l_rot[:, :, spine]), l_rot[:, :, spine])
            rot[:, :, spine] = quat_normalize(quat_mul(a_rot[:, :, spine], dev_loco))
        chains = arm_chains(roles, skeleton)
        for name in LIMBS:
            joints = list(chains[name][1])
            idle = torch.tensor([acting is not None and name not in acting[b] for b in range(B)], device=dev)
            if joints and bool(idle.any()):
                rot[:, :, joints] = torch.where(idle[:, None, None, None], l_rot[:, :, joints], rot[:, :, joints])
    else:
        raise ValueError(f"unknown method {method!r}")
    trans = torch.where(upper[:, None] & (method == "naive"), a_trans, l_trans).clone()
    return without_fk(rot, trans, loco.lengths.clone()), times
