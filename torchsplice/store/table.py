"""The clip table as typed values: :class:`ClipTable` (every clip's metadata, labels decoded)
and :class:`SkeletonInfo` (what a database records with each skeleton).

A database's clip table is read once per open database (:meth:`MotionDatabase.clip_table
<torchsplice.store.database.MotionDatabase.clip_table>`, kept until clips are added): every
column a read-only array of ``C`` rows in row order, each distinct labels text decoded here
once (a row whose labels are not a JSON object is one
:class:`~torchsplice.core.errors.DatabaseError` naming the file and the clip).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from typing import Mapping, Sequence

import numpy as np

from ..core.errors import DatabaseError
from ..core.skeleton import Skeleton
from .schema import COLUMNS, cap

__all__ = ["ClipTable", "SkeletonInfo", "decode_labels", "run_record", "json_value"]


def decode_labels(path, text, clip) -> dict:
    """A clip's labels column (JSON text) as a dict; a :class:`DatabaseError` naming the file
    ``path`` and ``clip`` when it is not a JSON object."""
    try:
        labels = json.loads(text or "{}")
    except ValueError:
        labels = None
    if not isinstance(labels, dict):
        raise DatabaseError(
            f"{path}: damaged database: the labels of clip {cap(clip, 60)} are not a JSON object ({cap(text)})"
        )
    return labels


@dataclass(frozen=True, eq=False)
class ClipTable:
    """Every clip's metadata, one row per clip in row order (row ``i`` is clip number ``i``).

    Attributes:
        name, source, role: ``(C,)`` arrays of ``str``.
        labels: ``C`` dicts of string labels, decoded (each row its own dict).
        labels_json: ``(C,)`` the labels as stored (JSON text), for writers that copy rows.
        skeleton: ``(C,)`` int32, the skeleton id of each clip (see :meth:`SkeletonInfo`).
        start, length: ``(C,)`` int64: the clip's frames are rows ``start:start+length`` of
            its skeleton's frame arrays.
        fps: ``(C,)`` float64.
        extra: the declared extra columns, name -> ``(C,)`` array (``str``; ``float``, NaN
            where unset; ``int``, -1 where unset); ``kinds``: name -> ``"str"``, ``"float"``
            or ``"int"``.
    """

    name: np.ndarray
    source: np.ndarray
    role: np.ndarray
    labels: list[dict]
    labels_json: np.ndarray
    skeleton: np.ndarray
    start: np.ndarray
    length: np.ndarray
    fps: np.ndarray
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)
    kinds: Mapping[str, str] = field(default_factory=dict)

    @classmethod
    def from_columns(cls, columns: Mapping[str, np.ndarray], kinds: Mapping[str, str], path) -> "ClipTable":
        """The table of the stored ``columns`` (column -> array, labels as JSON text; see
        :data:`~torchsplice.store.schema.COLUMNS`); each distinct labels text is decoded once."""
        decoded: dict[str, dict] = {}
        labels = []
        for text, clip in zip(columns["labels"], columns["name"]):
            if text not in decoded:
                decoded[text] = decode_labels(path, text, clip)
                labels.append(decoded[text])
            else:
                labels.append(dict(decoded[text]))
        for array in columns.values():  # shared by every caller of a database's table
            array.setflags(write=False)
        return cls(
            name=columns["name"],
            source=columns["source"],
            role=columns["role"],
            labels=labels,
            labels_json=columns["labels"],
            skeleton=columns["skeleton"],
            start=columns["start"],
            length=columns["length"],
            fps=columns["fps"],
            extra={n: columns[n] for n in kinds},
            kinds=dict(kinds),
        )

    def __len__(self) -> int:
        return len(self.name)

    @cached_property
    def names(self) -> list[str]:
        """The clips' names as a list (made once)."""
        return [str(n) for n in self.name]

    def column(self, name: str) -> np.ndarray:
        """A column by name, built-in or extra (``labels``: as stored, JSON text)."""
        if name == "labels":
            return self.labels_json
        if name in COLUMNS:
            return getattr(self, name)
        if name in self.extra:
            return self.extra[name]
        raise KeyError(f"no clip column {name!r} (columns: {', '.join([*COLUMNS, *self.extra])})")

    def info(self, i: int) -> dict:
        """Row ``i`` as :meth:`~torchsplice.store.database.MotionDatabase.clip_info` gives it:
        built-in columns then the extra ones, as Python values (labels a fresh dict)."""
        out = {
            "name": str(self.name[i]),
            "source": str(self.source[i]),
            "role": str(self.role[i]),
            "labels": dict(self.labels[i]),
            "skeleton": int(self.skeleton[i]),
            "start": int(self.start[i]),
            "length": int(self.length[i]),
            "fps": float(self.fps[i]),
        }
        for n, kind in self.kinds.items():
            v = self.extra[n][i]
            out[n] = float(v) if kind == "float" else int(v) if kind == "int" else str(v)
        return out

    def to_dict(self) -> dict[str, np.ndarray]:
        """Every column by name, labels as stored (JSON text): what
        :meth:`~torchsplice.store.database.MotionDatabase.table` gives."""
        return {name: self.column(name) for name in [*COLUMNS, *self.extra]}

    def take(self, rows: Sequence[int] | np.ndarray) -> "ClipTable":
        """The table of ``rows`` only (row numbers, or a boolean mask), in that order."""
        rows = np.asarray(rows)
        rows = np.flatnonzero(rows) if rows.dtype == bool else rows.astype(np.intp)
        return ClipTable(
            name=self.name[rows],
            source=self.source[rows],
            role=self.role[rows],
            labels=[self.labels[int(i)] for i in rows],
            labels_json=self.labels_json[rows],
            skeleton=self.skeleton[rows],
            start=self.start[rows],
            length=self.length[rows],
            fps=self.fps[rows],
            extra={n: v[rows] for n, v in self.extra.items()},
            kinds=dict(self.kinds),
        )

    def captures(self) -> list[tuple[str, str, dict]]:
        """``(name, role, labels)`` of every clip: the candidates a reference or ground-truth
        search looks through (see :func:`~torchsplice.splice.references.find_reference`)."""
        return [(str(n), str(r), lab) for n, r, lab in zip(self.name, self.role, self.labels)]


@dataclass(frozen=True)
class SkeletonInfo:
    """What a database records with skeleton ``id`` beside the skeleton itself.

    Attributes:
        id: the skeleton's number in the database.
        skeleton: the :class:`~torchsplice.core.skeleton.Skeleton`.
        units, up_axis: as recorded with the skeleton (``""`` where not).
        spec_json: the stored dataset spec as JSON, ``""`` where none was stored.
        spec_name: that spec's name (``""`` where none).
        frame_arrays: the per-frame arrays stored for it, in order: ``rotations``,
            ``root_translation``, ``translations`` (where stored), the per-frame columns.
        dtype: the float type of its frames.
    """

    id: int
    skeleton: Skeleton
    units: str
    up_axis: str
    spec_json: str
    spec_name: str
    frame_arrays: tuple[str, ...]
    dtype: np.dtype


def run_record(text) -> dict | str | None:
    """The root attribute ``run`` (JSON written by ``splice-all``) as a dict; ``None`` when absent,
    the raw text when it is not a JSON object."""
    if text is None or str(text) == "":
        return None
    try:
        value = json.loads(str(text))
    except ValueError:
        return str(text)
    return value if isinstance(value, dict) else str(text)


def json_value(v):
    """A numpy scalar as a JSON-ready Python value (NaN as None)."""
    if isinstance(v, (str, bytes)):
        return v.decode() if isinstance(v, bytes) else v
    v = v.item() if hasattr(v, "item") else v
    return None if isinstance(v, float) and v != v else v
