"""The built-in SMPL body skeleton: 22 joints (SMPL without hands), a retargeting target.

Conventions: joints in SMPL's and HumanML3D's order (:data:`SMPL22_NAMES`, parents
:data:`SMPL22_PARENTS`); metres; Y up; facing +Z; the character's left on +X. Its spec is the
shipped ``smpl22`` (``datasets_spec/smpl22.toml``).

The rest pose: each bone along HumanML3D's raw offset direction for it (legs and arms
straight down, hips, collars lateral, feet forward), except the head, which stands straight
up from the neck (HumanML3D points it forward, which would tilt the chest's frame); bone
lengths are HumanML3D's standard skeleton, measured on the sample clip its repository ships
(``HumanML3D/new_joints/012314.npy``: every bone constant to 5e-7 m), rounded to 0.1 mm.
The rest pose matters only to the local rotations stored: retargeting aligns rest poses per
bone, so world motion does not depend on it.
"""

from __future__ import annotations

import torch

from ..core.skeleton import Skeleton

__all__ = ["SMPL22", "SMPL22_NAMES", "SMPL22_PARENTS", "smpl22_skeleton"]

SMPL22 = "smpl22"
"""The name of the built-in target and of its spec."""

SMPL22_NAMES = ("pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
                "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
                "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist")
SMPL22_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)

# (direction, length in metres) of each joint's offset from its parent
_BONES = (
    ((0, 0, 0), 0.0),
    ((1, 0, 0), 0.1031), ((-1, 0, 0), 0.1099), ((0, 1, 0), 0.1316),       # hips, spine1
    ((0, -1, 0), 0.3936), ((0, -1, 0), 0.3902), ((0, 1, 0), 0.1432),      # knees, spine2
    ((0, -1, 0), 0.4324), ((0, -1, 0), 0.4256), ((0, 1, 0), 0.0574),      # ankles, spine3
    ((0, 0, 1), 0.1434), ((0, 0, 1), 0.1494), ((0, 1, 0), 0.2194),        # feet, neck
    ((1, 0, 0), 0.1375), ((-1, 0, 0), 0.1434), ((0, 1, 0), 0.1030),       # collars, head (up)
    ((0, -1, 0), 0.1316), ((0, -1, 0), 0.1230),                           # shoulders
    ((0, -1, 0), 0.2568), ((0, -1, 0), 0.2631),                           # elbows
    ((0, -1, 0), 0.2660), ((0, -1, 0), 0.2699),                           # wrists
)
_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")
_END_SITES = ((15, (0.0, 0.1, 0.0)), (20, (0.0, -0.08, 0.0)), (21, (0.0, -0.08, 0.0)), (10, (0.0, 0.0, 0.05)),
              (11, (0.0, 0.0, 0.05)))


def smpl22_skeleton() -> Skeleton:
    """The SMPL 22-joint skeleton (see the module docstring): offsets ``(22, 3)`` float64 in metres."""
    offsets = torch.tensor([[c * length for c in d] for d, length in _BONES], dtype=torch.float64)
    ends = sorted(_END_SITES)
    return Skeleton(names=SMPL22_NAMES, parents=SMPL22_PARENTS, offsets=offsets,
                    channels=tuple(_ROOT_CHANNELS if p < 0 else _CHANNELS for p in SMPL22_PARENTS),
                    end_site_parents=tuple(j for j, _ in ends),
                    end_site_offsets=torch.tensor([o for _, o in ends], dtype=torch.float64))
