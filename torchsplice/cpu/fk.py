"""Compiled forward kinematics of one clip, on all joints or on a subset.

Shapes: local rotations ``(T, J, 4)`` (unit WXYZ), local translations ``(T, J, 3)`` (row 0 is
the root's world position, the other rows the joints' offsets or animated translations),
outputs ``positions (T, J, 3)`` and ``global_rotations (T, J, 4)`` (joint frame to world).
Same formulas as :func:`torchsplice.kinematics.forward_kinematics`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .quat import qload, qmul, qrot, qstore

__all__ = ["fk_clip", "fk_clips", "joint_closure"]


@njit(cache=True, nogil=True)
def fk_clip(rot, trans, parents, joints, n, pos, grot):
    """FK of frames ``0..n-1`` for ``joints`` (ascending, closed under parents) into ``pos``/``grot``.

    Joints not listed are left untouched.
    """
    for t in range(n):
        for j in joints:
            p = parents[j]
            q = qload(rot, t, j)
            v = (trans[t, j, 0], trans[t, j, 1], trans[t, j, 2])
            if p < 0:
                qstore(grot, t, j, q)
                pos[t, j, 0], pos[t, j, 1], pos[t, j, 2] = v
            else:
                parent_rot = qload(grot, t, p)
                qstore(grot, t, j, qmul(parent_rot, q))
                offset = qrot(parent_rot, v)
                pos[t, j, 0] = pos[t, p, 0] + offset[0]
                pos[t, j, 1] = pos[t, p, 1] + offset[1]
                pos[t, j, 2] = pos[t, p, 2] + offset[2]


@njit(cache=True, parallel=True)
def fk_clips(rot, trans, parents, starts, lengths, pos, grot):
    """FK of every joint of clips packed along frames (clip ``c`` is rows
    ``starts[c]:starts[c]+lengths[c]`` of ``(N, J, ...)`` arrays), one clip per thread."""
    joints = np.arange(rot.shape[1])
    for c in prange(starts.shape[0]):
        first, n = starts[c], lengths[c]
        fk_clip(rot[first:first + n], trans[first:first + n], parents, joints, n, pos[first:first + n],
                grot[first:first + n])


def joint_closure(parents, joints) -> np.ndarray:
    """The joints and all their ancestors, ascending (topological order), as int64."""
    out = set()
    for j in joints:
        j = int(j)
        while j >= 0 and j not in out:
            out.add(j)
            j = int(parents[j])
    return np.array(sorted(out), dtype=np.int64)
