"""Engines that run the job's tasks: in this process, on local worker processes, or on Ray.

Every engine runs the same function on the same task (:func:`~torchsplice.job.task.run_task`)
and the result goes through the same :class:`~torchsplice.job.sink.Sink`, so the shards, and
the output merged from them, are the same bits whatever the engine and the worker count.

- :class:`InlineEngine`: this process (one worker, or a CUDA device). A background thread
  writes each task's shard while the next one computes.
- :class:`LocalEngine`: worker processes on this machine (``--workers N``, default one per
  core), each computing with one thread and writing its own shards, with at most
  :data:`IN_FLIGHT_PER_WORKER` tasks each handed out at a time. When a worker dies
  (killed, out of memory) the pool is restarted and the unfinished tasks run again; the job
  gives up after :data:`MAX_ATTEMPTS` breaks in a row without a task finishing.
- :class:`RayEngine`: Ray tasks on a cluster (``--ray-address``), or on a Ray instance started
  here. The driver puts each locomotion group's source clips in Ray's object store once; tasks
  return their results to the driver, which writes the shards. So a cluster needs no shared
  file system: only torchsplice installed on every node. Ray retries a task whose worker or
  node dies; the driver keeps at most two tasks in flight per CPU of the cluster, which bounds
  its memory and the object store's.

An engine calls ``done(task, part)`` for each finished task, one call at a time, in order of
completion (the inline engine from its writer thread, the others from the driver's), with the
task's :class:`~torchsplice.job.task.Part` when it is in memory (else ``None``: it is on
disk, and the merge reads it from there). Shards are written only where they outlive the task
(``keep_shards``): the slices of a ``--shard`` run, which a later merge joins, and a virtual
output, whose frames they are. Otherwise a task's part goes to the driver's merge as it is
(inline and Ray), or through a part file that the merge reads and removes (local workers),
and the checkpointed output is what a killed job resumes from.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import re
import signal
import sys
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, ThreadPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from ..core.errors import TorchspliceError
from .config import JobConfig
from .plan import Plan, Task
from .sink import Sink
from .sources import Sources
from .task import run_task

log = logging.getLogger("torchsplice.job")

__all__ = ["InlineEngine", "LocalEngine", "RayEngine", "make_engine", "MAX_ATTEMPTS"]

MAX_ATTEMPTS = 3
IN_FLIGHT_PER_WORKER = 2
"""Tasks a local worker has handed out at once (one computing, one waiting): finished tasks
wait for the driver's merge on disk, so this bounds the disk they take."""


def _shard_compression(config: JobConfig):
    """Shards of a virtual output are the output's frames: compressed like it; otherwise raw."""
    return config.compression if config.layout == "virtual" else None


class InlineEngine:
    """Tasks in this process, one after another (see the module docstring)."""

    name = "inline"

    def __init__(self, config: JobConfig, plan: Plan, sources: Sources, sink: Sink, shard_dir: Path, keep_shards: bool):
        self.config, self.plan, self.sources, self.sink, self.shard_dir = config, plan, sources, sink, shard_dir
        self.keep_shards = keep_shards

    def describe(self) -> str:
        from ..cpu import get_threads

        if self.config.backend() == "compiled":
            n = get_threads()
            return f"this process ({n} compute thread{'s' if n != 1 else ''})"
        return f"this process (torch on {self.config.device or 'cpu'})"

    def alive(self) -> int:
        return 1

    def run(self, tasks: list[Task], done) -> None:
        buffers = None
        if self.config.backend() == "compiled":
            from ..cpu.bank import Buffers

            buffers = (Buffers(), Buffers())  # the writer reads one while the next task fills the other
        comp = _shard_compression(self.config)
        pending: Future | None = None

        def write(task, part):  # in the writer thread, while the next task computes
            if self.keep_shards:
                self.sink.write_shard(part, self.shard_dir / self.sink.shard_name(task.id), comp)
            done(task, part)

        with ThreadPoolExecutor(max_workers=1) as writer:
            try:
                for n, task in enumerate(tasks):
                    part = run_task(self.plan, task, self.sources, self.config, buffers[n % 2] if buffers else None)
                    if pending is not None:
                        pending.result()
                    pending = writer.submit(write, task, part)
                if pending is not None:
                    pending.result()
            except BaseException:
                while pending is not None and not pending.done():
                    try:
                        pending.result()  # keep the task being written (a second Ctrl-C waits on)
                    except KeyboardInterrupt:
                        continue
                    except BaseException:
                        break
                raise

    def close(self) -> None:
        pass


# --------------------------------------------------------------------------------------------- local processes
_WORKER: dict = {}


def _worker_init(config: JobConfig, plan_path: str, shard_dir: str, driver: int, keep_shards: bool) -> None:
    """A worker process: one compute thread, Ctrl-C left to the driver, the plan read once; it
    exits when the driver is gone (a killed job leaves no worker behind)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _exit_with(driver)
    import torch

    torch.set_num_threads(1)
    if config.backend() == "compiled":
        from ..cpu import set_threads

        set_threads(1)
    from .sink import HDF5Sink

    plan = Plan.load(Path(plan_path))
    sources = Sources(config.database, config.actions_db, bank_dir=Path(shard_dir), bank_tag=plan.digest())  # mapped
    sources.share_banks(plan.groups)
    _WORKER.update(config=config, plan=plan, sources=sources, sink=HDF5Sink(), shard_dir=Path(shard_dir),
                   keep_shards=keep_shards)


def _exit_with(driver: int) -> None:
    """Exit as soon as the driver process is gone (checked twice a second, in a daemon thread).

    Workers are children of the fork server, and they hold the pipes that would tell it (and
    them) that the driver died, so neither would notice a killed driver by itself.
    """
    import threading
    import time

    from ..io.lock import pid_alive

    def watch():
        while pid_alive(driver):
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="torchsplice-driver-watch", daemon=True).start()


def _worker_task(index: int) -> None:
    """A task in a worker: its shard (``keep_shards``) or its part file (for the driver's merge)
    written. Results go through files, not the pool's pipe: a worker killed while sending a
    large result would leave the pool waiting for the rest of it."""
    w = _WORKER
    task = w["plan"].tasks[index]
    part = run_task(w["plan"], task, w["sources"], w["config"])
    if w["keep_shards"]:
        w["sink"].write_shard(part, w["shard_dir"] / w["sink"].shard_name(task.id), _shard_compression(w["config"]))
    else:
        part.save(w["shard_dir"] / w["sink"].part_name(task.id))


def _main_unguarded() -> bool:
    """Whether worker processes re-import the driver's main script (run as a file, not ``-m``)
    and that script does not guard its entry point with ``if __name__ == "__main__":`` (then
    each worker would run the job again, and fails to start). A console script (such as
    ``torchsplice``) is guarded; a script that cannot be read is taken as guarded."""
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if path is None or getattr(main, "__spec__", None) is not None:
        return False
    try:
        text = Path(path).read_text(errors="ignore")
    except OSError:
        return False
    return not re.search(r"""__name__\s*==\s*['"]__main__['"]""", text)


class LocalEngine:
    """Worker processes on this machine (see the module docstring)."""

    name = "local"

    def __init__(self, config: JobConfig, plan: Plan, plan_path: Path, shard_dir: Path, workers: int, keep_shards: bool):
        self.config, self.plan, self.plan_path, self.shard_dir, self.workers = config, plan, plan_path, shard_dir, workers
        self.keep_shards = keep_shards
        self.pool: ProcessPoolExecutor | None = None

    def describe(self) -> str:
        return f"{self.workers} local worker process{'es' if self.workers > 1 else ''}, one thread each"

    def _start(self) -> None:
        ctx = mp.get_context("forkserver" if sys.platform != "win32" else "spawn")
        if hasattr(ctx, "set_forkserver_preload"):
            ctx.set_forkserver_preload(["torchsplice.job.worker"])  # workers fork with torch and the kernels loaded
        self.pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx, initializer=_worker_init,
                                        initargs=(self.config, str(self.plan_path), str(self.shard_dir), os.getpid(),
                                                  self.keep_shards))

    def alive(self) -> int:
        procs = getattr(self.pool, "_processes", None) or {}
        return sum(p.is_alive() for p in list(procs.values()))

    def run(self, tasks: list[Task], done) -> None:
        index = {t.id: n for n, t in enumerate(self.plan.tasks)}
        todo = {t.id: t for t in tasks}
        window = IN_FLIGHT_PER_WORKER * self.workers  # tasks handed out at once: the driver's merge keeps pace
        rounds = 0  # pool breaks in a row without a task finished
        while todo:
            self._start()
            before = len(todo)
            rounds += 1
            broken = False
            queue = list(todo)
            futures: dict = {}
            try:
                while (queue or futures) and not broken:
                    try:
                        while queue and len(futures) < window:
                            tid = queue.pop(0)
                            futures[self.pool.submit(_worker_task, index[tid])] = tid
                    except BrokenProcessPool:  # a worker died while the tasks were being handed out
                        broken = True
                        break
                    finished, _ = wait(set(futures), return_when=FIRST_COMPLETED)
                    for f in sorted(finished, key=lambda f: index[futures[f]]):
                        tid = futures.pop(f)
                        try:
                            f.result()
                        except BrokenProcessPool:
                            broken = True
                            continue
                        done(todo.pop(tid), None)
            except BaseException:
                self.close(kill=True)
                raise
            if broken:
                self.close(kill=True)
                if len(todo) < before:
                    rounds = 0  # it made progress: only breaks in a row count
                if rounds == 1 and len(todo) == len(tasks) and _main_unguarded():
                    raise TorchspliceError(
                        "local worker processes could not start: a script that runs the job through the Python API "
                        "must guard its entry point with `if __name__ == \"__main__\":` (workers re-import it), or "
                        "use workers=1")
                if rounds >= MAX_ATTEMPTS:
                    raise TorchspliceError(f"worker processes died {rounds} times in a row ({len(todo)} tasks unfinished; "
                                           "out of memory, or killed); finished tasks are kept: rerun to resume")
            else:
                self.close()

    def close(self, kill: bool = False) -> None:
        if self.pool is None:
            return
        if kill:
            for p in list((getattr(self.pool, "_processes", None) or {}).values()):
                if p.is_alive():
                    p.kill()
        self.pool.shutdown(wait=True, cancel_futures=True)
        self.pool = None


# --------------------------------------------------------------------------------------------- Ray
_RAY_CACHE: dict = {}


def _ray_run(config: JobConfig, digest: str, plan_box: list, index: int, group_box: list):
    """A Ray task. The plan and each group's clips come boxed in a list, so that Ray passes their
    references untouched: a worker process fetches each only once and keeps it."""
    import ray

    if _RAY_CACHE.get("plan") != digest:
        import torch

        torch.set_num_threads(1)
        if config.backend() == "compiled":
            from ..cpu import set_threads

            set_threads(1)
        _RAY_CACHE.clear()
        _RAY_CACHE.update(plan=digest, obj=Plan.from_json(ray.get(plan_box[0])), sources=Sources.from_motions({}), groups=set())
    plan, sources = _RAY_CACHE["obj"], _RAY_CACHE["sources"]
    ref = group_box[0]
    if ref.hex() not in _RAY_CACHE["groups"]:
        for k, m in ray.get(ref).items():
            sources.motions.setdefault(k, m)
        _RAY_CACHE["groups"].add(ref.hex())
    return run_task(plan, plan.tasks[index], sources, config)


_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + b"\x00\x00\x00\x04\x00\x00\x00\x00\x00"  # + empty SETTINGS


def _check_reachable(address: str, timeout: float = 10.0, where: str = "{ray_address}") -> None:
    """Refuse at once, in one line, a ``HOST:PORT`` that is malformed, that nobody answers on, or
    whose answer is not gRPC's (HTTP/2) as a Ray cluster's GCS port speaks it (a dashboard's
    HTTP port, another service): Ray itself would wait long there, saying nothing. ``where``
    names what gave the address."""
    import socket

    host, _, port = address.rpartition(":")
    try:
        port_n = int(port)
    except ValueError:
        port_n = -1
    if not host or not 1 <= port_n <= 65535:
        raise TorchspliceError(f"{where} {address!r}: expected HOST:PORT with a port from 1 to 65535 (the head's GCS "
                               "port, 6379 by default)", options=("ray_address",))
    try:
        with socket.create_connection((host.strip("[]"), port_n), timeout=timeout) as conn:
            conn.settimeout(timeout)
            conn.sendall(_HTTP2_PREFACE)
            head = b""
            while len(head) < 9:
                chunk = conn.recv(9 - len(head))
                if not chunk:
                    break
                head += chunk
    except socket.timeout:
        head = b""
    except OSError as exc:
        raise TorchspliceError(f"cannot reach the Ray cluster at {address}: {exc.strerror or exc} "
                               f"(is `ray start --head` running there, and the port open?)") from None
    if len(head) < 9 or head[3] != 0x04:  # a gRPC server opens with a SETTINGS frame
        raise TorchspliceError(f"{address} answers, but not as a Ray cluster does (its GCS port, 6379 by default, "
                               "speaks gRPC; a dashboard's port, 8265, does not): give {ray_address} the head's GCS "
                               "port", options=("ray_address",))


def _ray_address(given: str | None) -> tuple[str, str]:
    """``(address for ray.init, where it came from)``: ``given``; else ``RAY_ADDRESS``; else
    ``"local"`` (a new local instance, never a cluster left from earlier). ``"auto"`` reads the
    address of the cluster started on this machine from Ray's record of it."""
    if given in (None, ""):
        env = os.environ.get("RAY_ADDRESS", "").strip()
        if not env:
            return "local", ""
        given, where = env, "RAY_ADDRESS"
    else:
        where = "{ray_address}"
    if given == "auto":
        record = Path(os.environ.get("RAY_TMPDIR", "/tmp")) / "ray" / "ray_current_cluster"
        try:
            given = record.read_text().strip()
        except OSError:
            raise TorchspliceError(f"{where} auto: no Ray cluster was started on this machine ({record} is missing); "
                                   "run `ray start --head`, or give no address for a local instance",
                                   options=("ray_address",)) from None
        where = f"{where} auto ({record})"
    return given, where


class RayEngine:
    """Ray tasks on a cluster (see the module docstring)."""

    name = "ray"

    def __init__(self, config: JobConfig, plan: Plan, sources: Sources, sink: Sink, shard_dir: Path, keep_shards: bool):
        self.config, self.plan, self.sources, self.sink, self.shard_dir = config, plan, sources, sink, shard_dir
        self.keep_shards = keep_shards
        try:
            import ray
        except ImportError:
            raise TorchspliceError("{engine} ray needs Ray: pip install 'torchsplice[ray]'", options=("engine",)) from None
        self.ray = ray
        self.started = not ray.is_initialized()
        if self.started:
            address, where = _ray_address(config.ray_address)
            if address != "local" and "://" not in address:  # a ray:// client address: Ray's client times out itself
                _check_reachable(address, where=where)
            log.info("connecting to Ray at %s", address if address != "local" else "(a new local instance)")
            import threading

            main = threading.current_thread() is threading.main_thread()
            handlers = {s: h for s in (signal.SIGINT, signal.SIGTERM) if (h := signal.getsignal(s)) is not None} \
                if main else {}
            try:
                ray.init(address=address, include_dashboard=False, log_to_driver=False,
                         logging_level="ERROR", configure_logging=True)
                for sig, handler in handlers.items():  # Ray installs its own (SIGTERM: exit 15 after its shutdown)
                    signal.signal(sig, handler)
            except (ConnectionError, ValueError, RuntimeError) as exc:
                raise TorchspliceError(f"cannot reach the Ray cluster at {address if address != 'local' else '(a new local one)'}: "
                                       f"{exc}") from None

    def describe(self) -> str:
        res = self.ray.cluster_resources()
        nodes = sum(n.get("Alive", False) for n in self.ray.nodes())
        return f"Ray, {nodes} node{'s' if nodes != 1 else ''}, {int(res.get('CPU', 0))} CPUs"

    def alive(self) -> int:
        return int(self.ray.cluster_resources().get("CPU", 0))

    def run(self, tasks: list[Task], done) -> None:
        ray = self.ray
        remote = ray.remote(num_cpus=1, max_retries=MAX_ATTEMPTS)(_ray_run)
        plan_ref = ray.put(self.plan.to_json())
        config_ref = ray.put(self.config)
        digest = self.plan.digest()
        group_refs: dict[int, object] = {}
        index = {t.id: n for n, t in enumerate(self.plan.tasks)}
        queue = list(tasks)
        inflight: dict = {}
        comp = _shard_compression(self.config)
        waited = 0.0
        try:
            while queue or inflight:
                limit = 2 * self.alive()  # two tasks in flight per CPU, as CPUs come and go
                if limit == 0 and not inflight:
                    if waited > 120:
                        raise TorchspliceError("the Ray cluster has had no CPU for two minutes: add a node with CPUs")
                    time.sleep(1.0)
                    waited += 1.0
                    continue
                waited = 0.0
                while queue and len(inflight) < max(limit, 1):
                    task = queue.pop(0)
                    if task.group not in group_refs:
                        keys = self.plan.groups[task.group].clips
                        group_refs[task.group] = ray.put(self.sources.group_motions(keys))
                    inflight[remote.remote(config_ref, digest, [plan_ref], index[task.id], [group_refs[task.group]])] = task
                ready, _ = ray.wait(list(inflight), num_returns=1, timeout=10.0)
                for ref in ready:
                    task = inflight.pop(ref)
                    try:
                        part = ray.get(ref)
                    except ray.exceptions.RayTaskError as exc:
                        cause = getattr(exc, "cause", None)
                        why = str(cause) if cause is not None else str(exc).strip().splitlines()[-1]
                        raise TorchspliceError(f"task {task.id} failed on the Ray cluster: {why}") from None
                    except (ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError,
                            ray.exceptions.ObjectLostError) as exc:
                        raise TorchspliceError(f"task {task.id} was lost {MAX_ATTEMPTS} times on the Ray cluster "
                                               f"({type(exc).__name__}); finished tasks are kept: rerun to resume") from None
                    except ray.exceptions.RayError as exc:
                        raise TorchspliceError(f"task {task.id} failed on the Ray cluster ({type(exc).__name__}); "
                                               "finished tasks are kept: rerun to resume") from None
                    if self.keep_shards:
                        self.sink.write_shard(part, self.shard_dir / self.sink.shard_name(task.id), comp)
                    done(task, part)  # the driver appends it from memory
        except BaseException:
            for ref in inflight:
                ray.cancel(ref, force=True)
            raise

    def close(self) -> None:
        if self.started and self.ray.is_initialized():
            self.ray.shutdown()


def make_engine(config: JobConfig, plan: Plan, plan_path: Path, sources: Sources, sink: Sink, shard_dir: Path,
                keep_shards: bool = True):
    """The engine ``config`` asks for (a CUDA device, or one worker, runs in this process);
    ``keep_shards``: write each task's shard (see the module docstring)."""
    if config.engine == "ray":
        return RayEngine(config, plan, sources, sink, shard_dir, keep_shards)
    workers = config.worker_count()
    if workers == 1 or config.backend() != "compiled":
        return InlineEngine(config, plan, sources, sink, shard_dir, keep_shards)
    return LocalEngine(config, plan, plan_path, shard_dir, workers, keep_shards)
