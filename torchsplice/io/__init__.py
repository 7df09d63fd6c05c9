"""Data in and out: BVH files, the HDF5 motion database, dataset specs and the built-in sample."""

from .bvh import format_bvh, parse_bvh, read_bvh, write_bvh
from .database import ClipBatch, MotionDatabase

__all__ = ["read_bvh", "parse_bvh", "write_bvh", "format_bvh", "MotionDatabase", "ClipBatch"]
