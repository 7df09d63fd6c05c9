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
    n_feet, n_upper = feet.shape[0], upper.shape[0]
    for c in prange(starts.shape[0]):
        n, first, clip_fps = lengths[c], starts[c], fps[c]
        pos = np.zeros((J, 3))
        grot = np.zeros((J, 4))
        foot_pos = np.empty((n, n_feet, 3))
        upper_pos = np.empty((n, n_upper, 3))  # in the chest's frame
        lowest = math.inf
        for t in range(n):
            for j in joints:
                p = parents[j]
                q = qload(rot, first + t, j)
                if p < 0:
                    grot[j, 0], grot[j, 1], grot[j, 2], grot[j, 3] = q
                    pos[j, 0], pos[j, 1], pos[j, 2] = (trans[first + t, j, 0], trans[first + t, j, 1],
                                                       trans[first + t, j, 2])
                else:
                    parent_rot = (grot[p, 0], grot[p, 1], grot[p, 2], grot[p, 3])
                    grot[j, 0], grot[j, 1], grot[j, 2], grot[j, 3] = qmul(parent_rot, q)
                    offset = qrot(parent_rot, (trans[first + t, j, 0], trans[first + t, j, 1], trans[first + t, j, 2]))
                    for x in range(3):
                        pos[j, x] = pos[p, x] + offset[x]
            for f in range(n_feet):
                for x in range(3):
                    foot_pos[t, f, x] = pos[feet[f], x]
                lowest = min(lowest, foot_pos[t, f, up])
            to_chest = qconj((grot[chest, 0], grot[chest, 1], grot[chest, 2], grot[chest, 3]))
            for u in range(n_upper):
                v = qrot(to_chest, (pos[upper[u], 0] - pos[chest, 0], pos[upper[u], 1] - pos[chest, 1],
                               pos[upper[u], 2] - pos[chest, 2]))
                upper_pos[t, u, 0], upper_pos[t, u, 1], upper_pos[t, u, 2] = v
        floor[c] = lowest
        # the mean horizontal speed of a foot in contact, at the clip's own rate
        contact = height * per_metre
        total, steps = 0.0, 0
        for t in range(1, n):
            for f in range(n_feet):
                if foot_pos[t - 1, f, up] - lowest < contact and foot_pos[t, f, up] - lowest < contact:
                    total += _flat(foot_pos[t, f], foot_pos[t - 1, f], up) * clip_fps
                    steps += 1
        slide[c] = total / steps if steps else 0.0
        # GMD's skate ratio, the feet resampled at its rate
        n_steps = int(math.floor((n - 1) / clip_fps * rate + 1e-9)) + 1 if n > 0 else 0
        if n_steps > 1:
            resampled = np.empty((n_steps, n_feet, 3))
            for k in range(n_steps):
                at = min(k / rate * clip_fps, n - 1.0)
                i0 = int(math.floor(at))
                i1 = min(i0 + 1, n - 1)
                w = at - i0
                for f in range(n_feet):
                    for x in range(3):
                        resampled[k, f, x] = (foot_pos[i0, f, x] * (1.0 - w) + foot_pos[i1, f, x] * w) / per_metre
            step_speed = np.zeros((n_steps - 1, n_feet))
            for k in range(n_steps - 1):
                for f in range(n_feet):
                    step_speed[k, f] = _flat(resampled[k + 1, f], resampled[k, f], up) * rate
            half = window // 2
            skating = 0
            for k in range(n_steps - 1):
                hit = False
                for f in range(n_feet):
                    box = 0.0
                    for i in range(k - half, k + half + 1):
                        if 0 <= i < n_steps - 1:
                            box += step_speed[i, f]
                    box /= window
                    rise0, rise1 = (resampled[k, f, up] - lowest / per_metre,
                                    resampled[k + 1, f, up] - lowest / per_metre)
                    if rise0 < height and rise1 < height and step_speed[k, f] > speed and box > speed:
                        hit = True
                skating += hit
            skate[c] = skating / (n_steps - 1)
        else:
            skate[c] = 0.0
        # the largest third difference of the upper joints in the chest's frame, mean over them
        largest = 0.0
        for t in range(3, n):
            size = 0.0
            for u in range(n_upper):
                s = 0.0
                for x in range(3):
                    d = (upper_pos[t, u, x] - 3.0 * upper_pos[t - 1, u, x] + 3.0 * upper_pos[t - 2, u, x]
                         - upper_pos[t - 3, u, x])
                    s += d * d
                size += math.sqrt(s)
            largest = max(largest, size / n_upper)
        jerk[c] = largest * clip_fps ** 3
