"""A careful per-pair NumPy splicer: the benchmark's fair peer.

What a careful user would write without torchsplice: the same method and parameters as
``torchsplice.splice`` (heading-restricted frame distance, windowed phase crop, slope-limited
DP with the same tie-breaking, the same B-spline curve, slerp resampling, per-frame Horn
rotation, posture transfer in the heading frame), one pair at a time, every step vectorised
in NumPy:

- forward kinematics loops over joints only, vectorised over frames;
- the distance grid is a few matrix products over all frame pairs;
- the DP runs along anti-diagonals (every cell of a diagonal depends only on the two before
  it), vectorised over the cells of each diagonal;
- the curve's basis is built for all path cells at once; Horn's rotations are one batched SVD.

The benchmark times it against the compiled batch splicer and checks that both give the same
clips. Quaternions are WXYZ; positions ``(T, J, 3)``; the up axis is the spec's.
"""

from __future__ import annotations

import math

import numpy as np


# -- rotations, vectorised over leading dimensions --------------------------------------------
def qmul(p, q):
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack([pw * qw - px * qx - py * qy - pz * qz, pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx, pw * qz + px * qy - py * qx + pz * qw], -1)


def qconj(q):
    return q * np.array([1.0, -1, -1, -1])


def qrot(q, v):
    w, xyz = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(xyz, v)
    return v + w * t + np.cross(xyz, t)


def q2m(q):
    w, x, y, z = np.moveaxis(q, -1, 0)
    m = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                  2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                  2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)
    return m.reshape(q.shape[:-1] + (3, 3))


def m2q(m):
    """Shepperd's method, vectorised; ``w >= 0``."""
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    sq = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    cand = np.stack([np.stack([sq[..., 0], m21 - m12, m02 - m20, m10 - m01], -1),
                     np.stack([m21 - m12, sq[..., 1], m10 + m01, m02 + m20], -1),
                     np.stack([m02 - m20, m10 + m01, sq[..., 2], m12 + m21], -1),
                     np.stack([m10 - m01, m20 + m02, m21 + m12, sq[..., 3]], -1)], -2)
    q = np.take_along_axis(cand, sq.argmax(-1)[..., None, None], -2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def slerp(p, q, t):
    """Shorter-arc slerp of ``(..., 4)`` quaternions, ``t`` broadcast over ``(...)``."""
    t = np.asarray(t)[..., None]
    d = np.sum(p * q, -1, keepdims=True)
    q = np.where(d < 0, -q, q)
    d = np.minimum(np.abs(d), 1.0)
    th = np.arccos(d)
    s = np.sin(th)
    near = s < 1e-6
    safe = np.where(near, 1.0, s)
    wp = np.where(near, 1.0 - t, np.sin((1.0 - t) * th) / safe)
    wq = np.where(near, t, np.sin(t * th) / safe)
    r = wp * p + wq * q
    r = r / np.maximum(np.linalg.norm(r, axis=-1, keepdims=True), 1e-12)
    return np.where(t == 0, p, r)


# -- kinematics ----------------------------------------------------------------------------------
def fk(rot, trans, parents):
    """Global positions ``(T, J, 3)`` and rotations ``(T, J, 4)``; loop over joints only."""
    pos, glob = np.zeros(trans.shape), np.zeros(rot.shape)
    for j, p in enumerate(parents):
        if p < 0:
            glob[:, j], pos[:, j] = rot[:, j], trans[:, j]
        else:
            glob[:, j] = qmul(glob[:, p], rot[:, j])
            pos[:, j] = pos[:, p] + qrot(glob[:, p], trans[:, j])
    return pos, glob


def heading(lh, rh, up):
    a1, a2 = (up + 1) % 3, (up + 2) % 3
    d = lh - rh
    return np.arctan2(-d[..., a1], d[..., a2])


def heading_q(lh, rh, up):
    lat = 1 if up == 0 else 0
    third = 3 - lat - up
    v = lh - rh
    v[..., up] = 0
    v = v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)
    u = np.broadcast_to(np.eye(3)[up], v.shape)
    other = np.cross(v, u) * (1 if (up - lat) % 3 == 1 else -1)
    M = np.zeros(v.shape[:-1] + (3, 3))
    M[..., :, lat], M[..., :, up], M[..., :, third] = v, u, other
    return m2q(M)


# -- time alignment ----------------------------------------------------------------------------
def wrap(x):
    return np.remainder(x + math.pi, 2 * math.pi) - math.pi


def distance_grid(ca, cb, ha, hb, window, up):
    """Whole ``(Ta, Tb)`` grid by matrix products; ``ca (Ta, K, 3)``, ``cb (Tb, K, 3)``."""
    a1, a2 = (up + 1) % 3, (up + 2) % 3
    w = 1.0 / ca.shape[1]
    fa = ca[..., [a1, a2]] - ca[..., [a1, a2]].mean(1, keepdims=True)
    fb = cb[..., [a1, a2]] - cb[..., [a1, a2]].mean(1, keepdims=True)
    perp = np.stack([fa[..., 1], -fa[..., 0]], -1)
    C = w * fa.reshape(len(fa), -1) @ fb.reshape(len(fb), -1).T
    S = w * perp.reshape(len(fa), -1) @ fb.reshape(len(fb), -1).T
    ya, yb = ca[..., up], cb[..., up]
    base = (w * ((fa ** 2).sum((1, 2)) + (ya ** 2).sum(1)))[:, None] + (w * ((fb ** 2).sum((1, 2)) + (yb ** 2).sum(1)))[None, :]
    Y = w * ya @ yb.T
    r, th = np.hypot(C, S), np.arctan2(S, C)
    e = wrap(th - (ha[:, None] - hb[None, :]))
    return np.maximum(base - 2 * (Y + r * np.cos(e - np.clip(e, -window, window))), 0.0)


def phase_crop(G, context, window, depth=0.25):
    Ta, Tb = G.shape
    W = max(1, min(context, Ta, Tb // 2))
    j = np.arange(Tb)
    allowed = (j + W <= Tb) & (j <= (Tb - 1) // 2)
    cols = np.minimum(j[None, :] + np.arange(W)[:, None], Tb - 1)
    d = np.where(allowed, G[np.arange(W)[:, None], cols].mean(0), np.inf)
    padded = np.concatenate([np.full(window, np.inf), d, np.full(window, np.inf)])
    nb_min = np.lib.stride_tricks.sliding_window_view(padded, 2 * window + 1).min(1)
    lo, hi = d[allowed].min(), d[allowed].max()
    ok = allowed & (d <= nb_min) & (d <= lo + depth * (hi - lo))
    return int(np.argmax(ok)) if ok.any() else 0


def timewarp(G, L):
    """Slope-limited DP along anti-diagonals; min-average end on the top/right edge; the path."""
    Ta, Tb = G.shape
    S = 2 * L + 1
    inf = np.inf
    bp = np.zeros((3, Ta, Tb), np.int8)
    top_sum, top_cnt = np.full((S, Tb), inf), np.zeros((S, Tb), np.int64)
    right_sum, right_cnt = np.full((S, Ta), inf), np.zeros((S, Ta), np.int64)
    # states on the two previous diagonals, indexed by row i (plus a guard row at i = -1)
    p1s, p1c = np.full((S, Ta + 1), inf), np.zeros((S, Ta + 1), np.int64)
    p2s, p2c = p1s.copy(), p1c.copy()
    h1_from = np.array([0] + list(range(L + 1, S)))
    for d in range(Ta + Tb - 1):
        i = np.arange(max(0, d - Tb + 1), min(d, Ta - 1) + 1)
        j = d - i
        g = G[i, j]
        cs, cc = np.full((S, Ta + 1), inf), np.zeros((S, Ta + 1), np.int64)
        k = i + 1  # guard-shifted row index
        # D from (i-1, j-1): diagonal d-2, row i-1
        a = np.argmin(p2s[:, k - 1], 0)
        cs[0, k] = np.where(j > 0, g + p2s[a, k - 1], inf)
        cc[0, k] = p2c[a, k - 1] + 1
        bp[0, i, j] = a
        if d == 0:
            cs[0, 1], cc[0, 1] = g[0], 1
        # V1 from D or H at (i-1, j); V_c from V_{c-1}: diagonal d-1, row i-1
        a = np.argmin(p1s[: L + 1, k - 1], 0)
        cs[L + 1, k] = g + p1s[a, k - 1]
        cc[L + 1, k] = p1c[a, k - 1] + 1
        bp[2, i, j] = a
        cs[L + 2:, k] = g + p1s[L + 1: S - 1, k - 1]
        cc[L + 2:, k] = p1c[L + 1: S - 1, k - 1] + 1
        # H1 from D or V at (i, j-1); H_c from H_{c-1}: diagonal d-1, row i
        a = np.argmin(p1s[h1_from][:, k], 0)
        src = h1_from[a]
        cs[1, k] = np.where(j > 0, g + p1s[src, k], inf)
        cc[1, k] = p1c[src, k] + 1
        bp[1, i, j] = src
        cs[2: L + 1, k] = np.where(j > 0, g + p1s[1:L, k], inf)
        cc[2: L + 1, k] = p1c[1:L, k] + 1
        top = i == Ta - 1
        top_sum[:, j[top]], top_cnt[:, j[top]] = cs[:, k[top]], cc[:, k[top]]
        right = j == Tb - 1
        right_sum[:, i[right]], right_cnt[:, i[right]] = cs[:, k[right]], cc[:, k[right]]
        p2s, p2c, p1s, p1c = p1s, p1c, cs, cc
    # end: minimal average; ties: top row from the corner leftwards, then the right column downwards
    avg = np.concatenate([(top_sum / np.maximum(top_cnt, 1))[:, ::-1].T.ravel(),
                          (right_sum[:, :-1] / np.maximum(right_cnt[:, :-1], 1))[:, ::-1].T.ravel()])
    best = int(np.argmin(avg))
    if best < S * Tb:
        ei, ej, s = Ta - 1, Tb - 1 - best // S, best % S
        total, n = top_sum[s, ej], top_cnt[s, ej]
    else:
        r = best - S * Tb
        ei, ej, s = Ta - 2 - r // S, Tb - 1, r % S
        total, n = right_sum[s, ei], right_cnt[s, ei]
    path = np.empty((n, 2), np.int64)
    i, j = ei, ej
    for step in range(n - 1, -1, -1):
        path[step] = i, j
        if s == 0:
            s, i, j = bp[0, i, j], i - 1, j - 1
        elif s <= L:
            s, j = (bp[1, i, j] if s == 1 else s - 1), j - 1
        else:
            s, i = (bp[2, i, j] if s == L + 1 else s - 1), i - 1
    return path, total / n


def bspline_basis(u, n):
    """Clamped uniform cubic basis ``(P, n)`` at every ``u (P,)`` in [0, 1] (Cox-de Boor, vectorised)."""
    knots = np.clip((np.arange(n + 4) - 3) / (n - 3), 0, 1)
    u = u[:, None]
    N = ((u >= knots[:-1]) & (u < knots[1:])).astype(float)
    N[u[:, 0] >= 1] = 0
    N[u[:, 0] >= 1, n - 1] = 1
    for d in range(1, 4):
        t0, t1, s0, s1 = knots[: -d - 1], knots[d:-1], knots[1:-d], knots[d + 1:]
        with np.errstate(divide="ignore", invalid="ignore"):
            left = np.where(t1 > t0, (u - t0) / (t1 - t0), 0.0)
            right = np.where(s1 > s0, (s1 - u) / (s1 - s0), 0.0)
        N = left * N[:, :-1] + right * N[:, 1:]
    return N[:, :n]


def fit_curve(path, knot_spacing, smoothing=1e-2):
    i_last, j_first, j_last = path[-1, 0], path[0, 1], path[-1, 1]
    n = max(int(round(i_last / knot_spacing)) + 3, 4)
    Bm = bspline_basis(path[:, 0] / i_last, n)
    knots = np.clip((np.arange(n + 4) - 3) / (n - 3), 0, 1)
    gre = (knots[1:n + 1] + knots[2:n + 2] + knots[3:n + 3]) / 3
    r = np.arange(n - 2)
    h0, h1 = np.maximum(gre[r + 1] - gre[r], 1e-9), np.maximum(gre[r + 2] - gre[r + 1], 1e-9)
    D = np.zeros((n - 2, n))
    D[r, r], D[r, r + 1], D[r, r + 2] = 1 / h0, -(1 / h0 + 1 / h1), 1 / h1
    D /= n - 1
    P = smoothing * D.T @ D
    fixed = np.zeros(n)
    fixed[0], fixed[-1] = j_first, j_last
    free = slice(1, n - 1)
    A = (Bm.T @ Bm + P)[free, free]
    b = (Bm.T @ (path[:, 1] - Bm @ fixed) - P @ fixed)[free]
    c = fixed.copy()
    c[free] = np.linalg.solve(A, b)
    eps = 0.01 * (j_last - j_first) / (n - 1)
    k = np.arange(n)
    c = np.minimum(np.maximum.accumulate(c - eps * k) + eps * k, j_last - eps * (n - 1 - k))
    c[0] = j_first
    return bspline_basis(np.minimum(np.arange(i_last + 1) / i_last, 1.0), n) @ c


def resample(rot, trans, times, n):
    """Rotations (slerp) and translations (linear) of frames ``0..n-1`` at fractional ``times``."""
    t = np.clip(times, 0, n - 1)
    i0 = np.floor(t).astype(int)
    i1 = np.minimum(i0 + 1, n - 1)
    w = t - i0
    return slerp(rot[i0], rot[i1], w[:, None]), trans[i0] + w[:, None, None] * (trans[i1] - trans[i0])


# -- spatial alignment -----------------------------------------------------------------------
def horn(src, tgt):
    """Best proper rotations ``(..., 4)`` for ``(..., K, 3)`` clouds: one batched SVD."""
    U, _, Vt = np.linalg.svd(np.swapaxes(src, -1, -2) @ tgt / src.shape[-2])
    V = np.swapaxes(Vt, -1, -2)
    fix = np.ones(U.shape[:-1])
    fix[..., 2] = np.where(np.linalg.det(V @ np.swapaxes(U, -1, -2)) < 0, -1.0, 1.0)
    return m2q(V @ (fix[..., None] * np.swapaxes(U, -1, -2)))


def splice_pair(loco, act, roles, parents, fps, L=3, window_deg=60.0, crop_context_s=0.5, crop_window_s=0.2,
                knot_spacing_s=0.25):
    """Splice one pair. ``loco``/``act``: dicts of numpy arrays ``rot (T, J, 4)`` and ``trans (T, J, 3)``
    (row 0: the root position). Returns ``(rotations, translations, curve, cost)``."""
    up = roles.up_axis
    pl, gl = fk(loco["rot"], loco["trans"], parents)
    pa, _ = fk(act["rot"], act["trans"], parents)
    lm = [roles.root, *roles.knees]
    hl = heading(pl[:, roles.hips[0]], pl[:, roles.hips[1]], up)
    ha = heading(pa[:, roles.hips[0]], pa[:, roles.hips[1]], up)
    G = distance_grid(pl[:, lm], pa[:, lm], hl, ha, math.radians(window_deg), up)
    crop = phase_crop(G, int(round(crop_context_s * fps)), max(1, int(round(crop_window_s * fps))))
    path, cost = timewarp(G[:, crop:], L)
    curve = fit_curve(path, knot_spacing_s * fps)
    T = len(curve)
    ar, at = resample(act["rot"][crop:], act["trans"][crop:], curve, act["rot"].shape[0] - crop)
    upper = np.zeros(len(parents), bool)
    upper[list(roles.upper_body)] = True
    pel = roles.pelvis

    def assemble(pelvis_rot):
        rot = np.where(upper[:, None], ar, loco["rot"][:T])
        trans = np.where(upper[:, None], at, loco["trans"][:T])
        rot[:, pel], trans[:, pel] = pelvis_rot, loco["trans"][:T, pel]
        return rot, trans

    cloud = [j for j in roles.spine if j != pel] + list(roles.shoulders)

    def pelvis_cloud(p, g):
        return qrot(qconj(g[:, pel])[:, None], p[:, cloud] - p[:, pel][:, None])

    q_lp = loco["rot"][:T, pel]
    rot, trans = assemble(q_lp)
    p0, g0 = fk(rot, trans, parents)
    pelvis = qmul(q_lp, horn(pelvis_cloud(p0, g0), pelvis_cloud(pl[:T], gl[:T])))
    rot, trans = assemble(pelvis)
    ps, gs = fk(rot, trans, parents)
    pr, _ = fk(ar, at, parents)
    sh = list(roles.shoulders)

    def posture(p):
        H = heading_q(p[:, roles.hips[0]].copy(), p[:, roles.hips[1]].copy(), up)
        return qrot(qconj(H)[:, None], p[:, sh] - p[:, pel][:, None]).mean(0), H

    mean_s, H = posture(ps)
    mean_u, _ = posture(pr)
    qg = horn(mean_s, mean_u)
    world = qmul(qmul(H, np.broadcast_to(qg, H.shape)), qconj(H))
    qpar = gs[:, parents[pel]]
    rot[:, pel] = qmul(qmul(qmul(qconj(qpar), world), qpar), pelvis)
    return rot, trans, curve + crop, cost
