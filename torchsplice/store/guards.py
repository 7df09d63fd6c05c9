"""Guards and value checks for the writes of a motion database (:mod:`torchsplice.store.writing`).

HDF5 failing to write (a full disk, an I/O error) is told apart from a bug (:func:`io_failure`,
:func:`no_space`) and turned into one :class:`~torchsplice.core.errors.DatabaseError` line
(:func:`guarded`); the values a write is given are checked and shaped here (:func:`frame_values`,
:func:`per_clip`, :func:`column_array`).
"""

from __future__ import annotations

import errno
import functools
from typing import Any, Callable, TypeVar, cast

import h5py
import numpy as np
import torch

from ..core.errors import DatabaseError
from .schema import COLUMNS, KINDS, STR

__all__ = [
    "io_failure",
    "no_space",
    "mb",
    "guarded",
    "column_array",
    "dataset_compression",
    "frame_values",
    "grow_rows",
    "growing_datasets",
    "per_clip",
]

Method = TypeVar("Method", bound=Callable[..., Any])


def io_failure(exc: BaseException) -> bool:
    """Whether ``exc`` is HDF5 failing to write the file (a full disk, an I/O error), not a bug."""
    if isinstance(exc, OSError):
        return True
    text = str(exc)
    return isinstance(exc, RuntimeError) and ("write failed" in text or "errno" in text or "flush" in text)


def no_space(exc: BaseException) -> bool:
    text = str(exc)
    return getattr(exc, "errno", None) == errno.ENOSPC or "No space left" in text or "errno = 28" in text


def mb(n: float) -> str:
    return f"{n / 1e6:,.1f} MB" if n < 1e9 else f"{n / 1e9:,.2f} GB"


def guarded(method: Method) -> Method:
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
            if not io_failure(exc) or self._tmp is None:
                raise
            raise DatabaseError(self._write_failed(exc)) from None

    return cast(Method, wrapper)  # wraps: the method's own signature


def column_array(columns: dict, name: str, values) -> np.ndarray:
    """Values of clip-table column ``name`` (built-in or one of ``columns``) as the array its dataset stores."""
    dt = COLUMNS.get(name) or KINDS[columns[name]][0]
    return np.array(values, dtype=object if dt is STR else dt)


def dataset_compression(policy: str | None, dataset: str) -> str | None:
    """The filter of one frame dataset under a file's compression policy (see :meth:`MotionDatabase.create`)."""
    if policy == "auto":
        return None if dataset == "rotations" else "lzf"
    return policy


def frame_values(values, T: int, column: str, clip: str) -> np.ndarray:
    """A per-frame column's ``(T,)`` float32 values for one clip (NaN when not given)."""
    if values is None:
        return np.full(T, np.nan, dtype=np.float32)
    a = (values.detach().cpu().numpy() if isinstance(values, torch.Tensor) else np.asarray(values)).astype(np.float32)
    if a.shape != (T,):
        raise DatabaseError(f"clip {clip!r}: column {column!r} needs {T} values, got shape {a.shape}")
    return a


def growing_datasets(g: h5py.Group) -> dict[str, h5py.Dataset]:
    """Name -> dataset of the skeleton group ``g`` that grows with its frames: every per-frame
    array, frames and parts alike. (A writer finds them once, not at every append: opening every
    member of the group to test it cost a job of short clips 6% of its writer's time.)"""
    datasets = {n: g[n] for n in g}
    return {n: d for n, d in datasets.items() if isinstance(d, h5py.Dataset) and d.maxshape and d.maxshape[0] is None}


def grow_rows(datasets, n: int) -> None:
    """Give every per-frame dataset of a skeleton group (``datasets``: those that grow with its
    frames) ``n`` rows: those a write did not fill (an alignment store's parts beside stored
    frames, and the reverse) are left unwritten, which HDF5 stores as nothing."""
    for ds in datasets:
        if ds.shape[0] < n:
            ds.resize(n, axis=0)


def per_clip(v, C: int, what: str, path) -> list:
    """One value for every one of ``C`` clips (``v`` repeated), or ``C`` values (a sequence or a
    tensor); one clear error naming ``what`` otherwise."""
    if isinstance(v, (str, bytes, int, float, np.generic)):
        return [v] * C
    out = list(v.detach().cpu().numpy() if isinstance(v, torch.Tensor) else v)
    if len(out) != C:
        raise DatabaseError(f"{path}: {what} needs {C} values, got {len(out)}")
    return out
