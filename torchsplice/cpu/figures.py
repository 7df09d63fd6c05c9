"""Compiled figures of what a person would reject in a clip (:func:`torchsplice.ops.plausibility.clip_figures`), clips packed along frames.

One clip per thread: per frame, FK of the joints needed (``joints``, ascending and closed under
parents), keeping the ``feet`` and the ``upper`` joints in the ``chest``'s frame; then per clip
GMD's skate ratio (resampled at 20 fps, contact within 5 cm of the clip's lowest foot point,
skating above 0.5 m/s in the step and over a 5-step box), the mean horizontal speed of a foot
in contact, the lowest a foot goes and the largest third difference of the upper joints (mean
over them). Shapes: rotations ``(N, J, 4)`` (unit WXYZ, local), translations ``(N, J, 3)``
(row 0 the root's position); per clip ``starts``, ``lengths``, ``fps``; out ``(B,)`` each, in
the skeleton's units (``per_metre`` of them to a metre; the caller converts).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .quat import qconj, qload, qmul, qrot

__all__ = ["figures_clips", "GMD"]

GMD = (20.0, 0.05, 0.5, 5)
"""GMD's skate convention: rate, contact height (m), speed (m/s), window (steps), as
:mod:`torchsplice.ops.plausibility`'s ``GMD_*``."""


@njit(cache=True, inline="always")
def _flat(a, b, up):
    """The horizontal distance between 3-vectors ``a`` and ``b`` (the up axis left out)."""
    s = 0.0
    for x in range(3):
        if x != up:
            s += (a[x] - b[x]) ** 2
    return math.sqrt(s)


@njit(cache=True, parallel=True)
def figures_clips(rot, trans, parents, joints, feet, upper, chest, up, per_metre, rate, height, speed, window, starts,
                  lengths, fps, skate, slide, floor, jerk):
    """Per clip ``c`` into ``skate[c]``, ``slide[c]`` (units/s), ``floor[c]`` (units) and
    ``jerk[c]`` (units/s^3) (see the module docstring)."""
    J = rot.shape[1]
    F, U = feet.shape[0], upper.shape[0]
    for c in prange(starts.shape[0]):
        n, r0, hz = lengths[c], starts[c], fps[c]
        pos = np.zeros((J, 3))
        grot = np.zeros((J, 4))
        fp = np.empty((n, F, 3))
        ub = np.empty((n, U, 3))
        low = math.inf
        for t in range(n):
            for j in joints:
                p = parents[j]
                q = qload(rot, r0 + t, j)
                if p < 0:
                    grot[j, 0], grot[j, 1], grot[j, 2], grot[j, 3] = q
                    pos[j, 0], pos[j, 1], pos[j, 2] = trans[r0 + t, j, 0], trans[r0 + t, j, 1], trans[r0 + t, j, 2]
                else:
                    gp = (grot[p, 0], grot[p, 1], grot[p, 2], grot[p, 3])
                    grot[j, 0], grot[j, 1], grot[j, 2], grot[j, 3] = qmul(gp, q)
                    o = qrot(gp, (trans[r0 + t, j, 0], trans[r0 + t, j, 1], trans[r0 + t, j, 2]))
                    for x in range(3):
                        pos[j, x] = pos[p, x] + o[x]
            for f in range(F):
                for x in range(3):
                    fp[t, f, x] = pos[feet[f], x]
                low = min(low, fp[t, f, up])
            inv = qconj((grot[chest, 0], grot[chest, 1], grot[chest, 2], grot[chest, 3]))
            for u in range(U):
                v = qrot(inv, (pos[upper[u], 0] - pos[chest, 0], pos[upper[u], 1] - pos[chest, 1],
                               pos[upper[u], 2] - pos[chest, 2]))
                ub[t, u, 0], ub[t, u, 1], ub[t, u, 2] = v
        floor[c] = low
        # the mean horizontal speed of a foot in contact, at the clip's own rate
        touch = height * per_metre
        total, steps = 0.0, 0
        for t in range(1, n):
            for f in range(F):
                if fp[t - 1, f, up] - low < touch and fp[t, f, up] - low < touch:
                    total += _flat(fp[t, f], fp[t - 1, f], up) * hz
                    steps += 1
        slide[c] = total / steps if steps else 0.0
        # GMD's skate ratio, the feet resampled at its rate
        K = int(math.floor((n - 1) / hz * rate + 1e-9)) + 1 if n > 0 else 0
        if K > 1:
            rs = np.empty((K, F, 3))
            for k in range(K):
                src = min(k / rate * hz, n - 1.0)
                lo = int(math.floor(src))
                hi = min(lo + 1, n - 1)
                w = src - lo
                for f in range(F):
                    for x in range(3):
                        rs[k, f, x] = (fp[lo, f, x] * (1.0 - w) + fp[hi, f, x] * w) / per_metre
            sp = np.zeros((K - 1, F))
            for k in range(K - 1):
                for f in range(F):
                    sp[k, f] = _flat(rs[k + 1, f], rs[k, f], up) * rate
            half = window // 2
            count = 0
            for k in range(K - 1):
                hit = False
                for f in range(F):
                    box = 0.0
                    for i in range(k - half, k + half + 1):
                        if 0 <= i < K - 1:
                            box += sp[i, f]
                    box /= window
                    h0, h1 = rs[k, f, up] - low / per_metre, rs[k + 1, f, up] - low / per_metre
                    if h0 < height and h1 < height and sp[k, f] > speed and box > speed:
                        hit = True
                count += hit
            skate[c] = count / (K - 1)
        else:
            skate[c] = 0.0
        # the largest third difference of the upper joints in the chest's frame, mean over them
        best = 0.0
        for t in range(3, n):
            size = 0.0
            for u in range(U):
                s = 0.0
                for x in range(3):
                    d = ub[t, u, x] - 3.0 * ub[t - 1, u, x] + 3.0 * ub[t - 2, u, x] - ub[t - 3, u, x]
                    s += d * d
                size += math.sqrt(s)
            best = max(best, size / U)
        jerk[c] = best * hz ** 3
