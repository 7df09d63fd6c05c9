"""One writer per output: a second writer is refused at once naming the holder, concurrent appends
lose no clip, a lock left by a dead process is taken over, and a killed writer's partial file is
removed by the next write of that output. Writers race as separate processes."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from cli_helpers import error_line, run
from writers import cli, held_elsewhere, leftovers, names


def test_a_second_writer_is_refused_at_once_naming_the_holder(sample_db, tmp_path, capsys, bandai_walks):
    out = tmp_path / "db.h5"
    shutil.copy(sample_db, out)
    with held_elsewhere(out) as pid:
        for argv in (["import", *bandai_walks[:2], "-o", out, "--append"], ["sample", "-o", out, "-f"],
                     ["splice-all", sample_db, "-o", out, "-f", "-q"]):
            rc, _, err = run(capsys, *argv)
            line = error_line(err)
            assert rc == 2 and f"is being written by process {pid}" in line and str(out) in line, line
    assert names(out) == names(sample_db)  # untouched
    assert leftovers(tmp_path) == [".db.h5.lock"]  # the killed holder's lock: stale, taken over by the next writer
    rc, _, err = run(capsys, "sample", "-o", out, "-f", "-q")
    assert rc == 0 and leftovers(tmp_path) == []


def test_two_appends_at_once_lose_no_clip(bandai_walks, sample_db, tmp_path):
    out = tmp_path / "db.h5"
    shutil.copy(sample_db, out)
    a, b = cli("import", *bandai_walks[:5], "-o", out, "--append", "-q"), cli("import", *bandai_walks[5:], "-o", out, "--append", "-q")
    ra, rb = a.wait(timeout=300), b.wait(timeout=300)
    errs = a.stderr.read() + b.stderr.read()
    assert "Traceback" not in errs
    assert {ra, rb} <= {0, 2} and 0 in (ra, rb)
    expect = len(names(sample_db)) + 5 * (ra == 0) + 5 * (rb == 0)
    assert len(names(out)) == expect, errs  # every append that said it succeeded is in the file
    if 2 in (ra, rb):
        assert "is being written by process" in errs
    assert leftovers(tmp_path) == []


def test_two_new_imports_to_one_path_never_both_succeed(bandai_walks, tmp_path):
    out = tmp_path / "db.h5"
    a, b = cli("import", *bandai_walks[:5], "-o", out, "-q"), cli("import", *bandai_walks[5:], "-o", out, "-q")
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
