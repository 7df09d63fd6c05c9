"""Alignment stores: spliced clips kept as what splicing computed, their motions assembled where
they are read.

A motion store (every database but these) holds each clip's frames. An *alignment store*
(``splice-all --store alignment``) holds each source clip once and, per spliced clip, only
its parts; every read assembles the motion from them with the compiled kernels of
:mod:`torchsplice.cpu.assemble`, the same code the motion store's frames were written with,
so a read gives the motion store's clip bit for bit. Readers (``read``, ``read_many``,
``read_batch``, ``batches``, ``packed``, ``frame_array``) see frames either way;
the database's methods for alignment stores are :class:`~torchsplice.store.assembling.Assembling`'s.

Layout, besides :mod:`torchsplice.store.schema`'s (root attribute ``store="alignment"``,
``schema_version=2``, and ``store_readme``, which says this in prose for a reader with plain h5py)::

    /assembly/banks/<b>/      one group per bank of source clips (one skeleton, one frame rate)
        rotations           (N_b, J, 4)  local rotations, WXYZ (float32, or float64 where the
                                         splicer's bank held values float32 cannot)
        translations        (N_b, J, 3)  local translations, row 0 the root's position
        starts, lengths     (C_b,) int64 source clip c is rows starts[c]:starts[c]+lengths[c]
        names               (C_b,) str   the source clip (an action retargeted onto this
                                         skeleton: "NAME (retargeted)")
        keys                (C_b,) str   the job's key of each source clip
        fps                 (C_b,) float64
        attrs: tables (JSON: upper, pelvis, standing_upper, spine, arms, blend, moved; joint indices)
    /skeletons/<k>/assembly_curve   (N_k,) float64   per frame of a timewarp clip: the action
                                                     frame it plays, counted from the crop
    /skeletons/<k>/assembly_pelvis  (N_k, 4) float32 per spliced frame: the pelvis's local
                                                     rotation (timewarp clips)
    /skeletons/<k>/assembly_arms    (N_k, 4, 4) float32 per spliced frame whose arms were moved
                                                     out of the body (torchsplice.ops.hands): the
                                                     local rotations of the bank table "moved"'s
                                                     joints (left shoulder, left elbow, right
                                                     shoulder, right elbow), which replace the
                                                     assembled ones; zeros for a joint not moved
                                                     (optional: stores without it move none)
    /clips/assembly_kind    -1: frames stored in rotations/... as in a motion store (methods whose
                            result is not an alignment: cpmc through the timewarp, plug-ins;
                            copied source clips);
                            1: timewarp (splice, naive); 2: standing action (the locomotion with the
                            action's upper body at a timing: loop, hold or fit; see STORE_README)
    /clips/assembly_bank, assembly_locomotion, assembly_action: the bank and its two source clips
    /clips/assembly_crop, assembly_method (0 splice, 1 naive, 2 cpmc), assembly_timing (0 loop,
           1 hold, 2 fit), assembly_window, assembly_loop_start, assembly_loop_end,
           assembly_acting (bit 0 left arm, bit 1 right arm)

The ``assembly_*`` clip columns are not among a database's :attr:`columns` (they are the
store's, not the user's: ``info --csv`` and the indexes do not list them). The frame datasets
(``rotations``, ...) have a row for every frame, written only for clips of kind -1 (HDF5 stores
no chunk that was never written).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import torch

from ..core.errors import DatabaseError
from ..core.method_table import BUILTINS
from ..core.ranges import lengths_to_starts, ranges_to_rows
from ..core.threads import run_in_threads, split_by_weight
from .assembly_torch import as_tensor, standing_frames, timewarp_frames
from .schema import CLIPS, damaged_frame, refuse_non_finite, skeleton_path
from .state import DatabaseState

__all__ = [
    "STORES",
    "ALIGNMENT",
    "MOTION",
    "PART_COLUMNS",
    "FRAME_PARTS",
    "KIND_CODES",
    "METHOD_CODES",
    "TIMING_CODES",
    "BANKS",
    "STORE_README",
    "store_kind",
    "bank_tables",
    "Assembly",
]

MOTION, ALIGNMENT = "motion", "alignment"
STORES = (MOTION, ALIGNMENT)
"""What a spliced output stores: each clip's frames, or what splicing computed (see the module docstring)."""
BANKS = "assembly/banks"
PART_COLUMNS = {
    name: "int"
    for name in (
        "assembly_kind",
        "assembly_bank",
        "assembly_locomotion",
        "assembly_action",
        "assembly_crop",
        "assembly_method",
        "assembly_timing",
        "assembly_window",
        "assembly_loop_start",
        "assembly_loop_end",
        "assembly_acting",
    )
}
"""The per-clip parts (hidden clip columns of an alignment store)."""
FRAME_PARTS = {
    "assembly_curve": ((), np.float64),
    "assembly_pelvis": ((4,), np.float32),
    "assembly_arms": ((4, 4), np.float32),
}
"""The per-frame parts: name -> (shape of a row, dtype)."""
OPTIONAL_PARTS = ("assembly_arms",)
"""Per-frame parts a store written before them lacks (read as nothing to apply)."""
HELD_PARTS_BYTES = 256 << 20
"""An alignment store's ``assembly_curve`` and ``assembly_pelvis`` of a skeleton (8 and 16 bytes a frame) are each
read whole, once per open database, where they take at most this many bytes (about 11 million frames), from the
:data:`HOLD_AFTER_READS`-th read of the database on: reads then take their frames' parts from memory instead of
reading each clip's rows from the file (a shuffled batch of 64 clips was 128 small reads), and a reader of a few
clips never reads them all. A larger store, or one whose read fails (a damaged chunk), reads each clip's rows as
they are asked for. The moved arms (``assembly_arms``) are held likewise, only the rows of the clips moved."""
HOLD_AFTER_READS = 4  # reads of an open alignment store (per skeleton and part) before its parts are held
SPLIT_FRAMES = 2048  # frames a thread assembles at least before a read is shared over threads (Assembly.frames)
MOVED_COLUMN = "corrected_frames"
"""The clip column that says a clip's arms were moved (above 0): only their ``assembly_arms`` rows are read."""
METHOD_CODES = {m.name: m.code for m in BUILTINS}
"""``assembly_method``: the built-in methods' codes (:data:`torchsplice.core.method_table.BUILTINS`)."""
TIMING_CODES = {"loop": 0, "hold": 1, "fit": 2}
"""``assembly_timing``: a standing action's timing (as :data:`torchsplice.cpu.standing.TIMING_CODES`)."""
KIND_CODES = {"motion": -1, "timewarp": 1, "standing": 2}
"""``assembly_kind``: -1 (an int column's empty value) for a clip whose frames are stored."""
STORE_README = (
    "torchsplice alignment store: the spliced clips' motions are not stored; each is assembled from two source "
    "clips and what splicing computed. Source clips: /assembly/banks/<b>/rotations (N,J,4 WXYZ local) and "
    "translations (N,J,3 local, row 0 the root), clip c at rows starts[c]:starts[c]+lengths[c]; the bank's joint "
    "sets are its attribute 'tables' (JSON, joint indices: upper, pelvis, standing_upper, spine, arms [left, right], "
    "blend in frames, moved). A spliced clip (row i of /clips, frames start:start+length of /skeletons/<k>; x(t) "
    "below is sampled between action frames floor(x) and floor(x)+1, the last held: rotations slerped, translations "
    "linearly) of assembly_kind 1 (timewarp: splice, naive) plays, at frame t, bank clip assembly_locomotion's frame "
    "t, its pelvis rotation replaced by assembly_pelvis[t], and on the joints of tables.upper bank clip "
    "assembly_action at x = assembly_crop + assembly_curve[t]. Kind 2 (a standing action, which does not locomote) "
    "plays the locomotion's frame t except on tables.standing_upper, where it plays the action (A frames, L the "
    "locomotion's) at x(t) per assembly_timing: 2 fit t*(A-1)/(L-1); else where L <= A assembly_window + t; 1 hold "
    "min(t, A-1); 0 loop t until assembly_loop_end, then assembly_loop_start + (t - loop_end) mod (loop_end - "
    "loop_start), each jump back faded over min(tables.blend, A//3) frames. assembly_acting (bit 0 left, bit 1 "
    "right) names the arms of tables.arms that act; assembly_method 0 (splice): the arms not acting keep the "
    "locomotion's, the other joints take the action's rotation, on tables.spine times the inverse of the "
    "locomotion's mean posture times its rotation at t; 1 (naive): the action's rotations and translations; 2 "
    "(cpmc): the locomotion's rotation times the action's since its first frame; splice and cpmc keep the "
    "locomotion's translations; the exact arithmetic, the fade included, is torchsplice/cpu/assemble.py's "
    "standing_rows. A frame's row of /skeletons/<k>/assembly_arms (4,4) holds, for "
    "each of tables.moved (shoulders and elbows moved out of the body), the local rotation that replaces the "
    "assembled one, or zeros where that joint was not moved; kind -1 clips hold their frames in "
    "/skeletons/<k>/rotations etc. `torchsplice materialize IN -o OUT` writes every motion as an ordinary "
    "database; torchsplice's MotionDatabase reads either transparently."
)


def store_kind(attrs) -> str:
    """``"alignment"`` or ``"motion"``: what a database's root attributes say it stores."""
    v = attrs.get("store", MOTION)
    v = v.decode(errors="replace") if isinstance(v, bytes) else str(v)
    return v or MOTION


def bank_tables(raw: dict, J: int) -> dict:
    """A bank's joint tables as the kernels take them (checked against ``J`` joints)."""

    def mask(v):
        m = np.zeros(J, np.bool_)
        m[np.asarray(v, np.int64)] = True
        return m

    arms = np.zeros((2, J), np.bool_)
    for a in range(2):
        arms[a] = mask(raw["arms"][a])
    pelvis = int(raw["pelvis"])
    if not 0 <= pelvis < J:
        raise IndexError(f"pelvis {pelvis}")
    spine = np.asarray(raw["spine"], np.int64).reshape(-1)
    if ((spine < 0) | (spine >= J)).any():
        raise IndexError(f"spine joint out of {J}")
    moved = np.asarray(raw.get("moved", ()), np.int64).reshape(-1)
    if len(moved) not in (0, 4) or ((moved < 0) | (moved >= J)).any():
        raise IndexError(f"moved joints {moved.tolist()} (4 of {J} joints)")
    return {
        "upper": mask(raw["upper"]),
        "pelvis": pelvis,
        "standing_upper": mask(raw["standing_upper"]),
        "spine": spine,
        "arms": arms,
        "blend": int(raw["blend"]),
        "moved": moved,
    }


class Assembly:
    """An alignment store's source banks and per-clip parts, read once per open database, and the
    assembly of frame ranges from them (:meth:`frames`)."""

    def __init__(self, db: DatabaseState) -> None:
        h5 = db.h5
        self.banks = []
        for b in range(len(h5[BANKS])):
            g = h5[f"{BANKS}/{b}"]
            rot, trans = g["rotations"][()], g["translations"][()]
            self.banks.append(
                {
                    "rot": rot.astype(np.float64),
                    "trans": trans.astype(np.float64),
                    "starts": g["starts"][()].astype(np.int64),
                    "lengths": g["lengths"][()].astype(np.int64),
                    "tables": bank_tables(json.loads(g.attrs["tables"]), rot.shape[1]),
                }
            )
        c = h5[CLIPS]
        self.parts = {n: c[n][()].astype(np.int64) for n in PART_COLUMNS}
        # the clips whose arms were moved out of the body (their assembly_arms rows are read)
        self.moved = c[MOVED_COLUMN][()].astype(np.int64) > 0 if MOVED_COLUMN in c else None
        self.skeleton = c["skeleton"][()].astype(np.int64)
        self.start = c["start"][()].astype(np.int64)
        self.length = c["length"][()].astype(np.int64)
        self.by_skeleton: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.held: dict[tuple[int, str], Any] = {}  # see HELD_PARTS_BYTES
        self.reads: dict[tuple[int, str], int] = {}
        self.arrays: dict[int, tuple[int, np.dtype, bool]] = {}  # see skeleton_arrays
        # (banks, 4): each bank's moved joints (its tables' "moved"), -1 where its skeleton has none
        self.moved_joints = np.array(
            [t if len(t) == 4 else [-1] * 4 for t in (b["tables"]["moved"] for b in self.banks)], np.int64
        ).reshape(-1, 4)

    def clips_of(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """``(starts, rows)``: the clips of skeleton ``k`` sorted by their first frame."""
        if k not in self.by_skeleton:
            rows = np.flatnonzero(self.skeleton == k)
            rows = rows[np.argsort(self.start[rows], kind="stable")]
            self.by_skeleton[k] = (self.start[rows], rows)
        return self.by_skeleton[k]

    def part_rows(self, db, k: int, name: str, clip: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """Rows ``starts[i] : starts[i] + lengths[i]`` of skeleton ``k``'s per-frame part ``name``
        (:data:`FRAME_PARTS`), each within clip ``clip[i]`` (a table row), concatenated: from
        memory where the part is held (:data:`HELD_PARTS_BYTES`), else read from the file."""
        return self._gathered(db, k, name, self._held_part(db, k, name), clip, starts, lengths)

    def _held_part(self, db, k: int, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """The read of part ``name`` of skeleton ``k`` counted; its held ``(at, rows)``
        (:meth:`_hold`), held from the :data:`HOLD_AFTER_READS`-th read on, or ``None``."""
        key = (k, name)
        self.reads[key] = self.reads.get(key, 0) + 1
        if key not in self.held and self.reads[key] >= HOLD_AFTER_READS:
            self.held[key] = self._hold(db, k, name)
        return self.held.get(key)

    def _gathered(self, db, k: int, name: str, held, clip, starts, lengths) -> np.ndarray:
        """:meth:`part_rows` of part ``name`` given its held ``(at, rows)`` (or ``None``: the file)."""
        if held is None:
            return db.frame_rows(k, name, starts, lengths)
        at, rows = held
        return rows[ranges_to_rows(at[clip] + starts - self.start[clip], lengths)]

    def timewarp_parts(self, db, k: int, clip, starts, lengths, first) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(curve, pelvis, at)`` of timewarp ranges (as :meth:`part_rows`'s arguments): the
        ``assembly_curve`` ``(M,)`` and ``assembly_pelvis`` ``(M, 4)`` rows that hold them, and the
        row where each range begins there. Where both parts are held, they are the held rows
        themselves, not copied (both hold the same clips, :meth:`_hold`, and a held curve has no
        NaN); else the ranges' rows one after another, a NaN in the curve refused as by
        :meth:`curve_rows`."""
        curve, pelvis = self._held_part(db, k, "assembly_curve"), self._held_part(db, k, "assembly_pelvis")
        if curve is not None and pelvis is not None:
            return curve[1], pelvis[1], curve[0][clip] + starts - self.start[clip]
        rows = self._gathered(db, k, "assembly_curve", curve, clip, starts, lengths)
        self._refuse_nan(db, rows, clip, lengths, first)
        return rows, self._gathered(db, k, "assembly_pelvis", pelvis, clip, starts, lengths), lengths_to_starts(lengths)

    def curve_rows(self, db, k: int, clip, starts, lengths, first) -> np.ndarray:
        """:meth:`part_rows` of ``assembly_curve``; a NaN (a damaged part, which the kernels would
        index with) is one :class:`DatabaseError` line naming the file, the clip and its frame."""
        curve = self.part_rows(db, k, "assembly_curve", clip, starts, lengths)
        self._refuse_nan(db, curve, clip, lengths, first)
        return curve

    @staticmethod
    def _refuse_nan(db, curve, clip, lengths, first) -> None:
        bad = np.flatnonzero(np.isnan(curve))
        if bad.size:
            raise DatabaseError(damaged_frame(db, int(bad[0]), clip, lengths, first, "has a NaN in its curve"))

    def _hold(self, db, k: int, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """``(at, rows)``: the rows of part ``name`` of every clip of skeleton ``k`` that has them
        (timewarp clips: the curve and the pelvis; clips whose arms were moved: the arms), read
        at once, and per table row where its clip's rows begin there; ``None`` where they would
        take more than :data:`HELD_PARTS_BYTES`, the file is being written, a chunk is damaged or
        the curve holds a NaN (each read then names its own rows)."""
        kind = self.parts["assembly_kind"]
        has = (kind == KIND_CODES["timewarp"]) if name != "assembly_arms" else (self.moved & (kind > 0))
        mine = np.flatnonzero(has & (self.skeleton == k))
        shape, dtype = FRAME_PARTS[name]
        row_bytes = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
        if db.mode != "r" or int(self.length[mine].sum()) * row_bytes > HELD_PARTS_BYTES:
            return None
        try:
            rows = db.frame_rows(k, name, self.start[mine], self.length[mine])
        except DatabaseError:
            return None
        if name == "assembly_curve" and np.isnan(rows).any():  # each read then refuses its own clips' NaN
            return None
        at = np.full(len(self.skeleton), -1, np.int64)
        at[mine] = lengths_to_starts(self.length[mine])
        return at, rows

    def skeleton_arrays(self, db, k: int) -> tuple[int, np.dtype, bool]:
        """``(J, dtype, has_translations)`` of skeleton ``k``'s frame arrays, looked up once."""
        if k not in self.arrays:
            g = db.h5[skeleton_path(k)]
            self.arrays[k] = (g["rotations"].shape[1], g["rotations"].dtype, "translations" in db.skeleton_datasets(k))
        return self.arrays[k]

    def locate(self, db, k: int, starts, lengths) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(starts, lengths, clip, first)``: frame ranges of skeleton ``k`` as int64 arrays, the
        clip (table row) holding each and the clip frame it starts at; a range that is not within
        one clip is one :class:`DatabaseError` line."""
        starts = np.asarray(starts, np.int64).reshape(-1)
        lengths = np.asarray(lengths, np.int64).reshape(-1)
        first_frames, rows = self.clips_of(k)
        at = np.searchsorted(first_frames, starts, side="right") - 1
        clip = rows[np.maximum(at, 0)]
        first = starts - self.start[clip]
        bad = (at < 0) | (first + lengths > self.length[clip])
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DatabaseError(
                f"{db.path}: frames {int(starts[i])}:{int(starts[i] + lengths[i])} of skeleton {k} are not "
                "within one clip of this alignment store"
            )
        return starts, lengths, clip, first

    def frames(
        self, db, k: int, starts: np.ndarray, lengths: np.ndarray, translations: bool = True, threads: int = 1
    ) -> dict[str, np.ndarray]:
        """Rows ``starts[i] : starts[i] + lengths[i]`` of skeleton ``k``'s frame arrays (each range
        within one clip), concatenated: ``rotations``, ``root_translation`` and ``translations``
        (where the skeleton stores them, unless ``translations`` is false: a reader that wants
        the root's only saves the other joints' work), as the store's dtype. ``threads``: the
        threads of this process the kernels share the clips over (:mod:`torchsplice.core.threads`;
        the same bits for any count), used from :data:`SPLIT_FRAMES` frames a thread."""
        from ..cpu.assemble import arc_table, assemble_standing, assemble_timewarp  # here: loads numba

        starts, lengths, clip, first = self.locate(db, k, starts, lengths)
        J, dtype, has_translations = self.skeleton_arrays(db, k)
        has_translations = has_translations and translations
        N = int(lengths.sum())
        out_start = lengths_to_starts(lengths)
        orot = np.empty((N, J, 4), dtype)
        otrans = np.empty((N, J if has_translations else 1, 3), dtype)  # the root's only, where that is all stored
        p = {n: v[clip] for n, v in self.parts.items()}
        kind = p["assembly_kind"]
        stored = kind <= 0
        if stored.any():  # frames kept as they are
            s, n, o = starts[stored], lengths[stored], out_start[stored]
            at_rows = ranges_to_rows(o, n)
            orot[at_rows] = db.frame_rows(k, "rotations", s, n)
            otrans[at_rows, 0] = db.frame_rows(k, "root_translation", s, n)
            if has_translations:
                otrans[at_rows, 1:] = db.frame_rows(k, "translations", s, n)[:, 1:]
        timewarp = kind == 1
        curve = prot = None
        part_at = np.zeros(len(kind), np.int64)  # where each timewarp clip's rows begin in curve and prot
        if timewarp.any():
            curve, prot, part_at[timewarp] = self.timewarp_parts(
                db, k, clip[timewarp], starts[timewarp], lengths[timewarp], first[timewarp]
            )
        built = np.flatnonzero(kind > 0)
        for b in sorted(set(p["assembly_bank"][built].tolist())):  # the slerps' angles between neighbouring frames,
            bank = self.banks[b]  # once per bank (before any thread reads it)
            if "arc" not in bank and (timewarp & (p["assembly_bank"] == b)).any():
                bank["arc"] = arc_table(bank["rot"], bank["tables"]["upper"])

        def assemble(chunk: np.ndarray) -> None:  # clips built[chunk] into their own rows of orot/otrans
            mine = np.zeros(len(kind), bool)
            mine[built[chunk]] = True
            for b in sorted(set(p["assembly_bank"][built[chunk]].tolist())):
                bank = self.banks[b]
                t = bank["tables"]
                args = (bank["rot"], bank["trans"], bank["starts"], bank["lengths"])
                m = mine & timewarp & (p["assembly_bank"] == b)
                if m.any():
                    assemble_timewarp(
                        args[0],
                        args[1],
                        bank["arc"],
                        *args[2:],
                        p["assembly_locomotion"][m],
                        p["assembly_action"][m],
                        p["assembly_crop"][m],
                        t["upper"],
                        t["pelvis"],
                        curve,
                        prot,
                        part_at[m],
                        first[m],
                        lengths[m],
                        out_start[m],
                        orot,
                        otrans,
                    )
                m = mine & (kind == 2) & (p["assembly_bank"] == b)
                if m.any():
                    acting = np.stack([(p["assembly_acting"][m] & 1) > 0, (p["assembly_acting"][m] & 2) > 0], axis=1)
                    loops = np.stack([p["assembly_loop_start"][m], p["assembly_loop_end"][m]], axis=1)
                    assemble_standing(
                        *args,
                        p["assembly_locomotion"][m],
                        p["assembly_action"][m],
                        p["assembly_method"][m],
                        p["assembly_timing"][m],
                        p["assembly_window"][m],
                        loops,
                        acting,
                        t["standing_upper"],
                        t["spine"],
                        t["arms"],
                        t["blend"],
                        first[m],
                        lengths[m],
                        out_start[m],
                        orot,
                        otrans,
                        np.empty(N),
                    )

        weight = lengths[built]
        parts = threads if int(weight.sum()) >= threads * SPLIT_FRAMES else 1
        run_in_threads(assemble, split_by_weight(weight, parts), parts)
        moved = self.moved_arms(db, k, starts, lengths, clip, out_start)
        if moved is not None:
            rows, joints, arms = moved
            orot[rows, joints] = arms
        refuse_non_finite(db, {"rotations": orot, "translations": otrans}, clip, lengths, first)  # a damaged part
        out = {"rotations": orot, "root_translation": np.ascontiguousarray(otrans[:, 0])}
        if has_translations:
            out["translations"] = otrans
        return out

    def moved_arms(self, db, k: int, starts, lengths, clip, out_start) -> tuple | None:
        """``(rows, joints, rotations)``: the joints moved out of the body, one entry each, in the
        assembled frames (rows of the ranges concatenated, ``(P,)``), ``joints`` ``(P,)`` and
        their local rotations ``(P, 4)`` (float32) that replace the assembled ones (a row of
        ``assembly_arms`` holds zeros for a joint not moved); ``None`` where no clip of the ranges
        has any."""
        if self.moved is None or "assembly_arms" not in db.skeleton_datasets(k):
            return None
        which = np.flatnonzero(self.moved[clip] & (self.parts["assembly_kind"][clip] > 0))
        if not len(which):
            return None
        n = lengths[which]
        arms = self.part_rows(db, k, "assembly_arms", clip[which], starts[which], n)
        rows = ranges_to_rows(out_start[which], n)
        joints = self.moved_joints[np.repeat(self.parts["assembly_bank"][clip[which]], n)]  # (M, 4)
        keep = (arms != 0).any(axis=2) & (joints >= 0)  # (M, 4): the joints moved
        frame, slot = np.nonzero(keep)
        return rows[frame], joints[frame, slot], arms[frame, slot]

    def frames_on(self, db, k: int, starts: np.ndarray, lengths: np.ndarray, device) -> dict:
        """:meth:`frames` assembled by torch on ``device`` (:mod:`.assembly_torch`): float32
        tensors there, equal to the compiled kernels' to float32's rounding."""
        starts, lengths, clip, first = self.locate(db, k, starts, lengths)
        J, _, has_translations = self.skeleton_arrays(db, k)
        N = int(lengths.sum())
        p = {n: v[clip] for n, v in self.parts.items()}
        kind = np.repeat(p["assembly_kind"], lengths)
        owner = np.repeat(np.arange(len(starts)), lengths)  # the range of each result frame
        t = ranges_to_rows(first, lengths)
        orot = torch.empty((N, J, 4), dtype=torch.float32, device=device)
        otrans = torch.empty((N, J, 3), dtype=torch.float32, device=device)
        stored = kind <= 0
        if stored.any():
            s, n = starts[p["assembly_kind"] <= 0], lengths[p["assembly_kind"] <= 0]
            at_rows = as_tensor(np.flatnonzero(stored), device)
            orot[at_rows] = as_tensor(db.frame_rows(k, "rotations", s, n), device, torch.float32)
            otrans[at_rows, 0] = as_tensor(db.frame_rows(k, "root_translation", s, n), device, torch.float32)
            if has_translations:
                otrans[at_rows, 1:] = as_tensor(db.frame_rows(k, "translations", s, n)[:, 1:], device, torch.float32)
        cache = self.__dict__.setdefault("_device_banks", {})
        for b in sorted(set(p["assembly_bank"][p["assembly_kind"] > 0].tolist())):
            key = (b, str(device))
            if key not in cache:
                bank = self.banks[b]
                cache[key] = (
                    as_tensor(bank["rot"], device),
                    as_tensor(bank["trans"], device),
                    {n: (as_tensor(v, device) if isinstance(v, np.ndarray) else v) for n, v in bank["tables"].items()},
                )
            rot, trans, tb = cache[key]
            bank = self.banks[b]
            mine = np.repeat(p["assembly_bank"] == b, lengths)
            sel = np.flatnonzero(mine & (kind == 1))
            if len(sel):
                tw = np.flatnonzero((p["assembly_kind"] == 1) & (p["assembly_bank"] == b))
                curve = self.curve_rows(db, k, clip[tw], starts[tw], lengths[tw], first[tw])
                prot = self.part_rows(db, k, "assembly_pelvis", clip[tw], starts[tw], lengths[tw])
                o = owner[sel]
                act, crop = p["assembly_action"][o], p["assembly_crop"][o]
                n_act = bank["lengths"][act] - crop
                x = np.minimum(np.maximum(curve, 0.0), n_act - 1.0)
                i0 = np.floor(x)
                i1 = np.minimum(i0 + 1, n_act - 1)
                base = bank["starts"][act] + crop
                r, tr = timewarp_frames(
                    rot,
                    trans,
                    as_tensor(bank["starts"][p["assembly_locomotion"][o]] + t[sel], device),
                    as_tensor(base + i0.astype(np.int64), device),
                    as_tensor(base + i1.astype(np.int64), device),
                    as_tensor(x - i0, device),
                    as_tensor(prot, device),
                    tb["upper"],
                    tb["pelvis"],
                )
                orot[as_tensor(sel, device)], otrans[as_tensor(sel, device)] = r, tr
            sel = np.flatnonzero(mine & (kind == 2))
            if len(sel):
                cl = np.flatnonzero((p["assembly_kind"] == 2) & (p["assembly_bank"] == b))
                index = np.full(len(starts), -1, np.int64)
                index[cl] = np.arange(len(cl))
                lo, ac = p["assembly_locomotion"][cl], p["assembly_action"][cl]
                per = lambda a: as_tensor(a, device)  # noqa: E731
                acting = np.stack([(p["assembly_acting"][cl] & 1) > 0, (p["assembly_acting"][cl] & 2) > 0], axis=1)
                r, tr = standing_frames(
                    rot,
                    trans,
                    per(index[owner[sel]]),
                    per(t[sel]),
                    per(bank["starts"][lo]),
                    per(bank["lengths"][lo]),
                    per(bank["starts"][ac]),
                    per(bank["lengths"][ac]),
                    per(p["assembly_method"][cl]),
                    per(p["assembly_timing"][cl]),
                    per(p["assembly_window"][cl]),
                    per(p["assembly_loop_start"][cl]),
                    per(p["assembly_loop_end"][cl]),
                    per(acting),
                    tb["standing_upper"],
                    tb["spine"],
                    tb["arms"],
                    int(tb["blend"]),
                )
                orot[as_tensor(sel, device)], otrans[as_tensor(sel, device)] = r, tr
        moved = self.moved_arms(db, k, starts, lengths, clip, lengths_to_starts(lengths))
        if moved is not None:
            rows, joints, arms = moved
            orot[as_tensor(rows, device), as_tensor(joints, device)] = as_tensor(arms, device, torch.float32)
        out = {"rotations": orot, "root_translation": otrans[:, 0].contiguous()}
        if has_translations:
            out["translations"] = otrans
        return out
