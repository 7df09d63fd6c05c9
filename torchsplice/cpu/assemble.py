"""Compiled assembly: a spliced clip's frames from what splicing computed (its *parts*) and its
two source clips, the one code that both the motion store writes with and every read of an
alignment store runs (see :mod:`torchsplice.store.assembly`).

A spliced clip is made of the same few parts, whatever store holds it:

- ``timewarp`` clips (``splice``, and ``naive``, whose curve is ``t``): per result frame ``t``
  the action's frame ``curve[t]`` (fractional, counted from the action's ``crop``) and the
  pelvis's local rotation ``pelvis[t]``; the root and the lower body are the locomotion's frame
  ``t``, the upper body the action slerped at ``curve[t]`` (translations linearly);
- ``standing`` clips (actions that do not locomote): the action's frame for each result frame
  follows from a few integers per clip (``timing``, ``window``, the loop points), and the
  assembly of :mod:`torchsplice.cpu.standing` (acting arms and spine from the action with the
  locomotion's secondary spine motion, a loop's seam smoothed by inertialization).

Inputs index a bank of source clips packed along frames (float64 local rotations
``rot (N, J, 4)``, WXYZ, and local translations ``trans (N, J, 3)``, row 0 the root's
position; clip ``c`` is rows ``starts[c] : starts[c] + lengths[c]``). Outputs are written as
their arrays' dtype (float32 for the stores). Every function computes result frames
``first .. first + count - 1`` of a clip, so a read of a window costs the window only. The batch
functions run in the calling thread and release the GIL (no parallel region: a read may happen
in a forked ``DataLoader`` worker, or beside other threads); a reader shares its clips over its
threads (:mod:`torchsplice.core.threads`), each thread writing its own rows.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..core.method_table import CPMC, NAIVE, SPLICE
from .curve import lerp, split_time
from .quat import qarc, qconj, qload, qmul, qnormalize, qslerp, qslerp_arc, qstore

__all__ = ["arc_table", "timewarp_rows", "standing_rows", "standing_times", "assemble_timewarp", "assemble_standing",
           "SPLICE_CODE", "NAIVE_CODE", "CPMC_CODE"]

SPLICE_CODE, NAIVE_CODE, CPMC_CODE = SPLICE.code, NAIVE.code, CPMC.code
"""The built-in methods' codes in the kernels (:data:`torchsplice.core.method_table.BUILTINS`): plain
module-level ints, which numba freezes into the compiled branches."""


@njit(cache=True, nogil=True)
def arc_table(rot, joints):
    """``(N, J, 2)`` float64: :func:`~torchsplice.cpu.quat.qarc` of rows ``r`` and ``r + 1`` of
    ``rot (N, J, 4)`` for each joint where ``joints (J,)`` is true (zeros elsewhere and on the
    last row). A timewarp clip samples its action between neighbouring frames, so a reader that
    assembles many clips of the same bank looks these up instead of computing an ``acos`` and a
    ``sin`` per joint and frame; the slerp it then computes is the same, bit for bit."""
    N, J = rot.shape[0], rot.shape[1]
    out = np.zeros((N, J, 2))
    for r in range(N - 1):
        for j in range(J):
            if joints[j]:
                out[r, j, 0], out[r, j, 1] = qarc(qload(rot, r, j), qload(rot, r + 1, j))
    return out


@njit(cache=True, nogil=True)
def timewarp_rows(rot, trans, arc, loco_start, action_start, action_frames, upper, pelvis, curve, pelvis_rot, n,
                  out_rot, out_trans):
    """``n`` result frames of a timewarp clip into rows ``0 .. n - 1`` of ``out_rot``/``out_trans``.

    ``loco_start``: the bank row of the locomotion's first frame wanted; ``action_start``: the
    bank row of the action's frame 0 after its crop, ``action_frames`` its frames from there; ``curve (n,)``: the
    action frame (from ``action_start``) of each result frame; ``pelvis_rot (n, 4)``: the pelvis's rotation.
    ``arc``: :func:`arc_table` of ``rot`` on the ``upper`` joints, or an empty ``(0, J, 2)``
    array to compute the slerps' angles here (the same bits either way). ``out_trans`` may hold
    fewer joints than ``rot`` (a reader that wants the root's only: ``(n, 1, 3)``); translations
    are computed for the joints it holds.
    """
    J, JT = rot.shape[1], out_trans.shape[1]
    table = arc.shape[0] > 0
    for t in range(n):
        i0, i1, w = split_time(curve[t], action_frames)
        for j in range(J):
            if j == pelvis:
                for c in range(4):
                    out_rot[t, j, c] = pelvis_rot[t, c]
                if j < JT:
                    for c in range(3):
                        out_trans[t, j, c] = trans[loco_start + t, j, c]
            elif upper[j]:
                p, q = qload(rot, action_start + i0, j), qload(rot, action_start + i1, j)
                if table:  # w > 0 only where i1 = i0 + 1: the pair the table holds at row as_ + i0
                    row = action_start + i0
                    qstore(out_rot, t, j, qslerp_arc(p, q, w, arc[row, j, 0], arc[row, j, 1]))
                else:
                    qstore(out_rot, t, j, qslerp(p, q, w))
                if j < JT:
                    for c in range(3):
                        out_trans[t, j, c] = lerp(trans[action_start + i0, j, c], trans[action_start + i1, j, c], w)
            else:
                for c in range(4):
                    out_rot[t, j, c] = rot[loco_start + t, j, c]
                if j < JT:
                    for c in range(3):
                        out_trans[t, j, c] = trans[loco_start + t, j, c]


@njit(cache=True, nogil=True)
def standing_times(t, loco_frames, action_frames, timing, window, loop_start, loop_end, blend):
    """``(time, fade source, fade phase)`` of result frame ``t`` of a standing clip (as
    :func:`torchsplice.splice.standing.action_times`): the action frame it plays, and during a
    loop's fade the frame faded from and how far the fade is (1: none)."""
    phase = 1.0
    if timing == 2:  # fit
        x = t * (action_frames - 1.0) / max(loco_frames - 1.0, 1.0)
    elif loco_frames <= action_frames:  # a window of the action
        x = min(window + t, action_frames - 1.0)
    elif timing == 1:  # hold
        x = min(float(t), action_frames - 1.0)
    else:  # loop
        period = max(loop_end - loop_start, 1.0)
        if t >= loop_end:
            after = t - loop_end
            u = after - math.floor(after / period) * period
            x = loop_start + u
            if u < blend:
                phase = min(max(u / blend, 0.0), 1.0)
        else:
            x = float(t)
    return x, (loop_end if phase < 1.0 else x), phase


@njit(cache=True, nogil=True)
def _aa(q):
    """Rotation vector of a unit quaternion (as :func:`~torchsplice.core.rotations.quat_to_axis_angle`)."""
    if q[0] < 0:
        q = (-q[0], -q[1], -q[2], -q[3])
    sn = math.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    angle = 2.0 * math.atan2(sn, q[0])
    sc = angle / sn if sn > 1e-8 else 2.0 + sn * sn / 3
    return (q[1] * sc, q[2] * sc, q[3] * sc)


@njit(cache=True, nogil=True)
def _exp(x, y, z):
    """Unit quaternion of a rotation vector (as :func:`~torchsplice.core.rotations.axis_angle_to_quat`)."""
    angle = math.sqrt(x * x + y * y + z * z)
    half = 0.5 * angle
    sc = math.sin(half) / angle if angle > 1e-8 else 0.5 - angle * angle / 48
    return (math.cos(half), x * sc, y * sc, z * sc)


@njit(cache=True, nogil=True, inline="always")
def _slerp_at(rot, start, at, j):
    """Joint ``j``'s rotation in the clip from bank row ``start``, at ``at`` (a
    :func:`~.curve.split_time`: frames ``i0``, ``i1`` and the weight between them)."""
    return qslerp(qload(rot, start + at[0], j), qload(rot, start + at[1], j), at[2])


@njit(cache=True, nogil=True, inline="always")
def _lerp_at(trans, start, at, j, c):
    """Component ``c`` of joint ``j``'s translation in the clip from bank row ``start``, at ``at``
    (as :func:`_slerp_at`'s)."""
    return trans[start + at[0], j, c] + at[2] * (trans[start + at[1], j, c] - trans[start + at[0], j, c])


@njit(cache=True, nogil=True, inline="always")
def _translation_offset(trans, action_start, c, j, jump, before_jump, loop_in, after_loop_in, pose_weight,
                        velocity_weight):
    """Component ``c`` of the inertialization offset of joint ``j``'s translation where a loop
    jumps back: the pose difference (at the frame it jumps from, ``jump``, less at the frame it
    jumps to, ``loop_in``) times ``pose_weight``, plus the velocity difference (``jump`` less
    ``before_jump``, against ``after_loop_in`` less ``loop_in``) times ``velocity_weight``;
    each time a :func:`~.curve.split_time` of the action (from bank row ``action_start``)."""
    at_jump = _lerp_at(trans, action_start, jump, j, c)
    at_before = _lerp_at(trans, action_start, before_jump, j, c)
    at_loop_in = _lerp_at(trans, action_start, loop_in, j, c)
    at_after = _lerp_at(trans, action_start, after_loop_in, j, c)
    return (at_jump - at_loop_in) * pose_weight + ((at_jump - at_before) - (at_after - at_loop_in)) * velocity_weight


@njit(cache=True, nogil=True)
def standing_rows(rot, trans, loco_start, loco_frames, action_start, action_frames, method, timing, window, loop_start,
                  loop_end, acting, upper, spine, arms, blend_s, first, n, curve, out_rot, out_trans):
    """Result frames ``first .. first + n - 1`` of a standing clip into rows ``0 .. n - 1`` of
    ``out_rot``/``out_trans``, and the action frame each plays into ``curve``.

    The locomotion is bank rows ``loco_start ..`` (``loco_frames`` frames), the action
    ``action_start ..`` (``action_frames``); ``method`` a built-in's code (:data:`SPLICE_CODE`,
    :data:`NAIVE_CODE`, :data:`CPMC_CODE`); ``timing`` 0 loop, 1 hold, 2 fit; ``window`` the
    action's first frame played onto a locomotion no longer than it; ``loop_start``/``loop_end`` the
    loop points; ``acting (2,)`` the arms that act (left, right); ``upper``, ``spine``,
    ``arms (2, J)`` and ``blend_s`` the skeleton's tables (:class:`torchsplice.cpu.bank.StandingTables`).
    ``out_trans`` may hold fewer joints than ``rot``, as :func:`timewarp_rows`'s.
    """
    J, JT = rot.shape[1], out_trans.shape[1]
    blend = max(min(blend_s, action_frames // 3), 1)
    # the locomotion's mean posture of each spine joint (splice)
    S = spine.shape[0]
    mean = np.zeros((S, 4))
    if method == SPLICE_CODE:
        for k in range(S):
            j = spine[k]
            q0 = qload(rot, loco_start, j)
            for t in range(loco_frames):
                q = qload(rot, loco_start + t, j)
                sg = -1.0 if q[0] * q0[0] + q[1] * q0[1] + q[2] * q0[2] + q[3] * q0[3] < 0 else 1.0
                for c in range(4):
                    mean[k, c] += sg * q[c]
            m = qnormalize((mean[k, 0], mean[k, 1], mean[k, 2], mean[k, 3]))
            mean[k, 0], mean[k, 1], mean[k, 2], mean[k, 3] = m
    spine_k = np.full(J, -1, np.int64)
    for k in range(S):
        spine_k[spine[k]] = k
    idle = np.zeros(J, np.bool_)
    for a in range(2):
        if not acting[a]:
            for j in range(J):
                if arms[a, j]:
                    idle[j] = True
    for i in range(n):
        t = first + i
        x, source, phase = standing_times(t, loco_frames, action_frames, timing, float(window), float(loop_start),
                                          float(loop_end), float(blend))
        curve[i] = x
        i0, i1, w = split_time(x, action_frames)
        fading = phase < 1.0
        f = g = 0.0  # the offset's weights: of the pose difference, of the velocity difference
        jump = before_jump = loop_in = after_loop_in = (0, 0, 0.0)
        if fading:
            sph = phase
            u = sph * blend
            f = 1 - sph * sph * (3 - 2 * sph)
            g = u * (1 - sph) ** 2
            jump = split_time(source, action_frames)  # the action's frame the loop jumps back from
            before_jump = split_time(source - 1, action_frames)
            loop_in = split_time(float(loop_start), action_frames)  # and the frame it jumps to
            after_loop_in = split_time(loop_start + 1.0, action_frames)
        for j in range(J):
            if not upper[j] or (method == SPLICE_CODE and idle[j]):
                qstore(out_rot, i, j, qload(rot, loco_start + t, j))
                if j < JT:
                    for c in range(3):
                        out_trans[i, j, c] = trans[loco_start + t, j, c]
                continue
            q = qslerp(qload(rot, action_start + i0, j), qload(rot, action_start + i1, j), w)
            tx = trans[action_start + i0, j, 0] + w * (trans[action_start + i1, j, 0] - trans[action_start + i0, j, 0])
            ty = trans[action_start + i0, j, 1] + w * (trans[action_start + i1, j, 1] - trans[action_start + i0, j, 1])
            tz = trans[action_start + i0, j, 2] + w * (trans[action_start + i1, j, 2] - trans[action_start + i0, j, 2])
            if fading:  # inertialization of the jump back (see torchsplice.splice.standing._sample)
                qb = _slerp_at(rot, action_start, jump, j)
                qbp = _slerp_at(rot, action_start, before_jump, j)
                qs = _slerp_at(rot, action_start, loop_in, j)
                qn = _slerp_at(rot, action_start, after_loop_in, j)
                r = _aa(qmul(qb, qconj(qs)))
                v1 = _aa(qmul(qb, qconj(qbp)))
                v2 = _aa(qmul(qn, qconj(qs)))
                q = qnormalize(qmul(_exp(r[0] * f + (v1[0] - v2[0]) * g, r[1] * f + (v1[1] - v2[1]) * g,
                                         r[2] * f + (v1[2] - v2[2]) * g), q))
                if method == NAIVE_CODE:  # only naive takes the action's translations
                    tx += _translation_offset(trans, action_start, 0, j, jump, before_jump, loop_in, after_loop_in, f, g)
                    ty += _translation_offset(trans, action_start, 1, j, jump, before_jump, loop_in, after_loop_in, f, g)
                    tz += _translation_offset(trans, action_start, 2, j, jump, before_jump, loop_in, after_loop_in, f, g)
            lq = qload(rot, loco_start + t, j)
            if method == NAIVE_CODE:  # naive: the action's upper body, translations too
                qstore(out_rot, i, j, q)
                if j < JT:
                    out_trans[i, j, 0], out_trans[i, j, 1], out_trans[i, j, 2] = tx, ty, tz
                continue
            if method == CPMC_CODE:  # cpmc: the action's motion since its first frame, on the locomotion
                q = qnormalize(qmul(lq, qmul(qconj(qload(rot, action_start, j)), q)))
            elif spine_k[j] >= 0:  # splice: the action's posture with the locomotion's deviation from its mean
                k = spine_k[j]
                q = qnormalize(qmul(q, qmul(qconj((mean[k, 0], mean[k, 1], mean[k, 2], mean[k, 3])), lq)))
            qstore(out_rot, i, j, q)
            if j < JT:
                for c in range(3):
                    out_trans[i, j, c] = trans[loco_start + t, j, c]


@njit(cache=True, nogil=True)
def assemble_timewarp(rot, trans, arc, starts, lengths, loco, action, crop, upper, pelvis, curve, pelvis_rot, part_at,
                      first, count, out_start, out_rot, out_trans):
    """Timewarp clips ``b``: result frames ``first[b] .. first[b] + count[b] - 1`` of
    the pair (bank clips ``loco[b]``, ``action[b]``, the action cropped by ``crop[b]``) into rows
    ``out_start[b] ..`` of ``out_rot``/``out_trans``; ``curve``/``pelvis_rot`` hold those frames' parts
    from row ``part_at[b]`` on (a reader passes the parts it holds in memory as they are, with
    each clip's place in them, so that no rows are gathered first)."""
    for b in range(loco.shape[0]):
        o, n, at = out_start[b], count[b], part_at[b]
        a = action[b]
        timewarp_rows(rot, trans, arc, starts[loco[b]] + first[b], starts[a] + crop[b], lengths[a] - crop[b], upper, pelvis,
                      curve[at:at + n], pelvis_rot[at:at + n], n, out_rot[o:o + n], out_trans[o:o + n])


@njit(cache=True, nogil=True)
def assemble_standing(rot, trans, starts, lengths, loco, action, method, timing, window, loops, acting, upper, spine,
                      arms, blend_s, first, count, out_start, out_rot, out_trans, out_curve):
    """Standing clips ``b`` (per-clip arguments as :func:`standing_rows`'s, ``loops
    (B, 2)``, ``acting (B, 2)``): result frames ``first[b] ..`` into rows ``out_start[b] ..``."""
    for b in range(loco.shape[0]):
        o, n = out_start[b], count[b]
        lo, a = loco[b], action[b]
        standing_rows(rot, trans, starts[lo], lengths[lo], starts[a], lengths[a], method[b], timing[b], window[b],
                      loops[b, 0], loops[b, 1], acting[b], upper, spine, arms, blend_s, first[b], n, out_curve[o:o + n],
                      out_rot[o:o + n], out_trans[o:o + n])
