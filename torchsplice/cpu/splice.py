"""Compiled splicing of many pairs: one pair per thread, the whole method in one pass.

The same steps and results as the torch implementation (:mod:`torchsplice.splice.heck` and
:mod:`torchsplice.splice.methods`), computed per pair in float64 and written as float32:

- ``splice`` (Heck et al. 2006): distance grid, phase crop, DP timewarp, B-spline curve, the
  action resampled on it, per-frame Horn rotation of the pelvis clouds, posture transfer in
  the heading frame, assembly (root and lower body from the locomotion);
- ``naive``: upper-body local rotations and translations copied frame by frame;
- ``cpmc``: the reference aligned to the action, per-joint differences ``q_ref^-1 q_act``,
  the action aligned to the locomotion, the differences resampled and added to it.

Inputs are a *bank* of prepared clips, packed along frames (clip ``c`` is rows
``starts[c] : starts[c] + lengths[c]``): local rotations ``rot (N, J, 4)`` (WXYZ), local
translations ``trans (N, J, 3)`` (row 0: root position), their FK ``pos (N, J, 3)`` and
``grot (N, J, 4)``, and the grid features of :func:`torchsplice.cpu.grid.clip_features`.
Pairs index the bank. Each pair writes its result into rows ``out_start[b] :`` of the outputs
(room for its locomotion's length) and its scalars into per-pair arrays; nothing a pair
computes depends on the other pairs of the call, so results do not depend on batching.

``joints`` (see :func:`joint_config` in :mod:`torchsplice.cpu.bank`) is a tuple of int64
arrays: parents, upper-body mask, FK joints, resampled action joints, landmarks, hips,
shoulders, pelvis-cloud joints, and scalars pelvis, pelvis parent, up axis.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..core.method_table import BUILTINS
from .curve import fit_curve, resample_clip, split_time
from .fk import fk_clip
from .grid import distance_row_block, phase_crop_pair
from .heading import heading_q
from .horn import horn_cloud
from .assemble import NAIVE_CODE, SPLICE_CODE, timewarp_rows
from .quat import qconj, qload, qmul, qrot, qslerp, qstore
from .timewarp import dp_pair

__all__ = ["METHOD_CODES", "STATUS", "splice_batch", "compact"]

METHOD_CODES = {m.name: m.code for m in BUILTINS}
"""Built-in method name -> its code in the kernels (:data:`torchsplice.core.method_table.BUILTINS`)."""
_UNIFORM = np.empty(0)  # horn_cloud's uniform weights
STATUS = {0: "ok", 1: "no path: +inf costs block every alignment", 2: "the alignment does not advance in both clips"}


@njit(cache=True, nogil=True)
def _time_align(feat, starts, a, na, b, nb, opts, cells, curve):
    """Align clip ``b`` (its first ``nb`` frames) to clip ``a`` (first ``na``): grid, crop, DP, curve.

    Returns ``(status, crop, path_length, cost, frames)``; the path goes to ``cells`` (in cropped
    frames of b) and the curve (cropped frames of b per frame of a) to ``curve``.
    """
    max_run, max_dev, do_crop, context, window, depth, knot_spacing, smoothing = opts
    grid = np.empty((na, nb))
    distance_row_block(feat, starts[a], na, starts[b], nb, max_dev, grid)
    crop = phase_crop_pair(grid, na, nb, int(context), int(window), depth) if do_crop > 0 else 0
    length, total = dp_pair(grid, crop, na, nb - crop, int(max_run), cells)
    if length < 0:
        return 1, crop, 0, np.nan, 0
    frames = fit_curve(cells, length, knot_spacing, smoothing, curve)
    if frames < 0:
        return 2, crop, length, total / length, 0
    return 0, crop, length, total / length, frames


@njit(cache=True, nogil=True)
def _mean_shoulders(pos, T, hips, shoulders, pelvis, up, out, H):
    """Frame-averaged shoulders ``out (2, 3)`` in heading frames around the pelvis; the heading
    frames go to ``H (T, 4)`` when it is not empty."""
    out[:, :] = 0.0
    for t in range(T):
        h = heading_q(pos, t, hips[0], hips[1], up)
        if H.shape[0] > 0:
            H[t, 0], H[t, 1], H[t, 2], H[t, 3] = h
        hc = qconj(h)
        for k in range(2):
            s = shoulders[k]
            v = qrot(hc, (pos[t, s, 0] - pos[t, pelvis, 0], pos[t, s, 1] - pos[t, pelvis, 1], pos[t, s, 2] - pos[t, pelvis, 2]))
            out[k, 0] += v[0]
            out[k, 1] += v[1]
            out[k, 2] += v[2]
    out /= T


@njit(cache=True, nogil=True)
def _twist_target(mean_u, mean_l, share, up):
    """Turn the action's mean shoulders ``mean_u (2, 3)`` about the up axis, in place, by
    ``share`` times the yaw of the locomotion's ``mean_l`` minus theirs, as
    :func:`torchsplice.splice.heck.twist_target` (yaw of left minus right shoulder in the floor
    plane, from the lateral axis towards the third). Not a heading (:mod:`.heading`): the
    shoulders' twist against the hips, measured inside heading frames."""
    lat = 1 if up == 0 else 0
    third = 3 - lat - up
    yl = math.atan2(mean_l[0, third] - mean_l[1, third], mean_l[0, lat] - mean_l[1, lat])
    yu = math.atan2(mean_u[0, third] - mean_u[1, third], mean_u[0, lat] - mean_u[1, lat])
    a = share * (yl - yu)
    c, s = math.cos(a), math.sin(a)
    for k in range(2):
        x, z = mean_u[k, lat], mean_u[k, third]
        mean_u[k, lat] = c * x - s * z
        mean_u[k, third] = s * x + c * z


@njit(cache=True, nogil=True)
def _assemble(lrot, ltrans, ls, arot, atrans, T, joints_list, upper, pelvis, prot, rot, trans):
    """Rows ``t < T`` for ``joints_list``: upper body from the resampled action, the rest from the
    locomotion (rows from ``ls``), the pelvis's rotation ``prot (T, 4)`` and its translation
    from the locomotion."""
    for t in range(T):
        for j in joints_list:
            if j == pelvis:
                rot[t, j, 0], rot[t, j, 1], rot[t, j, 2], rot[t, j, 3] = prot[t, 0], prot[t, 1], prot[t, 2], prot[t, 3]
                for c in range(3):
                    trans[t, j, c] = ltrans[ls + t, j, c]
            elif upper[j]:
                for c in range(4):
                    rot[t, j, c] = arot[t, j, c]
                for c in range(3):
                    trans[t, j, c] = atrans[t, j, c]
            else:
                for c in range(4):
                    rot[t, j, c] = lrot[ls + t, j, c]
                for c in range(3):
                    trans[t, j, c] = ltrans[ls + t, j, c]


@njit(cache=True, nogil=True)
def _pelvis_cloud(pos, grot, t, pelvis, cloud, out):
    """Joints ``cloud`` at frame ``t`` in the pelvis's own frame, into ``out (K, 3)``."""
    qc = qconj(qload(grot, t, pelvis))
    for k in range(cloud.shape[0]):
        j = cloud[k]
        v = qrot(qc, (pos[t, j, 0] - pos[t, pelvis, 0], pos[t, j, 1] - pos[t, pelvis, 1], pos[t, j, 2] - pos[t, pelvis, 2]))
        out[k, 0], out[k, 1], out[k, 2] = v


@njit(cache=True, nogil=True)
def _splice_one(bank, feat, starts, lengths, loco, act, joints, opts, posture, twist, cells, curve, orot, otrans, ocorr,
                opel):
    """The Heck et al. splice of one pair; returns ``(status, crop, path_length, cost, frames, posture_angle)``.
    ``twist``: the share of the locomotion's torso twist the posture takes (0: none). Its parts
    go to ``curve`` (the action frame after the crop) and ``opel`` (the pelvis's rotation), its
    frames, assembled from them (:func:`torchsplice.cpu.assemble.timewarp_rows`), to ``orot``/``otrans``."""
    rot, trans, pos, grot = bank
    parents, upper, fk_joints, act_joints, landmarks, hips, shoulders, pcloud, pelvis, pelvis_parent, up = joints
    J = rot.shape[1]
    ls, as_ = starts[loco], starts[act]
    status, crop, plen, cost, T = _time_align(feat, starts, loco, lengths[loco], act, lengths[act], opts, cells, curve)
    if status != 0:
        return status, crop, plen, cost, 0, 0.0
    n_c = lengths[act] - crop
    # every array below is read only on the joints it is written on (act_joints, fk_joints)
    arot = np.empty((T, J, 4))
    atrans = np.empty((T, J, 3))
    resample_clip(rot, trans, as_ + crop, n_c, curve, T, act_joints, arot, atrans)
    # spatial alignment: q_A per frame between the pelvis clouds of (action on loco) and loco
    frot = np.empty((T, J, 4))
    ftrans = np.empty((T, J, 3))
    fpos = np.empty((T, J, 3))
    fgrot = np.empty((T, J, 4))
    q_lp = np.empty((T, 4))
    for t in range(T):
        for c in range(4):
            q_lp[t, c] = rot[ls + t, pelvis, c]
    _assemble(rot, trans, ls, arot, atrans, T, fk_joints, upper, pelvis, q_lp, frot, ftrans)
    fk_clip(frot, ftrans, parents, fk_joints, T, fpos, fgrot)
    K = pcloud.shape[0]
    src = np.empty((K, 3))
    tgt = np.empty((K, 3))
    prot = np.empty((T, 4))
    lpos, lgrot = pos[ls:ls + T], grot[ls:ls + T]
    for t in range(T):
        _pelvis_cloud(fpos, fgrot, t, pelvis, pcloud, src)
        _pelvis_cloud(lpos, lgrot, t, pelvis, pcloud, tgt)
        qa = horn_cloud(src, tgt, _UNIFORM)
        ocorr[t] = 2.0 * math.atan2(math.sqrt(qa[1] * qa[1] + qa[2] * qa[2] + qa[3] * qa[3]), abs(qa[0]))
        p = qmul((q_lp[t, 0], q_lp[t, 1], q_lp[t, 2], q_lp[t, 3]), qa)
        prot[t, 0], prot[t, 1], prot[t, 2], prot[t, 3] = p
    angle = 0.0
    if posture:
        _assemble(rot, trans, ls, arot, atrans, T, fk_joints, upper, pelvis, prot, frot, ftrans)
        fk_clip(frot, ftrans, parents, fk_joints, T, fpos, fgrot)
        H = np.empty((T, 4))
        mean_s = np.empty((2, 3))
        mean_u = np.empty((2, 3))
        _mean_shoulders(fpos, T, hips, shoulders, pelvis, up, mean_s, H)
        upos = np.empty((T, J, 3))
        ugrot = np.empty((T, J, 4))
        fk_clip(arot, atrans, parents, fk_joints, T, upos, ugrot)
        _mean_shoulders(upos, T, hips, shoulders, pelvis, up, mean_u, np.empty((0, 4)))
        if twist != 0.0:
            mean_l = np.empty((2, 3))
            _mean_shoulders(lpos, T, hips, shoulders, pelvis, up, mean_l, np.empty((0, 4)))
            _twist_target(mean_u, mean_l, twist, up)
        qg = horn_cloud(mean_s, mean_u, _UNIFORM)
        angle = 2.0 * math.atan2(math.sqrt(qg[1] * qg[1] + qg[2] * qg[2] + qg[3] * qg[3]), abs(qg[0]))
        for t in range(T):
            h = (H[t, 0], H[t, 1], H[t, 2], H[t, 3])
            world = qmul(qmul(h, qg), qconj(h))
            qpar = qload(fgrot, t, pelvis_parent) if pelvis_parent >= 0 else (1.0, 0.0, 0.0, 0.0)
            local = qmul(qmul(qconj(qpar), world), qpar)
            p = qmul(local, (prot[t, 0], prot[t, 1], prot[t, 2], prot[t, 3]))
            prot[t, 0], prot[t, 1], prot[t, 2], prot[t, 3] = p
    for t in range(T):
        for c in range(4):
            opel[t, c] = prot[t, c]
    # the frames timewarp_rows(rot, trans, arc, ls, as_ + crop, n_c, upper, pelvis, curve, prot, ...) assembles
    # from these parts when an alignment store is read: the upper body is the action resampled above
    # (resample_clip: the same slerp and lerp at the same curve), taken from there rather than slerped twice
    _assemble(rot, trans, ls, arot, atrans, T, np.arange(J), upper, pelvis, prot, orot, otrans)
    return 0, crop, plen, cost, T, angle


@njit(cache=True, nogil=True)
def _naive_one(bank, starts, lengths, loco, act, joints, curve, orot, otrans, opel):
    """Naive DOF replacement of one pair; returns the number of frames. As a timewarp clip's
    parts: the curve ``t`` and the pelvis's rotation of whichever clip gives the upper body."""
    rot, trans, pos, grot = bank
    upper, pelvis = joints[1], joints[8]
    ls, as_ = starts[loco], starts[act]
    T = min(lengths[loco], lengths[act])
    src = as_ if upper[pelvis] else ls
    for t in range(T):
        curve[t] = t
        for c in range(4):
            opel[t, c] = rot[src + t, pelvis, c]
    timewarp_rows(rot, trans, np.empty((0, rot.shape[1], 2)), ls, as_, lengths[act], upper, pelvis, curve, opel, T, orot, otrans)
    return T


@njit(cache=True, nogil=True)
def _cpmc_one(bank, feat, starts, lengths, loco, act, ref, joints, opts, cells, curve, orot, otrans):
    """CPMC differencing of one pair against its reference; returns ``(status, crop, path_length, cost, frames)``."""
    rot, trans, pos, grot = bank
    upper = joints[1]
    J = rot.shape[1]
    ls, as_, rs = starts[loco], starts[act], starts[ref]
    upper_joints = np.nonzero(upper)[0]
    # the reference aligned to the action (rows: action frames)
    c1 = np.full((lengths[act] + lengths[ref], 2), -1, dtype=np.int64)
    curve1 = np.empty(lengths[act])
    status, crop1, _, _, n_act = _time_align(feat, starts, act, lengths[act], ref, lengths[ref], opts, c1, curve1)
    if status != 0:
        return status, crop1, 0, np.nan, 0
    rrot = np.empty((n_act, J, 4))
    rtrans = np.empty((n_act, J, 3))
    resample_clip(rot, trans, rs + crop1, lengths[ref] - crop1, curve1, n_act, upper_joints, rrot, rtrans)
    diff = np.empty((n_act, J, 4))  # upper-body joints only
    for t in range(n_act):
        for j in upper_joints:
            qstore(diff, t, j, qmul(qconj(qload(rrot, t, j)), qload(rot, as_ + t, j)))
    # the action (its frames with a reference) aligned to the locomotion
    status, crop, plen, cost, T = _time_align(feat, starts, loco, lengths[loco], act, n_act, opts, cells, curve)
    if status != 0:
        return status, crop, plen, cost, 0
    for t in range(T):
        i0, i1, w = split_time(curve[t], n_act - crop)
        for j in range(J):
            base = qload(rot, ls + t, j)
            if upper[j]:
                d = qslerp(qload(diff, crop + i0, j), qload(diff, crop + i1, j), w)
                qstore(orot, t, j, qmul(base, d))
            else:
                qstore(orot, t, j, base)
            for c in range(3):
                otrans[t, j, c] = trans[ls + t, j, c]
    return 0, crop, plen, cost, T


@njit(cache=True, parallel=True, nogil=True)
def splice_batch(bank, feat, starts, lengths, method, loco, act, ref, joints, opts, posture, twist, out_start,
                 orot, otrans, ocurve, ocorr, opel, cells, status, crop, plen, cost, frames, angle):
    """Splice every pair ``b`` (bank clips ``loco[b]``, ``act[b]``, ``ref[b]`` for cpmc) in parallel.

    Per pair: ``status`` (0 ok, else a :data:`STATUS` code), ``crop`` (action frames skipped),
    ``plen`` and ``cells[b]`` (the DP path, -1 padded), ``cost`` (mean path cost), ``frames``,
    ``angle`` (posture rotation, radians; ``twist`` is the share of the locomotion's torso twist
    it takes); per result frame from row ``out_start[b]``:
    ``orot``/``otrans`` (float32 local rotations and translations), ``ocurve`` (action frame,
    counted from the crop), ``ocorr`` (pelvis correction, radians) and ``opel (M, 4)`` (the
    pelvis's local rotation; splice and naive: with ``ocurve``, the parts the frames are
    assembled from, see :mod:`torchsplice.cpu.assemble`).
    """
    for b in prange(loco.shape[0]):
        o = out_start[b]
        n = lengths[loco[b]]
        r, tr, cu, co, pe = orot[o:o + n], otrans[o:o + n], ocurve[o:o + n], ocorr[o:o + n], opel[o:o + n]
        for t in range(n):
            co[t] = 0.0
        if method == NAIVE_CODE:
            frames[b] = _naive_one(bank, starts, lengths, loco[b], act[b], joints, cu, r, tr, pe)
            status[b], crop[b], plen[b], cost[b], angle[b] = 0, 0, 0, np.nan, 0.0
            cells[b, :, :] = -1
            continue
        cb = np.empty((cells.shape[1], 2), dtype=np.int64)
        if method == SPLICE_CODE:
            st, c, pl, cs, T, ang = _splice_one(bank, feat, starts, lengths, loco[b], act[b], joints, opts, posture,
                                                twist, cb, cu, r, tr, co, pe)
        else:  # cpmc
            st, c, pl, cs, T = _cpmc_one(bank, feat, starts, lengths, loco[b], act[b], ref[b], joints, opts, cb, cu, r, tr)
            ang = 0.0
        status[b], crop[b], plen[b], cost[b], frames[b], angle[b] = st, c, pl, cs, T, ang
        for p in range(cells.shape[1]):
            cells[b, p, 0] = cb[p, 0] if p < pl else -1
            cells[b, p, 1] = cb[p, 1] if p < pl else -1


@njit(cache=True, parallel=True, nogil=True)
def compact(rot, trans, curve, corr, pel, start, frames, new_start, crot, ctrans, ccurve, ccorr, cpel):
    """Copy pair ``b``'s ``frames[b]`` rows from ``start[b]`` to ``new_start[b]`` (packing the
    results of :func:`splice_batch` without gaps), in parallel over pairs."""
    for b in prange(start.shape[0]):
        s, d, n = start[b], new_start[b], frames[b]
        crot[d:d + n] = rot[s:s + n]
        ctrans[d:d + n] = trans[s:s + n]
        ccurve[d:d + n] = curve[s:s + n]
        ccorr[d:d + n] = corr[s:s + n]
        cpel[d:d + n] = pel[s:s + n]
