"""Retargeting: a clip of one humanoid skeleton played on another, analytically.

Conventions: quaternions unit WXYZ, local to the parent; lengths in each skeleton's own units;
each skeleton's up axis that of its spec (Y for every shipped one): a result has the target's,
the source's world turned onto it by :func:`~torchsplice.core.rotations.up_axis_turn` (a Z-up
clip played on a Y-up rig stands up, and walks where the usual Z-up to Y-up exchange puts it). Both skeletons' rest poses are their
BVH zero poses (every local rotation the identity), whatever shape that is (T-pose, A-pose, or
Bandai Namco's and LAFAN1's poses).

The method, with global rotations ``G`` and the joint map ``m`` (target joint -> source joint):

- **Rest alignment per bone.** For each mapped joint, ``A`` is the world rotation taking the
  source's rest bone (from the joint to the next joint of the canonical map, see
  :func:`~torchsplice.specs.canonical.canonical_bones`; a joint off the map, its first mapped
  child) onto the target's: the nearest mapped ancestor's ``A`` composed with the smallest
  rotation left between the two directions (a swing, so that twist is carried as it is, and
  the way a rig faces at rest is carried down its chains); the pelvis and the chest are
  aligned by two directions (across the hips or shoulders, and up), so their turn about the
  spine is kept. A joint with no bone to align (or unmapped) takes its nearest mapped
  ancestor's ``A``.
- **Globals.** ``G_t(j) = U G_s(m(j)) A(j)^-1`` (``U`` the turn between the up axes, the
  identity when they agree; ``G_t(j) = G_s(m(j)) A(j)^-1`` below): with both rest poses at identity globals this
  is ``G_s(t) G_s(ref)^-1 G_t(rest)``, ``ref`` being the source posed into the target's rest
  shape, so each mapped target bone points where its source bone points. An unmapped target
  joint (an extra spine or neck joint, a finger) holds its rest pose: its local rotation is
  the identity, and its mapped children absorb the difference (stated per joint in
  :attr:`RetargetMap.held`). Source joints without a target (CMU's fingers, a second neck
  joint) are folded into their mapped ancestors (:attr:`RetargetMap.folded`).
- **Trajectory.** The pelvis's world position is scaled by the ratio of leg lengths (hip to
  knee to ankle, averaged over both legs), about the floor below the first frame's pelvis.
- **Feet** (on by default): held where the source's stand, at the source's height above the
  floor, by two-bone IK of the legs and the pelvis's height (:mod:`torchsplice.ops.feet`).

Joints are mapped by canonical name (:mod:`torchsplice.specs.canonical`) and, beyond those, by
equal names with equal parents' names, so that a skeleton retargeted onto itself is the
identity (twist bones and fingers included). Everything is batched over frames (no loop over
frames; the loops run over joints).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..core.errors import MotionError
from ..core.fk import forward_kinematics
from ..core.motion import Motion
from ..core.rotations import quat_apply, quat_between, quat_conj, quat_mul, quat_normalize, rotmat_to_quat, up_axis_turn
from ..core.skeleton import Skeleton
from ..specs.canonical import canonical_bones, canonical_joints, canonical_legs
from ..specs.canonical import leg_length as canonical_leg_length
from ..specs.roles import chain as joint_chain
from ..specs.roles import SkeletonRoles
from . import feet

__all__ = ["RetargetMap", "retarget_map", "retarget_motion", "retarget_motions", "leg_length", "character_height"]


@dataclass(frozen=True)
class RetargetMap:
    """How one skeleton's joints drive another's (see the module docstring).

    Attributes:
        source, target: the skeletons.
        joints: target joint -> source joint, for every mapped target joint.
        align: ``(Jt, 4)`` float64, ``A`` of each target joint (its nearest mapped ancestor's where unmapped).
        held: target joints held at their rest pose (no source joint).
        folded: source joints with no target joint (their motion goes to their mapped ancestors).
        pelvis: ``(target, source)`` pelvis joints; scale: target leg length / source leg length.
        up_axis: the target's up axis, 0, 1 or 2 (the results' and the feet's).
        turn: ``(4,)`` float64, the turn from the source's up axis to the target's
            (:func:`~torchsplice.core.rotations.up_axis_turn`), applied to the source's world.
        legs: per leg (left, right) the target's ``(hip, knee, ankle, toe or None)``.
        source_legs: per leg the source's ``(ankle, toe or None)``; source_leg: its leg length.
    """

    source: Skeleton
    target: Skeleton
    joints: dict[int, int]
    align: torch.Tensor
    held: tuple[int, ...]
    folded: tuple[int, ...]
    pelvis: tuple[int, int]
    scale: float
    up_axis: int
    legs: tuple[tuple[int, int, int, int | None], ...]
    source_legs: tuple[tuple[int, int | None], ...]
    source_leg: float
    turn: torch.Tensor


def _unit(v: torch.Tensor) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def _frame(across: torch.Tensor, up: torch.Tensor) -> torch.Tensor:
    """``(3, 3)`` orthonormal frame (columns): ``up``, then ``across`` made perpendicular to it."""
    y = up / up.norm()
    x = across - (across @ y) * y
    x = x / x.norm().clamp_min(1e-12)
    return torch.stack([x, y, torch.linalg.cross(x, y)], dim=1)


def leg_length(skeleton: Skeleton, joints: dict) -> float:
    """Hip to knee to ankle at rest, averaged over both legs of canonical map ``joints`` (the
    skeleton's units)."""
    return canonical_leg_length(skeleton, canonical_legs(joints))


def character_height(skeleton: Skeleton, joints: dict) -> float:
    """The character's height along its bones: leg length plus pelvis to head (the skeleton's
    units), whatever its rest pose (a rig lying along X at rest measures as standing)."""
    rest, _ = skeleton.rest_positions()
    chain = [joints["pelvis"], *joints["spine"]]
    if "head" in joints and joints["head"] != chain[-1]:
        chain.append(joints["head"])
    return leg_length(skeleton, joints) + sum(float((rest[b] - rest[a]).norm()) for a, b in zip(chain, chain[1:]))


def retarget_map(source: Skeleton, source_roles: SkeletonRoles, target: Skeleton, target_roles: SkeletonRoles,
                 source_name: str = "the source skeleton", target_name: str = "the target skeleton") -> RetargetMap:
    """The joint map and rest alignment from ``source`` to ``target`` (see the module docstring)."""
    cs = canonical_joints(source_roles, source, source_name)
    ct = canonical_joints(target_roles, target, target_name)
    pairs: dict[int, int] = {}
    for name, jt in ct.items():
        if name == "spine" or name not in cs:
            continue
        pairs[int(jt)] = int(cs[name])
    # the spine chains: ends to ends, the joints between by their place in the chain (by index:
    # measured on the shipped rigs, it carries the spine's bend better than by length, since CMU's
    # chains hold zero-length helpers)
    st, ss = list(ct["spine"]), list(cs["spine"])
    for k, jt in enumerate(st):
        if jt not in pairs:
            pairs[jt] = ss[round(k * (len(ss) - 1) / max(len(st) - 1, 1))]
    # beyond the canonical joints, equal names under equal parent names (twist bones, fingers, the
    # whole skeleton when it is the same one)
    index = {n: j for j, n in enumerate(source.names)}
    used = set(pairs.values())
    for jt, name in enumerate(target.names):
        js = index.get(name)
        if jt in pairs or js is None or js in used:
            continue
        pt, ps = target.parents[jt], source.parents[js]
        if (pt < 0) == (ps < 0) and (pt < 0 or target.names[pt] == source.names[ps]):
            pairs[jt] = js
            used.add(js)
    rest_s, _ = source.rest_positions()
    rest_t, _ = target.rest_positions()
    inverse = {js: jt for jt, js in pairs.items()}
    # The pelvis, and the joint the arms hang from (the chest), by two directions each: across
    # (the hips, the shoulders) and up (to the head). Every other mapped bone by the smallest
    # rotation left once its nearest aligned ancestor's alignment is applied, so that the way a
    # rig faces at rest is carried down its chains (no stray twist about a bone).
    frames: dict[int, torch.Tensor] = {}
    head_t = ct.get("head", ct["spine"][-1])
    head_s = pairs.get(head_t, cs.get("head", cs["spine"][-1]))
    chest = target.parents[ct["shoulder_l"]] if "clavicle_l" not in ct else target.parents[ct["clavicle_l"]]
    for top, left, right in ((ct["pelvis"], "hip_l", "hip_r"), (chest, "shoulder_l", "shoulder_r")):
        if top not in pairs or top == head_t:
            continue
        f_t = _frame(rest_t[ct[right]] - rest_t[ct[left]], rest_t[head_t] - rest_t[top])
        f_s = _frame(rest_s[cs[right]] - rest_s[cs[left]], rest_s[head_s] - rest_s[pairs[top]])
        frames[top] = rotmat_to_quat(f_t @ f_s.T)
    bone_of = {a: b for a, b in canonical_bones(ct)}
    align = torch.zeros(target.num_joints, 4, dtype=torch.float64)
    align[:, 0] = 1.0
    for jt in range(target.num_joints):  # parents before children
        p = target.parents[jt]
        while p >= 0 and p not in pairs:
            p = target.parents[p]
        base = align[p] if p >= 0 else align[jt]
        if jt not in pairs:
            align[jt] = base
            continue
        if jt in frames:
            align[jt] = frames[jt]
            continue
        child = bone_of.get(jt)
        if child is None or child not in pairs:
            kids = [c for c in target.children(jt) if c in pairs]
            child = kids[0] if kids else None
        if child is not None:
            d_s, d_t = rest_s[pairs[child]] - rest_s[pairs[jt]], rest_t[child] - rest_t[jt]
            if d_s.norm() > 1e-9 and d_t.norm() > 1e-9:
                align[jt] = quat_mul(quat_between(_unit(quat_apply(base, d_s)), _unit(d_t)), base)
                continue
        align[jt] = base
    held = tuple(j for j in range(target.num_joints) if j not in pairs)
    folded = tuple(j for j in range(source.num_joints) if j not in inverse)
    source_leg = leg_length(source, cs)
    scale = leg_length(target, ct) / source_leg
    # toes where both skeletons have them
    legs = tuple((h, k, a, t if s_t is not None else None)
                 for (h, k, a, t), (_, _, _, s_t) in zip(canonical_legs(ct), canonical_legs(cs)))
    source_legs = tuple((a, t if l_t is not None else None)
                        for (_, _, a, t), (_, _, _, l_t) in zip(canonical_legs(cs), canonical_legs(ct)))
    return RetargetMap(source, target, pairs, align, held, folded, (int(ct["pelvis"]), int(cs["pelvis"])), scale,
                       int(target_roles.up_axis), legs, source_legs, source_leg,
                       up_axis_turn(int(source_roles.up_axis), int(target_roles.up_axis)))


def retarget_motion(motion: Motion, rmap: RetargetMap, fix_feet: bool = True,
                    target_heights: torch.Tensor | None = None) -> Motion:
    """``motion`` (on ``rmap.source``) played on ``rmap.target`` (see the module docstring); the
    result has the target skeleton, the source's frame rate and name, and its dtype.

    With ``fix_feet``, the feet are then held where the source's stand and kept at the source's
    height above the floor (:func:`torchsplice.ops.feet.fix_feet`; ``target_heights`` ``(2, 2)``
    the target rig's contact heights of (ankle, toe) per leg, in its units, where known)."""
    return retarget_motions([motion], rmap, fix_feet, target_heights)[0]


def retarget_motions(motions, rmap: RetargetMap, fix_feet: bool = True,
                     target_heights: torch.Tensor | None = None) -> list[Motion]:
    """:func:`retarget_motion` of each clip of ``motions`` (all on ``rmap.source``), computed
    together: the clips' frames are concatenated, so the loops over joints run once per call."""
    motions = list(motions)
    if not motions:
        return []
    short = [m.num_frames < 3 for m in motions]
    if fix_feet and any(short) and not all(short):  # too short for contacts: their feet left as they are
        done = dict(zip([i for i, s in enumerate(short) if not s],
                        retarget_motions([m for m, s in zip(motions, short) if not s], rmap, True, target_heights)))
        done.update(zip([i for i, s in enumerate(short) if s],
                        retarget_motions([m for m, s in zip(motions, short) if s], rmap, False)))
        return [done[i] for i in range(len(motions))]
    for m in motions:
        if m.skeleton is not rmap.source and not m.skeleton.same_topology(rmap.source):
            raise MotionError(f"clip {m.name!r} is not on the retargeting map's source skeleton")
    src, tgt = rmap.source, rmap.target
    lengths = [m.num_frames for m in motions]
    cat = lambda xs: torch.cat([x.to(torch.float64) for x in xs])  # noqa: E731
    rot = cat([m.rotations for m in motions])
    has_trans = [m.translations is not None for m in motions]
    if any(has_trans) and not all(has_trans):
        raise MotionError("clips of one skeleton either all have joint translations or none do")
    trans = cat([m.translations for m in motions]) if all(has_trans) else None
    pos, glob = forward_kinematics(rot, cat([m.root_translation for m in motions]), src.offsets, src.parents, trans)
    if float(rmap.turn[0]) < 1.0:  # the source's world turned onto the target's up axis
        pos = quat_apply(rmap.turn.expand_as(glob), pos)
        glob = quat_mul(rmap.turn.expand_as(glob), glob)
    T, J = rot.shape[0], tgt.num_joints
    g_t = torch.zeros(T, J, 4, dtype=torch.float64)
    local = torch.zeros(T, J, 4, dtype=torch.float64)
    inv_align = quat_conj(rmap.align)
    for j in range(J):  # parents before children (the skeleton's order)
        p = tgt.parents[j]
        if j in rmap.joints:
            g_t[:, j] = quat_mul(glob[:, rmap.joints[j]], inv_align[j].expand(T, 4))
            local[:, j] = g_t[:, j] if p < 0 else quat_mul(quat_conj(g_t[:, p]), g_t[:, j])
        else:  # held at rest
            local[:, j] = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=torch.float64)
            g_t[:, j] = local[:, j] if p < 0 else g_t[:, p]
    local = quat_normalize(local)
    # the trajectory: each clip's source pelvis path, scaled about the floor below its first frame
    pt, ps = rmap.pelvis
    starts = torch.tensor([0, *lengths[:-1]]).cumsum(0)
    origin = pos[starts, ps].clone()
    origin[:, rmap.up_axis] = 0.0
    origin = torch.repeat_interleave(origin, torch.tensor(lengths), dim=0)
    pelvis = origin + (pos[:, ps] - origin) * rmap.scale
    chain = joint_chain(tgt.parents, 0, pt)  # root ... pelvis
    translations = tgt.offsets.to(torch.float64).expand(T, J, 3).clone() if tgt.has_joint_translations else None
    if translations is not None and pt != 0 and tgt.translation_animated[pt]:
        # the trajectory on the pelvis's own channels (Bandai Namco: the root stays put): the
        # joints above it where the source's are (or at rest), the pelvis's translation placed
        root = (origin + (pos[:, rmap.joints[0]] - origin) * rmap.scale if 0 in rmap.joints  # scaled as the pelvis is
                else torch.zeros(T, 3, dtype=torch.float64))
        above = root
        for j in chain[1:-1]:
            above = above + quat_apply(g_t[:, tgt.parents[j]], tgt.offsets[j].expand(T, 3))
        translations[:, pt] = quat_apply(quat_conj(g_t[:, tgt.parents[pt]]), pelvis - above)
    else:  # the root's position that puts the pelvis there, from the new rotations
        root = pelvis.clone()
        for j in chain[:0:-1]:  # the pelvis up to, not including, the root
            root = root - quat_apply(g_t[:, tgt.parents[j]], tgt.offsets[j].expand(T, 3))
    if translations is not None:
        translations[:, 0] = root
    if fix_feet and min(lengths) >= 3:
        feet_map = feet.FeetMap(rmap.legs, rmap.source_legs, rmap.scale, rmap.source_leg, target_heights=target_heights,
                                up_axis=rmap.up_axis, pelvis=pt, source_pelvis=ps)
        local, root, translations = feet.fix_feet(tgt, local, root, translations, lengths, [float(m.fps) for m in motions],
                                                  pos, feet_map)
    parts = zip(local.split(lengths), root.split(lengths),
                translations.split(lengths) if translations is not None else [None] * len(lengths))
    return [Motion(skeleton=tgt, rotations=r.to(m.rotations.dtype), root_translation=x.to(m.rotations.dtype),
                   translations=None if t is None else t.to(m.rotations.dtype), fps=m.fps, name=m.name, source=m.source,
                   role=m.role, labels=dict(m.labels)) for m, (r, x, t) in zip(motions, parts)]
