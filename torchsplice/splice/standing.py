"""Standing actions onto locomotion: past the method's stated limit.

Heck et al. (2006) align two *locomoting* clips by their gait; most action libraries are
captured standing (a wave, a bow, a punch), with no gait to align. For such an action the
result lasts as long as the locomotion, and:

- **timing** (:func:`action_times`): which action frame plays at each result frame.

  - ``"loop"`` (the default): a locomotion no longer than the action plays the action's
    *best window* of its length (below); a longer one plays the action from its start and then
    loops it between two frames whose neighbourhoods match best (as motion graphs pick
    transitions), smoothing each jump back by inertialization. The looped span always holds
    the action's *main motion* (below), so every pass shows the whole gesture.
  - ``"hold"``: a locomotion no longer than the action plays its best window; a longer one plays
    the action once from its start, then holds its last frame.
  - ``"fit"``: the whole action, time-scaled to the locomotion's length (faster onto a shorter
    locomotion, slower onto a longer one).

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

What "shows the action" means, measured on the acting hands' positions in the chest's frame
(both hands when no arm acts), in float64 whatever the clips' dtype, so that every backend
chooses the same frames:

- the **best window** of ``n`` frames (:func:`best_windows`) is the one where the acting hands'
  positions spread most: the largest sum of their per-axis variances over the window (the
  first such window, to :data:`TIE` times the largest mean square);
- the **main motion** (:func:`motion_core`) is the span holding the central
  :data:`CORE_SHARE` of the acting hands' path length: a wave's raise, waving and lowering,
  not the still frames before and after. Loop points (:func:`loop_points`) start at or before
  it and end at or after it.

The baselines handle standing actions too: ``naive`` copies the action's whole upper body as
it is (on the same timing), and ``cpmc`` adds the action's motion relative to its first frame
onto the locomotion's upper body (an additive layer over the walk).

Everything is batched over pairs on padded tensors ``(B, T, J, ...)``; quaternions WXYZ. The
compiled CPU splicer (:mod:`torchsplice.cpu.standing`) computes the same, pair by pair.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..core.method_table import builtin, resolve
from ..core.rotations import axis_angle_to_quat, quat_apply, quat_conj, quat_mul, quat_normalize, quat_to_axis_angle
from ..core.skeleton import Skeleton
from ..specs import SkeletonRoles
from ..align.curve import interpolate_frames, slerp_frames
from .clips import ClipTensors, with_fk, without_fk
from .defaults import LIMBS, TIMINGS  # declared there (read by the command line without torch)
from .methods import upper_mask

__all__ = ["TIMINGS", "LIMBS", "ACTING_THRESHOLD", "LOOP_BLEND_SECONDS", "CORE_SHARE", "arm_chains", "acting_limbs",
           "blend_frames", "hands_in_chest", "acting_mask", "motion_core", "best_windows", "loop_points", "action_times",
           "standing_tensors", "standing_tables", "parse_limbs", "splice_upper", "naive_upper", "cpmc_upper"]


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


CORE_SHARE = 0.95
"""The share of the acting hands' path length that a loop span must hold (its central part:
2.5% of the path may lie before the loop's start and 2.5% after its end)."""

TIE = 1e-9
"""Relative tolerance of the best window and loop points: the first candidate within it of the
best wins, so that float64 rounding differences between backends choose the same frames."""


def hands_in_chest(clips: ClipTensors, roles: SkeletonRoles, skeleton: Skeleton) -> torch.Tensor:
    """``(B, T, 2, 3)``: the left and right hands (the shoulders without ``hands`` roles) in the
    chest's frame, from ``clips``' FK."""
    chest = arm_chains(roles, skeleton)[LIMBS[0]][0]
    hands = list(roles.hands) if roles.hands is not None else list(roles.shoulders)
    pos, grot = clips.positions, clips.global_rotations
    return quat_apply(quat_conj(grot[:, :, chest:chest + 1]), pos[:, :, hands] - pos[:, :, chest:chest + 1])


def acting_mask(acting, B: int, device=None) -> torch.Tensor:
    """``(B, 2)`` float64: 1 for the arms (left, right) whose hands measure the action, per pair.

    ``acting`` is ``None`` (every arm acts) or per pair a tuple of :data:`LIMBS`; a pair with no
    acting arm is measured on both hands."""
    if acting is None:
        return torch.ones(B, 2, dtype=torch.float64, device=device)
    m = torch.tensor([[float(n in a) for n in LIMBS] for a in acting], dtype=torch.float64).reshape(B, 2)
    m[m.sum(1) == 0] = 1.0
    return m.to(device)


def selection_tensors(act: ClipTensors, skeleton: Skeleton) -> ClipTensors:
    """``act`` in float64 with its FK recomputed in float64: what the best window and the loop
    points are chosen on (the same frames whatever dtype the splice runs in)."""
    if act.rotations.dtype == torch.float64 and act.positions is not None:
        return act

    return with_fk(act.rotations.double(), act.translations.double(), act.lengths, skeleton)


def motion_core(rel: torch.Tensor, lengths: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(first, last)`` ``(B,)``: the span of each clip holding the central :data:`CORE_SHARE`
    of the path its hands ``rel`` ``(B, T, 2, 3)`` travel (hands weighted by ``mask`` ``(B, 2)``).

    With ``path[t]`` the length travelled up to frame ``t``, ``first`` is the last frame with
    ``path <= (1 - CORE_SHARE) / 2 * total`` and ``last`` the first frame with
    ``path >= (1 + CORE_SHARE) / 2 * total`` (a still clip: its whole length).
    """
    B, T = rel.shape[:2]
    step = (rel[:, 1:] - rel[:, :-1]).square().sum(-1).sqrt()  # (B, T-1, 2)
    t = torch.arange(T, device=rel.device)
    valid = t[None, 1:] < lengths[:, None]  # step t-1 -> t inside the clip
    e = torch.where(valid, (step * mask[:, None, :]).sum(-1), torch.zeros((), dtype=rel.dtype, device=rel.device))
    path = torch.cat((torch.zeros(B, 1, dtype=rel.dtype, device=rel.device), torch.cumsum(e, 1)), 1)  # (B, T)
    total = path.gather(1, (lengths - 1).clamp(min=0)[:, None])
    inside = t[None, :] < lengths[:, None]
    lo, hi = (1 - CORE_SHARE) / 2 * total, (1 + CORE_SHARE) / 2 * total
    first = ((path <= lo) & inside).sum(1) - 1
    last = torch.minimum(((path < hi) & inside).sum(1), lengths - 1)  # the first frame at or past hi
    still = total[:, 0] <= 0
    first = torch.where(still, torch.zeros_like(first), first.clamp(min=0))
    last = torch.where(still, lengths - 1, last)
    return first, last


def best_windows(rel: torch.Tensor, lengths: torch.Tensor, mask: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
    """``(B,)`` the first frame of each clip's best window of ``n[b]`` frames (see the module
    docstring): the largest sum, over the hands of ``mask`` ``(B, 2)`` and the three axes, of the
    variance of the hands' positions ``rel`` ``(B, T, 2, 3)`` over the window. ``n[b]`` must not
    exceed ``lengths[b]``; windows stay inside the clip."""
    B, T = rel.shape[:2]
    z = torch.zeros(B, 1, 2, 3, dtype=rel.dtype, device=rel.device)
    s1 = torch.cat((z, torch.cumsum(rel, 1)), 1)  # (B, T+1, 2, 3): sums of frames < t
    s2 = torch.cat((z, torch.cumsum(rel * rel, 1)), 1)
    w = torch.arange(T, device=rel.device)[None, :].expand(B, T)  # candidate first frames
    end = (w + n[:, None]).clamp(max=T)
    idx = lambda i: i[:, :, None, None].expand(B, T, 2, 3)  # noqa: E731
    k = n.to(rel.dtype)[:, None, None, None]
    m1 = (s1.gather(1, idx(end)) - s1.gather(1, idx(w))) / k
    m2 = (s2.gather(1, idx(end)) - s2.gather(1, idx(w))) / k
    score = ((m2 - m1 * m1) * mask[:, None, :, None]).sum((2, 3))  # (B, T)
    ok = w <= (lengths - n)[:, None]
    score = torch.where(ok, score, torch.full_like(score, -math.inf))
    best = score.max(1, keepdim=True).values
    # within TIE of the best, relative to the mean squares (the rounding of m2 - m1^2): a still
    # clip's windows all tie, and the first wins
    scale = torch.where(ok, (m2 * mask[:, None, :, None]).sum((2, 3)), torch.zeros_like(score)).max(1, keepdim=True).values
    return (ok & (score >= best - TIE * scale)).to(torch.int64).argmax(1)


def loop_points(act: ClipTensors, roles: SkeletonRoles, skeleton: Skeleton, fps: float,
                acting=None) -> tuple[torch.Tensor, torch.Tensor]:
    """``(start, end)`` ``(B,)`` frames where each action loops back: after frame ``end`` it plays
    from ``start`` again, smoothed over :func:`blend_frames` frames.

    Chosen as motion graphs choose transitions: the pair whose following windows of
    :data:`MATCH_SECONDS` look most alike (upper-body joint positions in the chest frame, the
    distance over the window, so that velocities match too), with ``start`` at or before the
    action's main motion and ``end`` at or after it (:func:`motion_core`, on the hands of
    ``acting``, per clip: ``None`` for both), so that the loop holds the whole gesture; the
    end's window lies inside the clip. Ties go to the earliest end, then the earliest start (to
    a relative :data:`TIE`). A clip too short to choose loops whole. Batched over clips, in
    float64 (:func:`selection_tensors`).
    """
    act = selection_tensors(act, skeleton)
    pos, grot, lengths = act.positions, act.global_rotations, act.lengths
    Bn, T = pos.shape[:2]
    chest = arm_chains(roles, skeleton)[LIMBS[0]][0]
    upper = [j for j in roles.upper_body if j != chest]
    W = max(2, round(MATCH_SECONDS * fps))
    whole = torch.zeros_like(lengths), (lengths - 1).clamp(min=1)
    if T < W + 2:
        return whole
    first, last = motion_core(hands_in_chest(act, roles, skeleton), lengths, acting_mask(acting, Bn, pos.device))
    feat = quat_apply(quat_conj(grot[:, :, chest:chest + 1]), pos[:, :, upper] - pos[:, :, chest:chest + 1]).reshape(Bn, T, -1)
    windows = feat.unfold(1, W, 1).reshape(Bn, T - W + 1, -1)  # (B, T', F*W): frames t..t+W-1
    s_hi, e_lo = int(first.max()) + 1, int(last.min())  # candidate starts < s_hi, ends >= e_lo
    if e_lo > T - W:
        return whole
    # d[b, i, j] between the windows at end e_lo + i and start j
    d = torch.cdist(windows[:, e_lo:], windows[:, :s_hi], compute_mode="donot_use_mm_for_euclid_dist")
    end = e_lo + torch.arange(d.shape[1], device=pos.device)[None, :, None]
    start = torch.arange(s_hi, device=pos.device)[None, None, :]
    ok = (start <= first[:, None, None]) & (end >= last[:, None, None]) & (end + W <= lengths[:, None, None]) & (end > start)
    d = torch.where(ok, d, torch.full_like(d, math.inf)).reshape(Bn, -1)
    best = d.min(1, keepdim=True).values
    pick = (d <= best + TIE * best).to(torch.int64).argmax(1)
    e, s = e_lo + pick // s_hi, pick % s_hi
    fallback = ~torch.isfinite(best[:, 0]) | (lengths < W + 2)  # no candidate, or too short: loop the whole clip
    return torch.where(fallback, whole[0], s), torch.where(fallback, whole[1], e)


def action_times(loco_lengths: torch.Tensor, act_lengths: torch.Tensor, timing: str, fps: float,
                 T: int | None = None, loop: tuple[torch.Tensor, torch.Tensor] | None = None,
                 window: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """For every result frame, where in the action it plays: ``(times, blend_from, phase)``.

    All ``(B, T)`` with ``T`` the longest locomotion. ``times`` are action frames (float64).
    ``"fit"`` scales the action's time to the locomotion's length. ``"hold"`` and ``"loop"``
    play, onto a locomotion no longer than the action, its frames from ``window`` ``(B,)``
    (see :func:`best_windows`; default: the first frames); onto a longer one ``"hold"`` plays
    the action once, then holds its last frame, and ``"loop"`` plays it up to its loop ``end``,
    then from its loop ``start`` again (``loop``, see :func:`loop_points`; default: the whole
    clip), again and again. Each jump back is smoothed by inertialization (as game engines
    blend, see :func:`_sample`) over :func:`blend_frames` frames: ``blend_from`` holds ``end``
    during those frames, and ``phase`` goes from 0 at the jump to 1 at the end of the fade (it
    is 1 everywhere else).
    """
    if timing not in TIMINGS:
        raise ValueError(f"unknown timing {timing!r}; choose from {', '.join(TIMINGS)}")
    T = int(loco_lengths.max()) if T is None else T
    dev = loco_lengths.device
    t = torch.arange(T, dtype=torch.float64, device=dev)[None, :].expand(loco_lengths.shape[0], T)
    Ta = act_lengths.to(torch.float64)[:, None]
    Tl = loco_lengths.to(torch.float64)[:, None]
    ones = torch.ones_like(t)
    if timing == "fit":
        return t * (Ta - 1) / (Tl - 1).clamp(min=1), t.clone(), ones
    short = Tl <= Ta  # the locomotion fits in the action: one window of it, no loop
    w = torch.zeros_like(Ta) if window is None else window.to(torch.float64)[:, None]
    windowed = torch.minimum(w + t, Ta - 1)
    if timing == "hold":
        times = torch.where(short, windowed, torch.minimum(t, Ta - 1))
        return times, times.clone(), ones
    blend = blend_frames(act_lengths, fps).to(torch.float64)[:, None]
    if loop is None:
        start, end = torch.zeros_like(Ta), (Ta - blend).clamp(min=1)
    else:
        start, end = loop[0].to(torch.float64)[:, None], loop[1].to(torch.float64)[:, None]
    period = (end - start).clamp(min=1)
    after = (t - end).clamp(min=0)
    cycle = torch.floor(after / period)
    u = after - cycle * period
    looping = (t >= end) & ~short
    fading = looping & (u < blend)
    phase = torch.where(fading, (u / blend).clamp(0, 1), ones)
    times = torch.where(looping, start + u, torch.where(short, windowed, t))
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
    fading = (phase < 1)[..., None, None]  # elsewhere the offset is zero: the frames stay as sampled
    rot = torch.where(fading, quat_normalize(quat_mul(axis_angle_to_quat(r * f + w * g), rot)), rot)
    return rot, torch.where(fading, trans + tr * f + tw * g, trans)



def _mean_rotation(q: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    """Per clip and joint, the normalised mean of ``q`` ``(B, T, J, 4)`` over valid frames
    (signs aligned with the first frame): ``(B, J, 4)``."""
    valid = (torch.arange(q.shape[1], device=q.device)[None, :] < lengths[:, None]).to(q.dtype)
    sign = torch.where((q * q[:, :1]).sum(-1, keepdim=True) < 0, -1.0, 1.0).to(q.dtype)
    return quat_normalize((q * sign * valid[..., None, None]).sum(1))


def standing_tables(roles: SkeletonRoles, skeleton: Skeleton, fps: float):
    """The compiled splicer's tables for standing actions on ``skeleton`` at ``fps``
    (:class:`~torchsplice.cpu.bank.StandingTables`): the joints this module's functions use."""
    from ..cpu.bank import StandingTables  # here: importing this module loads no numba

    J = skeleton.num_joints
    upper = np.zeros(J, dtype=np.bool_)
    upper[list(roles.upper_body)] = True
    chains = arm_chains(roles, skeleton)
    arms = np.zeros((2, J), dtype=np.bool_)
    for side, name in enumerate(LIMBS):
        arms[side, list(chains[name][1])] = True
    chest = chains[LIMBS[0]][0]
    hands = roles.hands if roles.hands is not None else roles.shoulders
    return StandingTables(
        upper=upper, spine=np.array([j for j in roles.spine if upper[j]], dtype=np.int64), arms=arms, chest=int(chest),
        hands=np.array(hands, dtype=np.int64),
        feat_joints=np.array([j for j in roles.upper_body if j != chest], dtype=np.int64),
        blend=int(round(LOOP_BLEND_SECONDS * fps)), window=max(2, round(MATCH_SECONDS * fps)))


def standing_tensors(loco: ClipTensors, act: ClipTensors, roles: SkeletonRoles, skeleton: Skeleton, fps: float,
                     method: str = "splice", timing: str = "loop", acting: list[tuple[str, ...]] | None = None):
    """Splice standing actions onto locomotions: ``(clips, times)``.

    ``loco`` and ``act`` are pairs (row ``b`` of each), at the same frame rate ``fps``.
    ``acting`` gives, per pair, the limbs the action acts with (``None``: every arm acts); their
    hands choose the best window and the loop points (see the module docstring).
    ``method`` is a built-in's name; its row of :data:`torchsplice.core.method_table.BUILTINS`
    names how the upper body is assembled: ``"splice"`` (:func:`splice_upper`, see the module
    docstring), ``"naive"`` (:func:`naive_upper`, the action's whole upper body) or ``"cpmc"``
    (:func:`cpmc_upper`, the action's motion since its first frame, added to the locomotion's
    upper body). Returns the spliced clips (as long as their locomotions; no FK) and the action
    frame of every result frame ``(B, T)`` (float64).
    """
    row = builtin(method)
    if row is None:
        raise ValueError(f"unknown method {method!r}")
    assemble = resolve(row.standing)
    B, T, J = loco.rotations.shape[0], int(loco.lengths.max()), skeleton.num_joints
    dev = loco.rotations.device
    loop = window = None
    if timing != "fit":
        sel = selection_tensors(act, skeleton)
        window = best_windows(hands_in_chest(sel, roles, skeleton), act.lengths, acting_mask(acting, B, dev),
                              torch.minimum(loco.lengths, act.lengths))
        if timing == "loop":
            loop = loop_points(sel, roles, skeleton, fps, acting)
    times, blend_from, phase = action_times(loco.lengths, act.lengths, timing, fps, T, loop, window)
    a_rot, a_trans = _sample(act, times, blend_from, phase, loop[0] if loop is not None else None,
                             blend_frames(act.lengths, fps))  # (B, T, J, 4), (B, T, J, 3)
    l_rot, l_trans = loco.rotations[:, :T], loco.translations[:, :T]
    upper = upper_mask(roles, J, dev)
    rot, trans = assemble(act, loco, a_rot, a_trans, l_rot, l_trans, upper, roles, skeleton, acting)
    return without_fk(rot, trans, loco.lengths.clone()), times


# The upper-body assembly of each built-in method's standing variant, named by its row of
# torchsplice.core.method_table: (act, loco, a_rot, a_trans, l_rot, l_trans, upper, roles, skeleton,
# acting) -> (rotations, translations); a_* is the action sampled on the result's times, l_* the
# locomotion's first T frames, upper the (J,) upper-body mask.


def splice_upper(act, loco, a_rot, a_trans, l_rot, l_trans, upper, roles, skeleton, acting):
    """``splice``: acting arms and spine from the action (the spine with the locomotion's secondary
    motion on top), idle arms, root and lower body from the locomotion (see the module docstring)."""
    B, dev = l_rot.shape[0], l_rot.device
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
    return rot, l_trans.clone()


def naive_upper(act, loco, a_rot, a_trans, l_rot, l_trans, upper, roles, skeleton, acting):
    """``naive``: the action's whole upper body as it is, translations too."""
    return torch.where(upper[:, None], a_rot, l_rot), torch.where(upper[:, None], a_trans, l_trans)


def cpmc_upper(act, loco, a_rot, a_trans, l_rot, l_trans, upper, roles, skeleton, acting):
    """``cpmc``: the action's motion since its first frame added to the locomotion's upper body."""
    first = act.rotations[:, :1]  # (B, 1, J, 4): the action's own reference pose
    delta = quat_mul(quat_conj(first).expand_as(a_rot), a_rot)
    return torch.where(upper[:, None], quat_normalize(quat_mul(l_rot, delta)), l_rot), l_trans.clone()
