"""A splicing backend of one's own (:mod:`torchsplice.splice.backends`): one module and one
registration, with no other change to the package.

The toy backend splices every pair alone through the torch backend (a batching of its own). It
runs through ``splice_pairs``, the n x m job from Python, and the command line (``--plugin``,
``--backend``), and gives the bits the torch backend gives each pair alone.
"""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
import torch

from cli_helpers import run
from torchsplice.core.errors import TorchspliceError
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.splice import SpliceOptions, splice_pairs
from torchsplice.store.database import MotionDatabase

TOY_BACKEND = textwrap.dedent('''
    """A toy backend: every pair alone, through the torch backend."""
    from torchsplice.splice.backends import Backend, SplicedBatch, get_backend, register_backend

    CALLS = []


    class PairByPair(Backend):
        name = "pair-by-pair"

        def __init__(self):
            self.torch = get_backend("torch")

        def prepare(self, motions, skeleton, roles, options):
            return self.torch.prepare(motions, skeleton, roles, options)

        def positions(self, prepared, rows=None):
            return self.torch.positions(prepared, rows)

        def splice(self, prepared, loco, action, reference, method, options, fps, *, buffers=None, keep_going=False):
            CALLS.append(len(loco))
            return SplicedBatch.concat([
                self.torch.splice(prepared, [lo], [ac], None if reference is None else [reference[b]], method, options,
                                  fps, keep_going=keep_going)
                for b, (lo, ac) in enumerate(zip(loco, action))])

        def standing(self, prepared, loco, action, acting, tables, method, options, fps, *, buffers=None,
                     keep_going=False):
            CALLS.append(len(loco))
            return SplicedBatch.concat([
                self.torch.standing(prepared, [lo], [ac], [acting[b]], tables, method, options, fps, keep_going=keep_going)
                for b, (lo, ac) in enumerate(zip(loco, action))])


    register_backend("pair-by-pair", PairByPair)
''')


@pytest.fixture
def toy(tmp_path, monkeypatch):
    """The toy backend's module, imported (registered) for this test only."""
    import importlib

    import torchsplice.splice.backends as backends

    monkeypatch.setattr(backends, "_REGISTRY", dict(backends._REGISTRY))
    monkeypatch.setattr(backends, "_INSTANCES", dict(backends._INSTANCES))
    folder = tmp_path / "plugins"
    folder.mkdir()
    (folder / "toy_pairs.py").write_text(TOY_BACKEND)
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setenv("PYTHONPATH", str(folder))
    module = importlib.import_module("toy_pairs")
    yield module
    import sys

    sys.modules.pop("toy_pairs", None)


def test_a_registered_backend_splices_through_splice_pairs_with_the_torch_bits_of_each_pair_alone(toy):
    clips = sample_motions()
    walks = [m for m in clips if m.labels.get("content") in ("walk", "curve")][:2]
    actions = [m for m in clips if m.role == "action"][:2]
    pairs = [(w, a) for w in walks for a in actions]
    spec = load_spec("sample")
    got = splice_pairs(pairs, spec, options=SpliceOptions(backend="pair-by-pair"))
    assert toy.CALLS and sum(toy.CALLS) == len(pairs)
    for (w, a), r in zip(pairs, got):
        alone = splice_pairs([(w, a)], spec, options=SpliceOptions(backend="torch"))[0]
        assert torch.equal(r.motion.rotations, alone.motion.rotations)
        assert torch.equal(r.motion.root_translation, alone.motion.root_translation)
        assert torch.equal(r.curve, alone.curve)
        assert r.cost == alone.cost or (np.isnan(r.cost) and np.isnan(alone.cost))
        assert r.motion.name == alone.motion.name


def test_an_unknown_backend_names_the_registered_ones(toy):
    from torchsplice.splice.backends import backend_choices

    assert backend_choices()[:3] == ("auto", "compiled", "torch") and "pair-by-pair" in backend_choices()
    with pytest.raises(TorchspliceError, match="unknown backend 'nothing'; choose one of auto, compiled, torch, pair-by-pair"):
        splice_pairs([(sample_motions()[0], sample_motions()[1])], load_spec("sample"),
                     options=SpliceOptions(backend="nothing"))


def _frames(path):
    with MotionDatabase.open(path) as db:
        names = list(db.names)
        return names, [db.read(n).rotations for n in names]


def test_a_registered_backend_runs_the_job_from_python_and_the_command_line(toy, sample_db, tmp_path, capsys):
    from torchsplice.job import splice_all

    summary = splice_all(sample_db, tmp_path / "toy.h5", backend="pair-by-pair", methods="splice,naive", workers=1,
                         progress=False)
    assert summary.spliced > 0 and sum(toy.CALLS) == summary.spliced
    reference = splice_all(sample_db, tmp_path / "compiled.h5", methods="splice,naive", workers=1, progress=False)
    names, rotations = _frames(tmp_path / "toy.h5")
    ref_names, ref_rotations = _frames(tmp_path / "compiled.h5")
    assert names == ref_names and summary.spliced == reference.spliced
    for a, b in zip(rotations, ref_rotations):  # torch (float32) against the compiled splicer (float64)
        torch.testing.assert_close(a.abs(), b.abs(), atol=2e-3, rtol=0)
    code, out, err = run(capsys, "--plugin", "toy_pairs", "splice-all", sample_db, "-o", tmp_path / "cli.h5",
                         "--method", "splice,naive", "--workers", "1", "--backend", "pair-by-pair")
    assert code == 0, err
    cli_names, cli_rotations = _frames(tmp_path / "cli.h5")
    assert cli_names == names and all(torch.equal(a, b) for a, b in zip(cli_rotations, rotations))


class _Declared:
    """Backends that declare only where they run and how strongly ``"auto"`` prefers them."""

    @staticmethod
    def make(name: str, devices, priority: int, available: bool = True):
        from torchsplice.splice.backends import Backend

        return type(name, (Backend,), {"name": name, "devices": devices, "priority": priority,
                                       "available": lambda self: available})


@pytest.fixture
def registry(monkeypatch):
    """Registrations undone after the test: ``"auto"`` elsewhere sees the built-in backends only."""
    import torchsplice.splice.backends as backends

    monkeypatch.setattr(backends, "_REGISTRY", dict(backends._REGISTRY))
    monkeypatch.setattr(backends, "_INSTANCES", dict(backends._INSTANCES))
    return backends


def test_auto_chooses_the_highest_priority_backend_that_runs_on_the_device(registry):
    from torchsplice.cpu import available

    builtin_cpu = "compiled" if available() else "torch"
    assert registry.resolve_backend("auto", None) == builtin_cpu
    assert registry.resolve_backend("auto", "cuda") == "torch"  # the compiled splicer runs on the CPU only
    registry.register_backend("gpu", _Declared.make("gpu", ("cuda",), 50))
    assert registry.resolve_backend("auto", "cuda:1") == "gpu"
    assert registry.resolve_backend("auto", None) == builtin_cpu  # not on the CPU: the built-in choice stands
    registry.register_backend("slow-everywhere", _Declared.make("slow-everywhere", None, -1))
    assert registry.resolve_backend("auto", "mps") == "torch"  # the torch backend (0) beats a lower priority
    registry.register_backend("gone", _Declared.make("gone", None, 99, available=False))
    assert registry.resolve_backend("auto", None) == builtin_cpu  # an unavailable backend is never chosen
    registry.register_backend("twin", _Declared.make("twin", ("cuda",), 50))
    assert registry.resolve_backend("auto", "cuda") == "gpu"  # equals: the first registered


def test_a_backend_named_for_a_device_it_does_not_run_on_says_which_do(registry):
    registry.register_backend("gpu", _Declared.make("gpu", ("cuda",), 50))
    from torchsplice.cpu import available

    on_cpu = "'compiled' or 'torch'" if available() else "'torch'"
    with pytest.raises(TorchspliceError, match=f"the gpu backend runs on cuda devices; device None needs backend "
                                               f"{on_cpu} or 'auto'"):
        registry.resolve_backend("gpu", None)
    with pytest.raises(TorchspliceError, match=r"the compiled backend runs on the CPU; device 'cuda' needs backend "
                                               r"'torch' or 'gpu' or 'auto'"):
        registry.resolve_backend("compiled", "cuda")
