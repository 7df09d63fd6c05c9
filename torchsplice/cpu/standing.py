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
``tables`` (:class:`torchsplice.cpu.bank.StandingTables`, as a tuple) holds the joint tables: upper-body
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
def hands_in_chest(pos, grot, first_row, n, chest, hands, out):
    """Bank rows ``first_row .. first_row + n - 1``: both hands in the chest's frame, into ``out (n, 2, 3)``."""
    for t in range(n):
        to_chest = qconj(qload(grot, first_row + t, chest))
        for k in range(2):
            hand = hands[k]
            v = qrot(to_chest, (pos[first_row + t, hand, 0] - pos[first_row + t, chest, 0],
                                pos[first_row + t, hand, 1] - pos[first_row + t, chest, 1],
                                pos[first_row + t, hand, 2] - pos[first_row + t, chest, 2]))
            out[t, k, 0], out[t, k, 1], out[t, k, 2] = v


@njit(cache=True, nogil=True)
def motion_core(hand_pos, n, mask):
    """``(first, last)``: the span holding the central :data:`CORE_SHARE` of the path the hands
    ``hand_pos (n, 2, 3)`` (in the chest's frame) travel, weighted by ``mask (2,)`` (see
    :func:`torchsplice.splice.standing.motion_core`)."""
    path = np.empty(n)
    path[0] = 0.0
    for t in range(1, n):
        step = 0.0
        for k in range(2):
            dx, dy, dz = (hand_pos[t, k, 0] - hand_pos[t - 1, k, 0], hand_pos[t, k, 1] - hand_pos[t - 1, k, 1],
                          hand_pos[t, k, 2] - hand_pos[t - 1, k, 2])
            step += math.sqrt(dx * dx + dy * dy + dz * dz) * mask[k]
        path[t] = path[t - 1] + step
    total = path[n - 1]
    if total <= 0:
        return 0, n - 1
    core_begin, core_end = (1 - CORE_SHARE) / 2 * total, (1 + CORE_SHARE) / 2 * total
    first, last = -1, 0
    for t in range(n):
        if path[t] <= core_begin:
            first += 1
        if path[t] < core_end:
            last += 1
    return max(first, 0), min(last, n - 1)


@njit(cache=True, nogil=True)
def best_window(hand_pos, n, mask, width):
    """The first frame of the best window of ``width <= n`` frames of the hands ``hand_pos (n, 2, 3)``
    (in the chest's frame): the largest mask-weighted sum of per-axis variances (see
    :func:`torchsplice.splice.standing.best_windows`)."""
    sums = np.zeros((n + 1, 2, 3))
    square_sums = np.zeros((n + 1, 2, 3))
    for t in range(n):
        for k in range(2):
            for c in range(3):
                x = hand_pos[t, k, c]
                sums[t + 1, k, c] = sums[t, k, c] + x
                square_sums[t + 1, k, c] = square_sums[t, k, c] + x * x
    count = n - width + 1
    score = np.empty(count)
    best, scale = -np.inf, 0.0
    for start in range(count):
        variance = 0.0
        window_scale = 0.0
        for k in range(2):
            for c in range(3):
                mean = (sums[start + width, k, c] - sums[start, k, c]) / width
                mean_of_squares = (square_sums[start + width, k, c] - square_sums[start, k, c]) / width
                variance += (mean_of_squares - mean * mean) * mask[k]
                window_scale += mean_of_squares * mask[k]
        score[start] = variance
        best = max(best, variance)
        scale = max(scale, window_scale)
    for start in range(count):
        if score[start] >= best - TIE * scale:
            return start
    return 0


@njit(cache=True, nogil=True)
def loop_points(pos, grot, first_row, n, chest, hands, feat_joints, mask, match_window):
    """``(start, end)`` of one clip (bank rows from ``first_row``, ``n`` frames; see
    :func:`torchsplice.splice.standing.loop_points`): the closest pair of windows of ``match_window``
    frames (upper-body ``feat_joints`` in the chest frame), the start at or before the main motion
    of the hands of ``mask`` and the end at or after it."""
    whole_start, whole_end = 0, max(n - 1, 1)
    if n < match_window + 2:
        return whole_start, whole_end
    hand_pos = np.empty((n, 2, 3))
    hands_in_chest(pos, grot, first_row, n, chest, hands, hand_pos)
    first, last = motion_core(hand_pos, n, mask)
    first_end, last_end = max(last, 1), n - match_window  # candidate ends
    if first_end > last_end:
        return whole_start, whole_end
    n_feat = feat_joints.shape[0]
    feat = np.empty((n, n_feat, 3))
    for t in range(n):
        to_chest = qconj(qload(grot, first_row + t, chest))
        for f in range(n_feat):
            j = feat_joints[f]
            v = qrot(to_chest, (pos[first_row + t, j, 0] - pos[first_row + t, chest, 0],
                                pos[first_row + t, j, 1] - pos[first_row + t, chest, 1],
                                pos[first_row + t, j, 2] - pos[first_row + t, chest, 2]))
            feat[t, f, 0], feat[t, f, 1], feat[t, f, 2] = v
    n_starts = first + 1  # candidate starts 0 .. first
    distance = np.full((last_end - first_end + 1, n_starts), np.inf)
    best = np.inf
    for end in range(first_end, last_end + 1):
        for start in range(min(n_starts, end)):  # start < end
            acc = 0.0
            for f in range(n_feat):
                for c in range(3):
                    for w in range(match_window):
                        x = feat[end + w, f, c] - feat[start + w, f, c]
                        acc += x * x
            v = math.sqrt(acc)
            distance[end - first_end, start] = v
            best = min(best, v)
    if not best < np.inf:
        return whole_start, whole_end
    for end in range(first_end, last_end + 1):
        for start in range(n_starts):
            if distance[end - first_end, start] <= best + TIE * best:
                return start, end
    return whole_start, whole_end


@njit(cache=True, parallel=True, nogil=True)
def loop_points_batch(pos, grot, starts, lengths, clips, masks, chest, hands, feat_joints, match_window, out):
    """:func:`loop_points` of bank clips ``clips (C,)`` with hand masks ``masks (C, 2)``, in
    parallel, into ``out (C, 2)``."""
    for i in prange(clips.shape[0]):
        c = clips[i]
        start, end = loop_points(pos, grot, starts[c], lengths[c], chest, hands, feat_joints, masks[i], match_window)
        out[i, 0], out[i, 1] = start, end


@njit(cache=True, nogil=True)
def _standing_one(rot, trans, starts, lengths, loco, action, mask, acting, loop_start, loop_end, method, timing, tables,
                  curve, out_rot, out_trans):
    """One standing pair (bank clips ``loco``, ``action``) into rows ``0 .. loco_frames - 1`` of
    ``out_rot``/``out_trans`` (the assembly of
    :func:`torchsplice.cpu.assemble.standing_rows`), the action frame of each result frame into
    ``curve``. Returns ``(frames, window)``: the action's first frame played onto a locomotion
    no longer than it (0 otherwise). ``tables``: the skeleton's joint tables and frame counts
    (:class:`torchsplice.cpu.bank.StandingTables`) and the bank's FK ``pos``, ``grot``."""
    upper, spine, arms, chest, hands, feat_joints, blend_s, match_window, pos, grot = tables
    loco_start, action_start = starts[loco], starts[action]
    loco_frames, action_frames = lengths[loco], lengths[action]
    window = 0
    if timing != 2 and loco_frames < action_frames:
        hand_pos = np.empty((action_frames, 2, 3))
        hands_in_chest(pos, grot, action_start, action_frames, chest, hands, hand_pos)
        window = best_window(hand_pos, action_frames, mask, loco_frames)
    standing_rows(rot, trans, loco_start, loco_frames, action_start, action_frames, method, timing, window, loop_start,
                  loop_end, acting, upper, spine, arms, blend_s, 0, loco_frames, curve, out_rot, out_trans)
    return loco_frames, window


@njit(cache=True, parallel=True, nogil=True)
def standing_batch(rot, trans, starts, lengths, method, timing, loco, action, masks, acting, loops, tables, out_start,
                   out_rot, out_trans, out_curve, frames, window):
    """Splice every standing pair ``b`` (bank clips ``loco[b]``, ``action[b]``; hand mask
    ``masks[b] (2,)``, acting arms ``acting[b] (2,)``, loop points ``loops[b] (2,)``) in parallel,
    into rows ``out_start[b] :`` (room for the locomotion's length) of ``out_rot``/``out_trans``/``out_curve``;
    ``tables``: as :func:`_standing_one`'s;
    ``window[b]``: the action's first frame played onto a locomotion shorter than it."""
    for b in prange(loco.shape[0]):
        row = out_start[b]
        n = lengths[loco[b]]
        frames[b], window[b] = _standing_one(rot, trans, starts, lengths, loco[b], action[b], masks[b], acting[b],
                                             loops[b, 0], loops[b, 1], method, timing, tables, out_curve[row:row + n],
                                             out_rot[row:row + n], out_trans[row:row + n])
