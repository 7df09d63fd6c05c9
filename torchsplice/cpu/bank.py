"""Python side of the compiled splicer: clips packed into a bank, joint tables, the batch call.

:class:`ClipBank` holds clips of one skeleton at one frame rate, packed along frames, with
their forward kinematics and grid features computed once per clip (not per pair).
:func:`splice_bank` splices pairs of bank clips with :func:`torchsplice.cpu.splice.splice_batch`
and returns packed results (:class:`PackedSplices`). Shapes: ``N`` packed frames, ``J`` joints,
quaternions WXYZ, lengths in the skeleton's units, the up axis from the spec.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from numba import njit, prange

from ..core.motion import Motion
from ..core.skeleton import Skeleton
from ..specs import SkeletonRoles
from ..specs.roles import landmark_indices
from .fk import fk_clips, joint_closure
from .grid import clip_features
from .splice import METHOD_CODES, STATUS, compact, splice_batch

__all__ = ["ClipBank", "PackedSplices", "Buffers", "JointTables", "StandingTables", "joint_config", "splice_bank", "standing_bank"]


class JointTables(NamedTuple):
    """The joint tables of one skeleton that the splice kernels take (:func:`joint_config`), in the
    kernels' order (:func:`torchsplice.cpu.splice.splice_batch` takes them as a plain tuple).

    Attributes:
        parents ``(J,)`` int64; upper ``(J,)`` bool: the upper-body joints; fk_joints: the joints
        whose FK the spatial alignment needs (ancestors included); act_joints: the action's joints
        resampled at the alignment curve (``fk_joints`` and the upper body); landmarks ``(K,)``: the
        joints the distance grid compares; hips, shoulders ``(2,)`` (left, right); pcloud: the
        spine and shoulder joints whose point cloud Horn's alignment fits; pelvis, pelvis_parent
        (-1 when the pelvis is the root); up: the up axis (0 X, 1 Y, 2 Z).
    """

    parents: np.ndarray
    upper: np.ndarray
    fk_joints: np.ndarray
    act_joints: np.ndarray
    landmarks: np.ndarray
    hips: np.ndarray
    shoulders: np.ndarray
    pcloud: np.ndarray
    pelvis: int
    pelvis_parent: int
    up: int

    def to_json(self) -> list:
        return [a.tolist() if isinstance(a, np.ndarray) else a for a in self]

    @classmethod
    def from_json(cls, raw: list) -> "JointTables":
        kinds = (np.int64, np.bool_, np.int64, np.int64, np.int64, np.int64, np.int64, np.int64)
        return cls(*(np.array(raw[k], dtype=kinds[k]) for k in range(8)), *(int(x) for x in raw[8:]))


def joint_config(roles: SkeletonRoles, skeleton: Skeleton, landmarks) -> JointTables:
    """The joint tables the kernels take, for ``roles`` of ``skeleton`` and the grid's
    ``landmarks`` (names of :func:`~torchsplice.specs.roles.landmark_indices`)."""
    parents = np.array(skeleton.parents, dtype=np.int64)
    upper = np.zeros(skeleton.num_joints, dtype=np.bool_)
    upper[list(roles.upper_body)] = True
    pcloud = [j for j in roles.spine if j != roles.pelvis] + list(roles.shoulders)
    fk_joints = joint_closure(parents, [roles.pelvis, *pcloud, *roles.hips, *roles.shoulders])
    act_joints = np.array(sorted(set(fk_joints.tolist()) | set(np.nonzero(upper)[0].tolist())), dtype=np.int64)
    return JointTables(parents, upper, fk_joints, act_joints, np.array(landmark_indices(roles, landmarks), dtype=np.int64),
                       np.array(roles.hips, dtype=np.int64), np.array(roles.shoulders, dtype=np.int64),
                       np.array(pcloud, dtype=np.int64), int(roles.pelvis), int(parents[roles.pelvis]), int(roles.up_axis))


@dataclass(frozen=True)
class StandingTables:
    """The joint tables and frame counts of the standing-action kernels
    (:mod:`torchsplice.cpu.standing`), made by :func:`torchsplice.splice.standing.standing_tables`.

    Attributes:
        upper ``(J,)`` bool: upper-body joints; spine: the upper-body spine joints; arms
        ``(2, J)`` bool: the joints of the left and right arm; chest: the joint the arms hang
        from; hands ``(2,)``: the joints measured (left, right); feat_joints: the joints whose
        positions in the chest frame choose loop points; blend: frames of a loop's fade (before
        the cap at a third of the action); window: frames of the windows loop points compare.
    """

    upper: np.ndarray
    spine: np.ndarray
    arms: np.ndarray
    chest: int
    hands: np.ndarray
    feat_joints: np.ndarray
    blend: int
    window: int


@njit(cache=True, parallel=True)
def _features(pos, starts, lengths, landmarks, hips, up, floor, height, norm, hcos, hsin):
    for c in prange(starts.shape[0]):
        s, n = starts[c], lengths[c]
        clip_features(pos[s:s + n], landmarks, hips, up, n, floor[:, :, s:s + n], height[:, s:s + n], norm[s:s + n],
                      hcos[s:s + n], hsin[s:s + n])


@dataclass
class ClipBank:
    """Clips of one skeleton packed along frames, with FK and grid features (float64).

    Attributes:
        rot ``(N, J, 4)``, trans ``(N, J, 3)`` (row 0: root position), pos ``(N, J, 3)``,
        grot ``(N, J, 4)``; starts, lengths ``(C,)`` int64; feat: the five arrays of
        :func:`torchsplice.cpu.grid.clip_features`; joints: the :class:`JointTables`.
    """

    rot: np.ndarray
    trans: np.ndarray
    pos: np.ndarray
    grot: np.ndarray
    starts: np.ndarray
    lengths: np.ndarray
    feat: tuple
    joints: JointTables

    @classmethod
    def from_arrays(cls, rotations: list, translations: list, skeleton: Skeleton, roles: SkeletonRoles,
                    landmarks=("root", "knees")) -> "ClipBank":
        """A bank from per-clip ``(T, J, 4)`` rotations and ``(T, J, 3)`` local translations."""
        lengths = np.array([len(r) for r in rotations], dtype=np.int64)
        starts = np.concatenate(([0], np.cumsum(lengths)[:-1])).astype(np.int64)
        N, J = int(lengths.sum()), skeleton.num_joints
        rot, trans = np.empty((N, J, 4)), np.empty((N, J, 3))  # filled in place: float64 of any input dtype
        np.concatenate(rotations, axis=0, out=rot)
        np.concatenate(translations, axis=0, out=trans)
        joints = joint_config(roles, skeleton, landmarks)
        pos = np.zeros(trans.shape)
        grot = np.zeros(rot.shape)
        fk_clips(rot, trans, joints.parents, starts, lengths, pos, grot)
        K, N = joints.landmarks.shape[0], rot.shape[0]
        feat = (np.empty((K, 2, N)), np.empty((K, N)), np.empty(N), np.empty(N), np.empty(N))
        _features(pos, starts, lengths, joints.landmarks, joints.hips, joints.up, *feat)
        return cls(rot, trans, pos, grot, starts, lengths, feat, joints)

    @classmethod
    def from_motions(cls, motions: list[Motion], skeleton: Skeleton, roles: SkeletonRoles,
                     landmarks=("root", "knees")) -> "ClipBank":
        """A bank of clips (already at a common frame rate)."""
        return cls.from_arrays([m.rotations.detach().cpu().numpy() for m in motions],
                               [m.local_translations().detach().cpu().numpy() for m in motions],
                               skeleton, roles, landmarks)

    def __len__(self) -> int:
        return len(self.lengths)

    _ARRAYS = ("rot", "trans", "pos", "grot", "starts", "lengths")

    def save(self, folder: Path) -> None:
        """Write the bank into ``folder`` (one ``.npy`` file per array, the joint tables as
        JSON), made under a temporary name and renamed into place."""
        import shutil

        folder = Path(folder)
        tmp = folder.with_name(f".{folder.name}.writing")
        shutil.rmtree(tmp, ignore_errors=True)  # a killed writer's
        tmp.mkdir(parents=True)
        for name in self._ARRAYS:
            np.save(tmp / f"{name}.npy", getattr(self, name))
        for k, a in enumerate(self.feat):
            np.save(tmp / f"feat{k}.npy", a)
        (tmp / "joints.json").write_text(json.dumps(self.joints.to_json()))
        os.replace(tmp, folder)

    @classmethod
    def load(cls, folder: Path) -> "ClipBank":
        """A bank written by :meth:`save`, its arrays memory-mapped copy-on-write: processes that
        map one bank share its pages."""
        folder = Path(folder)
        arrays = {name: np.load(folder / f"{name}.npy", mmap_mode="c") for name in cls._ARRAYS}
        feat = tuple(np.load(folder / f"feat{k}.npy", mmap_mode="c") for k in range(5))
        joints = JointTables.from_json(json.loads((folder / "joints.json").read_text()))
        return cls(arrays["rot"], arrays["trans"], arrays["pos"], arrays["grot"], arrays["starts"], arrays["lengths"],
                   feat, joints)

    def loop_points(self, clips, masks, tables: StandingTables) -> np.ndarray:
        """``(C, 2)`` int64: the loop points (start, end) of bank clips ``clips (C,)`` measured on
        the hands of ``masks (C, 2)`` (see :func:`torchsplice.cpu.standing.loop_points`). Each
        clip's are computed once (in parallel over the clips not seen yet) and kept."""
        from .standing import loop_points_batch

        cache = self.__dict__.setdefault("_loops", {})
        clips = np.asarray(clips, dtype=np.int64)
        masks = np.asarray(masks, dtype=np.float64).reshape(len(clips), 2)
        keys = [(int(c), float(m[0]), float(m[1]), tables.window) for c, m in zip(clips, masks)]
        todo = sorted({k for k in keys if k not in cache})
        if todo:
            out = np.empty((len(todo), 2), np.int64)
            loop_points_batch(self.pos, self.grot, self.starts, self.lengths, np.array([k[0] for k in todo], np.int64),
                              np.array([k[1:3] for k in todo], np.float64), tables.chest, tables.hands, tables.feat_joints,
                              tables.window, out)
            cache.update({k: (int(a), int(b)) for k, (a, b) in zip(todo, out)})
        return np.array([cache[k] for k in keys], dtype=np.int64).reshape(len(keys), 2)

    def padded_positions(self, clips=None) -> tuple[torch.Tensor, torch.Tensor]:
        """FK positions ``(C, T, J, 3)`` of ``clips`` (default: all), padded by repeating each
        clip's last frame, and their lengths ``(C,)``, as float32 torch tensors."""
        clips = np.arange(len(self)) if clips is None else np.asarray(clips, dtype=np.int64)
        lengths = self.lengths[clips]
        T = int(lengths.max())
        rows = self.starts[clips, None] + np.minimum(np.arange(T)[None, :], lengths[:, None] - 1)
        return torch.from_numpy(self.pos[rows].astype(np.float32)), torch.from_numpy(lengths)


@dataclass
class PackedSplices:
    """Results of :func:`splice_bank`, packed: pair ``b``'s frames are rows
    ``start[b] : start[b] + frames[b]`` of ``rotations (M, J, 4)``, ``translations (M, J, 3)``
    (``dtype``), ``curve (M,)`` (action frame at the locomotion's rate, crop included, float64) and
    ``correction (M,)`` (pelvis correction, radians). Per pair: ``frames``, ``crop``, ``cost``
    (mean path cost, NaN for naive), ``posture`` (radians), ``cells (B, P, 2)`` and
    ``path_length`` (the DP path in cropped frames); ``status`` (0, or why the pair failed).

    The parts the frames were assembled from (:mod:`torchsplice.cpu.assemble`): ``part_curve
    (M,)`` (float64: the action frame counted from the crop; a standing pair's: its action frame)
    and ``pelvis (M, 4)`` (float64, timewarp pairs: the pelvis's rotation); per pair ``window``
    (standing pairs: the action's first frame played onto a shorter locomotion) and ``loops
    (B, 2)`` (standing pairs: the loop points)."""

    start: np.ndarray
    frames: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    curve: np.ndarray
    correction: np.ndarray
    crop: np.ndarray
    cost: np.ndarray
    posture: np.ndarray
    cells: np.ndarray
    path_length: np.ndarray
    status: np.ndarray
    part_curve: np.ndarray | None = None
    pelvis: np.ndarray | None = None
    window: np.ndarray | None = None
    loops: np.ndarray | None = None


_NOTED = False


def _note_first_compile() -> None:
    """Say so on a terminal when the kernels are about to be compiled (once per version)."""
    global _NOTED
    if not _NOTED:
        _NOTED = True
        import sys

        from . import warm

        if not warm() and sys.stderr.isatty():
            print("torchsplice: compiling the CPU splicer for this machine (once; about a minute)", file=sys.stderr, flush=True)


class CompiledSpliceError(ValueError):
    """A pair the compiled splicer could not align: ``pair`` (its index in the call) and ``reason``."""

    def __init__(self, pair: int, reason: str):
        super().__init__(f"pair {pair}: {reason}")
        self.pair, self.reason = pair, reason


class Buffers:
    """Output arrays reused from batch to batch (first-touch page faults cost as much as the
    copies): the per-pair room the kernel writes into, and the packed result. Results returned
    with a :class:`Buffers` are views, valid until the next call with the same buffers."""

    def __init__(self):
        self.room: dict = {}
        self.packed: dict = {}

    @staticmethod
    def _get(store: dict, rows: int, J: int, dtype) -> tuple:
        """``(rotations, translations, curve, correction, pelvis)`` with room for ``rows`` frames."""
        have = store.get("arrays")
        if have is None or have[0].shape[0] < rows or have[0].shape[1] != J or have[0].dtype != dtype:
            rows = max(rows, int(1.25 * (have[0].shape[0] if have is not None else 0)))
            have = (np.empty((rows, J, 4), dtype), np.empty((rows, J, 3), dtype), np.empty(rows), np.empty(rows),
                    np.empty((rows, 4)))
            store["arrays"] = have
        return have


def splice_bank(bank: ClipBank, loco, act, method: str = "splice", ref=None, *, max_run: int = 3,
                heading_window_deg: float | None = 60.0, crop: bool = True, crop_context: int = 15,
                crop_window: int = 6, crop_depth: float = 0.25, knot_spacing: float = 7.5,
                smoothing: float = 1e-2, posture: bool = True, twist: float = 0.0, dtype=np.float32,
                buffers: Buffers | None = None, on_error: str = "raise") -> PackedSplices:
    """Splice pairs of bank clips: ``loco``, ``act`` (and ``ref`` for cpmc) ``(B,)`` clip indices.

    Frame counts (``crop_context``, ``crop_window``, ``knot_spacing``) are at the bank's frame
    rate. ``twist`` is the share of the locomotion's torso twist posture transfer adds (see
    :func:`torchsplice.splice.heck.twist_target`). Rotations and translations come out as
    ``dtype`` (float32 or float64; the computation is float64 either way). With ``buffers`` the output arrays are reused from
    call to call (see :class:`Buffers`). A pair that cannot be aligned raises
    :class:`CompiledSpliceError`, or with ``on_error="keep"`` gets no frames and its
    :data:`~torchsplice.cpu.splice.STATUS` code in ``status`` (the other pairs are unaffected).
    """
    _note_first_compile()
    loco = np.ascontiguousarray(loco, dtype=np.int64)
    act = np.ascontiguousarray(act, dtype=np.int64)
    ref = np.ascontiguousarray(ref if ref is not None else np.zeros_like(loco), dtype=np.int64)
    B = len(loco)
    room = bank.lengths[loco]
    out_start = np.concatenate(([0], np.cumsum(room)[:-1])).astype(np.int64)
    M, J = int(room.sum()), bank.rot.shape[1]
    P = int((bank.lengths[loco] + bank.lengths[act]).max()) if B else 1
    if buffers is not None:
        rot_out, trans_out, curve_out, correction_out, pelvis_out = Buffers._get(buffers.room, M, J, dtype)
    else:
        rot_out, trans_out, curve_out, correction_out, pelvis_out = (
            np.empty((M, J, 4), dtype), np.empty((M, J, 3), dtype), np.empty(M), np.empty(M), np.empty((M, 4)))
    cells = np.empty((B, P, 2), np.int64)
    status, crop_out, path_len, frames = (np.empty(B, np.int64) for _ in range(4))
    cost, angle = np.empty(B), np.empty(B)
    max_dev = math.radians(heading_window_deg) if heading_window_deg is not None else math.pi
    opts = (float(max_run), float(max_dev), float(crop), float(crop_context), float(crop_window), float(crop_depth),
            float(knot_spacing), float(smoothing))
    if B:
        splice_batch((bank.rot, bank.trans, bank.pos, bank.grot), bank.feat, bank.starts, bank.lengths, METHOD_CODES[method],
                     loco, act, ref, tuple(bank.joints), opts, bool(posture), float(twist), out_start,
                     rot_out, trans_out, curve_out, correction_out, pelvis_out, cells, status, crop_out, path_len, cost, frames,
                     angle)
    bad = np.nonzero(status != 0)[0]
    if len(bad) and on_error == "raise":
        b = int(bad[0])
        raise CompiledSpliceError(b, STATUS[int(status[b])])
    if B:
        new_start = np.concatenate(([0], np.cumsum(frames)[:-1])).astype(np.int64)
        n = int(frames.sum())
        if buffers is not None:
            packed = Buffers._get(buffers.packed, n, J, dtype)
        else:
            packed = (np.empty((n, J, 4), dtype), np.empty((n, J, 3), dtype), np.empty(n), np.empty(n), np.empty((n, 4)))
        compact(rot_out, trans_out, curve_out, correction_out, pelvis_out, out_start, frames, new_start, *packed)
        rot_out, trans_out, curve_out, correction_out, pelvis_out = (a[:n] for a in packed)
        out_start = new_start
    else:
        rot_out, trans_out, curve_out, correction_out, pelvis_out = (
            a[:0] for a in (rot_out, trans_out, curve_out, correction_out, pelvis_out))
    curve = curve_out + np.repeat(np.where(status == 0, crop_out, 0), frames)  # at the locomotion's rate, crop included
    return PackedSplices(out_start, frames, rot_out, trans_out, curve, correction_out, crop_out, cost, angle, cells, path_len, status,
                         part_curve=curve_out, pelvis=pelvis_out, window=np.zeros(B, np.int64), loops=np.zeros((B, 2), np.int64))


def standing_bank(bank: ClipBank, loco, act, acting, tables: StandingTables, method: str = "splice",
                  timing: str = "loop", dtype=np.float32, buffers: Buffers | None = None) -> PackedSplices:
    """Splice standing actions: pairs of bank clips ``loco``, ``act`` ``(B,)``, with the arms each
    action acts with ``acting (B, 2)`` bool (left, right), by ``method`` and ``timing`` (see
    :mod:`torchsplice.cpu.standing`). Results as :func:`splice_bank`'s, each as long as its
    locomotion: ``curve`` holds the action frame of every result frame (at the bank's rate),
    ``correction``, ``crop``, ``posture`` are 0, ``cost`` NaN, no DP path; every status 0."""
    from .splice import METHOD_CODES
    from .standing import TIMING_CODES, standing_batch

    _note_first_compile()
    loco = np.ascontiguousarray(loco, dtype=np.int64)
    act = np.ascontiguousarray(act, dtype=np.int64)
    B = len(loco)
    acting = np.ascontiguousarray(acting, dtype=np.bool_).reshape(B, 2)
    masks = acting.astype(np.float64)
    masks[masks.sum(1) == 0] = 1.0  # no acting arm: both hands choose the frames
    frames = bank.lengths[loco].astype(np.int64)
    start = np.concatenate(([0], np.cumsum(frames)[:-1])).astype(np.int64)
    M, J = int(frames.sum()), bank.rot.shape[1]
    if buffers is not None:
        rot_out, trans_out, curve_out, correction_out, _ = Buffers._get(buffers.packed, M, J, dtype)
        rot_out, trans_out, curve_out, correction_out = rot_out[:M], trans_out[:M], curve_out[:M], correction_out[:M]
    else:
        rot_out, trans_out, curve_out, correction_out = (np.empty((M, J, 4), dtype), np.empty((M, J, 3), dtype), np.empty(M),
                                                         np.empty(M))
    correction_out[:] = 0.0
    window = np.zeros(B, np.int64)
    loops = bank.loop_points(act, masks, tables) if timing == "loop" and B else np.zeros((B, 2), np.int64)
    if B:
        sj = (tables.upper, tables.spine, tables.arms, int(tables.chest), tables.hands, tables.feat_joints,
              int(tables.blend), int(tables.window), bank.pos, bank.grot)
        standing_batch(bank.rot, bank.trans, bank.starts, bank.lengths, METHOD_CODES[method], TIMING_CODES[timing], loco,
                       act, masks, acting, loops, sj, start, rot_out, trans_out, curve_out, frames, window)
    zeros = np.zeros(B, np.int64)
    return PackedSplices(start, frames, rot_out, trans_out, curve_out, correction_out, zeros.copy(), np.full(B, np.nan),
                         np.zeros(B), np.full((B, 1, 2), -1, np.int64), zeros.copy(), zeros.copy(), part_curve=curve_out, pelvis=None,
                         window=window, loops=np.asarray(loops, np.int64).reshape(B, 2))
