"""The HDF5 motion database: any number of clips on one or more skeletons, in one file.

:class:`MotionDatabase` opens, creates, resumes and closes a database file; its reads are
:class:`~torchsplice.store.reading.Reading`'s, its writes
:class:`~torchsplice.store.writing.Writing`'s, its typed clip table
:class:`~torchsplice.store.table.ClipTable`. The file's layout is described once, in
:mod:`torchsplice.store.schema`; it is checked on open by :mod:`torchsplice.store.checks`.

Frames of all clips are packed into chunked, compressed datasets (no group per clip), so a
file holds 100,000 clips and more. Writing is atomic: a new database is written beside its
target and renamed into place when closed; appending works on a copy that replaces the
original only when closed cleanly. An interrupted write never leaves a file that looks
complete at the target path.

A *resumable* database (``create(..., staging=PATH)``) is written at a path of the caller's
that outlives the process, in HDF5's SWMR mode (see :mod:`torchsplice.store.resumable`):
:meth:`MotionDatabase.checkpoint` makes everything appended so far survive a killed process,
and :meth:`MotionDatabase.resume` reopens the file at its last checkpoint, so that a long
write killed at any moment carries on where it stood instead of starting again.
"""

from __future__ import annotations

import json
import os
import pickle
import shlex
import shutil
import sys
from pathlib import Path

import h5py
import numpy as np

from ..core.version import __version__
from ..core.errors import DatabaseError, OutputExistsError
from ..core.skeleton import Skeleton
from .atomic import os_error_message
from .checks import check_banks, check_header, unreadable_bank
from .lock import check_name_length, output_lock, remove_stale_temporaries, temp_path
from .assembling import Assembling
from .assembly import ALIGNMENT, PART_COLUMNS, STORE_README, STORES, Assembly, store_kind
from .reading import ClipBatch, Reading, virtual_files
from .resumable import RowLog, clear_status_flags, commit_path, detach, last_checkpoint, rows_path
from .schema import (
    FRAME_ARRAYS,
    CLIPS,
    COLUMNS,
    COMPRESSIONS,
    FORMAT,
    KINDS,
    SCHEMA_VERSION,
    SKELETONS,
    extra_columns,
    skeleton_from_group,
    skeleton_path,
)
from .table import ClipTable, SkeletonInfo
from .writing import SPACE_MARGIN, Writing, guarded, io_failure, mb

__all__ = ["MotionDatabase", "ClipBatch", "ClipTable", "SkeletonInfo", "SCHEMA_VERSION", "FORMAT", "COMPRESSIONS"]


def _writer_lock(path: Path):
    """Take the lock that lets one writer at a time at ``path`` (refused at once otherwise)."""
    return output_lock(path, shlex.join(sys.argv)[:300]).acquire()


class MotionDatabase(Reading, Writing, Assembling):
    """A motion database file; make one with :meth:`create`, open one with :meth:`open`.

    Use it as a context manager: leaving the ``with`` block normally commits a write (the
    file appears at its path); leaving it by an exception discards the write.
    """

    def __init__(self, path: Path, h5: h5py.File, mode: str, tmp: Path | None, dtype, skeletons: list | None = None):
        # the state the mixins share, its types and meanings declared in DatabaseState
        self.path, self._h5, self.mode, self._tmp, self._dtype = path, h5, mode, tmp, dtype
        self._target = path
        self._lock = None
        self._skeletons = (
            skeletons
            if skeletons is not None
            else [skeleton_from_group(h5[SKELETONS][k]) for k in sorted(h5[SKELETONS], key=int)]
        )
        self._names = None
        self._name_index = None
        self._info_reads = 0
        self._flushed = h5[f"{CLIPS}/name"].shape[0]
        columns, frame_columns = extra_columns(h5.attrs)
        self._declared = columns
        self.columns = {n: kind for n, kind in columns.items() if n not in PART_COLUMNS}
        self.frame_columns = frame_columns
        self._staged = []
        self._staged_frames = 0
        self._skeleton_ids = {}
        self._virtual = {}
        self._resumable = False
        self._row_log = None
        self._growing = {}

    # -- opening and closing ------------------------------------------------------------------
    @classmethod
    def create(
        cls,
        path,
        overwrite: bool = False,
        dtype=np.float32,
        chunk_frames: int = 1024,
        compression: str | None = "gzip",
        columns: dict[str, str] | None = None,
        frame_columns: tuple[str, ...] = (),
        attrs: dict | None = None,
        staging: Path | None = None,
        store: str = "motion",
    ) -> "MotionDatabase":
        """Start a new database that appears at ``path`` when closed.

        Frames are stored as ``dtype`` (float32 by default) in chunks of ``chunk_frames``,
        compressed with ``compression``: ``"gzip"`` (readable by every HDF5 tool), ``"lzf"``
        (several times faster, read by h5py), ``"auto"`` (LZF, except for rotations, which are
        stored raw: LZF shrinks float quaternions by only about 15% at a large cost in time,
        while it shrinks translations about tenfold), or ``None``. Every dataset is shuffled
        before compression.
        ``columns`` declares extra per-clip columns (name -> ``"str"``, ``"float"`` or ``"int"``),
        ``frame_columns`` extra per-frame float32 columns; ``attrs`` are extra root attributes.

        ``store="alignment"`` makes an alignment store (:mod:`torchsplice.store.assembly`):
        spliced clips are appended as their parts (:meth:`append_parts`) beside banks of their
        source clips (:meth:`add_bank`), and every read assembles their frames.

        With ``staging`` the file is written there (a path that outlives this process, instead
        of a temporary name beside ``path``) and is *resumable*: see :meth:`checkpoint` and
        :meth:`resume`. Skeletons added before the first checkpoint (:meth:`add_skeleton`) are
        covered by the guarantee that a killed process leaves a file that reopens; add every
        skeleton the file will hold first.
        """
        columns = dict(columns or {})
        if store not in STORES:
            raise ValueError(f"store must be one of {STORES}, got {store!r}")
        if store == ALIGNMENT:
            columns.update(PART_COLUMNS)
        bad = [
            c for c in list(columns) + list(frame_columns) if c in COLUMNS or c in FRAME_ARRAYS or not c.isidentifier()
        ]
        if bad or any(k not in KINDS for k in columns.values()):
            raise ValueError(f"bad extra columns {bad or columns}")
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {COMPRESSIONS}, got {compression!r}")
        path = Path(path)
        if not path.parent.exists():
            raise DatabaseError(f"{path}: folder {path.parent} does not exist")
        if path.is_dir():
            raise DatabaseError(f"{path}: is a folder; give the database a file name ending in .h5")
        check_name_length(path)
        lock = _writer_lock(path)
        if path.exists() and not overwrite:
            lock.release()
            raise OutputExistsError(f"{path}: already exists")
        # what a killed earlier writer of this output left (a SIGKILLed import, retarget or mirror)
        remove_stale_temporaries(path.parent, of=path)
        tmp = Path(staging) if staging is not None else temp_path(path)
        try:
            if staging is not None:
                commit_path(tmp).unlink(missing_ok=True)
                rows_path(tmp).unlink(missing_ok=True)
            h5 = h5py.File(tmp, "w", **({"libver": "latest"} if staging is not None else {}))
            h5.attrs.update(
                {
                    "format": FORMAT,
                    "schema_version": SCHEMA_VERSION if store == ALIGNMENT else 1,
                    "quaternion_order": "wxyz",
                    "rotation_convention": "local joint rotation, parent-from-child, column vectors",
                    "units": "",
                    "up_axis": "",
                    "created_by": f"torchsplice {__version__}",
                    "chunk_frames": chunk_frames,
                    "compression": compression or "",
                    "extra_columns": json.dumps({"clip": columns, "frame": list(frame_columns)}),
                    **({"store": ALIGNMENT, "store_readme": STORE_README} if store == ALIGNMENT else {}),
                    **(attrs or {}),
                }
            )
            h5.create_group(SKELETONS)
            clips = h5.create_group(CLIPS)
            for name, dt in list(COLUMNS.items()) + [(n, KINDS[k][0]) for n, k in columns.items()]:
                clips.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dt, chunks=(4096,))
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            lock.release()
            raise DatabaseError(os_error_message(path, exc)) from None
        db = cls(path, h5, "w", tmp, np.dtype(dtype))
        db._lock = lock
        if staging is not None:
            db._resumable, db._names, db._row_log = True, [], RowLog(rows_path(tmp), fresh=True)
        return db

    @guarded
    def checkpoint(self, note: dict | None = None) -> None:
        """Make every clip appended so far survive a killed process (a resumable database only).

        Flushes the file and records, beside the staging file (one line appended to
        ``STAGING.commit``), the size of every dataset, the skeletons, the root attributes and
        ``note`` (JSON, the caller's own record, e.g. which of its work the clips hold):
        :meth:`resume` returns the file to exactly this state and gives ``note`` back. It costs
        a flush and a line, so a writer may call it after every batch it appends.
        """
        if not self._resumable:
            raise ValueError(f"{self.path}: only a database created with a staging path has checkpoints")
        assert self._row_log is not None and self._tmp is not None  # set with _resumable (create, resume)
        self.flush()
        h5 = self.h5
        if not h5.swmr_mode:
            h5.swmr_mode = True  # from here on the file on disk is consistent at every moment
        h5.flush()
        shape = getattr(self, "_shape_of", None)
        if shape is None or shape[0] != len(
            self._skeletons
        ):  # the datasets and root attributes change with the skeletons
            names = []
            h5.visititems(
                lambda name, obj: (
                    names.append(name)
                    if isinstance(obj, h5py.Dataset) and obj.maxshape and obj.maxshape[0] is None
                    else None
                )
            )
            attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in h5.attrs.items()}
            shape = self._shape_of = (
                len(self._skeletons),
                [(n, h5[n]) for n in names],
                {k: v for k, v in attrs.items() if isinstance(v, (str, int, float))},
            )
        record = {
            "version": 1,
            "sizes": {n: int(ds.shape[0]) for n, ds in shape[1]},
            "skeletons": shape[0],
            "rows": self._row_log.size(),
            "attrs": shape[2],
            "virtual": {str(k): [list(p) for p in parts] for k, parts in self._virtual.items()},
            "note": note or {},
        }
        with open(commit_path(self._tmp), "a") as f:
            f.write(json.dumps(record) + "\n")  # one write: a killed process leaves whole lines

    @staticmethod
    def checkpoint_note(staging) -> dict | None:
        """The ``note`` of the last checkpoint of the database staged at ``staging`` (``None``
        when it has none), read without opening the file."""
        record = last_checkpoint(Path(staging))
        return None if record is None else dict(record["note"])

    @classmethod
    def resume(cls, path, staging, overwrite: bool = False) -> "tuple[MotionDatabase, dict] | None":
        """Reopen the resumable database staged at ``staging`` for ``path`` at its last
        :meth:`checkpoint`: every dataset cut back to its size then (dropping what a killed or
        interrupted process appended after it), skeletons added since removed. Returns the
        database (appends go on from there; closing it puts it at ``path``) and the
        checkpoint's ``note``, or ``None`` (and removes the staging file) when there is nothing
        to resume: no staging file, no checkpoint, or a file that does not reopen.
        """
        path, staging = Path(path), Path(staging)
        commit, rows = commit_path(staging), rows_path(staging)
        if not staging.is_file() or not commit.is_file() or not rows.is_file():
            for f in (staging, commit, rows):
                f.unlink(missing_ok=True)
            return None
        lock = _writer_lock(path)
        if path.exists() and not overwrite:
            lock.release()
            raise OutputExistsError(f"{path}: already exists")
        h5 = log = None
        try:
            record = last_checkpoint(staging)
            if record is None:
                raise ValueError("no complete checkpoint")
            log = RowLog(rows, fresh=False)
            log.truncate(int(record["rows"]))
            names = [str(n) for r in log.records() for n in r["name"]]
            clear_status_flags(staging)
            h5 = h5py.File(staging, "r+", libver="latest")
            for k in [k for k in h5[SKELETONS] if int(k) >= int(record["skeletons"])]:
                del h5[SKELETONS][k]
            for name, n in record["sizes"].items():
                ds = h5[name]
                if ds.shape[0] < n:
                    raise ValueError(f"{name} holds {ds.shape[0]} rows, the checkpoint {n}")
                if ds.shape[0] > n:
                    ds.resize(n, axis=0)
            for k, v in record["attrs"].items():
                if h5.attrs.get(k) != v:
                    h5.attrs[k] = v
            skeletons = check_header(path, h5, "a")
            dtype = h5[f"{skeleton_path(0)}/rotations"].dtype if "0" in h5[SKELETONS] else np.dtype(np.float32)
        except (
            OSError,
            ValueError,
            KeyError,
            TypeError,
            RuntimeError,
            EOFError,
            pickle.UnpicklingError,
            DatabaseError,
        ):
            if h5 is not None:
                detach(h5)
            if log is not None:
                log.close()
            for f in (staging, commit, rows):
                f.unlink(missing_ok=True)
            lock.release()
            return None
        db = cls(path, h5, "w", staging, dtype, skeletons)
        db._lock, db._resumable, db._row_log = lock, True, log
        db._names, db._flushed = names, len(names)
        db._virtual = {int(k): [tuple(p) for p in parts] for k, parts in record["virtual"].items()}
        return db, record["note"]

    @staticmethod
    def virtual_files(path) -> set[Path]:
        """The files whose frames the database at ``path`` reads through virtual datasets (empty
        for a database holding its own frames, or a file that is missing or not readable),
        found without checking or locking the file."""
        return virtual_files(Path(path))

    @classmethod
    def open(cls, path, mode: str = "r") -> "MotionDatabase":
        """Open an existing database, ``mode`` ``"r"`` (read) or ``"a"`` (append).

        Appending works on a copy beside the file that replaces it on a clean close (through a
        symbolic link: beside the file it names, which is replaced; the link stays). The file's
        structure is checked first (attributes, shapes, dtypes, JSON, the clip table's ranges,
        the root ``store`` attribute against the layout, :func:`~.checks.check_store_kind`; not
        the frames, whose damaged chunks are reported by the reads that meet them): a damaged
        file is one :class:`DatabaseError` naming it and its first problem.
        """
        path = Path(path)
        if mode not in ("r", "a"):
            raise ValueError(f"mode must be 'r' or 'a', got {mode!r}")
        if not path.is_file():
            raise DatabaseError(f"{path}: no such file")
        if not h5py.is_hdf5(path):
            raise DatabaseError(f"{path}: not an HDF5 file")
        tmp = None
        real = path.resolve() if mode == "a" else path  # an append through a link writes its target
        lock = _writer_lock(real) if mode == "a" else None
        try:
            if mode == "a":
                tmp = temp_path(real)
                free = shutil.disk_usage(real.parent).free
                if free < path.stat().st_size + SPACE_MARGIN:
                    raise DatabaseError(
                        f"{path}: no space left on the device to append: appending works on a copy "
                        f"of {mb(path.stat().st_size)} and {real.parent} has {mb(free)} free"
                    )
                shutil.copyfile(path, tmp)
            h5 = h5py.File(tmp or path, "r+" if mode == "a" else "r")
        except (OSError, DatabaseError) as exc:
            if tmp is not None:
                tmp.unlink(missing_ok=True)
            if lock is not None:
                lock.release()
            if isinstance(exc, DatabaseError):
                raise
            raise DatabaseError(os_error_message(path, exc)) from None
        try:
            skeletons = check_header(path, h5, mode)
            if mode == "a" and store_kind(h5.attrs) == ALIGNMENT:
                raise DatabaseError(
                    f"{path}: is an alignment store (spliced clips kept as their parts); clips cannot be "
                    f"appended to it: write its motions first (torchsplice materialize {path} -o OUT.h5)"
                )
        except DatabaseError:
            h5.close()
            if tmp is not None:
                tmp.unlink(missing_ok=True)
            if lock is not None:
                lock.release()
            raise
        dtype = h5[f"{skeleton_path(0)}/rotations"].dtype if "0" in h5[SKELETONS] else np.dtype(np.float32)
        db = cls(path, h5, mode, tmp, dtype, skeletons)
        db._lock, db._target = lock, real
        return db

    def _assembly(self) -> Assembly:
        """An alignment store's parts and source banks (:meth:`Assembling._assembly`), the banks
        checked each time they are read (:func:`~.checks.check_banks`, :func:`~.checks.unreadable_bank`):
        a damaged source row or chunk is one line naming the file, the bank and the source clip,
        never a motion assembled from it."""
        before = getattr(self, "_assembly_cache", None)
        try:
            have = super()._assembly()
        except OSError as exc:  # a chunk that does not decompress
            raise DatabaseError(unreadable_bank(self.path, self.h5, exc)) from None
        if have is not before:
            try:
                check_banks(self.path, self.h5, have.banks)
            except DatabaseError:
                del self._assembly_cache  # every later read is refused too
                raise
        return have

    def close(self) -> None:
        """Commit (for a write) and close. Safe to call twice."""
        if self._h5 is None:
            return
        if self.mode == "r":
            self._h5.close()
            self._h5 = None
            return
        try:
            self.flush()
            if self._resumable:
                self._write_logged_rows()
            self._build_virtual()
            self._h5.close()
            self._h5 = None
            assert self._tmp is not None  # a write works on a copy, a temporary or the staging file
            os.replace(self._tmp, self._target)
            if self._resumable:
                assert self._row_log is not None  # set with _resumable (create, resume)
                self._row_log.close()
                commit_path(self._tmp).unlink(missing_ok=True)
                rows_path(self._tmp).unlink(missing_ok=True)
            self._unlock()
        except DatabaseError:
            self.abort()
            raise
        except (OSError, RuntimeError) as exc:
            if not io_failure(exc):
                self.abort()
                raise
            raise DatabaseError(self._write_failed(exc)) from None
        except BaseException:
            self.abort()
            raise

    def abort(self, failed: bool = False) -> None:
        """Discard a write in progress: the file at ``path`` stays as it was.

        A resumable database keeps its staging file for :meth:`resume` (which returns it to
        its last checkpoint); ``failed`` (a write failed) closes it without writing more."""
        if self._resumable:
            if self._row_log is not None:
                self._row_log.close()
            if self._h5 is not None:
                if failed:
                    detach(self._h5)
                else:
                    try:
                        self._h5.close()
                    except Exception:
                        detach(self._h5)
                self._h5 = None
            self._unlock()
            return
        if self._h5 is not None and self._tmp is not None:
            try:  # free the space first: closing flushes HDF5's cache, which needs room on the disk
                os.truncate(self._tmp, 0)
            except OSError:
                pass
        if self._h5 is not None:
            try:
                self._h5.close()
            except Exception:
                pass
            self._h5 = None
        if self._tmp is not None:
            self._tmp.unlink(missing_ok=True)
        self._unlock()

    def _unlock(self) -> None:
        lock, self._lock = getattr(self, "_lock", None), None
        if lock is not None:
            lock.release()

    def __enter__(self) -> "MotionDatabase":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        elif self.mode == "r":
            self.close()
        else:
            self.abort()

    def __del__(self):
        if getattr(self, "_h5", None) is not None and self.mode != "r":
            self.abort()

    # -- metadata -----------------------------------------------------------------------------
    @property
    def h5(self) -> h5py.File:
        """The open h5py file (for advanced readers); raises if closed."""
        if self._h5 is None:
            raise DatabaseError(f"{self.path}: database is closed")
        return self._h5

    def __len__(self) -> int:
        self.h5  # noqa: B018 (raises when closed)
        return self._flushed + len(self._staged)

    @property
    def skeletons(self) -> list[Skeleton]:
        """The skeletons, indexed as ``/skeletons/<k>``."""
        return list(self._skeletons)

    @property
    def attrs(self) -> dict:
        """The file's attributes (format, schema_version, quaternion_order, units, up_axis, ...)."""
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in self.h5.attrs.items()}

    def spec_json(self, skeleton: int) -> str:
        """The dataset spec (JSON) stored with skeleton ``k``, or ``""``."""
        return str(self.h5[skeleton_path(skeleton)].attrs.get("spec", ""))

    def __repr__(self) -> str:
        state = "closed" if self._h5 is None else self.mode
        return f"MotionDatabase({str(self.path)!r}, {state})"
