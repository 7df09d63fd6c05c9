"""Which clips a :class:`~torchsplice.data.dataset.MotionDataset` holds: ``clips`` (names, globs,
row numbers), ``where`` (column values, label keys, predicates), ``select`` (the job's selection
language) and ``split`` (train, val or test, by source clips), as boolean masks over a
database's :class:`~torchsplice.store.table.ClipTable`; :func:`selection_mask` is all of them."""

from __future__ import annotations

import fnmatch
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ..core.errors import TorchspliceError
from ..store import ClipTable
from ..store.schema import COLUMNS
from ..store.select import select_clips
from .errors import DatasetError
from .splits import SPLITS, table_splits

__all__ = ["clip_mask", "where_mask", "select_mask", "split_mask", "selection_mask"]


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


def select_mask(select: str | Sequence[str], table: ClipTable, path: Path) -> np.ndarray:
    """Boolean mask ``(C,)`` of the rows the job's selectors pick (:mod:`torchsplice.store.select`)."""
    try:
        rows = select_clips(table, select, "select", str(path))
    except TorchspliceError as exc:
        raise DatasetError(str(exc)) from None
    keep = np.zeros(len(table), dtype=bool)
    keep[rows] = True
    return keep


def split_mask(split: str, table: ClipTable, ratios: Sequence[float], seed: int) -> np.ndarray:
    """Boolean mask ``(C,)`` of the rows in ``split``, split by source clips over the whole
    database (:mod:`torchsplice.data.splits`): no action or locomotion in two splits."""
    if split not in SPLITS:
        raise DatasetError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    return np.asarray(table_splits(table, ratios, seed)) == split


def selection_mask(table: ClipTable, path: Path, frame_columns: Sequence[str], *,
                   clips: Iterable[str | int] | None = None, where: Mapping[str, Any] | None = None,
                   select: str | Sequence[str] | None = None, split: str | None = None,
                   split_ratios: Sequence[float] = (0.8, 0.1, 0.1), split_seed: int = 0) -> np.ndarray:
    """Boolean mask ``(C,)`` of the rows that pass every one given of ``clips``, ``where``,
    ``select`` and ``split`` (see :class:`~torchsplice.data.dataset.MotionDataset`); a selection
    that keeps no clip is a :class:`DatasetError` naming the file and the selection."""
    keep = np.ones(len(table), dtype=bool)
    if clips is not None:
        keep &= clip_mask(clips, table.name, path)
    if where:
        keep &= where_mask(where, table, frame_columns, path)
    if select is not None:
        keep &= select_mask(select, table, path)
    if split is not None:
        keep &= split_mask(split, table, split_ratios, split_seed)
    if not keep.any():
        raise DatasetError(
            f"{path}: no clip is selected (of {len(keep)}) by clips={clips!r}, where={dict(where or {})!r}"
            + (f", select={select!r}" if select is not None else "") + (f", split={split!r}" if split else ""))
    return keep
