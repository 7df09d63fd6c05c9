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
        cu = 0.0
        cv = 0.0
        for k in range(K):
            cu += w * pos[t, landmarks[k], a1]
            cv += w * pos[t, landmarks[k], a2]
        nn = 0.0
        for k in range(K):
            u = pos[t, landmarks[k], a1] - cu
            v = pos[t, landmarks[k], a2] - cv
            floor[k, 0, t] = u
            floor[k, 1, t] = v
            height[k, t] = pos[t, landmarks[k], up]
            nn += w * (u * u + v * v)
        norm[t] = nn
        hcos[t], hsin[t] = heading_cos_sin(pos, t, hips[0], hips[1], up)


@njit(cache=True, nogil=True, inline="always")
def _aligned(c, s, cd, sd, cos_dev, sin_dev):
    """The best aligned term ``M`` from ``C``, ``S`` and the relative heading's cosine and sine."""
    r = math.sqrt(c * c + s * s)
    c2 = c * cd + s * sd
    s2 = s * cd - c * sd
    return r if c2 >= r * cos_dev else c2 * cos_dev + abs(s2) * sin_dev


@njit(cache=True, nogil=True)
def distance_row_block(feat, sa, la, sb, lb, max_dev, out):
    """``out[i, j]`` for ``i < la``, ``j < lb``: distance of frame ``sa + i`` to frame ``sb + j`` of
    the packed features ``feat`` (see :func:`clip_features`; ``max_dev >= pi``: unrestricted).

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
        b00, b01, b10, b11 = floor[0, 0, sb:sb + lb], floor[0, 1, sb:sb + lb], floor[1, 0, sb:sb + lb], floor[1, 1, sb:sb + lb]
        b20, b21 = floor[2, 0, sb:sb + lb], floor[2, 1, sb:sb + lb]
        y0, y1, y2 = height[0, sb:sb + lb], height[1, sb:sb + lb], height[2, sb:sb + lb]
        nb, cb, sbh = norm[sb:sb + lb], hcos[sb:sb + lb], hsin[sb:sb + lb]
        for i in range(la):
            ia = sa + i
            u0, v0, u1, v1 = w * floor[0, 0, ia], w * floor[0, 1, ia], w * floor[1, 0, ia], w * floor[1, 1, ia]
            u2, v2 = w * floor[2, 0, ia], w * floor[2, 1, ia]
            a0, a1, a2 = height[0, ia], height[1, ia], height[2, ia]
            ci, si, ni = hcos[ia], hsin[ia], norm[ia]
            row = out[i]
            for j in range(lb):
                c = u0 * b00[j] + v0 * b01[j] + u1 * b10[j] + v1 * b11[j] + u2 * b20[j] + v2 * b21[j]
                s = v0 * b00[j] - u0 * b01[j] + v1 * b10[j] - u1 * b11[j] + v2 * b20[j] - u2 * b21[j]
                d0, d1, d2 = a0 - y0[j], a1 - y1[j], a2 - y2[j]
                hh = w * (d0 * d0 + d1 * d1 + d2 * d2)
                m = _aligned(c, s, ci * cb[j] + si * sbh[j], si * cb[j] - ci * sbh[j], cos_dev, sin_dev)
                d = ni + nb[j] + hh - 2.0 * m
                row[j] = d if d > 0.0 else 0.0
        return
    C = np.empty(lb)
    S = np.empty(lb)
    Hh = np.empty(lb)
    for i in range(la):
        ia = sa + i
        for j in range(lb):
            C[j] = 0.0
            S[j] = 0.0
            Hh[j] = 0.0
        for k in range(K):
            u, v, y = w * floor[k, 0, ia], w * floor[k, 1, ia], height[k, ia]
            for j in range(lb):
                fu, fv = floor[k, 0, sb + j], floor[k, 1, sb + j]
                C[j] += u * fu + v * fv
                S[j] += v * fu - u * fv
                d = y - height[k, sb + j]
                Hh[j] += w * d * d
        ci, si, ni = hcos[ia], hsin[ia], norm[ia]
        for j in range(lb):
            jb = sb + j
            m = _aligned(C[j], S[j], ci * hcos[jb] + si * hsin[jb], si * hcos[jb] - ci * hsin[jb], cos_dev, sin_dev)
            d = ni + norm[jb] + Hh[j] - 2.0 * m
            out[i, j] = d if d > 0.0 else 0.0


@njit(cache=True, nogil=True)
def phase_crop_pair(grid, la, lb, context, window, depth):
    """Frames to crop from the start of clip b (columns) to bring it in phase with clip a, as
    :func:`torchsplice.splice.heck.phase_crop`: the first local minimum (over ``window``
    frames either side) of the windowed distance ``d(j)`` that is within ``depth`` of the way
    from its lowest to its highest value, leaving at least half of b; 0 if none."""
    W = max(1, min(la, lb // 2, context))
    d = np.full(lb, np.inf)
    lo = np.inf
    hi = -np.inf
    half = (lb - 1) // 2
    for j in range(lb):
        if j + W <= lb and j <= half:
            s = 0.0
            for k in range(W):
                s += grid[k, j + k]
            d[j] = s / W
            lo = min(lo, d[j])
            hi = max(hi, d[j])
    for j in range(lb):
        if not (j + W <= lb and j <= half):
            continue
        if not d[j] <= lo + depth * (hi - lo):
            continue
        ok = True
        for k in range(max(0, j - window), min(lb, j + window + 1)):
            if d[k] < d[j]:
                ok = False
                break
        if ok:
            return j
    return 0
