"""The package's own names: the main verbs import from ``torchsplice`` itself, each the object
its module defines, and ``import torchsplice`` loads no torch until one of them is used."""

from __future__ import annotations

import subprocess
import sys

import pytest
import torch

import torchsplice

VERBS = {"import_bvh": "torchsplice.formats.importer", "splice_all": "torchsplice.job.run",
         "export_clips": "torchsplice.formats.exporters", "MotionDatabase": "torchsplice.store.database",
         "MotionDataset": "torchsplice.data.dataset"}


@pytest.mark.parametrize("name", sorted(VERBS))
def test_each_main_verb_is_the_object_its_module_defines(name):
    module = __import__(VERBS[name], fromlist=[name])
    assert getattr(torchsplice, name) is getattr(module, name)
    assert name in torchsplice.__all__ and name in dir(torchsplice)


def test_splice_is_the_package_and_calls_the_splice_function():
    from torchsplice import splice
    from torchsplice.sample import sample_motions
    from torchsplice.specs import load_spec
    from torchsplice.splice.api import splice as splice_function

    assert splice is sys.modules["torchsplice.splice"] and splice.registry.get_method("splice").name == "splice"
    loco, action = sample_motions()[:2]
    spec = load_spec("sample")
    a, b = splice(loco, action, spec), splice_function(loco, action, spec)
    assert torch.equal(a.motion.rotations, b.motion.rotations)
    assert torch.equal(a.motion.root_translation, b.motion.root_translation)


def test_an_unknown_name_is_an_attribute_error_naming_it():
    with pytest.raises(AttributeError, match="no attribute 'splice_everything'"):
        torchsplice.splice_everything  # noqa: B018


def test_importing_the_package_loads_no_torch():
    probe = "import sys, torchsplice; print(','.join(m for m in ('torch', 'numba', 'h5py') if m in sys.modules))"
    p = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0 and p.stdout.strip() == "", p.stdout + p.stderr
