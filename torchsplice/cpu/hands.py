"""Compiled correction that keeps hands out of the body (:mod:`torchsplice.ops.hands`), clips packed along frames.

The same passes as :func:`torchsplice.ops.hands.keep_hands_out`, one clip per thread: per frame,
FK of the joints needed (``joints``, ascending and closed under parents); then ``iterations``
passes of the push out of every obstacle (closed-form closest points of the forearm's axis and
each obstacle's), taken into the chest's frame, spread in time (the largest push within ``w``
frames, then a Hann window of half-width ``w``) and added to the wrists' displacement, and
two-bone IK of shoulder and elbow onto it, about each elbow's hinge (the clip's mean plane
normal in the upper arm's frame; none, and the chest's, where its mean is ``hinge_min`` or
shorter), its reach's change damped by ``flex`` as there. Shapes: rotations ``(N, J, 4)`` (unit WXYZ,
local; ``out`` the same, written only at the moved joints of changed frames), translations
``(N, J, 3)`` (row 0 the root's position); capsule ends ``end_a``, ``end_b``, ``end_w``
``(2C,)`` as :mod:`.body`'s; per arm (left, right) ``sh``, ``el``, ``wr`` and their parents
``psh``, ``pel`` ``(2,)``; per clip ``target`` (how deep a forearm may stay, the skeleton's
units) and ``w`` (frames); ``corrected`` ``(B,)`` the frames changed.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .quat import qconj, qload, qmul, qrot
from .vec import add as _add, cross as _cross, dot as _dot, length as _length, normalized as _normalized
from .vec import row as _vec, scale as _scale, segment_closest as _closest, sub as _sub

__all__ = ["hands_out_clips"]


@njit(cache=True, inline="always")
def _between(u, v):
    """:func:`torchsplice.core.rotations.quat_between` of unit ``u``, ``v``."""
    d = _dot(u, v)
    if 1.0 + d < 1e-6:
        k = 0
        if abs(u[1]) < abs(u[k]):
            k = 1
        if abs(u[2]) < abs(u[k]):
            k = 2
        basis = (1.0 if k == 0 else 0.0, 1.0 if k == 1 else 0.0, 1.0 if k == 2 else 0.0)
        p = _cross(u, basis)
        q = (0.0, p[0], p[1], p[2])
    else:
        c = _cross(u, v)
        q = (1.0 + d, c[0], c[1], c[2])
    n = max(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), 1e-12)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@njit(cache=True, inline="always")
def _axis_angle(v):
    angle = _length(v)
    half = 0.5 * angle
    s = math.sin(half) / angle if angle > 1e-8 else 0.5 - angle * angle / 48.0
    return (math.cos(half), v[0] * s, v[1] * s, v[2] * s)


@njit(cache=True, nogil=True)
def _chest_hinge(upper, chest):
    """:func:`torchsplice.ops.hands.chest_hinge`: the chest's X axis less its part along the upper
    arm (its Z axis where the arm lies along X)."""
    unit = _scale(upper, 1.0 / max(_length(upper), 1e-300))
    side = qrot(chest, (1.0, 0.0, 0.0))
    side = _sub(side, _scale(unit, _dot(side, unit)))
    if _length(side) > 1e-6:
        return side
    side = qrot(chest, (0.0, 0.0, 1.0))
    return _sub(side, _scale(unit, _dot(side, unit)))


@njit(cache=True, nogil=True)
def _arm_ik(S, E, W, T, hinge, flex):
    """:func:`torchsplice.ops.hands.arm_ik` of one arm: ``(q1, q2, E', W')``."""
    upper, lower = _sub(E, S), _sub(W, E)
    l1 = _length(upper)
    u = _scale(upper, 1.0 / max(l1, 1e-300))
    a = _sub(hinge, _scale(u, _dot(hinge, u)))
    a = _scale(a, 1.0 / max(_length(a), 1e-300))
    flat = _sub(lower, _scale(a, _dot(lower, a)))
    lf, l2 = _length(flat), _length(lower)
    now = math.atan2(-_dot(_cross(u, flat), a), _dot(flat, u))
    d0 = _length(_sub(W, S))
    top = math.sqrt(l1 * l1 + l2 * l2 + 2.0 * l1 * lf)
    bottom = math.sqrt(max(l1 * l1 + l2 * l2 - 2.0 * l1 * lf, 0.0))
    e = (_length(_sub(T, S)) - d0) * (1.0 - math.exp(-(now / flex) ** 2))
    room = max(top - d0 if e > 0.0 else d0 - bottom, 1e-12 * (l1 + l2))
    sign = 1.0 if e > 0.0 else -1.0 if e < 0.0 else 0.0
    reach = d0 + sign * room * -math.expm1(-abs(e) / room)
    want = math.acos(min(max((reach * reach - l1 * l1 - l2 * l2) / max(2.0 * l1 * lf, 1e-300), -1.0), 1.0))
    if now < 0.0:
        want = -want
    q1 = _axis_angle(_scale(a, now - want))
    W1 = _add(E, qrot(q1, lower))
    q2 = _between(_normalized(_sub(W1, S), upper), _normalized(_sub(T, S), upper))
    return q1, q2, _add(S, qrot(q2, upper)), _add(S, qrot(q2, _sub(W1, S)))


@njit(cache=True, nogil=True)
def _push(pos, t, E, W, k, ends, end_a, end_b, end_w, radii, probe, obstacles, target, slack, el, wr):
    """The move of arm ``k``'s wrist (world) out of every obstacle at frame ``t`` (see :mod:`torchsplice.ops.hands`)."""
    pts = np.empty((2, 3))
    for e in range(2):
        row = 2 * probe + e
        for x in range(3):
            ja, jb = end_a[row], end_b[row]
            va = E[t, k, x] if ja == el else W[t, k, x] if ja == wr else pos[t, ja, x]
            vb = E[t, k, x] if jb == el else W[t, k, x] if jb == wr else pos[t, jb, x]
            pts[e, x] = va * (1.0 - end_w[row]) + vb * end_w[row] if end_w[row] != 0.0 else va
    pa, pb = _vec(pts, 0), _vec(pts, 1)
    arm = _length(_sub((W[t, k, 0], W[t, k, 1], W[t, k, 2]), (E[t, k, 0], E[t, k, 1], E[t, k, 2])))
    out = (0.0, 0.0, 0.0)
    for o in obstacles:
        oa, ob = _vec(ends[t], 2 * o), _vec(ends[t], 2 * o + 1)
        s, u = _closest(pa, pb, oa, ob)
        cp = _add(pa, _scale(_sub(pb, pa), s))
        co = _add(oa, _scale(_sub(ob, oa), u))
        excess = radii[o] - _length(_sub(cp, co)) - target
        if excess > 0.0:
            away = _normalized(_sub(cp, co), _sub(cp, _scale(_add(oa, ob), 0.5)))
            lever = min(max(_length(_sub(pb, pa)) / max(arm, 1e-300) * s, 0.5), 2.0)
            out = _add(out, _scale(away, (excess + slack) / lever))
    return out


@njit(cache=True, parallel=True)
def hands_out_clips(rot, trans, parents, joints, end_a, end_b, end_w, radii, probes, obstacles, chest, sh, el, wr, psh,
                    pel, starts, lengths, target, w, slack, iterations, hinge_min, flex, out, corrected):
    """Per clip ``c`` (rows ``starts[c]:starts[c]+lengths[c]``) into ``out`` and ``corrected[c]``
    (see the module docstring)."""
    J = rot.shape[1]
    K = end_a.shape[0]
    for c in prange(starts.shape[0]):
        n, r0, wc = lengths[c], starts[c], w[c]
        pos = np.zeros((n, J, 3))
        grot = np.zeros((n, J, 4))
        ends = np.empty((n, K, 3))
        E = np.empty((n, 2, 3))
        W = np.empty((n, 2, 3))
        D = np.zeros((n, 2, 3))
        P = np.zeros((n, 2, 3))
        widest = np.zeros((n, 2, 3))
        Q = np.zeros((n, 2, 8))  # per arm: q1, q2
        for t in range(n):
            for j in joints:
                p = parents[j]
                q = qload(rot, r0 + t, j)
                if p < 0:
                    grot[t, j, 0], grot[t, j, 1], grot[t, j, 2], grot[t, j, 3] = q
                    pos[t, j, 0], pos[t, j, 1], pos[t, j, 2] = trans[r0 + t, j, 0], trans[r0 + t, j, 1], trans[r0 + t, j, 2]
                else:
                    gp = qload(grot, t, p)
                    grot[t, j, 0], grot[t, j, 1], grot[t, j, 2], grot[t, j, 3] = qmul(gp, q)
                    o = qrot(gp, (trans[r0 + t, j, 0], trans[r0 + t, j, 1], trans[r0 + t, j, 2]))
                    for x in range(3):
                        pos[t, j, x] = pos[t, p, x] + o[x]
            for e in range(K):
                for x in range(3):
                    ends[t, e, x] = pos[t, end_a[e], x] * (1.0 - end_w[e]) + pos[t, end_b[e], x] * end_w[e]
            for k in range(2):
                for x in range(3):
                    E[t, k, x] = pos[t, el[k], x]
                    W[t, k, x] = pos[t, wr[k], x]
        H = np.zeros((2, 3))  # the clip's elbow hinges, in the upper arms' frames (ops.hands.elbow_hinges)
        for k in range(2):
            for t in range(n):
                up = _sub(_vec(E[t], k), _vec(pos[t], sh[k]))
                lo = _sub(_vec(W[t], k), _vec(E[t], k))
                nrm = _scale(_cross(_scale(up, -1.0), lo), 1.0 / max(_length(up) * _length(lo), 1e-300))
                loc = qrot(qconj(qload(grot, t, sh[k])), nrm)
                for x in range(3):
                    H[k, x] += loc[x]
            for x in range(3):
                H[k, x] /= max(n, 1)
            if _length(_vec(H, k)) <= hinge_min:
                H[k, 0] = H[k, 1] = H[k, 2] = 0.0
        moved = np.zeros(n, np.bool_)
        hann = np.empty(2 * wc + 1)  # the spread's weights by offset d = -w..w
        for d in range(2 * wc + 1):
            hann[d] = 1.0 + math.cos(math.pi * (d - wc) / (wc + 1.0))
        for it in range(iterations):
            lo, hi = n, -1  # the frames pushed in this pass
            for t in range(n):
                for k in range(2):
                    for x in range(3):
                        P[t, k, x] = 0.0
                if it > 0 and not moved[t]:
                    continue  # a frame no pass has moved was out already, and is still
                inv = qconj(qload(grot, t, chest))
                for k in range(2):
                    v = _push(pos, t, E, W, k, ends, end_a, end_b, end_w, radii, probes[k], obstacles, target[c], slack,
                              el[k], wr[k])
                    if v[0] != 0.0 or v[1] != 0.0 or v[2] != 0.0:
                        lo, hi = min(lo, t), max(hi, t)
                        v = qrot(inv, v)
                        P[t, k, 0], P[t, k, 1], P[t, k, 2] = v
            if hi < 0:
                break
            # a push reaches w frames by the largest-push step and w more by the window: only the
            # frames within 2 w of one change (the rest would add zeros)
            a0, a1 = max(lo - wc, 0), min(hi + wc, n - 1)
            for t in range(a0, a1 + 1):  # the spread in time: the largest push within w ...
                for k in range(2):
                    best, size = t, -1.0
                    for g in range(max(t - wc, 0), min(t + wc, n - 1) + 1):
                        s2 = P[g, k, 0] * P[g, k, 0] + P[g, k, 1] * P[g, k, 1] + P[g, k, 2] * P[g, k, 2]
                        if s2 > size:
                            best, size = g, s2
                    for x in range(3):
                        widest[t, k, x] = P[best, k, x]
            b0, b1 = max(lo - 2 * wc, 0), min(hi + 2 * wc, n - 1)
            for t in range(b0, b1 + 1):  # ... then a Hann window of half-width w
                den = 0.0
                for f in range(max(t - wc, 0), min(t + wc, n - 1) + 1):
                    den += hann[f - t + wc]
                for k in range(2):
                    num0 = num1 = num2 = 0.0
                    for f in range(max(t - wc, a0), min(t + wc, a1) + 1):
                        weight = hann[f - t + wc]
                        num0 += weight * widest[f, k, 0]
                        num1 += weight * widest[f, k, 1]
                        num2 += weight * widest[f, k, 2]
                    D[t, k, 0] += num0 / den
                    D[t, k, 1] += num1 / den
                    D[t, k, 2] += num2 / den
            for t in range(b0, b1 + 1):  # the IK where the displacement changed
                ch = qload(grot, t, chest)
                for k in range(2):
                    if D[t, k, 0] == 0.0 and D[t, k, 1] == 0.0 and D[t, k, 2] == 0.0:
                        continue
                    moved[t] = True
                    d = qrot(ch, (D[t, k, 0], D[t, k, 1], D[t, k, 2]))
                    S0 = _vec(pos[t], sh[k])
                    W0 = _vec(pos[t], wr[k])
                    E0 = _vec(pos[t], el[k])
                    hk = _vec(H, k)
                    if hk[0] != 0.0 or hk[1] != 0.0 or hk[2] != 0.0:
                        hinge = qrot(qload(grot, t, sh[k]), hk)
                    else:
                        hinge = _chest_hinge(_sub(E0, S0), ch)
                    q1, q2, e2, w2 = _arm_ik(S0, E0, W0, _add(W0, d), hinge, flex)
                    for x in range(4):
                        Q[t, k, x], Q[t, k, 4 + x] = q1[x], q2[x]
                    for x in range(3):
                        E[t, k, x], W[t, k, x] = e2[x], w2[x]
        count = 0
        for t in range(n):
            if not moved[t]:
                continue
            count += 1
            for k in range(2):
                if D[t, k, 0] == 0.0 and D[t, k, 1] == 0.0 and D[t, k, 2] == 0.0:
                    continue
                q1 = (Q[t, k, 0], Q[t, k, 1], Q[t, k, 2], Q[t, k, 3])
                q2 = (Q[t, k, 4], Q[t, k, 5], Q[t, k, 6], Q[t, k, 7])
                ns = qmul(qconj(qload(grot, t, psh[k])), qmul(q2, qload(grot, t, sh[k])))
                ne = qmul(qconj(qload(grot, t, pel[k])), qmul(q1, qload(grot, t, el[k])))
                for x in range(4):
                    out[r0 + t, sh[k], x] = ns[x]
                    out[r0 + t, el[k], x] = ne[x]
        corrected[c] = count
