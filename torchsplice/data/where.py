"""Which clips a :class:`~torchsplice.data.dataset.MotionDataset` holds: ``clips`` (names, globs,
row numbers) and ``where`` (column values, label keys, predicates), as boolean masks over a
database's :class:`~torchsplice.store.table.ClipTable`."""

from __future__ import annotations

import fnmatch
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ..store import ClipTable
from ..store.schema import COLUMNS
from .errors import DatasetError

__all__ = ["clip_mask", "where_mask"]


def _is_glob(s: str) -> bool:
    return any(ch in s for ch in "*?[")


def clip_mask(clips: Iterable[str | int], names: np.ndarray, path: Path) -> np.ndarray:
    """Boolean mask ``(C,)`` of the rows named by ``clips`` (names, shell globs or row numbers)."""
    C = len(names)
    keep = np.zeros(C, dtype=bool)
    index = None
    for c in ([clips] if isinstance(clips, str) else clips):
        if isinstance(c, (int, np.integer)):
            if not -C <= int(c) < C:
                raise DatasetError(f"{path}: no clip number {int(c)} (the database has {C})")
            keep[int(c)] = True
        elif isinstance(c, str) and _is_glob(c):
            hit = np.fromiter((fnmatch.fnmatchcase(n, c) for n in names), dtype=bool, count=C)
            if not hit.any():
                raise DatasetError(f"{path}: no clip name matches the pattern {c!r}")
            keep |= hit
        elif isinstance(c, str):
            if index is None:
                index = {n: i for i, n in enumerate(names)}
            if c not in index:
                close = [n for n in names if c.lower() in n.lower()][:5]
                hint = f"; similar: {', '.join(close)}" if close else ""
                raise DatasetError(f"{path}: no clip named {c!r}{hint}")
            keep[index[c]] = True
        else:
            raise TypeError(f"clips must hold clip names, shell patterns or row numbers, got {c!r}")
    return keep


def _matcher(want) -> Callable[[Any], bool]:
    """A predicate on one clip's value from a ``where`` entry (a callable, a collection or a value)."""
    if callable(want):
        return lambda v: bool(want(v))
    if isinstance(want, (list, tuple, set, frozenset, np.ndarray)):
        accepted = list(want)
        return lambda v: any(v == a for a in accepted)
    return lambda v: v == want


def where_mask(where: Mapping[str, Any], table: ClipTable, frame_columns: Sequence[str], path: Path) -> np.ndarray:
    """Boolean mask ``(C,)`` of the rows whose metadata satisfy every entry of ``where``."""
    C = len(table)
    keep = np.ones(C, dtype=bool)
    known = [*COLUMNS, *table.kinds]
    for key, want in where.items():
        if not isinstance(key, str):
            raise TypeError(f"where keys must be column names, got {key!r}")
        if key.startswith("labels."):
            label = key[len("labels."):]
            values = [lab.get(label) for lab in table.labels]
        elif key == "labels":
            values = list(table.labels)
        elif key in known:
            values = table.column(key).tolist()
        else:
            extra = f"; {key!r} is a per-frame column (a feature, not a filter)" if key in frame_columns else ""
            raise DatasetError(
                f"{path}: no column {key!r} to filter on{extra}; columns: {', '.join(known)}, "
                f"and labels.KEY for any label")
        match = _matcher(want)
        keep &= np.fromiter((match(v) for v in values), dtype=bool, count=C)
    return keep
