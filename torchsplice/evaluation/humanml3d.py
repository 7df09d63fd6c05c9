"""Measures of an exported HumanML3D folder: the format's properties, what its targets are stated
on (the tests and ``scripts/benchmark.py --only humanml3d`` print and check them).

Over every motion of ``new_joint_vecs`` and ``new_joints`` (metres): positions recovered from
the features against ``new_joints``; how far each bone's length strays from its mean; the lowest
joint's height per frame (its 5th percentile: the feet on the floor); features derived again
from ``new_joints`` against the exported ones, away from the clip's end by ``margins`` frames
(``new_joints`` lacks the clip's last frame, which the heading's smoothing reaches back from);
and the share of frames whose contacts agree.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ..formats.humanml3d_features import FEATURES, features_to_positions, positions_to_features
from ..specs.smpl import SMPL22_PARENTS

__all__ = ["folder_properties"]


def folder_properties(folder, margins=(20, 40, 60)) -> dict:
    """The worst figures over the folder's motions: ``recover``, ``bones`` (m), ``floor_p5`` (m),
    ``derived{M}`` for each margin ``M``, ``contacts`` (the lowest share), ``motions``. A file of
    the wrong shape or with values that are not finite raises ``ValueError`` naming it."""
    folder = Path(folder)
    worst = {"recover": 0.0, "bones": 0.0, "contacts": 1.0, **{f"derived{m}": 0.0 for m in margins}, "motions": 0}
    lows = []
    for f in sorted((folder / "new_joint_vecs").glob("*.npy")):
        vecs = torch.from_numpy(np.load(f)).double()
        joints = torch.from_numpy(np.load(folder / "new_joints" / f.name)).double()
        if vecs.dim() != 2 or vecs.shape[1] != FEATURES or joints.shape != (vecs.shape[0], 22, 3):
            raise ValueError(f"{f}: shapes {tuple(vecs.shape)} and {tuple(joints.shape)} are not (N, 263) and (N, 22, 3)")
        if not (bool(torch.isfinite(vecs).all()) and bool(torch.isfinite(joints).all())):
            raise ValueError(f"{f}: values that are not finite")
        worst["motions"] += 1
        worst["recover"] = max(worst["recover"], float((features_to_positions(vecs) - joints).abs().max()))
        bones = torch.stack([(joints[:, c] - joints[:, p]).norm(dim=-1) for c, p in enumerate(SMPL22_PARENTS) if p >= 0], 1)
        worst["bones"] = max(worst["bones"], float((bones - bones.mean(0)).abs().max()))
        lows.append(joints[..., 1].amin(1))
        again = positions_to_features(joints, normalize=False)
        n = again.shape[0]
        for m in margins:
            if n > m:
                gap = float((again[:n - m, :259] - vecs[:n - m, :259]).abs().max())
                worst[f"derived{m}"] = max(worst[f"derived{m}"], gap)
        worst["contacts"] = min(worst["contacts"], float((again[:, 259:] == vecs[:n, 259:]).double().mean()))
    worst["floor_p5"] = float(torch.cat(lows).quantile(0.05)) if lows else float("nan")
    return worst
