"""Writing clips into a motion database: the write half of
:class:`~torchsplice.store.database.MotionDatabase` (:class:`Writing`).

Clips are appended one at a time (buffered, written by :meth:`Writing.flush`), packed many at
a time (:meth:`Writing.append_packed`) or by reference to other files' frames
(:meth:`Writing.append_virtual`). Every write method either completes or leaves the file as it
was; HDF5 failing to write (a full disk, an I/O error) discards the whole write in progress
and is one :class:`~torchsplice.core.errors.DatabaseError` line (:func:`guarded`). The room on
the disk is checked before each write (:data:`SPACE_MARGIN`).
"""

from __future__ import annotations

import errno
import json
import os
import shutil
from pathlib import Path

import h5py
import numpy as np
import torch

from ..core.errors import DatabaseError
from ..core.ranges import lengths_to_starts
from ..core.motion import Motion
from ..core.skeleton import Skeleton
from .atomic import os_error_message
from .checks import control_name
from .guards import (
    column_array,
    dataset_compression,
    frame_values,
    grow_rows,
    growing_datasets,
    guarded,
    io_failure,
    mb,
    no_space,
    per_clip,
)
from .assembly import ALIGNMENT, FRAME_PARTS
from .schema import FRAME_ARRAYS, CLIPS, COLUMNS, KINDS, MIXED, SKELETONS, first_non_finite_row, short
from .schema import skeleton_path, skeleton_to_group
from .state import DatabaseState

__all__ = ["Writing", "guarded", "io_failure", "SPACE_MARGIN", "FLUSH_FRAMES"]

FLUSH_FRAMES = 1 << 16
"""Buffered frames that make :meth:`Writing.append` write its buffer."""
SPACE_MARGIN = 4 << 20
"""Bytes kept free beyond each write, for HDF5's caches and metadata."""


class Writing(DatabaseState):
    """The write methods of :class:`~torchsplice.store.database.MotionDatabase` (a mixin: the
    database's state, file and opening live there)."""

    def _reserve(self, nbytes: int) -> None:
        """Refuse to write ``nbytes`` (uncompressed) where the disk has no room for them.

        HDF5 reports a full disk only while it frees its objects, where the error cannot be
        caught and the process later crashes; so the room is checked before every write, with
        a margin for the data HDF5 still holds in its caches (``SPACE_MARGIN``).
        """
        if self._tmp is None:
            return
        try:
            free = shutil.disk_usage(self._tmp.parent).free
        except OSError:
            return
        if free < nbytes + SPACE_MARGIN:
            # nothing failed yet: a resumable database stays open, so that its writer can
            # checkpoint what it holds (within the margin) before it stops
            raise DatabaseError(
                self._write_failed(
                    OSError(errno.ENOSPC, "No space left on device"), nbytes, discard=not self._resumable
                )
            )

    def _write_failed(self, exc: BaseException, pending: int = 0, discard: bool = True) -> str:
        """Discard the write after ``exc`` (unless not ``discard``) and return the line that says so."""
        try:
            written = self._tmp.stat().st_size if self._tmp is not None else 0
        except OSError:
            written = 0
        pending = pending or self._staged_bytes()
        kept = "what was written is kept" if self._resumable else "nothing was written"
        if discard:
            self.abort(failed=True)
        if not no_space(exc):
            return (
                os_error_message(self.path, exc)
                if isinstance(exc, OSError)
                else f"{self.path}: cannot write the file ({short(exc)})"
            )
        folder = self.path.parent.resolve()
        free = shutil.disk_usage(folder).free
        return (
            f"{self.path}: no space left on the device; the database needs more than {mb(written + pending)} "
            f"and {folder} has {mb(free)} free ({kept}; free some space and run the command again)"
        )

    def _staged_bytes(self) -> int:
        """Uncompressed bytes of the clips waiting in the buffer (an upper bound of their size)."""
        size = self._dtype.itemsize
        return sum(
            m.num_frames * (7 * m.skeleton.num_joints + 3 + len(self.frame_columns)) * size for m, *_ in self._staged
        )

    # -- writing ------------------------------------------------------------------------------
    def update_run_record(self, fields: dict) -> None:
        """Update the run record (the root attribute ``run``, JSON written by ``splice-all``)
        with ``fields``; a file without one is left as it is."""
        self._writable()
        run = json.loads(str(self.h5.attrs.get("run", "")) or "{}")
        if run:
            run.update(fields)
            self.h5.attrs["run"] = json.dumps(run)

    def _writable(self) -> None:
        if self.mode == "r":
            raise DatabaseError(f"{self.path}: opened read-only")

    @guarded
    def add_skeleton(self, skeleton: Skeleton, spec=None) -> int:
        """Index of a stored skeleton that matches ``skeleton``, storing it if none does.

        ``spec`` (a :class:`~torchsplice.specs.DatasetSpec` or ``None``) is stored with a new
        skeleton, with its units and up axis (each skeleton keeps its own: datasets of different
        units share one file; the file's ``units`` and ``up_axis`` attributes then say ``"mixed"``).
        """
        known = self._skeleton_ids.get(id(skeleton))
        if known is not None and known[0] is skeleton:
            return known[1]  # matched once per skeleton object, not per appended clip
        for k, sk in enumerate(self._skeletons):
            if sk.matches(skeleton):
                self._skeleton_ids[id(skeleton)] = (skeleton, k)
                return k
        self._writable()
        units = getattr(spec, "units", "") or ""
        up = getattr(spec, "up_axis", "") or ""
        for key, value in (
            ("units", units),
            ("up_axis", up),
        ):  # each skeleton keeps its own; the file's is their common one
            have = str(self.h5.attrs.get(key, ""))
            if value and have and have != value:
                self.h5.attrs[key] = MIXED
            if value and not have:
                self.h5.attrs[key] = value
        k = len(self._skeletons)
        g = self.h5[SKELETONS].create_group(str(k))
        skeleton_to_group(g, skeleton)
        g.attrs.update({"spec": spec.to_json() if spec is not None else "", "units": units, "up_axis": up})
        chunk = int(self.h5.attrs["chunk_frames"])
        policy = str(self.h5.attrs["compression"]) or None
        J = skeleton.num_joints
        shapes = {"rotations": (J, 4), "root_translation": (3,)}
        if skeleton.has_joint_translations:
            shapes["translations"] = (J, 3)
        for name, shape in shapes.items():
            comp = dataset_compression(policy, name)
            g.create_dataset(
                name,
                shape=(0,) + shape,
                maxshape=(None,) + shape,
                dtype=self._dtype,
                chunks=(chunk,) + shape,
                compression=comp,
                shuffle=comp is not None,
            )
        for name in self.frame_columns:
            comp = dataset_compression(policy, name)
            g.create_dataset(
                name,
                shape=(0,),
                maxshape=(None,),
                dtype=np.float32,
                chunks=(chunk,),
                compression=comp,
                shuffle=comp is not None,
            )
        if self.store == ALIGNMENT:  # the per-frame parts of spliced clips (see torchsplice.store.assembly)
            for name, (shape, dt) in FRAME_PARTS.items():
                g.create_dataset(
                    name,
                    shape=(0,) + shape,
                    maxshape=(None,) + shape,
                    dtype=dt,
                    chunks=(chunk,) + shape,
                    compression="lzf",
                    shuffle=True,
                )
        self._skeletons.append(skeleton)
        self._skeleton_ids[id(skeleton)] = (skeleton, k)
        return k

    def append(self, motion: Motion, spec=None, extra: dict | None = None, frame_extra: dict | None = None) -> int:
        """Add a clip (buffered; written by :meth:`flush` or on close). Returns its row number.

        The clip name must be new to the database; non-finite values are refused. ``extra``
        gives values of the declared extra columns (missing ones: ``""``, NaN or -1) and
        ``frame_extra`` per-frame arrays ``(T,)`` of the declared frame columns (missing: NaN).
        """
        extra, frame_extra = dict(extra or {}), dict(frame_extra or {})
        unknown = [k for k in extra if k not in self._declared] + [
            k for k in frame_extra if k not in self.frame_columns
        ]
        if unknown:
            raise DatabaseError(f"{self.path}: no extra column {unknown[0]!r} was declared")
        self._writable()
        motion.check_finite()
        if not motion.name:
            raise DatabaseError(f"{self.path}: a clip needs a name")
        if (bad := control_name([motion.name])) is not None:
            raise DatabaseError(f"{self.path}: {bad}")
        index = self._index_map()
        if motion.name in index:
            raise DatabaseError(f"{self.path}: a clip named {motion.name!r} is already in the database")
        k = self.add_skeleton(motion.skeleton, spec)
        index[motion.name] = len(self)
        self._staged.append((motion, k, extra, frame_extra))
        self._staged_frames += motion.num_frames
        if self._staged_frames >= FLUSH_FRAMES:
            self.flush()
        return len(self) - 1

    @guarded
    def append_packed(
        self,
        skeleton: Skeleton,
        rotations,
        root_translation,
        translations,
        lengths,
        names,
        fps,
        spec=None,
        sources="",
        roles="",
        labels=None,
        extra: dict | None = None,
        frame_extra: dict | None = None,
        check: bool = True,
    ) -> None:
        """Add many clips of one skeleton at once, from arrays packed along frames.

        Args:
            skeleton: the clips' :class:`Skeleton` (matched against the stored ones once).
            rotations: ``(N, J, 4)`` local rotations (WXYZ) of every frame of every clip, clip
                after clip; root_translation: ``(N, 3)``; translations: ``(N, J, 3)`` local
                translations (row 0 is ignored) or ``None`` (the skeleton's offsets).
            lengths: ``(C,)`` frames per clip, summing to ``N``; names: ``C`` new clip names.
            fps: one rate for all clips or ``(C,)``; sources, roles: one string or ``C``;
                labels: ``C`` dicts or JSON strings (``None``: no labels).
            extra: declared per-clip columns, ``C`` values each; frame_extra: declared
                per-frame columns, ``(N,)`` values each (missing ones: ``""``, NaN or -1).

        Numpy arrays or tensors. The clips are written at once, after any clips appended
        before, so row order is call order. Non-finite values are refused (``check=False``
        skips that scan, for arrays read back from a database that was checked when written).
        """
        self._writable()
        self.flush()
        arr = lambda x: x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)  # noqa: E731
        rot, root = arr(rotations), arr(root_translation)
        lengths = arr(lengths).astype(np.int64).reshape(-1)
        names = [str(n) for n in names]
        C, N, J = len(names), int(lengths.sum()), skeleton.num_joints
        if lengths.shape != (C,) or rot.shape != (N, J, 4) or root.shape != (N, 3) or (lengths < 1).any():
            raise DatabaseError(
                f"{self.path}: packed clips do not fit: {C} names, lengths summing to {N}, "
                f"rotations {rot.shape}, root translation {root.shape} for {J} joints"
            )
        trans = None if translations is None else arr(translations)
        if trans is not None and trans.shape != (N, J, 3):
            raise DatabaseError(f"{self.path}: translations must be {(N, J, 3)}, got {trans.shape}")
        index = self._new_names(names)
        starts = lengths_to_starts(lengths)
        for name, a in (("rotations", rot), ("root translation", root), ("translations", trans)) if check else ():
            if a is not None and (row := first_non_finite_row(a)) is not None:
                c = int(np.searchsorted(starts, row, side="right") - 1)
                raise DatabaseError(f"{self.path}: clip {names[c]!r} has non-finite {name} at frame {row - starts[c]}")
        extra, frame_extra = dict(extra or {}), dict(frame_extra or {})
        unknown = [k for k in extra if k not in self._declared] + [
            k for k in frame_extra if k not in self.frame_columns
        ]
        if unknown:
            raise DatabaseError(f"{self.path}: no extra column {unknown[0]!r} was declared")
        if C == 0:
            return
        frames = {}
        for name in self.frame_columns:
            v = frame_extra.get(name)
            frames[name] = np.full(N, np.nan, np.float32) if v is None else arr(v).astype(np.float32).reshape(-1)
            if frames[name].shape != (N,):
                raise DatabaseError(f"{self.path}: column {name!r} needs {N} values, got {frames[name].shape}")

        rows = self._rows(names, lengths, fps, sources, roles, labels, extra)
        k = self.add_skeleton(skeleton, spec)
        self._no_virtual(k)
        grown = self._growing_datasets(k)
        arrays = {"rotations": rot, "root_translation": root, **frames}
        if "translations" in grown:
            if trans is not None and np.array_equal(trans[:, 0], root):
                arrays["translations"] = trans  # row 0 already holds the root
            else:
                t = trans.copy() if trans is not None else np.broadcast_to(skeleton.offsets.numpy(), (N, J, 3)).copy()
                t[:, 0] = root
                arrays["translations"] = t
        self._reserve(sum(a.nbytes for a in arrays.values()) + 200 * C)
        n0 = grown["rotations"].shape[0]
        rows["skeleton"], rows["start"] = [k] * C, n0 + starts
        try:
            for name, a in arrays.items():
                ds = grown[name]
                ds.resize(n0 + N, axis=0)
                ds[n0:] = a.astype(ds.dtype, copy=False)
            grow_rows(grown.values(), n0 + N)
            self._store_rows(rows)
        except BaseException as exc:
            if io_failure(exc):
                raise  # the whole write is discarded (see guarded)
            try:  # leave the file as it was before the call: no half-written rows
                for name in arrays:
                    grown[name].resize(n0, axis=0)
            except Exception:
                pass
            if isinstance(exc, OSError):
                raise DatabaseError(os_error_message(self.path, exc)) from None
            if isinstance(exc, (TypeError, ValueError)):
                raise DatabaseError(f"{self.path}: cannot store these clips: {exc}") from None
            raise
        self._added(index, names)

    @guarded
    def append_virtual(
        self,
        source: Path,
        skeleton: Skeleton,
        lengths,
        names,
        fps,
        spec=None,
        sources="",
        roles="",
        labels=None,
        extra: dict | None = None,
        refer_as: Path | None = None,
    ) -> None:
        """Add the clips of skeleton 0 of the database file ``source`` without copying their frames.

        The clips' rows go into this file's table; their frames stay in ``source``. When this
        file is closed, each frame dataset of the skeleton becomes an HDF5 *virtual dataset*
        over the sources, in call order, which plain h5py reads like any dataset. The sources
        are referred to by their path relative to this file's folder, so the two must stay
        side by side; ``refer_as`` names where the source will be when this file is read, if it
        is elsewhere now. Arguments as :meth:`append_packed` (without the frames). A skeleton
        holds either virtual or real frames, not both.
        """
        self._writable()
        self.flush()
        lengths = np.asarray(lengths, dtype=np.int64).reshape(-1)
        names = [str(n) for n in names]
        C, N = len(names), int(lengths.sum())
        if C == 0:
            return
        k = self.add_skeleton(skeleton, spec)
        n0 = self._virtual_rows(k)
        self._append_rows(k, n0, lengths, names, fps, sources, roles, labels, extra or {})
        self._virtual[k].append((self._virtual_source(source, refer_as), N))

    def _virtual_rows(self, k: int) -> int:
        """The frames skeleton ``k`` reads through virtual datasets so far (it may hold no real ones)."""
        if self.h5[f"{skeleton_path(k)}/rotations"].shape[0]:
            raise DatabaseError(
                f"{self.path}: skeleton {k} already holds real frames; it cannot also take virtual ones"
            )
        return sum(n for _, n in self._virtual.setdefault(k, []))

    def _virtual_source(self, source: Path, refer_as: Path | None) -> str:
        """How this file refers to a virtual source: its path relative to this file's folder."""
        return os.path.relpath(Path(refer_as or source).resolve(), Path(self._target).resolve().parent)

    @guarded
    def append_frame_source(self, skeleton: Skeleton, spec, arrays: dict) -> None:
        """Rows of the skeleton's group that hold only per-frame ``arrays`` (name -> ``(N, ...)``,
        those the group stores; every other per-frame dataset gets ``N`` unwritten rows) and no
        clips: the frames of a shard that a virtual alignment store reads (:meth:`append_parts`
        with ``virtual=``), whose table rows are the output's own."""
        self._writable()
        self.flush()
        k = self.add_skeleton(skeleton, spec)
        grown = self._growing_datasets(k)
        arrays = {n: a for n, a in arrays.items() if n in grown}
        n0 = grown["rotations"].shape[0]
        N = len(next(iter(arrays.values()))) if arrays else 0
        self._reserve(sum(np.asarray(a).nbytes for a in arrays.values()))
        grow_rows(grown.values(), n0 + N)
        for name, a in arrays.items():
            grown[name][n0:] = a

    def _added(self, index: dict, names: list[str]) -> None:
        """Note ``names``, just written as rows, in the name index and the name list."""
        for n in names:
            index[n] = len(index)
        if self._names is not None:
            self._names += names
        self._flushed += len(names)

    def _new_names(self, names: list[str]) -> dict:
        """The name index, once ``names`` are checked as new, distinct and printable."""
        index = self._index_map()
        clash = [n for n in names if n in index] or (
            [n for n in names if names.count(n) > 1][:1] if len(set(names)) < len(names) else []
        )
        if clash:
            raise DatabaseError(f"{self.path}: a clip named {clash[0]!r} is already in the database")
        if (bad := control_name(names)) is not None:
            raise DatabaseError(f"{self.path}: {bad}")
        return index

    def _rows(self, names, lengths, fps, sources, roles, labels, extra: dict) -> dict:
        """The table rows of new clips (every column but ``skeleton`` and ``start``): one length
        of at least a frame per name, and only declared extra columns."""
        C = len(names)
        lengths = np.asarray(lengths, dtype=np.int64).reshape(-1)
        if lengths.shape != (C,) or (lengths < 1).any():
            raise DatabaseError(
                f"{self.path}: {C} clip names need {C} lengths of at least one frame, got "
                f"{len(lengths)} ({', '.join(map(str, lengths[:6].tolist()))}{', ...' if len(lengths) > 6 else ''})"
            )
        unknown = [n for n in extra if n not in self._declared]
        if unknown:
            raise DatabaseError(f"{self.path}: no extra column {unknown[0]!r} was declared")
        each = lambda v, what: per_clip(v, C, what, self.path)  # noqa: E731
        rows = {
            "name": names,
            "source": each(sources, "source"),
            "role": each(roles, "role"),
            "labels": [
                v if isinstance(v, str) else json.dumps(v, sort_keys=True)
                for v in each(labels if labels is not None else "{}", "labels")
            ],
            "length": lengths,
            "fps": each(float(fps) if np.ndim(fps) == 0 else fps, "fps"),
        }
        for n, kind in self._declared.items():
            rows[n] = each(extra[n], f"column {n!r}") if n in extra else [KINDS[kind][1]] * C
        return rows

    def _append_rows(self, k: int, n0: int, lengths, names, fps, sources, roles, labels, extra: dict) -> None:
        """Table rows of ``C`` clips of skeleton ``k`` whose frames start at row ``n0``."""
        C = len(names)
        index = self._new_names(names)
        rows = self._rows(names, lengths, fps, sources, roles, labels, extra)
        rows["skeleton"], rows["start"] = [k] * C, n0 + lengths_to_starts(lengths)
        self._store_rows(rows)
        self._added(index, names)

    def _build_virtual(self) -> None:
        """Replace the empty frame datasets of virtual skeletons by virtual datasets over their sources."""
        for k, parts in self._virtual.items():
            g = self.h5[skeleton_path(k)]
            total = sum(n for _, n in parts)
            for name in [n for n in (*FRAME_ARRAYS, *FRAME_PARTS, *self.frame_columns) if n in g]:
                ds = g[name]
                shape, dtype = (total,) + ds.shape[1:], ds.dtype
                layout = h5py.VirtualLayout(shape=shape, dtype=dtype)
                at = 0
                for rel, n in parts:
                    layout[at : at + n] = h5py.VirtualSource(
                        rel, f"{skeleton_path(0)}/{name}", shape=(n,) + ds.shape[1:]
                    )
                    at += n
                del g[name]
                g.create_virtual_dataset(name, layout, fillvalue=np.nan)
        self._virtual = {}
        self._growing = {}  # the datasets replaced: found again if written

    @guarded
    def flush(self) -> None:
        """Write buffered clips to the file."""
        if not self._staged:
            return
        self._write_staged()
        if self._names is not None:
            self._names += [m.name for m, *_ in self._staged]
        self._flushed += len(self._staged)
        self._staged, self._staged_frames = [], 0

    def _growing_datasets(self, k: int) -> dict[str, h5py.Dataset]:
        """:func:`~.guards.growing_datasets` of skeleton ``k`` for one write: names kept, datasets not (held open, they keep chunks in HDF5's cache, past the disk check)."""
        g = self.h5[skeleton_path(k)]
        if self._growing.get(k, (None,))[0] != len(g):
            self._growing[k] = (len(g), tuple(growing_datasets(g)))
        return {n: g[n] for n in self._growing[k][1]}

    def _no_virtual(self, k: int) -> None:
        if k in self._virtual:
            raise DatabaseError(f"{self.path}: skeleton {k} holds virtual frames; real frames cannot be added to it")

    def _write_staged(self) -> None:
        self._reserve(self._staged_bytes() + 200 * len(self._staged))
        starts = {}
        for k in sorted({k for _, k, *_ in self._staged}):
            self._no_virtual(k)
            grown = self._growing_datasets(k)
            staged = [(m, fx) for m, kk, _, fx in self._staged if kk == k]
            n0 = grown["rotations"].shape[0]
            starts[k] = n0
            arrays = {
                "rotations": torch.cat([m.rotations.detach().cpu() for m, _ in staged]).numpy(),
                "root_translation": torch.cat([m.root_translation.detach().cpu() for m, _ in staged]).numpy(),
            }
            if "translations" in grown:
                arrays["translations"] = torch.cat([m.local_translations().detach().cpu() for m, _ in staged]).numpy()
            for name in self.frame_columns:
                arrays[name] = np.concatenate(
                    [frame_values(fx.get(name), m.num_frames, name, m.name) for m, fx in staged]
                )
            for name, a in arrays.items():
                ds = grown[name]
                ds.resize(n0 + a.shape[0], axis=0)
                ds[n0:] = a.astype(ds.dtype)
            grow_rows(grown.values(), grown["rotations"].shape[0])
        rows: dict[str, list] = {c: [] for c in [*COLUMNS, *self._declared]}
        for m, k, extra, _ in self._staged:
            rows["name"].append(m.name)
            rows["source"].append(m.source)
            rows["role"].append(m.role)
            rows["labels"].append(json.dumps(m.labels, sort_keys=True))
            rows["skeleton"].append(k)
            rows["start"].append(starts[k])
            rows["length"].append(m.num_frames)
            rows["fps"].append(m.fps)
            for n, kind in self._declared.items():
                rows[n].append(extra.get(n, KINDS[kind][1]))
            starts[k] += m.num_frames
        self._store_rows(rows)

    def _store_rows(self, rows: dict) -> None:
        """Write clip-table rows (column -> ``C`` values) after the stored ones: into the clips
        datasets, or, for a resumable database, into its row log (:class:`~torchsplice.store.resumable.RowLog`), which
        :meth:`close` writes to the datasets at once (HDF5's heap of variable-length strings is
        not covered by SWMR's ordered writes, so a killed process could leave it torn)."""
        if self._resumable:
            assert self._row_log is not None  # a resumable database has its row log (create, resume)
            self._row_log.append({name: column_array(self._declared, name, values) for name, values in rows.items()})
            return
        c = self.h5[CLIPS]
        m0 = c["name"].shape[0]
        try:
            for name, values in rows.items():
                c[name].resize(m0 + len(values), axis=0)
                c[name][m0:] = column_array(self._declared, name, values)
        except BaseException as exc:
            if io_failure(exc):
                raise  # the whole write is discarded (see guarded)
            try:  # no half-written rows
                for name in rows:
                    c[name].resize(m0, axis=0)
            except Exception:
                pass
            raise

    def _write_logged_rows(self, block_rows: int = 1 << 14) -> None:
        """A resumable database's logged rows into its clips datasets (at :meth:`close`), about
        ``block_rows`` rows at a time, so that a table of millions of clips never sits in
        memory whole (its strings are Python objects until they are written). A block's strings
        and h5py's conversion of them cost about 1.6 KB a row at their peak: on a copy of the
        3.1 million rows of the whole Bandai Namco job's table, blocks of 16,384 rows add 33 MB
        to the process where blocks of 131,072 added 214 MB, at the same speed."""
        c = self.h5[CLIPS]
        names = list(c)
        for name in names:
            c[name].resize(0, axis=0)
        written = 0
        block: list[dict] = []  # the records of the rows not yet written

        def write() -> int:
            n = 0
            for name in names:
                column = np.concatenate([r[name] for r in block])
                n = len(column)
                c[name].resize(written + n, axis=0)
                c[name][written:] = column
            block.clear()
            return n

        pending = 0
        assert self._row_log is not None  # only a resumable database logs its rows
        for record in self._row_log.records():
            block.append(record)
            pending += len(record[names[0]])
            if pending >= block_rows:
                written, pending = written + write(), 0
        if block:
            written += write()
