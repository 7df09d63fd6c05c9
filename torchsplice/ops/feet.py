"""Feet fixed after retargeting: each foot held where it stands while the source's foot stands,
by two-bone IK of the leg, and kept at the source's height above the floor.

Conventions: quaternions unit WXYZ, local to the parent; positions in the skeleton's units; the
up axis an index (Y = 1); the floor at height 0 of the up axis (every shipped dataset is captured
so). Shapes: ``T`` frames, ``J`` joints. Batched over clips whose frames are concatenated; the
Python loops run over the two legs, and over clips only to smooth a lowered pelvis, never over
frames or contact runs.

Why: retargeting carries rotations and scales the trajectory by leg length, but a target whose
legs hang otherwise from its pelvis (or whose feet are longer) puts its feet a little elsewhere
each frame, so a standing foot slides, and its foot joints sit at other heights above the
floor than its rig needs. :func:`fix_feet` corrects both:

- **Where a foot stands.** The source's contacts (:func:`~torchsplice.kinematics.contacts.foot_contacts`
  on its ankles and toes, :data:`PIN_HEIGHT_RATIO` and :data:`PIN_SPEED_RATIO`), each widened
  by a frame on both sides (a speed by central differences reads them), are runs of frames.
  Over a run of the ankle, the target's ankle follows the source's ankle's own path (scaled
  like the trajectory), moved by one offset for the run (its mean distance from where the
  retargeting put the ankle), so it slides exactly as the source's does; over a run of the toe
  alone (the heel lifting), the toe does, and the ankle follows the foot's own rotation about
  it. A run that starts as the other point's ends starts where that one left the foot, so the
  hand-over does not jump. The pin blends in and out over :data:`BLEND_SECONDS` beyond each run.
- **How high.** Every frame, the target's ankle and toe are each put at least at the source's
  height above that point's resting height (its height while the foot stands), times the
  leg-length scale, above the target's resting height (its own clips' where known, else the
  source's scaled); the foot keeps the source's pitch, so one of the two decides and the other
  may stand a little higher. A foot that rests on the floor in the source rests on it in the
  target, whatever the two rigs' ankle and toe heights, and sinks no lower than the source's.
- **The pelvis's height.** The pelvis is raised or lowered by one amount for the clip, the
  median of what the standing feet lack (a rig whose hips hang lower below its pelvis stands
  lower), and lowered further where a leg still cannot reach its target (smoothly over
  :data:`BLEND_SECONDS`).

:func:`two_bone_ik` keeps bone lengths, the knee in the plane it bends in, and the foot's world
rotation (so the toes point as they did).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..core.fk import forward_kinematics
from ..core.ranges import ranges_to_rows
from ..core.rotations import quat_apply, quat_between, quat_conj, quat_mul, quat_normalize
from ..kinematics.contacts import foot_contacts
from ..specs.canonical import leg_length

__all__ = ["two_bone_ik", "fix_feet", "FeetMap", "contact_heights", "rig_heights", "BLEND_SECONDS", "PIN_HEIGHT_RATIO",
           "PIN_SPEED_RATIO"]

BLEND_SECONDS = 4 / 30
"""Seconds over which a pinned foot blends in before its contact run and out after it (4 frames
at 30 fps), and over which a lowered pelvis eases in and out."""

PIN_HEIGHT_RATIO = 0.06
"""A source foot point is pinned within this many leg lengths of its lowest height..."""

PIN_SPEED_RATIO = 0.4
"""... and slower than this many leg lengths per second (a little looser than the skate
measure's 0.05 and 0.3, so that every frame the measure counts as standing is pinned)."""

_STILL = 1e-6
"""A foot whose target is within this many leg lengths of where it is keeps its leg's rotations as
they are (a clip retargeted onto its own skeleton comes back unchanged, not re-solved)."""

_NEARLY_STRAIGHT = 0.05
"""A knee this many thigh lengths or less off the hip-ankle line (bent about 5 degrees or less)
takes its bend side from the foot's forward direction (:func:`two_bone_ik`)."""

_SLIGHTLY_BENT = 0.25
"""... and one bent backwards (against the foot's forward direction) by up to this many thigh
lengths off the line (about 15 degrees), which a knee does not do: a deeper bend keeps its side
(a kneeling leg whose foot points back, a kick with the toes pointed)."""

_REACH = 0.9995
"""The fraction of a leg's full length that IK stretches it to (a straight knee is singular)."""


def _norm(v: torch.Tensor) -> torch.Tensor:
    return (v * v).sum(-1).sqrt()


def _unit(v: torch.Tensor) -> torch.Tensor:
    return v / (v * v).sum(-1, keepdim=True).sqrt().clamp_min(1e-12)


def two_bone_ik(hip: torch.Tensor, knee: torch.Tensor, ankle: torch.Tensor, target: torch.Tensor,
                g_hip: torch.Tensor, g_knee: torch.Tensor, forward: torch.Tensor | None = None
                ) -> tuple[torch.Tensor, torch.Tensor]:
    """New world rotations ``(N, 4)`` of a hip and its knee that bring the ankle (the knee's
    child) from ``ankle`` to ``target`` (positions ``(N, 3)``; ``g_hip``, ``g_knee`` the current
    world rotations ``(N, 4)``). The knee stays on the side it bends to; a target out of reach is
    approached along the same line (the leg straightens to :data:`_REACH`, or stays as
    straight as it is), one too close along
    it as far as the bones allow.

    ``forward`` ``(N, 3)``: the way the knee bends (the foot's forward direction, ankle to toe).
    A knee nearly straight (bent less than :data:`_NEARLY_STRAIGHT` of its thigh's length off
    the line), or slightly past straight (:data:`_SLIGHTLY_BENT`), gives no side of its own
    (rounding decides it, and the leg would bend backwards as it shortens): it bends towards
    ``forward`` there."""
    a = _norm(knee - hip)[:, None]
    b = _norm(ankle - knee)[:, None]
    to = target - hip
    reach = torch.maximum((a + b) * _REACH, _norm(ankle - hip)[:, None])  # no straighter than it is
    d = torch.minimum(_norm(to)[:, None].clamp_min((a - b).abs() + 1e-9 * (a + b)), reach)
    u = _unit(to)
    pole = knee - hip
    pole = pole - (pole * u).sum(-1, keepdim=True) * u
    straight = _norm(pole)[:, None] <= 1e-9 * a
    # a straight leg: no side to keep, so it bends to a fixed side perpendicular to the line
    fallback = torch.linalg.cross(u, torch.roll(u, 1, dims=-1), dim=-1)
    n = _unit(torch.where(straight, fallback, pole))
    if forward is not None:  # nearly straight or past straight: the knee bends forward, as knees do
        fwd = forward - (forward * u).sum(-1, keepdim=True) * u
        usable = _norm(fwd)[:, None] > 1e-6 * _norm(forward).clamp_min(1e-12)[:, None]
        side = _norm(pole)[:, None]
        unsure = (side <= _NEARLY_STRAIGHT * a) | (((pole * fwd).sum(-1, keepdim=True) < 0) & (side <= _SLIGHTLY_BENT * a))
        n = torch.where(usable & unsure, _unit(fwd), n)
    x = (a * a - b * b + d * d) / (2 * d)
    new_knee = hip + u * x + n * (a * a - x * x).clamp_min(0).sqrt()
    new_ankle = hip + u * d
    turn = quat_between(_unit(knee - hip), _unit(new_knee - hip))
    q_hip = quat_mul(turn, g_hip)
    lower = quat_apply(turn, ankle - knee)
    q_knee = quat_mul(quat_between(_unit(lower), _unit(new_ankle - new_knee)), quat_mul(turn, g_knee))
    return q_hip, q_knee


def _runs(mask: np.ndarray, first: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(starts, stops)`` of the runs of True in a ``(N,)`` mask of concatenated clips, ``first``
    marking each clip's first frame (a run never crosses from one clip into the next)."""
    prev = np.concatenate(([False], mask[:-1])) & ~first
    nxt = np.concatenate((mask[1:], [False])) & ~np.concatenate((first[1:], [True]))
    return np.flatnonzero(mask & ~prev), np.flatnonzero(mask & ~nxt) + 1


def _blend_weight(held: np.ndarray, clip: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """``(N,)`` 1 on held frames, falling linearly to 0 over ``frames`` (per frame: its clip's)
    frames on each side, within each clip (``clip``: each frame's clip index)."""
    N = held.shape[0]
    gap = int(frames.max(initial=0)) + 2
    t = np.arange(N, dtype=np.float64) + clip * gap  # clips apart by more than a blend
    far = float(t[-1] + 2 * gap + 1) if N else 0.0
    before = np.maximum.accumulate(np.where(held, t, -far)) if N else t
    after = -np.maximum.accumulate(np.where(held, -t, -far)[::-1])[::-1] if N else t
    dist = np.minimum(t - before, after - t)
    return np.clip(1.0 - dist / (frames + 1), 0.0, None)


def _widened(mask: np.ndarray, first: np.ndarray) -> np.ndarray:
    """``mask`` ``(N,)`` with each run one frame longer on both sides, within each clip (``first``
    marks each clip's first frame)."""
    out = mask.copy()
    out[1:] |= mask[:-1] & ~first[1:]
    out[:-1] |= mask[1:] & ~first[1:]
    return out


def _pins(pos: np.ndarray, guide: np.ndarray, ankle: int, toe: int | None, s_ankle: int, s_toe: int | None,
          contact_ankle: np.ndarray, contact_toe: np.ndarray | None, first: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ankle's pinned position ``(N, 3)`` (its up component unused) and held mask ``(N,)``
    of one leg, over concatenated clips (``first`` marks each clip's first frame): over each
    contact run, the source's own path of the standing point (``guide`` ``(N, Js, 3)``, the
    source's positions scaled into the target's units) moved by one offset per run, the run's
    mean distance from the target's point, or, for a run that starts as the other point's
    ends, where that one left the foot (see the module docstring). Offsets along such a chain
    of runs add up (a cumulative sum), so no loop runs over runs."""
    N = pos.shape[0]
    # each contact one frame wider on both sides (within its clip): a speed by central
    # differences at a standing frame reads its neighbours, so they follow the source's path too
    contact_ankle = _widened(contact_ankle, first)
    contact_toe = _widened(contact_toe, first) if contact_toe is not None else None
    pinned = pos[:, ankle].copy()
    held = contact_ankle.copy()
    ga = guide[:, s_ankle]
    sa, ea = _runs(contact_ankle, first)
    kinds = [np.zeros(len(sa), dtype=bool)]  # True: a toe run
    starts, stops = [sa], [ea]
    if contact_toe is not None:
        foot = pos[:, toe] - pos[:, ankle]  # the foot's world rotation is kept by the IK
        gt = guide[:, s_toe]
        st, et = _runs(contact_toe & ~contact_ankle, first)
        kinds.append(np.ones(len(st), dtype=bool))
        starts.append(st)
        stops.append(et)
        held |= contact_toe
    s, e, toe_run = np.concatenate(starts), np.concatenate(stops), np.concatenate(kinds)
    order = np.argsort(s, kind="stable")
    s, e, toe_run = s[order], e[order], toe_run[order]
    if not len(s):
        return pinned, held
    # each run's own offset: the mean of (target point - guide) over its frames (prefix sums)
    da = np.concatenate((np.zeros((1, 3)), np.cumsum(pos[:, ankle] - ga, axis=0)))
    own = (da[e] - da[s]) / (e - s)[:, None]
    chained = np.zeros(len(s), dtype=bool)
    chained[1:] = (s[1:] == e[:-1]) & ~first[s[1:]]
    inc = np.zeros((len(s), 3))
    if contact_toe is not None:
        dt = np.concatenate((np.zeros((1, 3)), np.cumsum(pos[:, toe] - gt, axis=0)))
        own[toe_run] = ((dt[e] - dt[s]) / (e - s)[:, None])[toe_run]
        p = np.maximum(s - 1, 0)
        # heel lifts (an ankle run, then a toe run): the toe stays where the foot left it
        inc = np.where(toe_run[:, None], ga[p] + foot[p] - gt[p], gt[p] - foot[p] - ga[p])
    inc[~chained] = 0.0
    chain = np.cumsum(~chained) - 1  # each run's chain
    heads = np.flatnonzero(~chained)
    total = np.cumsum(inc, axis=0)
    offset = own[heads][chain] + total - total[heads][chain]
    # per frame: the run it is in
    run_of = np.full(N, -1)
    lengths = e - s
    idx = np.repeat(np.arange(len(s)), lengths)
    frames = ranges_to_rows(s, lengths)
    run_of[frames] = idx
    inside = run_of >= 0
    r = run_of[inside]
    at = ga[inside] + offset[r]
    if contact_toe is not None:
        on_toe = toe_run[r]
        at[on_toe] = (gt[inside] + offset[r] - foot[inside])[on_toe]
    pinned[inside] = at
    return pinned, held


def contact_heights(positions: torch.Tensor, points: list[int], leg: float, fps: float, up_axis: int) -> torch.Tensor:
    """``(P,)`` the median height of each foot point (joint indices ``points``) over its own contact
    frames in one clip's world ``positions`` ``(T, J, 3)`` (its lowest height where it never
    stands): how high that rig's ankle or toe is when the foot rests on the floor."""
    pts = positions[:, points][None]
    contact = foot_contacts(pts, torch.tensor([positions.shape[0]]), fps, torch.tensor([leg]), up_axis,
                            PIN_HEIGHT_RATIO, PIN_SPEED_RATIO)[0]
    h = pts[0, ..., up_axis]
    out = h.min(dim=0).values.clone()
    for p in range(len(points)):
        if contact[:, p].any():
            out[p] = h[contact[:, p], p].median()
    return out


def rig_heights(motions, legs: list[tuple[int, int, int, int | None]], up_axis: int = 1) -> torch.Tensor | None:
    """``(legs, 2)`` how high a rig's (ankle, toe) stand when its foot rests on the floor (its
    units): per clip :func:`contact_heights`, then the median over ``motions`` (clips of one
    skeleton; NaN for a leg without a toe). ``None`` without a clip."""
    per_clip = []
    points = [j for leg_ in legs for j in leg_[2:] if j is not None]
    for m in motions:
        pos = m.global_positions().to(torch.float64)
        leg = leg_length(m.skeleton, legs)
        h = dict(zip(points, contact_heights(pos, points, leg, float(m.fps), up_axis).tolist()))
        per_clip.append([[h[a], h[t] if t is not None else float("nan")] for _, _, a, t in legs])
    if not per_clip:
        return None
    return torch.tensor(per_clip, dtype=torch.float64).median(dim=0).values


def _slices(lengths: list[int]) -> list[slice]:
    out, at = [], 0
    for n in lengths:
        out.append(slice(at, at + n))
        at += n
    return out


@dataclass(frozen=True, eq=False)
class FeetMap:
    """How the target's legs follow the source's: what :func:`fix_feet` needs of the retargeting
    (a :class:`~torchsplice.ops.retarget.RetargetMap` holds all of it but the rig's heights), with
    the defaults :func:`fix_feet` always had.

    Attributes:
        legs: per leg ``(hip, knee, ankle, toe or None)`` of the target (knee the hip's child,
            ankle the knee's).
        source_legs: per leg ``(ankle, toe or None)`` of the source.
        scale: target units per source unit (the trajectory's scale).
        source_leg: the source's leg length (source units), for the contact thresholds.
        target_heights: ``(legs, 2)`` the target rig's contact heights of (ankle, toe), in its
            units; ``None`` takes the source's, scaled.
        up_axis: 0, 1 or 2.
        pelvis: the target joint whose translation or whose ancestors' carry the trajectory
            (raised or lowered).
        source_pelvis: the source's (the trajectory was scaled about the floor below its first frame).
    """

    legs: tuple[tuple[int, int, int, int | None], ...]
    source_legs: tuple[tuple[int, int | None], ...]
    scale: float
    source_leg: float
    target_heights: torch.Tensor | None = None
    up_axis: int = 1
    pelvis: int = 0
    source_pelvis: int = 0


def fix_feet(skeleton, rotations: torch.Tensor, root: torch.Tensor, translations: torch.Tensor | None,
             lengths: list[int], fps: list[float], source_positions: torch.Tensor,
             feet: FeetMap) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """Retargeted clips with their feet fixed (see the module docstring), batched over clips
    whose frames are concatenated (``N = sum(lengths)``).

    Args:
        skeleton: the target skeleton.
        rotations, root, translations: ``(N, J, 4)``, ``(N, 3)``, ``(N, J, 3)`` or ``None``: the
            retargeted clips' local rotations, root positions and joint translations.
        lengths, fps: each clip's frames and frame rate.
        source_positions: ``(N, Js, 3)`` the source clips' world positions (source units).
        feet: which joints are the legs, the pelvis and the up axis, on both rigs, the scale and
            the rig's heights (:class:`FeetMap`).

    Returns ``(rotations, root, translations)`` float64, the same shapes.
    """
    legs, source_legs, up_axis, scale = feet.legs, feet.source_legs, feet.up_axis, feet.scale
    sk = skeleton
    _check_legs(sk, legs)
    rot = rotations.to(torch.float64)
    root = root.to(torch.float64).clone()
    trans = translations.to(torch.float64).clone() if translations is not None else None
    offsets, parents = sk.offsets.to(torch.float64), sk.parents
    src = source_positions.to(torch.float64)
    spans = _slices(lengths)
    src_points = [j for a, t in source_legs for j in (a, t) if j is not None]
    contact_of, rest_src, per_frame = _source_contacts(src, spans, lengths, fps, src_points, feet.source_leg, up_axis)
    origin = src[[sl.start for sl in spans], feet.source_pelvis].clone()
    origin[:, up_axis] = 0.0
    origin = origin[per_frame]
    guide = origin[:, None] + (src - origin[:, None]) * scale  # the source in the target's units, scaled like the trajectory
    pos, glob = forward_kinematics(rot, root, offsets, parents, trans)
    targets, helds = _ankle_targets(pos, guide, src, spans, fps, legs, source_legs, contact_of, rest_src, src_points,
                                    per_frame, scale, feet.target_heights, up_axis)
    size = leg_length(sk, legs)
    up = torch.zeros(3, dtype=torch.float64)
    up[up_axis] = 1.0
    lift = _pelvis_lift(pos, targets, helds, legs, lengths, size, up_axis)[per_frame]
    drop = _pelvis_drop(pos, targets, legs, offsets, lift, up, spans, fps, up_axis)
    shift = (lift - drop)[:, None] * up
    if bool((shift != 0).any()):
        root = _shift_pelvis(sk, pos, glob, root, trans, shift, feet.pelvis)
    out = _solve_legs(rot, pos, glob, parents, legs, targets, size)
    return quat_normalize(out), root, trans


def _check_legs(sk, legs) -> None:
    """Each leg one chain of three joints: the knee the hip's child, the ankle the knee's."""
    for hip, knee, ankle, _ in legs:
        if sk.parents[knee] != hip or sk.parents[ankle] != knee:
            raise ValueError(f"leg {sk.names[hip]}-{sk.names[knee]}-{sk.names[ankle]} is not one chain of three joints")


def _source_contacts(src: torch.Tensor, spans: list[slice], lengths: list[int], fps: list[float], src_points: list[int],
                     source_leg: float, up_axis: int):
    """The source's contacts, clip by clip: ``{point: (N,) bool}`` of each foot point
    ``src_points``, ``(B, P)`` each point's resting height per clip (its median height while in
    contact, else its lowest) and ``(N,)`` each frame's clip."""
    B = len(lengths)
    counts = torch.tensor(lengths)
    # the source's contacts, clip by clip (padded), and each point's resting height per clip
    padded = torch.nn.utils.rnn.pad_sequence([src[sl][:, src_points] for sl in spans], batch_first=True)
    contacts = foot_contacts(padded, counts, torch.tensor(fps, dtype=torch.float64),
                             torch.full((B,), float(source_leg), dtype=torch.float64), up_axis, PIN_HEIGHT_RATIO,
                             PIN_SPEED_RATIO)
    valid = torch.arange(padded.shape[1])[None, :] < counts[:, None]
    h = padded[..., up_axis]  # (B, T, P)
    rest_src = torch.where(contacts, h, torch.full_like(h, float("nan"))).nanmedian(dim=1).values
    contacts = contacts[valid]  # (N, P), the clips' frames in order
    lowest = torch.where(valid[..., None], h, torch.full_like(h, float("inf"))).min(dim=1).values
    rest_src = torch.where(torch.isnan(rest_src), lowest, rest_src)  # a point that never stands: its lowest
    per_frame = torch.repeat_interleave(torch.arange(B), counts)  # each frame's clip
    contact_of = {j: contacts[:, k] for k, j in enumerate(src_points)}
    return contact_of, rest_src, per_frame


def _ankle_targets(pos, guide, src, spans, fps, legs, source_legs, contact_of, rest_src, src_points, per_frame,
                   scale, target_heights, up_axis):
    """Per leg, where its ankle should be ``(N, 3)`` (pinned on the floor plane where the source's
    foot stands, blended in and out; at the source's height above the floor) and the frames it is
    held ``(N,)``."""
    N = pos.shape[0]
    # where each ankle should be: pinned on the floor plane, at the source's height above floor
    first = np.zeros(N, dtype=bool)
    first[[sl.start for sl in spans]] = True
    clip_of = per_frame.numpy()
    blend = np.maximum(1, np.round(BLEND_SECONDS * np.asarray(fps, dtype=np.float64))).astype(np.int64)[clip_of]
    pos_np, guide_np = pos.numpy(), guide.numpy()
    targets, helds = [], []
    for k, ((_hip, _knee, ankle, toe), (s_ankle, s_toe)) in enumerate(zip(legs, source_legs)):
        use_toe = toe if s_toe is not None else None
        pinned, held = _pins(pos_np, guide_np, ankle, use_toe, s_ankle, s_toe, contact_of[s_ankle].numpy(),
                             contact_of[s_toe].numpy() if use_toe is not None else None, first)
        w = torch.from_numpy(_blend_weight(held, clip_of, blend))
        pinned, held = torch.from_numpy(pinned), torch.from_numpy(held)
        target = pos[:, ankle] + w[:, None] * (pinned - pos[:, ankle])
        # the height: the ankle and the toe each at least at the source's lift above its resting
        # height (the foot keeps the source's pitch, so on a rig whose foot rests otherwise one
        # of them decides, and the other stands a little higher)
        height = None
        for point_s, point_t, col in ((s_ankle, ankle, 0), (s_toe, use_toe, 1)):
            if point_t is None:
                continue
            rest_s = rest_src[:, src_points.index(point_s)][per_frame]
            rest_t = float(target_heights[k, col]) if target_heights is not None else rest_s * scale
            lift_h = rest_t + (src[:, point_s, up_axis] - rest_s) * scale  # where the point should be
            ankle_h = lift_h - (pos[:, point_t, up_axis] - pos[:, ankle, up_axis])  # the ankle that puts it there
            height = ankle_h if height is None else torch.maximum(height, ankle_h)
        target[:, up_axis] = height
        targets.append(target)
        helds.append(held)
    return targets, helds


def _pelvis_lift(pos, targets, helds, legs, lengths, size: float, up_axis: int) -> torch.Tensor:
    """``(B,)`` per clip, how much the pelvis is raised (or lowered): the median of what the
    standing feet lack (a rig whose hips hang lower from its pelvis stands lower); 0 where that is
    negligible or the feet never stand."""
    B = len(lengths)
    lack = torch.stack([t[:, up_axis] - pos[:, leg[2], up_axis] for t, leg in zip(targets, legs)], dim=1)
    standing = torch.stack(helds, dim=1)
    nan = float("nan")
    lift = torch.nn.utils.rnn.pad_sequence(list(torch.where(standing, lack, nan).split(lengths)), batch_first=True,
                                           padding_value=nan).reshape(B, -1).nanmedian(dim=1).values
    return torch.where(lift.abs() > _STILL * size, lift, torch.zeros_like(lift))  # NaN (never standing) too  # a clip on its own skeleton: as it is


def _pelvis_drop(pos, targets, legs, offsets, lift, up, spans, fps, up_axis: int) -> torch.Tensor:
    """``(N,)`` how much further the pelvis comes down where a leg is short of its target
    (after ``lift``), smoothed over :data:`BLEND_SECONDS` within each clip."""
    N = pos.shape[0]
    # reach: lower it more where a leg is short of its target
    drop = torch.zeros(N, dtype=torch.float64)
    for (hip, knee, ankle, _), target in zip(legs, targets):
        full = torch.clamp_min(_norm(pos[:, ankle] - pos[:, hip]),
                               float(offsets[knee].norm() + offsets[ankle].norm()) * _REACH * 0.999)
        v = target - pos[:, hip] - lift[:, None] * up
        vert = v[:, up_axis]
        horiz2 = (v * v).sum(-1) - vert * vert
        need = (-vert) - (full * full - horiz2).clamp_min(0).sqrt()  # the hip must come down by this
        drop = torch.maximum(drop, need.clamp_min(0))
    if bool((drop > 0).any()):
        for b, sl in enumerate(spans):
            if not bool((drop[sl] > 0).any()):
                continue
            blend = max(1, round(BLEND_SECONDS * float(fps[b])))
            k = 2 * blend + 1
            d = torch.nn.functional.max_pool1d(drop[sl][None, None], k, 1, blend)
            kernel = torch.ones(1, 1, k, dtype=torch.float64) / k
            drop[sl] = torch.nn.functional.conv1d(torch.nn.functional.pad(d, (blend, blend), mode="replicate"),
                                                  kernel)[0, 0]
    return drop


def _shift_pelvis(sk, pos, glob, root, trans, shift, pelvis: int) -> torch.Tensor:
    """Move the pelvis by ``shift`` ``(N, 3)``: through its own translation channels where they
    carry the trajectory, else the root (``trans`` and ``pos`` are updated in place); returns the
    root."""
    parents = sk.parents
    if trans is not None and pelvis != 0 and sk.translation_animated[pelvis]:
        # the pelvis's own channels carry the trajectory: move it in its parent's frame
        trans[:, pelvis] = trans[:, pelvis] + quat_apply(quat_conj(glob[:, parents[pelvis]]), shift)
        moved_joints = [pelvis, *sk.descendants(pelvis)]
    else:
        root = root + shift
        if trans is not None:
            trans[:, 0] = root
        moved_joints = list(range(sk.num_joints))
    pos[:, moved_joints] += shift[:, None]  # rotations unchanged: the joints below move with it
    return root


def _solve_legs(rot, pos, glob, parents, legs, targets, size: float) -> torch.Tensor:
    """The local rotations with each leg's hip and knee solved by :func:`two_bone_ik` onto its
    target (a leg already there keeps its rotations), the foot keeping its world rotation."""
    out = rot.clone()
    for (hip, knee, ankle, toe), target in zip(legs, targets):
        # the way the knee bends: the foot's forward (ankle to toe), else the source knee's side
        forward = pos[:, toe] - pos[:, ankle] if toe is not None else None
        q_hip, q_knee = two_bone_ik(pos[:, hip], pos[:, knee], pos[:, ankle], target, glob[:, hip], glob[:, knee],
                                    forward)
        parent = parents[hip]
        moved = (_norm(target - pos[:, ankle]) > _STILL * size)[:, None]  # else exactly as it was
        new = quat_mul(quat_conj(glob[:, parent]), q_hip) if parent >= 0 else q_hip
        out[:, hip] = torch.where(moved, new, rot[:, hip])
        out[:, knee] = torch.where(moved, quat_mul(quat_conj(q_hip), q_knee), rot[:, knee])
        # the foot keeps its world rotation
        out[:, ankle] = torch.where(moved, quat_mul(quat_conj(q_knee), glob[:, ankle]), rot[:, ankle])
    return out
