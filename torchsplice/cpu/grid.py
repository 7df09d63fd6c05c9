"""Compiled frame-distance grids and phase cropping for one pair (Heck et al. 2006, §3.1).

The distance is :func:`torchsplice.align.distance.distance_grid`'s: landmark clouds (root and
knees by default) compared after the best rotation about the up axis and floor translation,
the rotation restricted to within ``max_dev`` radians of the two frames' relative heading.

Per clip, :func:`clip_features` prepares once (frames along the last axis, so that a grid row
is a vectorised pass over the action's frames):

- ``floor`` ``(K, 2, T)``: landmark floor coordinates ``(a1, a2)`` centred on the cloud's
  centroid, ``a1 = (up + 1) % 3``, ``a2 = (up + 2) % 3``;
- ``height`` ``(K, T)``: landmark heights; ``norm`` ``(T,)``: ``sum_k w |floor_k|^2``;
- ``hcos``, ``hsin`` ``(T,)``: cosine and sine of the heading from the hips (:func:`~.heading.heading_cos_sin`).

Closed form per cell, without ``atan2``: with ``C = sum w fa.fb``, ``S = sum w (fb x fa)``,
``r = |(C, S)|`` and the relative heading ``delta``, ``C' = C cos delta + S sin delta`` and
``S' = S cos delta - C sin delta`` are ``r cos e`` and ``r sin e`` for the angle ``e`` between
the unrestricted optimum and ``delta``, so the best aligned term is ``r`` when
``C' >= r cos(max_dev)`` and ``C' cos(max_dev) + |S'| sin(max_dev)`` otherwise (the nearer end
of the allowed arc). ``D = norm_a + norm_b + sum w (ya - yb)^2 - 2 M``, clamped at 0.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .heading import heading_cos_sin

__all__ = ["clip_features", "distance_row_block", "phase_crop_pair"]


@njit(cache=True, nogil=True)
def clip_features(pos, landmarks, hips, up, n, floor, height, norm, hcos, hsin):
    """Fill one clip's grid features (see the module docstring) from positions ``(T, J, 3)``.

    ``landmarks`` ``(K,)`` joint indices (uniform weights ``1/K``), ``hips`` ``(2,)`` (left,
    right), ``up`` the up axis; frames ``0..n-1``.
    """
    K = landmarks.shape[0]
    a1, a2 = (up + 1) % 3, (up + 2) % 3
    w = 1.0 / K
    for t in range(n):
        centre_u = 0.0
        centre_v = 0.0
        for k in range(K):
            centre_u += w * pos[t, landmarks[k], a1]
            centre_v += w * pos[t, landmarks[k], a2]
        norm_t = 0.0
        for k in range(K):
            u = pos[t, landmarks[k], a1] - centre_u
            v = pos[t, landmarks[k], a2] - centre_v
            floor[k, 0, t] = u
            floor[k, 1, t] = v
            height[k, t] = pos[t, landmarks[k], up]
            norm_t += w * (u * u + v * v)
        norm[t] = norm_t
        hcos[t], hsin[t] = heading_cos_sin(pos, t, hips[0], hips[1], up)


@njit(cache=True, nogil=True, inline="always")
def _aligned(c, s, cos_delta, sin_delta, cos_dev, sin_dev):
    """The best aligned term ``M`` from ``C``, ``S`` and the relative heading's cosine and sine
    ``cos_delta``, ``sin_delta`` (``c_rel``, ``s_rel``: the module docstring's ``C'``, ``S'``)."""
    r = math.sqrt(c * c + s * s)
    c_rel = c * cos_delta + s * sin_delta
    s_rel = s * cos_delta - c * sin_delta
    return r if c_rel >= r * cos_dev else c_rel * cos_dev + abs(s_rel) * sin_dev


@njit(cache=True, nogil=True)
def distance_row_block(feat, start_a, frames_a, start_b, frames_b, max_dev, out):
    """``out[i, j]`` for ``i < frames_a``, ``j < frames_b``: distance of frame ``start_a + i`` to frame
    ``start_b + j`` of the packed features ``feat`` (see :func:`clip_features`; ``max_dev >= pi``:
    unrestricted).

    The features stay whole arrays indexed by offset, so that the compiler sees unit strides
    and vectorises the pass over ``j``; three landmarks (root and knees, the default) take a
    fused single pass.
    """
    floor, height, norm, hcos, hsin = feat
    K = floor.shape[0]
    w = 1.0 / K
    cos_dev = math.cos(max_dev) if max_dev < math.pi else -2.0
    sin_dev = math.sin(max_dev)
    if K == 3:
        # 1-D rows of b's features from its first frame (unit stride, no aliasing with out)
        b00, b01, b10, b11 = (floor[0, 0, start_b:start_b + frames_b], floor[0, 1, start_b:start_b + frames_b],
                              floor[1, 0, start_b:start_b + frames_b], floor[1, 1, start_b:start_b + frames_b])
        b20, b21 = floor[2, 0, start_b:start_b + frames_b], floor[2, 1, start_b:start_b + frames_b]
        y0, y1, y2 = (height[0, start_b:start_b + frames_b], height[1, start_b:start_b + frames_b],
                      height[2, start_b:start_b + frames_b])
        norm_b, cos_b, sin_b = (norm[start_b:start_b + frames_b], hcos[start_b:start_b + frames_b],
                                hsin[start_b:start_b + frames_b])
        for i in range(frames_a):
            row_a = start_a + i
            u0, v0, u1, v1 = (w * floor[0, 0, row_a], w * floor[0, 1, row_a], w * floor[1, 0, row_a],
                              w * floor[1, 1, row_a])
            u2, v2 = w * floor[2, 0, row_a], w * floor[2, 1, row_a]
            a0, a1, a2 = height[0, row_a], height[1, row_a], height[2, row_a]
            cos_a, sin_a, norm_a = hcos[row_a], hsin[row_a], norm[row_a]
            row = out[i]
            for j in range(frames_b):
                c = u0 * b00[j] + v0 * b01[j] + u1 * b10[j] + v1 * b11[j] + u2 * b20[j] + v2 * b21[j]
                s = v0 * b00[j] - u0 * b01[j] + v1 * b10[j] - u1 * b11[j] + v2 * b20[j] - u2 * b21[j]
                d0, d1, d2 = a0 - y0[j], a1 - y1[j], a2 - y2[j]
                height_term = w * (d0 * d0 + d1 * d1 + d2 * d2)
                m = _aligned(c, s, cos_a * cos_b[j] + sin_a * sin_b[j], sin_a * cos_b[j] - cos_a * sin_b[j], cos_dev,
                             sin_dev)
                d = norm_a + norm_b[j] + height_term - 2.0 * m
                row[j] = d if d > 0.0 else 0.0
        return
    C = np.empty(frames_b)
    S = np.empty(frames_b)
    height_terms = np.empty(frames_b)
    for i in range(frames_a):
        row_a = start_a + i
        for j in range(frames_b):
            C[j] = 0.0
            S[j] = 0.0
            height_terms[j] = 0.0
        for k in range(K):
            u, v, y = w * floor[k, 0, row_a], w * floor[k, 1, row_a], height[k, row_a]
            for j in range(frames_b):
                fu, fv = floor[k, 0, start_b + j], floor[k, 1, start_b + j]
                C[j] += u * fu + v * fv
                S[j] += v * fu - u * fv
                d = y - height[k, start_b + j]
                height_terms[j] += w * d * d
        cos_a, sin_a, norm_a = hcos[row_a], hsin[row_a], norm[row_a]
        for j in range(frames_b):
            row_b = start_b + j
            m = _aligned(C[j], S[j], cos_a * hcos[row_b] + sin_a * hsin[row_b],
                         sin_a * hcos[row_b] - cos_a * hsin[row_b], cos_dev, sin_dev)
            d = norm_a + norm[row_b] + height_terms[j] - 2.0 * m
            out[i, j] = d if d > 0.0 else 0.0


@njit(cache=True, nogil=True)
def phase_crop_pair(grid, frames_a, frames_b, context, window, depth):
    """Frames to crop from the start of clip b (columns) to bring it in phase with clip a, as
    :func:`torchsplice.splice.heck.phase_crop`: the first local minimum (over ``window``
    frames either side) of the windowed distance ``d(j)`` that is within ``depth`` of the way
    from its lowest to its highest value, leaving at least half of b; 0 if none. ``grid``: the pair's
    ``(frames_a, frames_b)`` distances; ``d(j)`` the mean over ``span`` frames of its diagonal from
    ``(0, j)``."""
    span = max(1, min(frames_a, frames_b // 2, context))
    d = np.full(frames_b, np.inf)
    lowest = np.inf
    highest = -np.inf
    half = (frames_b - 1) // 2
    for j in range(frames_b):
        if j + span <= frames_b and j <= half:
            s = 0.0
            for k in range(span):
                s += grid[k, j + k]
            d[j] = s / span
            lowest = min(lowest, d[j])
            highest = max(highest, d[j])
    for j in range(frames_b):
        if not (j + span <= frames_b and j <= half):
            continue
        if not d[j] <= lowest + depth * (highest - lowest):
            continue
        ok = True
        for k in range(max(0, j - window), min(frames_b, j + window + 1)):
            if d[k] < d[j]:
                ok = False
                break
        if ok:
            return j
    return 0
