"""Outputs, plans and slices under attack: paths without a name, an empty ``-o``, the file
system's root, file names too long for the files written beside them, a plan that is not a
JSON object, and slice counts in the quintillions. Each gets one line, before any work."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from cli_helpers import error_line, run_any as run  # a usage mistake (said by the argument parser) as its exit code
from torchsplice.store.lock import MAX_NAME_BYTES, temp_path
from writers import leftovers


def test_export_into_the_current_folder_by_dot(sample_db, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code, _, err = run(capsys, "export", sample_db, "--all", "-o", ".", "-q")
    assert code == 0, err
    assert len(list(tmp_path.glob("*.bvh"))) == 10 and not list(tmp_path.glob(".*.lock"))


@pytest.mark.parametrize("argv", [["export", "{db}", "--all", "-o", ""], ["export", "{db}", "walk_straight", "-o", ""],
                                  ["merge", ""], ["merge", "."], ["splice-all", "{db}", "-o", ""],
                                  ["export", "{db}", "--all", "-o", "/"]])
def test_outputs_without_a_name_get_one_line(sample_db, tmp_path, monkeypatch, capsys, argv):
    monkeypatch.chdir(tmp_path)
    root_before = set(os.listdir("/"))
    code, _, err = run(capsys, *[str(sample_db) if a == "{db}" else a for a in argv])
    assert code == 2
    error_line(err)
    assert set(os.listdir("/")) == root_before and not list(tmp_path.iterdir())


def test_a_plan_that_is_not_an_object_is_one_line(sample_db, tmp_path, capsys):
    out = tmp_path / "out.h5"
    work = tmp_path / ".out.h5.parts"
    work.mkdir()
    for text in ("[1, 2, 3]", '"a plan"', "null", "{", '{"version": 3}'):
        (work / "plan.json").write_text(text)
        code, _, err = run(capsys, "merge", out)
        assert code == 2
        error_line(err)
        assert "not a readable job plan" in err or "version" in err, err


@pytest.mark.parametrize("shard", ["", "1/99999999999999999999", "1/2000000", "0/3", "a/b", "3/2", "1/" + "9" * 500])
def test_slices_are_bounded_and_an_empty_one_is_a_mistake(sample_db, tmp_path, capsys, shard):
    t0 = time.perf_counter()
    code, _, err = run(capsys, "splice-all", sample_db, "-o", tmp_path / "out.h5", "--shard", shard)
    assert code == 2 and time.perf_counter() - t0 < 10
    error_line(err)
    assert "--shard" in err and len(err) < 300, err
    assert not list(tmp_path.iterdir())


def test_missing_slices_are_said_as_ranges(sample_db, tmp_path, capsys):
    out = tmp_path / "out.h5"
    assert run(capsys, "splice-all", sample_db, "-o", out, "--shard", "1/100000", "-q")[0] == 0
    code, _, err = run(capsys, "merge", out)
    assert code == 2
    error_line(err)
    assert "slices of 100000 done: 1; missing: 2-100000" in err and len(err) < 400, err


def test_long_output_names_are_refused_before_any_work_and_temporaries_stay_short(sample_db, tmp_path, capsys):
    for n in (MAX_NAME_BYTES + 1, 250):
        name = "x" * (n - 3) + ".h5"
        for argv in (["sample", "-o", tmp_path / name], ["splice-all", sample_db, "-o", tmp_path / name],
                     ["import", tmp_path / "none.bvh", "-o", tmp_path / name]):
            t0 = time.perf_counter()
            code, _, err = run(capsys, *argv)
            assert code == 2 and time.perf_counter() - t0 < 10, argv
            error_line(err)
            assert f"file name is {n} bytes long" in err, err
        assert not list(tmp_path.iterdir())
    name = "é" * ((MAX_NAME_BYTES - 3) // 2) + ".h5"  # as long as allowed, in two-byte characters
    assert len(name.encode()) <= MAX_NAME_BYTES
    assert len(temp_path(tmp_path / name).name.encode()) < 200
    code, _, err = run(capsys, "sample", "-o", tmp_path / name, "-q")
    assert code == 0, err
    code, text, err = run(capsys, "splice-all", tmp_path / name, "-o", tmp_path / ("y" * (MAX_NAME_BYTES - 3) + ".h5"),
                          "--batch-size", "5", "-q")
    assert code == 0, err
    assert {p.name[:1] for p in tmp_path.iterdir()} == {"é", "y"}  # no temporary left


def test_temporary_names_carry_host_and_pid_and_fit(tmp_path):
    short = temp_path(tmp_path / "out.h5")
    assert short.name.startswith(".out.h5.partial-") and short.name.endswith(f"-{os.getpid()}")
    long = temp_path(tmp_path / ("z" * 240 + ".h5"), "staged")
    assert ".staged-" in long.name and len(long.name.encode()) < 200
    assert temp_path(tmp_path / ("z" * 240 + ".h5")) != temp_path(tmp_path / ("z" * 239 + "w.h5"))
    assert json.dumps(str(long))  # a plain str path
    assert Path(long).parent == tmp_path


@pytest.mark.parametrize("window", ["1e-300", "0", "-5", "nan", "inf", "0.5"])
def test_windows_shorter_than_a_second_are_refused(tmp_path, capsys, window):
    from torchsplice.formats.bvh import write_bvh
    from torchsplice.sample import sample_motions

    write_bvh(sample_motions()[0], tmp_path / "walk.bvh")
    code, _, err = run(capsys, "import", tmp_path / "walk.bvh", "-o", tmp_path / "db.h5", "--spec", "sample",
                       "--window", window)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "--window" in err and ("at least 1 s" in err or "must be a positive number" in err), err
    assert not (tmp_path / "db.h5").exists()


@pytest.mark.parametrize("address, why", [("127.0.0.1:99999", "port from 1 to 65535"),
                                          ("127.0.0.1:0", "port from 1 to 65535"), ("nohost", "HOST:PORT")])
def test_ray_addresses_that_cannot_be_ports_get_one_line(address, why):
    from torchsplice.core.errors import TorchspliceError
    from torchsplice.job.engines.ray_cluster import _check_reachable

    with pytest.raises(TorchspliceError, match=why):
        _check_reachable(address, timeout=2)


def test_a_ray_address_that_answers_but_is_not_ray_is_refused_at_once():
    """A plain HTTP server (a dashboard's port, an easy mix-up) on 127.0.0.1: refused in one
    line within seconds, not waited on."""
    import http.server
    import threading

    from torchsplice.core.errors import TorchspliceError
    from torchsplice.job.engines.ray_cluster import _check_reachable

    server = http.server.HTTPServer(("127.0.0.1", 0), http.server.BaseHTTPRequestHandler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        t0 = time.perf_counter()
        with pytest.raises(TorchspliceError, match="answers, but not as a Ray cluster does"):
            _check_reachable(f"127.0.0.1:{server.server_address[1]}", timeout=3)
        assert time.perf_counter() - t0 < 5
    finally:
        server.shutdown()
        server.server_close()


def test_a_stale_ray_address_in_the_environment_is_checked_and_no_address_starts_a_local_instance(monkeypatch):
    from torchsplice.core.errors import TorchspliceError
    from torchsplice.job.engines.ray_cluster import _ray_address

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert _ray_address(None) == ("local", "")
    monkeypatch.setenv("RAY_ADDRESS", "10.1.2.3:6379")
    assert _ray_address(None) == ("10.1.2.3:6379", "RAY_ADDRESS")
    monkeypatch.setenv("RAY_TMPDIR", "/nonexistent-torchsplice")
    with pytest.raises(TorchspliceError, match="auto: no Ray cluster was started on this machine"):
        _ray_address("auto")


def test_a_rerun_of_merge_removes_what_a_killed_merge_left(sample_db, tmp_path, capsys):
    out = tmp_path / "out.h5"
    assert run(capsys, "splice-all", sample_db, "-o", out, "--shard", "1/1", "--batch-size", "5", "-q")[0] == 0
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".out.h5.partial-{socket.gethostname()}-{dead.pid}"
    stale.write_bytes(b"x" * 1000)  # as a SIGKILLed merge leaves it
    code, _, err = run(capsys, "merge", out)
    assert code == 0, err
    assert not stale.exists()


def test_a_page_holds_a_bounded_number_of_frames(tmp_path, capsys):
    from dataclasses import replace

    from torchsplice.store.database import MotionDatabase
    from torchsplice.sample import sample_motions
    from torchsplice.specs import load_spec
    from torchsplice.viz.viewer import MAX_PAGE_FRAMES, build_viewer

    walk = sample_motions()[0]
    reps = MAX_PAGE_FRAMES // (3 * walk.num_frames) + 1  # each clip over a third of the bound
    db = tmp_path / "long.h5"
    with MotionDatabase.create(db) as w:
        for k in range(4):
            w.append(replace(walk, name=f"long{k}", rotations=walk.rotations.repeat(reps, 1, 1),
                             root_translation=walk.root_translation.repeat(reps, 1)), spec=load_spec("sample"))
    html, contents = build_viewer(db)
    assert contents.names == ["long0", "long1"] and contents.cut
    assert len(html) < 40e6
    code, _, err = run(capsys, "view", db, "long0", "long1", "long2", "-o", tmp_path / "v.html")
    assert code == 2 and "more than" in err and not (tmp_path / "v.html").exists()
    error_line(err)


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]  # closed once the socket is: nobody listens there


@pytest.mark.parametrize("how", ["RAY_ADDRESS", "auto"])
def test_a_stale_ray_cluster_record_is_one_line_at_once(sample_db, tmp_path, monkeypatch, capsys, how):
    """A ``RAY_ADDRESS`` left in the environment, or ``auto`` when Ray's record on this machine
    names a cluster that is gone: one line within seconds, not a wait on Ray."""
    pytest.importorskip("ray", reason="Ray is not installed (scripts/test.sh installs it)")
    address = f"127.0.0.1:{_closed_port()}"
    extra = []
    if how == "RAY_ADDRESS":
        monkeypatch.setenv("RAY_ADDRESS", address)
    else:
        (tmp_path / "ray").mkdir()
        (tmp_path / "ray" / "ray_current_cluster").write_text(address + "\n")
        monkeypatch.setenv("RAY_TMPDIR", str(tmp_path))
        extra = ["--ray-address", "auto"]
    t0 = time.perf_counter()
    code, _, err = run(capsys, "splice-all", sample_db, "-o", tmp_path / "out.h5", "--engine", "ray", *extra)
    assert code == 2 and time.perf_counter() - t0 < 15, err
    error_line(err)
    assert f"cannot reach the Ray cluster at {address}" in err, err
    assert not (tmp_path / "out.h5").exists()


def test_an_output_that_is_an_input_is_refused_whatever_force_says(sample_db, tmp_path, capsys, bandai_walks):
    db = tmp_path / "db.h5"
    shutil.copy(sample_db, db)
    link = tmp_path / "link.h5"
    link.symlink_to(db)
    walk = tmp_path / "walk.bvh"
    shutil.copy(bandai_walks[0], walk)
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
