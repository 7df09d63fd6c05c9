"""Options are declared once, torch-free: each package whose options the command line shows has a
``defaults`` module (``torchsplice/<package>/defaults.py``: allowed values as plural nouns,
defaults as ``DEFAULT_<OPTION>``) that the library and the command line both import. Such a
module imports only the standard library and other ``defaults`` modules (checked from its
syntax tree in tests/project/test_layout.py), so importing any of them, in a fresh process,
loads no torch, numpy or h5py; neither do the export formats' declared options, which the
``export`` command makes its flags from."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2] / "torchsplice"
DEFAULTS = sorted("torchsplice." + ".".join(p.relative_to(ROOT).with_suffix("").parts) for p in ROOT.rglob("defaults.py"))
HEAVY = ("torch", "numpy", "h5py", "numba", "matplotlib")
PROBE = """
import importlib, json, sys
out = {}
for name in %r:
    importlib.import_module(name)
    out[name] = [m for m in %r if m in sys.modules]
from torchsplice.formats.exporters import available_exporters, get_exporter
options = {f: {k: [repr(o.default), o.help != ""] for k, o in get_exporter(f).options.items()} for f in available_exporters()}
out["exporters"] = [m for m in %r if m in sys.modules]
print(json.dumps([out, options]))
"""


def test_the_packages_declare_their_options_in_defaults_modules():
    names = {m.split(".")[1] for m in DEFAULTS}
    assert names >= {"splice", "job", "store", "formats", "viz", "evaluation", "retarget"}, names


def test_every_defaults_module_and_the_export_options_load_no_heavy_module():
    """Each ``defaults`` module imports in a fresh process without torch, numpy or h5py (the
    package it is in included), and so do the registered formats with their options."""
    probe = PROBE % (DEFAULTS, HEAVY, HEAVY)
    p = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    loaded, options = json.loads(p.stdout)
    assert loaded == {name: [] for name in [*DEFAULTS, "exporters"]}, loaded
    assert set(options) >= {"bvh", "npz", "humanml3d"}
    assert all(has_help for f in ("npz", "humanml3d") for _, has_help in options[f].values())  # each a flag with help
