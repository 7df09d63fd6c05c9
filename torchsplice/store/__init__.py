"""Storage: the HDF5 motion database, its locks and atomic writes.

This package is the only one that opens HDF5 files or knows the paths inside them; every
other layer reads and writes clips through :class:`~torchsplice.store.database.MotionDatabase`
(its clip table typed as :class:`~torchsplice.store.table.ClipTable`, what it records with
each skeleton as :class:`~torchsplice.store.table.SkeletonInfo`, rows of a stored per-frame
array as :class:`~torchsplice.store.frame_array.FrameArray`).

Modules: :mod:`.schema` (the file's layout, described once), :mod:`.checks` (its structure,
checked on open), :mod:`.table` (the typed clip table), :mod:`.reading` and :mod:`.writing`
(the two halves of the database), :mod:`.database` (opening, creating, resuming, closing),
:mod:`.resumable` (files written across runs), :mod:`.lock` and :mod:`.atomic` (one writer
at a time, outputs that appear whole), :mod:`.state` (the database's state, declared once for
its mixins' type checks), :mod:`.defaults` (the compressions, torch-free).

The names below are imported on first use, so that :mod:`.defaults` is read without h5py.
"""

from typing import TYPE_CHECKING

from ..core.lazy import lazy_names

if TYPE_CHECKING:  # pragma: no cover
    from .database import ClipBatch, MotionDatabase
    from .reading import FrameArray
    from .table import ClipTable, SkeletonInfo

__all__ = ["MotionDatabase", "ClipBatch", "ClipTable", "SkeletonInfo", "FrameArray"]

__getattr__, __dir__ = lazy_names(
    __name__,
    {
        "MotionDatabase": ".database",
        "ClipBatch": ".database",
        "ClipTable": ".table",
        "SkeletonInfo": ".table",
        "FrameArray": ".reading",
    },
)
