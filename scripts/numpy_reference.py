"""A straightforward per-pair NumPy version of the splice, the benchmark's reference.

It follows the same steps and parameters as ``torchsplice.splice`` (heading-restricted frame
distance, windowed phase crop, slope-limited DP with the same tie-breaking, the same B-spline
curve, slerp resampling, per-frame Horn by SVD, posture transfer in the heading frame), written
the obvious way: one pair at a time, loops over frames, cells and joints. The benchmark times
it against the batched torch code and checks that both give the same clips.

Quaternions are WXYZ; ``pos`` arrays are ``(T, J, 3)``; Y (or the spec's axis) is up.
"""

from __future__ import annotations

import math

import numpy as np


# -- rotations -------------------------------------------------------------------------------
def qmul(p, q):
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return np.array([pw * qw - px * qx - py * qy - pz * qz, pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx, pw * qz + px * qy - py * qx + pz * qw])


def qconj(q):
    return q * np.array([1.0, -1, -1, -1])


def q2m(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def m2q(m):
    tr = np.trace(m)
    cands = [1 + tr, 1 + m[0, 0] - m[1, 1] - m[2, 2], 1 - m[0, 0] + m[1, 1] - m[2, 2], 1 - m[0, 0] - m[1, 1] + m[2, 2]]
    k = int(np.argmax(cands))
    if k == 0:
        q = [cands[0], m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]
    elif k == 1:
        q = [m[2, 1] - m[1, 2], cands[1], m[1, 0] + m[0, 1], m[0, 2] + m[2, 0]]
    elif k == 2:
        q = [m[0, 2] - m[2, 0], m[1, 0] + m[0, 1], cands[2], m[1, 2] + m[2, 1]]
    else:
        q = [m[1, 0] - m[0, 1], m[2, 0] + m[0, 2], m[2, 1] + m[1, 2], cands[3]]
    q = np.array(q) / np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def slerp(p, q, t):
    if t == 0:
        return p
    d = float(np.dot(p, q))
    if d < 0:
        q, d = -q, -d
    d = min(d, 1.0)
    th = math.acos(d)
    s = math.sin(th)
    if s < 1e-6:
        r = (1 - t) * p + t * q
    else:
        r = math.sin((1 - t) * th) / s * p + math.sin(t * th) / s * q
    return r / np.linalg.norm(r)


# -- kinematics ------------------------------------------------------------------------------
def fk(rot, trans, parents):
    """Per frame, per joint: global positions (T, J, 3) and rotation matrices (T, J, 3, 3)."""
    T, J = rot.shape[:2]
    pos, glob = np.zeros((T, J, 3)), np.zeros((T, J, 3, 3))
    for t in range(T):
        for j, p in enumerate(parents):
            R = q2m(rot[t, j])
            if p < 0:
                glob[t, j], pos[t, j] = R, trans[t, j]
            else:
                glob[t, j] = glob[t, p] @ R
                pos[t, j] = pos[t, p] + glob[t, p] @ trans[t, j]
    return pos, glob


def heading(lh, rh, up):
    a1, a2 = (up + 1) % 3, (up + 2) % 3
    d = np.cross(lh - rh, np.eye(3)[up])
    return math.atan2(d[a2], d[a1])


def heading_matrix(lh, rh, up):
    lat = 1 if up == 0 else 0
    third = 3 - lat - up
    v = lh - rh
    v[up] = 0
    v = v / np.linalg.norm(v)
    u = np.eye(3)[up]
    other = np.cross(v, u) * (1 if (up - lat) % 3 == 1 else -1)
    M = np.zeros((3, 3))
    M[:, lat], M[:, up], M[:, third] = v, u, other
    return M


# -- time alignment --------------------------------------------------------------------------
def wrap(x):
    return (x + math.pi) % (2 * math.pi) - math.pi


def frame_distance(a, b, ha, hb, window, up):
    """The closed form for one pair of clouds (K, 3)."""
    a1, a2 = (up + 1) % 3, (up + 2) % 3
    fa, fb = a[:, [a1, a2]] - a[:, [a1, a2]].mean(0), b[:, [a1, a2]] - b[:, [a1, a2]].mean(0)
    w = 1.0 / len(a)
    C = w * np.sum(fa * fb)
    S = w * np.sum(fb[:, 0] * fa[:, 1] - fb[:, 1] * fa[:, 0])
    base = w * (np.sum(fa ** 2) + np.sum(fb ** 2)) + w * np.sum((a[:, up] - b[:, up]) ** 2)
    r, th = math.hypot(C, S), math.atan2(S, C)
    e = wrap(th - (ha - hb))
    return max(base - 2 * r * math.cos(e - min(max(e, -window), window)), 0.0)


def distance_grid(ca, cb, ha, hb, window, up):
    G = np.zeros((len(ca), len(cb)))
    for i in range(len(ca)):
        for j in range(len(cb)):
            G[i, j] = frame_distance(ca[i], cb[j], ha[i], hb[j], window, up)
    return G


def phase_crop(G, context, window, depth=0.25):
    Ta, Tb = G.shape
    W = max(1, min(context, Ta, Tb // 2))
    d = np.full(Tb, np.inf)
    for j in range(Tb):
        if j + W <= Tb and j <= (Tb - 1) // 2:
            d[j] = np.mean([G[k, j + k] for k in range(W)])
    ok = np.isfinite(d)
    lo, hi = d[ok].min(), d[ok].max()
    for j in range(Tb):
        nb = d[max(0, j - window): j + window + 1]
        if ok[j] and d[j] <= nb.min() and d[j] <= lo + depth * (hi - lo):
            return j
    return 0


def timewarp(G, L):
    """Cell-by-cell DP over states D, H1..HL, V1..VL; min-average end on the top/right edge."""
    Ta, Tb = G.shape
    S = 2 * L + 1
    tot = np.full((Ta, Tb, S), np.inf)
    cnt = np.zeros((Ta, Tb, S), dtype=int)
    back = {}
    for i in range(Ta):
        for j in range(Tb):
            g = G[i, j]
            if i == 0 and j == 0:
                tot[0, 0, 0], cnt[0, 0, 0] = g, 1
                continue
            if i > 0 and j > 0:
                s = int(np.argmin(tot[i - 1, j - 1]))
                tot[i, j, 0], cnt[i, j, 0] = g + tot[i - 1, j - 1, s], cnt[i - 1, j - 1, s] + 1
                back[i, j, 0] = (i - 1, j - 1, s)
            if j > 0:
                src = [0] + list(range(L + 1, S))
                s = src[int(np.argmin(tot[i, j - 1, src]))]
                tot[i, j, 1], cnt[i, j, 1] = g + tot[i, j - 1, s], cnt[i, j - 1, s] + 1
                back[i, j, 1] = (i, j - 1, s)
                for c in range(2, L + 1):
                    tot[i, j, c], cnt[i, j, c] = g + tot[i, j - 1, c - 1], cnt[i, j - 1, c - 1] + 1
                    back[i, j, c] = (i, j - 1, c - 1)
            if i > 0:
                s = int(np.argmin(tot[i - 1, j, : L + 1]))
                tot[i, j, L + 1], cnt[i, j, L + 1] = g + tot[i - 1, j, s], cnt[i - 1, j, s] + 1
                back[i, j, L + 1] = (i - 1, j, s)
                for c in range(L + 2, S):
                    tot[i, j, c], cnt[i, j, c] = g + tot[i - 1, j, c - 1], cnt[i - 1, j, c - 1] + 1
                    back[i, j, c] = (i - 1, j, c - 1)
    best, end = np.inf, None
    cells = [(Ta - 1, j) for j in range(Tb - 1, -1, -1)] + [(i, Tb - 1) for i in range(Ta - 2, -1, -1)]
    for (i, j) in cells:
        for s in range(S):
            if np.isfinite(tot[i, j, s]):
                avg = tot[i, j, s] / cnt[i, j, s]
                if avg < best:
                    best, end = avg, (i, j, s)
    path, cur = [], end
    while True:
        path.append(cur[:2])
        if cur[:2] == (0, 0):
            break
        cur = back[cur]
    return np.array(path[::-1]), best


def bspline_basis(u, n):
    """Clamped uniform cubic basis values (n,) at u in [0, 1], Cox-de Boor, one point at a time."""
    knots = np.clip((np.arange(n + 4) - 3) / (n - 3), 0, 1)
    N = np.array([1.0 if knots[k] <= u < knots[k + 1] else 0.0 for k in range(n + 3)])
    if u >= 1:
        N[:] = 0
        N[n - 1] = 1
    for d in range(1, 4):
        M = np.zeros(n + 3 - d)
        for k in range(n + 3 - d):
            left = (u - knots[k]) / (knots[k + d] - knots[k]) * N[k] if knots[k + d] > knots[k] else 0.0
            right = (knots[k + d + 1] - u) / (knots[k + d + 1] - knots[k + 1]) * N[k + 1] if knots[k + d + 1] > knots[k + 1] else 0.0
            M[k] = left + right
        N = M
    return N


def fit_curve(path, knot_spacing, smoothing=1e-2):
    i_last, j_first, j_last = path[-1, 0], path[0, 1], path[-1, 1]
    n = max(int(round(i_last / knot_spacing)) + 3, 4)
    Bm = np.array([bspline_basis(i / i_last, n) for i, _ in path])
    knots = np.clip((np.arange(n + 4) - 3) / (n - 3), 0, 1)
    gre = (knots[1:n + 1] + knots[2:n + 2] + knots[3:n + 3]) / 3
    D = np.zeros((n - 2, n))
    for r in range(n - 2):
        h0, h1 = max(gre[r + 1] - gre[r], 1e-9), max(gre[r + 2] - gre[r + 1], 1e-9)
        D[r, r], D[r, r + 1], D[r, r + 2] = 1 / h0, -(1 / h0 + 1 / h1), 1 / h1
    D /= n - 1
    P = smoothing * D.T @ D
    fixed = np.zeros(n)
    fixed[0], fixed[-1] = j_first, j_last
    y = path[:, 1] - Bm @ fixed
    free = slice(1, n - 1)
    A = (Bm.T @ Bm + P)[free, free]
    b = (Bm.T @ y - P @ fixed)[free]
    c = fixed.copy()
    c[free] = np.linalg.solve(A, b)
    eps = 0.01 * (j_last - j_first) / (n - 1)
    for k in range(1, n):
        c[k] = max(c[k], c[k - 1] + eps)
    for k in range(n - 2, 0, -1):
        c[k] = min(c[k], j_last - eps * (n - 1 - k))
    c[0], c[-1] = j_first, j_last
    return np.array([bspline_basis(t / i_last, n) @ c for t in range(int(i_last) + 1)])


# -- spatial alignment -----------------------------------------------------------------------
def horn(src, tgt):
    U, _, Vt = np.linalg.svd(src.T @ tgt)
    V = Vt.T
    d = np.sign(np.linalg.det(V @ U.T)) or 1.0
    return m2q(V @ np.diag([1, 1, d]) @ U.T)


def splice_pair(loco, act, roles, parents, fps, L=3, window_deg=60.0, crop_context_s=0.5, crop_window_s=0.2,
                knot_spacing_s=0.25):
    """Splice one pair. ``loco``/``act``: dicts of numpy arrays ``rot`` (T, J, 4) and ``trans`` (T, J, 3)."""
    up = roles.up_axis
    pl, gl = fk(loco["rot"], loco["trans"], parents)
    pa, _ = fk(act["rot"], act["trans"], parents)
    lm = [roles.root, *roles.knees]
    hl = [heading(p[roles.hips[0]], p[roles.hips[1]], up) for p in pl]
    ha = [heading(p[roles.hips[0]], p[roles.hips[1]], up) for p in pa]
    G = distance_grid(pl[:, lm], pa[:, lm], hl, ha, math.radians(window_deg), up)
    crop = phase_crop(G, int(round(crop_context_s * fps)), max(1, int(round(crop_window_s * fps))))
    path, cost = timewarp(G[:, crop:], L)
    curve = fit_curve(path, knot_spacing_s * fps)
    T = len(curve)
    n_act = act["rot"].shape[0] - crop
    upper = set(roles.upper_body)
    rot = loco["rot"][:T].copy()
    trans = loco["trans"][:T].copy()
    for t, lam in enumerate(curve):
        i0 = min(int(math.floor(lam)), n_act - 1)
        i1 = min(i0 + 1, n_act - 1)
        w = lam - i0
        for j in upper:
            rot[t, j] = slerp(act["rot"][crop + i0, j], act["rot"][crop + i1, j], w)
            if j != roles.pelvis:
                trans[t, j] = act["trans"][crop + i0, j] + w * (act["trans"][crop + i1, j] - act["trans"][crop + i0, j])
        rot[t, roles.pelvis] = loco["rot"][t, roles.pelvis]
    cloud = [j for j in roles.spine if j != roles.pelvis] + list(roles.shoulders)
    p0, g0 = fk(rot, trans, parents)
    for t in range(T):
        src = (p0[t, cloud] - p0[t, roles.pelvis]) @ g0[t, roles.pelvis]
        tgt = (pl[t, cloud] - pl[t, roles.pelvis]) @ gl[t, roles.pelvis]
        rot[t, roles.pelvis] = qmul(loco["rot"][t, roles.pelvis], horn(src, tgt))
    ps, gs = fk(rot, trans, parents)
    # posture: the action resampled along the curve, and the spliced-so-far motion
    act_r = np.zeros((T,) + act["rot"].shape[1:])
    for t, lam in enumerate(curve):
        i0 = min(int(math.floor(lam)), n_act - 1)
        i1 = min(i0 + 1, n_act - 1)
        for j in range(act_r.shape[1]):
            act_r[t, j] = slerp(act["rot"][crop + i0, j], act["rot"][crop + i1, j], lam - i0)
    act_t = np.array([act["trans"][crop + min(int(math.floor(lam)), n_act - 1)] +
                      (lam - math.floor(lam)) * (act["trans"][crop + min(int(math.floor(lam)) + 1, n_act - 1)] -
                                                 act["trans"][crop + min(int(math.floor(lam)), n_act - 1)]) for lam in curve])
    pr, _ = fk(act_r, act_t, parents)
    sh = list(roles.shoulders)

    def posture(p):
        out, Hs = [], []
        for t in range(T):
            H = heading_matrix(p[t, roles.hips[0]], p[t, roles.hips[1]], up)
            Hs.append(H)
            out.append((p[t, sh] - p[t, roles.pelvis]) @ H)
        return np.mean(out, 0), Hs

    mean_s, Hs = posture(ps)
    mean_u, _ = posture(pr)
    qg = horn(mean_s, mean_u)
    parent = parents[roles.pelvis]
    for t in range(T):
        world = m2q(Hs[t] @ q2m(qg) @ Hs[t].T)
        qpar = m2q(gs[t, parent])
        rot[t, roles.pelvis] = qmul(qmul(qmul(qconj(qpar), world), qpar), rot[t, roles.pelvis])
    return rot, trans, curve + crop, cost
