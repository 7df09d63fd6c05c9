"""Compiled frame-distance grids and phase cropping for one pair (Heck et al. 2006, §3.1).

The distance is :func:`torchsplice.align.distance.distance_grid`'s: landmark clouds (root and
knees by default) compared after the best rotation about the up axis and floor translation,
the rotation restricted to within ``max_dev`` radians of the two frames' relative heading.

Per clip, :func:`clip_features` prepares once (frames along the last axis, so that a grid row
is a vectorised pass over the action's frames):

- ``floor`` ``(K, 2, T)``: landmark floor coordinates ``(a1, a2)`` centred on the cloud's
  centroid, ``a1 = (up + 1) % 3``, ``a2 = (up + 2) % 3``;
- ``height`` ``(K, T)``: landmark heights; ``norm`` ``(T,)``: ``sum_k w |floor_k|^2``;
- ``hcos``, ``hsin`` ``(T,)``: cosine and sine of the heading from the hips.

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
        # heading = atan2(-d[a1], d[a2]) for d = left hip - right hip
        y = -(pos[t, hips[0], a1] - pos[t, hips[1], a1])
        x = pos[t, hips[0], a2] - pos[t, hips[1], a2]
        r = math.sqrt(x * x + y * y)
        if r > 0.0:
            hcos[t], hsin[t] = x / r, y / r
        else:
            hcos[t], hsin[t] = 1.0, 0.0


@njit(cache=True, nogil=True)
def distance_row_block(fa, ya, na, ca, sa, la, fb, yb, nb, cb, sb, lb, max_dev, out):
    """``out[i, j]`` for ``i < la``, ``j < lb``: distance of frame ``i`` of clip a to frame
    ``j`` of clip b, from both clips' features (``max_dev >= pi``: unrestricted)."""
    K = fa.shape[0]
    w = 1.0 / K
    cos_dev = math.cos(max_dev) if max_dev < math.pi else -2.0
    sin_dev = math.sin(max_dev)
    C = np.empty(lb)
    S = np.empty(lb)
    Hh = np.empty(lb)
    for i in range(la):
        for j in range(lb):
            C[j] = 0.0
            S[j] = 0.0
            Hh[j] = 0.0
        for k in range(K):
            u, v, y = w * fa[k, 0, i], w * fa[k, 1, i], ya[k, i]
            fbu, fbv, ybk = fb[k, 0], fb[k, 1], yb[k]
            for j in range(lb):
                C[j] += u * fbu[j] + v * fbv[j]
                S[j] += v * fbu[j] - u * fbv[j]
                d = y - ybk[j]
                Hh[j] += w * d * d
        ci, si, ni = ca[i], sa[i], na[i]
        row = out[i]
        for j in range(lb):
            cd = ci * cb[j] + si * sb[j]  # cos(heading_a - heading_b)
            sd = si * cb[j] - ci * sb[j]
            c, s = C[j], S[j]
            r = math.sqrt(c * c + s * s)
            c2 = c * cd + s * sd
            s2 = s * cd - c * sd
            m = r if c2 >= r * cos_dev else c2 * cos_dev + abs(s2) * sin_dev
            d = ni + nb[j] + Hh[j] - 2.0 * m
            row[j] = d if d > 0.0 else 0.0


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
