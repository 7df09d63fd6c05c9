"""The HDF5 motion database: any number of clips on one or more skeletons, in one file.

Layout (schema version 1; readable with plain h5py, see ``datasets_spec/README.md`` and the
project README for a ten-line example)::

    /                       attrs: format="torchsplice.motiondb", schema_version=1,
                                   quaternion_order="wxyz", units, up_axis, created_by
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
"""

from __future__ import annotations

import difflib
import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

import h5py
import numpy as np
import torch

from .. import __version__
from ..core.errors import DatabaseError
from ..core.motion import Motion
from ..core.skeleton import Skeleton
from .atomic import os_error_message
from .lock import host_pid

__all__ = ["MotionDatabase", "ClipBatch", "SCHEMA_VERSION", "FORMAT", "COMPRESSIONS"]

FORMAT = "torchsplice.motiondb"
SCHEMA_VERSION = 1
_STR = h5py.string_dtype()
_COLUMNS = {  # name: (dtype, numpy fill for an empty table)
    "name": _STR, "source": _STR, "role": _STR, "labels": _STR,
    "skeleton": np.int32, "start": np.int64, "length": np.int64, "fps": np.float64,
}
_FLUSH_FRAMES = 1 << 16
COMPRESSIONS = ("gzip", "lzf", "auto", None)


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


def _skeleton_from_group(g: h5py.Group) -> Skeleton:
    return Skeleton(
        names=[s for s in g["names"].asstr()[()]],
        parents=g["parents"][()].tolist(),
        offsets=torch.from_numpy(g["offsets"][()]),
        channels=[c.split() for c in g["channels"].asstr()[()]],
        end_site_parents=g["end_site_parents"][()].tolist(),
        end_site_offsets=torch.from_numpy(g["end_site_offsets"][()]),
    )


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

    def __init__(self, path: Path, h5: h5py.File, mode: str, tmp: Path | None, dtype):
        self.path, self._h5, self.mode, self._tmp, self._dtype = path, h5, mode, tmp, dtype
        self._skeletons = [_skeleton_from_group(h5["skeletons"][k]) for k in sorted(h5["skeletons"], key=int)]
        self._names: list[str] | None = None
        self._name_index: dict[str, int] | None = None
        self._flushed = h5["clips/name"].shape[0]
        extra = json.loads(str(h5.attrs.get("extra_columns", "")) or "{}")
        self.columns: dict[str, str] = dict(extra.get("clip", {}))
        self.frame_columns: tuple[str, ...] = tuple(extra.get("frame", ()))
        self._staged: list[tuple] = []
        self._staged_frames = 0
        self._skeleton_ids: dict[int, tuple[Skeleton, int]] = {}  # id -> (object kept alive, row)
        self._virtual: dict[int, list[tuple[str, int]]] = {}  # skeleton -> (source file, frames) in order

    # -- opening and closing ------------------------------------------------------------------
    @classmethod
    def create(cls, path, overwrite: bool = False, dtype=np.float32, chunk_frames: int = 1024,
               compression: str | None = "gzip", columns: dict[str, str] | None = None,
               frame_columns: tuple[str, ...] = (), attrs: dict | None = None) -> "MotionDatabase":
        """Start a new database that appears at ``path`` when closed.

        Frames are stored as ``dtype`` (float32 by default) in chunks of ``chunk_frames``,
        compressed with ``compression``: ``"gzip"`` (readable by every HDF5 tool), ``"lzf"``
        (several times faster, read by h5py), ``"auto"`` (LZF, except for rotations, which are
        stored raw: LZF shrinks float quaternions by only about 15% at a large cost in time,
        while it shrinks translations about tenfold), or ``None``. Every dataset is shuffled
        before compression.
        ``columns`` declares extra per-clip columns (name -> ``"str"``, ``"float"`` or ``"int"``),
        ``frame_columns`` extra per-frame float32 columns; ``attrs`` are extra root attributes.
        """
        columns = dict(columns or {})
        bad = [c for c in list(columns) + list(frame_columns)
               if c in _COLUMNS or c in ("rotations", "root_translation", "translations") or not c.isidentifier()]
        if bad or any(k not in _KINDS for k in columns.values()):
            raise ValueError(f"bad extra columns {bad or columns}")
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {COMPRESSIONS}, got {compression!r}")
        path = Path(path)
        if path.exists() and not overwrite:
            raise DatabaseError(f"{path}: already exists (use --force to overwrite)")
        if not path.parent.exists():
            raise DatabaseError(f"{path}: folder {path.parent} does not exist")
        tmp = path.with_name(f".{path.name}.partial-{host_pid()}")
        try:
            h5 = h5py.File(tmp, "w")
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
            raise DatabaseError(os_error_message(path, exc)) from None
        return cls(path, h5, "w", tmp, np.dtype(dtype))

    @classmethod
    def open(cls, path, mode: str = "r") -> "MotionDatabase":
        """Open an existing database, ``mode`` ``"r"`` (read) or ``"a"`` (append).

        Appending works on a copy beside the file that replaces it on a clean close.
        """
        path = Path(path)
        if mode not in ("r", "a"):
            raise ValueError(f"mode must be 'r' or 'a', got {mode!r}")
        if not path.is_file():
            raise DatabaseError(f"{path}: no such file")
        if not h5py.is_hdf5(path):
            raise DatabaseError(f"{path}: not an HDF5 file")
        tmp = None
        try:
            if mode == "a":
                tmp = path.with_name(f".{path.name}.partial-{host_pid()}")
                shutil.copyfile(path, tmp)
            h5 = h5py.File(tmp or path, "r+" if mode == "a" else "r")
        except OSError as exc:
            if tmp is not None:
                tmp.unlink(missing_ok=True)
            raise DatabaseError(os_error_message(path, exc)) from None
        try:
            cls._check_header(path, h5)
        except DatabaseError:
            h5.close()
            if tmp is not None:
                tmp.unlink(missing_ok=True)
            raise
        dtype = h5["skeletons/0/rotations"].dtype if "0" in h5["skeletons"] else np.dtype(np.float32)
        return cls(path, h5, mode, tmp, dtype)

    @staticmethod
    def _check_header(path: Path, h5: h5py.File) -> None:
        if h5.attrs.get("format") != FORMAT:
            raise DatabaseError(f"{path}: not a torchsplice motion database (no format attribute {FORMAT!r})")
        version = int(h5.attrs.get("schema_version", -1))
        if version > SCHEMA_VERSION:
            raise DatabaseError(f"{path}: schema version {version} is newer than this torchsplice reads ({SCHEMA_VERSION}); upgrade torchsplice")
        if version < 1 or "skeletons" not in h5 or "clips" not in h5:
            raise DatabaseError(f"{path}: damaged database (schema version {version}, missing groups)")

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
            self._build_virtual()
            self._h5.close()
            self._h5 = None
            os.replace(self._tmp, self.path)
        except OSError as exc:
            self.abort()
            raise DatabaseError(os_error_message(self.path, exc)) from None
        except BaseException:
            self.abort()
            raise

    def abort(self) -> None:
        """Discard a write in progress: the file at ``path`` stays as it was."""
        if self._h5 is not None:
            try:
                self._h5.close()
            except Exception:
                pass
            self._h5 = None
        if self._tmp is not None:
            self._tmp.unlink(missing_ok=True)

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

    @property
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

    def clip_info(self, clip: str | int) -> dict:
        """Metadata of one clip: name, source, role, labels, skeleton, start, length, fps."""
        i = self.index(clip)
        self._require_flushed(i)
        c = self.h5["clips"]
        info = {k: c[k][i] for k in [*_COLUMNS, *self.columns]}
        for k in ("name", "source", "role", "labels", *[n for n, kind in self.columns.items() if kind == "str"]):
            info[k] = info[k].decode() if isinstance(info[k], bytes) else str(info[k])
        for n, kind in self.columns.items():
            info[n] = float(info[n]) if kind == "float" else int(info[n]) if kind == "int" else info[n]
        info["labels"] = json.loads(info["labels"] or "{}")
        for k in ("skeleton", "start", "length"):
            info[k] = int(info[k])
        info["fps"] = float(info["fps"])
        return info

    def table(self) -> dict[str, np.ndarray]:
        """Every metadata column, extra ones too, as an array (labels as JSON strings)."""
        self.flush()
        c = self.h5["clips"]
        return {k: (c[k].asstr()[()] if c[k].dtype == object else c[k][()]) for k in [*_COLUMNS, *self.columns]}

    def read_frame_column(self, clip: str | int, name: str) -> np.ndarray:
        """A clip's values ``(T,)`` of the per-frame column ``name``."""
        if name not in self.frame_columns:
            raise DatabaseError(f"{self.path}: no per-frame column {name!r} (has: {', '.join(self.frame_columns) or 'none'})")
        info = self.clip_info(clip)
        return self.h5[f"skeletons/{info['skeleton']}/{name}"][info["start"]:info["start"] + info["length"]]

    def _require_flushed(self, i: int) -> None:
        if i >= self._flushed:
            self.flush()

    # -- writing ------------------------------------------------------------------------------
    def _writable(self) -> None:
        if self.mode == "r":
            raise DatabaseError(f"{self.path}: opened read-only")

    def add_skeleton(self, skeleton: Skeleton, spec=None) -> int:
        """Index of a stored skeleton that matches ``skeleton``, storing it if none does.

        ``spec`` (a :class:`~torchsplice.io.spec.DatasetSpec` or ``None``) is stored with a new
        skeleton; its units and up axis must agree with the database's.
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
        for key, value in (("units", units), ("up_axis", up)):
            have = str(self.h5.attrs.get(key, ""))
            if value and have and have != value:
                raise DatabaseError(f"{self.path}: database {key} is {have!r}, the new skeleton's spec says {value!r}")
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
        c = self.h5["clips"]
        n0, m0 = g["rotations"].shape[0], c["name"].shape[0]
        rows["skeleton"], rows["start"] = [k] * C, n0 + starts
        try:
            for name, a in arrays.items():
                ds = g[name]
                ds.resize(n0 + N, axis=0)
                ds[n0:] = a.astype(ds.dtype, copy=False)
            for name, values in rows.items():
                dt = _COLUMNS.get(name) or _KINDS[self.columns[name]][0]
                c[name].resize(m0 + C, axis=0)
                c[name][m0:] = np.array(values, dtype=object if dt is _STR else dt)
        except BaseException as exc:
            try:  # leave the file as it was before the call: no half-written rows
                for name in arrays:
                    g[name].resize(n0, axis=0)
                for name in rows:
                    c[name].resize(m0, axis=0)
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
        rel = os.path.relpath(Path(refer_as or source).resolve(), self._tmp.resolve().parent)
        self._append_rows(k, n0, lengths, names, fps, sources, roles, labels, extra or {})
        parts.append((rel, N))

    def _append_rows(self, k: int, n0: int, lengths, names, fps, sources, roles, labels, extra: dict) -> None:
        """Table rows of ``C`` clips of skeleton ``k`` whose frames start at row ``n0``."""
        C = len(names)
        index = self._index_map()
        clash = [n for n in names if n in index] or ([n for n in names if names.count(n) > 1][:1] if len(set(names)) < C else [])
        if clash:
            raise DatabaseError(f"{self.path}: a clip named {clash[0]!r} is already in the database")

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
        c = self.h5["clips"]
        m0 = c["name"].shape[0]
        try:
            for name, values in rows.items():
                dt = _COLUMNS.get(name) or _KINDS[self.columns[name]][0]
                c[name].resize(m0 + C, axis=0)
                c[name][m0:] = np.array(values, dtype=object if dt is _STR else dt)
        except BaseException as exc:
            for name in rows:
                c[name].resize(m0, axis=0)
            if isinstance(exc, OSError):
                raise DatabaseError(os_error_message(self.path, exc)) from None
            raise
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

    def packed(self, skeleton: int = 0) -> dict[str, np.ndarray]:
        """Every frame of skeleton ``k`` as whole arrays: ``rotations``, ``root_translation``,
        ``translations`` (when stored) and the per-frame columns, rows as in the file (read at
        once: meant for a splice job's parts and other small files)."""
        g = self.h5[f"skeletons/{skeleton}"]
        return {n: g[n][()] for n in ("rotations", "root_translation", "translations", *self.frame_columns) if n in g}

    def flush(self) -> None:
        """Write buffered clips to the file."""
        if not self._staged:
            return
        try:
            self._write_staged()
        except OSError as exc:
            raise DatabaseError(os_error_message(self.path, exc)) from None
        if self._names is not None:
            self._names += [m.name for m, *_ in self._staged]
        self._flushed += len(self._staged)
        self._staged, self._staged_frames = [], 0

    def _no_virtual(self, k: int) -> None:
        if k in self._virtual:
            raise DatabaseError(f"{self.path}: skeleton {k} holds virtual frames; real frames cannot be added to it")

    def _write_staged(self) -> None:
        h5 = self.h5
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
        c = h5["clips"]
        n = c["name"].shape[0]
        for name, values in rows.items():
            dt = _COLUMNS.get(name) or _KINDS[self.columns[name]][0]
            c[name].resize(n + len(values), axis=0)
            c[name][n:] = np.array(values, dtype=object if dt is _STR else dt)

    # -- reading ------------------------------------------------------------------------------
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
                blocks[k] = (lo, {n: g[n][lo:hi] for n in ("rotations", "root_translation", "translations") if n in g})
        out = []
        for i in idx:
            k, s, n = int(t["skeleton"][i]), int(t["start"][i]), int(t["length"][i])
            g = self.h5[f"skeletons/{k}"]
            lo, block = blocks.get(k, (0, None))

            def get(name):
                a = block[name][s - lo:s - lo + n] if block is not None else g[name][s:s + n]
                return torch.from_numpy(np.ascontiguousarray(a)).to(dtype)

            out.append(Motion(
                skeleton=self._skeletons[k], rotations=get("rotations"), root_translation=get("root_translation"),
                translations=get("translations") if "translations" in g else None, fps=float(t["fps"][i]),
                name=str(t["name"][i]), source=str(t["source"][i]), role=str(t["role"][i]),
                labels=json.loads(t["labels"][i] or "{}"),
            ))
        return out

    def read(self, clip: str | int, dtype: torch.dtype = torch.float32, device=None) -> Motion:
        """One clip as a :class:`Motion` (``dtype`` and ``device`` as asked)."""
        info = self.clip_info(clip)
        g = self.h5[f"skeletons/{info['skeleton']}"]
        s, n = info["start"], info["length"]

        def get(name):
            return torch.from_numpy(g[name][s:s + n]).to(device=device, dtype=dtype)

        return Motion(
            skeleton=self._skeletons[info["skeleton"]],
            rotations=get("rotations"),
            root_translation=get("root_translation"),
            translations=get("translations") if "translations" in g else None,
            fps=info["fps"], name=info["name"], source=info["source"], role=info["role"], labels=info["labels"],
        )

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
                frames[k] = {n: g[n][()] for n in ("rotations", "root_translation", "translations", *self.frame_columns) if n in g}
            f, s, n = frames[k], int(t["start"][i]), int(t["length"][i])

            def get(name):
                return torch.from_numpy(f[name][s:s + n]).to(dtype)

            motion = Motion(self._skeletons[k], get("rotations"), get("root_translation"), float(t["fps"][i]),
                            get("translations") if "translations" in f else None, name=str(t["name"][i]),
                            source=str(t["source"][i]), role=str(t["role"][i]), labels=json.loads(t["labels"][i] or "{}"))
            extra = {c: _json_value(t[c][i]) for c in self.columns}
            yield motion, extra, {c: f[c][s:s + n] for c in self.frame_columns}

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

    def summary(self) -> dict:
        """A JSON-ready description: file attributes, skeletons, roles and every clip."""
        t = self.table()
        clips = [
            {"name": str(t["name"][i]), "frames": int(t["length"][i]), "fps": float(t["fps"][i]),
             "duration_s": round(float(t["length"][i] / t["fps"][i]), 3), "role": str(t["role"][i]),
             "labels": json.loads(t["labels"][i] or "{}"), "skeleton": int(t["skeleton"][i]),
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
                              "clips": sum(c["skeleton"] == k for c in clips), "joint_names": list(sk.names)})
        attrs = self.attrs
        return {
            "path": str(self.path), "format": attrs.get("format"), "schema_version": int(attrs.get("schema_version", 0)),
            "quaternion_order": attrs.get("quaternion_order"), "units": attrs.get("units"), "up_axis": attrs.get("up_axis"),
            "created_by": attrs.get("created_by"), "num_clips": len(clips),
            "num_frames": int(sum(c["frames"] for c in clips)),
            "duration_s": round(sum(c["duration_s"] for c in clips), 3),
            "roles": roles, "skeletons": skeletons, "clips": clips,
        }

    def __repr__(self) -> str:
        state = "closed" if self._h5 is None else self.mode
        return f"MotionDatabase({str(self.path)!r}, {state})"

