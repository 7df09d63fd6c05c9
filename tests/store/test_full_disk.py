"""A full disk (import_bvh, MotionDatabase, splice_all): one line, the partial file removed, and a rerun that resumes (on a small tmpfs where
the tests run as root; simulated everywhere)."""

from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest

from torchsplice import DatabaseError, import_bvh, splice_all, write_sample
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


def test_full_disk_gives_one_line_removes_the_partial_file_and_a_rerun_resumes(small_disk, sample_db, mocap_dir):
    bandai = mocap_dir / "bandai_namco_research_motiondataset"
    # import: the folder's database is larger than the room left
    ballast = fill(small_disk, 10)
    with pytest.raises(DatabaseError, match="no space left on the device") as caught:
        import_bvh([bandai], small_disk / "b.h5")
    line = str(caught.value)
    assert str(small_disk / "b.h5") in line and "free" in line and "\n" not in line
    assert sorted(p.name for p in small_disk.iterdir()) == ["ballast"]
    ballast.unlink()
    # the sample
    ballast = fill(small_disk, 2)
    with pytest.raises(DatabaseError, match="no space left") as caught:
        write_sample(small_disk / "s.h5")
    assert "\n" not in str(caught.value)
    assert sorted(p.name for p in small_disk.iterdir()) == ["ballast"]
    ballast.unlink()
    # splice_all: some tasks land, then the disk is full; after freeing space the rerun resumes
    reference = small_disk.parent / "reference.h5"
    job = dict(workers=1, batch_pairs=4)
    splice_all(sample_db, reference, **job)
    from torchsplice.store.writing import SPACE_MARGIN

    ballast = fill(small_disk, SPACE_MARGIN / 1e6 + 0.8)  # room for some tasks of the job, not all
    out = small_disk / "out.h5"
    with pytest.raises(DatabaseError, match="no space left") as caught:
        splice_all(sample_db, out, **job)
    assert "\n" not in str(caught.value)
    parts = small_disk / ".out.h5.parts"
    assert not out.exists() and not any("partial" in p.name for p in parts.rglob("*"))
    held = (MotionDatabase.checkpoint_note(parts / "output.h5") or {}).get("tasks", 0)
    assert held >= 1, "some tasks should have landed in the staged output before the disk filled"
    ballast.unlink()
    summary = splice_all(sample_db, out, **job)
    assert summary.resumed == 4 * held  # the rerun goes on where the disk filled
    assert f"({4 * held} pairs from an earlier run)" in " ".join(summary.lines())
    with MotionDatabase.open(out) as a, MotionDatabase.open(reference) as b:
        assert a.names == b.names
        pa, pb = a.packed(0), b.packed(0)
        assert all(np.array_equal(pa[k], pb[k], equal_nan=True) for k in pb)
    assert sorted(p.name for p in small_disk.iterdir()) == ["out.h5", "out.h5.index.csv"]


def test_full_disk_simulated(tmp_path, monkeypatch):
    """Where no tmpfs can be mounted: the free space the database sees is made small."""
    import torchsplice.store.database as database

    real = shutil.disk_usage
    monkeypatch.setattr(database.shutil, "disk_usage", lambda p: real(p)._replace(free=1 << 20))
    with pytest.raises(DatabaseError, match="no space left on the device") as caught:
        write_sample(tmp_path / "s.h5")
    line = str(caught.value)
    assert "1.0 MB free" in line and "\n" not in line
    assert list(tmp_path.iterdir()) == []
