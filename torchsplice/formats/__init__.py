"""File formats in and out of the database: BVH (:mod:`.bvh`), the BVH folder importer
(:mod:`.importer`) and the NumPy export (:mod:`.npz`)."""

from .bvh import format_bvh, parse_bvh, read_bvh, write_bvh

__all__ = ["read_bvh", "parse_bvh", "write_bvh", "format_bvh"]
