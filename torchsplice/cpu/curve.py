"""Compiled alignment curves and resampling for one pair (see :mod:`torchsplice.align.curve`).

:func:`fit_curve` turns a timewarp path into the alignment curve ``lambda(t)`` of Heck et al.
2006 exactly as :func:`torchsplice.align.curve.fit_alignment_curve` does: a cubic B-spline
on clamped uniform knots, ``round(i_last / knot_spacing) + 3`` control points (at least 4), the
first and last fixed to the path's end values, the others fitted by least squares with a
second-difference penalty (P-spline), then made strictly increasing and evaluated at every
frame ``t = 0 .. i_last``. The normal equations are banded (width 3), so they are solved by a
banded Cholesky factorisation in ``O(n)``, which keeps 4-minute takes cheap.

:func:`resample_clip` samples a clip at fractional frame times: rotations by slerp, local
translations linearly (:func:`torchsplice.align.curve.slerp_frames` and ``interpolate_frames``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .quat import qload, qslerp, qstore

__all__ = ["knots", "basis4", "fit_curve", "lerp", "split_time", "resample_clip"]


@njit(cache=True, nogil=True)
def knots(n):
    """``(n + 4,)`` clamped uniform cubic knots on [0, 1] for ``n`` control points."""
    k = np.empty(n + 4)
    for m in range(n + 4):
        k[m] = min(max((m - 3.0) / (n - 3.0), 0.0), 1.0)
    return k


@njit(cache=True, nogil=True, inline="always")
def _span(kn, n, u):
    """Index ``k`` of the knot span holding ``u`` (``kn[k] <= u < kn[k+1]``; ``u >= 1`` in the last)."""
    if u >= 1.0:
        return n - 1
    k = min(max(3 + int(u * (n - 3)), 3), n - 1)
    while k < n - 1 and u >= kn[k + 1]:
        k += 1
    while k > 3 and u < kn[k]:
        k -= 1
    return k


@njit(cache=True, nogil=True)
def basis4(kn, n, u, N):
    """The four non-zero cubic basis values at ``u`` into ``N`` (4,); returns the first index ``k - 3``."""
    k = _span(kn, n, u)
    left = np.empty(4)
    right = np.empty(4)
    N[0] = 1.0
    for j in range(1, 4):
        left[j] = u - kn[k + 1 - j]
        right[j] = kn[k + j] - u
        saved = 0.0
        for r in range(j):
            temp = N[r] / (right[r + 1] + left[j - r])
            N[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        N[j] = saved
    return k - 3


@njit(cache=True, nogil=True)
def _penalty(kn, n, scale_smooth, A):
    """Add ``smoothing * D^T D`` (divided second differences on the Greville abscissae, scaled by
    ``1 / (n - 1)``) to the band matrix ``A`` ``(n, 4)`` (``A[i, d] = M[i, i - d]``)."""
    g = np.empty(n)
    for k in range(n):
        g[k] = (kn[k + 1] + kn[k + 2] + kn[k + 3]) / 3.0
    scale = 1.0 / (n - 1)
    for r in range(n - 2):
        h0 = max(g[r + 1] - g[r], 1e-9)
        h1 = max(g[r + 2] - g[r + 1], 1e-9)
        d = (scale / h0, -scale * (1.0 / h0 + 1.0 / h1), scale / h1)
        for a in range(3):
            for b in range(a + 1):
                A[r + a, a - b] += scale_smooth * d[a] * d[b]


@njit(cache=True, nogil=True)
def _band_cholesky_solve(A, rhs, lo, hi):
    """Solve the SPD band system ``M x = rhs`` on rows/columns ``lo..hi-1`` (``A[i, d] = M[i, i-d]``,
    bandwidth 3) in place: ``rhs`` holds the solution on return. Returns False if not positive."""
    bw = 3
    L = np.zeros((A.shape[0], bw + 1))
    for i in range(lo, hi):
        for d in range(min(bw, i - lo), -1, -1):
            c = i - d
            s = A[i, d]
            for k in range(max(i - bw, lo), c):
                s -= L[i, i - k] * L[c, c - k]
            if d == 0:
                if not s > 0.0:
                    return False
                L[i, 0] = math.sqrt(s)
            else:
                L[i, d] = s / L[c, 0]
    for i in range(lo, hi):
        s = rhs[i]
        for k in range(max(i - bw, lo), i):
            s -= L[i, i - k] * rhs[k]
        rhs[i] = s / L[i, 0]
    for i in range(hi - 1, lo - 1, -1):
        s = rhs[i]
        for k in range(i + 1, min(i + bw + 1, hi)):
            s -= L[k, k - i] * rhs[k]
        rhs[i] = s / L[i, 0]
    return True


@njit(cache=True, nogil=True)
def fit_curve(cells, length, knot_spacing, smoothing, curve):
    """Fit the alignment curve to ``cells[:length]`` (path cells ``(i, j)``) and evaluate it into
    ``curve[:i_last + 1]``. Returns the number of frames ``i_last + 1``, or ``-1`` when the path
    does not advance in both clips (``i_last <= 0`` or ``j_last <= j_first``)."""
    i_last = cells[length - 1, 0]
    j_first, j_last = float(cells[0, 1]), float(cells[length - 1, 1])
    if length < 2 or i_last <= 0 or not j_last > j_first:
        return -1
    n = max(int(np.round(i_last / knot_spacing)) + 3, 4)
    kn = knots(n)
    A = np.zeros((n, 4))
    rhs = np.zeros(n)
    N = np.empty(4)
    for p in range(length):
        k0 = basis4(kn, n, cells[p, 0] / i_last, N)
        y = float(cells[p, 1])
        for a in range(4):
            rhs[k0 + a] += N[a] * y
            for b in range(a + 1):
                A[k0 + a, a - b] += N[a] * N[b]
    _penalty(kn, n, smoothing, A)
    # fixed ends: move their columns to the right-hand side, solve for the free ones
    coef = np.zeros(n)
    coef[0], coef[n - 1] = j_first, j_last
    for i in range(1, n - 1):
        for d in range(4):
            c = i - d
            if c == 0 or c == n - 1:
                rhs[i] -= A[i, d] * coef[c]
        for d in range(1, 4):
            r = i + d
            if r == n - 1:
                rhs[i] -= A[r, d] * coef[r]
    if not _band_cholesky_solve(A, rhs, 1, n - 1):
        return -1
    for i in range(1, n - 1):
        coef[i] = rhs[i]
    # strictly increasing, steps of at least 1% of the mean step, inside [first, last]
    eps = 0.01 * (j_last - j_first) / (n - 1)
    run = -np.inf
    for k in range(n):
        run = max(run, coef[k] - eps * k)
        coef[k] = min(run + eps * k, j_last - eps * (n - 1 - k))
    coef[0] = j_first
    for t in range(i_last + 1):
        k0 = basis4(kn, n, min(t / i_last, 1.0), N)
        curve[t] = N[0] * coef[k0] + N[1] * coef[k0 + 1] + N[2] * coef[k0 + 2] + N[3] * coef[k0 + 3]
    return i_last + 1


@njit(cache=True, nogil=True, inline="always")
def lerp(a, b, w):
    """``a + w (b - a)``, and ``a`` itself at ``w = 0`` (its sign of zero kept)."""
    return a if w == 0.0 else a + w * (b - a)


@njit(cache=True, nogil=True)
def split_time(x, n):
    """Frames ``i0``, ``i1`` and weight ``w`` to sample a clip of ``n`` frames at fractional frame
    ``x`` (clamped to ``[0, n - 1]``), as :func:`torchsplice.align.curve.slerp_frames` does."""
    top = n - 1
    x = min(max(x, 0.0), float(top))
    i0 = int(math.floor(x))
    return i0, min(i0 + 1, top), x - i0


@njit(cache=True, nogil=True)
def resample_clip(rot, trans, start, n, times, T, joints, out_rot, out_trans):
    """Frames ``start .. start + n - 1`` of a clip sampled at ``times[:T]`` (fractional, relative
    to ``start``, clamped to ``[0, n - 1]``) for ``joints``: slerp of ``rot`` ``(., J, 4)`` and
    linear ``trans`` ``(., J, 3)`` into ``out_rot``/``out_trans`` ``(T, J, .)``."""
    for t in range(T):
        i0, i1, w = split_time(times[t], n)
        for j in joints:
            qstore(out_rot, t, j, qslerp(qload(rot, start + i0, j), qload(rot, start + i1, j), w))
            for c in range(3):
                out_trans[t, j, c] = lerp(trans[start + i0, j, c], trans[start + i1, j, c], w)
