"""Measures of retargeting: how faithfully a clip played on another skeleton keeps its motion.

Conventions: positions in each skeleton's own units, converted to centimetres where figures
of two rigs are compared (their specs' units); each spec's up axis (Y for every shipped one;
a source's world turned onto the target's where they differ); angles in degrees. Every
measure is batched over frames.

- :func:`round_trip_errors`: a clip retargeted onto another skeleton and back, the mean distance
  of its mapped joints from where they were, over the character's height.
- :func:`bone_angles`: per mapped bone, the mean angle between its world direction in the
  source and in the result.
- :func:`feet_figures`: foot skate (the evaluation's measure) of source and result in cm/s, the
  source's scaled like the trajectory, and how much further below its resting height the
  result's lowest ankle and toe go than the source's (each rig rests its feet at its own heights).
- :func:`wrist_spread`: the acting wrist's range of motion in the chest's frame (the RMS
  distance from its mean place, rotation-invariant, so rigs with other joint axes compare),
  over arm length.
"""

from __future__ import annotations

import torch

from ..core.rotations import quat_apply, quat_conj
from ..core.fk import forward_kinematics
from ..ops.feet import contact_heights
from ..ops.retarget import RetargetMap, character_height, retarget_motions
from ..ops.units import centimetres as units_centimetres
from ..specs.canonical import canonical_bones, canonical_joints
from .metrics import foot_skate_stats

__all__ = ["round_trip_errors", "bone_angles", "feet_figures", "wrist_spread", "centimetres"]


def centimetres(spec) -> float:
    """Centimetres per unit of a spec's units (NaN when unknown)."""
    return units_centimetres(spec.units)


def round_trip_errors(motions, there: RetargetMap, back: RetargetMap, roles, fix_feet: bool = False,
                      heights_there=None, heights_back=None) -> list[float]:
    """Per clip of ``motions`` (on ``there.source``), the mean distance of its mapped joints
    (every canonical joint but the spine chain's inner ones) after a round trip ``there`` and
    ``back``, over the character's height (``heights_*``: the rigs' foot heights, see
    :func:`~torchsplice.ops.retarget.retarget_motion`)."""
    joints = canonical_joints(roles, there.source)
    mapped = [j for name, j in joints.items() if name != "spine"]
    height = character_height(there.source, joints)
    out = retarget_motions(retarget_motions(motions, there, fix_feet, heights_there), back, fix_feet, heights_back)
    errs = []
    for a, b in zip(motions, out):
        err = (b.global_positions().double()[:, mapped] - a.global_positions().double()[:, mapped]).norm(dim=-1)
        errs.append(float(err.mean()) / height)
    return errs


def bone_angles(motion, result, rmap: RetargetMap, target_roles) -> dict[str, float]:
    """``"A->B"`` (target joint names) -> the mean angle (degrees) between the bone's world
    direction in ``result`` and its source bone's in ``motion`` (bones of no length in either
    rig are left out)."""
    pa, pb = motion.global_positions().double(), result.global_positions().double()
    pa = quat_apply(rmap.turn.expand(*pa.shape[:-1], 4), pa)  # onto the target's up axis
    ct = canonical_joints(target_roles, rmap.target)
    out = {}
    rest_s, _ = rmap.source.rest_positions()
    rest_t, _ = rmap.target.rest_positions()
    for x, y in canonical_bones(ct):
        if float((rest_t[y] - rest_t[x]).norm()) < 1e-9 or float((rest_s[rmap.joints[y]] - rest_s[rmap.joints[x]]).norm()) < 1e-9:
            continue  # a bone of no length in either rig (a spine joint paired twice, CMU's helpers): no direction
        da, db = pa[:, rmap.joints[y]] - pa[:, rmap.joints[x]], pb[:, y] - pb[:, x]
        cos = (da * db).sum(-1) / (da.norm(dim=-1) * db.norm(dim=-1)).clamp_min(1e-12)
        out[f"{rmap.target.names[x]}->{rmap.target.names[y]}"] = float(torch.rad2deg(torch.acos(cos.clamp(-1, 1))).mean())
    return out


def feet_figures(motion, result, rmap: RetargetMap, source_roles, target_roles, cm_source: float,
                 cm_target: float, target_heights=None) -> dict[str, float]:
    """``skate_source`` (cm/s, scaled like the trajectory), ``skate`` (cm/s), and ``lower`` (cm):
    how much further below its resting height (its height when its foot stands: the clip's own
    for the source, ``target_heights`` ``(2, 2)`` for the result where given, else the source's
    scaled) the result's lowest ankle or toe goes than the source's does; 0 or less is none."""
    scale_cm = rmap.scale * cm_target / cm_source  # target cm per source cm
    src = float(foot_skate_stats([motion], source_roles).speed[0]) * cm_source * scale_cm
    got = float(foot_skate_stats([result], target_roles).speed[0]) * cm_target
    up, up_t = source_roles.up_axis, target_roles.up_axis
    pa, pb = motion.global_positions().double(), result.global_positions().double()
    lower = 0.0
    for k, (ankle, toe) in enumerate(rmap.source_legs):
        hip, knee, t_ankle, t_toe = rmap.legs[k]
        points = [(ankle, t_ankle, 0)] + ([(toe, t_toe, 1)] if toe is not None and t_toe is not None else [])
        for js, jt, col in points:
            leg = float((pa[0, ankle] - pa[0, rmap.joints[knee]]).norm() + (pa[0, rmap.joints[knee]] - pa[0, rmap.joints[hip]]).norm())
            rest_s = float(contact_heights(pa, [js], leg, float(motion.fps), up)[0])
            rest_t = float(target_heights[k, col]) if target_heights is not None else rest_s * rmap.scale
            sink_s = (rest_s - float(pa[:, js, up].min())) * cm_source * scale_cm
            sink_t = (rest_t - float(pb[:, jt, up_t].min())) * cm_target
            lower = max(lower, sink_t - sink_s)
    return {"skate_source": src, "skate": got, "lower": lower}


def wrist_spread(motion, roles, side: int, frames=None) -> float:
    """The RMS distance of wrist ``side`` (0 left, 1 right) from its mean place in the chest's
    frame (the shoulder's parent), over the arm's length (shoulder to elbow to wrist); over the
    clip's ``frames`` (indices) where given."""
    sk = motion.skeleton
    joints = canonical_joints(roles, sk)
    s = "lr"[side]
    wrist, elbow, shoulder = joints[f"wrist_{s}"], joints[f"elbow_{s}"], joints[f"shoulder_{s}"]
    chest = sk.parents[joints.get(f"clavicle_{s}", shoulder)]
    pos, glob = forward_kinematics(motion.rotations.double(), motion.root_translation.double(), sk.offsets, sk.parents,
                                   None if motion.translations is None else motion.translations.double())
    local = quat_apply(quat_conj(glob[:, chest]), pos[:, wrist] - pos[:, chest])
    if frames is not None:
        local = local[torch.as_tensor(frames, dtype=torch.long)]
    spread = float((local - local.mean(0)).norm(dim=-1).pow(2).mean().sqrt())
    rest, _ = sk.rest_positions()
    arm = float((rest[elbow] - rest[shoulder]).norm() + (rest[wrist] - rest[elbow]).norm())
    return spread / arm
