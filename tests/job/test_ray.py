"""``splice-all --engine ray`` on a real two-node Ray cluster (see tests/helpers/ray_scenarios.py).

The cluster runs in a private network namespace (``unshare --net``, loopback only), so Ray
binds 127.0.0.1 and nothing leaves the machine; it is started and stopped by the scenario
script, by the handles of its own processes. Every run must equal the local engine's output
bit for bit: a plain run, one whose worker process is killed mid-task, one that loses a node
mid-job, and one whose driver is killed and rerun (it resumes from the finished shards).
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import tempfile
import sys
from pathlib import Path

import pytest

from torchsplice.cli import main
from torchsplice.store.database import MotionDatabase

REPO = Path(__file__).resolve().parents[2]


def _why_not() -> str | None:
    if importlib.util.find_spec("ray") is None:
        return "Ray is not installed (scripts/test.sh installs it: pip install 'torchsplice[ray]')"
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "needs unshare and ip (util-linux, iproute2) for a private network namespace"
    if os.geteuid() != 0:
        return "needs root for a private network namespace (unshare --net)"
    return None


pytestmark = [pytest.mark.slow, pytest.mark.skipif(_why_not() is not None, reason=_why_not() or ""),
              pytest.mark.timeout(1800)]  # the first test also starts the cluster and runs its scenarios (up to 900 s)


def frames_and_table(path) -> dict:
    with MotionDatabase.open(path) as db:
        t = db.table()
        out = {k: (list(v) if v.dtype == object else v.tobytes()) for k, v in t.items()}
        for k in range(len(db.skeletons)):
            for name, a in db.packed(k).items():
                out[f"{k}/{name}"] = a.tobytes()
    return out


def assert_same(path, want, what) -> None:
    got = frames_and_table(path)
    differ = sorted(k for k in set(got) | set(want) if got.get(k) != want.get(k))
    assert not differ, f"{what}: {differ} differ from the local engine's output"


@pytest.fixture(scope="module")
def scenarios():
    # a short folder of its own: Ray's socket paths under it must stay within AF_UNIX's 107 bytes,
    # which pytest's own temporary folders (deeper still under pytest-xdist) can exceed
    tmp = Path(tempfile.mkdtemp(prefix="tsray-"))
    try:
        yield _scenarios(tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _scenarios(tmp: Path):
    db = tmp / "sample.h5"
    assert main(["sample", "-o", str(db), "-q"]) == 0
    ref = tmp / "local.h5"
    assert main(["splice-all", str(db), "-o", str(ref), "--method", "splice,naive,cpmc", "--batch-size", "1",
                 "--copy-sources", "--workers", "2", "-q"]) == 0
    result = tmp / "result.json"
    script = f"ip link set lo up && exec {sys.executable} {REPO / 'tests' / 'helpers' / 'ray_scenarios.py'} {db} {tmp} {result}"
    # loopback only, in a namespace of its own: no token needed between the cluster's processes
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0", RAY_AUTH_MODE="disabled", PYTHONUNBUFFERED="1")
    done = subprocess.run(["unshare", "--net", "bash", "-c", script], capture_output=True, text=True, timeout=900,
                          env=env, cwd=tmp)
    assert result.exists(), f"the scenarios did not finish: {done.stdout[-2000:]} {done.stderr[-3000:]}"
    res = json.loads(result.read_text())
    assert "error" not in res, res.get("error") + "\n" + (tmp / "head.log").read_text()[-2000:]
    return res, tmp, frames_and_table(ref)


def test_a_ray_run_equals_the_local_engine(scenarios):
    res, tmp, want = scenarios
    assert res["nodes"] == 2
    assert res["plain"]["code"] == 0, res["plain"]["stderr"]
    assert_same(tmp / "plain.h5", want, "plain run")


def test_a_killed_ray_worker_is_retried(scenarios):
    res, tmp, want = scenarios
    assert res["worker"]["killed"], "no Ray worker process was found to kill"
    assert res["worker"]["code"] == 0, (res["worker"]["killed"], res["worker"]["stderr"])
    assert_same(tmp / "worker.h5", want, f"run with worker {res['worker']['killed']} killed")


def test_a_lost_node_is_survived(scenarios):
    res, tmp, want = scenarios
    assert res["node"]["stopped"] and res["node"]["nodes_after"] == 1
    assert res["node"]["code"] == 0, res["node"]["stderr"]
    assert_same(tmp / "node.h5", want, "run that lost a node")


def test_a_killed_driver_resumes_from_the_finished_tasks(scenarios):
    res, tmp, want = scenarios
    assert res["driver_killed"]["cut"] and res["driver_killed"]["finished"] >= 3
    assert res["driver"]["code"] == 0, res["driver"]["stderr"]
    assert "from an earlier run" in res["driver"]["stdout"]
    assert_same(tmp / "driver.h5", want, "resumed run")


def test_a_ray_run_writes_an_alignment_store_that_reads_as_the_local_motion_store(scenarios):
    res, tmp, want = scenarios
    assert res["alignment"]["code"] == 0, res["alignment"]["stderr"]
    with MotionDatabase.open(tmp / "alignment.h5") as db:
        assert db.store == "alignment"
    assert_same(tmp / "alignment.h5", want, "alignment-store run")


@pytest.mark.parametrize("sig, code, word", [("SIGTERM", 143, "terminated"), ("SIGINT", 130, "interrupted")])
def test_a_signal_stops_a_ray_job_soon_with_its_exit_code(scenarios, sig, code, word):
    """Ray re-raises a signal met in its calls as a plain KeyboardInterrupt and installs its own
    SIGTERM handler (exit 15): the job still stops as the signal says, in seconds, its finished
    tasks kept."""
    res, _, _ = scenarios
    r = res[f"signal_{sig}"]
    assert r["began"], "the job finished no task before the signal"
    assert r["code"] == code and word in r["stderr"] and "finished tasks are kept" in r["stderr"], r
    assert r["seconds"] < 10, r  # it took 29 s before; about 1 to 3 s on 2 busy cores
