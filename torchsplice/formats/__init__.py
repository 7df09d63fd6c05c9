"""File formats in and out of the database.

In: BVH (:mod:`.bvh`, its limits :mod:`.bvh_limits`), the BVH folder importer (:mod:`.importer`),
and HumanML3D folders (:mod:`.humanml3d_import`). Out: the export formats as plug-ins
(:mod:`.exporters`: one :class:`~.exporters.Exporter` per format, :func:`~.exporters.export_clips`
writing any of them all or nothing through :mod:`.staging`, with the index and split lists of
:mod:`.index`). The built-in formats are ``bvh`` (:mod:`.bvh_exporter`, written by
:mod:`.bvh_write`), ``npz`` (:mod:`.npz_exporter`, :mod:`.npz`, :mod:`.npz_features`) and
``humanml3d`` (:mod:`.humanml3d_exporter`, its 263 features :mod:`.humanml3d_features` and
captions :mod:`.captions`); :mod:`.humanml3d_stream` streams the same features without files.
:mod:`.plain_files` reads users' small files safely; :mod:`.sample_database` writes the built-in
sample as a database.

The names below are imported on first use, so that the export registry (and the command line)
can be read without loading torch.
"""

__all__ = ["read_bvh", "parse_bvh", "write_bvh", "format_bvh", "Exporter", "ExportOption", "ExportResult",
           "register_exporter", "get_exporter", "available_exporters", "export_clips", "write_sample"]

from ..core.lazy import lazy_names

__getattr__, __dir__ = lazy_names(__name__, {
    "read_bvh": ".bvh", "parse_bvh": ".bvh", "write_bvh": ".bvh", "format_bvh": ".bvh",
    "Exporter": ".exporters", "ExportOption": ".exporters", "ExportResult": ".exporters",
    "register_exporter": ".exporters", "get_exporter": ".exporters", "available_exporters": ".exporters",
    "export_clips": ".exporters", "write_sample": ".sample_database",
})
