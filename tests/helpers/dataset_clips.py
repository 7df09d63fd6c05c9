"""Records and clips the torchsplice.data tests build their databases from
(``tests/data/conftest.py``): a database shaped like the splice job's output, and small
skeletons with random clips."""

from __future__ import annotations

import numpy as np
import torch

from torchsplice.core.motion import Motion
from torchsplice.core.skeleton import Skeleton

ALL_FEATURES = ("rotations", "root_translation", "translations", "positions", "global_rotations", "velocities")
SPLICED_COLUMNS = {"locomotion": "str", "action": "str", "method": "str", "cost": "float", "crop": "int"}


def spliced_records(motions):
    """(motion, extra, frame_extra) of a database shaped like the splice job's output.

    Three input clips (role locomotion/action) and 3 x 3 spliced clips with extra columns and
    a per-frame ``action_frame``; one spliced clip is cut to 40 frames.
    """
    by = {m.name: m for m in motions}
    records = []
    for name in ("walk_straight", "jog", "wave"):
        records.append((by[name], {}, {}))
    styles = {"walk_straight": "elderly", "walk_curve": "proud"}  # jog carries no style label
    for i, loco in enumerate(("walk_straight", "walk_curve", "jog")):
        for j, act in enumerate(("wave", "punch", "carry_box")):
            lm, am = by[loco], by[act]
            T = min(lm.num_frames, am.num_frames)
            if (i, j) == (2, 2):
                T = 40
            rot = lm.rotations[:T].clone()
            rot[:, 11:] = am.rotations[:T, 11:]  # some upper body from the action
            labels = {"content": act}
            if loco in styles:
                labels["style"] = styles[loco]
            m = Motion(lm.skeleton, rot, lm.root_translation[:T].clone(), 30.0, name=f"{loco}+{act}",
                       source="splice", role="spliced", labels=labels)
            extra = {"locomotion": loco, "action": act, "method": "splice" if j < 2 else "naive",
                     "cost": float(i * 3 + j), "crop": j}
            frames = {"action_frame": np.arange(T, dtype=np.float32) * 0.5 + i}
            records.append((m, extra, frames))
    return records


CH6 = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
CH3 = ("Zrotation", "Xrotation", "Yrotation")


def animated_skeleton() -> Skeleton:
    """Five joints, one non-root joint with animated translation (stored ``translations``)."""
    return Skeleton(
        names=["Pelvis", "Spine", "Head", "LLeg", "RLeg"], parents=[-1, 0, 1, 0, 0],
        offsets=[[0, 90, 0], [0, 10, 0], [0, 50, 0], [10, -5, 0], [-10, -5, 0]],
        channels=[CH6, CH6, CH3, CH3, CH3],
    )


def chain_skeleton() -> Skeleton:
    return Skeleton(names=["A", "B", "C"], parents=[-1, 0, 1], offsets=[[0, 0, 0], [0, 1, 0], [0, 1, 0.5]],
                    channels=[CH6, CH3, CH3])


def random_clip(sk: Skeleton, T: int, name: str, seed: int) -> Motion:
    g = torch.Generator().manual_seed(seed)
    J = sk.num_joints
    rot = torch.nn.functional.normalize(torch.randn(T, J, 4, generator=g), dim=-1)
    root = torch.randn(T, 3, generator=g) * 10
    trans = None
    if sk.has_joint_translations:
        trans = sk.offsets.float().expand(T, J, 3).clone()
        trans[:, 1] += torch.randn(T, 3, generator=g)
        trans[:, 0] = root
    return Motion(sk, rot, root, 24.0, trans, name=name, role="locomotion")
