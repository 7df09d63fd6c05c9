"""A body of capsules around any humanoid skeleton, to tell when a hand or forearm is inside it.

No body mesh is needed: the body is sized from the skeleton itself. Each capsule is a segment
between two points of the skeleton's joints (each end a blend of two joints, so it follows
the motion frame by frame) with a radius, a fixed share of the character's height along its
bones (:func:`~torchsplice.ops.retarget.character_height`'s measure: leg length plus pelvis to
head, whatever the rest pose). Joints come from the canonical humanoid map
(:func:`~torchsplice.specs.canonical.canonical_joints`), so the body is built alike for Bandai
Namco, CMU (both namings), LAFAN1, SMPL-22 and the sample.

Capsules (:data:`CAPSULES`; ends and radius, ``H`` the height along the bones):

==============  =============================================================  ======
capsule         from, to                                                       radius
==============  =============================================================  ======
torso_l, _r     halfway from the pelvis to a hip, to 0.4 of the way from the   0.068 H
                chest (the arms' parent joint) to that side's shoulder
pelvis          hip to hip                                                     0.070 H
head            the head joint, to 0.6 of the neck-to-head bone beyond it      0.065 H
upper_arm_l, r  shoulder to elbow                                              0.030 H
forearm_l, _r   elbow to the hand's end (0.35 of the forearm past the wrist)   0.025 H
thigh_l, _r     hip to knee                                                    0.050 H
shin_l, _r      knee to ankle                                                  0.032 H
==============  =============================================================  ======

On SMPL-22's standard skeleton (``H`` 1.476 m, a body about 1.7 m tall) that is a torso 10 cm
deep on each side of its axis, a thigh 7.4 cm and a forearm 3.7 cm in radius: a little slimmer
than an adult's (chest depth about 0.13 of the stature), so that a hand resting on the body is
not counted inside it. The probes are the forearms (with the hand): a probe is inside a body
part when its axis enters that part's capsule deeper than :data:`INSIDE_MARGIN` (:data:`OBSTACLES`: the torso, pelvis, head,
thighs and shins; not the arms, which touch each other in claps and folded arms).

Conventions: positions ``(..., J, 3)`` in the skeleton's units, any up axis (capsules are
round, so the measure does not depend on it).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..core.skeleton import Skeleton
from ..specs.canonical import canonical_joints, canonical_legs, leg_length
from ..specs.roles import SkeletonRoles

__all__ = ["CAPSULES", "PROBES", "OBSTACLES", "INSIDE_MARGIN", "Body", "body_of", "capsule_ends", "segment_closest",
           "segment_distance", "inside_depth"]

CAPSULES = {  # name: ((joint a, joint b, share from a to b) for each end, radius in character heights)
    "torso_l": (("pelvis", "hip_l", 0.5), ("chest", "shoulder_l", 0.4), 0.068),
    "torso_r": (("pelvis", "hip_r", 0.5), ("chest", "shoulder_r", 0.4), 0.068),
    "pelvis": (("hip_l", "hip_l", 0.0), ("hip_r", "hip_r", 0.0), 0.070),
    "head": (("head", "head", 0.0), ("neck", "head", 1.6), 0.065),
    "upper_arm_l": (("shoulder_l", "shoulder_l", 0.0), ("elbow_l", "elbow_l", 0.0), 0.030),
    "upper_arm_r": (("shoulder_r", "shoulder_r", 0.0), ("elbow_r", "elbow_r", 0.0), 0.030),
    "forearm_l": (("elbow_l", "elbow_l", 0.0), ("elbow_l", "wrist_l", 1.35), 0.025),
    "forearm_r": (("elbow_r", "elbow_r", 0.0), ("elbow_r", "wrist_r", 1.35), 0.025),
    "thigh_l": (("hip_l", "hip_l", 0.0), ("knee_l", "knee_l", 0.0), 0.050),
    "thigh_r": (("hip_r", "hip_r", 0.0), ("knee_r", "knee_r", 0.0), 0.050),
    "shin_l": (("knee_l", "knee_l", 0.0), ("ankle_l", "ankle_l", 0.0), 0.032),
    "shin_r": (("knee_r", "knee_r", 0.0), ("ankle_r", "ankle_r", 0.0), 0.032),
}
"""The body's capsules (see the module docstring): each end at ``a + share (b - a)`` of two
canonical joints (``chest``: the joint the arms hang from; ``neck``: the chest where the map
has no neck), the radius a share of the height along the bones."""
PROBES = ("forearm_l", "forearm_r")
"""The capsules whose entering the body counts: the forearms, hands included."""
OBSTACLES = ("torso_l", "torso_r", "pelvis", "head", "thigh_l", "thigh_r", "shin_l", "shin_r")
"""The body parts a probe may not enter."""
INSIDE_MARGIN = 0.02
"""How deep (in heights along the bones: 3 cm on SMPL-22) a probe's axis must be inside an
obstacle to count as inside it: a hand resting on the body, or brushing past it, is not. Of
the 109 real clips of ``../shared/mocap``, 9 then have a frame with a hand inside the torso,
pelvis or a thigh, most of them hands held against the belly or hips (CMU's 131, a Bandai Namco
walk that clasps them in front)."""


@dataclass(frozen=True)
class Body:
    """A skeleton's capsules (see the module docstring).

    Attributes:
        names: the capsules' names (:data:`CAPSULES` order).
        radii: ``(C,)`` float64, in the skeleton's units.
        height: the height along the bones they are shares of (the skeleton's units).
        probes, obstacles: indices into ``names`` of :data:`PROBES` and :data:`OBSTACLES`.
        margin: :data:`INSIDE_MARGIN` in the skeleton's units.
        end_joints, end_shares: ``(2C, 2)`` joint indices ``(a, b)`` and ``(2C,)`` shares: end
            ``k`` is ``pos[a] + share (pos[b] - pos[a])``, capsule ``c`` ends ``2c`` and ``2c + 1``
            (:func:`capsule_ends`).
    """

    names: tuple[str, ...]
    radii: torch.Tensor
    height: float
    probes: tuple[int, ...]
    obstacles: tuple[int, ...]
    margin: float
    end_joints: torch.Tensor
    end_shares: torch.Tensor

    def sizes(self) -> dict[str, float]:
        """Each capsule's radius, ``height`` and ``margin`` (the skeleton's units): what the body states."""
        return {"height": self.height, "margin": self.margin, **{n: float(r) for n, r in zip(self.names, self.radii)}}


def body_of(skeleton: Skeleton, roles: SkeletonRoles, what: str = "the skeleton") -> Body:
    """The :class:`Body` of ``skeleton`` (bound ``roles``); a skeleton that is not a humanoid is
    refused in one line naming ``what`` (:func:`~torchsplice.specs.canonical.canonical_joints`)."""
    joints = dict(canonical_joints(roles, skeleton, what))
    joints["chest"] = skeleton.parents[joints["clavicle_l"] if "clavicle_l" in joints else joints["shoulder_l"]]
    joints.setdefault("neck", joints["chest"])
    joints.setdefault("head", joints["spine"][-1])
    rest, _ = skeleton.rest_positions()
    spine = [joints["pelvis"], *joints["spine"]]
    if joints["head"] != spine[-1]:
        spine.append(joints["head"])
    height = leg_length(skeleton, canonical_legs(joints)) + sum(
        float((rest[b] - rest[a]).norm()) for a, b in zip(spine, spine[1:]))
    end_joints = torch.zeros(2 * len(CAPSULES), 2, dtype=torch.long)
    end_shares = torch.zeros(2 * len(CAPSULES), dtype=torch.float64)
    for c, (first, second, _) in enumerate(CAPSULES.values()):
        for e, (a, b, share) in enumerate((first, second)):
            end_joints[2 * c + e] = torch.tensor([joints[a], joints[b]])
            end_shares[2 * c + e] = share
    names = tuple(CAPSULES)
    radii = torch.tensor([r for *_, r in CAPSULES.values()], dtype=torch.float64) * height
    return Body(names, radii, height, tuple(names.index(n) for n in PROBES),
                tuple(names.index(n) for n in OBSTACLES), INSIDE_MARGIN * height, end_joints, end_shares)


def capsule_ends(positions: torch.Tensor, body: Body) -> tuple[torch.Tensor, torch.Tensor]:
    """Both ends ``(..., C, 3)`` of every capsule of ``body`` at joint positions ``(..., J, 3)``."""
    a, b = positions[..., body.end_joints[:, 0], :], positions[..., body.end_joints[:, 1], :]
    e = a + body.end_shares.to(positions.dtype)[:, None] * (b - a)
    return e[..., 0::2, :], e[..., 1::2, :]


def segment_closest(p0: torch.Tensor, p1: torch.Tensor, q0: torch.Tensor, q1: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(s, t)`` ``(...)``: where segments ``p0 p1`` and ``q0 q1`` (``(..., 3)``, broadcast) come
    closest, as shares along each (``p0 + s (p1 - p0)``, ``q0 + t (q1 - q0)``), in closed form:
    the closest points of the two lines, each parameter clamped to its segment and the other's
    then chosen again for it (parallel and zero-length segments included)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, b = (d1 * d1).sum(-1), (d2 * d2).sum(-1), (d1 * d2).sum(-1)
    c, f = (d1 * r).sum(-1), (d2 * r).sum(-1)
    eps = 1e-12 * (a + e).clamp_min(1e-300)
    one = torch.ones_like(a)
    pa, pe = a > eps, e > eps  # which segments have a length
    denom = a * e - b * b
    s = torch.where(pa & pe & (denom > eps * (a + e)), (b * f - c * e) / torch.where(denom > 0, denom, one), 0.0)
    s = torch.where(pa & ~pe, -c / torch.where(pa, a, one), s).clamp(0.0, 1.0)
    t = torch.where(pe, (b * s + f) / torch.where(pe, e, one), 0.0)
    s = torch.where(pa & (t < 0.0), (-c / torch.where(pa, a, one)).clamp(0.0, 1.0), s)
    s = torch.where(pa & (t > 1.0), ((b - c) / torch.where(pa, a, one)).clamp(0.0, 1.0), s)
    return s, t.clamp(0.0, 1.0)


def segment_distance(p0: torch.Tensor, p1: torch.Tensor, q0: torch.Tensor, q1: torch.Tensor) -> torch.Tensor:
    """``(...)`` the shortest distance between segments ``p0 p1`` and ``q0 q1`` (``(..., 3)``,
    broadcast), at :func:`segment_closest`'s points."""
    s, t = segment_closest(p0, p1, q0, q1)
    return ((p0 + (p1 - p0) * s[..., None]) - (q0 + (q1 - q0) * t[..., None])).norm(dim=-1)


def inside_depth(positions: torch.Tensor, body: Body) -> torch.Tensor:
    """``(..., P, O)`` how deep each probe's axis goes inside each obstacle (``r_o - distance``
    between the axes, the skeleton's units; 0 or less: not inside) at joint positions
    ``(..., J, 3)``; ``P`` and ``O`` in :attr:`Body.probes` and :attr:`Body.obstacles` order."""
    a, b = capsule_ends(positions, body)
    probes, obstacles = list(body.probes), list(body.obstacles)
    pa, pb = a[..., probes, None, :], b[..., probes, None, :]
    oa, ob = a[..., None, obstacles, :], b[..., None, obstacles, :]
    return body.radii[obstacles].to(positions.dtype) - segment_distance(pa, pb, oa, ob)
