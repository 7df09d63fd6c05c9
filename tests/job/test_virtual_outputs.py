"""Virtual outputs under attack: a job or merge killed at each step of putting a new virtual
output in place of an old one (the old one stays readable, or the new one is whole, and a
rerun finishes), an output renamed away while another job writes its old name (it keeps
reading its own frames), and a copy-layout job over a virtual output (no orphaned shards); the
jobs run through ``splice_all`` and ``merge_job``, stopped as by Ctrl-C."""

from __future__ import annotations

import numpy as np
import pytest

import torchsplice.job.shards as run_module
from torchsplice.job import merge_job, splice_all
from torchsplice.store.database import MotionDatabase

LOCOS, ACTIONS = "walk_curve,jog,turn_sharp", "carry_box,wave"


def job(db, out, method, **extra):
    """The virtual-layout job of ``method`` on the locomotions LOCOS x the actions ACTIONS."""
    return splice_all(db, out, locomotions=LOCOS, actions=ACTIONS, methods=method, layout="virtual", batch_pairs=2,
                      workers=1, **extra)


def frames(path) -> dict:
    """Every clip's rotations, by name."""
    with MotionDatabase.open(path) as db:
        return {n: db.read(n).rotations.numpy().copy() for n in db.names}


def same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


@pytest.fixture(scope="module")
def references(sample_db, tmp_path_factory):
    """The splice and naive outputs of the job, each written alone."""
    d = tmp_path_factory.mktemp("refs")
    job(sample_db, d / "splice.h5", "splice")
    job(sample_db, d / "naive.h5", "naive")
    return frames(d / "splice.h5"), frames(d / "naive.h5")


def interrupt_after(monkeypatch, name: str, first: int | None = None):
    """Make ``torchsplice.job.shards.<name>`` stop the process (as Ctrl-C) once it has run (on
    the ``first`` shards only, when given)."""
    original = getattr(run_module, name)

    def cut(*args):
        if first is not None:
            args = (*args[:-1], args[-1][:first])
        original(*args)
        raise KeyboardInterrupt

    monkeypatch.setattr(run_module, name, cut)


@pytest.mark.parametrize("kill", ["mid-install", "after-install"])
def test_a_virtual_job_killed_while_replacing_an_output_leaves_one_readable_then_finishes(
        sample_db, references, tmp_path, monkeypatch, kill):
    want_splice, want_naive = references
    out = tmp_path / "v.h5"
    job(sample_db, out, "splice")
    interrupt_after(monkeypatch, "install_shards", first=1 if kill == "mid-install" else None)
    with pytest.raises(KeyboardInterrupt):
        job(sample_db, out, "naive", overwrite=True)
    assert same(frames(out), want_splice)  # the old output, whole and its own
    monkeypatch.undo()
    job(sample_db, out, "naive", overwrite=True)  # the rerun finishes
    assert same(frames(out), want_naive)
    subfolders = [p for p in (tmp_path / "v.h5.shards").iterdir()]
    assert len(subfolders) == 1  # the old output's shards went with it
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no work folder, lock or temporary


def test_a_merge_killed_while_replacing_an_output_leaves_one_readable_then_finishes(
        sample_db, references, tmp_path, monkeypatch):
    want_splice, want_naive = references
    out = tmp_path / "bv.h5"
    job(sample_db, out, "splice")
    job(sample_db, out, "naive", shard="1/1")
    interrupt_after(monkeypatch, "install_shards")
    with pytest.raises(KeyboardInterrupt):
        merge_job(out, overwrite=True, progress=False)
    assert same(frames(out), want_splice)
    monkeypatch.undo()
    merge_job(out, overwrite=True, progress=False)
    assert same(frames(out), want_naive)
    assert len(list((tmp_path / "bv.h5.shards").iterdir())) == 1


def test_an_output_renamed_away_keeps_reading_its_own_frames(sample_db, references, tmp_path):
    want_splice, want_naive = references
    out = tmp_path / "v.h5"
    job(sample_db, out, "splice")
    out.rename(tmp_path / "run1.h5")
    job(sample_db, out, "naive")
    assert same(frames(tmp_path / "run1.h5"), want_splice)
    assert same(frames(out), want_naive)


def test_a_copy_job_over_a_virtual_output_leaves_no_orphaned_shards(sample_db, references, tmp_path):
    _, want_naive = references
    out = tmp_path / "v.h5"
    job(sample_db, out, "splice")
    assert (tmp_path / "v.h5.shards").is_dir()
    splice_all(sample_db, out, locomotions=LOCOS, actions=ACTIONS, methods="naive", workers=1, overwrite=True)
    assert not (tmp_path / "v.h5.shards").exists()
    assert same(frames(out), want_naive)
