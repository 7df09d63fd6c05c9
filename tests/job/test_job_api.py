"""The whole job from Python: :func:`torchsplice.job.splice_all` takes the command line's
selections and options and writes the same database as ``torchsplice splice-all``."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from torchsplice.cli import main
from torchsplice.core.errors import OutputExistsError, TorchspliceError
from torchsplice.store.database import MotionDatabase
from torchsplice.job import JobConfig, job_config, merge_job, splice_all


def _datasets(path) -> dict:
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return out


def test_same_output_as_the_command_line(sample_db, tmp_path):
    api, cli = tmp_path / "api.h5", tmp_path / "cli.h5"
    summary = splice_all(sample_db, api, locomotions="walk_*", actions=["role:action", "carry_*"],
                         methods="splice,naive", workers=1, acting_limbs="auto", copy_sources=True)
    # 2 walks x 2 carrying actions x 2 methods, and the 4 source clips copied
    assert summary.spliced == 8 and summary.copied == 4 and summary.skipped == {}
    assert main(["splice-all", str(sample_db), "-o", str(cli), "--locomotions", "walk_*", "--actions", "role:action",
                 "--actions", "carry_*", "--method", "splice,naive", "--workers", "1", "--copy-sources", "-q"]) == 0
    a, b = _datasets(api), _datasets(cli)
    assert a.keys() == b.keys()
    for k in a:
        assert np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"), k
    with MotionDatabase.open(api) as db:
        names = sorted(str(n) for n in db.table()["name"])
    assert names == sorted(["walk_straight", "walk_curve", "carry_box", "carry_cup"]
                           + [f"{lo}+{ac}{s}" for lo in ("walk_straight", "walk_curve")
                              for ac in ("carry_box", "carry_cup") for s in ("", ".naive")])
    with pytest.raises(OutputExistsError):
        splice_all(sample_db, api, workers=1)
    assert splice_all(sample_db, api, workers=1, overwrite=True).spliced == 25  # defaults: role x role, splice


def test_shards_then_merge(sample_db, tmp_path):
    out = tmp_path / "out.h5"
    for k in (1, 2):
        s = splice_all(sample_db, out, methods=("naive",), workers=1, batch_pairs=5, shard=f"{k}/2")
        assert s.shard == (k, 2) and s.tasks_done == s.tasks > 0 and not out.exists()
    assert merge_job(out, progress=False).spliced == 25 and out.exists()


def test_options_are_the_config_fields(tmp_path, sample_db):
    c = job_config(sample_db, tmp_path / "o.h5", locomotions=None, actions="role:both", methods=" splice , cpmc",
                   acting_limbs="none")
    assert isinstance(c, JobConfig)
    assert c.locomotions == JobConfig.locomotions and c.actions == ("role:both",)
    assert c.methods == ("splice", "cpmc") and c.acting_limbs == ()
    with pytest.raises(TorchspliceError, match="unknown job option 'method'; the options are actions_db, locomotions"):
        job_config(sample_db, tmp_path / "o.h5", method="naive")
    with pytest.raises(TorchspliceError, match="acting_limbs: unknown limb 'tail'"):
        job_config(sample_db, tmp_path / "o.h5", acting_limbs="tail")


def test_twist_reaches_every_splice_and_is_recorded(sample_db, tmp_path):
    """``twist=`` (``--twist``) gives the clips ``splice_pairs(..., SpliceOptions(twist=...))`` gives,
    differs from the default on a sharp turn, and is recorded in ``params`` (the command's parser
    refusing ``--twist 2``: tests/cli/test_command_words.py)."""
    import json

    from torchsplice.specs import load_spec
    from torchsplice.splice import SpliceOptions, splice_pairs

    out0, out5 = tmp_path / "t0.h5", tmp_path / "t5.h5"
    for out, extra in ((out0, {}), (out5, {"twist": 1})):
        splice_all(sample_db, out, locomotions="turn_sharp", actions="carry_box", workers=1, **extra)
    with MotionDatabase.open(out0) as a, MotionDatabase.open(out5) as b, MotionDatabase.open(sample_db) as src:
        r0, r5 = a.read("turn_sharp+carry_box"), b.read("turn_sharp+carry_box")
        assert json.loads(b.table()["params"][0])["twist"] == 1 and json.loads(a.table()["params"][0])["twist"] == 0
        want = splice_pairs([(src.read("turn_sharp"), src.read("carry_box"))], load_spec("sample"),
                            options=SpliceOptions(twist=1.0))[0].motion
    assert not np.allclose(r0.rotations.numpy(), r5.rotations.numpy(), atol=1e-4)
    np.testing.assert_allclose(r5.rotations.numpy(), want.rotations.numpy(), atol=1e-5)
    with pytest.raises(TorchspliceError, match="twist"):
        splice_all(sample_db, tmp_path / "bad.h5", twist=1.5, workers=1)


def test_freed_memory_is_given_back_after_planning_large_sources_only(sample_db, tmp_path, monkeypatch):
    # a full garbage collection costs 0.13-0.2 s: worth it after planning the whole dataset, not a sample
    import gc

    from torchsplice.job import run

    calls = []
    real = gc.collect
    monkeypatch.setattr(gc, "collect", lambda *a: calls.append(a) or real(*a))
    a = splice_all(sample_db, tmp_path / "small.h5", workers=1)
    assert calls == []
    monkeypatch.setattr(run, "RETURN_FREED_FRAMES", 1)  # as if the sample's clips were the whole dataset's
    b = splice_all(sample_db, tmp_path / "large.h5", workers=1)
    assert len(calls) == 2  # after the clips are let go, and after the banks are in the output
    assert a.spliced == b.spliced == 25
    fa, fb = _datasets(tmp_path / "small.h5"), _datasets(tmp_path / "large.h5")
    assert fa.keys() == fb.keys() and all(np.array_equal(fa[k], fb[k]) for k in fa)  # the same bits either way
