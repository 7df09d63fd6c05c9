"""Horn's closed-form best rotation (Horn 1987, quaternion form), compiled, one cloud at a time.

For clouds ``source, target (K, 3)`` (pivot at the origin) and weights ``w (K,)``, the unit
quaternion ``q`` (WXYZ, ``w >= 0``) minimises ``sum_k w_k |target_k - q source_k|^2`` over
proper rotations. With ``H = sum_k w_k source_k target_k^T``, ``q`` is the eigenvector of the
largest eigenvalue of Horn's symmetric traceless 4x4 matrix ``N(H)`` (the same ``N`` as
:func:`torchsplice.align.horn.horn_rotation_eig`).

Instead of a 4x4 eigensolver (or the batched LAPACK SVD of the torch version), the largest
eigenvalue is found by Newton's method on the characteristic polynomial
``P(l) = l^4 - tr(N^2)/2 l^2 - tr(N^3)/3 l + det N``, started above every root (at
``sqrt(3) |H|_F``, a bound on ``s1 + s2 + s3``). All roots of ``P`` are real, so ``P`` is convex
right of its largest root and the iteration descends monotonically onto it (the "QCP" idea of
Theobald 2005). The eigenvector is a column of the adjugate of ``N - l I`` (the one with the
largest diagonal cofactor). Degenerate inputs follow the SVD form's rules: ``H ~ 0`` gives the
identity; a rank-1 ``H`` (collinear clouds, one point) gives the smallest rotation taking the
source line onto the target line. ``H`` is scaled to unit norm first, so clouds of any size
(micrometres or kilometres) give unit quaternions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .quat import qcanonical, qnormalize

__all__ = ["horn_from_h", "horn_cloud", "horn_batch"]

_EPS = np.finfo(np.float64).eps
_TINY_SQRT = math.sqrt(np.finfo(np.float64).tiny)


@njit(cache=True, inline="always")
def _minor(m, r0, r1, r2, c0, c1, c2):
    """Determinant of rows ``r*`` and columns ``c*`` of the 4x4 tuple matrix ``m``."""
    return (m[r0][c0] * (m[r1][c1] * m[r2][c2] - m[r1][c2] * m[r2][c1])
            - m[r0][c1] * (m[r1][c0] * m[r2][c2] - m[r1][c2] * m[r2][c0])
            + m[r0][c2] * (m[r1][c0] * m[r2][c1] - m[r1][c1] * m[r2][c0]))


@njit(cache=True)
def _min_rotation(ux, uy, uz, vx, vy, vz):
    """Smallest rotation taking unit ``u`` onto unit ``v`` (half turn about a fixed
    perpendicular axis for antipodal vectors), as the torch form does."""
    d = ux * vx + uy * vy + uz * vz
    if 1.0 + d < 1e-6:
        ax, ay, az = abs(ux), abs(uy), abs(uz)
        if ax <= ay and ax <= az:
            ex, ey, ez = 1.0, 0.0, 0.0
        elif ay <= az:
            ex, ey, ez = 0.0, 1.0, 0.0
        else:
            ex, ey, ez = 0.0, 0.0, 1.0
        return qcanonical(qnormalize((0.0, uy * ez - uz * ey, uz * ex - ux * ez, ux * ey - uy * ex)))
    return qcanonical(qnormalize((1.0 + d, uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx)))


@njit(cache=True)
def _rank1_rotation(sxx, sxy, sxz, syx, syy, syz, szx, szy, szz):
    """For ``H = s u v^T``: ``v`` from H's largest row, ``u`` from its largest column."""
    H = ((sxx, sxy, sxz), (syx, syy, syz), (szx, szy, szz))
    r, c, br, bc = 0, 0, -1.0, -1.0
    for k in range(3):
        nr = H[k][0] * H[k][0] + H[k][1] * H[k][1] + H[k][2] * H[k][2]
        nc = H[0][k] * H[0][k] + H[1][k] * H[1][k] + H[2][k] * H[2][k]
        if nr > br:
            br, r = nr, k
        if nc > bc:
            bc, c = nc, k
    sr, sc = math.sqrt(br), math.sqrt(bc)
    sign = 1.0 if H[r][c] >= 0 else -1.0
    return _min_rotation(H[0][c] / sc, H[1][c] / sc, H[2][c] / sc,
                         sign * H[r][0] / sr, sign * H[r][1] / sr, sign * H[r][2] / sr)


@njit(cache=True)
def horn_from_h(sxx, sxy, sxz, syx, syy, syz, szx, szy, szz):
    """The rotation (WXYZ tuple, ``w >= 0``) from the cross-covariance entries ``S_ab = H[a, b]``."""
    # the rotation does not depend on H's scale: work on H / |H|_F (no overflow, and the
    # adjugate below stays of order one, so the quaternion normalises cleanly)
    big = max(abs(sxx), abs(sxy), abs(sxz), abs(syx), abs(syy), abs(syz), abs(szx), abs(szy), abs(szz))
    if not big > 0.0 or not math.isfinite(big):
        return (1.0, 0.0, 0.0, 0.0)
    sxx, sxy, sxz, syx, syy, syz, szx, szy, szz = (sxx / big, sxy / big, sxz / big, syx / big, syy / big, syz / big,
                                                  szx / big, szy / big, szz / big)
    f = math.sqrt(sxx * sxx + sxy * sxy + sxz * sxz + syx * syx + syy * syy + syz * syz + szx * szx + szy * szy + szz * szz)
    if big * f <= _TINY_SQRT:
        return (1.0, 0.0, 0.0, 0.0)
    sxx, sxy, sxz, syx, syy, syz, szx, szy, szz = (sxx / f, sxy / f, sxz / f, syx / f, syy / f, syz / f,
                                                  szx / f, szy / f, szz / f)
    fro = fro2 = 1.0
    # cofactor norm ~ s1 s2: rank 1 when s2 <= 1e3 eps s1 (the torch form's test)
    c00, c01, c02 = syy * szz - syz * szy, syz * szx - syx * szz, syx * szy - syy * szx
    c10, c11, c12 = sxz * szy - sxy * szz, sxx * szz - sxz * szx, sxy * szx - sxx * szy
    c20, c21, c22 = sxy * syz - sxz * syy, sxz * syx - sxx * syz, sxx * syy - sxy * syx
    cof = math.sqrt(c00 * c00 + c01 * c01 + c02 * c02 + c10 * c10 + c11 * c11 + c12 * c12 + c20 * c20 + c21 * c21 + c22 * c22)
    if cof <= 1e3 * _EPS * fro2:
        return _rank1_rotation(sxx, sxy, sxz, syx, syy, syz, szx, szy, szz)
    n00, n01, n02, n03 = sxx + syy + szz, syz - szy, szx - sxz, sxy - syx
    n11, n12, n13 = sxx - syy - szz, sxy + syx, szx + sxz
    n22, n23 = -sxx + syy - szz, syz + szy
    n33 = -sxx - syy + szz
    n = ((n00, n01, n02, n03), (n01, n11, n12, n13), (n02, n12, n22, n23), (n03, n13, n23, n33))
    tr2 = 0.0
    tr3 = 0.0
    for a in range(4):
        for b in range(4):
            tr2 += n[a][b] * n[a][b]
            tr3 += (n[a][0] * n[0][b] + n[a][1] * n[1][b] + n[a][2] * n[2][b] + n[a][3] * n[3][b]) * n[b][a]
    det = (n00 * _minor(n, 1, 2, 3, 1, 2, 3) - n01 * _minor(n, 1, 2, 3, 0, 2, 3)
           + n02 * _minor(n, 1, 2, 3, 0, 1, 3) - n03 * _minor(n, 1, 2, 3, 0, 1, 2))
    c2, c1, c0 = -0.5 * tr2, -tr3 / 3.0, det
    lam = math.sqrt(3.0) * fro
    for _ in range(100):
        p = ((lam * lam + c2) * lam + c1) * lam + c0
        dp = (4.0 * lam * lam + 2.0 * c2) * lam + c1
        if dp <= 0.0:
            break
        step = p / dp
        lam -= step
        if abs(step) <= 1e-15 * fro:
            break
    a = ((n00 - lam, n01, n02, n03), (n01, n11 - lam, n12, n13), (n02, n12, n22 - lam, n23), (n03, n13, n23, n33 - lam))
    # the adjugate's column with the largest diagonal cofactor
    d0, d1 = abs(_minor(a, 1, 2, 3, 1, 2, 3)), abs(_minor(a, 0, 2, 3, 0, 2, 3))
    d2, d3 = abs(_minor(a, 0, 1, 3, 0, 1, 3)), abs(_minor(a, 0, 1, 2, 0, 1, 2))
    if d0 >= d1 and d0 >= d2 and d0 >= d3:
        v = (_minor(a, 1, 2, 3, 1, 2, 3), -_minor(a, 1, 2, 3, 0, 2, 3), _minor(a, 1, 2, 3, 0, 1, 3), -_minor(a, 1, 2, 3, 0, 1, 2))
    elif d1 >= d2 and d1 >= d3:
        v = (-_minor(a, 0, 2, 3, 1, 2, 3), _minor(a, 0, 2, 3, 0, 2, 3), -_minor(a, 0, 2, 3, 0, 1, 3), _minor(a, 0, 2, 3, 0, 1, 2))
    elif d2 >= d3:
        v = (_minor(a, 0, 1, 3, 1, 2, 3), -_minor(a, 0, 1, 3, 0, 2, 3), _minor(a, 0, 1, 3, 0, 1, 3), -_minor(a, 0, 1, 3, 0, 1, 2))
    else:
        v = (-_minor(a, 0, 1, 2, 1, 2, 3), _minor(a, 0, 1, 2, 0, 2, 3), -_minor(a, 0, 1, 2, 0, 1, 3), _minor(a, 0, 1, 2, 0, 1, 2))
    return qcanonical(qnormalize((v[0], v[1], v[2], v[3])))


@njit(cache=True)
def horn_cloud(source, target, weights):
    """Rotation of one cloud: ``source, target (K, 3)``, ``weights (K,)`` (an empty array:
    uniform ``1 / K``); a WXYZ tuple."""
    h00 = h01 = h02 = h10 = h11 = h12 = h20 = h21 = h22 = 0.0
    K = source.shape[0]
    uniform = weights.shape[0] == 0
    for k in range(K):
        w = 1.0 / K if uniform else weights[k]
        sx, sy, sz = w * source[k, 0], w * source[k, 1], w * source[k, 2]
        tx, ty, tz = target[k, 0], target[k, 1], target[k, 2]
        h00 += sx * tx
        h01 += sx * ty
        h02 += sx * tz
        h10 += sy * tx
        h11 += sy * ty
        h12 += sy * tz
        h20 += sz * tx
        h21 += sz * ty
        h22 += sz * tz
    return horn_from_h(h00, h01, h02, h10, h11, h12, h20, h21, h22)


@njit(cache=True, parallel=True)
def horn_batch(source, target, weights, out):
    """``out[n] = horn_cloud(source[n], target[n], weights)`` for ``(N, K, 3)`` clouds, in parallel."""
    for i in prange(source.shape[0]):
        q = horn_cloud(source[i], target[i], weights)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = q
