"""Compiled test of a hand inside the body (:mod:`torchsplice.ops.body`) on clips packed along frames.

The same figures as :func:`torchsplice.ops.plausibility.penetration_packed`: per clip the share
of frames in which a probe capsule's axis is deeper than ``margin`` inside an obstacle capsule
(``radius - axis distance``), and the deepest it goes. One clip per thread; per frame, FK of
the joints the capsules need (``joints``, ascending and closed under parents) then each probe
against each obstacle, the segment distance in closed form (skipped for a pair whose midpoints
are too far apart for it to count). Shapes: rotations ``(N, J, 4)``
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


@njit(cache=True, nogil=True)
def _apart(e, i, k):
    """A lower bound on the distance between segments ``i`` and ``k`` of ``e`` (rows ``2i, 2i+1``):
    their midpoints' distance less both half-lengths (a pair surely further than a capsule's
    reach is skipped)."""
    a0, a1, b0, b1 = row(e, 2 * i), row(e, 2 * i + 1), row(e, 2 * k), row(e, 2 * k + 1)
    return length(scale(sub(add(a0, a1), add(b0, b1)), 0.5)) - 0.5 * length(sub(a1, a0)) - 0.5 * length(sub(b1, b0))


@njit(cache=True, parallel=True)
def inside_clips(rot, trans, parents, joints, end_a, end_b, end_w, radii, probes, obstacles, margin, starts, lengths,
                 share, depth):
    """Per clip ``c`` (rows ``starts[c]:starts[c]+lengths[c]``) into ``share[c]`` and ``depth[c]``
    (see the module docstring)."""
    J = rot.shape[1]
    K = end_a.shape[0]
    for c in prange(starts.shape[0]):
        pos = np.zeros((J, 3))
        grot = np.zeros((J, 4))
        ends = np.empty((K, 3))
        inside = 0
        deepest = 0.0
        for t in range(starts[c], starts[c] + lengths[c]):
            for j in joints:
                p = parents[j]
                q = qload(rot, t, j)
                if p < 0:
                    grot[j, 0], grot[j, 1], grot[j, 2], grot[j, 3] = q
                    pos[j, 0], pos[j, 1], pos[j, 2] = trans[t, j, 0], trans[t, j, 1], trans[t, j, 2]
                else:
                    gp = (grot[p, 0], grot[p, 1], grot[p, 2], grot[p, 3])
                    grot[j, 0], grot[j, 1], grot[j, 2], grot[j, 3] = qmul(gp, q)
                    o = qrot(gp, (trans[t, j, 0], trans[t, j, 1], trans[t, j, 2]))
                    pos[j, 0] = pos[p, 0] + o[0]
                    pos[j, 1] = pos[p, 1] + o[1]
                    pos[j, 2] = pos[p, 2] + o[2]
            for k in range(K):
                w = end_w[k]
                for x in range(3):
                    ends[k, x] = pos[end_a[k], x] * (1.0 - w) + pos[end_b[k], x] * w
            best = -math.inf
            for i in probes:
                for o_ in obstacles:
                    if _apart(ends, i, o_) >= radii[o_] - margin:  # cannot count: not measured
                        continue
                    d = radii[o_] - segment_distance(row(ends, 2 * i), row(ends, 2 * i + 1), row(ends, 2 * o_),
                                                     row(ends, 2 * o_ + 1))
                    if d > best:
                        best = d
            if best > margin:
                inside += 1
                if best > deepest:
                    deepest = best
        share[c] = inside / max(lengths[c], 1)
        depth[c] = deepest
