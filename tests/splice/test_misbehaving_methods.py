"""Plug-in methods that misbehave (``adversary_corpus.HOSTILE_METHODS``: raising, exiting, values
that are not finite, arrays of the wrong shape, dtype or device, quaternions that are not
rotations) and a module that registers a built-in's name. The job (``splice_all``) skips such
pairs with the reason (nothing non-finite lands in the output), a single ``splice`` is refused in
one line, and a result that needs only detaching and normalising lands; the command keeps its
own one-line refusals (``test_cli_*``)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from adversary_corpus import HOSTILE_METHODS as HOSTILE, rotations_through as _rotations
from torchsplice.cli import main
from torchsplice.core.errors import TorchspliceError
from torchsplice.job import splice_all
from torchsplice.splice import splice
from torchsplice.store.database import MotionDatabase
from torchsplice.splice.registry import Method, register_method


@pytest.fixture(scope="module")
def methods():
    from torchsplice.splice import registry

    for name, (fn, _) in HOSTILE.items():
        register_method(Method(name, "misbehaves", fn))
    register_method(Method("adv_grad", "returns tensors that require grad, in float64, nearly unit",
                           _rotations(lambda r: (r.double() * 1.001).requires_grad_())))
    yield
    for n in [*HOSTILE, "adv_grad"]:
        registry._REGISTRY.pop(n, None)


@pytest.mark.parametrize("method, why", [(m, why) for m, (_, why) in HOSTILE.items()])
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


@pytest.fixture(scope="module")
def pair(sample_db):
    """walk_curve and carry_box read from the sample database, with its spec (what ``torchsplice
    splice`` reads)."""
    with MotionDatabase.open(sample_db) as db:
        return db.read("walk_curve"), db.read("carry_box"), db.spec(db.clip_info("walk_curve")["skeleton"])


@pytest.mark.parametrize("method, why", [(m, why) for m, (_, why) in HOSTILE.items()])
def test_a_single_splice_refuses_a_misbehaving_method_in_one_line(methods, pair, method, why):
    with pytest.raises(TorchspliceError) as caught:
        splice(*pair, method=method)
    msg = str(caught.value)
    assert "\n" not in msg and method in msg and why in msg, msg
    assert len(msg) < 600 and "\x1b" not in msg and "\x07" not in msg, msg


def test_cli_splice_refuses_a_misbehaving_method_in_one_line(methods, sample_db, tmp_path, capsys):
    """The command's own line (its prefix, exit code 2, no file written) for the method whose
    message is longest and full of escape sequences."""
    out = tmp_path / "x.bvh"
    rc = main(["splice", str(sample_db), "--locomotion", "walk_curve", "--action", "carry_box", "-o", str(out),
               "--method", "adv_shouts"])
    err = capsys.readouterr().err
    assert rc == 2 and not out.exists()
    assert err.count("\n") == 1 and err.startswith("torchsplice: error:") and "adv_shouts" in err, err
    assert len(err) < 600 and "\x1b" not in err and "\x07" not in err, err


def test_results_that_need_no_more_than_detaching_and_normalising_land(methods, sample_db, pair, tmp_path):
    """Tensors that require grad, in float64, with quaternions 0.1% off unit norm: detached,
    cast, normalised, stored."""
    out = tmp_path / "grad.h5"
    summary = splice_all(sample_db, out, methods="adv_grad", workers=1, locomotions="walk_curve,jog",
                         actions="carry_box,wave")
    assert summary.spliced == 4 and not summary.skipped
    with h5py.File(out) as f:
        q = f["skeletons/0/rotations"][()]
    assert np.abs(np.linalg.norm(q, axis=-1) - 1).max() < 1e-5
    result = splice(*pair, method="adv_grad")
    q = result.motion.rotations
    assert q.dtype == pair[0].rotations.dtype and not q.requires_grad
    assert (q.norm(dim=-1) - 1).abs().max() < 1e-5


def test_registering_a_builtin_name_says_so_without_an_install_hint(tmp_path, monkeypatch):
    from torchsplice.splice.registry import available_methods, load_plugins

    assert available_methods()[:3] == ("splice", "naive", "cpmc")  # built-ins first, whoever registered first
    (tmp_path / "adv_dup.py").write_text(
        "from torchsplice.splice.registry import Method, register_method\n"
        "register_method(Method('splice', 'a second splice', lambda inp: None))\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(TorchspliceError, match="'splice' is already registered") as caught:
        load_plugins(["adv_dup"])
    msg = str(caught.value)
    assert "adv_dup" in msg and "\n" not in msg
    assert "PYTHONPATH" not in msg  # it was imported fine: the name is the problem


def test_a_plugin_that_exits_on_import_is_one_line_not_a_quiet_exit(tmp_path, monkeypatch):
    from torchsplice.splice.registry import load_plugins

    (tmp_path / "adv_exit.py").write_text("import sys\nsys.exit(3)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(TorchspliceError, match=r"'adv_exit' called sys.exit\(3\) on import") as caught:
        load_plugins(["adv_exit"])
    assert "\n" not in str(caught.value)


def test_cli_a_plugin_that_exits_on_import_is_one_line_not_a_quiet_exit(tmp_path, monkeypatch, capsys):
    """``--plugin``'s refusal: exit code 2 and one line, not the plug-in's quiet exit 3."""
    (tmp_path / "adv_exit2.py").write_text("import sys\nsys.exit(3)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    rc = main(["--plugin", "adv_exit2", "info", "--help"])
    err = capsys.readouterr().err
    assert rc == 2 and "'adv_exit2' called sys.exit(3) on import" in err and len(err.strip().splitlines()) == 1


class _EntryPoint:
    """A stand-in for an installed package's entry point of the group torchsplice.methods."""

    def __init__(self, obj):
        self.name, self.value, self.obj = "adv_ep", "adv_pkg.methods:setup", obj

    def load(self):
        return self.obj


def _boom():
    raise ValueError("setup failed")


@pytest.mark.parametrize("obj, why", [(_boom, "ValueError: setup failed"), (42, "neither a Method nor a function")])
def test_an_entry_point_that_fails_is_one_line(monkeypatch, obj, why):
    import importlib.metadata

    from torchsplice.splice import registry

    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group=None: [_EntryPoint(obj)])
    monkeypatch.setitem(registry._LOADED, "entry_points", False)
    with pytest.raises(TorchspliceError) as caught:
        registry.available_methods()
    msg = str(caught.value)
    assert "\n" not in msg and "adv_ep" in msg and why in msg, msg
    with pytest.raises(TorchspliceError) as again:  # said again, not skipped from then on
        registry.available_methods()
    assert str(again.value) == msg
