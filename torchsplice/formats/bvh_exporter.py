"""The ``bvh`` export format: one BVH file per clip, with the skeleton's original channel
layout (:func:`torchsplice.formats.bvh.write_bvh`). Registered on import; imports no torch
until it writes."""

from __future__ import annotations

from pathlib import Path

from .exporters import Exporter, register_exporter

__all__ = ["BVHExporter"]


class BVHExporter(Exporter):
    """Each clip as a BVH file (opens in Blender, MotionBuilder and most other tools)."""

    name = "bvh"
    suffix = ".bvh"
    what = "BVH"
    title = "BVH"

    def write(self, motion, path: Path) -> None:
        from . import bvh

        Path(path).write_text(bvh.format_bvh(motion))  # the export stages its files already


register_exporter(BVHExporter)
