"""Plug-in methods that misbehave: a method whose function raises, returns values that are not
finite or arrays of the wrong shape, and a module that registers a built-in's name. The job
skips such pairs with the reason (nothing non-finite lands in the output) and a single splice
is refused in one line."""

from __future__ import annotations

from dataclasses import replace

import h5py
import numpy as np
import pytest

from torchsplice.cli import main
from torchsplice.core.errors import TorchspliceError
from torchsplice.job import splice_all
from torchsplice.splice.registry import Method, MethodOutput, register_method


def _nan_run(inp):
    """The locomotion, with frame 3 of every pair's rotations NaN."""
    rot = inp.loco.rotations.clone()
    rot[:, 3] = float("nan")
    return MethodOutput(replace(inp.loco, rotations=rot), inp.loco.rotations.new_zeros(rot.shape[:2]).double())


def _raising_run(inp):
    raise RuntimeError("boom inside the plug-in")


def _short_times(inp):
    """Times of the wrong shape: (B, 3) instead of (B, T)."""
    return MethodOutput(inp.loco, inp.loco.rotations.new_zeros(inp.loco.rotations.shape[0], 3).double())


@pytest.fixture(scope="module")
def methods():
    from torchsplice.splice import registry

    register_method(Method("adv_nan", "returns NaN", _nan_run))
    register_method(Method("adv_raises", "raises", _raising_run))
    register_method(Method("adv_times", "times of the wrong shape", _short_times))
    yield
    for n in ("adv_nan", "adv_raises", "adv_times"):
        registry._REGISTRY.pop(n, None)


@pytest.fixture(scope="module")
def sample_db(tmp_path_factory):
    db = tmp_path_factory.mktemp("sample") / "sample.h5"
    assert main(["sample", "-o", str(db), "-q"]) == 0
    return db


@pytest.mark.parametrize("method, why", [("adv_nan", "not finite"), ("adv_raises", "boom inside the plug-in"),
                                         ("adv_times", "times")])
def test_job_skips_pairs_of_a_misbehaving_method(methods, sample_db, tmp_path, method, why):
    out = tmp_path / "out.h5"
    summary = splice_all(sample_db, out, methods=f"splice,{method}", workers=1,
                         locomotions="walk_curve,jog", actions="carry_box,wave")
    reasons = " ".join(summary.skipped)
    assert why in reasons and method in reasons, summary.skipped
    assert summary.spliced == 4  # the built-in's pairs land
    with h5py.File(out) as f:
        names = list(f["clips/name"].asstr()[()])
        assert not any(n.endswith("." + method) for n in names)
        assert np.isfinite(f["skeletons/0/rotations"][()]).all()


@pytest.mark.parametrize("method", ["adv_nan", "adv_raises", "adv_times"])
def test_splice_command_refuses_a_misbehaving_method_in_one_line(methods, sample_db, tmp_path, capsys, method):
    out = tmp_path / "x.bvh"
    rc = main(["splice", str(sample_db), "--locomotion", "walk_curve", "--action", "carry_box", "-o", str(out),
               "--method", method])
    err = capsys.readouterr().err
    assert rc == 2 and not out.exists()
    assert err.count("\n") == 1 and err.startswith("torchsplice: error:") and method in err, err


def test_registering_a_builtin_name_says_so_without_an_install_hint(tmp_path, monkeypatch, capsys):
    from torchsplice.splice.registry import available_methods

    assert available_methods()[:3] == ("splice", "naive", "cpmc")  # built-ins first, whoever registered first
    (tmp_path / "adv_dup.py").write_text(
        "from torchsplice.splice.registry import Method, register_method\n"
        "register_method(Method('splice', 'a second splice', lambda inp: None))\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    rc = main(["--plugin", "adv_dup", "info", "--help"])
    err = capsys.readouterr().err
    assert rc == 2 and "'splice' is already registered" in err and "adv_dup" in err
    assert "PYTHONPATH" not in err  # it was imported fine: the name is the problem


def test_a_plugin_that_exits_on_import_is_one_line_not_a_quiet_exit(tmp_path, monkeypatch, capsys):
    (tmp_path / "adv_exit.py").write_text("import sys\nsys.exit(3)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    rc = main(["--plugin", "adv_exit", "info", "--help"])
    err = capsys.readouterr().err
    assert rc == 2 and "'adv_exit' called sys.exit(3) on import" in err and len(err.strip().splitlines()) == 1


class _EntryPoint:
    """A stand-in for an installed package's entry point of the group torchsplice.methods."""

    def __init__(self, obj):
        self.name, self.value, self.obj = "adv_ep", "adv_pkg.methods:setup", obj

    def load(self):
        return self.obj


def _boom():
    raise ValueError("setup failed")


@pytest.mark.parametrize("obj, why", [(_boom, "ValueError: setup failed"), (42, "neither a Method nor a function")])
def test_an_entry_point_that_fails_is_one_line(monkeypatch, capsys, obj, why):
    import importlib.metadata

    from torchsplice.splice import registry

    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group=None: [_EntryPoint(obj)])
    monkeypatch.setitem(registry._LOADED, "entry_points", False)
    rc = main(["info", "--help"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "adv_ep" in err and why in err, err
