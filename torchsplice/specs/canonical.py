"""The canonical humanoid map: which joint of a skeleton is the pelvis, a shoulder, an elbow...

Retargeting (clips of one skeleton played on another) pairs joints by these names, whatever each
dataset calls them. A skeleton's map comes from its dataset spec's roles
(:class:`~torchsplice.specs.roles.SkeletonRoles`: named in a shipped spec, guessed by
``generic``) and its hierarchy:

- ``pelvis``: the root role (the joint carrying the trajectory); ``spine``: the spine chain
  from the pelvis role up, ``neck`` its last joint below the head, ``head``;
- ``clavicle_l/r``: a shoulder's parent when it is not on the spine (absent otherwise);
- ``shoulder_l/r``, ``wrist_l/r`` (the hands role), ``elbow_l/r``: the joint between shoulder
  and wrist furthest from both (CMU's zero-length helpers are never chosen);
- ``hip_l/r``, ``knee_l/r``, ``ankle_l/r`` (the feet role), ``toe_l/r`` (optional).

Fingers, twist bones and helper joints have no canonical name: retargeting folds them into
their mapped ancestor or holds them at rest. A skeleton without a joint the splice needs (hips,
knees, ankles, shoulders, elbows, wrists, a spine) is refused in one line naming what is
missing.
"""

from __future__ import annotations

from ..core.errors import SpecError
from .roles import SkeletonRoles, chain

__all__ = ["CANONICAL", "REQUIRED", "canonical_joints", "canonical_bones", "canonical_legs", "leg_length"]

CANONICAL = (
    "pelvis",
    "spine",
    "neck",
    "head",
    "clavicle_l",
    "clavicle_r",
    "shoulder_l",
    "shoulder_r",
    "elbow_l",
    "elbow_r",
    "wrist_l",
    "wrist_r",
    "hip_l",
    "hip_r",
    "knee_l",
    "knee_r",
    "ankle_l",
    "ankle_r",
    "toe_l",
    "toe_r",
)
"""Canonical joint names (``spine`` names the chain; the others one joint each)."""

REQUIRED = (
    "pelvis",
    "spine",
    "shoulder_l",
    "shoulder_r",
    "elbow_l",
    "elbow_r",
    "wrist_l",
    "wrist_r",
    "hip_l",
    "hip_r",
    "knee_l",
    "knee_r",
    "ankle_l",
    "ankle_r",
)
"""What a skeleton must have to be retargeted (and spliced across skeletons)."""


def _elbow(skeleton, shoulder: int, wrist: int) -> int | None:
    """The joint strictly between shoulder and wrist whose position splits the arm best: the one
    furthest from both ends (a zero-length helper is never chosen over a real joint)."""
    arm = chain(skeleton.parents, shoulder, wrist)
    if len(arm) < 3:
        return None
    rest, _ = skeleton.rest_positions()
    a, b = rest[shoulder], rest[wrist]
    best = max(arm[1:-1], key=lambda j: min(float((rest[j] - a).norm()), float((rest[j] - b).norm())))
    return best if float((rest[best] - a).norm()) > 0 and float((rest[best] - b).norm()) > 0 else None


def canonical_joints(roles: SkeletonRoles, skeleton, what: str = "the skeleton") -> dict[str, int | tuple[int, ...]]:
    """The canonical map of ``skeleton`` (bound ``roles``): canonical name -> joint index
    (``spine``: the chain, pelvis role first). Raises :class:`~torchsplice.core.errors.SpecError`
    naming ``what`` and every required joint it lacks, or saying that its bones have no length."""
    if not float(skeleton.offsets.abs().max()) > 0:  # every joint at one point: none can be told apart by place
        raise SpecError(
            f"{what}: every bone has zero length (all its rest OFFSETs are 0), so its joints have no "
            "rest pose to map onto another skeleton"
        )
    out: dict[str, int | tuple[int, ...]] = {"pelvis": roles.root, "spine": tuple(roles.spine)}
    spine = list(roles.spine)
    if roles.head is not None:
        out["head"] = roles.head
        below = [j for j in spine if j != roles.head and roles.head in skeleton.descendants(j)]
        if below:
            out["neck"] = below[-1]
    elif len(spine) > 1:
        out["neck"] = spine[-1]
    missing = []
    for side, k in (("l", 0), ("r", 1)):
        shoulder, hip, knee, ankle = roles.shoulders[k], roles.hips[k], roles.knees[k], roles.feet[k]
        out.update({f"shoulder_{side}": shoulder, f"hip_{side}": hip, f"knee_{side}": knee, f"ankle_{side}": ankle})
        parent = skeleton.parents[shoulder]
        if parent >= 0 and parent not in spine:
            out[f"clavicle_{side}"] = parent
        if roles.toes is not None:
            out[f"toe_{side}"] = roles.toes[k]
        if roles.hands is None:
            missing += [f"wrist_{side}", f"elbow_{side}"]
            continue
        wrist = roles.hands[k]
        out[f"wrist_{side}"] = wrist
        elbow = _elbow(skeleton, shoulder, wrist)
        if elbow is None:
            missing.append(f"elbow_{side}")
        else:
            out[f"elbow_{side}"] = elbow
    if not spine:
        missing.append("spine")
    if missing:
        raise SpecError(
            f"{what} cannot be retargeted: no {', '.join(missing)} (a humanoid needs hips, knees, ankles, "
            "a spine, shoulders, elbows and wrists)"
        )
    return {name: out[name] for name in CANONICAL if name in out}  # in canonical order


def canonical_bones(joints: dict) -> list[tuple[int, int]]:
    """``(joint, the canonical joint its bone points to)`` of a canonical map: the spine chain to
    the neck and head, each clavicle to its shoulder, shoulder to elbow, elbow to wrist, hip to
    knee, knee to ankle, ankle to toe (where the map has them)."""
    spine = [*joints["spine"]]
    for name in ("neck", "head"):
        if name in joints and joints[name] not in spine:
            spine.append(joints[name])
    bones = list(zip(spine, spine[1:]))
    for side in ("l", "r"):
        limb = [f"clavicle_{side}", f"shoulder_{side}", f"elbow_{side}", f"wrist_{side}"]
        leg = [f"hip_{side}", f"knee_{side}", f"ankle_{side}", f"toe_{side}"]
        for names in (limb, leg):
            have = [joints[n] for n in names if n in joints]
            bones += list(zip(have, have[1:]))
    return bones


def canonical_legs(joints: dict) -> tuple[tuple[int, int, int, int | None], ...]:
    """Per leg (left, right) of a canonical map: ``(hip, knee, ankle, toe or None)``."""
    return tuple((joints[f"hip_{s}"], joints[f"knee_{s}"], joints[f"ankle_{s}"], joints.get(f"toe_{s}")) for s in "lr")


def leg_length(skeleton, legs) -> float:
    """Hip to knee to ankle at rest, averaged over ``legs`` (:func:`canonical_legs`), in the
    skeleton's units."""
    rest, _ = skeleton.rest_positions()
    return sum(float((rest[k] - rest[h]).norm() + (rest[a] - rest[k]).norm()) for h, k, a, _ in legs) / len(legs)
