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

``joints`` is :class:`torchsplice.cpu.bank.JointTables` as a plain tuple (its fields, in order:
parents, upper-body mask, FK joints, resampled action joints, landmarks, hips, shoulders,
pelvis-cloud joints, and scalars pelvis, pelvis parent, up axis).
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
def _time_align(feat, starts, clip_a, frames_a, clip_b, frames_b, opts, cells, curve):
    """Align bank clip ``clip_b`` (its first ``frames_b`` frames) to bank clip ``clip_a`` (first ``frames_a``): grid,
    crop, DP, curve.

    Returns ``(status, crop, path_length, cost, frames)``; the path goes to ``cells`` (in cropped
    frames of b) and the curve (cropped frames of b per frame of a) to ``curve``.
    """
    max_run, max_dev, do_crop, context, window, depth, knot_spacing, smoothing = opts
    grid = np.empty((frames_a, frames_b))
    distance_row_block(feat, starts[clip_a], frames_a, starts[clip_b], frames_b, max_dev, grid)
    crop = phase_crop_pair(grid, frames_a, frames_b, int(context), int(window), depth) if do_crop > 0 else 0
    path_length, total_cost = dp_pair(grid, crop, frames_a, frames_b - crop, int(max_run), cells)
    if path_length < 0:
        return 1, crop, 0, np.nan, 0
    frames = fit_curve(cells, path_length, knot_spacing, smoothing, curve)
    if frames < 0:
        return 2, crop, path_length, total_cost / path_length, 0
    return 0, crop, path_length, total_cost / path_length, frames


@njit(cache=True, nogil=True)
def _mean_shoulders(pos, frames, hips, shoulders, pelvis, up, out, headings):
    """Frame-averaged shoulders ``out (2, 3)`` in heading frames around the pelvis; the heading
    frames (of the first ``frames`` rows of ``pos``) go to ``headings (frames, 4)`` when it is not empty."""
    out[:, :] = 0.0
    for t in range(frames):
        heading = heading_q(pos, t, hips[0], hips[1], up)
        if headings.shape[0] > 0:
            headings[t, 0], headings[t, 1], headings[t, 2], headings[t, 3] = heading
        from_heading = qconj(heading)
        for k in range(2):
            shoulder = shoulders[k]
            v = qrot(from_heading, (pos[t, shoulder, 0] - pos[t, pelvis, 0], pos[t, shoulder, 1] - pos[t, pelvis, 1],
                                    pos[t, shoulder, 2] - pos[t, pelvis, 2]))
            out[k, 0] += v[0]
            out[k, 1] += v[1]
            out[k, 2] += v[2]
    out /= frames


@njit(cache=True, nogil=True)
def _twist_target(mean_action, mean_loco, share, up):
    """Turn the action's mean shoulders ``mean_action (2, 3)`` about the up axis, in place, by
    ``share`` times the yaw of the locomotion's ``mean_loco`` minus theirs, as
    :func:`torchsplice.splice.heck.twist_target` (yaw of left minus right shoulder in the floor
    plane, from the lateral axis towards the third). Not a heading (:mod:`.heading`): the
    shoulders' twist against the hips, measured inside heading frames."""
    lateral = 1 if up == 0 else 0
    third = 3 - lateral - up
    yaw_loco = math.atan2(mean_loco[0, third] - mean_loco[1, third], mean_loco[0, lateral] - mean_loco[1, lateral])
    yaw_action = math.atan2(mean_action[0, third] - mean_action[1, third],
                            mean_action[0, lateral] - mean_action[1, lateral])
    angle = share * (yaw_loco - yaw_action)
    c, s = math.cos(angle), math.sin(angle)
    for k in range(2):
        x, z = mean_action[k, lateral], mean_action[k, third]
        mean_action[k, lateral] = c * x - s * z
        mean_action[k, third] = s * x + c * z


@njit(cache=True, nogil=True)
def _assemble(loco_rot, loco_trans, loco_start, action_rot, action_trans, frames, joints_list, upper, pelvis,
              pelvis_rot, out_rot, out_trans):
    """Rows ``t < frames`` of ``out_rot``/``out_trans`` for ``joints_list``: upper body from the resampled
    action ``action_rot``/``action_trans``, the rest from the locomotion (``loco_rot``/``loco_trans``
    rows from ``loco_start``), the pelvis's rotation ``pelvis_rot (frames, 4)`` and its translation
    from the locomotion."""
    for t in range(frames):
        for j in joints_list:
            if j == pelvis:
                (out_rot[t, j, 0], out_rot[t, j, 1], out_rot[t, j, 2],
                 out_rot[t, j, 3]) = pelvis_rot[t, 0], pelvis_rot[t, 1], pelvis_rot[t, 2], pelvis_rot[t, 3]
                for c in range(3):
                    out_trans[t, j, c] = loco_trans[loco_start + t, j, c]
            elif upper[j]:
                for c in range(4):
                    out_rot[t, j, c] = action_rot[t, j, c]
                for c in range(3):
                    out_trans[t, j, c] = action_trans[t, j, c]
            else:
                for c in range(4):
                    out_rot[t, j, c] = loco_rot[loco_start + t, j, c]
                for c in range(3):
                    out_trans[t, j, c] = loco_trans[loco_start + t, j, c]


@njit(cache=True, nogil=True)
def _pelvis_cloud(pos, grot, t, pelvis, cloud, out):
    """Joints ``cloud`` at frame ``t`` in the pelvis's own frame, into ``out (K, 3)``."""
    to_pelvis = qconj(qload(grot, t, pelvis))
    for k in range(cloud.shape[0]):
        j = cloud[k]
        v = qrot(to_pelvis, (pos[t, j, 0] - pos[t, pelvis, 0], pos[t, j, 1] - pos[t, pelvis, 1],
                             pos[t, j, 2] - pos[t, pelvis, 2]))
        out[k, 0], out[k, 1], out[k, 2] = v


@njit(cache=True, nogil=True)
def _splice_one(bank, feat, starts, lengths, loco, action, joints, opts, posture, twist, cells, curve, out_rot,
                out_trans, out_corr, out_pelvis):
    """The Heck et al. splice of one pair; returns ``(status, crop, path_length, cost, frames, posture_angle)``.
    ``twist``: the share of the locomotion's torso twist the posture takes (0: none). Its parts
    go to ``curve`` (the action frame after the crop) and ``out_pelvis`` (the pelvis's rotation), its
    frames, assembled from them (:func:`torchsplice.cpu.assemble.timewarp_rows`), to
    ``out_rot``/``out_trans``; the pelvis correction per frame (radians) to ``out_corr``."""
    rot, trans, pos, grot = bank
    parents, upper, fk_joints, act_joints, landmarks, hips, shoulders, pelvis_cloud, pelvis, pelvis_parent, up = joints
    J = rot.shape[1]
    loco_start, action_start = starts[loco], starts[action]
    status, crop, path_length, cost, T = _time_align(feat, starts, loco, lengths[loco], action, lengths[action], opts,
                                                     cells, curve)
    if status != 0:
        return status, crop, path_length, cost, 0, 0.0
    action_frames = lengths[action] - crop
    # every array below is read only on the joints it is written on (act_joints, fk_joints)
    action_rot = np.empty((T, J, 4))
    action_trans = np.empty((T, J, 3))
    resample_clip(rot, trans, action_start + crop, action_frames, curve, T, act_joints, action_rot, action_trans)
    # spatial alignment: q_A per frame between the pelvis clouds of (action on loco) and loco
    spliced_rot = np.empty((T, J, 4))
    spliced_trans = np.empty((T, J, 3))
    spliced_pos = np.empty((T, J, 3))
    spliced_grot = np.empty((T, J, 4))
    loco_pelvis = np.empty((T, 4))
    for t in range(T):
        for c in range(4):
            loco_pelvis[t, c] = rot[loco_start + t, pelvis, c]
    _assemble(rot, trans, loco_start, action_rot, action_trans, T, fk_joints, upper, pelvis, loco_pelvis, spliced_rot,
              spliced_trans)
    fk_clip(spliced_rot, spliced_trans, parents, fk_joints, T, spliced_pos, spliced_grot)
    K = pelvis_cloud.shape[0]
    spliced_cloud = np.empty((K, 3))
    loco_cloud = np.empty((K, 3))
    pelvis_rot = np.empty((T, 4))
    loco_pos, loco_grot = pos[loco_start:loco_start + T], grot[loco_start:loco_start + T]
    for t in range(T):
        _pelvis_cloud(spliced_pos, spliced_grot, t, pelvis, pelvis_cloud, spliced_cloud)
        _pelvis_cloud(loco_pos, loco_grot, t, pelvis, pelvis_cloud, loco_cloud)
        align = horn_cloud(spliced_cloud, loco_cloud, _UNIFORM)
        out_corr[t] = 2.0 * math.atan2(math.sqrt(align[1] * align[1] + align[2] * align[2] + align[3] * align[3]),
                                       abs(align[0]))
        p = qmul((loco_pelvis[t, 0], loco_pelvis[t, 1], loco_pelvis[t, 2], loco_pelvis[t, 3]), align)
        pelvis_rot[t, 0], pelvis_rot[t, 1], pelvis_rot[t, 2], pelvis_rot[t, 3] = p
    angle = 0.0
    if posture:
        _assemble(rot, trans, loco_start, action_rot, action_trans, T, fk_joints, upper, pelvis, pelvis_rot,
                  spliced_rot, spliced_trans)
        fk_clip(spliced_rot, spliced_trans, parents, fk_joints, T, spliced_pos, spliced_grot)
        headings = np.empty((T, 4))
        mean_spliced = np.empty((2, 3))
        mean_action = np.empty((2, 3))
        _mean_shoulders(spliced_pos, T, hips, shoulders, pelvis, up, mean_spliced, headings)
        action_pos = np.empty((T, J, 3))
        action_grot = np.empty((T, J, 4))
        fk_clip(action_rot, action_trans, parents, fk_joints, T, action_pos, action_grot)
        _mean_shoulders(action_pos, T, hips, shoulders, pelvis, up, mean_action, np.empty((0, 4)))
        if twist != 0.0:
            mean_loco = np.empty((2, 3))
            _mean_shoulders(loco_pos, T, hips, shoulders, pelvis, up, mean_loco, np.empty((0, 4)))
            _twist_target(mean_action, mean_loco, twist, up)
        posture_rot = horn_cloud(mean_spliced, mean_action, _UNIFORM)
        angle = 2.0 * math.atan2(math.sqrt(posture_rot[1] * posture_rot[1] + posture_rot[2] * posture_rot[2]
                                           + posture_rot[3] * posture_rot[3]), abs(posture_rot[0]))
        for t in range(T):
            heading = (headings[t, 0], headings[t, 1], headings[t, 2], headings[t, 3])
            world = qmul(qmul(heading, posture_rot), qconj(heading))
            parent_rot = qload(spliced_grot, t, pelvis_parent) if pelvis_parent >= 0 else (1.0, 0.0, 0.0, 0.0)
            local = qmul(qmul(qconj(parent_rot), world), parent_rot)
            p = qmul(local, (pelvis_rot[t, 0], pelvis_rot[t, 1], pelvis_rot[t, 2], pelvis_rot[t, 3]))
            pelvis_rot[t, 0], pelvis_rot[t, 1], pelvis_rot[t, 2], pelvis_rot[t, 3] = p
    for t in range(T):
        for c in range(4):
            out_pelvis[t, c] = pelvis_rot[t, c]
    # the frames timewarp_rows(rot, trans, arc, loco_start, action_start + crop, action_frames, upper, pelvis, curve,
    # pelvis_rot, ...) assembles
    # from these parts when an alignment store is read: the upper body is the action resampled above
    # (resample_clip: the same slerp and lerp at the same curve), taken from there rather than slerped twice
    _assemble(rot, trans, loco_start, action_rot, action_trans, T, np.arange(J), upper, pelvis, pelvis_rot, out_rot,
              out_trans)
    return 0, crop, path_length, cost, T, angle


@njit(cache=True, nogil=True)
def _naive_one(bank, starts, lengths, loco, action, joints, curve, out_rot, out_trans, out_pelvis):
    """Naive DOF replacement of one pair; returns the number of frames. As a timewarp clip's
    parts: the curve ``t`` and the pelvis's rotation of whichever clip gives the upper body."""
    rot, trans, pos, grot = bank
    upper, pelvis = joints[1], joints[8]
    loco_start, action_start = starts[loco], starts[action]
    n = min(lengths[loco], lengths[action])
    source_start = action_start if upper[pelvis] else loco_start
    for t in range(n):
        curve[t] = t
        for c in range(4):
            out_pelvis[t, c] = rot[source_start + t, pelvis, c]
    timewarp_rows(rot, trans, np.empty((0, rot.shape[1], 2)), loco_start, action_start, lengths[action], upper, pelvis,
                  curve, out_pelvis, n, out_rot, out_trans)
    return n


@njit(cache=True, nogil=True)
def _cpmc_one(bank, feat, starts, lengths, loco, action, ref, joints, opts, cells, curve, out_rot, out_trans):
    """CPMC differencing of one pair against its reference; returns ``(status, crop, path_length, cost, frames)``."""
    rot, trans, pos, grot = bank
    upper = joints[1]
    J = rot.shape[1]
    loco_start, action_start, ref_start = starts[loco], starts[action], starts[ref]
    upper_joints = np.nonzero(upper)[0]
    # the reference aligned to the action (rows: action frames)
    ref_cells = np.full((lengths[action] + lengths[ref], 2), -1, dtype=np.int64)
    ref_curve = np.empty(lengths[action])
    status, ref_crop, _, _, action_frames = _time_align(feat, starts, action, lengths[action], ref, lengths[ref], opts,
                                                        ref_cells, ref_curve)
    if status != 0:
        return status, ref_crop, 0, np.nan, 0
    ref_rot = np.empty((action_frames, J, 4))
    ref_trans = np.empty((action_frames, J, 3))
    resample_clip(rot, trans, ref_start + ref_crop, lengths[ref] - ref_crop, ref_curve, action_frames, upper_joints,
                  ref_rot, ref_trans)
    diff = np.empty((action_frames, J, 4))  # upper-body joints only
    for t in range(action_frames):
        for j in upper_joints:
            qstore(diff, t, j, qmul(qconj(qload(ref_rot, t, j)), qload(rot, action_start + t, j)))
    # the action (its frames with a reference) aligned to the locomotion
    status, crop, path_length, cost, T = _time_align(feat, starts, loco, lengths[loco], action, action_frames, opts,
                                                     cells, curve)
    if status != 0:
        return status, crop, path_length, cost, 0
    for t in range(T):
        i0, i1, w = split_time(curve[t], action_frames - crop)
        for j in range(J):
            loco_q = qload(rot, loco_start + t, j)
            if upper[j]:
                delta = qslerp(qload(diff, crop + i0, j), qload(diff, crop + i1, j), w)
                qstore(out_rot, t, j, qmul(loco_q, delta))
            else:
                qstore(out_rot, t, j, loco_q)
            for c in range(3):
                out_trans[t, j, c] = trans[loco_start + t, j, c]
    return 0, crop, path_length, cost, T


@njit(cache=True, parallel=True, nogil=True)
def splice_batch(bank, feat, starts, lengths, method, loco, action, ref, joints, opts, posture, twist, out_start,
                 out_rot, out_trans, out_curve, out_corr, out_pelvis, cells, status, crop, path_length, cost, frames,
                 angle):
    """Splice every pair ``b`` (bank clips ``loco[b]``, ``action[b]``, ``ref[b]`` for cpmc) in parallel.

    Per pair: ``status`` (0 ok, else a :data:`STATUS` code), ``crop`` (action frames skipped),
    ``path_length`` and ``cells[b]`` (the DP path, -1 padded), ``cost`` (mean path cost), ``frames``,
    ``angle`` (posture rotation, radians; ``twist`` is the share of the locomotion's torso twist
    it takes); per result frame from row ``out_start[b]``:
    ``out_rot``/``out_trans`` (float32 local rotations and translations), ``out_curve`` (action frame,
    counted from the crop), ``out_corr`` (pelvis correction, radians) and ``out_pelvis (M, 4)`` (the
    pelvis's local rotation; splice and naive: with ``out_curve``, the parts the frames are
    assembled from, see :mod:`torchsplice.cpu.assemble`).
    """
    for b in prange(loco.shape[0]):
        row = out_start[b]
        n = lengths[loco[b]]
        rot_b, trans_b, curve_b, corr_b, pelvis_b = (out_rot[row:row + n], out_trans[row:row + n],
                                                     out_curve[row:row + n], out_corr[row:row + n],
                                                     out_pelvis[row:row + n])
        for t in range(n):
            corr_b[t] = 0.0
        if method == NAIVE_CODE:
            frames[b] = _naive_one(bank, starts, lengths, loco[b], action[b], joints, curve_b, rot_b, trans_b, pelvis_b)
            status[b], crop[b], path_length[b], cost[b], angle[b] = 0, 0, 0, np.nan, 0.0
            cells[b, :, :] = -1
            continue
        cells_b = np.empty((cells.shape[1], 2), dtype=np.int64)
        if method == SPLICE_CODE:
            status_b, crop_b, path_b, cost_b, frames_b, angle_b = _splice_one(
                bank, feat, starts, lengths, loco[b], action[b], joints, opts, posture, twist, cells_b, curve_b, rot_b,
                trans_b, corr_b, pelvis_b)
        else:  # cpmc
            status_b, crop_b, path_b, cost_b, frames_b = _cpmc_one(
                bank, feat, starts, lengths, loco[b], action[b], ref[b], joints, opts, cells_b, curve_b, rot_b, trans_b)
            angle_b = 0.0
        status[b], crop[b], path_length[b], cost[b], frames[b], angle[b] = (status_b, crop_b, path_b, cost_b, frames_b,
                                                                            angle_b)
        for p in range(cells.shape[1]):
            cells[b, p, 0] = cells_b[p, 0] if p < path_b else -1
            cells[b, p, 1] = cells_b[p, 1] if p < path_b else -1


@njit(cache=True, parallel=True, nogil=True)
def compact(rot, trans, curve, corr, pelvis, start, frames, new_start, packed_rot, packed_trans, packed_curve,
            packed_corr, packed_pelvis):
    """Copy pair ``b``'s ``frames[b]`` rows from ``start[b]`` to ``new_start[b]`` of the ``packed_*``
    arrays (packing the results of :func:`splice_batch` without gaps), in parallel over pairs."""
    for b in prange(start.shape[0]):
        old, new, n = start[b], new_start[b], frames[b]
        packed_rot[new:new + n] = rot[old:old + n]
        packed_trans[new:new + n] = trans[old:old + n]
        packed_curve[new:new + n] = curve[old:old + n]
        packed_corr[new:new + n] = corr[old:old + n]
        packed_pelvis[new:new + n] = pelvis[old:old + n]
