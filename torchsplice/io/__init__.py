"""The names ``torchsplice.io`` gave before the layout split, kept for users' code: BVH reading
and writing now live in :mod:`torchsplice.formats`, the database in :mod:`torchsplice.store`."""

from ..formats.bvh import format_bvh, parse_bvh, read_bvh, write_bvh
from ..store.database import ClipBatch, MotionDatabase

__all__ = ["read_bvh", "parse_bvh", "write_bvh", "format_bvh", "MotionDatabase", "ClipBatch"]
