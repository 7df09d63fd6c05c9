"""A full disk: one line, the partial file removed, and a rerun that resumes (on a small tmpfs where
the tests run as root; simulated everywhere)."""

from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest

from cli_helpers import error_line, run
from torchsplice.cli import main
from torchsplice.store.database import MotionDatabase
from writers import fill


@pytest.fixture
def small_disk(tmp_path):
    """A 32 MB tmpfs mounted in the test's folder (needs root, as in CI); skipped elsewhere."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root (CI runs as root); test_full_disk_simulated covers the rest")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=32m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            pytest.fail(f"cannot mount a tmpfs in CI: {r.stderr.strip()}")
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_full_disk_gives_one_line_removes_the_partial_file_and_a_rerun_resumes(small_disk, sample_db, mocap_dir, capsys):
    bandai = mocap_dir / "bandai_namco_research_motiondataset"
    # import: the folder's database is larger than the room left
    ballast = fill(small_disk, 10)
    rc, _, err = run(capsys, "import", bandai, "-o", small_disk / "b.h5", "-q")
    line = error_line(err)
    assert rc == 2 and "no space left on the device" in line and str(small_disk / "b.h5") in line and "free" in line
    assert sorted(p.name for p in small_disk.iterdir()) == ["ballast"]
    ballast.unlink()
    # sample
    ballast = fill(small_disk, 2)
    rc, _, err = run(capsys, "sample", "-o", small_disk / "s.h5", "-q")
    assert rc == 2 and "no space left" in error_line(err)
    assert sorted(p.name for p in small_disk.iterdir()) == ["ballast"]
    ballast.unlink()
    # splice-all: some tasks land, then the disk is full; after freeing space the rerun resumes
    reference = small_disk.parent / "reference.h5"
    assert main(["splice-all", str(sample_db), "-o", str(reference), "-q", "--workers", "1", "--batch-size", "4"]) == 0
    from torchsplice.store.writing import SPACE_MARGIN

    ballast = fill(small_disk, SPACE_MARGIN / 1e6 + 0.8)  # room for some tasks of the job, not all
    out = small_disk / "out.h5"
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", out, "-q", "--workers", "1", "--batch-size", "4")
    assert rc == 2 and "no space left" in error_line(err)
    parts = small_disk / ".out.h5.parts"
    assert not out.exists() and not any("partial" in p.name for p in parts.rglob("*"))
    held = (MotionDatabase.checkpoint_note(parts / "output.h5") or {}).get("tasks", 0)
    assert held >= 1, "some tasks should have landed in the staged output before the disk filled"
    ballast.unlink()
    rc, text, err = run(capsys, "splice-all", sample_db, "-o", out, "--workers", "1", "--batch-size", "4")
    assert rc == 0, err
    assert f"({4 * held} pairs from an earlier run)" in text  # the rerun goes on where the disk filled
    with MotionDatabase.open(out) as a, MotionDatabase.open(reference) as b:
        assert a.names == b.names
        pa, pb = a.packed(0), b.packed(0)
        assert all(np.array_equal(pa[k], pb[k], equal_nan=True) for k in pb)
    assert sorted(p.name for p in small_disk.iterdir()) == ["out.h5", "out.h5.index.csv"]


def test_full_disk_simulated(sample_db, tmp_path, capsys, monkeypatch):
    """Where no tmpfs can be mounted: the free space the database sees is made small."""
    import torchsplice.store.database as database

    real = shutil.disk_usage
    monkeypatch.setattr(database.shutil, "disk_usage", lambda p: real(p)._replace(free=1 << 20))
    rc, _, err = run(capsys, "sample", "-o", tmp_path / "s.h5", "-q")
    line = error_line(err)
    assert rc == 2 and "no space left on the device" in line and "1.0 MB free" in line
    assert list(tmp_path.iterdir()) == []
