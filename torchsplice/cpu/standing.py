"""Compiled splicing of standing actions: one pair per thread, as :mod:`.splice` does for the timewarp.

The same steps and results as the torch implementation (:mod:`torchsplice.splice.standing`,
which states the method): the action's frame for every result frame (its best window onto a
locomotion no longer than it, else ``loop``, ``hold`` or ``fit``), the action sampled there
(slerp, linear translations) with each loop seam smoothed by inertialization, and the
assembly of ``splice`` (acting arms and spine from the action, the locomotion's secondary
spine motion on top, idle arms and lower body from the locomotion), ``naive`` (the action's
upper body) or ``cpmc`` (the action's motion since its first frame added to the
locomotion's upper body). Computed in float64, written as the output's dtype.

The choices of frames (:func:`motion_core`, :func:`best_window`, :func:`loop_points`) use the
acting hands' positions in the chest's frame from the bank's float64 FK, with the torch
implementation's formulas, sums in the same order and the same tie tolerance, so that both
choose the same frames.

Inputs index a bank (:class:`torchsplice.cpu.bank.ClipBank`): packed local rotations
``rot (N, J, 4)`` (WXYZ), local translations ``trans (N, J, 3)`` (row 0: root position) and
their FK ``pos``, ``grot``; clip ``c`` is rows ``starts[c] : starts[c] + lengths[c]``.
``sj`` (see :func:`torchsplice.cpu.bank.standing_config`) holds the joint tables: upper-body
mask ``(J,)``, upper spine joints, arm joints ``(2, J)`` (left, right), chest, hands ``(2,)``,
the loop features' joints, and the timing constants (fade frames, match window).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .assemble import standing_rows
from .quat import qconj, qload, qrot

__all__ = ["TIMING_CODES", "CORE_SHARE", "TIE", "hands_in_chest", "motion_core", "best_window", "loop_points",
           "loop_points_batch", "standing_batch"]

TIMING_CODES = {"loop": 0, "hold": 1, "fit": 2}
CORE_SHARE = 0.95  # as torchsplice.splice.standing.CORE_SHARE
TIE = 1e-9  # as torchsplice.splice.standing.TIE


@njit(cache=True, nogil=True)
def hands_in_chest(pos, grot, s, n, chest, hands, out):
    """Rows ``s .. s + n - 1``: both hands in the chest's frame, into ``out (n, 2, 3)``."""
    for t in range(n):
        qc = qconj(qload(grot, s + t, chest))
        for k in range(2):
            h = hands[k]
            v = qrot(qc, (pos[s + t, h, 0] - pos[s + t, chest, 0], pos[s + t, h, 1] - pos[s + t, chest, 1],
                          pos[s + t, h, 2] - pos[s + t, chest, 2]))
            out[t, k, 0], out[t, k, 1], out[t, k, 2] = v


@njit(cache=True, nogil=True)
def motion_core(rel, n, mask):
    """``(first, last)``: the span holding the central :data:`CORE_SHARE` of the path the hands
    ``rel (n, 2, 3)`` travel, weighted by ``mask (2,)`` (see :func:`torchsplice.splice.standing.motion_core`)."""
    path = np.empty(n)
    path[0] = 0.0
    for t in range(1, n):
        e = 0.0
        for k in range(2):
            dx, dy, dz = rel[t, k, 0] - rel[t - 1, k, 0], rel[t, k, 1] - rel[t - 1, k, 1], rel[t, k, 2] - rel[t - 1, k, 2]
            e += math.sqrt(dx * dx + dy * dy + dz * dz) * mask[k]
        path[t] = path[t - 1] + e
    total = path[n - 1]
    if total <= 0:
        return 0, n - 1
    lo, hi = (1 - CORE_SHARE) / 2 * total, (1 + CORE_SHARE) / 2 * total
    first, last = -1, 0
    for t in range(n):
        if path[t] <= lo:
            first += 1
        if path[t] < hi:
            last += 1
    return max(first, 0), min(last, n - 1)


@njit(cache=True, nogil=True)
def best_window(rel, n, mask, m):
    """The first frame of the best window of ``m <= n`` frames of the hands ``rel (n, 2, 3)``:
    the largest mask-weighted sum of per-axis variances (see :func:`torchsplice.splice.standing.best_windows`)."""
    s1 = np.zeros((n + 1, 2, 3))
    s2 = np.zeros((n + 1, 2, 3))
    for t in range(n):
        for k in range(2):
            for c in range(3):
                x = rel[t, k, c]
                s1[t + 1, k, c] = s1[t, k, c] + x
                s2[t + 1, k, c] = s2[t, k, c] + x * x
    count = n - m + 1
    score = np.empty(count)
    best, scale = -np.inf, 0.0
    for w in range(count):
        v = 0.0
        sq = 0.0
        for k in range(2):
            for c in range(3):
                m1 = (s1[w + m, k, c] - s1[w, k, c]) / m
                m2 = (s2[w + m, k, c] - s2[w, k, c]) / m
                v += (m2 - m1 * m1) * mask[k]
                sq += m2 * mask[k]
        score[w] = v
        best = max(best, v)
        scale = max(scale, sq)
    for w in range(count):
        if score[w] >= best - TIE * scale:
            return w
    return 0


@njit(cache=True, nogil=True)
def loop_points(pos, grot, s, n, chest, hands, feat_joints, mask, W):
    """``(start, end)`` of one clip (see :func:`torchsplice.splice.standing.loop_points`): the
    closest pair of windows of ``W`` frames (upper-body ``feat_joints`` in the chest frame), the
    start at or before the main motion of the hands of ``mask`` and the end at or after it."""
    whole_s, whole_e = 0, max(n - 1, 1)
    if n < W + 2:
        return whole_s, whole_e
    rel = np.empty((n, 2, 3))
    hands_in_chest(pos, grot, s, n, chest, hands, rel)
    first, last = motion_core(rel, n, mask)
    e_lo, e_hi = max(last, 1), n - W  # candidate ends
    if e_lo > e_hi:
        return whole_s, whole_e
    F = feat_joints.shape[0]
    feat = np.empty((n, F, 3))
    for t in range(n):
        qc = qconj(qload(grot, s + t, chest))
        for f in range(F):
            j = feat_joints[f]
            v = qrot(qc, (pos[s + t, j, 0] - pos[s + t, chest, 0], pos[s + t, j, 1] - pos[s + t, chest, 1],
                          pos[s + t, j, 2] - pos[s + t, chest, 2]))
            feat[t, f, 0], feat[t, f, 1], feat[t, f, 2] = v
    S = first + 1  # candidate starts 0 .. first
    d = np.full((e_hi - e_lo + 1, S), np.inf)
    best = np.inf
    for e in range(e_lo, e_hi + 1):
        for st in range(min(S, e)):  # start < end
            acc = 0.0
            for f in range(F):
                for c in range(3):
                    for w in range(W):
                        x = feat[e + w, f, c] - feat[st + w, f, c]
                        acc += x * x
            v = math.sqrt(acc)
            d[e - e_lo, st] = v
            best = min(best, v)
    if not best < np.inf:
        return whole_s, whole_e
    for e in range(e_lo, e_hi + 1):
        for st in range(S):
            if d[e - e_lo, st] <= best + TIE * best:
                return st, e
    return whole_s, whole_e


@njit(cache=True, parallel=True, nogil=True)
def loop_points_batch(pos, grot, starts, lengths, clips, masks, chest, hands, feat_joints, W, out):
    """:func:`loop_points` of bank clips ``clips (C,)`` with hand masks ``masks (C, 2)``, in
    parallel, into ``out (C, 2)``."""
    for i in prange(clips.shape[0]):
        c = clips[i]
        st, e = loop_points(pos, grot, starts[c], lengths[c], chest, hands, feat_joints, masks[i], W)
        out[i, 0], out[i, 1] = st, e


@njit(cache=True, nogil=True)
def _standing_one(rot, trans, starts, lengths, loco, act, mask, acting, loop_s, loop_e, method, timing, sj,
                  curve, orot, otrans):
    """One standing pair into rows ``0 .. Tl - 1`` of ``orot``/``otrans`` (the assembly of
    :func:`torchsplice.cpu.assemble.standing_rows`), the action frame of each result frame into
    ``curve``. Returns ``(frames, window)``: the action's first frame played onto a locomotion
    no longer than it (0 otherwise)."""
    upper, spine, arms, chest, hands, feat_joints, blend_s, W, pos, grot = sj
    ls, as_ = starts[loco], starts[act]
    Tl, Ta = lengths[loco], lengths[act]
    window = 0
    if timing != 2 and Tl < Ta:
        rel = np.empty((Ta, 2, 3))
        hands_in_chest(pos, grot, as_, Ta, chest, hands, rel)
        window = best_window(rel, Ta, mask, Tl)
    standing_rows(rot, trans, ls, Tl, as_, Ta, method, timing, window, loop_s, loop_e, acting, upper, spine, arms,
                  blend_s, 0, Tl, curve, orot, otrans)
    return Tl, window


@njit(cache=True, parallel=True, nogil=True)
def standing_batch(rot, trans, starts, lengths, method, timing, loco, act, masks, acting, loops, sj, out_start,
                   orot, otrans, ocurve, frames, window):
    """Splice every standing pair ``b`` (bank clips ``loco[b]``, ``act[b]``; hand mask
    ``masks[b] (2,)``, acting arms ``acting[b] (2,)``, loop points ``loops[b] (2,)``) in parallel,
    into rows ``out_start[b] :`` (room for the locomotion's length) of ``orot``/``otrans``/``ocurve``;
    ``window[b]``: the action's first frame played onto a locomotion shorter than it."""
    for b in prange(loco.shape[0]):
        o = out_start[b]
        n = lengths[loco[b]]
        frames[b], window[b] = _standing_one(rot, trans, starts, lengths, loco[b], act[b], masks[b], acting[b], loops[b, 0],
                                             loops[b, 1], method, timing, sj, ocurve[o:o + n], orot[o:o + n], otrans[o:o + n])
