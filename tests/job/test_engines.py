"""The job at scale: engines, shards and merge, locks (:mod:`torchsplice.job`).

Worker processes killed mid-job (retried, or a clean failure, never a hang), ``--shard K/N``
slices merged into the one-shot output, the virtual layout, locks refusing a second writer and
taking over a dead one's, and temporary files of dead processes cleaned up.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from cli_helpers import run
from torchsplice.core.errors import TorchspliceError
from torchsplice.job import merge_job, splice_all
from torchsplice.store.database import MotionDatabase
from torchsplice.store.lock import LockedError
from writers import reaped, splice_all_process

REPO = Path(__file__).resolve().parents[2]


def frames_and_table(path) -> dict:
    """Every clip's data and columns, as plain arrays (the run record and layout left out)."""
    with MotionDatabase.open(path) as db:
        t = db.table()
        out = {k: (list(v) if v.dtype == object else v.tobytes()) for k, v in t.items()}  # NaN-safe, bit for bit
        for k in range(len(db.skeletons)):
            for name, a in db.packed(k).items():
                out[f"{k}/{name}"] = a.tobytes()
    return out


@pytest.fixture(scope="module")
def reference(sample_db, tmp_path_factory):
    """The one-shot run in this process, three methods: what every other way must reproduce."""
    out = tmp_path_factory.mktemp("ref") / "out.h5"
    splice_all(sample_db, out, **JOB, workers=1)
    return out


JOB = dict(methods="splice,naive,cpmc", batch_pairs=4, copy_sources=True)  # the job every test here runs
JOB_FLAGS = ["--method", "splice,naive,cpmc", "--batch-size", "4", "--copy-sources", "-q"]  # the same, on the command line


def children(pid: int) -> list[int]:
    out = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                if int((p / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(p.name))
            except (OSError, IndexError, ValueError):
                pass
    return out


def workers_of(driver: int) -> list[int]:
    """The local engine's worker processes: children of the driver's fork server."""
    return [w for server in children(driver) for w in children(server)]


def kill_one_worker(proc, when) -> str:
    """SIGKILL the first worker of the job ``proc`` seen once ``when()`` holds, let the job end,
    and return its stderr (asserting that a worker was killed)."""
    killed = None
    with reaped(proc):
        deadline = time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline and killed is None:
            ws = workers_of(proc.pid) if when() else []
            if ws:
                os.kill(ws[0], signal.SIGKILL)
                killed = ws[0]
            time.sleep(0.005)
        _, stderr = proc.communicate(timeout=180)
    assert killed is not None, "no worker was found to kill"
    return stderr


def start_job(db, out, **options):
    """The job (:data:`JOB`, and ``options``) through the Python API, in a process of its own."""
    env = dict(os.environ, PYTHONUNBUFFERED="1", TORCHSPLICE_CHECKPOINT_SECONDS="0")  # a checkpoint after each task
    return splice_all_process(db, out, **{**JOB, **options}, env=env, cwd=REPO)


def start_cli_job(db, out, *extra):
    """The job (:data:`JOB_FLAGS`, and ``extra``) through ``python -m torchsplice splice-all``."""
    env = dict(os.environ, PYTHONUNBUFFERED="1", TORCHSPLICE_CHECKPOINT_SECONDS="0")  # a checkpoint after each task
    return subprocess.Popen([sys.executable, "-m", "torchsplice", "splice-all", str(db), "-o", str(out), *JOB_FLAGS,
                             *extra], cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


# --------------------------------------------------------------------------------------------
# local worker processes
# --------------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="finds worker processes through /proc")
def test_a_killed_worker_is_replaced_and_the_output_is_unchanged(sample_db, reference, tmp_path):
    out = tmp_path / "out.h5"
    proc = start_job(sample_db, out, workers=2, batch_pairs=1)
    merged = lambda: (MotionDatabase.checkpoint_note(tmp_path / ".out.h5.parts" / "output.h5") or {}).get("tasks")  # noqa: E731
    stderr = kill_one_worker(proc, when=merged)  # once a task is merged
    assert proc.returncode == 0, stderr
    assert frames_and_table(out) == frames_and_table(reference)


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="finds worker processes through /proc")
def test_a_worker_killed_before_any_task_finishes_is_retried_under_a_console_script(sample_db, reference, tmp_path):
    """A console script (``torchsplice``: a file run as ``__main__``, guarded) whose worker is
    killed in the first round, as an out-of-memory kill would: the task runs again, no
    misdiagnosis of an unguarded script."""
    script = tmp_path / "torchsplice-console"
    script.write_text("import sys\nfrom torchsplice.cli import main\nif __name__ == '__main__':\n    sys.exit(main())\n")
    out = tmp_path / "out.h5"
    env = dict(os.environ, PYTHONUNBUFFERED="1", PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, str(script), "splice-all", str(sample_db), "-o", str(out), *JOB_FLAGS,
                             "--workers", "2", "--batch-size", "1"], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    stderr = kill_one_worker(proc, when=lambda: True)  # at once: no task has finished yet
    assert proc.returncode == 0 and "__main__" not in stderr, stderr
    assert frames_and_table(out) == frames_and_table(reference)


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="finds worker processes through /proc")
def test_workers_killed_again_and_again_end_the_job_cleanly(sample_db, tmp_path):
    """The command line's end of it: exit code 2 and one line, no traceback."""
    out = tmp_path / "out.h5"
    proc = start_cli_job(sample_db, out, "--workers", "2", "--batch-size", "1")
    with reaped(proc):
        deadline = time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline:
            for w in workers_of(proc.pid):
                try:
                    os.kill(w, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            time.sleep(0.02)
        stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 2, stderr
    assert stderr.strip().count("\n") == 0 and "worker processes died 3 times in a row" in stderr and "Traceback" not in stderr
    assert not out.exists() and (tmp_path / ".out.h5.parts" / "plan.json").is_file()  # kept, to resume


def test_a_pool_that_breaks_while_tasks_are_handed_out_is_a_break_not_a_crash(monkeypatch):
    """A worker can die between two submissions; the engine must retry, not raise a traceback."""
    from concurrent.futures import Future
    from concurrent.futures.process import BrokenProcessPool
    from types import SimpleNamespace

    from torchsplice.job.engines import EngineContext
    from torchsplice.job.engines.local import LocalEngine

    tasks = [SimpleNamespace(id=f"t{k}") for k in range(4)]
    starts = []

    class Pool:
        def __init__(self, broken_after):
            self.broken_after, self.handed = broken_after, 0
            self._processes = {}

        def submit(self, fn, index):
            if self.handed == self.broken_after:
                raise BrokenProcessPool("a child process terminated abruptly")
            self.handed += 1
            f = Future()
            f.set_result((tasks[index].id, 0))
            return f

        def shutdown(self, wait=True, cancel_futures=False):
            pass

    config = SimpleNamespace(worker_count=lambda: 2)
    engine = LocalEngine(EngineContext(config, SimpleNamespace(tasks=tasks), Path("plan.json"), None, None, Path("."),
                                       False))

    def start():  # the first pool breaks after two tasks were handed out, the next one works
        starts.append(1)
        engine.pool = Pool(2 if len(starts) == 1 else None)

    monkeypatch.setattr(engine, "_start", start)
    finished = []
    engine.run(tasks, lambda task, _: finished.append(task.id))
    assert sorted(finished) == [t.id for t in tasks] and len(starts) == 2


@pytest.mark.slow
def test_a_killed_driver_leaves_no_worker_behind(sample_db, tmp_path):
    out = tmp_path / "out.h5"
    proc = start_job(sample_db, out, workers=2, batch_pairs=1)
    ws = []
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline and not ws:
        ws = workers_of(proc.pid)
        time.sleep(0.01)
    proc.kill()
    proc.wait()
    assert ws, "no worker process was seen"
    def running(pid: int) -> bool:  # a zombie waiting for its parent to reap it has exited
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
        except OSError:
            return False

    deadline = time.monotonic() + 20
    while any(running(w) for w in ws) and time.monotonic() < deadline:
        time.sleep(0.1)
    alive = [w for w in ws if running(w)]
    for w in alive:
        os.kill(w, signal.SIGKILL)  # do not leave them to the next test
    assert not alive, f"workers {alive} outlived their driver"


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="finds worker processes through /proc")
def test_a_supervisor_reading_the_output_of_a_killed_driver_is_not_left_waiting(sample_db, tmp_path):
    """``subprocess.run(..., capture_output=True)`` around a job whose driver is SIGKILLed: the
    driver stays a zombie until the supervisor reaps it, which it does only once the output
    pipes close; the workers holding them must notice the zombie and exit."""
    out = tmp_path / "out.h5"
    proc = start_job(sample_db, out, workers=2, batch_pairs=1)
    with reaped(proc):
        deadline, seen = time.monotonic() + 120, []
        while proc.poll() is None and time.monotonic() < deadline and not seen:
            seen = workers_of(proc.pid)  # kept: a worker may finish between this look and the next
            time.sleep(0.01)
        assert seen, "no worker process was seen"
        os.kill(proc.pid, signal.SIGKILL)  # not reaped: a zombie until communicate() has read both pipes to the end
        t0 = time.monotonic()
        proc.communicate(timeout=30)
        assert time.monotonic() - t0 < 30


@pytest.mark.slow
def test_an_unguarded_script_gets_a_clear_error(sample_db, tmp_path):
    script = tmp_path / "unguarded.py"
    out = tmp_path / "out.h5"
    script.write_text("from torchsplice.job import JobConfig, SpliceJob\n"
                      f"SpliceJob(JobConfig(database={str(sample_db)!r}, output={str(out)!r}, workers=2), progress=False).run()\n")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode != 0 and 'if __name__ == "__main__":' in done.stderr


# --------------------------------------------------------------------------------------------
# an engine of one's own
# --------------------------------------------------------------------------------------------
TOY_ENGINE = '''
from concurrent.futures import ThreadPoolExecutor, as_completed

from torchsplice.job.engines import Engine, register_engine
from torchsplice.job.task import run_task


class ThreadsEngine(Engine):
    """The tasks on two threads of this process (a concurrent.futures executor)."""

    name = "threads"

    def describe(self):
        return "two threads of this process"

    def run(self, tasks, done):
        ctx = self.ctx
        with ThreadPoolExecutor(max_workers=2) as pool:
            futures = {pool.submit(run_task, ctx.plan, t, ctx.sources, ctx.config): t for t in tasks}
            for f in as_completed(futures):  # done() one call at a time, in order of completion
                task = futures[f]
                part = f.result()
                ctx.write_shard(task, part)
                done(task, part)


register_engine("threads", ThreadsEngine)
'''


def test_an_engine_of_ones_own_is_one_module_and_a_registration(sample_db, reference, tmp_path, monkeypatch, capsys):
    """An engine over a concurrent.futures executor, registered by a plug-in module, runs the job
    through the command line and the Python API, with the same bits as the built-in engines."""
    import torchsplice.job.engines.registry as engines

    monkeypatch.setattr(engines, "_ENGINES", dict(engines._ENGINES))  # the registration ends with the test
    (tmp_path / "toy_threads.py").write_text(TOY_ENGINE)
    monkeypatch.syspath_prepend(str(tmp_path))
    out = tmp_path / "cli.h5"
    code, text, err = run(capsys, "--plugin", "toy_threads", "splice-all", sample_db, "-o", out, *JOB_FLAGS[:-1],
                          "--engine", "threads")
    assert code == 0, err
    assert "with two threads of this process" in text
    assert frames_and_table(out) == frames_and_table(reference)
    from torchsplice.job.engines import available_engines

    assert available_engines()[:2] == ("local", "ray") and "threads" in available_engines()
    summary = splice_all(sample_db, tmp_path / "api.h5", engine="threads", methods="splice,naive,cpmc", batch_pairs=4,
                         copy_sources=True, progress=False)
    assert summary.engine == "two threads of this process"
    assert frames_and_table(tmp_path / "api.h5") == frames_and_table(reference)


def test_an_unknown_engine_names_the_registered_ones(sample_db, tmp_path, capsys):
    from torchsplice.job.engines import register_engine

    with pytest.raises(SystemExit) as exit_:  # a usage mistake, said by the argument parser
        run(capsys, "splice-all", sample_db, "-o", tmp_path / "x.h5", "--engine", "nothing")
    assert exit_.value.code == 2 and "invalid choice: 'nothing'" in capsys.readouterr().err
    with pytest.raises(TorchspliceError, match="unknown engine 'nothing'; choose one of local, ray"):
        splice_all(sample_db, tmp_path / "x.h5", engine="nothing")
    for bad in ("Bad", "a b", "", "x\n"):
        with pytest.raises(TorchspliceError, match="must be lower case letters"):
            register_engine(bad, lambda ctx: None)
    with pytest.raises(TorchspliceError, match="'local' is already registered"):
        register_engine("local", lambda ctx: None)


# --------------------------------------------------------------------------------------------
# slices and merge
# --------------------------------------------------------------------------------------------
def test_slices_then_merge_equal_the_one_shot_run(sample_db, reference, tmp_path):
    out = tmp_path / "out.h5"
    summary = splice_all(sample_db, out, **JOB, shard="2/3")
    text = "\n".join(summary.lines())
    assert summary.shard == (2, 3) and "slice 2/3" in text and "torchsplice merge" in text and not out.exists()
    with pytest.raises(TorchspliceError, match="slices of 3 done: 2; missing: 1, 3") as exc:
        merge_job(out, progress=False)
    assert "\n" not in str(exc.value)
    for k in ("1/3", "3/3"):
        splice_all(sample_db, out, **JOB, shard=k, workers=2)
    merge_job(out, progress=False)
    assert frames_and_table(out) == frames_and_table(reference)
    assert not (tmp_path / ".out.h5.parts").exists()
    with h5py.File(out, "r") as f:
        assert json.loads(f.attrs["run"])["plan_sha256"]


def test_a_slice_resumes_into_a_full_run(sample_db, reference, tmp_path):
    """Slices done by hand count as finished tasks for an ordinary run of the same job."""
    out = tmp_path / "out.h5"
    splice_all(sample_db, out, **JOB, shard="1/2")
    summary = splice_all(sample_db, out, **JOB)
    assert 0 < summary.resumed < summary.spliced and "from an earlier run" in "\n".join(summary.lines())
    assert frames_and_table(out) == frames_and_table(reference)


def test_merge_without_a_job(tmp_path, capsys):
    code, _, err = run(capsys, "merge", tmp_path / "nothing.h5")
    assert code == 2 and "no unfinished splice-all job" in err


# --------------------------------------------------------------------------------------------
# the virtual layout
# --------------------------------------------------------------------------------------------
def test_virtual_layout_reads_like_the_copy(sample_db, reference, tmp_path):
    """The command's refusal of --copy-sources with --layout virtual: tests/cli/test_command_words.py."""
    out = tmp_path / "out.h5"
    with pytest.raises(TorchspliceError, match="copy_sources needs layout copy"):  # a virtual output holds spliced clips only
        splice_all(sample_db, out, **JOB, layout="virtual")
    splice_all(sample_db, out, **dict(JOB, copy_sources=False), layout="virtual")
    shards = tmp_path / "out.h5.shards"
    assert shards.is_dir() and len(list(shards.glob("*/part-*.h5"))) > 1  # in the run's own folder
    with h5py.File(out, "r") as f:
        assert f["skeletons/0/rotations"].is_virtual and not f["skeletons/0/rotations"][()].size == 0
    want = frames_and_table(reference)
    got = frames_and_table(out)
    spliced = [n for n in want["name"] if "+" in n]
    assert got["name"][:len(spliced)] == want["name"][:len(spliced)]
    cwd = os.getcwd()
    try:  # the shards are found relative to the output, wherever one reads it from
        os.chdir("/")
        with MotionDatabase.open(out) as a, MotionDatabase.open(reference) as b:
            for name in spliced:
                assert np.array_equal(a.read(name).rotations.numpy(), b.read(name).rotations.numpy())
                assert np.array_equal(a.read_frame_column(name, "action_frame"), b.read_frame_column(name, "action_frame"))
    finally:
        os.chdir(cwd)
    # another job over the same output replaces the shards; none of the old ones is reused
    splice_all(sample_db, out, methods="naive", layout="virtual", overwrite=True)
    with MotionDatabase.open(out) as db:
        assert set(db.table()["method"]) == {"naive"} and len(db) == 25
        assert np.isfinite(db.read(len(db) - 1).rotations.numpy()).all()
    assert not list(tmp_path.glob(".out.h5.shards.*"))


# --------------------------------------------------------------------------------------------
# locks and temporary files
# --------------------------------------------------------------------------------------------
def test_a_second_writer_is_refused_and_a_dead_ones_lock_is_taken_over(sample_db, tmp_path):
    out = tmp_path / "out.h5"
    lock = tmp_path / ".out.h5.lock"
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock.write_text(json.dumps({"host": socket.gethostname(), "pid": holder.pid, "started": "then"}))
        with pytest.raises(LockedError) as exc:
            splice_all(sample_db, out)
        err = str(exc.value)
        assert "\n" not in err
        assert f"being written by process {holder.pid} on {socket.gethostname()}" in err and str(lock) in err
        assert not out.exists() and lock.exists()
    finally:
        holder.kill()
        holder.wait()

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    lock.write_text(json.dumps({"host": socket.gethostname(), "pid": dead.pid, "started": "then"}))
    splice_all(sample_db, out)
    assert out.exists() and not lock.exists()


def test_a_lock_from_another_host_is_not_broken(sample_db, tmp_path):
    out = tmp_path / "out.h5"
    (tmp_path / ".out.h5.lock").write_text(json.dumps({"host": "elsewhere.example", "pid": 1, "started": "then"}))
    with pytest.raises(LockedError, match="on elsewhere.example"):
        splice_all(sample_db, out)
    assert not out.exists()


def test_temporary_files_of_dead_processes_on_this_host_are_removed(sample_db, tmp_path):
    out = tmp_path / "out.h5"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    living = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        me = socket.gethostname()
        stale = tmp_path / f".out.h5.partial-{me}-{dead.pid}"
        alive = tmp_path / f".out.h5.partial-{me}-{living.pid}"
        remote = tmp_path / ".out.h5.partial-elsewhere.example-12345"
        for f in (stale, alive, remote):
            f.write_bytes(b"half")
        splice_all(sample_db, out)
        assert not stale.exists() and alive.exists() and remote.exists()
    finally:
        living.kill()
        living.wait()
