"""Virtual outputs under attack: a job or merge killed at each step of putting a new virtual
output in place of an old one (the old one stays readable, or the new one is whole, and a
rerun finishes), an output renamed away while another job writes its old name (it keeps
reading its own frames), and a copy-layout job over a virtual output (no orphaned shards)."""

from __future__ import annotations

import numpy as np
import pytest

import torchsplice.job.shards as run_module
from torchsplice.cli import main
from torchsplice.store.database import MotionDatabase

LOCOS, ACTIONS = "walk_curve,jog,turn_sharp", "carry_box,wave"


def job(db, out, method, *extra):
    return main(["splice-all", str(db), "-o", str(out), "--locomotions", LOCOS, "--actions", ACTIONS, "--method", method,
                 "--layout", "virtual", "--batch-size", "2", "--workers", "1", "-q", *extra])


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
    assert job(sample_db, d / "splice.h5", "splice") == 0
    assert job(sample_db, d / "naive.h5", "naive") == 0
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
    assert job(sample_db, out, "splice") == 0
    interrupt_after(monkeypatch, "install_shards", first=1 if kill == "mid-install" else None)
    assert job(sample_db, out, "naive", "--force") == 130
    assert same(frames(out), want_splice)  # the old output, whole and its own
    monkeypatch.undo()
    assert job(sample_db, out, "naive", "--force") == 0  # the rerun finishes
    assert same(frames(out), want_naive)
    subfolders = [p for p in (tmp_path / "v.h5.shards").iterdir()]
    assert len(subfolders) == 1  # the old output's shards went with it
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no work folder, lock or temporary


def test_a_merge_killed_while_replacing_an_output_leaves_one_readable_then_finishes(
        sample_db, references, tmp_path, monkeypatch, capsys):
    want_splice, want_naive = references
    out = tmp_path / "bv.h5"
    assert job(sample_db, out, "splice") == 0
    assert job(sample_db, out, "naive", "--shard", "1/1") == 0
    interrupt_after(monkeypatch, "install_shards")
    assert main(["merge", str(out), "-f"]) == 130
    assert same(frames(out), want_splice)
    monkeypatch.undo()
    capsys.readouterr()
    assert main(["merge", str(out), "-f"]) == 0, capsys.readouterr().err
    assert same(frames(out), want_naive)
    assert len(list((tmp_path / "bv.h5.shards").iterdir())) == 1


def test_an_output_renamed_away_keeps_reading_its_own_frames(sample_db, references, tmp_path):
    want_splice, want_naive = references
    out = tmp_path / "v.h5"
    assert job(sample_db, out, "splice") == 0
    out.rename(tmp_path / "run1.h5")
    assert job(sample_db, out, "naive") == 0
    assert same(frames(tmp_path / "run1.h5"), want_splice)
    assert same(frames(out), want_naive)


def test_a_copy_job_over_a_virtual_output_leaves_no_orphaned_shards(sample_db, references, tmp_path):
    _, want_naive = references
    out = tmp_path / "v.h5"
    assert job(sample_db, out, "splice") == 0
    assert (tmp_path / "v.h5.shards").is_dir()
    assert main(["splice-all", str(sample_db), "-o", str(out), "--locomotions", LOCOS, "--actions", ACTIONS,
                 "--method", "naive", "--workers", "1", "-q", "--force"]) == 0
    assert not (tmp_path / "v.h5.shards").exists()
    assert same(frames(out), want_naive)
