"""The sample's skeleton: a 22-joint human (Y up, centimetres, facing +Z, about 175 cm tall) and
the leg geometry the gait is solved on.

The rest pose stands upright with the arms hanging straight down and every joint's local axes
aligned with the world (X left, Y up, Z forward). :data:`JOINT_NAMES` lists the joints in
topological order and :data:`JOINT` maps a name to its index; the leg geometry constants
(:data:`THIGH`, :data:`SHIN`, :data:`HIP_OFFSET`, :data:`ANKLE_HEIGHT`, :data:`BALL`,
:data:`HEEL`, :data:`REACH`) are in centimetres, read off the joint table.
"""

from __future__ import annotations

import numpy as np
import torch

from ..core.skeleton import Skeleton

__all__ = ["sample_skeleton", "JOINT_NAMES", "JOINT", "THIGH", "SHIN", "HIP_OFFSET", "ANKLE_HEIGHT", "BALL", "HEEL",
           "REACH"]

_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
_JOINT_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")

# name, parent, offset in the parent's frame (cm). Rest pose: standing, arms straight down.
_JOINTS: tuple[tuple[str, str | None, tuple[float, float, float]], ...] = (
    ("Hips", None, (0.0, 98.0, 0.0)),
    ("LeftUpLeg", "Hips", (9.0, -5.0, 0.0)),
    ("LeftLeg", "LeftUpLeg", (0.0, -44.0, 0.0)),
    ("LeftFoot", "LeftLeg", (0.0, -42.0, 0.0)),
    ("LeftToe", "LeftFoot", (0.0, -4.0, 13.0)),
    ("RightUpLeg", "Hips", (-9.0, -5.0, 0.0)),
    ("RightLeg", "RightUpLeg", (0.0, -44.0, 0.0)),
    ("RightFoot", "RightLeg", (0.0, -42.0, 0.0)),
    ("RightToe", "RightFoot", (0.0, -4.0, 13.0)),
    ("Spine", "Hips", (0.0, 8.0, 0.0)),
    ("Spine1", "Spine", (0.0, 12.0, 0.0)),
    ("Spine2", "Spine1", (0.0, 12.0, 0.0)),
    ("Neck", "Spine2", (0.0, 16.0, 0.0)),
    ("Head", "Neck", (0.0, 10.0, 0.0)),
    ("LeftShoulder", "Spine2", (3.0, 12.0, 0.0)),
    ("LeftArm", "LeftShoulder", (15.0, 0.0, 0.0)),
    ("LeftForeArm", "LeftArm", (0.0, -30.0, 0.0)),
    ("LeftHand", "LeftForeArm", (0.0, -26.0, 0.0)),
    ("RightShoulder", "Spine2", (-3.0, 12.0, 0.0)),
    ("RightArm", "RightShoulder", (-15.0, 0.0, 0.0)),
    ("RightForeArm", "RightArm", (0.0, -30.0, 0.0)),
    ("RightHand", "RightForeArm", (0.0, -26.0, 0.0)),
)
# End sites: toe tips, top of the head, fingertips (in the parent joint's frame, cm).
_END_SITES: tuple[tuple[str, tuple[float, float, float]], ...] = (
    ("LeftToe", (0.0, 0.0, 6.0)),
    ("RightToe", (0.0, 0.0, 6.0)),
    ("Head", (0.0, 19.0, 0.0)),
    ("LeftHand", (0.0, -18.0, 0.0)),
    ("RightHand", (0.0, -18.0, 0.0)),
)
JOINT_NAMES = tuple(j[0] for j in _JOINTS)
JOINT = {n: i for i, n in enumerate(JOINT_NAMES)}

# Leg geometry (cm), read off the table above.
THIGH = 44.0
SHIN = 42.0
HIP_OFFSET = {0: np.array([9.0, -5.0, 0.0]), 1: np.array([-9.0, -5.0, 0.0])}  # left, right
ANKLE_HEIGHT = 7.0  # ankle above the floor with the foot flat (98 - 5 - 44 - 42)
BALL = np.array([0.0, -4.0, 13.0])  # ball of the foot (the toe joint) in the foot frame
HEEL = np.array([0.0, -ANKLE_HEIGHT, -4.0])  # heel contact point in the foot frame
REACH = 0.997 * (THIGH + SHIN)  # the pelvis never rises so high that a leg exceeds this


def sample_skeleton() -> Skeleton:
    """The sample's 22-joint human skeleton (Y up, cm, facing +Z, about 175 cm tall).

    Rest pose: standing upright, arms hanging straight down at the sides, every joint's local
    axes aligned with the world (X left, Y up, Z forward); the root ``Hips`` rests 98 cm above
    the floor, the ankles 7 cm, the top of the head (an end site) at 175 cm.

    Joints, in topological order: ``Hips``; ``LeftUpLeg LeftLeg LeftFoot LeftToe``;
    ``RightUpLeg RightLeg RightFoot RightToe``; ``Spine Spine1 Spine2 Neck Head``;
    ``LeftShoulder LeftArm LeftForeArm LeftHand``; ``RightShoulder RightArm RightForeArm
    RightHand``. ``Hips`` has the channels ``Xposition Yposition Zposition Zrotation Xrotation
    Yrotation``, every other joint ``Zrotation Xrotation Yrotation``. End sites hang from the
    toes, the head and the hands (one per leaf joint).

    Returns:
        A new :class:`Skeleton` (offsets ``(22, 3)`` float64, end-site offsets ``(5, 3)``).
    """
    names = JOINT_NAMES
    parents = tuple(-1 if p is None else JOINT[p] for _, p, _ in _JOINTS)
    offsets = torch.tensor([o for _, _, o in _JOINTS], dtype=torch.float64)
    channels = tuple(_ROOT_CHANNELS if p is None else _JOINT_CHANNELS for _, p, _ in _JOINTS)
    ends = sorted(_END_SITES, key=lambda e: JOINT[e[0]])
    return Skeleton(
        names=names,
        parents=parents,
        offsets=offsets,
        channels=channels,
        end_site_parents=tuple(JOINT[n] for n, _ in ends),
        end_site_offsets=torch.tensor([o for _, o in ends], dtype=torch.float64),
    )
