"""Compiled test of a hand inside the body (:mod:`torchsplice.ops.body`) on clips packed along frames.

The same figures as :func:`torchsplice.ops.plausibility.penetration_packed`: per clip the share
of frames in which a probe capsule's axis is deeper than ``margin`` inside an obstacle capsule
(``radius - axis distance``), and the deepest it goes. One clip per thread; per frame, FK of
the joints the capsules need (``joints``, ascending and closed under parents), each capsule's
midpoint and half-length, then each probe against each obstacle, the segment distance in closed
form (skipped for a pair whose midpoints are further apart than both half-lengths and the
obstacle's reach: it cannot count). Shapes: rotations ``(N, J, 4)``
(unit WXYZ, local), translations ``(N, J, 3)`` (row 0 the root's world position, the others
offsets or animated translations); capsule ends ``end_a``, ``end_b``, ``end_w`` ``(2C,)``: end
``k`` is ``pos[end_a[k]] (1 - end_w[k]) + pos[end_b[k]] end_w[k]``, capsule ``c`` its ends
``2c`` and ``2c + 1``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .quat import qload, qmul, qrot
from .vec import add, length, row, scale, segment_distance, sub

__all__ = ["inside_clips"]


@njit(cache=True, parallel=True)
def inside_clips(rot, trans, parents, joints, end_a, end_b, end_w, radii, probes, obstacles, margin, floor, starts,
                 lengths, share, depth, frame_deepest):
    """Per clip ``c`` (rows ``starts[c]:starts[c]+lengths[c]``) into ``share[c]`` and ``depth[c]``,
    and per frame ``t`` its deepest pair into ``frame_deepest[t]`` (exact where deeper than ``floor``,
    at most ``floor`` elsewhere: a pair that cannot be deeper is not measured; ``floor`` at most
    ``margin``; see the module docstring)."""
    J = rot.shape[1]
    n_ends = end_a.shape[0]
    for c in prange(starts.shape[0]):
        pos = np.zeros((J, 3))
        grot = np.zeros((J, 4))
        ends = np.empty((n_ends, 3))
        mids = np.empty((n_ends // 2, 3))  # per capsule its axis' midpoint and half its length
        halves = np.empty(n_ends // 2)
        frames_inside = 0
        deepest = 0.0
        for t in range(starts[c], starts[c] + lengths[c]):
            for j in joints:
                p = parents[j]
                q = qload(rot, t, j)
                if p < 0:
                    grot[j, 0], grot[j, 1], grot[j, 2], grot[j, 3] = q
                    pos[j, 0], pos[j, 1], pos[j, 2] = trans[t, j, 0], trans[t, j, 1], trans[t, j, 2]
                else:
                    parent_rot = (grot[p, 0], grot[p, 1], grot[p, 2], grot[p, 3])
                    grot[j, 0], grot[j, 1], grot[j, 2], grot[j, 3] = qmul(parent_rot, q)
                    offset = qrot(parent_rot, (trans[t, j, 0], trans[t, j, 1], trans[t, j, 2]))
                    pos[j, 0] = pos[p, 0] + offset[0]
                    pos[j, 1] = pos[p, 1] + offset[1]
                    pos[j, 2] = pos[p, 2] + offset[2]
            for k in range(n_ends):
                share_b = end_w[k]
                for x in range(3):
                    ends[k, x] = pos[end_a[k], x] * (1.0 - share_b) + pos[end_b[k], x] * share_b
            for capsule in range(n_ends // 2):
                start, end = row(ends, 2 * capsule), row(ends, 2 * capsule + 1)
                mid = scale(add(start, end), 0.5)
                mids[capsule, 0], mids[capsule, 1], mids[capsule, 2] = mid
                halves[capsule] = 0.5 * length(sub(end, start))
            frame_depth = -math.inf
            for probe in probes:
                for obstacle in obstacles:
                    # a lower bound on the axes' distance: the midpoints' distance less both half-lengths
                    apart = length(sub(row(mids, probe), row(mids, obstacle))) - halves[probe] - halves[obstacle]
                    if apart >= radii[obstacle] - floor:  # cannot count: not measured
                        continue
                    pair_depth = radii[obstacle] - segment_distance(row(ends, 2 * probe), row(ends, 2 * probe + 1),
                                                                    row(ends, 2 * obstacle),
                                                                    row(ends, 2 * obstacle + 1))
                    if pair_depth > frame_depth:
                        frame_depth = pair_depth
            frame_deepest[t] = frame_depth
            if frame_depth > margin:
                frames_inside += 1
                if frame_depth > deepest:
                    deepest = frame_depth
        share[c] = frames_inside / max(lengths[c], 1)
        depth[c] = deepest
