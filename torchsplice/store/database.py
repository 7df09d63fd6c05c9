"""The HDF5 motion database: any number of clips on one or more skeletons, in one file.

Layout (schema version 1; readable with plain h5py, see ``datasets_spec/README.md`` and the
project README for a ten-line example)::

    /                       attrs: format="torchsplice.motiondb", schema_version=1,
                                   quaternion_order="wxyz", units, up_axis (those of the
                                   skeletons, or "mixed" where they differ), created_by
    /skeletons/<k>/         one group per skeleton k = 0, 1, ...
        names               (J,) str      joint names, topological order
        parents             (J,) int32    parent index, -1 for the root
        offsets             (J, 3) float64 rest offsets in the parent's frame
        channels            (J,) str      BVH channel names, space separated
        end_site_parents    (E,) int32
        end_site_offsets    (E, 3) float64
        rotations           (N_k, J, 4)   local rotations of every frame of every clip, WXYZ
        root_translation    (N_k, 3)      world position of joint 0
        translations        (N_k, J, 3)   local joint translations (only where the skeleton
                                          animates non-root translations, e.g. Bandai Namco)
        attrs: spec (the dataset spec as JSON, or ""), units, up_axis
    /clips/                 one row per clip, in insertion order
        name, source, role  (C,) str
        labels              (C,) str      a JSON object of string labels
        skeleton            (C,) int32    which /skeletons/<k>
        start, length       (C,) int64    the clip's frames are rows start:start+length
        fps                 (C,) float64
        <extra>             (C,) str, float64 or int64: optional columns a writer declares,
                            listed in the root attribute ``extra_columns`` (JSON), e.g. the
                            source clips, method and alignment cost of spliced clips
    /skeletons/<k>/<extra>  (N_k,) float32: optional per-frame columns (same rows as the
                            frames), e.g. the action frame each spliced frame came from

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

import difflib
import errno
import functools
import inspect
import json
import os
import pickle
import shutil
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

import h5py
import numpy as np
import torch

from ..core.version import __version__
from ..core.errors import DatabaseError, OutputExistsError
from ..core.motion import Motion
from ..core.names import CONTROL, control_character, printable
from ..core.skeleton import Skeleton
from .atomic import os_error_message
from .lock import check_name_length, output_lock, temp_path
from .resumable import clear_status_flags, detach

__all__ = ["MotionDatabase", "ClipBatch", "SCHEMA_VERSION", "FORMAT", "COMPRESSIONS"]

FORMAT = "torchsplice.motiondb"
SCHEMA_VERSION = 1
_STR = h5py.string_dtype()
_COLUMNS = {  # name: (dtype, numpy fill for an empty table)
    "name": _STR, "source": _STR, "role": _STR, "labels": _STR,
    "skeleton": np.int32, "start": np.int64, "length": np.int64, "fps": np.float64,
}
_FLUSH_FRAMES = 1 << 16
MIXED = "mixed"  # the file's units or up axis when its skeletons differ in them
_SPACE_MARGIN = 4 << 20  # bytes kept free beyond each write, for HDF5's caches and metadata
COMPRESSIONS = ("gzip", "lzf", "auto", None)


def _io_failure(exc: BaseException) -> bool:
    """Whether ``exc`` is HDF5 failing to write the file (a full disk, an I/O error), not a bug."""
    if isinstance(exc, OSError):
        return True
    text = str(exc)
    return isinstance(exc, RuntimeError) and ("write failed" in text or "errno" in text or "flush" in text)


def _no_space(exc: BaseException) -> bool:
    text = str(exc)
    return getattr(exc, "errno", None) == errno.ENOSPC or "No space left" in text or "errno = 28" in text


def _mb(n: float) -> str:
    return f"{n / 1e6:,.1f} MB" if n < 1e9 else f"{n / 1e9:,.2f} GB"


def _guarded(method):
    """Make a write method of :class:`MotionDatabase` fail cleanly when the file cannot be written.

    HDF5 cannot carry on after a failed write (a full disk leaves its metadata cache dirty, and
    closing the file later crashes the process), so the write in progress is discarded at once
    (:meth:`MotionDatabase.abort`) and one :class:`DatabaseError` line says what happened.
    """
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except (OSError, RuntimeError) as exc:
            if not _io_failure(exc) or self._tmp is None:
                raise
            raise DatabaseError(self._write_failed(exc)) from None
    return wrapper


def _column_array(columns: dict, name: str, values) -> np.ndarray:
    """Values of clip-table column ``name`` (built-in or one of ``columns``) as the array its dataset stores."""
    dt = _COLUMNS.get(name) or _KINDS[columns[name]][0]
    return np.array(values, dtype=object if dt is _STR else dt)


class _RowLog:
    """The clip-table rows of a resumable database, appended to a file beside its staging file
    (``STAGING.rows``): one length-prefixed pickle per append (column -> array). Appends only;
    :meth:`truncate` returns it to a checkpoint's size."""

    def __init__(self, path: Path, fresh: bool):
        self.path = path
        self.file = open(path, "wb" if fresh else "r+b")
        self.file.seek(0, os.SEEK_END)

    def append(self, rows: dict) -> None:
        data = pickle.dumps(rows, protocol=pickle.HIGHEST_PROTOCOL)
        self.file.write(len(data).to_bytes(8, "little") + data)

    def size(self) -> int:
        self.file.flush()
        return self.file.tell()

    def truncate(self, size: int) -> None:
        self.file.flush()
        if os.fstat(self.file.fileno()).st_size < size:
            raise ValueError(f"{self.path} holds fewer rows than its checkpoint")
        self.file.truncate(size)
        self.file.seek(size)

    def records(self):
        """Every append, in order."""
        self.file.flush()
        with open(self.path, "rb") as f:
            while head := f.read(8):
                yield pickle.loads(f.read(int.from_bytes(head, "little")))

    def close(self) -> None:
        self.file.close()


def _commit_path(staging: Path) -> Path:
    """Where a resumable database staged at ``staging`` records its last checkpoint."""
    return staging.with_name(f"{staging.name}.commit")


def _rows_path(staging: Path) -> Path:
    """Where a resumable database staged at ``staging`` logs its clip-table rows."""
    return staging.with_name(f"{staging.name}.rows")


def _writer_lock(path: Path):
    """Take the lock that lets one writer at a time at ``path`` (refused at once otherwise)."""
    import shlex
    import sys

    return output_lock(path, shlex.join(sys.argv)[:300]).acquire()


def _dataset_compression(policy: str | None, dataset: str) -> str | None:
    """The filter of one frame dataset under a file's compression policy (see :meth:`MotionDatabase.create`)."""
    if policy == "auto":
        return None if dataset == "rotations" else "lzf"
    return policy
_KINDS = {"str": (_STR, ""), "float": (np.float64, np.nan), "int": (np.int64, -1)}


@dataclass
class ClipBatch:
    """Clips of one skeleton, padded to a common length.

    Attributes:
        rotations: ``(B, T, J, 4)`` local rotations, WXYZ; padding repeats each clip's last frame.
        root_translation: ``(B, T, 3)``.
        translations: ``(B, T, J, 3)`` or ``None`` (see :class:`~torchsplice.core.motion.Motion`).
        lengths: ``(B,)`` int64 number of real frames per clip.
        mask: ``(B, T)`` bool, True on real frames.
        fps: ``(B,)`` float64.
        names: the clips' names; ``indices``: their row numbers in the database.
        skeleton: the shared :class:`Skeleton`.
    """

    rotations: torch.Tensor
    root_translation: torch.Tensor
    translations: torch.Tensor | None
    lengths: torch.Tensor
    mask: torch.Tensor
    fps: torch.Tensor
    names: list[str]
    indices: list[int]
    skeleton: Skeleton

    def __len__(self) -> int:
        return len(self.names)

    def motion(self, b: int) -> Motion:
        """Clip ``b`` of the batch, without padding."""
        n = int(self.lengths[b])
        return Motion(
            self.skeleton, self.rotations[b, :n], self.root_translation[b, :n], float(self.fps[b]),
            None if self.translations is None else self.translations[b, :n], name=self.names[b],
        )


def _skeleton_to_group(g: h5py.Group, sk: Skeleton) -> None:
    g["names"] = np.array(sk.names, dtype=object).astype(_STR)
    g["parents"] = np.array(sk.parents, dtype=np.int32)
    g["offsets"] = sk.offsets.numpy()
    g["channels"] = np.array([" ".join(c) for c in sk.channels], dtype=object).astype(_STR)
    g["end_site_parents"] = np.array(sk.end_site_parents, dtype=np.int32)
    g["end_site_offsets"] = sk.end_site_offsets.numpy().reshape(-1, 3)


class _Damage(Exception):
    """What is wrong with a database file's structure (one line, without the file's name)."""


def _cap(value, n: int = 40) -> str:
    """A value quoted for a one-line message: on one line, cut after ``n`` characters."""
    if isinstance(value, bytes):
        value = value.decode(errors="replace")
    text = " ".join(str(value).split())
    return repr(text if len(text) <= n else text[:n] + "...")


def _short(exc: BaseException, n: int = 120) -> str:
    """The first line of an exception's message, at most ``n`` characters."""
    text = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    return text if len(text) <= n else text[:n] + "..."


def _dataset(g: h5py.Group, name: str, where: str, shape: tuple | None = None, kind: str = "") -> h5py.Dataset:
    """``g[name]``, checked: a dataset, of ``shape`` (``None`` entries: any size) and dtype
    ``kind`` (numpy kind letters, or ``"str"``); raises :class:`_Damage` otherwise."""
    obj = g.get(name)
    if obj is None:
        raise _Damage(f"{where}/{name} is missing")
    if not isinstance(obj, h5py.Dataset):
        raise _Damage(f"{where}/{name} is not a dataset")
    if shape is not None and (len(obj.shape) != len(shape) or any(w is not None and s != w for s, w in zip(obj.shape, shape))):
        want = "(" + ", ".join("N" if w is None else str(w) for w in shape) + ("," if len(shape) == 1 else "") + ")"
        raise _Damage(f"{where}/{name} has shape {obj.shape}, expected {want}")
    if kind == "str" and h5py.check_string_dtype(obj.dtype) is None:
        raise _Damage(f"{where}/{name} holds {obj.dtype}, not text")
    if kind and kind != "str" and obj.dtype.kind not in kind:
        raise _Damage(f"{where}/{name} holds {obj.dtype}, expected {'whole numbers' if kind == 'iu' else 'numbers'}")
    return obj


def _skeleton_from_group(g: h5py.Group, where: str = "skeleton") -> Skeleton:
    """The skeleton stored in ``g``; :class:`_Damage` says what is wrong if it cannot be one."""
    names = _dataset(g, "names", where, (None,), "str")
    J = names.shape[0]
    E = _dataset(g, "end_site_parents", where, (None,), "iu").shape[0]
    offsets = _dataset(g, "offsets", where, (J, 3), "fiu")[()].astype(np.float64)
    ends = _dataset(g, "end_site_offsets", where, (E, 3) if E else None, "fiu")[()].astype(np.float64).reshape(-1, 3)
    if not (np.isfinite(offsets).all() and np.isfinite(ends).all()):
        raise _Damage(f"{where} has non-finite offsets")
    try:
        return Skeleton(
            names=[s for s in names.asstr()[()]],
            parents=_dataset(g, "parents", where, (J,), "iu")[()].tolist(),
            offsets=torch.from_numpy(offsets),
            channels=[c.split() for c in _dataset(g, "channels", where, (J,), "str").asstr()[()]],
            end_site_parents=g["end_site_parents"][()].tolist(),
            end_site_offsets=torch.from_numpy(ends),
        )
    except ValueError as exc:  # Skeleton's own checks: channels, parents, roots, End Sites
        raise _Damage(f"{where}: {_short(exc, 160)}") from None


def _whole_number(v) -> int | None:
    """An attribute's value as an int, or ``None`` when it is not one whole number."""
    if isinstance(v, bytes):
        v = v.decode(errors="replace")
    if isinstance(v, str):
        v = v.strip()
        return int(v) if v.lstrip("+-").isdigit() and v.isascii() else None
    if np.ndim(v) != 0 or isinstance(v, (bool, np.bool_)):
        return None
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)) and float(v).is_integer():
        return int(v)
    return None


def _text_attr(attrs, key: str, where: str) -> str:
    """A text attribute (``""`` when absent)."""
    v = attrs.get(key, "")
    if isinstance(v, bytes):
        v = v.decode(errors="replace")
    if not isinstance(v, str):
        raise _Damage(f"{where}{key} is not text ({_cap(v)})")
    return v


def _extra_columns(attrs) -> tuple[dict[str, str], tuple[str, ...]]:
    """The declared extra columns ``(clip name -> kind, frame names)`` of the root attribute."""
    text = _text_attr(attrs, "extra_columns", "")
    try:
        extra = json.loads(text or "{}")
    except ValueError:
        raise _Damage(f"extra_columns is not valid JSON ({_cap(text)})") from None
    clip = extra.get("clip", {}) if isinstance(extra, dict) else None
    frame = extra.get("frame", []) if isinstance(extra, dict) else None
    if not isinstance(clip, dict) or not isinstance(frame, list):
        raise _Damage(f"extra_columns is not an object of clip columns and frame columns ({_cap(text)})")
    reserved = (*_COLUMNS, "rotations", "root_translation", "translations")
    for name, kind in clip.items():
        if kind not in _KINDS or name in reserved or not name.isidentifier():
            raise _Damage(f"extra_columns declares clip column {_cap(name)} of kind {_cap(kind)} "
                          f"(a column needs a new name and a kind of {', '.join(_KINDS)})")
    for name in frame:
        if not isinstance(name, str) or name in reserved or not name.isidentifier() or frame.count(name) > 1:
            raise _Damage(f"extra_columns declares a bad frame column {_cap(name)}")
    return dict(clip), tuple(frame)


def _check_structure(h5: h5py.File, mode: str) -> list[Skeleton]:
    """Check a database's structure without reading its frames; returns its skeletons.

    Shapes and dtypes of every dataset, attributes, JSON, and the clip table's index ranges
    (vectorised: a 100,000-clip file opens in milliseconds). Raises :class:`_Damage` naming
    the first problem.
    """
    if mode == "a":
        if (_whole_number(h5.attrs.get("chunk_frames")) or 0) < 1:
            raise _Damage(f"chunk_frames is not a positive whole number ({_cap(h5.attrs.get('chunk_frames'))})")
        comp = _text_attr(h5.attrs, "compression", "")
        if comp and comp not in COMPRESSIONS:
            raise _Damage(f"compression {_cap(comp)} is not one of {', '.join(c for c in COMPRESSIONS if c)}")
    columns, frame_columns = _extra_columns(h5.attrs)
    for group in ("skeletons", "clips"):
        if not isinstance(h5.get(group), h5py.Group):
            raise _Damage(f"the {group} group is missing")
    keys = list(h5["skeletons"])
    if sorted(keys, key=lambda k: (len(k), k)) != [str(k) for k in range(len(keys))]:
        raise _Damage(f"skeletons holds {_cap(', '.join(keys))}, expected groups 0..{len(keys) - 1}")
    skeletons, frames = [], []
    for k in range(len(keys)):
        where = f"skeletons/{k}"
        g = h5[where]
        if not isinstance(g, h5py.Group):
            raise _Damage(f"{where} is not a group")
        sk = _skeleton_from_group(g, where)
        spec = _text_attr(g.attrs, "spec", f"{where} ")
        if spec.strip():
            try:
                ok = isinstance(json.loads(spec), dict)
            except ValueError:
                ok = False
            if not ok:
                raise _Damage(f"{where} spec is not valid JSON ({_cap(spec)})")
        J = sk.num_joints
        rot = _dataset(g, "rotations", where, (None, J, 4), "f")
        N = rot.shape[0]
        if rot.is_virtual and not os.environ.get("HDF5_VDS_PREFIX"):  # a missing source reads as NaN, silently
            folder = Path(h5.filename).resolve().parent
            for src in sorted({vs.file_name for vs in rot.virtual_sources()} - {"."}):
                if not (folder / src).is_file():
                    raise _Damage(f"the frames of {where} are in {_cap(src, 80)}, which is missing "
                                  "(keep the shards folder beside the database)")
        _dataset(g, "root_translation", where, (N, 3), "f")
        if "translations" in g or sk.has_joint_translations:
            _dataset(g, "translations", where, (N, J, 3), "f")
        for name in frame_columns:
            _dataset(g, name, where, (N,), "f")
        skeletons.append(sk)
        frames.append(N)
    c = h5["clips"]
    C = _dataset(c, "name", "clips", (None,), "str").shape[0]
    kinds = {"str": "str", "int": "iu", "float": "fiu"}
    for name, kind in [("name", "str"), ("source", "str"), ("role", "str"), ("labels", "str"), ("skeleton", "int"),
                       ("start", "int"), ("length", "int"), ("fps", "float"), *columns.items()]:
        ds = _dataset(c, name, "clips", (None,), kinds[kind])
        if ds.shape[0] != C:
            raise _Damage(f"clips/{name} has {ds.shape[0]} rows, clips/name {C}")
    if C == 0:
        return skeletons
    sk, start, length, fps = (c[n][()] for n in ("skeleton", "start", "length", "fps"))

    def clip(i: int) -> str:
        try:
            return f"clip {_cap(c['name'].asstr()[i])}"
        except (OSError, ValueError):
            return f"clip row {i}"

    def first(bad: np.ndarray) -> int | None:
        hits = np.flatnonzero(bad)
        return int(hits[0]) if hits.size else None

    K = len(skeletons)
    if (i := first((sk < 0) | (sk >= K))) is not None:
        have = f"the file has skeletons 0..{K - 1}" if K > 1 else "the file has only skeleton 0" if K else "the file has none"
        raise _Damage(f"{clip(i)} points at skeleton {int(sk[i])}; {have}")
    if (i := first(start < 0)) is not None:
        raise _Damage(f"{clip(i)} starts at row {int(start[i])} of skeleton {int(sk[i])}")
    if (i := first(length < 0)) is not None:
        raise _Damage(f"{clip(i)} has {int(length[i])} frames")
    rows = np.asarray(frames, dtype=np.int64)[sk.astype(np.int64)]
    if (i := first(start.astype(np.int64) + length.astype(np.int64) > rows)) is not None:
        raise _Damage(f"{clip(i)} ends at row {int(start[i]) + int(length[i])} of skeleton {int(sk[i])}, "
                      f"which has {int(rows[i])} frames")
    if (i := first(~(np.isfinite(fps) & (fps > 0)))) is not None:
        raise _Damage(f"{clip(i)} has fps {float(fps[i]):g}")
    bad = _control_name(c["name"].asstr()[()])
    if bad is not None:
        raise _Damage(bad)
    return skeletons


def _control_name(names) -> str | None:
    """What is wrong with the first of ``names`` that holds a control character (see
    :mod:`torchsplice.core.names`), or ``None``; fast when none does."""
    names = [str(n) for n in names]
    if not CONTROL.search("".join(names)):
        return None
    row, name = next((k, n) for k, n in enumerate(names) if CONTROL.search(n))
    return f"clip name {_cap(printable(name))} (row {row}) contains {control_character(name)}"


def _reads(method):
    """Make a read method of :class:`MotionDatabase` turn HDF5's ``OSError`` (a damaged file:
    a chunk that does not decompress, a truncated file) into one :class:`DatabaseError` line
    naming the file; reads of frames name the clip too (:meth:`MotionDatabase._frames`)."""
    if inspect.isgeneratorfunction(method):
        @functools.wraps(method)
        def generator(self, *args, **kwargs):
            try:
                yield from method(self, *args, **kwargs)
            except OSError as exc:
                raise self._unreadable(exc, "the file") from None
        return generator

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except OSError as exc:
            raise self._unreadable(exc, "the file") from None
    return wrapper


def _run_record(text) -> dict | str | None:
    """The root attribute ``run`` (JSON written by ``splice-all``) as a dict; ``None`` when absent,
    the raw text when it is not a JSON object."""
    if text is None or str(text) == "":
        return None
    try:
        value = json.loads(str(text))
    except ValueError:
        return str(text)
    return value if isinstance(value, dict) else str(text)


def _json_value(v):
    """A numpy scalar as a JSON-ready Python value (NaN as None)."""
    if isinstance(v, (str, bytes)):
        return v.decode() if isinstance(v, bytes) else v
    v = v.item() if hasattr(v, "item") else v
    return None if isinstance(v, float) and v != v else v


def _frame_values(values, T: int, column: str, clip: str) -> np.ndarray:
    """A per-frame column's ``(T,)`` float32 values for one clip (NaN when not given)."""
    if values is None:
        return np.full(T, np.nan, dtype=np.float32)
    a = (values.detach().cpu().numpy() if isinstance(values, torch.Tensor) else np.asarray(values)).astype(np.float32)
    if a.shape != (T,):
        raise DatabaseError(f"clip {clip!r}: column {column!r} needs {T} values, got shape {a.shape}")
    return a


class MotionDatabase:
    """A motion database file; make one with :meth:`create`, open one with :meth:`open`.

    Use it as a context manager: leaving the ``with`` block normally commits a write (the
    file appears at its path); leaving it by an exception discards the write.
    """

    def __init__(self, path: Path, h5: h5py.File, mode: str, tmp: Path | None, dtype, skeletons: list | None = None):
        self.path, self._h5, self.mode, self._tmp, self._dtype = path, h5, mode, tmp, dtype
        self._target = path  # the file a write replaces on close (an append through a link: its target)
        self._lock = None
        self._skeletons = skeletons if skeletons is not None else [_skeleton_from_group(h5["skeletons"][k]) for k in sorted(h5["skeletons"], key=int)]
        self._names: list[str] | None = None
        self._name_index: dict[str, int] | None = None
        self._flushed = h5["clips/name"].shape[0]
        columns, frame_columns = _extra_columns(h5.attrs)
        self.columns: dict[str, str] = columns
        self.frame_columns: tuple[str, ...] = frame_columns
        self._staged: list[tuple] = []
        self._staged_frames = 0
        self._skeleton_ids: dict[int, tuple[Skeleton, int]] = {}  # id -> (object kept alive, row)
        self._virtual: dict[int, list[tuple[str, int]]] = {}  # skeleton -> (source file, frames) in order
        self._resumable = False  # written at a staging path across runs (see checkpoint, resume)
        self._row_log: _RowLog | None = None  # a resumable database's clip-table rows until it closes

    # -- opening and closing ------------------------------------------------------------------
    @classmethod
    def create(cls, path, overwrite: bool = False, dtype=np.float32, chunk_frames: int = 1024,
               compression: str | None = "gzip", columns: dict[str, str] | None = None,
               frame_columns: tuple[str, ...] = (), attrs: dict | None = None,
               staging: Path | None = None) -> "MotionDatabase":
        """Start a new database that appears at ``path`` when closed.

        Frames are stored as ``dtype`` (float32 by default) in chunks of ``chunk_frames``,
        compressed with ``compression``: ``"gzip"`` (readable by every HDF5 tool), ``"lzf"``
        (several times faster, read by h5py), ``"auto"`` (LZF, except for rotations, which are
        stored raw: LZF shrinks float quaternions by only about 15% at a large cost in time,
        while it shrinks translations about tenfold), or ``None``. Every dataset is shuffled
        before compression.
        ``columns`` declares extra per-clip columns (name -> ``"str"``, ``"float"`` or ``"int"``),
        ``frame_columns`` extra per-frame float32 columns; ``attrs`` are extra root attributes.

        With ``staging`` the file is written there (a path that outlives this process, instead
        of a temporary name beside ``path``) and is *resumable*: see :meth:`checkpoint` and
        :meth:`resume`. Skeletons added before the first checkpoint (:meth:`add_skeleton`) are
        covered by the guarantee that a killed process leaves a file that reopens; add every
        skeleton the file will hold first.
        """
        columns = dict(columns or {})
        bad = [c for c in list(columns) + list(frame_columns)
               if c in _COLUMNS or c in ("rotations", "root_translation", "translations") or not c.isidentifier()]
        if bad or any(k not in _KINDS for k in columns.values()):
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
        tmp = Path(staging) if staging is not None else temp_path(path)
        try:
            if staging is not None:
                _commit_path(tmp).unlink(missing_ok=True)
                _rows_path(tmp).unlink(missing_ok=True)
            h5 = h5py.File(tmp, "w", **({"libver": "latest"} if staging is not None else {}))
            h5.attrs.update({
                "format": FORMAT, "schema_version": SCHEMA_VERSION, "quaternion_order": "wxyz",
                "rotation_convention": "local joint rotation, parent-from-child, column vectors",
                "units": "", "up_axis": "", "created_by": f"torchsplice {__version__}",
                "chunk_frames": chunk_frames, "compression": compression or "",
                "extra_columns": json.dumps({"clip": columns, "frame": list(frame_columns)}),
                **(attrs or {}),
            })
            h5.create_group("skeletons")
            clips = h5.create_group("clips")
            for name, dt in list(_COLUMNS.items()) + [(n, _KINDS[k][0]) for n, k in columns.items()]:
                clips.create_dataset(name, shape=(0,), maxshape=(None,), dtype=dt, chunks=(4096,))
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            lock.release()
            raise DatabaseError(os_error_message(path, exc)) from None
        db = cls(path, h5, "w", tmp, np.dtype(dtype))
        db._lock = lock
        if staging is not None:
            db._resumable, db._names, db._row_log = True, [], _RowLog(_rows_path(tmp), fresh=True)
        return db

    @_guarded
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
        self.flush()
        h5 = self.h5
        if not h5.swmr_mode:
            h5.swmr_mode = True  # from here on the file on disk is consistent at every moment
        h5.flush()
        shape = getattr(self, "_shape_of", None)
        if shape is None or shape[0] != len(self._skeletons):  # the datasets and root attributes change with the skeletons
            names = []
            h5.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) and obj.maxshape
                          and obj.maxshape[0] is None else None)
            attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in h5.attrs.items()}
            shape = self._shape_of = (len(self._skeletons), [(n, h5[n]) for n in names],
                                      {k: v for k, v in attrs.items() if isinstance(v, (str, int, float))})
        record = {"version": 1, "sizes": {n: int(ds.shape[0]) for n, ds in shape[1]}, "skeletons": shape[0],
                  "rows": self._row_log.size(), "attrs": shape[2],
                  "virtual": {str(k): [list(p) for p in parts] for k, parts in self._virtual.items()},
                  "note": note or {}}
        with open(_commit_path(self._tmp), "a") as f:
            f.write(json.dumps(record) + "\n")  # one write: a killed process leaves whole lines

    @staticmethod
    def _last_checkpoint(staging: Path) -> dict | None:
        """The last complete record of ``STAGING.commit`` (``None`` when it has none)."""
        try:
            lines = _commit_path(Path(staging)).read_text().splitlines()
        except OSError:
            return None
        for line in reversed(lines):
            try:
                record = json.loads(line)
            except ValueError:
                continue
            if isinstance(record, dict) and isinstance(record.get("note"), dict):
                return record
        return None

    @staticmethod
    def checkpoint_note(staging) -> dict | None:
        """The ``note`` of the last checkpoint of the database staged at ``staging`` (``None``
        when it has none), read without opening the file."""
        record = MotionDatabase._last_checkpoint(Path(staging))
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
        commit, rows = _commit_path(staging), _rows_path(staging)
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
            record = cls._last_checkpoint(staging)
            if record is None:
                raise ValueError("no complete checkpoint")
            log = _RowLog(rows, fresh=False)
            log.truncate(int(record["rows"]))
            names = [str(n) for r in log.records() for n in r["name"]]
            clear_status_flags(staging)
            h5 = h5py.File(staging, "r+", libver="latest")
            for k in [k for k in h5["skeletons"] if int(k) >= int(record["skeletons"])]:
                del h5["skeletons"][k]
            for name, n in record["sizes"].items():
                ds = h5[name]
                if ds.shape[0] < n:
                    raise ValueError(f"{name} holds {ds.shape[0]} rows, the checkpoint {n}")
                if ds.shape[0] > n:
                    ds.resize(n, axis=0)
            for k, v in record["attrs"].items():
                if h5.attrs.get(k) != v:
                    h5.attrs[k] = v
            skeletons = cls._check_header(path, h5, "a")
            dtype = h5["skeletons/0/rotations"].dtype if "0" in h5["skeletons"] else np.dtype(np.float32)
        except (OSError, ValueError, KeyError, TypeError, RuntimeError, EOFError, pickle.UnpicklingError, DatabaseError):
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

    @classmethod
    def open(cls, path, mode: str = "r") -> "MotionDatabase":
        """Open an existing database, ``mode`` ``"r"`` (read) or ``"a"`` (append).

        Appending works on a copy beside the file that replaces it on a clean close (through a
        symbolic link: beside the file it names, which is replaced; the link stays). The file's
        structure is checked first (attributes, shapes, dtypes, JSON, the clip table's ranges;
        not the frames, whose damaged chunks are reported by the reads that meet them): a
        damaged file is one :class:`DatabaseError` naming it and its first problem.
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
                if free < path.stat().st_size + _SPACE_MARGIN:
                    raise DatabaseError(f"{path}: no space left on the device to append: appending works on a copy "
                                        f"of {_mb(path.stat().st_size)} and {real.parent} has {_mb(free)} free")
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
            skeletons = cls._check_header(path, h5, mode)
        except DatabaseError:
            h5.close()
            if tmp is not None:
                tmp.unlink(missing_ok=True)
            if lock is not None:
                lock.release()
            raise
        dtype = h5["skeletons/0/rotations"].dtype if "0" in h5["skeletons"] else np.dtype(np.float32)
        db = cls(path, h5, mode, tmp, dtype, skeletons)
        db._lock, db._target = lock, real
        return db

    @staticmethod
    def _check_header(path: Path, h5: h5py.File, mode: str = "r") -> list[Skeleton]:
        """Check the file's format, version and structure (see :func:`_check_structure`); returns
        its skeletons, or raises one :class:`DatabaseError` line naming the file and the first problem."""
        fmt = h5.attrs.get("format")
        if not isinstance(fmt, (str, bytes)) or (fmt.decode(errors="replace") if isinstance(fmt, bytes) else fmt) != FORMAT:
            raise DatabaseError(f"{path}: not a torchsplice motion database (no format attribute {FORMAT!r})")
        raw = h5.attrs.get("schema_version")
        version = _whole_number(raw) if raw is not None else None
        if version is None:
            have = "no schema_version attribute" if raw is None else f"schema_version is not a whole number ({_cap(raw)})"
            raise DatabaseError(f"{path}: damaged database: {have}")
        if version > SCHEMA_VERSION:
            raise DatabaseError(f"{path}: schema version {version} is newer than this torchsplice reads ({SCHEMA_VERSION}); upgrade torchsplice")
        if version < 1:
            raise DatabaseError(f"{path}: damaged database: schema version {version}")
        try:
            return _check_structure(h5, mode)
        except _Damage as exc:
            raise DatabaseError(f"{path}: damaged database: {exc}") from None
        except (OSError, KeyError, TypeError, ValueError, IndexError, AttributeError, RuntimeError) as exc:
            raise DatabaseError(f"{path}: damaged database: cannot read its structure ({_short(exc)})") from None

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
            os.replace(self._tmp, self._target)
            if self._resumable:
                self._row_log.close()
                _commit_path(self._tmp).unlink(missing_ok=True)
                _rows_path(self._tmp).unlink(missing_ok=True)
            self._unlock()
        except DatabaseError:
            self.abort()
            raise
        except (OSError, RuntimeError) as exc:
            if not _io_failure(exc):
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

    def _reserve(self, nbytes: int) -> None:
        """Refuse to write ``nbytes`` (uncompressed) where the disk has no room for them.

        HDF5 reports a full disk only while it frees its objects, where the error cannot be
        caught and the process later crashes; so the room is checked before every write, with
        a margin for the data HDF5 still holds in its caches (``_SPACE_MARGIN``).
        """
        if self._tmp is None:
            return
        try:
            free = shutil.disk_usage(self._tmp.parent).free
        except OSError:
            return
        if free < nbytes + _SPACE_MARGIN:
            # nothing failed yet: a resumable database stays open, so that its writer can
            # checkpoint what it holds (within the margin) before it stops
            raise DatabaseError(self._write_failed(OSError(errno.ENOSPC, "No space left on device"), nbytes,
                                                   discard=not self._resumable))

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
        if not _no_space(exc):
            return os_error_message(self.path, exc) if isinstance(exc, OSError) else f"{self.path}: cannot write the file ({str(exc).splitlines()[0][:120]})"
        folder = self.path.parent.resolve()
        free = shutil.disk_usage(folder).free
        return (f"{self.path}: no space left on the device; the database needs more than {_mb(written + pending)} "
                f"and {folder} has {_mb(free)} free ({kept}; free some space and run the command again)")

    def _staged_bytes(self) -> int:
        """Uncompressed bytes of the clips waiting in the buffer (an upper bound of their size)."""
        size = self._dtype.itemsize
        return sum(m.num_frames * (7 * m.skeleton.num_joints + 3 + len(self.frame_columns)) * size for m, *_ in self._staged)

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
        self.h5  # raises when closed
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
        return str(self.h5[f"skeletons/{skeleton}"].attrs.get("spec", ""))

    def _unreadable(self, exc: BaseException, what: str) -> DatabaseError:
        return DatabaseError(f"{self.path}: damaged database: cannot read {what} ({_short(exc)})")

    def _frames_error(self, exc: OSError, k: int, rows) -> DatabaseError:
        """The error for a failed read of skeleton ``k``'s frames: names the first of the clips
        ``rows`` (``None``: every clip of the skeleton) whose own frames cannot be read."""
        try:
            c = self.h5["clips"]
            start, length = c["start"][()], c["length"][()]
            if rows is None:
                rows = np.flatnonzero(c["skeleton"][()] == k)
            g = self.h5[f"skeletons/{k}"]
            sets = [n for n in ("rotations", "root_translation", "translations", *self.frame_columns) if n in g]
            for i in sorted((int(i) for i in rows), key=lambda i: int(start[i])):
                s, n = int(start[i]), int(length[i])
                for name in sets:
                    try:
                        g[name][s:s + n]
                    except OSError as inner:
                        return self._unreadable(inner, f"the frames of clip {_cap(self.names[i], 60)}")
        except (OSError, DatabaseError):
            pass
        return self._unreadable(exc, f"the frames of skeleton {k}")

    @contextmanager
    def _frames(self, k: int, rows=None):
        """Reads of skeleton ``k``'s frames for the clips ``rows``: a damaged chunk is one
        :class:`DatabaseError` naming the file and the clip."""
        try:
            yield
        except OSError as exc:
            raise self._frames_error(exc, k, rows) from None

    def _labels(self, text, clip) -> dict:
        """A clip's labels column (JSON) as a dict; a clear error when it is not one."""
        try:
            labels = json.loads(text or "{}")
        except ValueError:
            labels = None
        if not isinstance(labels, dict):
            raise DatabaseError(f"{self.path}: damaged database: the labels of clip {_cap(clip, 60)} "
                                f"are not a JSON object ({_cap(text)})")
        return labels

    @property
    @_reads
    def names(self) -> list[str]:
        """Every clip's name, in row order."""
        if self._names is None:
            self._names = list(self.h5["clips/name"].asstr()[()])
        return self._names + [m.name for m, *_ in self._staged]

    def index(self, clip: str | int) -> int:
        """Row number of a clip given by name or row number; a clear error otherwise."""
        if isinstance(clip, (int, np.integer)):
            if not 0 <= clip < len(self):
                raise DatabaseError(f"{self.path}: no clip number {clip} (the database has {len(self)})")
            return int(clip)
        index = self._index_map()
        if clip not in index:
            close = [n for n in index if clip.lower() in n.lower()][:5] or difflib.get_close_matches(clip, list(index), n=5)
            hint = f"; similar: {', '.join(close)}" if close else "; `torchsplice info` lists the clips"
            raise DatabaseError(f"{self.path}: no clip named {clip!r}{hint}")
        return self._name_index[clip]

    def _index_map(self) -> dict[str, int]:
        """Name -> row, built once per open and kept up to date by :meth:`append`."""
        if self._name_index is None:
            self._name_index = {n: i for i, n in enumerate(self.names)}
        return self._name_index

    @_reads
    def clip_info(self, clip: str | int) -> dict:
        """Metadata of one clip: name, source, role, labels, skeleton, start, length, fps."""
        i = self.index(clip)
        self._require_flushed(i)
        self._table_written()
        c = self.h5["clips"]
        info = {k: c[k][i] for k in [*_COLUMNS, *self.columns]}
        for k in ("name", "source", "role", "labels", *[n for n, kind in self.columns.items() if kind == "str"]):
            info[k] = info[k].decode() if isinstance(info[k], bytes) else str(info[k])
        for n, kind in self.columns.items():
            info[n] = float(info[n]) if kind == "float" else int(info[n]) if kind == "int" else info[n]
        info["labels"] = self._labels(info["labels"], info["name"])
        for k in ("skeleton", "start", "length"):
            info[k] = int(info[k])
        info["fps"] = float(info["fps"])
        return info

    @_reads
    def table(self) -> dict[str, np.ndarray]:
        """Every metadata column, extra ones too, as an array (labels as JSON strings, each
        checked to be a JSON object, so that callers may ``json.loads`` them)."""
        self.flush()
        self._table_written()
        c = self.h5["clips"]
        t = {k: (c[k].asstr()[()] if h5py.check_string_dtype(c[k].dtype) else c[k][()]) for k in [*_COLUMNS, *self.columns]}
        checked: set[str] = set()
        for i, text in enumerate(t["labels"]):
            if text not in checked:
                self._labels(text, t["name"][i])
                checked.add(text)
        return t

    @_reads
    def read_frame_column(self, clip: str | int, name: str) -> np.ndarray:
        """A clip's values ``(T,)`` of the per-frame column ``name``."""
        if name not in self.frame_columns:
            raise DatabaseError(f"{self.path}: no per-frame column {name!r} (has: {', '.join(self.frame_columns) or 'none'})")
        info = self.clip_info(clip)
        with self._frames(info["skeleton"], [self.index(clip)]):
            return self.h5[f"skeletons/{info['skeleton']}/{name}"][info["start"]:info["start"] + info["length"]]

    def _table_written(self) -> None:
        if self._resumable and self._h5 is not None:
            raise DatabaseError(f"{self.path}: is being written (its clip table is written when it is closed)")

    def _require_flushed(self, i: int) -> None:
        if i >= self._flushed:
            self.flush()

    # -- writing ------------------------------------------------------------------------------
    def _writable(self) -> None:
        if self.mode == "r":
            raise DatabaseError(f"{self.path}: opened read-only")

    @_guarded
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
        for key, value in (("units", units), ("up_axis", up)):  # each skeleton keeps its own; the file's is their common one
            have = str(self.h5.attrs.get(key, ""))
            if value and have and have != value:
                self.h5.attrs[key] = MIXED
            if value and not have:
                self.h5.attrs[key] = value
        k = len(self._skeletons)
        g = self.h5["skeletons"].create_group(str(k))
        _skeleton_to_group(g, skeleton)
        g.attrs.update({"spec": spec.to_json() if spec is not None else "", "units": units, "up_axis": up})
        chunk = int(self.h5.attrs["chunk_frames"])
        policy = str(self.h5.attrs["compression"]) or None
        J = skeleton.num_joints
        shapes = {"rotations": (J, 4), "root_translation": (3,)}
        if skeleton.has_joint_translations:
            shapes["translations"] = (J, 3)
        for name, shape in shapes.items():
            comp = _dataset_compression(policy, name)
            g.create_dataset(name, shape=(0,) + shape, maxshape=(None,) + shape, dtype=self._dtype,
                             chunks=(chunk,) + shape, compression=comp, shuffle=comp is not None)
        for name in self.frame_columns:
            comp = _dataset_compression(policy, name)
            g.create_dataset(name, shape=(0,), maxshape=(None,), dtype=np.float32, chunks=(chunk,),
                             compression=comp, shuffle=comp is not None)
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
        unknown = [k for k in extra if k not in self.columns] + [k for k in frame_extra if k not in self.frame_columns]
        if unknown:
            raise DatabaseError(f"{self.path}: no extra column {unknown[0]!r} was declared")
        self._writable()
        motion.check_finite()
        if not motion.name:
            raise DatabaseError(f"{self.path}: a clip needs a name")
        if (bad := _control_name([motion.name])) is not None:
            raise DatabaseError(f"{self.path}: {bad}")
        index = self._index_map()
        if motion.name in index:
            raise DatabaseError(f"{self.path}: a clip named {motion.name!r} is already in the database")
        k = self.add_skeleton(motion.skeleton, spec)
        index[motion.name] = len(self)
        self._staged.append((motion, k, extra, frame_extra))
        self._staged_frames += motion.num_frames
        if self._staged_frames >= _FLUSH_FRAMES:
            self.flush()
        return len(self) - 1

    @_guarded
    def append_packed(self, skeleton: Skeleton, rotations, root_translation, translations, lengths, names, fps,
                      spec=None, sources="", roles="", labels=None, extra: dict | None = None,
                      frame_extra: dict | None = None, check: bool = True) -> None:
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
            raise DatabaseError(f"{self.path}: packed clips do not fit: {C} names, lengths summing to {N}, "
                                f"rotations {rot.shape}, root translation {root.shape} for {J} joints")
        trans = None if translations is None else arr(translations)
        if trans is not None and trans.shape != (N, J, 3):
            raise DatabaseError(f"{self.path}: translations must be {(N, J, 3)}, got {trans.shape}")
        index = self._index_map()
        clash = [n for n in names if n in index] or ([n for n in names if names.count(n) > 1][:1] if len(set(names)) < C else [])
        if clash:
            raise DatabaseError(f"{self.path}: a clip named {clash[0]!r} is already in the database")
        if (bad := _control_name(names)) is not None:
            raise DatabaseError(f"{self.path}: {bad}")
        starts = np.concatenate(([0], np.cumsum(lengths)[:-1]))
        for name, a in (("rotations", rot), ("root translation", root), ("translations", trans)) if check else ():
            if a is not None and not np.isfinite(a).all():
                row = int(np.nonzero(~np.isfinite(a.reshape(N, -1)).all(1))[0][0])
                c = int(np.searchsorted(starts, row, side="right") - 1)
                raise DatabaseError(f"{self.path}: clip {names[c]!r} has non-finite {name} at frame {row - starts[c]}")
        extra, frame_extra = dict(extra or {}), dict(frame_extra or {})
        unknown = [k for k in extra if k not in self.columns] + [k for k in frame_extra if k not in self.frame_columns]
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

        def each(v, what):
            """One value for every clip, or ``C`` values."""
            out = [v] * C if isinstance(v, (str, bytes, int, float, np.generic)) else list(arr(v) if isinstance(v, torch.Tensor) else v)
            if len(out) != C:
                raise DatabaseError(f"{self.path}: {what} needs {C} values, got {len(out)}")
            return out

        rows = {
            "name": names, "source": each(sources, "source"), "role": each(roles, "role"),
            "labels": [v if isinstance(v, str) else json.dumps(v, sort_keys=True) for v in each(labels if labels is not None else "{}", "labels")],
            "length": lengths, "fps": each(float(fps) if np.ndim(fps) == 0 else fps, "fps"),
        }
        for n, kind in self.columns.items():
            rows[n] = each(extra[n], f"column {n!r}") if n in extra else [_KINDS[kind][1]] * C
        k = self.add_skeleton(skeleton, spec)
        self._no_virtual(k)
        g = self.h5[f"skeletons/{k}"]
        arrays = {"rotations": rot, "root_translation": root, **frames}
        if "translations" in g:
            if trans is not None and np.array_equal(trans[:, 0], root):
                arrays["translations"] = trans  # row 0 already holds the root
            else:
                t = trans.copy() if trans is not None else np.broadcast_to(skeleton.offsets.numpy(), (N, J, 3)).copy()
                t[:, 0] = root
                arrays["translations"] = t
        self._reserve(sum(a.nbytes for a in arrays.values()) + 200 * C)
        n0 = g["rotations"].shape[0]
        rows["skeleton"], rows["start"] = [k] * C, n0 + starts
        try:
            for name, a in arrays.items():
                ds = g[name]
                ds.resize(n0 + N, axis=0)
                ds[n0:] = a.astype(ds.dtype, copy=False)
            self._store_rows(rows)
        except BaseException as exc:
            if _io_failure(exc):
                raise  # the whole write is discarded (see _guarded)
            try:  # leave the file as it was before the call: no half-written rows
                for name in arrays:
                    g[name].resize(n0, axis=0)
            except Exception:
                pass
            if isinstance(exc, OSError):
                raise DatabaseError(os_error_message(self.path, exc)) from None
            if isinstance(exc, (TypeError, ValueError)):
                raise DatabaseError(f"{self.path}: cannot store these clips: {exc}") from None
            raise
        for n in names:
            index[n] = len(index)
        if self._names is not None:
            self._names += names
        self._flushed += C

    @_guarded
    def append_virtual(self, source: Path, skeleton: Skeleton, lengths, names, fps, spec=None, sources="", roles="",
                       labels=None, extra: dict | None = None, refer_as: Path | None = None) -> None:
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
        if self.h5[f"skeletons/{k}/rotations"].shape[0]:
            raise DatabaseError(f"{self.path}: skeleton {k} already holds real frames; it cannot also take virtual ones")
        parts = self._virtual.setdefault(k, [])
        n0 = sum(n for _, n in parts)
        rel = os.path.relpath(Path(refer_as or source).resolve(), Path(self._target).resolve().parent)
        self._append_rows(k, n0, lengths, names, fps, sources, roles, labels, extra or {})
        parts.append((rel, N))

    def _append_rows(self, k: int, n0: int, lengths, names, fps, sources, roles, labels, extra: dict) -> None:
        """Table rows of ``C`` clips of skeleton ``k`` whose frames start at row ``n0``."""
        C = len(names)
        index = self._index_map()
        clash = [n for n in names if n in index] or ([n for n in names if names.count(n) > 1][:1] if len(set(names)) < C else [])
        if clash:
            raise DatabaseError(f"{self.path}: a clip named {clash[0]!r} is already in the database")
        if (bad := _control_name(names)) is not None:
            raise DatabaseError(f"{self.path}: {bad}")

        def each(v, what):
            out = [v] * C if isinstance(v, (str, bytes, int, float, np.generic)) else list(v)
            if len(out) != C:
                raise DatabaseError(f"{self.path}: {what} needs {C} values, got {len(out)}")
            return out

        rows = {
            "name": names, "source": each(sources, "source"), "role": each(roles, "role"),
            "labels": [v if isinstance(v, str) else json.dumps(v, sort_keys=True) for v in each(labels if labels is not None else "{}", "labels")],
            "length": lengths, "fps": each(float(fps) if np.ndim(fps) == 0 else fps, "fps"),
            "skeleton": [k] * C, "start": n0 + np.concatenate(([0], np.cumsum(lengths)[:-1])),
        }
        for n, kind in self.columns.items():
            rows[n] = each(extra[n], f"column {n!r}") if n in extra else [_KINDS[kind][1]] * C
        self._store_rows(rows)
        for n in names:
            index[n] = len(index)
        if self._names is not None:
            self._names += names
        self._flushed += C

    def _build_virtual(self) -> None:
        """Replace the empty frame datasets of virtual skeletons by virtual datasets over their sources."""
        for k, parts in self._virtual.items():
            g = self.h5[f"skeletons/{k}"]
            total = sum(n for _, n in parts)
            for name in [n for n in ("rotations", "root_translation", "translations", *self.frame_columns) if n in g]:
                ds = g[name]
                shape, dtype = (total,) + ds.shape[1:], ds.dtype
                layout = h5py.VirtualLayout(shape=shape, dtype=dtype)
                at = 0
                for rel, n in parts:
                    layout[at:at + n] = h5py.VirtualSource(rel, f"skeletons/0/{name}", shape=(n,) + ds.shape[1:])
                    at += n
                del g[name]
                g.create_virtual_dataset(name, layout, fillvalue=np.nan)
        self._virtual = {}

    @_reads
    def packed(self, skeleton: int = 0) -> dict[str, np.ndarray]:
        """Every frame of skeleton ``k`` as whole arrays: ``rotations``, ``root_translation``,
        ``translations`` (when stored) and the per-frame columns, rows as in the file (read at
        once: meant for a splice job's parts and other small files)."""
        g = self.h5[f"skeletons/{skeleton}"]
        with self._frames(skeleton):
            return {n: g[n][()] for n in ("rotations", "root_translation", "translations", *self.frame_columns) if n in g}

    @_guarded
    def flush(self) -> None:
        """Write buffered clips to the file."""
        if not self._staged:
            return
        self._write_staged()
        if self._names is not None:
            self._names += [m.name for m, *_ in self._staged]
        self._flushed += len(self._staged)
        self._staged, self._staged_frames = [], 0

    def _no_virtual(self, k: int) -> None:
        if k in self._virtual:
            raise DatabaseError(f"{self.path}: skeleton {k} holds virtual frames; real frames cannot be added to it")

    def _write_staged(self) -> None:
        h5 = self.h5
        self._reserve(self._staged_bytes() + 200 * len(self._staged))
        starts = {}
        for k in sorted({k for _, k, *_ in self._staged}):
            self._no_virtual(k)
            g = h5[f"skeletons/{k}"]
            staged = [(m, fx) for m, kk, _, fx in self._staged if kk == k]
            n0 = g["rotations"].shape[0]
            starts[k] = n0
            arrays = {
                "rotations": torch.cat([m.rotations.detach().cpu() for m, _ in staged]).numpy(),
                "root_translation": torch.cat([m.root_translation.detach().cpu() for m, _ in staged]).numpy(),
            }
            if "translations" in g:
                arrays["translations"] = torch.cat([m.local_translations().detach().cpu() for m, _ in staged]).numpy()
            for name in self.frame_columns:
                arrays[name] = np.concatenate([_frame_values(fx.get(name), m.num_frames, name, m.name) for m, fx in staged])
            for name, a in arrays.items():
                ds = g[name]
                ds.resize(n0 + a.shape[0], axis=0)
                ds[n0:] = a.astype(ds.dtype)
        rows = {c: [] for c in [*_COLUMNS, *self.columns]}
        for m, k, extra, _ in self._staged:
            rows["name"].append(m.name)
            rows["source"].append(m.source)
            rows["role"].append(m.role)
            rows["labels"].append(json.dumps(m.labels, sort_keys=True))
            rows["skeleton"].append(k)
            rows["start"].append(starts[k])
            rows["length"].append(m.num_frames)
            rows["fps"].append(m.fps)
            for n, kind in self.columns.items():
                rows[n].append(extra.get(n, _KINDS[kind][1]))
            starts[k] += m.num_frames
        self._store_rows(rows)

    def _store_rows(self, rows: dict) -> None:
        """Write clip-table rows (column -> ``C`` values) after the stored ones: into the clips
        datasets, or, for a resumable database, into its row log (:class:`_RowLog`), which
        :meth:`close` writes to the datasets at once (HDF5's heap of variable-length strings is
        not covered by SWMR's ordered writes, so a killed process could leave it torn)."""
        if self._resumable:
            self._row_log.append({name: _column_array(self.columns, name, values) for name, values in rows.items()})
            return
        c = self.h5["clips"]
        m0 = c["name"].shape[0]
        try:
            for name, values in rows.items():
                c[name].resize(m0 + len(values), axis=0)
                c[name][m0:] = _column_array(self.columns, name, values)
        except BaseException as exc:
            if _io_failure(exc):
                raise  # the whole write is discarded (see _guarded)
            try:  # no half-written rows
                for name in rows:
                    c[name].resize(m0, axis=0)
            except Exception:
                pass
            raise

    def _write_logged_rows(self) -> None:
        """A resumable database's logged rows into its clips datasets (at :meth:`close`), a
        column at a time."""
        c = self.h5["clips"]
        records = list(self._row_log.records())
        for name in c:
            values = [r[name] for r in records]
            column = np.concatenate(values) if values else _column_array(self.columns, name, [])
            c[name].resize(len(column), axis=0)
            c[name][:] = column

    # -- reading ------------------------------------------------------------------------------
    @_reads
    def read_many(self, clips: Sequence[str | int], dtype: torch.dtype = torch.float32) -> list[Motion]:
        """Several clips as :class:`Motion` objects, in the order asked; the metadata table is
        read once (faster than :meth:`read` per clip)."""
        idx = [self.index(c) for c in clips]
        if not idx:
            return []
        self._require_flushed(max(idx))
        t = self.table()
        blocks: dict[int, tuple[int, dict]] = {}  # skeleton -> (first row, whole block of its frames)
        for k in sorted({int(t["skeleton"][i]) for i in idx}):
            mine = [i for i in idx if int(t["skeleton"][i]) == k]
            lo = min(int(t["start"][i]) for i in mine)
            hi = max(int(t["start"][i] + t["length"][i]) for i in mine)
            if hi - lo <= 2 * sum(int(t["length"][i]) for i in mine):  # one read, each chunk decompressed once
                g = self.h5[f"skeletons/{k}"]
                with self._frames(k, mine):
                    blocks[k] = (lo, {n: g[n][lo:hi] for n in ("rotations", "root_translation", "translations") if n in g})
        out = []
        for i in idx:
            k, s, n = int(t["skeleton"][i]), int(t["start"][i]), int(t["length"][i])
            g = self.h5[f"skeletons/{k}"]
            lo, block = blocks.get(k, (0, None))

            def get(name):
                with self._frames(k, [i]):
                    a = block[name][s - lo:s - lo + n] if block is not None else g[name][s:s + n]
                return torch.from_numpy(np.ascontiguousarray(a)).to(dtype)

            out.append(Motion(
                skeleton=self._skeletons[k], rotations=get("rotations"), root_translation=get("root_translation"),
                translations=get("translations") if "translations" in g else None, fps=float(t["fps"][i]),
                name=str(t["name"][i]), source=str(t["source"][i]), role=str(t["role"][i]),
                labels=self._labels(t["labels"][i], t["name"][i]),
            ))
        return out

    @_reads
    def read(self, clip: str | int, dtype: torch.dtype = torch.float32, device=None) -> Motion:
        """One clip as a :class:`Motion` (``dtype`` and ``device`` as asked)."""
        info = self.clip_info(clip)
        g = self.h5[f"skeletons/{info['skeleton']}"]
        s, n = info["start"], info["length"]

        def get(name):
            with self._frames(info["skeleton"], [self.index(clip)]):
                a = g[name][s:s + n]
            return torch.from_numpy(a).to(device=device, dtype=dtype)

        return Motion(
            skeleton=self._skeletons[info["skeleton"]],
            rotations=get("rotations"),
            root_translation=get("root_translation"),
            translations=get("translations") if "translations" in g else None,
            fps=info["fps"], name=info["name"], source=info["source"], role=info["role"], labels=info["labels"],
        )

    @_reads
    def read_batch(self, clips: Sequence[str | int], dtype: torch.dtype = torch.float32, device=None) -> ClipBatch:
        """Several clips of one skeleton as a padded :class:`ClipBatch`."""
        if len(clips) == 0:
            raise DatabaseError(f"{self.path}: an empty batch was asked for")
        idx = [self.index(c) for c in clips]
        self._require_flushed(max(idx))
        col = self.h5["clips"]
        sk_ids = col["skeleton"][()][idx]
        if len(set(sk_ids.tolist())) != 1:
            raise DatabaseError(f"{self.path}: clips of one batch must share a skeleton, got skeletons {sorted(set(sk_ids.tolist()))}")
        k = int(sk_ids[0])
        starts = col["start"][()][idx].astype(np.int64)
        lengths = col["length"][()][idx].astype(np.int64)
        g = self.h5[f"skeletons/{k}"]
        lo, hi = int(starts.min()), int((starts + lengths).max())
        T = int(lengths.max())
        # one contiguous read when the clips are close together, else one read per clip
        contiguous = hi - lo <= 2 * int(lengths.sum())
        rows = starts[:, None] + np.minimum(np.arange(T)[None, :], lengths[:, None] - 1)  # edge padding

        def gather(name):
            ds = g[name]
            with self._frames(k, idx):
                if contiguous:
                    block = ds[lo:hi]
                    out = block[rows - lo]
                else:
                    out = np.stack([ds[s:s + n][np.minimum(np.arange(T), n - 1)] for s, n in zip(starts, lengths)])
            return torch.from_numpy(out).to(device=device, dtype=dtype)

        lengths_t = torch.from_numpy(lengths).to(device)
        all_names = self.names
        return ClipBatch(
            rotations=gather("rotations"),
            root_translation=gather("root_translation"),
            translations=gather("translations") if "translations" in g else None,
            lengths=lengths_t,
            mask=torch.arange(T, device=device)[None, :] < lengths_t[:, None],
            fps=torch.from_numpy(col["fps"][()][idx]).to(device),
            names=[all_names[i] for i in idx],
            indices=idx,
            skeleton=self._skeletons[k],
        )

    @_reads
    def read_all(self, dtype: torch.dtype = torch.float32) -> Iterator[tuple[Motion, dict, dict]]:
        """Every clip in row order as ``(motion, extra columns, per-frame columns)``.

        Reads each dataset of the file once, whole: meant for small databases (the splice
        job's parts); use :meth:`read` or :meth:`batches` on large ones.
        """
        t = self.table()
        frames: dict[int, dict[str, np.ndarray]] = {}
        for i in range(len(t["name"])):
            k = int(t["skeleton"][i])
            if k not in frames:
                g = self.h5[f"skeletons/{k}"]
                with self._frames(k):
                    frames[k] = {n: g[n][()] for n in ("rotations", "root_translation", "translations", *self.frame_columns) if n in g}
            f, s, n = frames[k], int(t["start"][i]), int(t["length"][i])

            def get(name):
                return torch.from_numpy(f[name][s:s + n]).to(dtype)

            motion = Motion(self._skeletons[k], get("rotations"), get("root_translation"), float(t["fps"][i]),
                            get("translations") if "translations" in f else None, name=str(t["name"][i]),
                            source=str(t["source"][i]), role=str(t["role"][i]), labels=self._labels(t["labels"][i], t["name"][i]))
            extra = {c: _json_value(t[c][i]) for c in self.columns}
            yield motion, extra, {c: f[c][s:s + n] for c in self.frame_columns}

    @_reads
    def batches(self, clips: Sequence[str | int] | None = None, batch_size: int = 32,
                dtype: torch.dtype = torch.float32, device=None, sort_by_length: bool = False) -> Iterator[ClipBatch]:
        """Iterate padded batches of up to ``batch_size`` clips, each batch on one skeleton.

        ``clips`` defaults to every clip in row order; ``sort_by_length`` groups clips of
        similar length to reduce padding.
        """
        self.flush()
        idx = [self.index(c) for c in clips] if clips is not None else list(range(len(self)))
        col = self.h5["clips"]
        sk = col["skeleton"][()]
        length = col["length"][()]
        for k in sorted(set(sk[idx].tolist())):
            group = [i for i in idx if sk[i] == k]
            if sort_by_length:
                group.sort(key=lambda i: int(length[i]))
            for b in range(0, len(group), batch_size):
                yield self.read_batch(group[b:b + batch_size], dtype=dtype, device=device)

    @_reads
    def summary(self) -> dict:
        """A JSON-ready description: file attributes, skeletons, roles, every clip and, for a
        database written by ``splice-all``, its run record ``run`` (tool version, command,
        settings, inputs, time; ``None`` otherwise)."""
        t = self.table()
        clips = [
            {"name": str(t["name"][i]), "frames": int(t["length"][i]), "fps": float(t["fps"][i]),
             "duration_s": round(float(t["length"][i] / t["fps"][i]), 3), "role": str(t["role"][i]),
             "labels": self._labels(t["labels"][i], t["name"][i]), "skeleton": int(t["skeleton"][i]),
             "source": str(t["source"][i]),
             **{n: _json_value(t[n][i]) for n in self.columns}}
            for i in range(len(t["name"]))
        ]
        roles: dict[str, int] = {}
        for c in clips:
            roles[c["role"] or "(none)"] = roles.get(c["role"] or "(none)", 0) + 1
        skeletons = []
        for k, sk in enumerate(self._skeletons):
            spec = json.loads(self.spec_json(k) or "{}")
            skeletons.append({"id": k, "joints": sk.num_joints, "root": sk.names[0],
                              "spec": spec.get("name", "") if isinstance(spec, dict) else "",
                              "clips": sum(c["skeleton"] == k for c in clips), "joint_names": list(sk.names),
                              "units": str(self.h5[f"skeletons/{k}"].attrs.get("units", "")),
                              "up_axis": str(self.h5[f"skeletons/{k}"].attrs.get("up_axis", "")),
                              "guessed_roles": (spec.get("guessed") or {}) if isinstance(spec, dict) else {}})
        attrs = self.attrs
        return {
            "path": str(self.path), "format": attrs.get("format"), "schema_version": int(attrs.get("schema_version", 0)),
            "quaternion_order": attrs.get("quaternion_order"), "units": attrs.get("units"), "up_axis": attrs.get("up_axis"),
            "created_by": attrs.get("created_by"), "num_clips": len(clips),
            "num_frames": int(sum(c["frames"] for c in clips)),
            "duration_s": round(sum(c["duration_s"] for c in clips), 3),
            "roles": roles, "skeletons": skeletons, "clips": clips, "run": _run_record(attrs.get("run")),
        }

    def __repr__(self) -> str:
        state = "closed" if self._h5 is None else self.mode
        return f"MotionDatabase({str(self.path)!r}, {state})"

