"""File formats in and out of the database: BVH (:mod:`.bvh`), the BVH folder importer
(:mod:`.importer`), the NumPy export (:mod:`.npz`), and the export formats as plug-ins
(:mod:`.exporters`: one :class:`~.exporters.Exporter` per format, :func:`~.exporters.export_clips`
writing any of them all or nothing; the built-ins are :mod:`.bvh_exporter` and :mod:`.npz_exporter`).

The names below are imported on first use, so that the export registry (and the command line)
can be read without loading torch.
"""

__all__ = ["read_bvh", "parse_bvh", "write_bvh", "format_bvh", "Exporter", "ExportOption", "ExportResult",
           "register_exporter", "get_exporter", "available_exporters", "export_clips"]

_LAZY = {
    "read_bvh": "bvh", "parse_bvh": "bvh", "write_bvh": "bvh", "format_bvh": "bvh",
    "Exporter": "exporters", "ExportOption": "exporters", "ExportResult": "exporters",
    "register_exporter": "exporters", "get_exporter": "exporters", "available_exporters": "exporters",
    "export_clips": "exporters",
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
