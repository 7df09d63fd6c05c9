"""Feet fixed after retargeting: each foot held where it stands while the source's foot stands,
by two-bone IK of the leg, and kept at the source's height above the floor.

Conventions: quaternions unit WXYZ, local to the parent; positions in the skeleton's units; the
up axis an index (Y = 1); the floor at height 0 of the up axis (every shipped dataset is captured
so). Shapes: ``T`` frames, ``J`` joints. Batched over frames; the Python loops run over the two
legs and over contact runs (a few a second), never over frames.

Why: retargeting carries rotations and scales the trajectory by leg length, but a target whose
legs hang otherwise from its pelvis (or whose feet are longer) puts its feet a little elsewhere
each frame, so a standing foot slides, and its foot joints sit at other heights above the
floor than its rig needs. :func:`fix_feet` corrects both:

- **Where a foot stands.** The source's contacts (:func:`~torchsplice.kinematics.contacts.foot_contacts`
  on its ankles and toes, :data:`PIN_HEIGHT_RATIO` and :data:`PIN_SPEED_RATIO`) are runs of
  frames. Over a run of the ankle, the target's ankle holds one floor position (the run's mean);
  over a run of the toe alone (the heel lifting), the toe holds one and the ankle follows the
  foot's own rotation about it. A run that starts while the other point is held starts where
  that one left the foot, so the hand-over does not jump. The pin blends in and out over
  :data:`BLEND_SECONDS` beyond each run.
- **How high.** Every frame, the target's toe (the ankle where a rig has no toe) is put at the
  source's toe height above its own contact height, times the leg-length scale, above the
  target's contact height (its own clips' where known, else the source's scaled): a foot that
  rests on the floor in the source rests on it in the target, whatever the two rigs' ankle and
  toe heights, and no foot goes lower than the source's does.
- **The pelvis's height.** The pelvis is raised or lowered by one amount for the clip, the
  median of what the standing feet lack (a rig whose hips hang lower below its pelvis stands
  lower), and lowered further where a leg still cannot reach its target (smoothly over
  :data:`BLEND_SECONDS`).

:func:`two_bone_ik` keeps bone lengths, the knee in the plane it bends in, and the foot's world
rotation (so the toes point as they did).
"""

from __future__ import annotations

from dataclasses import replace

import torch

from ..core.fk import forward_kinematics
from ..core.motion import Motion
from ..core.rotations import quat_apply, quat_between, quat_conj, quat_mul, quat_normalize
from ..kinematics.contacts import foot_contacts

__all__ = ["two_bone_ik", "fix_feet", "contact_heights", "rig_heights", "BLEND_SECONDS", "PIN_HEIGHT_RATIO", "PIN_SPEED_RATIO"]

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

_REACH = 0.9995
"""The fraction of a leg's full length that IK stretches it to (a straight knee is singular)."""


def _unit(v: torch.Tensor) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def two_bone_ik(hip: torch.Tensor, knee: torch.Tensor, ankle: torch.Tensor, target: torch.Tensor,
                g_hip: torch.Tensor, g_knee: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """New world rotations ``(N, 4)`` of a hip and its knee that bring the ankle (the knee's
    child) from ``ankle`` to ``target`` (positions ``(N, 3)``; ``g_hip``, ``g_knee`` the current
    world rotations ``(N, 4)``). The knee stays on the side it bends to; a target out of reach is
    approached along the same line (the leg straightens to :data:`_REACH`, or stays as
    straight as it is), one too close along
    it as far as the bones allow."""
    a = (knee - hip).norm(dim=-1, keepdim=True)
    b = (ankle - knee).norm(dim=-1, keepdim=True)
    to = target - hip
    reach = torch.maximum((a + b) * _REACH, (ankle - hip).norm(dim=-1, keepdim=True))  # no straighter than it is
    d = torch.minimum(to.norm(dim=-1, keepdim=True).clamp_min((a - b).abs() + 1e-9 * (a + b)), reach)
    u = _unit(to)
    pole = knee - hip
    pole = pole - (pole * u).sum(-1, keepdim=True) * u
    straight = pole.norm(dim=-1, keepdim=True) <= 1e-9 * a
    # a straight leg bends toward where its knee points now (the thigh's turn from the line)
    fallback = torch.linalg.cross(u, torch.roll(u, 1, dims=-1), dim=-1)
    n = _unit(torch.where(straight, fallback, pole))
    x = (a * a - b * b + d * d) / (2 * d)
    new_knee = hip + u * x + n * (a * a - x * x).clamp_min(0).sqrt()
    new_ankle = hip + u * d
    turn = quat_between(_unit(knee - hip), _unit(new_knee - hip))
    q_hip = quat_mul(turn, g_hip)
    lower = quat_apply(turn, ankle - knee)
    q_knee = quat_mul(quat_between(_unit(lower), _unit(new_ankle - new_knee)), quat_mul(turn, g_knee))
    return q_hip, q_knee


def _runs(mask: torch.Tensor) -> list[tuple[int, int]]:
    """``(start, stop)`` of each run of True in a ``(T,)`` bool mask."""
    m = mask.to(torch.int8)
    edges = torch.diff(torch.cat([m.new_zeros(1), m, m.new_zeros(1)]))
    return list(zip(torch.nonzero(edges == 1).flatten().tolist(), torch.nonzero(edges == -1).flatten().tolist()))


def _blend_weight(held: torch.Tensor, frames: int) -> torch.Tensor:
    """``(T,)`` 1 on held frames, falling linearly to 0 over ``frames`` frames on each side."""
    T = held.shape[0]
    t = torch.arange(T, dtype=torch.float64)
    far = torch.tensor(float(T + frames + 1), dtype=torch.float64)
    before = torch.cummax(torch.where(held, t, -far), dim=0).values  # the last held frame so far
    after = torch.cummax(torch.where(held, -t, -far).flip(0), dim=0).values.flip(0)  # minus the next one
    dist = torch.minimum(t - before, -after - t)
    return (1.0 - dist / (frames + 1)).clamp_min(0.0)


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
    for m in motions:
        pos = m.global_positions().to(torch.float64)
        hip, knee, ankle, _ = legs[0]
        leg = float((pos[0, knee] - pos[0, hip]).norm() + (pos[0, ankle] - pos[0, knee]).norm())
        points = [j for leg_ in legs for j in leg_[2:] if j is not None]
        h = dict(zip(points, contact_heights(pos, points, leg, float(m.fps), up_axis).tolist()))
        per_clip.append([[h[a], h[t] if t is not None else float("nan")] for _, _, a, t in legs])
    if not per_clip:
        return None
    return torch.tensor(per_clip, dtype=torch.float64).median(dim=0).values


def _pins(pos: torch.Tensor, guide: torch.Tensor, ankle: int, toe: int | None, s_ankle: int, s_toe: int | None,
          contact_ankle: torch.Tensor, contact_toe: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
    """The ankle's pinned position ``(T, 3)`` (its up component unused) and held mask ``(T,)``
    of one leg: over each contact run, the source's own path of the standing point (``guide``
    ``(T, Js, 3)``, the source's positions scaled into the target's units) moved by one offset
    per run, the run's mean distance from the target's point, or where the other point's pin
    left the foot (see the module docstring)."""
    pinned = pos[:, ankle].clone()
    held = contact_ankle.clone()
    foot = pos[:, toe] - pos[:, ankle] if toe is not None else None  # the foot's world rotation is kept
    events = [(s, e, "ankle") for s, e in _runs(contact_ankle)]
    if contact_toe is not None:
        events += [(s, e, "toe") for s, e in _runs(contact_toe & ~contact_ankle)]
        held = held | contact_toe
    last_end, last_at = -10, None  # where the ankle was when the last pin ended
    for s, e, kind in sorted(events):
        if kind == "ankle":
            path = guide[s:e, s_ankle]
            at = last_at if s == last_end else None  # toe, then the heel down: stay where the foot is
            offset = (at - guide[s - 1, s_ankle]) if at is not None else (pos[s:e, ankle] - path).mean(0)
            pinned[s:e] = path + offset
        else:
            path = guide[s:e, s_toe]
            at = last_at + foot[s - 1] if s == last_end else None  # the heel lifts: the toe stays
            offset = (at - guide[s - 1, s_toe]) if at is not None else (pos[s:e, toe] - path).mean(0)
            pinned[s:e] = path + offset - foot[s:e]
        last_end, last_at = e, pinned[e - 1].clone()
    return pinned, held


def fix_feet(motion: Motion, legs: list[tuple[int, int, int, int | None]], source_positions: torch.Tensor,
             source_legs: list[tuple[int, int | None]], scale: float, source_leg: float,
             target_heights: torch.Tensor | None = None, up_axis: int = 1, pelvis: int = 0,
             source_pelvis: int = 0) -> Motion:
    """``motion`` (a retargeted clip) with its feet fixed (see the module docstring).

    Args:
        motion: the clip on its target skeleton.
        legs: per leg ``(hip, knee, ankle, toe or None)`` of the target (knee the hip's child,
            ankle the knee's).
        source_positions: ``(T, Js, 3)`` the source clip's world positions (source units).
        source_legs: per leg ``(ankle, toe or None)`` of the source.
        scale: target units per source unit for this clip (the trajectory's scale).
        source_leg: the source's leg length (source units), for the contact thresholds.
        target_heights: ``(legs, 2)`` the target rig's contact heights of (ankle, toe), in its
            units; ``None`` takes the source's, scaled.
        up_axis: 0, 1 or 2; pelvis: the target joint whose translation or whose ancestors'
            carry the trajectory (lowered where a leg cannot reach); source_pelvis: the
            source's (the trajectory was scaled about the floor below its first frame).
    """
    sk = motion.skeleton
    for hip, knee, ankle, _ in legs:
        if sk.parents[knee] != hip or sk.parents[ankle] != knee:
            raise ValueError(f"leg {sk.names[hip]}-{sk.names[knee]}-{sk.names[ankle]} is not one chain of three joints")
    T = motion.num_frames
    rot = motion.rotations.to(torch.float64)
    root = motion.root_translation.to(torch.float64).clone()
    trans = motion.translations.to(torch.float64).clone() if motion.translations is not None else None
    offsets, parents = sk.offsets.to(torch.float64), sk.parents
    src = source_positions.to(torch.float64)
    src_points = [j for a, t in source_legs for j in (a, t) if j is not None]
    src_h = contact_heights(src, src_points, source_leg, motion.fps, up_axis)
    heights_of = dict(zip(src_points, src_h.tolist()))
    contacts = foot_contacts(src[:, src_points][None], torch.tensor([T]), motion.fps, torch.tensor([source_leg]),
                             up_axis, PIN_HEIGHT_RATIO, PIN_SPEED_RATIO)[0]
    contact_of = {j: contacts[:, k] for k, j in enumerate(src_points)}
    blend = max(1, round(BLEND_SECONDS * float(motion.fps)))
    origin = src[0, source_pelvis].clone()
    origin[up_axis] = 0.0
    guide = origin + (src - origin) * scale  # the source in the target's units, scaled like the trajectory
    pos, glob = forward_kinematics(rot, root, offsets, parents, trans)
    # where each ankle should be: pinned on the floor plane, at the source's height above floor
    targets, helds = [], []
    for k, ((hip, knee, ankle, toe), (s_ankle, s_toe)) in enumerate(zip(legs, source_legs)):
        use_toe = toe if s_toe is not None else None
        pinned, held = _pins(pos, guide, ankle, use_toe, s_ankle, s_toe, contact_of[s_ankle],
                             contact_of[s_toe] if use_toe is not None else None)
        w = _blend_weight(held, blend)[:, None]
        target = pos[:, ankle] + w * (pinned - pos[:, ankle])
        # the height: the toe (else the ankle) at the source's lift above its contact height
        lead_s, lead_t, col = (s_toe, use_toe, 1) if use_toe is not None else (s_ankle, ankle, 0)
        rest_h = float(target_heights[k, col]) if target_heights is not None else heights_of[lead_s] * scale
        lead_h = rest_h + (src[:, lead_s, up_axis] - heights_of[lead_s]) * scale
        below = pos[:, lead_t, up_axis] - pos[:, ankle, up_axis]  # the lead point's height over the ankle
        target[:, up_axis] = lead_h - below
        targets.append(target)
        helds.append(held)
    # the pelvis's height: raised or lowered by one amount for the clip, the median of what the
    # standing feet lack (a rig whose hips hang lower from its pelvis stands lower)
    up = torch.zeros(3, dtype=torch.float64)
    up[up_axis] = 1.0
    lack = torch.cat([(t[:, up_axis] - pos[:, leg[2], up_axis])[h] for t, h, leg in zip(targets, helds, legs)])
    lift = float(lack.median()) if lack.numel() else 0.0
    size = float((pos[0, legs[0][1]] - pos[0, legs[0][0]]).norm() + (pos[0, legs[0][2]] - pos[0, legs[0][1]]).norm())
    lift = lift if abs(lift) > _STILL * size else 0.0  # a clip on its own skeleton is left as it is
    # reach: lower it more where a leg is short of its target
    drop = torch.zeros(T, dtype=torch.float64)
    for (hip, knee, ankle, _), target in zip(legs, targets):
        full = ((pos[0, knee] - pos[0, hip]).norm() + (pos[0, ankle] - pos[0, knee]).norm()) * _REACH * 0.999
        full = torch.maximum(full, (pos[:, ankle] - pos[:, hip]).norm(dim=-1))
        v = target - pos[:, hip] - lift * up
        vert = v[:, up_axis]
        horiz2 = (v * v).sum(-1) - vert * vert
        need = (-vert) - (full * full - horiz2).clamp_min(0).sqrt()  # the hip must come down by this
        drop = torch.maximum(drop, need.clamp_min(0))
    if lift != 0.0 or bool((drop > 0).any()):
        k = 2 * blend + 1
        drop = torch.nn.functional.max_pool1d(drop[None, None], k, 1, blend)[0, 0]
        kernel = torch.ones(1, 1, k, dtype=torch.float64) / k
        drop = torch.nn.functional.conv1d(torch.nn.functional.pad(drop[None, None], (blend, blend),
                                                                  mode="replicate"), kernel)[0, 0]
        shift = (lift - drop)[:, None] * up
        if trans is not None and pelvis != 0 and sk.translation_animated[pelvis]:
            # the pelvis's own channels carry the trajectory: move it in its parent's frame
            trans[:, pelvis] = trans[:, pelvis] + quat_apply(quat_conj(glob[:, parents[pelvis]]), shift)
        else:
            root = root + shift
            if trans is not None:
                trans[:, 0] = root
        pos, glob = forward_kinematics(rot, root, offsets, parents, trans)
    out = rot.clone()
    for (hip, knee, ankle, _), target in zip(legs, targets):
        q_hip, q_knee = two_bone_ik(pos[:, hip], pos[:, knee], pos[:, ankle], target, glob[:, hip], glob[:, knee])
        parent = parents[hip]
        moved = ((target - pos[:, ankle]).norm(dim=-1) > _STILL * size)[:, None]  # else exactly as it was
        new = quat_mul(quat_conj(glob[:, parent]), q_hip) if parent >= 0 else q_hip
        out[:, hip] = torch.where(moved, new, rot[:, hip])
        out[:, knee] = torch.where(moved, quat_mul(quat_conj(q_hip), q_knee), rot[:, knee])
        # the foot keeps its world rotation
        out[:, ankle] = torch.where(moved, quat_mul(quat_conj(q_knee), glob[:, ankle]), rot[:, ankle])
    dtype = motion.rotations.dtype
    return replace(motion, rotations=quat_normalize(out).to(dtype), root_translation=root.to(dtype),
                   translations=None if trans is None else trans.to(dtype))
