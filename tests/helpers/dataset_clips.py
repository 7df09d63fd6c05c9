"""Records and clips the tests build their databases from: a database shaped like the splice
job's output (``tests/data/conftest.py``), and small skeletons with random clips (the data and
store tests)."""

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


def chain_skeleton(J: int = 3, bone: float = 1.0, prefix: str = "J", animated: bool = False) -> Skeleton:
    """A chain J0 <- J1 <- ... with one End Site; ``animated`` gives every joint position channels."""
    return Skeleton(
        names=[f"{prefix}{j}" for j in range(J)],
        parents=[-1] + list(range(J - 1)),
        offsets=[[0.0, 0.0, 0.0]] + [[0.0, bone, 0.1 * j] for j in range(1, J)],
        channels=[CH6] + [CH6 if animated else ("Yrotation", "Xrotation", "Zrotation")] * (J - 1),
        end_site_parents=[J - 1],
        end_site_offsets=[[0.0, bone / 2, 0.0]],
    )


def branching_skeleton() -> Skeleton:
    """Five joints, two branches, three end sites, animated non-root translation on one joint."""
    return Skeleton(
        names=["Pelvis", "Spine", "Head", "Left Leg", "Right Leg"],
        parents=[-1, 0, 1, 0, 0],
        offsets=[[0, 90, 0], [0, 10, 0], [0, 50, 0], [10, -5, 0], [-10, -5, 0]],
        channels=[CH6, CH6, ("Xrotation", "Yrotation", "Zrotation"), CH3, CH3],
        end_site_parents=[2, 3, 4],
        end_site_offsets=[[0, 10, 0], [0, -80, 5], [0, -80, 5]],
    )


def random_clip(sk: Skeleton, T: int, name: str, seed: int = 0, dtype=torch.float64, fps: float = 30.0,
                role: str = "", labels: dict | None = None, source: str = "") -> Motion:
    g = torch.Generator().manual_seed(seed)
    J = sk.num_joints
    rot = torch.nn.functional.normalize(torch.randn(T, J, 4, generator=g, dtype=torch.float64), dim=-1)
    root = torch.randn(T, 3, generator=g, dtype=torch.float64) * 10
    trans = None
    if sk.has_joint_translations:
        trans = sk.offsets.expand(T, J, 3).clone()
        animated = torch.tensor(sk.translation_animated)
        trans[:, animated] += torch.randn(T, int(animated.sum()), 3, generator=g, dtype=torch.float64)
        trans[:, 0] = root
    return Motion(sk, rot.to(dtype), root.to(dtype), fps, None if trans is None else trans.to(dtype),
                  name=name, source=source or f"/data/{name}.bvh", role=role, labels=dict(labels or {}))


def tiny_clips(n: int, sk: Skeleton, T: int = 3) -> list[Motion]:
    """``n`` small float32 clips, cheap to build in bulk."""
    g = torch.Generator().manual_seed(1)
    rot = torch.nn.functional.normalize(torch.randn(n, T, sk.num_joints, 4, generator=g), dim=-1)
    root = torch.randn(n, T, 3, generator=g)
    return [Motion(sk, rot[i], root[i], 30.0, name=f"clip{i:05d}") for i in range(n)]
