"""The ``ray`` engine: Ray tasks on a cluster (``--ray-address``), or on a Ray instance started
here. The driver puts each locomotion group's source clips in Ray's object store once; tasks
return their results to the driver, which writes the shards (when kept) and merges them. So a
cluster needs no shared file system: only torchsplice installed on every node. Ray retries a
task whose worker or node dies; the driver keeps at most two tasks in flight per CPU of the
cluster, which bounds its memory and the object store's. An address is checked before Ray is
asked (:func:`_check_reachable`, :func:`_ray_address`).
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import threading
import time
from pathlib import Path

from ...core.errors import TorchspliceError
from ..config import JobConfig
from ..plan import Plan, Task
from ..sources import Sources
from ..task import run_task
from .base import MAX_ATTEMPTS, Engine, EngineContext, one_thread_worker

__all__ = ["RayEngine"]

log = logging.getLogger("torchsplice.job")

_RAY_CACHE: dict = {}


def _ray_run(config: JobConfig, digest: str, plan_box: list, index: int, group_box: list):
    """A Ray task. The plan and each group's clips come boxed in a list, so that Ray passes their
    references untouched: a worker process fetches each only once and keeps it."""
    import ray  # an optional dependency (the ray extra): imported where used

    if _RAY_CACHE.get("plan") != digest:
        one_thread_worker(config)
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


class RayEngine(Engine):
    """Ray tasks on a cluster (see the module docstring)."""

    name = "ray"

    def __init__(self, ctx: EngineContext):
        super().__init__(ctx)
        config = ctx.config
        self.sources = ctx.sources
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
                    self.ctx.write_shard(task, part)
                    done(task, part)  # the driver appends it from memory
        except BaseException:
            for ref in inflight:
                ray.cancel(ref, force=True)
            raise

    def close(self) -> None:
        if self.started and self.ray.is_initialized():
            self.ray.shutdown()
