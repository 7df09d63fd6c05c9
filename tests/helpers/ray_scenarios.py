"""Run inside a private network namespace by tests/job/test_ray.py: a two-node Ray cluster on
127.0.0.1 (one CPU and a small object store per node), started and stopped here by the
handles of its own processes, and four jobs on it. Writes what happened to a JSON file.

    python tests/helpers/ray_scenarios.py SAMPLE_DB OUT_DIR RESULT_JSON
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

PORT = 6399
JOB = ["--method", "splice,naive,cpmc", "--batch-size", "1", "--copy-sources", "-q"]


def start_node(temp: Path, head: bool) -> subprocess.Popen:
    common = ["--block", "--node-ip-address", "127.0.0.1", "--num-cpus", "1", "--object-store-memory", "80000000",
              "--disable-usage-stats"]
    args = ["--head", "--port", str(PORT), "--include-dashboard", "false", "--temp-dir", str(temp)] if head else \
        ["--address", f"127.0.0.1:{PORT}"]
    log = open(temp.parent / ("head.log" if head else "node.log"), "w")
    # notice a lost node within seconds, not the default half minute
    env = dict(os.environ, RAY_health_check_period_ms="500", RAY_health_check_failure_threshold="4")
    return subprocess.Popen(["ray", "start", *args, *common], stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
                            env=env)


def stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        try:
            os.killpg(p.pid, signal.SIGKILL)  # the node's whole process group: raylet, store, workers
        except ProcessLookupError:
            pass
        p.wait(timeout=30)


def alive_nodes() -> int:
    done = subprocess.run(["ray", "status", "--address", f"127.0.0.1:{PORT}"], capture_output=True, text=True, timeout=30)
    text = done.stdout.split("Pending:")[0]
    return sum(1 for line in text.splitlines() if line.strip().startswith("1 node_"))


def job(db: str, out: Path, *extra, quiet: bool = True) -> subprocess.Popen:
    flags = JOB if quiet else [f for f in JOB if f != "-q"]
    # Ctrl-C as a terminal delivers it: a harness started in the background (nohup, &) has SIGINT
    # ignored, which its children would inherit
    return subprocess.Popen([sys.executable, "-m", "torchsplice", "splice-all", db, "-o", str(out), "--engine", "ray",
                             "--ray-address", f"127.0.0.1:{PORT}", *flags, *extra],
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, TORCHSPLICE_CHECKPOINT_SECONDS="0"))  # a checkpoint after each task


def finished(out: Path) -> int:
    """Tasks the job has finished: those its staged output holds, and the shards waiting to join it."""
    from torchsplice.store.database import MotionDatabase

    work = out.parent / f".{out.name}.parts"
    held = (MotionDatabase.checkpoint_note(work / "output.h5") or {}).get("tasks", 0)
    return held + len(list(work.glob("part-*")))


def ray_workers(netns: str) -> list[int]:
    """The Ray worker processes (their title starts ``ray::``: idle, or the task it runs) in the
    network namespace ``netns`` (``/proc/PID/ns/net``'s link: this scenario's cluster, not one
    another test run started in its own namespace)."""
    pids = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                if (p / "cmdline").read_bytes().startswith(b"ray::") and os.readlink(p / "ns" / "net") == netns:
                    pids.append(int(p.name))
            except OSError:
                pass
    return pids


def kill_a_running_task(driver: subprocess.Popen, timeout: float = 120) -> list[int]:
    """SIGKILL the first Ray worker caught running a task of the job ``driver`` runs (its title
    ``ray::_ray_run``); returns its pid, or nothing if none ran within ``timeout`` s or the job
    ended first. A task on the sample lasts tens
    of milliseconds, and a scan of /proc on a loaded machine as long, so the scan only finds the
    workers (every 0.2 s) and the watch reads just their titles, about every millisecond."""
    deadline = time.monotonic() + timeout
    try:
        netns = os.readlink(f"/proc/{driver.pid}/ns/net")
    except OSError:  # the job ended already
        return []
    workers: list[int] = []
    rescan = 0.0
    while time.monotonic() < deadline and driver.poll() is None:
        if time.monotonic() >= rescan:
            workers, rescan = ray_workers(netns), time.monotonic() + 0.2
        for pid in workers:
            try:
                if b"ray::_ray_run" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    os.kill(pid, signal.SIGKILL)
                    return [pid]
            except OSError:
                pass  # gone meanwhile
        time.sleep(0.001)
    return []


def finish(p: subprocess.Popen, timeout: float = 300) -> dict:
    out, err = p.communicate(timeout=timeout)
    return {"code": p.returncode, "stdout": out, "stderr": err[-3000:]}


def wait_for(cond, timeout: float = 120, poll: float = 0.02) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(poll)
    return False


def main() -> None:
    db, outdir, result_path = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3])
    temp = outdir / "ray"
    temp.mkdir(parents=True, exist_ok=True)
    result: dict = {}
    head = start_node(temp, True)
    node = None
    try:
        assert wait_for(lambda: head.poll() is None and alive_nodes() >= 1, 60), "the head node did not start"
        node = start_node(temp, False)
        assert wait_for(lambda: alive_nodes() >= 2, 60), "the second node did not join"
        result["nodes"] = alive_nodes()

        # 1. a plain run
        result["plain"] = finish(job(db, outdir / "plain.h5"))

        # 2. a worker process killed while it runs a task
        p = job(db, outdir / "worker.h5")
        result["worker"] = {"killed": kill_a_running_task(p)}
        result["worker"].update(finish(p))

        # 3. a node stopped mid-job: its tasks run on the other one
        p = job(db, outdir / "node.h5")
        stopped = wait_for(lambda: finished(outdir / "node.h5") >= 2)
        if stopped:
            stop(node)
        result["node"] = {**finish(p), "stopped": stopped}
        wait_for(lambda: alive_nodes() == 1, 60)
        result["node"]["nodes_after"] = alive_nodes()

        # 4. the driver killed mid-job, then the same command again
        p = job(db, outdir / "driver.h5")
        cut = wait_for(lambda: finished(outdir / "driver.h5") >= 3)
        p.kill()
        p.wait()
        result["driver_killed"] = {"cut": cut, "finished": finished(outdir / "driver.h5")}
        result["driver"] = finish(job(db, outdir / "driver.h5", quiet=False))

        # 6. the job writing an alignment store (parts from the cluster's workers, banks from the driver)
        result["alignment"] = finish(job(db, outdir / "alignment.h5", "--store", "alignment"))

        # 5. SIGTERM and SIGINT mid-job: the job stops soon, with the exit code of its signal. On
        # the sample mirrored (20 clips, 300 tasks), so that a warm cluster cannot finish the job
        # in the moment between its first task and the signal
        big = outdir / "mirrored.h5"
        subprocess.run([sys.executable, "-m", "torchsplice", "mirror", db, "--all", "-o", str(big), "-q"], check=True)
        for sig in (signal.SIGTERM, signal.SIGINT):
            out = outdir / f"signal-{sig.name}.h5"
            p = job(str(big), out)
            began = wait_for(lambda: finished(out) >= 1)
            t0 = time.monotonic()
            p.send_signal(sig)
            done = finish(p, timeout=60)
            result[f"signal_{sig.name}"] = {**done, "began": began, "seconds": time.monotonic() - t0}
    except BaseException as exc:  # recorded for the test to show
        result["error"] = repr(exc)
    finally:
        if node is not None:
            stop(node)
        stop(head)
        result_path.write_text(json.dumps(result))


if __name__ == "__main__":
    main()
