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

import contextlib
import logging
import os
import re
import shutil
import socket
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch

from ..core.errors import OutputExistsError, TorchspliceError, UnfinishedJobError
from ..store.lock import FileLock, check_name_length, remove_stale_temporaries
from ..splice.registry import get_method
from .config import DEFAULT_ACTIONS, DEFAULT_LOCOMOTIONS, JobConfig
from .engines import EngineContext, make_engine
from .engines.forkserver import prestart
from .plan import SKELETONS_DIFFER, Plan, make_plan
from .sink import HDF5Sink
from .sources import Sources
from .size import OutputSize, estimate_output, format_bytes
from .task import FLAG_SEPARATOR, FRAME_COLUMNS, OUTPUT_COLUMNS, POOR_ALIGNMENT, Part

__all__ = ["JobConfig", "JobSummary", "SpliceJob", "merge_job", "OUTPUT_COLUMNS", "FRAME_COLUMNS", "POOR_ALIGNMENT",
           "FLAG_SEPARATOR", "DEFAULT_LOCOMOTIONS", "DEFAULT_ACTIONS"]

log = logging.getLogger("torchsplice.job")


REASON_OPTIONS = ("max_length_ratio", "force_locomotion")
"""Options that skip reasons may name, as ``{name}``."""


@dataclass
class JobSummary:
    """What a run did. ``skipped`` maps a reason to the number of pairs it skipped, ``flagged``
    a kind of flag to the number of clips carrying it (``flagged_clips`` clips in all). A reason
    may name an option as ``{name}`` (of :data:`REASON_OPTIONS`, as errors do, see
    :mod:`torchsplice.core.errors`); :meth:`lines` writes it out."""

    output: Path
    pairs: int = 0
    spliced: int = 0
    resumed: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    flagged: dict[str, int] = field(default_factory=dict)
    flagged_clips: int = 0
    timings: dict[str, int] = field(default_factory=dict)
    copied: int = 0
    seconds: float = 0.0
    compute_seconds: float = 0.0
    engine: str = ""
    shard: tuple[int, int] | None = None
    tasks: int = 0
    tasks_done: int = 0
    merge: bool = False
    merged_shards: int = 0  # shards this run appended to the output (an earlier run's are not merged again)
    dry_run: bool = False
    standing: int = 0  # pairs of standing actions among the pairs
    expected: OutputSize | None = None  # the output's expected size (see torchsplice.job.size)
    written: int | None = None  # bytes the output took
    free: int | None = None  # bytes free beside the output when the job started

    def lines(self, option_name=None) -> list[str]:
        """The closing summary, as printed by the command line; ``option_name(option)`` writes the
        options a skip reason names (default: the library's names; the command line: its flags)."""
        from ..core.errors import render_message

        name = option_name or (lambda o: o)
        say = lambda why: render_message(why, REASON_OPTIONS, name)  # noqa: E731
        rate = (self.spliced - self.resumed) / self.compute_seconds if self.compute_seconds > 0 else float("nan")
        where = f" with {self.engine}" if self.engine else ""
        if self.dry_run:
            out = [f"would write {self.output}: {self.pairs} spliced clips in {self.tasks} tasks"
                   + (f" ({self.pairs - self.standing} time-aligned, {self.standing} standing actions)" if self.standing else "")
                   + f"; {self._room()}"]
        elif self.shard is not None:
            k, n = self.shard
            out = [f"slice {k}/{n}: {self.tasks_done} of {self.tasks} tasks done"
                   + (f" ({self.resumed} pairs from an earlier run)" if self.resumed else "")
                   + f" in {self.seconds:.1f} s{where}; when every slice is done: torchsplice merge {self.output}"]
        else:
            done = f" merged from the shards in {self.seconds:.1f} s" if self.merge else \
                f" in {self.seconds:.1f} s ({rate:,.0f} splices/s){where}"
            out = [f"wrote {self.output}: {self.spliced} spliced clips"
                   + (f" ({self.resumed} pairs from an earlier run)" if self.resumed else "")
                   + (f" + {self.copied} source clips" if self.copied else "") + done]
        standing = {t: n for t, n in self.timings.items() if t != "timewarp"}
        if standing:
            out.append(f"  {self.timings.get('timewarp', 0)} time-aligned (timewarp), "
                       + ", ".join(f"{n} standing actions ({t})" for t, n in sorted(standing.items())))
        if self.written is not None and not self.dry_run:
            out.append(f"  {format_bytes(self.written)} on disk" + (f" (expected {format_bytes(self.expected.bytes)})"
                                                                    if self.expected is not None else ""))
        skipped = {w: n for w, n in self.skipped.items() if not w.startswith(SKELETONS_DIFFER)}
        apart = {w[len(SKELETONS_DIFFER):]: n for w, n in self.skipped.items() if w.startswith(SKELETONS_DIFFER)}
        if skipped:
            out.append(f"skipped {sum(skipped.values())} pairs:" if self.shard is None and not self.dry_run else
                       f"the whole job (every slice) skips {sum(skipped.values())} pairs:" if self.shard is not None else
                       f"would skip {sum(skipped.values())} pairs:")
            out += _reason_lines(skipped, say)
        if apart:
            out.append(f"not formed: {sum(apart.values())} pairs whose clips are on skeletons of different joints "
                       "(splicing needs one joint hierarchy):")
            out += [f"  {n} x {why}" for why, n in sorted(apart.items(), key=lambda kv: -kv[1])]
        if self.flagged:
            out.append(f"flagged {self.flagged_clips} clips (see the 'flags' column):")
            out += [f"  {n} x {why}" for why, n in sorted(self.flagged.items(), key=lambda kv: -kv[1])]
        return out

    def _room(self) -> str:
        folder = self.output.parent
        expect = (f"expected output about {format_bytes(self.expected.bytes)} ({self.expected.frames:,} frames)"
                  if self.expected is not None else "")
        free = f"{format_bytes(self.free)} free in {folder}" if self.free is not None else ""
        fits = "" if self.expected is None or self.free is None else \
            ("" if self.free >= self.expected.bytes else " (it does not fit)")
        return "; ".join(x for x in (expect, free) if x) + fits


REASONS_SHOWN = 8
"""Skip reasons of one kind (clips that do not locomote, clips too short) listed one by one; more
are summed up in one line."""


_KINDS = ((re.compile(r"^\S+ does not locomote \("), "clips that do not locomote"),
          (re.compile(r"^\S+ is too short to splice \("), "clips too short to splice"),
          (re.compile(r"^no plain-locomotion reference for \S+ \((\S+)\)$"), "actions with no plain-locomotion reference"))


def _reason_lines(skipped: dict[str, int], say) -> list[str]:
    """``N x reason`` lines, most frequent first; reasons of one kind that name a clip (clips
    that do not locomote, are too short or have no reference) past the first
    :data:`REASONS_SHOWN` summed up in one line."""
    kinds: dict[str, list] = {}
    for why, n in sorted(skipped.items(), key=lambda kv: -kv[1]):
        text = say(why)
        kind = next((label for pattern, label in _KINDS if pattern.search(text)), text)
        kinds.setdefault(kind, []).append((n, text))
    out = []
    for kind, items in kinds.items():
        out += [f"  {n} x {text}" for n, text in items[:REASONS_SHOWN]]
        if len(items) > REASONS_SHOWN:
            rest = items[REASONS_SHOWN:]
            out.append(f"  {sum(n for n, _ in rest)} x {len(rest)} other {kind}")
    return out


class SpliceJob:
    """Plan and run one splice job, or one slice of it (see the module docstring)."""

    def __init__(self, config: JobConfig, progress: bool = True, restart: bool = False, overwrite: bool = False,
                 command: str | None = None, shard: tuple[int, int] | None = None, dry_run: bool = False):
        self.config = config.checked()
        self.progress, self.restart, self.overwrite, self.shard = progress, restart, overwrite, shard
        self.dry_run = dry_run
        self.command = command or "torchsplice.job.SpliceJob (Python API)"
        self.work = self.config.work
        self.sink = HDF5Sink()

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
        prestart(c.engine, c.worker_count(), c.device)
        if self.shard is not None and self.restart:
            raise TorchspliceError("{restart} discards the whole job, every slice's work too: run it once without {shard}",
                                   options=("restart", "shard"))
        if self.shard is None:
            lock = FileLock(_output_lock(c.output), str(c.output), self.command)
        else:
            self.work.mkdir(exist_ok=True)
            lock = FileLock(self.work / f"lock-{self.shard[0]}-of-{self.shard[1]}", f"slice {self.shard[0]}/{self.shard[1]} of {c.output}", self.command)
        with lock, _compute_threads(c):
            if self.shard is None:
                _refuse_live_slices(self.work)
            if self.restart and self.work.exists():
                _clear_work(self.work, keep=lock.path)
            for folder in (self.work, c.output.parent):
                remove_stale_temporaries(folder)
            sources = Sources(c.database, c.actions_db)
            try:
                summary = self._run(sources, t0)
            finally:
                sources.close()
            if self.shard is None:
                shutil.rmtree(self.work, ignore_errors=True)
        summary.seconds = time.perf_counter() - t0
        return summary

    def _dry_run(self, t0: float) -> JobSummary:
        """Plan, and say what the job would do and how much disk it needs; writes nothing."""
        c = self.config
        sources = Sources(c.database, c.actions_db)
        try:
            plan = make_plan(c, sources)
            summary = JobSummary(output=c.output, pairs=len(plan.pairs), skipped=dict(plan.skipped), tasks=len(plan.tasks),
                                 dry_run=True, standing=sum(p.mode == "standing" for p in plan.pairs))
            summary.expected = self._expected(plan, sources)
            summary.free = _free_bytes(c.output.parent)
        finally:
            sources.close()
        summary.seconds = time.perf_counter() - t0
        return summary

    def _expected(self, plan: Plan, sources: Sources) -> OutputSize:
        copied = None
        if self.config.copy_sources:
            copied = []
            for db, rows in SpliceJob._source_rows(plan, sources):
                t = db.table()
                copied += [(int(t["length"][r]), db.skeletons[int(t["skeleton"][r])]) for r in rows]
        return estimate_output(plan, lambda g: _source_skeleton(plan, g, sources)[0], self.config.compression, copied)

    def _check_room(self, plan: Plan, sources: Sources) -> tuple[OutputSize, int | None]:
        """The output's expected size and the free space; refuses, before any work, a job whose
        output (what is left of it) and banks do not fit."""
        c = self.config
        expected, free = self._expected(plan, sources), _free_bytes(c.output.parent)
        held = sum(f.stat().st_size for f in (self.work / STAGING, self.work / f"{STAGING}.rows") if f.exists())
        banks = sources.unsaved_bank_bytes(self.work) if _shares_banks(c) else 0
        need = max(0, expected.bytes - held) + banks
        if free is not None and need > free:
            raise TorchspliceError(
                f"{c.output}: the job needs about {format_bytes(need)} more on the disk (an output of about "
                f"{format_bytes(expected.bytes)}, {expected.frames:,} frames) and {c.output.parent} has "
                f"{format_bytes(free)} free; free some space, or splice fewer pairs")
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
        tasks = plan.tasks if self.shard is None else _slice(plan.tasks, *self.shard)
        sources.share_banks(plan.groups)
        if c.backend() == "compiled":  # the banks hold what splicing needs: shared with the workers, the clips let go
            if _shares_banks(c):
                if not sources.banks:  # a resumed plan: the banks are in the work folder, or made now
                    sources.bank_dir, sources.bank_tag = self.work, plan.digest()
                    for n, g in enumerate(plan.groups):
                        sources.bank(n, g.clips, g.fps, g.roles(sources.motion(g.clips[0]).skeleton),
                                     c.align_options().landmarks)
                sources.save_banks(self.work, plan.digest())
            sources.release_clips(keep=[g.clips[0] for g in plan.groups])
            _return_freed_memory()
        try:
            engine = make_engine(EngineContext(c, plan, plan_path, sources, self.sink, shard_dir,
                                               keep_shards=self.shard is not None or c.layout == "virtual"))
        except BaseException:
            if new_plan and not any(shard_dir.glob("part-*")):  # nothing was done: leave no plan that would tie
                plan_path.unlink(missing_ok=True)                # the next run to these arguments
                try:
                    self.work.rmdir()  # only when empty
                except OSError:
                    pass
            raise
        out, merged, merge = None, 0, None
        try:
            summary = JobSummary(output=c.output, pairs=len(plan.pairs), skipped=dict(plan.skipped), shard=self.shard,
                                 tasks=len(tasks), engine=engine.describe(), expected=expected, free=free)
            if self.shard is None:  # the output, resumed at its last checkpoint if an earlier run left one
                run = {**plan.key, "pairs": len(plan.pairs), "batch_pairs": plan.key["task_pairs"],
                       "plan_sha256": plan.digest(), "command": self.command, "started": self._started,
                       "engine": summary.engine, "pairs_spliced": len(plan.pairs)}
                out, merged = _open_output(self.sink, c, plan, self.work, run, self.overwrite,
                                           lambda g: _source_skeleton(plan, g, sources), sources)
                _remove_merged_shards(shard_dir, self.sink, tasks[:merged], c.layout)
            have = {t.id for t in tasks[:merged]} | {t.id for t in tasks[merged:] if _finished(shard_dir, self.sink, t)}
            pending = [t for t in tasks if t.id not in have]
            summary.resumed = sum(t.size for t in tasks if t.id in have)
            if out is not None:
                merge = _Merge(out, self.sink, c, plan, tasks, shard_dir, merged, have,
                               lambda g: _source_skeleton(plan, g, sources))
        except BaseException:
            if out is not None:
                out.abort()
            engine.close()
            raise
        log.info("%d pairs in %d tasks (%d already done, %d of them in the output) on %s", sum(t.size for t in tasks),
                 len(tasks), len(have), merged, summary.engine)
        bar = _progress(sum(t.size for t in tasks), summary.resumed, self.progress)

        def done(task, part) -> None:
            if merge is not None:
                merge.add(task, part)
            bar.update(task.size)
            bar.set_postfix_str(f"workers {engine.alive()}", refresh=False)

        t1 = time.perf_counter()
        try:
            if merge is not None:
                merge.flush()  # tasks an earlier run finished, ahead of the first new one
            engine.run(pending, done)
            summary.compute_seconds = time.perf_counter() - t1
            summary.tasks_done = len(have) + len(pending)
            if merge is not None:
                merge.finish(sources, self._copy_sources)
                _summarise_output(summary, out, merge)
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

    @staticmethod
    def _source_rows(plan: Plan, sources: Sources) -> list:
        """``(database, rows)`` of the source clips a ``copy_sources`` output holds: locomotions
        first, then actions and references (one database when both are one file)."""
        return [(sources.db("L"), sorted({p.loco for p in plan.pairs})),
                (sources.db("A"), sorted({p.action for p in plan.pairs}
                                         | {p.reference for p in plan.pairs if p.reference is not None
                                            and get_method(p.method).needs_reference}))]

    @staticmethod
    def _copy_sources(out, plan: Plan, sources: Sources) -> None:
        out.copy_sources(SpliceJob._source_rows(plan, sources))


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
    - output: ``copy_sources``, ``compression``, ``layout``;
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
    from .config import job_config, parse_shard

    config = job_config(database, output, **options)
    if shard is not None:
        shard = parse_shard(shard)
    job = SpliceJob(config, progress=progress, restart=restart, overwrite=overwrite,
                    command=command or "torchsplice.job.splice_all (Python API)", shard=tuple(shard) if shard else None,
                    dry_run=dry_run)
    return job.run()


def merge_job(output: Path, overwrite: bool = False, progress: bool = True, command: str | None = None) -> JobSummary:
    """Write ``output`` from the finished shards of its job (``splice-all --shard`` runs).

    Resumable as the job is: a merge killed midway goes on from its last checkpoint."""
    output = Path(output)
    if output.name in ("", ".", "..") or output.is_dir():
        raise TorchspliceError(f"{output}: is a folder; name the job's output database (OUT.h5)")
    check_name_length(output)
    work = output.with_name(f".{output.name}.parts")
    plan_path = work / "plan.json"
    if not plan_path.exists():
        raise TorchspliceError(f"{output}: no unfinished splice-all job to merge (no {plan_path})")
    if output.exists() and not overwrite:
        raise OutputExistsError(f"{output}: already exists")
    plan = Plan.load(plan_path)
    key = plan.key
    config = JobConfig(database=Path(key["database"]["path"]), output=output,
                       actions_db=Path(key["actions_db"]["path"]) if key["actions_db"] else None,
                       copy_sources=key["copy_sources"], compression=key["compression"], layout=key["layout"]).checked()
    if config.copy_sources and Path(key["database"]["path"]).exists():
        from .plan import plan_key as _key

        now = _key(config)
        if now["database"] != key["database"] or now["actions_db"] != key["actions_db"]:
            raise UnfinishedJobError(f"{output}: the job's input databases changed since it was planned; cannot copy its "
                                     "source clips")
    t0 = time.perf_counter()
    sink = HDF5Sink()
    shard_dir = work
    merged = _checkpointed_tasks(work, plan)
    missing = [t for t in plan.tasks[merged:] if not (shard_dir / sink.shard_name(t.id)).exists()]
    if missing:
        done = sorted((int(m.group(1)), int(m.group(2))) for f in work.glob("slice-*-of-*.done")
                      if (m := re.fullmatch(r"slice-(\d+)-of-(\d+)\.done", f.name)))
        n = done[0][1] if done else None
        hint = ""
        if n is not None:
            have = sorted({k for k, m in done if m == n})
            hint = f"; slices of {n} done: {_ranges(have)}; missing: {_ranges(_gaps(have, n)) or 'none'}"
        raise TorchspliceError(f"{output}: {len(missing)} of {len(plan.tasks)} tasks have no shard yet (first: task "
                               f"{missing[0].id}){hint}")
    with FileLock(_output_lock(output), str(output), command or ""):
        _refuse_live_slices(work)
        for folder in (work, output.parent):  # what a killed merge left
            remove_stale_temporaries(folder)
        summary = JobSummary(output=output, pairs=len(plan.pairs), skipped=dict(plan.skipped), engine="merge", merge=True)
        run = {**key, "pairs": len(plan.pairs), "batch_pairs": key["task_pairs"], "plan_sha256": plan.digest(),
               "command": command or "torchsplice.job.merge_job (Python API)",
               "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "engine": "merge", "pairs_spliced": len(plan.pairs)}
        sources = Sources(config.database, config.actions_db)
        out = None
        try:
            out, merged = _open_output(sink, config, plan, work, run, overwrite,
                                       lambda g: _shard_skeleton(plan, g, sink, shard_dir), sources)
            _remove_merged_shards(shard_dir, sink, plan.tasks[:merged], config.layout)
            if any(not (shard_dir / sink.shard_name(t.id)).exists() for t in plan.tasks[merged:]):
                raise TorchspliceError(f"{output}: the merge's staged output could not be resumed and some shards it "
                                       "held are gone; run the whole job once without {shard} to splice them again",
                                       options=("shard",))
            summary.resumed = sum(t.size for t in plan.tasks[:merged])
            merge = _Merge(out, sink, config, plan, plan.tasks, shard_dir, merged, {t.id for t in plan.tasks})
            bar = _progress(len(plan.pairs), summary.resumed, progress)
            try:
                for t in plan.tasks[merged:]:
                    merge.flush(limit=1)
                    bar.update(t.size)
                merge.finish(sources, SpliceJob._copy_sources)
            except BaseException:
                merge.save_progress()
                raise
            finally:
                merge.close()
                bar.close()
        except BaseException:
            if out is not None:
                out.abort()
            raise
        finally:
            sources.close()
        shutil.rmtree(work, ignore_errors=True)
    _summarise_output(summary, out, merge)
    summary.seconds = summary.compute_seconds = time.perf_counter() - t0
    return summary


# ----------------------------------------------------------------------------------------- helpers
STAGING = "output.h5"
"""The output's name in the work folder while the job writes it (see :mod:`.sink`)."""


CHECKPOINT_SECONDS = 2.0
"""How often the merge checkpoints the output (and at its end; the environment variable
``TORCHSPLICE_CHECKPOINT_SECONDS`` overrides it, 0: after every task): a killed job resumes
from the last checkpoint, and splices again the tasks merged after it (at most these seconds
of work)."""


def _checkpoint_seconds() -> float:
    try:
        return max(0.0, float(os.environ.get("TORCHSPLICE_CHECKPOINT_SECONDS", CHECKPOINT_SECONDS)))
    except ValueError:
        return CHECKPOINT_SECONDS


class _Merge:
    """Joins finished tasks into the output in plan order, checkpointing it every
    :data:`CHECKPOINT_SECONDS`. A task's part file is appended once and deleted at once; a
    shard (the work of a ``--shard`` run) once a checkpoint holds it (``copy`` layout: a
    ``virtual`` output's shards are its frames and stay); deletions run in a background thread.
    Tasks that finish ahead of their turn wait on disk, a few of them in memory."""

    def __init__(self, out, sink, config: JobConfig, plan: Plan, tasks: list, shard_dir: Path, merged: int, have,
                 group_skeleton=None):
        self.out, self.sink, self.config, self.plan, self.tasks, self.shard_dir = out, sink, config, plan, tasks, shard_dir
        self.group_skeleton = group_skeleton  # group -> (skeleton, spec): the skeleton of part files
        self.order = {t.id: n for n, t in enumerate(tasks)}
        self.ready: dict[int, object] = {self.order[tid]: None for tid in have if self.order[tid] >= merged}
        self.next = merged
        self.appended = 0
        self.checkpointed = merged
        self.rows = len(out.db)
        self.last = time.monotonic()
        self.spent: list[Path] = []  # files of tasks merged since the last checkpoint
        self.remover = None
        self.every = _checkpoint_seconds()

    def add(self, task, part) -> None:
        """A finished task: ``part`` in memory, or ``None`` (its shard or part file is on disk).
        A part also on disk waits there if four others already wait in memory."""
        n = self.order[task.id]
        on_disk = part is None or (self.shard_dir / self.sink.shard_name(task.id)).exists()
        held = sum(p is not None for p in self.ready.values())
        self.ready[n] = part if (n == self.next or held < 4 or not on_disk) else None
        self.flush()

    def flush(self, limit: int | None = None) -> None:
        """Append every task whose turn has come (at most ``limit``)."""
        c, done = self.config, 0
        while self.next in self.ready and (limit is None or done < limit):
            task = self.tasks[self.next]
            part = self.ready.pop(self.next)
            name, file = self.sink.shard_name(task.id), self.shard_dir / self.sink.part_name(task.id)
            if part is None and file.exists():
                part = Part.load(file, self.group_skeleton(task.group)[0])
            self.out.append_shard(self.shard_dir / name, part, virtual=c.layout == "virtual",
                                  refer_as=run_shards(c, self.plan) / name)
            self.next += 1
            self.rows = len(self.out.db)  # what a checkpoint at self.next must hold
            del part  # a mapped part file is let go before it is deleted
            self.appended += 1
            done += 1
            self._remove([file])  # a part is recomputed rather than kept until a checkpoint: the disk stays free
            if c.layout != "virtual":
                self.spent.append(self.shard_dir / name)  # a shard may hold another run's work: kept until then
            if time.monotonic() - self.last >= self.every:
                self.checkpoint()

    def checkpoint(self) -> None:
        """Checkpoint the output at the tasks appended so far, then delete their files."""
        if self.checkpointed == self.next:
            return
        self.out.checkpoint({"plan": self.plan.digest(), "tasks": self.next})
        self.checkpointed, self.last = self.next, time.monotonic()
        spent, self.spent = self.spent, []
        self._remove(spent)

    def _remove(self, files: list) -> None:
        """Delete ``files`` in a background thread (freeing their pages costs the kernel time)."""
        if not files:
            return
        if self.remover is None:
            from concurrent.futures import ThreadPoolExecutor

            self.remover = ThreadPoolExecutor(max_workers=1, thread_name_prefix="torchsplice-remove")
        self.remover.submit(lambda: [f.unlink(missing_ok=True) for f in files])

    def save_progress(self) -> None:
        """Checkpoint what was appended before an interruption, if the output is whole: open,
        and holding exactly the tasks counted (an append that was cut short rolls itself back)."""
        try:
            if self.out.db._h5 is not None and len(self.out.db) == self.rows:
                self.checkpoint()
        except Exception:  # the last checkpoint stands
            pass

    def close(self) -> None:
        if self.remover is not None:
            self.remover.shutdown(wait=True)
            self.remover = None

    def finish(self, sources: Sources, copy_sources) -> None:
        """After the last task: the source clips (``copy_sources``), the run record, the shards
        of a virtual output moved into place, and the output renamed into place."""
        c = self.config
        self.flush()
        if self.next != len(self.tasks):
            raise TorchspliceError(f"{c.output}: task {self.tasks[self.next].id} has no shard; rerun to finish the job")
        self.checkpoint()
        self.close()
        if c.copy_sources:
            copy_sources(self.out, self.plan, sources)
        self.out.set_spliced(self.out.clips)
        replaced = _shard_files(c.output)  # the frames of the output this one replaces (a virtual one's)
        mine = run_shards(c, self.plan)
        if c.layout == "virtual":
            _install_shards(self.shard_dir, mine, [self.sink.shard_name(t.id) for t in self.tasks])
        self.out.close()  # the new output is in place: the old one's shards are its no more
        _remove_shard_files([f for f in replaced if f.parent != mine], c.shards_folder)


def _open_output(sink, config: JobConfig, plan: Plan, work: Path, run: dict, overwrite: bool, group_skeleton,
                 sources: Sources):
    """``(output, merged)``: the staged output resumed at its last checkpoint, holding the first
    ``merged`` tasks of the plan, or a new one holding the output's skeletons (``merged`` 0)."""
    staging = work / STAGING
    resumed = sink.resume_output(config.output, staging, overwrite)
    if resumed is not None:
        out, note = resumed
        tasks = note.get("tasks")
        if note.get("plan") == plan.digest() and isinstance(tasks, int) and 0 <= tasks <= len(plan.tasks):
            out.expect_plan = plan.digest()
            return out, tasks
        out.abort()
        _discard_staging(work)
    skeletons = _output_skeletons(plan, group_skeleton, sources if config.copy_sources else None)
    out = sink.open_output(config.output, config.compression, run, overwrite, staging, skeletons)
    out.expect_plan = plan.digest()
    return out, 0


def _checkpointed_tasks(work: Path, plan: Plan) -> int:
    """How many tasks the staged output's last checkpoint holds (0 when none or another plan's)."""
    from ..store.database import MotionDatabase

    note = MotionDatabase.checkpoint_note(work / STAGING) or {}
    tasks = note.get("tasks")
    return tasks if note.get("plan") == plan.digest() and isinstance(tasks, int) and 0 <= tasks <= len(plan.tasks) else 0


def _discard_staging(work: Path) -> None:
    for f in (work / STAGING, work / f"{STAGING}.commit"):
        f.unlink(missing_ok=True)


def _finished(shard_dir: Path, sink, task) -> bool:
    """Whether a task's results wait on disk: its shard, or its part file."""
    return (shard_dir / sink.shard_name(task.id)).exists() or (shard_dir / sink.part_name(task.id)).exists()


def _remove_merged_shards(shard_dir: Path, sink, tasks: list, layout: str) -> None:
    """Part files and shards whose clips the output holds already (left by a job killed between
    its checkpoint and their removal); a virtual output's shards are its frames and stay."""
    for t in tasks:
        (shard_dir / sink.part_name(t.id)).unlink(missing_ok=True)
        if layout != "virtual":
            (shard_dir / sink.shard_name(t.id)).unlink(missing_ok=True)


def _output_skeletons(plan: Plan, group_skeleton, sources: Sources | None) -> list:
    """``(Skeleton, spec)`` of every skeleton the output will hold, in the order its clips
    arrive: each locomotion group's (``group_skeleton(g)``, ``(None, None)`` when unknown), in
    task order, then (``sources``: the source clips are copied) those of the source clips."""
    from ..specs import DatasetSpec

    out, seen = [], set()
    for t in plan.tasks:
        if t.group not in seen:
            seen.add(t.group)
            sk, spec = group_skeleton(t.group)
            if sk is not None:
                out.append((sk, spec))
    if sources is not None:
        for db, rows in SpliceJob._source_rows(plan, sources):
            ks = db.table()["skeleton"]
            for r in rows:
                k = int(ks[r])
                text = db.spec_json(k)
                out.append((db.skeletons[k], DatasetSpec.from_json(text) if text else None))
    return out


def _source_skeleton(plan: Plan, g: int, sources: Sources):
    """A locomotion group's skeleton and spec, from its first clip."""
    from ..specs import DatasetSpec

    group = plan.groups[g]
    return sources.motion(group.clips[0]).skeleton, DatasetSpec.from_json(group.spec)


def _shard_skeleton(plan: Plan, g: int, sink, shard_dir: Path):
    """A locomotion group's skeleton and spec, from the first of its shards that holds clips."""
    from ..store.database import MotionDatabase
    from ..specs import DatasetSpec

    for t in plan.tasks:
        path = shard_dir / sink.shard_name(t.id)
        if t.group == g and path.exists():
            with MotionDatabase.open(path) as shard:
                if len(shard):
                    return shard.skeletons[0], DatasetSpec.from_json(plan.groups[g].spec)
    return None, None


def _summarise_output(summary: JobSummary, out, merge: _Merge) -> None:
    summary.merged_shards = merge.appended
    c = merge.config
    shards = run_shards(c, merge.plan)
    summary.written = c.output.stat().st_size + (sum(f.stat().st_size for f in shards.iterdir())
                                                 if c.layout == "virtual" and shards.is_dir() else 0)
    summary.spliced, summary.flagged, summary.flagged_clips, summary.copied, summary.timings = (
        out.clips, out.flagged, out.flagged_clips, out.copied, out.timings)
    for why, n in out.skipped.items():
        summary.skipped[why] = summary.skipped.get(why, 0) + n


def _shares_banks(config: JobConfig) -> bool:
    """Whether the job's local workers map the driver's banks (see :mod:`.sources`)."""
    return config.backend() == "compiled" and config.engine == "local" and config.worker_count() > 1


def _free_bytes(folder: Path) -> int | None:
    try:
        return shutil.disk_usage(folder).free
    except OSError:
        return None


def _return_freed_memory() -> None:
    """Give the memory planning freed back to the system (glibc keeps freed heap memory, and
    planning's batches of clips leave much of it), so that the driver holds what it uses."""
    import ctypes
    import gc

    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def _gaps(have: list[int], n: int) -> list[tuple[int, int]]:
    """The runs ``(first, last)`` of 1..n missing from the sorted ``have``."""
    out, nxt = [], 1
    for k in have + [n + 1]:
        if k > nxt:
            out.append((nxt, k - 1))
        nxt = max(nxt, k + 1)
    return out


def _ranges(items, shown: int = 8) -> str:
    """Numbers (or ``(first, last)`` runs) as ``1-3, 5, 7-9``: at most ``shown`` runs, then a count."""
    runs = []
    for x in items:
        a, b = x if isinstance(x, tuple) else (x, x)
        if runs and runs[-1][1] + 1 == a:
            runs[-1] = (runs[-1][0], b)
        else:
            runs.append((a, b))
    text = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs[:shown])
    return text + (f" and {len(runs) - shown} more runs" if len(runs) > shown else "")


def _slice(tasks: list, k: int, n: int) -> list:
    """The K-th of N contiguous slices of the tasks (1-based)."""
    return tasks[(k - 1) * len(tasks) // n: k * len(tasks) // n]


def _refuse_live_slices(work: Path) -> None:
    """A whole run or a merge must not touch the work folder while a slice writes into it."""
    if not work.is_dir():
        return
    for lock in sorted(work.glob("lock-*-of-*")):
        holder = FileLock(lock, "").holder()
        if holder is not None and not FileLock.stale(holder):
            raise TorchspliceError(f"{work}: slice {lock.name[5:].replace('-of-', '/')} is still running (process "
                                   f"{holder.get('pid')} on {holder.get('host')}); wait for it to finish")


def run_shards(config: JobConfig, plan: Plan) -> Path:
    """Where a ``virtual`` output of ``plan`` keeps its shards: ``OUT.h5.shards/<plan digest>/``.
    Each run of other settings has its own folder, so that an output renamed away keeps reading
    its own frames, and replacing an output never touches the frames it reads until the new one
    is in place."""
    return config.shards_folder / plan.digest()[:16]


def _install_shards(work: Path, folder: Path, names: list[str]) -> None:
    """Move a virtual output's shards from ``work`` into ``folder``, one atomic rename each. A
    shard already there (a rerun of an install that was cut short, or of the same plan, whose
    shards are the same bits) is replaced in place: at every moment every output that reads
    ``folder`` finds whole shards."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        src = work / name
        if src.exists():
            os.replace(src, folder / name)
        elif not (folder / name).exists():
            raise TorchspliceError(f"{folder}: shard {name} is missing, and the job's work folder has it no more; "
                                   "rerun the job with {restart}", options=("restart",))


def _shard_files(output: Path) -> set[Path]:
    """The files whose frames ``output`` reads through virtual datasets (empty for a copy or a
    file that is not there or not readable)."""
    import h5py

    if not output.is_file():
        return set()
    files: set[Path] = set()
    try:
        with h5py.File(output, "r") as f:
            for g in f["skeletons"].values():
                for ds in g.values():
                    if isinstance(ds, h5py.Dataset) and ds.is_virtual:
                        files |= {(output.parent / vs.file_name).resolve() for vs in ds.virtual_sources()
                                  if vs.file_name != "."}
    except (OSError, KeyError, ValueError):
        return set()
    return files


def _remove_shard_files(files, shards_folder: Path) -> None:
    """Delete shard files no output reads any more, then the folders of ``shards_folder`` they
    leave empty (the folder itself too)."""
    for f in files:
        if shards_folder.resolve() in f.parents:  # never a file outside the output's shards
            f.unlink(missing_ok=True)
    if shards_folder.is_dir():
        for sub in sorted((p for p in shards_folder.iterdir() if p.is_dir()), reverse=True):
            with contextlib.suppress(OSError):
                sub.rmdir()  # only when empty
        with contextlib.suppress(OSError):
            shards_folder.rmdir()


def _output_lock(output: Path) -> Path:
    return output.with_name(f".{output.name}.lock")


def _clear_work(work: Path, keep: Path) -> None:
    """Discard an unfinished run's plan and shards (not the lock just taken)."""
    for f in work.iterdir():
        if f != keep:
            shutil.rmtree(f, ignore_errors=True) if f.is_dir() else f.unlink(missing_ok=True)


class _compute_threads:
    """On the compiled path, torch's intra-op threads are one while the job runs (no fine-grained
    parallel regions), and one worker in this process computes with one thread."""

    def __init__(self, config: JobConfig):
        self.config = config

    def __enter__(self):
        self.old_torch = torch.get_num_threads()
        self.old = None
        if self.config.backend() == "compiled":
            from ..cpu import get_threads, set_threads

            torch.set_num_threads(1)
            if self.config.engine == "local" and self.config.worker_count() == 1:
                self.old = get_threads()
                set_threads(1)
        return self

    def __exit__(self, *exc):
        torch.set_num_threads(self.old_torch)
        if self.old is not None:
            from ..cpu import set_threads

            set_threads(self.old)


def _progress(total: int, initial: int, show: bool):
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="splice", desc="splice-all", disable=True if not show else None,
                file=sys.stderr, dynamic_ncols=True, smoothing=0.1)
