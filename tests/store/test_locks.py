"""One writer per output: a second writer is refused at once naming the holder, concurrent appends
lose no clip, a lock left by a dead process is taken over, and a killed writer's partial file is
removed by the next write of that output. Writers race as separate processes (the command in
its own process where two race; the Python API where one writer meets a held or stale lock)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from torchsplice import export_clips, import_bvh, splice_all, write_sample
from torchsplice.retarget import retarget_clips
from torchsplice.retarget.mirror import mirror_clips
from torchsplice.store.lock import LockedError
from writers import cli, held_elsewhere, leftovers, names


def test_a_second_writer_is_refused_at_once_naming_the_holder(sample_db, tmp_path, bandai_walks):
    out = tmp_path / "db.h5"
    shutil.copy(sample_db, out)
    with held_elsewhere(out) as pid:
        for write in (lambda: import_bvh(bandai_walks[:2], out, append=True),
                      lambda: write_sample(out, overwrite=True),
                      lambda: splice_all(sample_db, out, overwrite=True)):
            with pytest.raises(LockedError, match=f"is being written by process {pid}") as caught:
                write()
            line = str(caught.value)
            assert str(out) in line and "\n" not in line, line
    assert names(out) == names(sample_db)  # untouched
    assert leftovers(tmp_path) == [".db.h5.lock"]  # the killed holder's lock: stale, taken over by the next writer
    write_sample(out, overwrite=True)
    assert leftovers(tmp_path) == []


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


def test_a_lock_left_by_a_dead_process_is_taken_over(tmp_path):
    out = tmp_path / "db.h5"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    lock = tmp_path / ".db.h5.lock"
    import socket

    lock.write_text(json.dumps({"host": socket.gethostname(), "pid": dead.pid, "started": "then", "command": "x"}))
    write_sample(out)
    assert not lock.exists() and out.is_file()


def test_splice_all_restart_while_the_same_job_runs_is_refused(sample_db, tmp_path):
    out = tmp_path / "out.h5"
    with held_elsewhere(out):
        with pytest.raises(LockedError, match="is being written by process") as caught:
            splice_all(sample_db, out, restart=True)
    assert "\n" not in str(caught.value)
    assert not out.exists() and not (tmp_path / ".out.h5.parts").exists()


@pytest.mark.parametrize("command", ["retarget", "mirror", "import"])
def test_a_killed_writers_partial_file_is_removed_by_the_next_write_of_that_output(sample_db, tmp_path, command):
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
    export_clips(sample_db, ["walk_straight"], out=bvh)
    write = {"retarget": lambda: retarget_clips(sample_db, ["walk_straight"], to="smpl22", out=out),
             "mirror": lambda: mirror_clips(sample_db, ["walk_straight"], out=out),
             "import": lambda: import_bvh([bvh], out)}[command]
    report = write()
    assert out.is_file() and (command != "import" or report.ok)  # the import skipped nothing
    assert not stale.exists() and alive.exists() and remote.exists() and other.exists()
