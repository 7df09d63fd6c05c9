"""The main job: splice every selected (locomotion, action) pair into a new motion database.

    torchsplice splice-all DB.h5 -o OUT.h5 [--locomotions SELECT] [--actions SELECT] [--method splice,naive]
    torchsplice splice-all DB.h5 -o OUT.h5 --engine ray --ray-address HOST:PORT
    torchsplice splice-all DB.h5 -o OUT.h5 --shard 2/8      # then: torchsplice merge OUT.h5

How it runs:

1. **Plan** (:mod:`.plan`). The selections, the locomotion checks, the pairs and the skips
   with their reasons, cut into tasks with stable ids; saved as ``plan.json`` in the work
   folder ``.OUT.h5.parts/``. A rerun whose plan differs (other arguments or inputs) refuses
   to mix with the unfinished one; ``--restart`` discards it.
2. **Tasks** (:mod:`.task`, :mod:`.engines`). Each task splices its pairs. Tasks run in
   this process, on local worker processes (``--workers``) or on Ray (``--engine ray``); a
   task gives the same bits wherever it runs. A task's results reach the driver as a raw part
   file, ``part-<task id>.part`` (local workers), or as an object (Ray); ``--shard`` runs and
   ``--layout virtual`` keep each task as a compressed shard, ``part-<task id>.h5``. Files are
   written under a temporary name (carrying host and PID) and renamed into place.
3. **Merge** (:mod:`.sink`). Results are appended in plan order, as they finish, to the staged
   output ``output.h5`` in the work folder (:meth:`MotionDatabase.create` with ``staging``):
   a checkpoint every :data:`CHECKPOINT_SECONDS` records which tasks it holds. A part file is
   deleted as soon as it is appended (a kill before the next checkpoint splices its task
   again), a shard once a checkpoint holds it, so the job's disk is about its output. The
   finished output is renamed into place with a run record, and the work folder is removed.
   With ``--layout virtual`` the output's frames are virtual datasets over the shards, which
   then stay in ``OUT.h5.shards/``.
4. **Resume.** Killed at any moment, the same command (with any engine or worker count) reuses
   its plan, opens the staged output at its last checkpoint and runs only the tasks it does
   not hold: a resume costs the remaining work, and no task is merged twice. ``--shard K/N``
   runs the K-th of N slices of the tasks and writes no output; ``torchsplice merge OUT.h5``
   then joins the finished slices.

Before any write, the job estimates its output's size (:mod:`.size`) and refuses to start
when the disk cannot hold it; ``dry_run`` (``--dry-run``) plans and reports without splicing.
The job holds a lock on its output (``--shard`` runs: on their slice), so a second writer is
refused at once; a lock or temporary file left by a dead process on this host is cleaned up.
The output has the input's schema plus per-clip columns (source names and rows, method and
parameters, alignment cost and quality figures) and a per-frame ``action_frame`` column.
"""

from __future__ import annotations

import ctypes
import gc
import logging
import shutil
import socket
import tempfile
import time
from pathlib import Path

import torch

from ..core.errors import OutputExistsError, TorchspliceError, UnfinishedJobError
from ..core.stop import check_stop
from ..formats.index import refresh_database_index
from ..store.lock import FileLock, check_name_length, remove_stale_temporaries
from .config import DEFAULT_ACTIONS, DEFAULT_LOCOMOTIONS, JobConfig, job_config, parse_shard
from .engines.base import EngineContext, make_engine
from .engines.forkserver import prestart
from .merge import (STAGING, OutputMerge, merge_job, open_output, remove_merged_shards, source_rows, source_skeleton,
                    task_finished)
from .plan import Plan, make_plan
from .shards import clear_work, output_lock_path, refuse_live_slices, slice_tasks
from .sink import make_sink
from .sources import Sources
from .size import OutputSize, estimate_output, format_bytes
from .summary import JobSummary, progress_bar
from .target import onto_target
from .task import FLAG_CODES, FLAG_SEPARATOR, FRAME_COLUMNS, OUTPUT_COLUMNS, POOR_ALIGNMENT

__all__ = ["JobConfig", "JobSummary", "SpliceJob", "merge_job", "OUTPUT_COLUMNS", "FRAME_COLUMNS", "POOR_ALIGNMENT",
           "FLAG_SEPARATOR", "FLAG_CODES", "DEFAULT_LOCOMOTIONS", "DEFAULT_ACTIONS"]

log = logging.getLogger("torchsplice.job")


class SpliceJob:
    """Plan and run one splice job, or one slice of it (see the module docstring)."""

    def __init__(self, config: JobConfig, progress: bool = True, restart: bool = False, overwrite: bool = False,
                 command: str | None = None, shard: tuple[int, int] | None = None, dry_run: bool = False):
        self.config = config.checked()
        self.progress, self.restart, self.overwrite, self.shard = progress, restart, overwrite, shard
        self.dry_run = dry_run
        self.command = command or "torchsplice.job.SpliceJob (Python API)"
        self.work = self.config.work
        self.sink = make_sink(config)

    # -- the run ------------------------------------------------------------------------------
    def run(self) -> JobSummary:
        """Plan, run the tasks not done yet, merge (unless a slice); returns the summary."""
        c = self.config
        t0 = time.perf_counter()
        self._started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        if not c.output.parent.exists():
            raise TorchspliceError(f"{c.output}: folder {c.output.parent} does not exist")
        check_name_length(c.output)
        if self.shard is None and c.output.exists() and not self.overwrite:
            raise OutputExistsError(f"{c.output}: already exists")
        if self.dry_run:
            return self._dry_run(t0)
        prestart(c.engine, c.worker_count(), c.device, c.backend)
        if self.shard is not None and self.restart:
            raise TorchspliceError("{restart} discards the whole job, every slice's work too: run it once without {shard}",
                                   options=("restart", "shard"))
        if self.shard is None:
            lock = FileLock(output_lock_path(c.output), str(c.output), self.command)
        else:
            self.work.mkdir(exist_ok=True)
            lock = FileLock(self.work / f"lock-{self.shard[0]}-of-{self.shard[1]}", f"slice {self.shard[0]}/{self.shard[1]} of {c.output}", self.command)
        with lock, _compute_threads(c):
            if self.shard is None:
                refuse_live_slices(self.work)
            if self.restart and self.work.exists():
                clear_work(self.work, keep=lock.path)
            for folder in (self.work, c.output.parent):
                remove_stale_temporaries(folder)
            c = self.config = onto_target(c)  # --target: the clips on one skeleton first (made once)
            sources = Sources(c.database, c.actions_db, fix_feet=c.fix_feet)
            try:
                summary = self._run(sources, t0)
            finally:
                sources.close()
            if self.shard is None:
                shutil.rmtree(self.work, ignore_errors=True)

                summary.index = refresh_database_index(c.output, write=c.index)  # never an earlier run's left beside it
        summary.seconds = time.perf_counter() - t0
        if c.target is not None:
            summary.target = f"{c.target} ({', '.join(str(p) for p in (c.database, c.actions_db) if p is not None)})"
        return summary

    def _dry_run(self, t0: float) -> JobSummary:
        """Plan, and say what the job would do and how much disk it needs; writes nothing."""
        with tempfile.TemporaryDirectory(dir=self.config.output.parent) as tmp:  # --target's databases, if any
            c = onto_target(self.config, Path(tmp))
            summary = self._dry_run_of(c, t0)
        if self.config.target is not None:
            summary.target = str(self.config.target)
        return summary

    def _dry_run_of(self, c: JobConfig, t0: float) -> JobSummary:
        sources = Sources(c.database, c.actions_db, fix_feet=c.fix_feet)
        try:
            plan = make_plan(c, sources)
            summary = JobSummary(output=c.output, pairs=len(plan.pairs), skipped=dict(plan.skipped), tasks=len(plan.tasks),
                                 dry_run=True, standing=plan.pairs.count("standing"),
                                 retargeted=plan.retargeted)
            summary.expected = self._expected(plan, sources)
            summary.alignment = self._expected_alignment(plan, sources)
            summary.free = _free_bytes(c.output.parent)
        finally:
            sources.close()
        summary.seconds = time.perf_counter() - t0
        return summary

    def _expected(self, plan: Plan, sources: Sources, store: str | None = None) -> OutputSize:
        """The output's expected size (``store``: as that store; default the job's)."""
        copied = None
        if self.config.copy_sources:
            copied = []
            for db, rows in source_rows(plan, sources):
                t = db.clip_table()
                copied += [(int(t.length[r]), db.skeletons[int(t.skeleton[r])]) for r in rows]
        return estimate_output(plan, lambda g: source_skeleton(plan, g, sources)[0], self.config.compression, copied,
                               store=store or self.config.store)

    def _expected_alignment(self, plan: Plan, sources: Sources) -> OutputSize | None:
        """What ``--store alignment`` would take, for a job of motions (``None`` for an alignment store)."""
        return None if self.config.store == "alignment" else self._expected(plan, sources, store="alignment")

    def _check_room(self, plan: Plan, sources: Sources) -> tuple[OutputSize, int | None]:
        """The output's expected size and the free space; refuses, before any work, a job whose
        output (what is left of it) and banks do not fit."""
        c = self.config
        expected, free = self._expected(plan, sources), _free_bytes(c.output.parent)
        held = sum(f.stat().st_size for f in (self.work / STAGING, self.work / f"{STAGING}.rows") if f.exists())
        banks = sources.unsaved_bank_bytes(self.work) if _shares_banks(c) else 0
        need = max(0, expected.bytes - held) + banks
        if free is not None and need > free:
            other = self._expected_alignment(plan, sources)
            hint = ("" if other is None else f", or write {{store}} alignment (about {format_bytes(other.bytes)}: the "
                    "source clips once and what splicing computed; every reader assembles the motions)")
            raise TorchspliceError(
                f"{c.output}: the job needs about {format_bytes(need)} more on the disk (an output of about "
                f"{format_bytes(expected.bytes)}, {expected.frames:,} frames) and {c.output.parent} has "
                f"{format_bytes(free)} free; free some space, or splice fewer pairs{hint}", options=("store",))
        return expected, free

    def _run(self, sources: Sources, t0: float) -> JobSummary:
        c = self.config
        plan_path = self.work / "plan.json"
        saved = Plan.load(plan_path) if plan_path.exists() else None
        if saved is not None and saved.made_for(c):  # a resume of the same job: its plan stands
            plan = saved
        else:
            plan = make_plan(c, sources)
        new_plan = False
        if saved is not None and saved.digest() != plan.digest():
            raise UnfinishedJobError(
                f"{self.work} holds an unfinished job with other arguments or inputs; rerun it with the same "
                "arguments to finish it")
        expected, free = self._check_room(plan, sources) if self.shard is None else (None, None)  # before any write
        if not plan_path.exists():
            self.work.mkdir(exist_ok=True)
            plan.save(plan_path)
            new_plan = True
        shard_dir = self.work
        tasks = plan.tasks if self.shard is None else slice_tasks(plan.tasks, *self.shard)
        sources.share_banks(plan.groups)
        if c.splice_backend().prepares_once:  # the banks hold what splicing needs: shared with the workers, the clips let go
            if _shares_banks(c):
                if not sources.banks:  # a resumed plan: the banks are in the work folder, or made now
                    sources.bank_dir, sources.bank_tag = self.work, plan.digest()
                    for n, g in enumerate(plan.groups):
                        sources.bank(n, g.clips, g.fps, g.roles(sources.motion(g.clips[0]).skeleton),
                                     c.splice_options(), c.splice_backend())
                sources.save_banks(self.work, plan.digest())
            sources.release_clips(keep=[g.clips[0] for g in plan.groups])
            _return_freed_memory(plan)
        try:
            engine = make_engine(EngineContext(c, plan, plan_path, sources, self.sink, shard_dir,
                                               keep_shards=self.shard is not None or c.layout == "virtual"))
        except BaseException:
            if new_plan:
                _forget_plan(plan_path, shard_dir)
            raise
        out, merged, merge = None, 0, None
        try:
            summary = JobSummary(output=c.output, pairs=len(plan.pairs), skipped=dict(plan.skipped), shard=self.shard,
                                 tasks=len(tasks), engine=engine.describe(), expected=expected, free=free,
                                 retargeted=plan.retargeted)
            if self.shard is None:  # the output, resumed at its last checkpoint if an earlier run left one
                run = {**plan.key, "pairs": len(plan.pairs), "batch_pairs": plan.key["task_pairs"],
                       "plan_sha256": plan.digest(), "command": self.command, "started": self._started,
                       "engine": summary.engine, "pairs_spliced": len(plan.pairs)}
                out, merged = open_output(self.sink, c, plan, self.work, run, self.overwrite,
                                           lambda g: source_skeleton(plan, g, sources), sources)
                remove_merged_shards(shard_dir, self.sink, tasks[:merged], c.layout)
                sources.release_banks()  # in the output now; the workers map their own (this process again if it splices)
                _return_freed_memory(plan)
            have = {t.id for t in tasks[:merged]} | {t.id for t in tasks[merged:] if task_finished(shard_dir, self.sink, t)}
            pending = [t for t in tasks if t.id not in have]
            summary.resumed = sum(t.size for t in tasks if t.id in have)
            if out is not None:
                merge = OutputMerge(out, self.sink, c, plan, tasks, shard_dir, merged, have,
                               lambda g: source_skeleton(plan, g, sources))
        except BaseException:
            if out is not None:
                out.abort()
            engine.close()
            if new_plan and out is None and self.shard is None:  # refused before the output was staged (a store it cannot write)
                _forget_plan(plan_path, shard_dir)
            raise
        log.info("%d pairs in %d tasks (%d already done, %d of them in the output) on %s", sum(t.size for t in tasks),
                 len(tasks), len(have), merged, summary.engine)
        bar = progress_bar(sum(t.size for t in tasks), summary.resumed, self.progress)

        def done(task, part) -> None:
            if merge is not None:
                merge.add(task, part)
            bar.update(task.size)
            bar.set_postfix_str(f"workers {engine.alive()}", refresh=False)
            check_stop()  # a SIGTERM that a library swallowed still stops the job here, its tasks kept

        t1 = time.perf_counter()
        try:
            if merge is not None:
                merge.flush()  # tasks an earlier run finished, ahead of the first new one
            engine.run(pending, done)
            summary.compute_seconds = time.perf_counter() - t1
            summary.tasks_done = len(have) + len(pending)
            if merge is not None:
                merge.finish(sources, summary)
        except BaseException:
            if merge is not None:
                merge.save_progress()
            if out is not None:
                out.abort()  # the staged output keeps its last checkpoint: a rerun resumes there
            raise
        finally:
            if merge is not None:
                merge.close()
            bar.close()
            engine.close()
        if self.shard is not None:
            marker = self.work / f"slice-{self.shard[0]}-of-{self.shard[1]}.done"
            marker.write_text(f"{socket.gethostname()} {self._started}\n")
        return summary


def splice_all(database, output, *, restart: bool = False, overwrite: bool = False, shard=None,
               progress: bool = False, command: str | None = None, dry_run: bool = False, **options) -> JobSummary:
    """Splice every selected locomotion x action pair of ``database`` into the new database
    ``output``: what ``torchsplice splice-all DATABASE -o OUTPUT ...`` does, from Python.

    ``options`` take the same selections and settings as the command line's flags, under the
    names of :class:`~torchsplice.job.config.JobConfig` (built by
    :func:`~torchsplice.job.config.job_config`, as the command line builds it)::

        summary = splice_all("bandai.h5", "spliced.h5", locomotions="label:style=normal",
                             actions=["role:action,role:both", "*walk*"], methods="splice,naive",
                             engine="local", workers=2, timing="loop", copy_sources=True)

    - selections: ``locomotions``, ``actions`` (a selector string or a list that must all
      match; ``None``: the spec's roles), ``actions_db``, ``max_length_ratio``;
    - splicing: ``methods`` (``"splice,naive"`` or a sequence; plug-ins included),
      ``force_locomotion``, ``timing``, ``acting_limbs``, ``max_run``, ``posture``, ``device``;
    - output: ``copy_sources``, ``compression``, ``layout``, ``index`` (``NAME.h5.index.csv`` beside it);
    - running: ``engine`` (``"local"`` or ``"ray"``), ``workers``, ``ray_address``,
      ``memory_budget_mb``, ``batch_pairs``.

    ``restart`` discards an unfinished run of another plan (``--restart``), ``overwrite``
    replaces an existing output (``--force``), ``shard`` (``"K/N"`` or ``(K, N)``) runs one
    slice into the work folder and writes no output (``--shard``); ``dry_run`` plans the job
    and says what it would do and how much disk its output needs, writing nothing
    (``--dry-run``); ``progress`` shows the progress bar. An interrupted call (Ctrl-C) keeps its
    finished tasks: the same call resumes.
    With ``engine="local"`` and more than one worker, a script must guard its entry point with
    ``if __name__ == "__main__":`` (multiprocessing re-imports it).

    Returns the :class:`JobSummary` (``spliced``, ``skipped`` by reason, ``flagged``,
    ``seconds``; ``lines()`` is what the command line prints).
    """
    config = job_config(database, output, **options)
    if shard is not None:
        shard = parse_shard(shard)
    job = SpliceJob(config, progress=progress, restart=restart, overwrite=overwrite,
                    command=command or "torchsplice.job.splice_all (Python API)", shard=tuple(shard) if shard else None,
                    dry_run=dry_run)
    return job.run()


# ----------------------------------------------------------------------------------------- helpers
def _shares_banks(config: JobConfig) -> bool:
    """Whether the job's local workers map the driver's banks (see :mod:`.sources`)."""
    return config.engine == "local" and config.uses_worker_processes()


def _forget_plan(plan_path: Path, shard_dir: Path) -> None:
    """A plan this run saved, removed when the run is refused before any task ran, so that it
    does not tie the next run to these arguments; the work folder goes too when it is empty."""
    if any(shard_dir.glob("part-*")):
        return
    plan_path.unlink(missing_ok=True)
    try:
        plan_path.parent.rmdir()  # only when empty
    except OSError:
        pass


def _free_bytes(folder: Path) -> int | None:
    try:
        return shutil.disk_usage(folder).free
    except OSError:
        return None


RETURN_FREED_FRAMES = 100_000
"""Source clips of at least this many frames in all (about 70 MB of 25-joint float32 frames; the
whole Bandai Namco dataset has 417,000) leave enough freed memory for the driver to give it
back (:func:`_return_freed_memory`). Below it, the full garbage collection that goes first costs
more than it returns: 0.13 s in a fresh command's process, 0.2 s in one holding many objects
(a test run, a notebook), twice a job."""


def _return_freed_memory(plan) -> None:
    """Give the memory planning freed back to the system (glibc keeps freed heap memory, and
    planning's batches of clips leave much of it), so that the driver holds what it uses: for a
    plan whose clips hold :data:`RETURN_FREED_FRAMES` frames or more."""
    if sum(c.frames for c in plan.clips.values()) < RETURN_FREED_FRAMES:
        return
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


class _compute_threads:
    """On the compiled path, torch's intra-op threads are one while the job runs (no fine-grained
    parallel regions), and one worker in this process computes with one thread."""

    def __init__(self, config: JobConfig):
        self.config = config

    def __enter__(self):
        self.old_torch = torch.get_num_threads()
        self.old = None
        backend = self.config.splice_backend()
        if backend.prepares_once:  # a compiled splicer computes in threads of its own
            torch.set_num_threads(1)
            if self.config.engine == "local" and self.config.worker_count() == 1:
                self.old = backend.threads()
                backend.set_threads(1)
        return self

    def __exit__(self, *exc):
        torch.set_num_threads(self.old_torch)
        if self.old is not None:
            self.config.splice_backend().set_threads(self.old)
