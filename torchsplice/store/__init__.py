"""Storage: the HDF5 motion database, its locks and atomic writes.

This package is the only one that opens HDF5 files or knows the paths inside them; every
other layer reads and writes clips through :class:`~torchsplice.store.database.MotionDatabase`.
"""

from .database import ClipBatch, MotionDatabase

__all__ = ["MotionDatabase", "ClipBatch"]
