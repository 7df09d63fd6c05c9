"""A toy export format, as a user would write one: each clip's root position per frame as CSV.

One module and one ``register_exporter`` call, nothing else in the package: load it with
``torchsplice --plugin toy_exporter export DB --all --format toy -o OUT`` (this folder on
``PYTHONPATH``) or ``import toy_exporter`` before ``export_clips(..., format="toy")``.
Used by tests/formats/test_plugin_exporter.py.
"""

from torchsplice.formats.exporters import Exporter, register_exporter


class ToyExporter(Exporter):
    name = "toy"
    suffix = ".csv"
    what = "a CSV file"
    title = "root CSV"

    def write(self, motion, path):
        rows = motion.root_translation.tolist()
        path.write_text("frame,x,y,z\n" + "".join(f"{t},{x!r},{y!r},{z!r}\n" for t, (x, y, z) in enumerate(rows)))


register_exporter(ToyExporter)
