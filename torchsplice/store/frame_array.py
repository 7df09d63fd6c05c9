"""Rows of stored frames, read with damage as one line: :class:`FrameArray` (one per-frame
array of one skeleton), :func:`reads` (the guard on every read method of a motion database) and
:func:`virtual_files` (the files a database's virtual datasets point into).
"""

from __future__ import annotations

import functools
import inspect
from pathlib import Path
from typing import Any, Callable, TypeVar, cast

import h5py
import numpy as np

from ..core.errors import DatabaseError
from ..core.ranges import ranges_to_rows
from .schema import SKELETONS, short

__all__ = ["FrameArray", "reads", "virtual_files"]

Method = TypeVar("Method", bound=Callable[..., Any])


def reads(method: Method) -> Method:
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

        return cast(Method, generator)  # wraps: the method's own signature

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except OSError as exc:
            raise self._unreadable(exc, "the file") from None

    return cast(Method, wrapper)


class FrameArray:
    """Rows of one per-frame array of one skeleton (``rotations``, ``root_translation``,
    ``translations`` or a per-frame column), read from the open file as numpy arrays.

    ``array[lo:hi]`` reads rows ``lo:hi``; :meth:`gather` the rows of several clips at once.
    A damaged chunk is one :class:`DatabaseError` line naming the file, the array and the rows.
    """

    def __init__(self, dataset: h5py.Dataset):
        self._ds = dataset

    @property
    def shape(self) -> tuple[int, ...]:
        return self._ds.shape

    @property
    def dtype(self) -> np.dtype:
        return self._ds.dtype

    def __len__(self) -> int:
        return self._ds.shape[0]

    def __getitem__(self, rows: slice) -> np.ndarray:
        """Rows ``rows`` (a slice)."""
        try:
            return self._ds[rows]
        except OSError as exc:
            raise self._damaged(rows.start, rows.stop, exc) from None

    def gather(self, starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """Rows ``start:start+length`` for several clips, concatenated.

        One read of the covering span when the clips lie close together, else one read per clip.
        """
        ds = self._ds
        if len(starts) == 0:
            return ds[0:0]
        lo, hi = int(starts.min()), int((starts + lengths).max())
        total = int(lengths.sum())
        try:
            if hi - lo <= 2 * total:
                block = ds[lo:hi]
                rel = ranges_to_rows(starts - lo, lengths)
                return block[rel]
            return np.concatenate([ds[int(s) : int(s + n)] for s, n in zip(starts, lengths)])
        except OSError as exc:  # a damaged chunk: one clear line, not HDF5's traceback
            raise self._damaged(lo, hi, exc) from None

    def _damaged(self, lo, hi, exc: OSError) -> DatabaseError:
        ds = self._ds
        return DatabaseError(
            f"{ds.file.filename}: damaged database: cannot read {ds.name} rows {lo}:{hi} ({short(exc)})"
        )


def virtual_files(path: Path) -> set[Path]:
    """The files whose frames the database at ``path`` reads through virtual datasets (see
    :meth:`~torchsplice.store.writing.Writing.append_virtual`); empty for a database holding
    its own frames, and for a file that is not there or not readable."""
    if not path.is_file():
        return set()
    files: set[Path] = set()
    try:
        with h5py.File(path, "r") as f:
            for g in f[SKELETONS].values():
                for ds in g.values():
                    if isinstance(ds, h5py.Dataset) and ds.is_virtual:
                        files |= {
                            (path.parent / vs.file_name).resolve() for vs in ds.virtual_sources() if vs.file_name != "."
                        }
    except (OSError, KeyError, ValueError):
        return set()
    return files
