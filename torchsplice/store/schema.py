"""The HDF5 layout of a motion database: the one description of it, its constants, and the
checked reading of its skeleton groups.

Layout (schema version 1; readable with plain h5py, see ``datasets_spec/README.md`` and
``docs/python.md``, "Reading a database without torchsplice", for a ten-line example)::

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
file holds 100,000 clips and more.

Conventions of this package (only :mod:`torchsplice.store` opens HDF5 files or knows these
paths): :func:`skeleton_path`, :data:`SKELETONS` and :data:`CLIPS` name the groups; a structural problem found
while reading is a :class:`Damage` (one line, without the file's name), which the database
turns into a :class:`~torchsplice.core.errors.DatabaseError` naming the file.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import torch

from ..core.errors import DatabaseError
from ..core.skeleton import Skeleton
from .defaults import COMPRESSIONS  # declared there, torch-free (the command line reads it)

__all__ = [
    "damaged_frame",
    "refuse_non_finite",
    "FORMAT",
    "SCHEMA_VERSION",
    "COMPRESSIONS",
    "MIXED",
    "STR",
    "COLUMNS",
    "KINDS",
    "FRAME_ARRAYS",
    "CLIPS",
    "SKELETONS",
    "skeleton_path",
    "Damage",
    "cap",
    "short",
    "checked_dataset",
    "skeleton_to_group",
    "skeleton_from_group",
    "text_attr",
    "extra_columns",
]

FORMAT = "torchsplice.motiondb"
SCHEMA_VERSION = 2
"""The newest schema this version reads: 1 for motion databases, 2 for alignment stores
(:mod:`torchsplice.store.assembly`), which older versions must refuse rather than misread."""
STR = h5py.string_dtype()
COLUMNS = {  # the built-in clip columns: name -> dtype
    "name": STR,
    "source": STR,
    "role": STR,
    "labels": STR,
    "skeleton": np.int32,
    "start": np.int64,
    "length": np.int64,
    "fps": np.float64,
}
MIXED = "mixed"  # the file's units or up axis when its skeletons differ in them
KINDS = {"str": (STR, ""), "float": (np.float64, np.nan), "int": (np.int64, -1)}
"""Kinds of extra clip columns: ``kind: (dtype, the value of a row that does not give one)``."""
FRAME_ARRAYS = ("rotations", "root_translation", "translations")
"""The frame datasets of a skeleton group (``translations`` only where stored)."""
CLIPS = "clips"
"""The clip table's group."""
SKELETONS = "skeletons"
"""The group of the skeleton groups."""


def skeleton_path(k: int) -> str:
    """The group of skeleton ``k``."""
    return f"{SKELETONS}/{k}"


def skeleton_to_group(g: h5py.Group, sk: Skeleton) -> None:
    g["names"] = np.array(sk.names, dtype=object).astype(STR)
    g["parents"] = np.array(sk.parents, dtype=np.int32)
    g["offsets"] = sk.offsets.numpy()
    g["channels"] = np.array([" ".join(c) for c in sk.channels], dtype=object).astype(STR)
    g["end_site_parents"] = np.array(sk.end_site_parents, dtype=np.int32)
    g["end_site_offsets"] = sk.end_site_offsets.numpy().reshape(-1, 3)


class Damage(Exception):
    """What is wrong with a database file's structure (one line, without the file's name)."""


def damaged_frame(db, row: int, clip, lengths, first, what: str) -> str:
    """The line that refuses packed row ``row`` of an alignment store's read (ranges of
    ``lengths`` frames, the ``first`` of each in table row ``clip``'s frames): the file, the
    clip, ``what`` is wrong and the clip's frame."""
    ends = np.cumsum(lengths)
    i = int(np.searchsorted(ends, row, side="right"))
    frame = int(first[i] + row - ends[i] + lengths[i])
    return f"{db.path}: damaged alignment store: clip {cap(db.names[int(clip[i])])} {what} at its frame {frame}"


def first_non_finite_row(a: np.ndarray) -> int | None:
    """The first row of ``a`` ``(N, ...)`` that holds a value which is not finite, or ``None``:
    one ``isfinite`` pass, its rows searched only where it finds one."""
    finite = np.isfinite(a)
    if finite.all():
        return None
    return int(np.flatnonzero(~finite.reshape(len(a), -1).all(1))[0])


def refuse_non_finite(db, arrays: dict, clip, lengths, first) -> None:
    """Refuse an alignment store's assembled ``arrays`` (name -> ``(N, ...)``, packed ranges as
    :func:`damaged_frame`'s) where a value is not finite (a damaged part): one
    :class:`~torchsplice.core.errors.DatabaseError` line (:func:`first_non_finite_row`)."""
    for name, a in arrays.items():
        bad = first_non_finite_row(a)
        if bad is not None:
            raise DatabaseError(damaged_frame(db, bad, clip, lengths, first, f"assembles to non-finite {name}"))


def cap(value, n: int = 40) -> str:
    """A value quoted for a one-line message: on one line, cut after ``n`` characters."""
    if isinstance(value, bytes):
        value = value.decode(errors="replace")
    text = " ".join(str(value).split())
    return repr(text if len(text) <= n else text[:n] + "...")


def short(exc: BaseException, n: int = 120) -> str:
    """The first line of an exception's message, at most ``n`` characters."""
    text = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    return text if len(text) <= n else text[:n] + "..."


def checked_dataset(g: h5py.Group, name: str, where: str, shape: tuple | None = None, kind: str = "") -> h5py.Dataset:
    """``g[name]``, checked: a dataset, of ``shape`` (``None`` entries: any size) and dtype
    ``kind`` (numpy kind letters, or ``"str"``); raises :class:`Damage` otherwise."""
    obj = g.get(name)
    if obj is None:
        raise Damage(f"{where}/{name} is missing")
    if not isinstance(obj, h5py.Dataset):
        raise Damage(f"{where}/{name} is not a dataset")
    if shape is not None and (
        len(obj.shape) != len(shape) or any(w is not None and s != w for s, w in zip(obj.shape, shape))
    ):
        want = "(" + ", ".join("N" if w is None else str(w) for w in shape) + ("," if len(shape) == 1 else "") + ")"
        raise Damage(f"{where}/{name} has shape {obj.shape}, expected {want}")
    if kind == "str" and h5py.check_string_dtype(obj.dtype) is None:
        raise Damage(f"{where}/{name} holds {obj.dtype}, not text")
    if kind and kind != "str" and obj.dtype.kind not in kind:
        raise Damage(f"{where}/{name} holds {obj.dtype}, expected {'whole numbers' if kind == 'iu' else 'numbers'}")
    return obj


def skeleton_from_group(g: h5py.Group, where: str = "skeleton") -> Skeleton:
    """The skeleton stored in ``g``; :class:`Damage` says what is wrong if it cannot be one."""
    names = checked_dataset(g, "names", where, (None,), "str")
    J = names.shape[0]
    E = checked_dataset(g, "end_site_parents", where, (None,), "iu").shape[0]
    offsets = checked_dataset(g, "offsets", where, (J, 3), "fiu")[()].astype(np.float64)
    ends = (
        checked_dataset(g, "end_site_offsets", where, (E, 3) if E else None, "fiu")[()]
        .astype(np.float64)
        .reshape(-1, 3)
    )
    if not (np.isfinite(offsets).all() and np.isfinite(ends).all()):
        raise Damage(f"{where} has non-finite offsets")
    try:
        return Skeleton(
            names=tuple(names.asstr()[()]),
            parents=checked_dataset(g, "parents", where, (J,), "iu")[()].tolist(),
            offsets=torch.from_numpy(offsets),
            channels=tuple(tuple(c.split()) for c in checked_dataset(g, "channels", where, (J,), "str").asstr()[()]),
            end_site_parents=g["end_site_parents"][()].tolist(),
            end_site_offsets=torch.from_numpy(ends),
        )
    except ValueError as exc:  # Skeleton's own checks: channels, parents, roots, End Sites
        raise Damage(f"{where}: {short(exc, 160)}") from None


def text_attr(attrs, key: str, where: str) -> str:
    """A text attribute (``""`` when absent)."""
    v = attrs.get(key, "")
    if isinstance(v, bytes):
        v = v.decode(errors="replace")
    if not isinstance(v, str):
        raise Damage(f"{where}{key} is not text ({cap(v)})")
    return v


def extra_columns(attrs) -> tuple[dict[str, str], tuple[str, ...]]:
    """The declared extra columns ``(clip name -> kind, frame names)`` of the root attribute."""
    text = text_attr(attrs, "extra_columns", "")
    try:
        extra = json.loads(text or "{}")
    except ValueError:
        raise Damage(f"extra_columns is not valid JSON ({cap(text)})") from None
    clip = extra.get("clip", {}) if isinstance(extra, dict) else None
    frame = extra.get("frame", []) if isinstance(extra, dict) else None
    if not isinstance(clip, dict) or not isinstance(frame, list):
        raise Damage(f"extra_columns is not an object of clip columns and frame columns ({cap(text)})")
    reserved = (*COLUMNS, *FRAME_ARRAYS)
    for name, kind in clip.items():
        if kind not in KINDS or name in reserved or not name.isidentifier():
            raise Damage(
                f"extra_columns declares clip column {cap(name)} of kind {cap(kind)} "
                f"(a column needs a new name and a kind of {', '.join(KINDS)})"
            )
    for name in frame:
        if not isinstance(name, str) or name in reserved or not name.isidentifier() or frame.count(name) > 1:
            raise Damage(f"extra_columns declares a bad frame column {cap(name)}")
    return dict(clip), tuple(frame)
