"""A toy export format, as a user would write one: each clip's root position per frame as CSV.

One module and one ``register_exporter`` call, nothing else in the package: load it with
``torchsplice --plugin toy_exporter export DB --all --format toy -o OUT`` (this folder on
``PYTHONPATH``) or ``import toy_exporter`` before ``export_clips(..., format="toy")``. Its one
option, ``decimals``, is the flag ``--decimals N`` of ``torchsplice export`` and the keyword
``export_clips(..., decimals=N)``. Used by tests/formats/test_plugin_exporter.py.
"""

from torchsplice.formats.exporters import Exporter, ExportOption, register_exporter


class ToyExporter(Exporter):
    name = "toy"
    suffix = ".csv"
    what = "a CSV file"
    title = "root CSV"
    options = {"decimals": ExportOption(None, type=int, metavar="N",
                                        help="digits after the point (default: every digit, as Python prints it)")}

    def write(self, motion, path):
        rows = motion.root_translation.tolist()
        d = self.options["decimals"]
        text = repr if d is None else (lambda v: f"{v:.{d}f}")
        path.write_text("frame,x,y,z\n" + "".join(f"{t},{text(x)},{text(y)},{text(z)}\n" for t, (x, y, z) in enumerate(rows)))


register_exporter(ToyExporter)
