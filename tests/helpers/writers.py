"""Helpers of the tests of writers (locks, full disks, killed processes, determinism): a command in
its own process, another process holding an output's lock, what a command left behind."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

from torchsplice.store.database import MotionDatabase

REPO = Path(__file__).resolve().parents[2]


def cli(*argv, env: dict | None = None) -> subprocess.Popen:
    env = dict(os.environ if env is None else env, PYTHONPATH=str(REPO))
    return subprocess.Popen([sys.executable, "-m", "torchsplice", *map(str, argv)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


SPLICE_ALL = """
import json, sys
from torchsplice.job import splice_all

if __name__ == "__main__":
    options = json.loads(sys.argv[1])
    s = splice_all(options.pop("database"), options.pop("output"), **options)
    print(json.dumps({"pairs": s.pairs, "spliced": s.spliced, "resumed": s.resumed, "skipped": s.skipped,
                      "lines": s.lines()}))
"""


def splice_all_process(database, output, *, env: dict | None = None, cwd=None, **options) -> subprocess.Popen:
    """``splice_all(database, output, **options)`` (the Python API) in a process of its own, to
    kill it or to give it an environment; its last line of stdout is the summary as JSON
    (``pairs``, ``spliced``, ``resumed``, ``skipped``, ``lines``)."""
    env = dict(os.environ if env is None else env, PYTHONPATH=str(REPO))
    args = json.dumps({"database": str(database), "output": str(output), **options})
    return subprocess.Popen([sys.executable, "-c", SPLICE_ALL, args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, cwd=cwd)


@contextlib.contextmanager
def reaped(proc: subprocess.Popen):
    """Yields ``proc``; on leaving, even by a failed assertion, kills it if it still runs, waits
    for it and closes its pipes, so that no test leaves a process or a file handle behind."""
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for stream in (proc.stdin, proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()


def killed_when(proc: subprocess.Popen, ready, seconds: float = 120.0) -> None:
    """SIGKILL ``proc`` once ``ready()`` is true (polled every 5 ms, for at most ``seconds``),
    and wait for it; fails if it ended first, with the end of its stderr."""
    import signal
    import time

    deadline = time.monotonic() + seconds
    while proc.poll() is None and time.monotonic() < deadline and not ready():
        time.sleep(0.005)
    assert proc.poll() is None, "the job ended before it could be killed: " + proc.stderr.read()[-2000:]
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL


def summary_of(stdout: str) -> dict:
    """The summary a :func:`splice_all_process` printed."""
    return json.loads(stdout.strip().splitlines()[-1])


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


def names(path: Path) -> list[str]:
    with MotionDatabase.open(path) as db:
        return db.names


def leftovers(folder: Path) -> list[str]:
    """Temporary, partial and lock files a command left in ``folder``."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".") or "partial" in p.name)


def fill(folder: Path, leave_mb: float) -> Path:
    """A ballast file that leaves about ``leave_mb`` MB free in ``folder``."""
    free = shutil.disk_usage(folder).free
    ballast = folder / "ballast"
    with open(ballast, "wb") as f:
        f.write(b"\0" * max(0, int(free - leave_mb * 1e6)))
    return ballast


def nan_copy(sample_db: Path, tmp_path: Path, clip: str) -> Path:
    db = tmp_path / "nan.h5"
    shutil.copy(sample_db, db)
    with h5py.File(db, "r+") as f:
        row = list(f["clips/name"].asstr()[()]).index(clip)
        f["skeletons/0/root_translation"][int(f["clips/start"][row]) + 5] = np.nan
    return db


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
