"""The n x m job on each torch device, and the choices the job makes from its backend's declared
properties (:mod:`torchsplice.splice.backends`) rather than from backend names.

The job on a device (the CPU here; CUDA, marked ``gpu``, wherever torch sees one) runs the torch
splicer and gives the compiled splicer's results: the same clips, lengths, crops, timings and
action frames, rotations within 1e-3 degrees. The fork server is started only where the
resolved backend shares prepared clips with worker processes, and deciding so loads no torch.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from torchsplice.core.errors import TorchspliceError
from torchsplice.core.rotations import quat_angle
from torchsplice.job import splice_all
from torchsplice.store.database import MotionDatabase

REPO = Path(__file__).resolve().parents[2]
DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.gpu)]
PAIRS = dict(locomotions="walk_curve,jog", actions="carry_box,wave", methods="splice,naive,cpmc", index=False)
EXACT = ("name", "length", "locomotion", "action", "method", "timing", "acting", "crop", "coverage")
CLOSE = ("cost", "posture_deg", "pelvis_correction_deg")  # float64 columns; torch computes in float32


@pytest.fixture
def one_torch_thread():
    """Torch's CPU ops on one thread while a test runs: the torch splicer's many small ops wait
    for descheduled threads on a busy machine (ten times slower on two shared cores)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="module")
def compiled_job(sample_db, tmp_path_factory):
    """2 sample locomotions x 2 actions x 3 methods, spliced by the compiled splicer on the CPU."""
    out = tmp_path_factory.mktemp("devices") / "compiled.h5"
    splice_all(sample_db, out, workers=1, **PAIRS)
    return out


@pytest.mark.parametrize("device", DEVICES)
def test_the_job_on_a_device_gives_the_compiled_jobs_results(sample_db, compiled_job, tmp_path, device, monkeypatch,
                                                              one_torch_thread):
    """``splice_all(device=...)`` with ``backend="auto"`` runs the torch splicer on the device (on
    the CPU too, numba hidden) in this process, and writes the compiled job's clips: names,
    lengths, crops, timings and coverage equal; cost, posture and pelvis correction within 1e-3;
    rotations within 1e-3 degrees; root translations within 1e-5 of their scale; action frames
    within 1e-4 frames. An alignment store, which needs the compiled splicer's parts, is refused
    in one line."""
    import torchsplice.cpu
    from torchsplice.splice.backends import resolve_backend

    monkeypatch.setattr(torchsplice.cpu, "_AVAILABLE", False)
    assert resolve_backend("auto", device) == "torch"
    out = tmp_path / "torch.h5"
    summary = splice_all(sample_db, out, device=device, **PAIRS)
    assert summary.spliced == 12 and summary.engine.startswith("this process")
    with MotionDatabase.open(out) as got, MotionDatabase.open(compiled_job) as want:
        tg, tw = got.table(), want.table()
        for col in EXACT:
            assert np.array_equal(np.asarray(tg[col]), np.asarray(tw[col])), col
        for col in CLOSE:
            np.testing.assert_allclose(np.asarray(tg[col]), np.asarray(tw[col]), atol=1e-3, rtol=0, err_msg=col)
        pg, pw = got.packed(0), want.packed(0)
        angle = torch.rad2deg(quat_angle(torch.from_numpy(pg["rotations"]).double(),
                                         torch.from_numpy(pw["rotations"]).double()))
        assert float(angle.max()) < 1e-3
        scale = float(np.abs(pw["root_translation"]).max())
        assert float(np.abs(pg["root_translation"] - pw["root_translation"]).max()) <= 1e-5 * scale
        assert float(np.abs(pg["action_frame"] - pw["action_frame"]).max()) <= 1e-4
    with pytest.raises(TorchspliceError, match=r"the torch splicer gives no alignments to store; write store motion$"):
        splice_all(sample_db, tmp_path / "alignment.h5", device=device, store="alignment", **PAIRS)


# ------------------------------------------------------------------------------ the fork server


@pytest.fixture
def registry(monkeypatch):
    """Backend registrations undone after the test."""
    import torchsplice.splice.backends as backends

    monkeypatch.setattr(backends, "_REGISTRY", dict(backends._REGISTRY))
    monkeypatch.setattr(backends, "_INSTANCES", dict(backends._INSTANCES))
    return backends


def test_the_fork_server_starts_where_the_backend_shares_its_prepared_clips(registry, monkeypatch):
    """``prestart`` starts the fork server for a local job of several workers whose backend (as
    resolved on the device) prepares its clips once for its workers: the compiled splicer on the
    CPU, or any registered backend that declares so; never for torch, a backend that cannot run
    on the device, or an unknown one."""
    from multiprocessing import forkserver

    import torchsplice.cpu
    from torchsplice.job.engines.forkserver import prestart

    started = []
    monkeypatch.setattr(forkserver, "ensure_running", lambda: started.append(True))
    monkeypatch.setattr(forkserver, "set_forkserver_preload", lambda names: None)

    def starts(*args) -> bool:
        started.clear()
        prestart(*args)
        return bool(started)

    assert starts("local", 2, "cpu", "auto") and starts("local", 2, None, "compiled") and starts("local", 2, "cpu:0", "auto")
    assert not starts("local", 1, "cpu", "auto") and not starts("ray", 2, "cpu", "auto")
    assert not starts("local", 2, "cpu", "torch") and not starts("local", 2, "cuda", "auto")
    assert not starts("local", 2, "cuda", "compiled") and not starts("local", 2, "cpu", "no-such-backend")

    class SharedGpu(registry.Backend):
        name, devices, priority, prepares_once = "shared-gpu", ("cuda",), 50, True

    registry.register_backend("shared-gpu", SharedGpu)
    assert starts("local", 2, "cuda", "auto") and starts("local", 2, "cuda:1", "shared-gpu")
    assert not starts("local", 2, "cuda", "torch") and not starts("local", 2, "cpu", "shared-gpu")
    monkeypatch.setattr(torchsplice.cpu, "_AVAILABLE", False)  # no numba: "auto" is torch on the CPU
    assert not starts("local", 2, "cpu", "auto")


def test_deciding_whether_to_start_the_fork_server_loads_no_torch():
    """The command line calls ``prestart`` before it imports torch: resolving the backend asks
    every registered backend its properties, and none of them loads torch to answer."""
    code = ("import sys\n"
            "from torchsplice.job.engines.forkserver import prestart\n"
            "for device, backend in (('cuda', 'auto'), ('cpu', 'torch'), ('cuda', 'compiled'), ('cpu', 'nope')):\n"
            "    prestart('local', 4, device, backend)\n"
            "assert 'torch' not in sys.modules, 'torch was imported'\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    p = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
