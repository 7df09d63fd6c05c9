"""Nothing lost, no traceback: locks against concurrent writers, outputs that are inputs, a full
disk, bad files among good ones, damaged clips, bounded flags.

Each test exercises the command line as a user would (in-process through ``main``, or as
separate processes where two writers race) and checks the one-line promise: a user's mistake
gives ``torchsplice: error: ...`` and exit 2, good files still land, nothing is left behind.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from torchsplice.cli import main
from torchsplice.store.database import MotionDatabase
from cli_helpers import run, error_line

REPO = Path(__file__).resolve().parents[1]


def cli(*argv, env: dict | None = None) -> subprocess.Popen:
    env = dict(os.environ if env is None else env, PYTHONPATH=str(REPO))
    return subprocess.Popen([sys.executable, "-m", "torchsplice", *map(str, argv)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


@contextlib.contextmanager
def held_elsewhere(out: Path):
    """Another process holding the output's lock (as a running command does); yields its PID."""
    code = ("import sys, time; from torchsplice.store.lock import output_lock; "
            "output_lock(sys.argv[1], 'holder').acquire(); print('held', flush=True); time.sleep(120)")
    p = subprocess.Popen([sys.executable, "-c", code, str(out)], stdout=subprocess.PIPE, text=True,
                         env=dict(os.environ, PYTHONPATH=str(REPO)))
    try:
        assert p.stdout.readline().strip() == "held"
        yield p.pid
    finally:
        p.kill()
        p.wait()


@pytest.fixture
def bandai(mocap_dir, tmp_path) -> list[Path]:
    """Ten real Bandai Namco walks, copied into one folder per half."""
    files = sorted((mocap_dir / "bandai_namco_research_motiondataset").glob("dataset-1_walk*.bvh"))[:10]
    assert len(files) == 10
    return files


@pytest.fixture(scope="module")
def sample_db(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("sample") / "sample.h5"
    assert main(["sample", "-o", str(path), "-q"]) == 0
    return path


def names(path: Path) -> list[str]:
    with MotionDatabase.open(path) as db:
        return db.names


def leftovers(folder: Path) -> list[str]:
    """Temporary, partial and lock files a command left in ``folder``."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".") or "partial" in p.name)


# --------------------------------------------------------------------------------------------
# concurrent writers
# --------------------------------------------------------------------------------------------
def test_a_second_writer_is_refused_at_once_naming_the_holder(sample_db, tmp_path, capsys, bandai):
    out = tmp_path / "db.h5"
    shutil.copy(sample_db, out)
    with held_elsewhere(out) as pid:
        for argv in (["import", *bandai[:2], "-o", out, "--append"], ["sample", "-o", out, "-f"],
                     ["splice-all", sample_db, "-o", out, "-f", "-q"]):
            rc, _, err = run(capsys, *argv)
            line = error_line(err)
            assert rc == 2 and f"is being written by process {pid}" in line and str(out) in line, line
    assert names(out) == names(sample_db)  # untouched
    assert leftovers(tmp_path) == [".db.h5.lock"]  # the killed holder's lock: stale, taken over by the next writer
    rc, _, err = run(capsys, "sample", "-o", out, "-f", "-q")
    assert rc == 0 and leftovers(tmp_path) == []


def test_two_appends_at_once_lose_no_clip(bandai, sample_db, tmp_path):
    out = tmp_path / "db.h5"
    shutil.copy(sample_db, out)
    a, b = cli("import", *bandai[:5], "-o", out, "--append", "-q"), cli("import", *bandai[5:], "-o", out, "--append", "-q")
    ra, rb = a.wait(timeout=300), b.wait(timeout=300)
    errs = a.stderr.read() + b.stderr.read()
    assert "Traceback" not in errs
    assert {ra, rb} <= {0, 2} and 0 in (ra, rb)
    expect = len(names(sample_db)) + 5 * (ra == 0) + 5 * (rb == 0)
    assert len(names(out)) == expect, errs  # every append that said it succeeded is in the file
    if 2 in (ra, rb):
        assert "is being written by process" in errs
    assert leftovers(tmp_path) == []


def test_two_new_imports_to_one_path_never_both_succeed(bandai, tmp_path):
    out = tmp_path / "db.h5"
    a, b = cli("import", *bandai[:5], "-o", out, "-q"), cli("import", *bandai[5:], "-o", out, "-q")
    ra, rb = a.wait(timeout=300), b.wait(timeout=300)
    errs = a.stderr.read() + b.stderr.read()
    assert sorted((ra, rb)) == [0, 2], errs
    assert "is being written by process" in errs or "already exists" in errs
    assert len(names(out)) == 5
    assert leftovers(tmp_path) == []


def test_a_lock_left_by_a_dead_process_is_taken_over(sample_db, tmp_path, capsys):
    out = tmp_path / "db.h5"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    lock = tmp_path / ".db.h5.lock"
    import socket

    lock.write_text(json.dumps({"host": socket.gethostname(), "pid": dead.pid, "started": "then", "command": "x"}))
    rc, _, err = run(capsys, "sample", "-o", out, "-q")
    assert rc == 0, err
    assert not lock.exists() and out.is_file()


def test_splice_all_restart_while_the_same_job_runs_is_refused(sample_db, tmp_path, capsys):
    out = tmp_path / "out.h5"
    with held_elsewhere(out):
        rc, _, err = run(capsys, "splice-all", sample_db, "-o", out, "--restart", "-q")
    assert rc == 2 and "is being written by process" in error_line(err)
    assert not out.exists() and not (tmp_path / ".out.h5.parts").exists()


# --------------------------------------------------------------------------------------------
# outputs that are inputs, suffixes, arguments checked before any work
# --------------------------------------------------------------------------------------------
def test_an_output_that_is_an_input_is_refused_whatever_force_says(sample_db, tmp_path, capsys, bandai):
    db = tmp_path / "db.h5"
    shutil.copy(sample_db, db)
    link = tmp_path / "link.h5"
    link.symlink_to(db)
    walk = tmp_path / "walk.bvh"
    shutil.copy(bandai[0], walk)
    before = db.read_bytes(), walk.read_bytes()
    for argv in (["splice-all", db, "-o", db, "--force"], ["splice-all", db, "-o", link, "--force"],
                 ["splice-all", sample_db, "--actions-db", db, "-o", db, "--force"],
                 ["splice-all", sample_db, "--target", f"{db}:0", "-o", db, "--force"],
                 ["splice-all", sample_db, "--target", str(link), "-o", db, "--force"]):
        rc, _, err = run(capsys, *argv)
        assert rc == 2 and "is also the job's input" in error_line(err)
    assert "--target" in error_line(err)
    assert db.read_bytes() == before[0]
    for argv in (["evaluate", db, "-o", db, "--force"], ["import", walk, "-o", walk, "--force"]):
        rc, _, err = run(capsys, *argv)
        assert rc == 2 and "must end in" in error_line(err)
    rc, _, err = run(capsys, "import", tmp_path, "-o", tmp_path / "x.bvh", "--force")
    assert rc == 2 and "must end in .h5" in error_line(err)
    assert (db.read_bytes(), walk.read_bytes()) == before
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("argv, expect", [
    (["splice-all", "{db}", "-o", "{tmp}/out.md"], "must end in .h5"),
    (["sample", "-o", "{tmp}/x.txt"], "must end in .h5"),
    (["evaluate", "{db}", "-o", "{tmp}/r.h5"], "must end in .md"),
    (["render", "{db}", "walk_straight", "-o", "{tmp}/r.jpg"], "must end in .gif"),
    (["export", "{db}", "walk_straight", "-o", "{tmp}/x.h5"], "no export format writes .h5 files"),
])
def test_an_output_suffix_that_does_not_fit_the_command_is_refused(argv, expect, sample_db, tmp_path, capsys):
    rc, _, err = run(capsys, *[a.format(db=sample_db, tmp=tmp_path) for a in argv])
    assert rc == 2 and expect in error_line(err)
    assert list(tmp_path.iterdir()) == []


def test_job_arguments_are_checked_before_any_work(sample_db, tmp_path, capsys):
    folder = tmp_path / "out.h5"
    folder.mkdir()
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", folder)
    assert rc == 2 and "is a folder" in error_line(err)
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", tmp_path / "o.h5", "--method", "splice,splice")
    assert rc == 2 and "asked for twice" in error_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.h5"]  # no .parts left behind


def test_render_frames_are_bounded(sample_db, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["render", str(sample_db), "walk_straight", "-o", str(tmp_path / "x.png"), "--frames", "100000"])
    assert e.value.code == 2
    assert "must be from 1 to 64" in capsys.readouterr().err
    with MotionDatabase.open(sample_db) as db:
        short = min(db.names, key=lambda n: db.clip_info(n)["length"])
        T = db.clip_info(short)["length"]
    if T < 64:
        rc, _, err = run(capsys, "render", sample_db, short, "-o", tmp_path / "x.png", "--frames", "64")
        assert rc == 0 and f"drawing {T}" in err


# --------------------------------------------------------------------------------------------
# one bad file among good ones
# --------------------------------------------------------------------------------------------
def test_an_unexpected_failure_on_one_file_skips_only_that_file(bandai, tmp_path, capsys, monkeypatch):
    import torchsplice.formats.bvh as bvh

    real = bvh.read_bvh

    def flaky(path, *a, **kw):
        if Path(path).name == bandai[3].name:
            raise RuntimeError("a bug met on this one file")
        return real(path, *a, **kw)

    monkeypatch.setattr(bvh, "read_bvh", flaky)
    out = tmp_path / "db.h5"
    rc, _, err = run(capsys, "import", *bandai, "-o", out)
    assert rc == 1 and "Traceback" not in err
    skipped = [ln for ln in err.splitlines() if ln.startswith("skipped ")]
    assert len(skipped) == 1 and bandai[3].name in skipped[0] and "RuntimeError" in skipped[0]
    assert len(names(out)) == 9


# --------------------------------------------------------------------------------------------
# a full disk
# --------------------------------------------------------------------------------------------
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


def fill(folder: Path, leave_mb: float) -> Path:
    """A ballast file that leaves about ``leave_mb`` MB free in ``folder``."""
    free = shutil.disk_usage(folder).free
    ballast = folder / "ballast"
    with open(ballast, "wb") as f:
        f.write(b"\0" * max(0, int(free - leave_mb * 1e6)))
    return ballast


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


# --------------------------------------------------------------------------------------------
# damaged clips and values that are not finite
# --------------------------------------------------------------------------------------------
def nan_copy(sample_db: Path, tmp_path: Path, clip: str) -> Path:
    db = tmp_path / "nan.h5"
    shutil.copy(sample_db, db)
    with h5py.File(db, "r+") as f:
        row = list(f["clips/name"].asstr()[()]).index(clip)
        f["skeletons/0/root_translation"][int(f["clips/start"][row]) + 5] = np.nan
    return db


def test_a_nan_locomotion_is_skipped_for_its_real_reason(sample_db, tmp_path, capsys):
    db = nan_copy(sample_db, tmp_path, "walk_straight")
    rc, out, err = run(capsys, "splice-all", db, "-o", tmp_path / "o.h5", "--workers", "1", "--force-locomotion")
    assert rc == 0, err
    assert "walk_straight has non-finite values (NaN or infinity) from frame 5" in out
    assert "walk_straight does not locomote" not in out
    with MotionDatabase.open(tmp_path / "o.h5") as o:
        assert not any(n.startswith("walk_straight") for n in o.names)


def test_export_refuses_values_that_are_not_finite(sample_db, tmp_path, capsys):
    db = nan_copy(sample_db, tmp_path, "wave")
    rc, _, err = run(capsys, "export", db, "wave", "-o", tmp_path / "w.bvh")
    line = error_line(err)
    assert rc == 2 and "wave" in line and "frame 5" in line
    assert not (tmp_path / "w.bvh").exists() and leftovers(tmp_path) == []


# --------------------------------------------------------------------------------------------
# datasets of different units in one database
# --------------------------------------------------------------------------------------------
def test_a_folder_mixing_datasets_imports_every_file_whatever_the_order(mocap_dir, tmp_path, capsys):
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    picks = [*sorted((mocap_dir / "cmu_graphics_lab").glob("*.bvh"))[:2],
             sorted((mocap_dir / "bandai_namco_research_motiondataset").glob("dataset-1_walk*.bvh"))[0]]
    for order in (picks, picks[::-1]):
        for f in mixed.iterdir():
            f.unlink()
        for n, f in enumerate(order):
            shutil.copy(f, mixed / f"{n}_{f.name}")
        out = tmp_path / "mixed.h5"
        rc, _, err = run(capsys, "import", mixed, "-o", out, "--force", "-q")
        assert rc == 0, err
        rc, out_json, _ = run(capsys, "info", out, "--json")
        info = json.loads(out_json)
        assert info["num_clips"] == 3
        units = {k["spec"]: k["units"] for k in info["skeletons"]}
        assert len(set(units.values())) == 2 and info["units"] == "mixed", units


# --------------------------------------------------------------------------------------------
# termination
# --------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_sigterm_stops_a_job_like_ctrl_c_and_the_rerun_resumes(sample_db, tmp_path):
    out = tmp_path / "o.h5"
    p = cli("splice-all", sample_db, "-o", out, "--workers", "1", "--batch-size", "2",
            env=dict(os.environ, TORCHSPLICE_CHECKPOINT_SECONDS="0"))  # a checkpoint after each task
    parts = tmp_path / ".o.h5.parts"
    deadline = time.time() + 120
    held = lambda: (MotionDatabase.checkpoint_note(parts / "output.h5") or {}).get("tasks", 0)  # noqa: E731
    while time.time() < deadline and not held() and p.poll() is None:  # a task in the staged output
        time.sleep(0.05)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    if p.returncode == 0:
        pytest.skip("the job finished before it could be stopped")
    assert p.returncode == 143 and "Traceback" not in err
    assert "terminated" in err and "run the same command again to resume" in err
    q = cli("splice-all", sample_db, "-o", out, "--workers", "1", "--batch-size", "2")
    sout, err = q.communicate(timeout=300)
    assert q.returncode == 0, err
    assert "from an earlier run" in sout


# --------------------------------------------------------------------------------------------
# determinism: the same inputs give the same bits, whatever the threads and workers
# --------------------------------------------------------------------------------------------
def _digest(path: Path) -> str:
    import hashlib

    h = hashlib.sha1()
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                v = obj[()]
                h.update(name.encode() + (v.tobytes() if v.dtype.kind != "O" else repr(v.tolist()).encode()))
        f.visititems(visit)
    return h.hexdigest()


def test_import_gives_the_same_bits_with_any_thread_count(bandai, tmp_path, capsys):
    import torch

    before = torch.get_num_threads()
    digests = set()
    try:
        for k in (1, 2, 3):
            torch.set_num_threads(k)
            rc, _, err = run(capsys, "import", *bandai[:4], "-o", tmp_path / f"i{k}.h5", "-q")
            assert rc == 0, err
            digests.add(_digest(tmp_path / f"i{k}.h5"))
    finally:
        torch.set_num_threads(before)
    assert len(digests) == 1


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_splice_all_gives_the_same_bits_with_any_workers_and_threads(backend, sample_db, tmp_path, monkeypatch):
    import torch

    if backend == "torch":
        monkeypatch.setenv("TORCHSPLICE_BACKEND", "torch")
    runs = [["--workers", "1"], ["--workers", "2"], ["--workers", "3"]]
    if backend == "compiled":  # each pair is spliced on its own: the batching does not matter either
        runs = [r + ["--batch-size", str(b)] for r, b in zip(runs, (8, 3, 5))]
    digests = set()
    before = torch.get_num_threads()
    try:
        for n, extra in enumerate(runs):
            torch.set_num_threads(1 + n % 2)
            p = cli("splice-all", sample_db, "-o", tmp_path / f"o{n}.h5", "-q", "--method", "splice,naive,cpmc", *extra,
                    env=dict(os.environ, OMP_NUM_THREADS=str(1 + n % 2)))
            _, err = p.communicate(timeout=600)
            assert p.returncode == 0, err
            digests.add(_digest(tmp_path / f"o{n}.h5"))
    finally:
        torch.set_num_threads(before)
    assert len(digests) == 1


# --------------------------------------------------------------------------------------------
# engines that cannot start leave nothing behind
# --------------------------------------------------------------------------------------------
def test_an_unreachable_ray_address_fails_at_once_and_leaves_no_plan(sample_db, tmp_path, capsys):
    pytest.importorskip("ray", reason="Ray is an optional extra (scripts/test.sh installs it)")
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.time()
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", tmp_path / "o.h5", "--engine", "ray",
                     "--ray-address", f"127.0.0.1:{port}")
    assert rc == 2 and f"cannot reach the Ray cluster at 127.0.0.1:{port}" in error_line(err)
    assert time.time() - t0 < 60
    assert list(tmp_path.iterdir()) == []


def test_a_missing_engine_leaves_no_plan_that_blocks_the_next_run(sample_db, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # as if Ray were not installed
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", tmp_path / "o.h5", "--engine", "ray")
    assert rc == 2 and "needs Ray" in error_line(err)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.delitem(sys.modules, "ray")
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", tmp_path / "o.h5", "--workers", "1", "--method", "naive", "-q")
    assert rc == 0, err


# --------------------------------------------------------------------------------------------
# the generic spec says what it guessed
# --------------------------------------------------------------------------------------------
def test_import_prints_the_guessed_roles_once_per_skeleton_and_info_shows_them(mocap_dir, tmp_path, capsys):
    walk = sorted((mocap_dir / "cmu_graphics_lab").glob("*walk*.bvh"))[0]
    copy = tmp_path / "again.bvh"
    shutil.copy(walk, copy)
    out = tmp_path / "g.h5"
    rc, text, err = run(capsys, "import", walk, copy, "-o", out, "--spec", "generic")
    assert rc == 0, err
    assert text.count("joint roles guessed by the 'generic' spec") == 1
    assert "  left leg: LeftUpLeg > LeftLeg > LeftFoot > LeftToeBase" in text
    rc, text, _ = run(capsys, "info", out, "--json")
    roles = json.loads(text)["skeletons"][0]["guessed_roles"]
    assert roles["left_leg"] == ["LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"] and roles["head"] == "Head"
    rc, text, _ = run(capsys, "import", walk, "-o", tmp_path / "s.h5", "--spec", "cmu")
    assert rc == 0 and "joint roles guessed" not in text


def test_import_warns_in_one_line_about_lines_after_the_declared_frames(bandai, tmp_path, capsys):
    f = tmp_path / "keyframes.bvh"
    f.write_text(bandai[0].read_text().rstrip("\n") + "\n1 5 9 13\n")  # as QAvimator writes keyframe indices
    rc, _, err = run(capsys, "import", f, "-o", tmp_path / "k.h5")
    assert rc == 0 and "Traceback" not in err
    warned = [ln for ln in err.splitlines() if ln.startswith("warning: ")]
    assert len(warned) == 1 and str(f) in warned[0] and "ignored" in warned[0]
    assert names(tmp_path / "k.h5") == ["keyframes"]


@pytest.mark.parametrize("preload", [False, True])
def test_a_training_dataset_over_a_damaged_chunk_raises_one_clear_error(sample_db, tmp_path, preload):
    from torchsplice.core.errors import DatabaseError
    from torchsplice.data import MotionDataset

    db = tmp_path / "damaged.h5"
    shutil.copy(sample_db, db)
    with h5py.File(db, "r") as f:
        info = f["skeletons/0/rotations"].id.get_chunk_info(0)
    with open(db, "r+b") as fh:
        fh.seek(info.byte_offset + info.size // 2)
        raw = fh.read(64)
        fh.seek(info.byte_offset + info.size // 2)
        fh.write(bytes(b ^ 0xFF for b in raw))
    with pytest.raises(DatabaseError, match="damaged database: cannot read /skeletons/0/rotations"):
        ds = MotionDataset(db, preload=preload)
        ds[0]


@pytest.mark.parametrize("command", ["retarget", "mirror", "import"])
def test_a_killed_writers_partial_file_is_removed_by_the_next_write_of_that_output(sample_db, tmp_path, capsys, command):
    """A SIGKILLed retarget, mirror or import leaves ``.OUT.h5.partial-HOST-PID``; the next
    command writing that output removes it (its process is dead), and never a live process's,
    another host's or another output's."""
    import socket

    from torchsplice.store.lock import temp_path

    out = tmp_path / "out.h5"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = socket.gethostname()
    stale = out.with_name(f".out.h5.partial-{host}-{dead.pid}")
    alive = out.with_name(f".out.h5.partial-{host}-{os.getppid()}")
    remote = out.with_name(".out.h5.partial-elsewhere-1")
    other = out.with_name(f".other.h5.partial-{host}-{dead.pid}")
    for f in (stale, alive, remote, other):
        f.write_bytes(b"left by a killed writer")
    assert temp_path(out).name.startswith(".out.h5.partial-")
    bvh = tmp_path / "walk.bvh"
    assert run(capsys, "export", sample_db, "walk_straight", "-o", bvh, "-q")[0] == 0
    argv = {"retarget": ["retarget", sample_db, "walk_straight", "--to", "smpl22", "-o", out, "-q"],
            "mirror": ["mirror", sample_db, "walk_straight", "-o", out, "-q"],
            "import": ["import", bvh, "-o", out, "-q"]}[command]
    rc, _, err = run(capsys, *argv)
    assert rc == 0, err
    assert not stale.exists() and alive.exists() and remote.exists() and other.exists()


def test_a_ctrl_c_that_a_library_swallows_still_stops_the_job_as_an_interrupt():
    """Ctrl-C raised inside a weak reference's callback is printed and lost by Python (the Ray
    driver met it so); the handler records it, and the job's check between tasks raises it."""
    from torchsplice.cli.common import on_sigint, on_sigterm, stop_code, stopped
    from torchsplice.core.stop import Terminated, check_stop, clear_stop

    for handler, exc_type, code, word in ((on_sigint, KeyboardInterrupt, 130, "interrupted"),
                                          (on_sigterm, Terminated, 143, "terminated")):
        clear_stop()
        with pytest.raises(exc_type):
            handler(None, None)
        with pytest.raises(exc_type) as got:  # what was swallowed comes back here
            check_stop()
        assert (got.type is Terminated) == (exc_type is Terminated)
        assert stop_code(got.value) == code and stopped(got.value) == word
    clear_stop()
    check_stop()  # nothing asked: nothing raised
