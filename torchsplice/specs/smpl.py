"""The built-in SMPL body skeleton: 22 joints (SMPL without hands), a retargeting target.

Conventions: joints in SMPL's and HumanML3D's order (:data:`SMPL22_NAMES`, parents
:data:`SMPL22_PARENTS`); metres; Y up; facing +Z; the character's left on +X. Its spec is the
shipped ``smpl22`` (``datasets_spec/smpl22.toml``).

The rest pose: each bone along HumanML3D's raw offset direction for it (legs and arms
straight down, feet forward), except the head, which stands straight up from the neck
(HumanML3D points it forward, which would tilt the chest's frame), and the bones that branch
from the pelvis (hips, spine) and from the chest (neck, collars): the body holds those rigid
as SMPL's does, hips below and behind the pelvis and collars above the chest, so they are
where the format's motions hold them, measured in the frame of the pelvis (across the hips,
up the spine) and of the chest (across the collars, up the neck) on the sample clip the
format's repository ships (``HumanML3D/new_joints/012314.npy``: rigid there to 2e-7 m). Bone
lengths are HumanML3D's standard skeleton, measured on the same clip (every bone constant to
5e-7 m), rounded to 0.1 mm. Retargeting aligns rest poses per bone, so world motion does not
depend on the rest pose otherwise.
"""

from __future__ import annotations

import torch

from ..core.skeleton import Skeleton

__all__ = ["SMPL22", "SMPL22_NAMES", "SMPL22_PARENTS", "SMPL22_MIRROR", "smpl22_skeleton"]

SMPL22 = "smpl22"
"""The name of the built-in target and of its spec."""

SMPL22_NAMES = (
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
)
SMPL22_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)

# (direction, length in metres) of each joint's offset from its parent
_BONES = (
    ((0, 0, 0), 0.0),
    ((1, 0, 0), 0.1031),
    ((-1, 0, 0), 0.1099),
    ((0, 1, 0), 0.1316),  # hips, spine1
    ((0, -1, 0), 0.3936),
    ((0, -1, 0), 0.3902),
    ((0, 1, 0), 0.1432),  # knees, spine2
    ((0, -1, 0), 0.4324),
    ((0, -1, 0), 0.4256),
    ((0, 1, 0), 0.0574),  # ankles, spine3
    ((0, 0, 1), 0.1434),
    ((0, 0, 1), 0.1494),
    ((0, 1, 0), 0.2194),  # feet, neck
    ((1, 0, 0), 0.1375),
    ((-1, 0, 0), 0.1434),
    ((0, 1, 0), 0.1030),  # collars, head (up)
    ((0, -1, 0), 0.1316),
    ((0, -1, 0), 0.1230),  # shoulders
    ((0, -1, 0), 0.2568),
    ((0, -1, 0), 0.2631),  # elbows
    ((0, -1, 0), 0.2660),
    ((0, -1, 0), 0.2699),  # wrists
)
# the bones branching from the pelvis and the chest, as the format's motions hold them (see above)
_BRANCHES = {
    1: (0.0563, -0.0826, -0.0250),
    2: (-0.0642, -0.0856, -0.0250),
    3: (0.0, 0.1316, 0.0),
    12: (0.0, 0.2194, 0.0),
    13: (0.0697, 0.1175, -0.0151),
    14: (-0.0740, 0.1219, -0.0151),
}
_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")
_END_SITES = (
    (15, (0.0, 0.1, 0.0)),
    (20, (0.0, -0.08, 0.0)),
    (21, (0.0, -0.08, 0.0)),
    (10, (0.0, 0.0, 0.05)),
    (11, (0.0, 0.0, 0.05)),
)


SMPL22_MIRROR = (0, 2, 1, 3, 5, 4, 6, 8, 7, 9, 11, 10, 12, 14, 13, 15, 17, 16, 19, 18, 21, 20)
"""Each joint's counterpart on the other side (itself on the midline)."""


def smpl22_skeleton(mirrored: bool = False) -> Skeleton:
    """The SMPL 22-joint skeleton (see the module docstring): offsets ``(22, 3)`` float64 in metres.

    ``mirrored``: its mirror image (each joint's offset is its counterpart's, X negated), the body
    a mirrored copy of a motion stands on (HumanML3D's ``M`` copies: left and right bones swap
    lengths); same names and parents."""
    offsets = torch.tensor(
        [_BRANCHES.get(j, [c * length for c in d]) for j, (d, length) in enumerate(_BONES)], dtype=torch.float64
    )
    if mirrored:
        offsets = offsets[list(SMPL22_MIRROR)] * torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64)
    ends = sorted(_END_SITES)
    return Skeleton(
        names=SMPL22_NAMES,
        parents=SMPL22_PARENTS,
        offsets=offsets,
        channels=tuple(_ROOT_CHANNELS if p < 0 else _CHANNELS for p in SMPL22_PARENTS),
        end_site_parents=tuple(j for j, _ in ends),
        end_site_offsets=torch.tensor([o for _, o in ends], dtype=torch.float64),
    )
