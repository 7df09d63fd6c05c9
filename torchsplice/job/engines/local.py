"""The ``local`` engine: worker processes on this machine (``--workers N``, default one per
core), each computing with one thread, with at most :data:`IN_FLIGHT_PER_WORKER` tasks each
handed out at a time. A task's results reach the driver's merge as a part file (or, kept, a
shard), not through the pool's pipe: a worker killed while sending would stall the pool. When
a worker dies (killed, out of memory) the pool is restarted and the unfinished tasks run
again; the job gives up after :data:`~torchsplice.job.engines.MAX_ATTEMPTS` breaks in a row
without a task finishing. Workers map the driver's clip banks (see :mod:`..sources`) and exit
when the driver is gone. One worker, or a torch device, runs in this process instead
(:class:`~torchsplice.job.engines.inline.InlineEngine`).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import re
import signal
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from ...core.errors import TorchspliceError
from ...store.lock import pid_alive
from ..config import JobConfig
from ..plan import Plan, Task
from ..sink import make_sink
from ..sources import Sources
from ..task import run_task
from .base import MAX_ATTEMPTS, Engine, EngineContext, one_thread_worker, shard_compression
from .inline import InlineEngine

__all__ = ["LocalEngine", "make_local_engine", "IN_FLIGHT_PER_WORKER"]

IN_FLIGHT_PER_WORKER = 2
"""Tasks a local worker has handed out at once (one computing, one waiting): finished tasks
wait for the driver's merge on disk, so this bounds the disk they take."""


def make_local_engine(ctx: EngineContext) -> Engine:
    """The ``local`` engine: worker processes, or this process for one worker or a torch device."""
    if not ctx.config.uses_worker_processes():
        return InlineEngine(ctx)
    return LocalEngine(ctx)


_WORKER: dict = {}


def _worker_init(config: JobConfig, plan_path: str, shard_dir: str, driver: int, keep_shards: bool) -> None:
    """A worker process: one compute thread, Ctrl-C left to the driver, the plan read once; it
    exits when the driver is gone (a killed job leaves no worker behind)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _exit_with(driver)
    one_thread_worker(config)

    plan = Plan.load(Path(plan_path))
    sources = Sources(config.database, config.actions_db, bank_dir=Path(shard_dir), bank_tag=plan.digest(),
                      fix_feet=config.fix_feet)  # mapped
    sources.share_banks(plan.groups)
    _WORKER.update(config=config, plan=plan, sources=sources, sink=make_sink(config), shard_dir=Path(shard_dir),
                   keep_shards=keep_shards)


def _exit_with(driver: int) -> None:
    """Exit as soon as the driver process is gone (checked twice a second, in a daemon thread).

    Workers are children of the fork server, and they hold the pipes that would tell it (and
    them) that the driver died, so neither would notice a killed driver by itself.
    """
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
        w["sink"].write_shard(part, w["shard_dir"] / w["sink"].shard_name(task.id), shard_compression(w["config"]))
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


class LocalEngine(Engine):
    """Worker processes on this machine (see the module docstring)."""

    name = "local"

    def __init__(self, ctx: EngineContext):
        super().__init__(ctx)
        self.plan_path, self.shard_dir, self.keep_shards = ctx.plan_path, ctx.shard_dir, ctx.keep_shards
        self.workers = ctx.config.worker_count()
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
