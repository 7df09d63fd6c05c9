"""The alignment store's methods of :class:`~torchsplice.store.database.MotionDatabase`
(:class:`Assembling`, a mixin): its kind, assembled frames, and writing banks of source clips
and spliced clips as their parts. The layout is :mod:`torchsplice.store.assembly`'s."""

from __future__ import annotations

import json

import h5py
import numpy as np
import torch

from ..core.errors import DatabaseError
from ..core.ranges import lengths_to_starts, ranges_to_rows
from .assembly import ALIGNMENT, BANKS, Assembly, store_kind
from .reading import FrameArray
from .schema import CLIPS, FRAME_ARRAYS, STR, skeleton_path
from .state import DatabaseState
from .writing import io_failure

__all__ = ["Assembling", "AssembledArray"]


class AssembledArray(FrameArray):
    """A frame array of an alignment store (``rotations``, ``root_translation`` or
    ``translations``): :class:`FrameArray`'s interface, the rows assembled from the parts when
    read (see :mod:`torchsplice.store.assembly`). The last ranges' frames are kept, so reading
    the three arrays of the same rows assembles them once."""

    def __init__(self, db, skeleton: int, name: str):
        super().__init__(db.h5[skeleton_path(skeleton)][name])
        self._db, self._k, self._name = db, skeleton, name

    def __getitem__(self, rows: slice) -> np.ndarray:
        lo, hi, _ = rows.indices(len(self))
        return self.gather(np.array([lo]), np.array([max(hi - lo, 0)]))

    def gather(self, starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        key = (self._k, np.asarray(starts).tobytes(), np.asarray(lengths).tobytes())
        last = getattr(self._db, "_last_assembled", None)
        if last is None or last[0] != key:
            # the motion arrays only: a per-frame column is read as it is stored, and only when asked
            last = self._db._last_assembled = (key, self._db._assembly().frames(self._db, self._k, starts, lengths))
        return last[1][self._name]


class Assembling(DatabaseState):
    """The alignment store's methods of :class:`~torchsplice.store.database.MotionDatabase` (a
    mixin: the database's state, file and opening live there)."""

    @property
    def store(self) -> str:
        """``"alignment"`` or ``"motion"`` (see :mod:`torchsplice.store.assembly`), read once per open."""
        kind = getattr(self, "_store_kind", None)
        if kind is None:
            kind = self._store_kind = store_kind(self.h5.attrs)
        return kind

    def _assembly(self) -> Assembly:
        have = getattr(self, "_assembly_cache", None)
        if have is None or (self.mode != "r" and len(have.skeleton) != self.h5[f"{CLIPS}/name"].shape[0]):
            self.flush()
            self._table_written()
            have = self._assembly_cache = Assembly(self)
        return have

    def frame_rows(self, k: int, name: str, starts, lengths) -> np.ndarray:
        """Stored rows ``starts[i] : starts[i] + lengths[i]`` of skeleton ``k``'s dataset ``name``,
        concatenated (a damaged chunk: one line naming the file)."""
        arrays = self.__dict__.setdefault("_frame_row_arrays", {})  # h5py's lookups cost more than small reads
        if (k, name) not in arrays or self.mode != "r":  # a file being written may still replace its arrays
            arrays[(k, name)] = FrameArray(self.h5[skeleton_path(k)][name])
        return arrays[(k, name)].gather(np.asarray(starts, np.int64), np.asarray(lengths, np.int64))

    def skeleton_datasets(self, k: int) -> frozenset[str]:
        """The names of skeleton ``k``'s datasets (frame arrays, per-frame columns and parts),
        looked up once per open file read only: h5py's lookups cost more than a batch's other work."""
        have = self.__dict__.setdefault("_skeleton_datasets", {})
        if k not in have or self.mode != "r":  # a file being written may still add arrays
            have[k] = frozenset(self.h5[skeleton_path(k)])
        return have[k]

    def assembled(self, k: int, starts, lengths, names=None, threads: int = 1) -> dict[str, np.ndarray]:
        """Frames of skeleton ``k`` (rows ``starts[i] : starts[i] + lengths[i]``, each within one
        clip) as a motion store holds them: ``rotations``, ``root_translation``, ``translations``
        (where stored) and the per-frame columns; in an alignment store assembled from the parts.
        ``names``: the frame arrays and per-frame columns wanted (default: all); ``threads``: the
        threads of this process an alignment store's assembly may use (the same bits for any count)."""
        starts, lengths = np.asarray(starts, np.int64).reshape(-1), np.asarray(lengths, np.int64).reshape(-1)
        arrays = [n for n in FRAME_ARRAYS if n in self.skeleton_datasets(k) and (names is None or n in names)]
        if self.store == ALIGNMENT:
            made = (
                self._assembly().frames(self, k, starts, lengths, "translations" in arrays, threads) if arrays else {}
            )
            out = {n: made[n] for n in arrays}
        else:
            out = {n: self.frame_rows(k, n, starts, lengths) for n in arrays}
        for n in self.frame_columns:
            if names is None or n in names:
                out[n] = self.frame_rows(k, n, starts, lengths)
        return out

    def assembled_on(self, k: int, starts, lengths, device, names=None) -> dict:
        """:meth:`assembled` as float32 tensors on ``device``: an alignment store's clips
        assembled there by torch (:mod:`torchsplice.store.assembly_torch`; equal to the compiled
        kernels' frames to float32's rounding), a motion store's frames read and moved there.
        ``names``: the frame arrays and per-frame columns wanted (default: all)."""
        starts, lengths = np.asarray(starts, np.int64).reshape(-1), np.asarray(lengths, np.int64).reshape(-1)
        g = self.h5[skeleton_path(k)]
        arrays = [n for n in FRAME_ARRAYS if n in g and (names is None or n in names)]
        if self.store == ALIGNMENT:
            out = self._assembly().frames_on(self, k, starts, lengths, device) if arrays else {}
        else:
            out = {
                n: torch.as_tensor(self.frame_rows(k, n, starts, lengths), device=device, dtype=torch.float32)
                for n in arrays
            }
        out = {n: out[n] for n in arrays}
        for n in self.frame_columns:
            if names is None or n in names:
                out[n] = torch.as_tensor(self.frame_rows(k, n, starts, lengths), device=device)
        return out

    def assembled_array(self, k: int, name: str) -> "AssembledArray":
        """The frame array ``name`` of skeleton ``k`` of an alignment store (see :class:`AssembledArray`)."""
        return AssembledArray(self, k, name)

    def whole_frames(self, k: int) -> dict[str, np.ndarray]:
        """Every row of skeleton ``k``'s frame arrays and per-frame columns, as a motion store
        holds them (:meth:`~torchsplice.store.reading.Reading.packed` of an alignment store)."""
        g = self.h5[skeleton_path(k)]
        N = g["rotations"].shape[0]
        starts, rows = self._assembly().clips_of(k)
        lengths = self._assembly().length[rows]
        made = self.assembled(k, starts, lengths)
        at = ranges_to_rows(starts, lengths)
        out = {}
        for name, a in made.items():
            whole = np.zeros((N,) + a.shape[1:], a.dtype)
            whole[at] = a
            out[name] = whole
        return out

    def add_bank(self, rotations: np.ndarray, translations: np.ndarray, lengths, names, keys, fps, tables: dict) -> int:
        """Store a bank of source clips (packed ``(N, J, 4)`` float64 rotations and ``(N, J, 3)``
        local translations, ``C`` lengths, names, keys and rates) with its joint tables (see
        :func:`_tables`: joint indices); returns its number. Values float32 holds exactly are
        stored as float32. Each chunk carries a Fletcher-32 checksum, so a flipped byte that
        still decompresses to finite values fails the read (h5py's ``OSError``, turned into one
        line naming the file and the bank by :func:`~.checks.unreadable_bank`); files written
        without it read as before."""
        self._writable()
        if self.store != ALIGNMENT:
            raise DatabaseError(f"{self.path}: is a motion store; source banks belong in an alignment store")
        rot, trans = np.asarray(rotations), np.asarray(translations)
        lengths = np.asarray(lengths, np.int64).reshape(-1)
        exact = all(np.array_equal(a.astype(np.float32), a) for a in (rot, trans))
        dt = np.float32 if exact else np.float64
        self._reserve(rot.size * np.dtype(dt).itemsize * 7 // 4 + 200 * len(lengths))
        banks = self.h5.require_group(BANKS)
        b = len(banks)
        g = banks.create_group(str(b))
        for name, a in (("rotations", rot), ("translations", trans)):
            g.create_dataset(
                name,
                data=a.astype(dt),
                chunks=(min(max(len(a), 1), 1024),) + a.shape[1:],
                compression="lzf",
                shuffle=True,
                fletcher32=True,  # a damaged byte that still decompresses is an error on read, not a motion
            )
        g["starts"] = lengths_to_starts(lengths)
        g["lengths"] = lengths
        g["names"] = np.array([str(n) for n in names], dtype=object).astype(STR)
        g["keys"] = np.array([str(n) for n in keys], dtype=object).astype(STR)
        g["fps"] = np.asarray(fps, np.float64).reshape(-1) * np.ones(len(lengths))
        g.attrs["tables"] = json.dumps(tables)
        return b

    def bank_index(self) -> dict[tuple[int, str, float], int]:
        """``(bank, key, fps) -> row`` of every source clip the banks hold (the job's keys)."""
        out = {}
        for b in range(len(self.h5[BANKS]) if BANKS in self.h5 else 0):
            g = self.h5[f"{BANKS}/{b}"]
            for r, (key, fps) in enumerate(zip(g["keys"].asstr()[()], g["fps"][()])):
                out[(b, str(key), float(fps))] = r
        return out

    def append_parts(
        self,
        skeleton,
        lengths,
        names,
        fps,
        *,
        curve,
        pelvis,
        parts: dict,
        arms=None,
        spec=None,
        sources="",
        roles="",
        labels=None,
        extra: dict | None = None,
        frame_extra: dict | None = None,
        virtual: tuple | None = None,
    ) -> None:
        """Add spliced clips of one skeleton as their parts: per frame ``curve (N,)`` and
        ``pelvis (N, 4)`` (``None`` for standing clips: their frames follow from their timing),
        ``arms (N, 4, 4)`` (the arms moved out of the body, zeros where not; ``None``: none),
        per clip the :data:`PART_COLUMNS` in ``parts`` (``C`` values each); other arguments as
        :meth:`append_packed`'s. ``virtual=(source, refer_as)``: the per-frame parts are in the
        file ``source`` (:meth:`append_frame_source`), read through virtual datasets as
        :meth:`append_virtual` reads frames; only the table rows are written here."""
        self._writable()
        if self.store != ALIGNMENT:
            raise DatabaseError(f"{self.path}: is a motion store; it cannot take clips as parts (write their motions)")
        self.flush()
        lengths = np.asarray(lengths, np.int64).reshape(-1)
        names = [str(n) for n in names]
        C, N = len(names), int(lengths.sum())
        if C == 0:
            return
        if virtual is not None:  # table rows only, as append_virtual writes them
            k = self.add_skeleton(skeleton, spec)
            self._append_rows(
                k, self._virtual_rows(k), lengths, names, fps, sources, roles, labels, {**(extra or {}), **parts}
            )
            self._virtual[k].append((self._virtual_source(*virtual), N))
            return
        index = self._new_names(names)
        frame_extra = dict(frame_extra or {})
        arrays: dict[str, np.ndarray] = {}
        if curve is not None:
            arrays["assembly_curve"] = np.asarray(curve, np.float64).reshape(N)
        if pelvis is not None:
            arrays["assembly_pelvis"] = np.asarray(pelvis, np.float32).reshape(N, 4)
        if arms is not None:
            arrays["assembly_arms"] = np.asarray(arms, np.float32).reshape(N, 4, 4)
        for name in self.frame_columns:
            v = frame_extra.get(name)
            arrays[name] = np.full(N, np.nan, np.float32) if v is None else np.asarray(v, np.float32).reshape(N)
        rows = self._rows(names, lengths, fps, sources, roles, labels, {**(extra or {}), **parts})
        k = self.add_skeleton(skeleton, spec)
        self._no_virtual(k)
        grown = self._growing_datasets(k)
        self._reserve(sum(a.nbytes for a in arrays.values()) + 300 * C)
        n0 = grown["rotations"].shape[0]
        rows["skeleton"], rows["start"] = [k] * C, n0 + lengths_to_starts(lengths)
        try:
            for ds in grown.values():
                ds.resize(n0 + N, axis=0)
            for name, a in arrays.items():
                ds = grown[name]
                if name in SPARSE_PARTS:
                    _write_nonzero_chunks(ds, n0, a)
                else:
                    ds[n0:] = a
            self._store_rows(rows)
        except BaseException as exc:
            if io_failure(exc):
                raise
            try:
                for ds in grown.values():
                    ds.resize(n0, axis=0)
            except Exception:
                pass
            raise
        self._added(index, names)


SPARSE_PARTS = ("assembly_arms",)
"""Per-frame parts that are zeros on most frames: only their chunks that hold a non-zero row are written."""


def _write_nonzero_chunks(ds: h5py.Dataset, n0: int, a: np.ndarray) -> None:
    """Rows ``n0 ..`` of ``ds`` from ``a``, written only in the chunks that hold a non-zero row of
    ``a``: HDF5 stores no chunk that was never written and reads its rows as the fill value,
    zeros, so a part that is zeros on most frames costs the frames that are not."""
    chunk = int(ds.chunks[0])
    nonzero = np.flatnonzero(a.reshape(len(a), -1).any(axis=1))
    if not len(nonzero):
        return
    chunks = np.unique((n0 + nonzero) // chunk)
    gaps = np.flatnonzero(np.diff(chunks) > 1)
    for first, last in zip(np.r_[chunks[0], chunks[gaps + 1]], np.r_[chunks[gaps], chunks[-1]]):
        lo, hi = max(int(first) * chunk - n0, 0), min((int(last) + 1) * chunk - n0, len(a))
        ds[n0 + lo : n0 + hi] = a[lo:hi]
