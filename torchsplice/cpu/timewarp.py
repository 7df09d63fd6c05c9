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
def _argmin_into(best_sum, best_cnt, best_state, sums, counts, state, offset, n):
    """``best_sum[j], best_cnt[j], best_state[j] = sums[offset + j], counts[offset + j], state`` where
    ``sums[offset + j] < best_sum[j]``
    (strictly: the earlier state wins ties); a select per column, vectorised."""
    for j in range(n):
        v = sums[offset + j]
        lt = v < best_sum[j]
        best_sum[j] = v if lt else best_sum[j]
        best_cnt[j] = counts[offset + j] if lt else best_cnt[j]
        best_state[j] = state if lt else best_state[j]


@njit(cache=True, nogil=True)
def dp_forward(grid, col0, frames_a, frames_b, L, back, right_sum, right_cnt, top_sum, top_cnt, cell_min):
    """Forward pass over one pair: rows ``0..frames_a-1`` (clip A's frames) and columns
    ``col0..col0+frames_b-1`` (clip B's) of ``grid``; ``L`` the longest run of one clip's frames.

    Writes back-pointers ``back`` ``(3, >=frames_a, >=frames_b)`` int8, or int16 for ``2L + 1 > 127``
    states (predecessor state of D, H1, V1 at each cell), the states of the right column
    ``right_sum/right_cnt`` ``(S, frames_a)`` and of the top row ``top_sum/top_cnt`` ``(S, frames_b)``,
    and when ``cell_min`` is not empty ``(frames_a, frames_b)`` the minimal
    total over states of every cell. State rows are stored with a guard column 0 (``j = -1``)
    holding ``+inf``, so that every pass is a branch-free loop over the columns.
    """
    S = 2 * L + 1
    inf = np.inf
    prev_sum = np.empty((S, frames_b + 1), dtype=grid.dtype)
    prev_cnt = np.zeros((S, frames_b + 1), dtype=np.int32)
    cur_sum = np.empty((S, frames_b + 1), dtype=grid.dtype)
    cur_cnt = np.zeros((S, frames_b + 1), dtype=np.int32)
    prev_sum[:, :] = inf
    cur_sum[:, 0] = inf
    best_sum = np.empty(frames_b, dtype=grid.dtype)
    best_cnt = np.empty(frames_b, dtype=np.int32)
    best_state = np.empty(frames_b, dtype=back.dtype)
    keep_min = cell_min.shape[0] > 0
    for i in range(frames_a):
        grid_row = grid[i]
        # D at (i, j) from any state at (i-1, j-1): state row index j (guard = j-1 = -1).
        for j in range(frames_b):
            best_sum[j] = prev_sum[0, j]
            best_cnt[j] = prev_cnt[0, j]
            best_state[j] = 0
        for s in range(1, S):
            _argmin_into(best_sum, best_cnt, best_state, prev_sum[s], prev_cnt[s], s, 0, frames_b)
        row_sum, row_cnt = cur_sum[0], cur_cnt[0]
        for j in range(frames_b):
            row_sum[j + 1] = grid_row[col0 + j] + best_sum[j]
            row_cnt[j + 1] = best_cnt[j] + 1
            back[0, i, j] = best_state[j]
        row_sum[1] = grid_row[col0] if i == 0 else inf  # the start cell counts as D
        row_cnt[1] = 1
        # V1 from D or any H state at (i-1, j); V_c from V_{c-1} at (i-1, j).
        for j in range(frames_b):
            best_sum[j] = prev_sum[0, j + 1]
            best_cnt[j] = prev_cnt[0, j + 1]
            best_state[j] = 0
        for s in range(1, L + 1):
            _argmin_into(best_sum, best_cnt, best_state, prev_sum[s], prev_cnt[s], s, 1, frames_b)
        row_sum, row_cnt = cur_sum[L + 1], cur_cnt[L + 1]
        for j in range(frames_b):
            row_sum[j + 1] = grid_row[col0 + j] + best_sum[j]
            row_cnt[j + 1] = best_cnt[j] + 1
            back[2, i, j] = best_state[j]
        for k in range(L + 2, S):
            row_sum, row_cnt, from_sum, from_cnt = cur_sum[k], cur_cnt[k], prev_sum[k - 1], prev_cnt[k - 1]
            for j in range(frames_b):
                row_sum[j + 1] = grid_row[col0 + j] + from_sum[j + 1]
                row_cnt[j + 1] = from_cnt[j + 1] + 1
        # H1 from D or any V state at (i, j-1); H_c from H_{c-1} at (i, j-1).
        for j in range(frames_b):
            best_sum[j] = cur_sum[0, j]
            best_cnt[j] = cur_cnt[0, j]
            best_state[j] = 0
        for s in range(L + 1, S):
            _argmin_into(best_sum, best_cnt, best_state, cur_sum[s], cur_cnt[s], s, 0, frames_b)
        row_sum, row_cnt = cur_sum[1], cur_cnt[1]
        for j in range(frames_b):
            row_sum[j + 1] = grid_row[col0 + j] + best_sum[j]
            row_cnt[j + 1] = best_cnt[j] + 1
            back[1, i, j] = best_state[j]
        row_sum[1] = inf
        row_cnt[1] = 1
        for k in range(2, L + 1):
            row_sum, row_cnt, from_sum, from_cnt = cur_sum[k], cur_cnt[k], cur_sum[k - 1], cur_cnt[k - 1]
            for j in range(frames_b):
                row_sum[j + 1] = grid_row[col0 + j] + from_sum[j]
                row_cnt[j + 1] = from_cnt[j] + 1
            row_sum[1] = inf
            row_cnt[1] = 1
        for s in range(S):
            right_sum[s, i] = cur_sum[s, frames_b]
            right_cnt[s, i] = cur_cnt[s, frames_b]
        if keep_min:
            for j in range(frames_b):
                best_sum[j] = cur_sum[0, j + 1]
            for s in range(1, S):
                for j in range(frames_b):
                    v = cur_sum[s, j + 1]
                    best_sum[j] = v if v < best_sum[j] else best_sum[j]
            for j in range(frames_b):
                cell_min[i, j] = best_sum[j]
        prev_sum, cur_sum = cur_sum, prev_sum
        prev_cnt, cur_cnt = cur_cnt, prev_cnt
    for s in range(S):
        for j in range(frames_b):
            top_sum[s, j] = prev_sum[s, j + 1]
            top_cnt[s, j] = prev_cnt[s, j + 1]


@njit(cache=True, nogil=True)
def choose_end(frames_a, frames_b, L, right_sum, right_cnt, top_sum, top_cnt):
    """End cell and state of minimal average: ``(i, j, state, total, length)``; ``state = -1``
    when no edge cell is reachable. Candidates in priority order: the top row from the corner
    leftwards, then the right column downwards; within a cell, states in order."""
    S = 2 * L + 1
    best = np.inf
    end_i, end_j, end_state, end_total, end_length = -1, -1, -1, top_sum[0, 0], 0
    count_f = np.empty(1, dtype=top_sum.dtype)  # the count in the sums' dtype, as torch divides
    for j in range(frames_b - 1, -1, -1):
        for s in range(S):
            n = top_cnt[s, j]
            count_f[0] = max(n, 1)
            avg = top_sum[s, j] / count_f[0]
            if avg < best:
                best, end_i, end_j, end_state, end_total, end_length = avg, frames_a - 1, j, s, top_sum[s, j], n
    for i in range(frames_a - 2, -1, -1):
        for s in range(S):
            n = right_cnt[s, i]
            count_f[0] = max(n, 1)
            avg = right_sum[s, i] / count_f[0]
            if avg < best:
                best, end_i, end_j, end_state, end_total, end_length = avg, i, frames_b - 1, s, right_sum[s, i], n
    return end_i, end_j, end_state, end_total, end_length


@njit(cache=True, nogil=True)
def backtrack(back, L, end_i, end_j, state, length, out):
    """Fill ``out`` ``(length, 2)`` with the path's cells from ``(0, 0)`` to the end cell, following the
    back-pointers ``back`` of :func:`dp_forward`."""
    i, j, s = end_i, end_j, state
    for step in range(length - 1, -1, -1):
        out[step, 0] = i
        out[step, 1] = j
        if i == 0 and j == 0:
            break
        if s == 0:
            prev_state = back[0, i, j]
            i -= 1
            j -= 1
        elif s <= L:
            prev_state = back[1, i, j] if s == 1 else s - 1
            j -= 1
        else:
            prev_state = back[2, i, j] if s == L + 1 else s - 1
            i -= 1
        s = prev_state


@njit(cache=True, nogil=True)
def dp_pair(grid, col0, frames_a, frames_b, max_run, cells):
    """Timewarp of one pair (rows ``0..frames_a-1``, columns ``col0..col0+frames_b-1`` of ``grid``): the
    path into ``cells`` ``(>= frames_a + frames_b - 1, 2)`` (column indices relative to ``col0``); returns
    ``(length, total)``, or ``(-1, nan)`` when ``+inf`` costs block every path."""
    L = max(1, min(max_run, max(frames_a, frames_b) - 1))
    if 2 * L + 1 > 127:  # state indices no longer fit int8 back-pointers
        return _dp_pair_with(np.empty((3, frames_a, frames_b), dtype=np.int16), grid, col0, frames_a, frames_b, L,
                             cells)
    return _dp_pair_with(np.empty((3, frames_a, frames_b), dtype=np.int8), grid, col0, frames_a, frames_b, L, cells)


@njit(cache=True, nogil=True)
def _dp_pair_with(back, grid, col0, frames_a, frames_b, L, cells):
    S = 2 * L + 1
    right_sum = np.empty((S, frames_a), dtype=grid.dtype)
    right_cnt = np.empty((S, frames_a), dtype=np.int32)
    top_sum = np.empty((S, frames_b), dtype=grid.dtype)
    top_cnt = np.empty((S, frames_b), dtype=np.int32)
    dp_forward(grid, col0, frames_a, frames_b, L, back, right_sum, right_cnt, top_sum, top_cnt,
               np.empty((0, 0), dtype=grid.dtype))
    end_i, end_j, end_state, total, length = choose_end(frames_a, frames_b, L, right_sum, right_cnt, top_sum, top_cnt)
    if end_state < 0:
        return -1, np.nan
    backtrack(back, L, end_i, end_j, end_state, length, cells)
    return length, total


@njit(cache=True, parallel=True)
def timewarp_batch(grid, lengths_a, lengths_b, max_run, cells, length, total):
    """Every pair ``b`` of a padded ``(B, Ta, Tb)`` grid (its first ``lengths_a[b]`` rows and
    ``lengths_b[b]`` columns), one pair per thread.

    Fills ``cells`` ``(B, Ta + Tb - 1, 2)`` int64 (pre-filled with -1 by the caller),
    ``length`` ``(B,)`` int64 (-1 for a blocked pair) and ``total`` ``(B,)``.
    """
    for b in prange(grid.shape[0]):
        path_length, path_total = dp_pair(grid[b], 0, lengths_a[b], lengths_b[b], max_run, cells[b])
        length[b] = path_length
        total[b] = path_total


@njit(cache=True, parallel=True)
def cumulative_cost_batch(grid, lengths_a, lengths_b, max_run, out):
    """Minimal path total to every cell (``out`` ``(B, Ta, Tb)``, pre-filled with +inf)."""
    for b in prange(grid.shape[0]):
        frames_a, frames_b = lengths_a[b], lengths_b[b]
        L = max(1, min(max_run, max(frames_a, frames_b) - 1))
        S = 2 * L + 1
        cell_min = np.empty((frames_a, frames_b), dtype=grid.dtype)
        dp_forward(grid[b], 0, frames_a, frames_b, L, np.empty((3, frames_a, frames_b), dtype=np.int16),
                   np.empty((S, frames_a), dtype=grid.dtype), np.empty((S, frames_a), dtype=np.int32),
                   np.empty((S, frames_b), dtype=grid.dtype), np.empty((S, frames_b), dtype=np.int32), cell_min)
        out[b, :frames_a, :frames_b] = cell_min
