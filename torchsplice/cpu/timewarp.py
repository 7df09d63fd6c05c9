"""Compiled slope-limited DP timewarp on the CPU: one pair per thread, in parallel over pairs.

Same conventions, tie-breaking and results as :func:`torchsplice.align.timewarp.timewarp`
(the torch implementation, kept for CUDA): a cost grid ``(Ta, Tb)`` (rows: clip A, the
locomotion; columns: clip B, the action), states ``[D, H1..HL, V1..VL]``, the minimal *total*
per cell and state, then the minimal *average* over the top and right edges, ties as documented
there. Sums are taken in the grid's dtype (float32 or float64) in the same order as the torch
code, so both give the same bits on the same grid.

The loop over one pair runs row by row; inside a row every state is a pass over the columns
that the compiler vectorises (the horizontal states only look one column back at the row
being built, never at themselves). ``dp_pair`` does one pair; :func:`timewarp_batch` runs many
pairs of a padded ``(B, Ta, Tb)`` grid in parallel threads (coarse-grained: one pair per task).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["dp_forward", "choose_end", "backtrack", "dp_pair", "timewarp_batch", "cumulative_cost_batch"]


@njit(cache=True, nogil=True, inline="always")
def _argmin_into(m, c, a, sums, cnts, s, off, n):
    """``m[j], c[j], a[j] = sums[off + j], cnts[off + j], s`` where ``sums[off + j] < m[j]``
    (strictly: the earlier state wins ties); a select per column, vectorised."""
    for j in range(n):
        v = sums[off + j]
        lt = v < m[j]
        m[j] = v if lt else m[j]
        c[j] = cnts[off + j] if lt else c[j]
        a[j] = s if lt else a[j]


@njit(cache=True, nogil=True)
def dp_forward(g, col0, la, lb, L, bp, right_sum, right_cnt, top_sum, top_cnt, cmin):
    """Forward pass over one pair: rows ``0..la-1`` and columns ``col0..col0+lb-1`` of ``g``.

    Writes back-pointers ``bp`` ``(3, >=la, >=lb)`` int8, or int16 for ``2L + 1 > 127`` states (predecessor state of D, H1, V1 at
    each cell), the states of the right column ``right_sum/right_cnt`` ``(S, la)`` and of the top
    row ``top_sum/top_cnt`` ``(S, lb)``, and when ``cmin`` is not empty ``(la, lb)`` the minimal
    total over states of every cell. State rows are stored with a guard column 0 (``j = -1``)
    holding ``+inf``, so that every pass is a branch-free loop over the columns.
    """
    S = 2 * L + 1
    inf = np.inf
    prev_sum = np.empty((S, lb + 1), dtype=g.dtype)
    prev_cnt = np.zeros((S, lb + 1), dtype=np.int32)
    cur_sum = np.empty((S, lb + 1), dtype=g.dtype)
    cur_cnt = np.zeros((S, lb + 1), dtype=np.int32)
    prev_sum[:, :] = inf
    cur_sum[:, 0] = inf
    m = np.empty(lb, dtype=g.dtype)
    c = np.empty(lb, dtype=np.int32)
    a = np.empty(lb, dtype=bp.dtype)
    keep_min = cmin.shape[0] > 0
    for i in range(la):
        gi = g[i]
        # D at (i, j) from any state at (i-1, j-1): state row index j (guard = j-1 = -1).
        for j in range(lb):
            m[j] = prev_sum[0, j]
            c[j] = prev_cnt[0, j]
            a[j] = 0
        for s in range(1, S):
            _argmin_into(m, c, a, prev_sum[s], prev_cnt[s], s, 0, lb)
        cs, cc = cur_sum[0], cur_cnt[0]
        for j in range(lb):
            cs[j + 1] = gi[col0 + j] + m[j]
            cc[j + 1] = c[j] + 1
            bp[0, i, j] = a[j]
        cs[1] = gi[col0] if i == 0 else inf  # the start cell counts as D
        cc[1] = 1
        # V1 from D or any H state at (i-1, j); V_c from V_{c-1} at (i-1, j).
        for j in range(lb):
            m[j] = prev_sum[0, j + 1]
            c[j] = prev_cnt[0, j + 1]
            a[j] = 0
        for s in range(1, L + 1):
            _argmin_into(m, c, a, prev_sum[s], prev_cnt[s], s, 1, lb)
        cs, cc = cur_sum[L + 1], cur_cnt[L + 1]
        for j in range(lb):
            cs[j + 1] = gi[col0 + j] + m[j]
            cc[j + 1] = c[j] + 1
            bp[2, i, j] = a[j]
        for k in range(L + 2, S):
            cs, cc, ps, pc = cur_sum[k], cur_cnt[k], prev_sum[k - 1], prev_cnt[k - 1]
            for j in range(lb):
                cs[j + 1] = gi[col0 + j] + ps[j + 1]
                cc[j + 1] = pc[j + 1] + 1
        # H1 from D or any V state at (i, j-1); H_c from H_{c-1} at (i, j-1).
        for j in range(lb):
            m[j] = cur_sum[0, j]
            c[j] = cur_cnt[0, j]
            a[j] = 0
        for s in range(L + 1, S):
            _argmin_into(m, c, a, cur_sum[s], cur_cnt[s], s, 0, lb)
        cs, cc = cur_sum[1], cur_cnt[1]
        for j in range(lb):
            cs[j + 1] = gi[col0 + j] + m[j]
            cc[j + 1] = c[j] + 1
            bp[1, i, j] = a[j]
        cs[1] = inf
        cc[1] = 1
        for k in range(2, L + 1):
            cs, cc, ps, pc = cur_sum[k], cur_cnt[k], cur_sum[k - 1], cur_cnt[k - 1]
            for j in range(lb):
                cs[j + 1] = gi[col0 + j] + ps[j]
                cc[j + 1] = pc[j] + 1
            cs[1] = inf
            cc[1] = 1
        for s in range(S):
            right_sum[s, i] = cur_sum[s, lb]
            right_cnt[s, i] = cur_cnt[s, lb]
        if keep_min:
            for j in range(lb):
                m[j] = cur_sum[0, j + 1]
            for s in range(1, S):
                for j in range(lb):
                    v = cur_sum[s, j + 1]
                    m[j] = v if v < m[j] else m[j]
            for j in range(lb):
                cmin[i, j] = m[j]
        prev_sum, cur_sum = cur_sum, prev_sum
        prev_cnt, cur_cnt = cur_cnt, prev_cnt
    for s in range(S):
        for j in range(lb):
            top_sum[s, j] = prev_sum[s, j + 1]
            top_cnt[s, j] = prev_cnt[s, j + 1]


@njit(cache=True, nogil=True)
def choose_end(la, lb, L, right_sum, right_cnt, top_sum, top_cnt):
    """End cell and state of minimal average: ``(i, j, state, total, length)``; ``state = -1``
    when no edge cell is reachable. Candidates in priority order: the top row from the corner
    leftwards, then the right column downwards; within a cell, states in order."""
    S = 2 * L + 1
    best = np.inf
    bi, bj, bs, bt, bn = -1, -1, -1, top_sum[0, 0], 0
    nf = np.empty(1, dtype=top_sum.dtype)  # the count in the sums' dtype, as torch divides
    for j in range(lb - 1, -1, -1):
        for s in range(S):
            n = top_cnt[s, j]
            nf[0] = max(n, 1)
            avg = top_sum[s, j] / nf[0]
            if avg < best:
                best, bi, bj, bs, bt, bn = avg, la - 1, j, s, top_sum[s, j], n
    for i in range(la - 2, -1, -1):
        for s in range(S):
            n = right_cnt[s, i]
            nf[0] = max(n, 1)
            avg = right_sum[s, i] / nf[0]
            if avg < best:
                best, bi, bj, bs, bt, bn = avg, i, lb - 1, s, right_sum[s, i], n
    return bi, bj, bs, bt, bn


@njit(cache=True, nogil=True)
def backtrack(bp, L, end_i, end_j, state, length, out):
    """Fill ``out`` ``(length, 2)`` with the path's cells from ``(0, 0)`` to the end cell."""
    i, j, s = end_i, end_j, state
    for step in range(length - 1, -1, -1):
        out[step, 0] = i
        out[step, 1] = j
        if i == 0 and j == 0:
            break
        if s == 0:
            ns = bp[0, i, j]
            i -= 1
            j -= 1
        elif s <= L:
            ns = bp[1, i, j] if s == 1 else s - 1
            j -= 1
        else:
            ns = bp[2, i, j] if s == L + 1 else s - 1
            i -= 1
        s = ns


@njit(cache=True, nogil=True)
def dp_pair(g, col0, la, lb, max_run, cells):
    """Timewarp of one pair (rows ``0..la-1``, columns ``col0..col0+lb-1`` of ``g``): the path
    into ``cells`` ``(>= la + lb - 1, 2)`` (column indices relative to ``col0``); returns
    ``(length, total)``, or ``(-1, nan)`` when ``+inf`` costs block every path."""
    L = max(1, min(max_run, max(la, lb) - 1))
    if 2 * L + 1 > 127:  # state indices no longer fit int8 back-pointers
        return _dp_pair_with(np.empty((3, la, lb), dtype=np.int16), g, col0, la, lb, L, cells)
    return _dp_pair_with(np.empty((3, la, lb), dtype=np.int8), g, col0, la, lb, L, cells)


@njit(cache=True, nogil=True)
def _dp_pair_with(bp, g, col0, la, lb, L, cells):
    S = 2 * L + 1
    right_sum = np.empty((S, la), dtype=g.dtype)
    right_cnt = np.empty((S, la), dtype=np.int32)
    top_sum = np.empty((S, lb), dtype=g.dtype)
    top_cnt = np.empty((S, lb), dtype=np.int32)
    dp_forward(g, col0, la, lb, L, bp, right_sum, right_cnt, top_sum, top_cnt, np.empty((0, 0), dtype=g.dtype))
    ei, ej, es, total, length = choose_end(la, lb, L, right_sum, right_cnt, top_sum, top_cnt)
    if es < 0:
        return -1, np.nan
    backtrack(bp, L, ei, ej, es, length, cells)
    return length, total


@njit(cache=True, parallel=True)
def timewarp_batch(grid, la, lb, max_run, cells, length, total):
    """Every pair ``b`` of a padded ``(B, Ta, Tb)`` grid, one pair per thread.

    Fills ``cells`` ``(B, Ta + Tb - 1, 2)`` int64 (pre-filled with -1 by the caller),
    ``length`` ``(B,)`` int64 (-1 for a blocked pair) and ``total`` ``(B,)``.
    """
    for b in prange(grid.shape[0]):
        n, t = dp_pair(grid[b], 0, la[b], lb[b], max_run, cells[b])
        length[b] = n
        total[b] = t


@njit(cache=True, parallel=True)
def cumulative_cost_batch(grid, la, lb, max_run, out):
    """Minimal path total to every cell (``out`` ``(B, Ta, Tb)``, pre-filled with +inf)."""
    for b in prange(grid.shape[0]):
        na, nb = la[b], lb[b]
        L = max(1, min(max_run, max(na, nb) - 1))
        S = 2 * L + 1
        cmin = np.empty((na, nb), dtype=grid.dtype)
        dp_forward(grid[b], 0, na, nb, L, np.empty((3, na, nb), dtype=np.int16), np.empty((S, na), dtype=grid.dtype),
                   np.empty((S, na), dtype=np.int32), np.empty((S, nb), dtype=grid.dtype), np.empty((S, nb), dtype=np.int32),
                   cmin)
        out[b, :na, :nb] = cmin
