"""The job's output: tasks merged as they finish into a staged output with checkpoints, and
:func:`merge_job`, which writes an output from the shards of ``--shard`` runs. The run and the
merge end alike, in :meth:`OutputMerge.finish`."""

from __future__ import annotations

import logging
import os

import numpy as np
import re
import shutil
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from ..core.errors import OutputExistsError, TorchspliceError, UnfinishedJobError
from ..core.stop import check_stop
from ..formats.index import refresh_database_index
from ..ops.body import body_of
from ..ops.hands import arms_of
from ..specs import DatasetSpec
from ..splice.registry import get_method
from ..splice.standing import LIMBS
from ..store.lock import FileLock, check_name_length, remove_stale_temporaries
from ..store.database import MotionDatabase
from . import shards
from .config import JobConfig
from .defaults import DEFAULT_INDEX
from .plan import Plan, plan_key
from .shards import gaps, output_lock_path, ranges, refuse_live_slices, remove_shard_files, run_shards
from .sink import make_sink
from .sources import Sources, retargeted_parts
from .summary import JobSummary, progress_bar
from .task import Part

__all__ = ["merge_job", "OutputMerge", "source_rows", "open_output", "output_banks", "STAGING", "CHECKPOINT_SECONDS",
           "source_skeleton", "summarise_output", "checkpointed_tasks", "discard_staging", "task_finished",
           "remove_merged_shards"]

log = logging.getLogger("torchsplice.job")


def merge_job(output: Path, overwrite: bool = False, progress: bool = True, command: str | None = None,
              index: bool = DEFAULT_INDEX) -> JobSummary:
    """Write ``output`` from the finished shards of its job (``splice-all --shard`` runs), and
    with ``index`` its ``NAME.h5.index.csv`` beside it (as the job does: see ``JobConfig.index``).

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
                       copy_sources=key["copy_sources"], compression=key["compression"], layout=key["layout"],
                       fix_feet=key.get("fix_feet", True), store=key.get("store", "motion")).checked()
    if config.store == "alignment" and not all(Path(key[k]["path"]).is_file() for k in ("database", "actions_db")
                                               if key[k]):
        raise UnfinishedJobError(f"{output}: an alignment store holds the job's source clips, and its input databases "
                                 "are gone; merge where they are")
    if (config.copy_sources or config.store == "alignment") and Path(key["database"]["path"]).exists():
        now = plan_key(config)
        if now["database"] != key["database"] or now["actions_db"] != key["actions_db"]:
            raise UnfinishedJobError(f"{output}: the job's input databases changed since it was planned; cannot copy its "
                                     "source clips")
    t0 = time.perf_counter()
    sink = make_sink(config)
    shard_dir = work
    merged = checkpointed_tasks(work, plan)
    missing = [t for t in plan.tasks[merged:] if not (shard_dir / sink.shard_name(t.id)).exists()]
    if missing:
        done = sorted((int(m.group(1)), int(m.group(2))) for f in work.glob("slice-*-of-*.done")
                      if (m := re.fullmatch(r"slice-(\d+)-of-(\d+)\.done", f.name)))
        n = done[0][1] if done else None
        hint = ""
        if n is not None:
            have = sorted({k for k, m in done if m == n})
            hint = f"; slices of {n} done: {ranges(have)}; missing: {ranges(gaps(have, n)) or 'none'}"
        raise TorchspliceError(f"{output}: {len(missing)} of {len(plan.tasks)} tasks have no shard yet (first: task "
                               f"{missing[0].id}){hint}")
    with FileLock(output_lock_path(output), str(output), command or ""):
        refuse_live_slices(work)
        for folder in (work, output.parent):  # what a killed merge left
            remove_stale_temporaries(folder)
        summary = JobSummary(output=output, pairs=len(plan.pairs), skipped=dict(plan.skipped), engine="merge", merge=True,
                             retargeted=plan.retargeted)
        run = {**key, "pairs": len(plan.pairs), "batch_pairs": key["task_pairs"], "plan_sha256": plan.digest(),
               "command": command or "torchsplice.job.merge_job (Python API)",
               "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "engine": "merge", "pairs_spliced": len(plan.pairs)}
        sources = Sources(config.database, config.actions_db, fix_feet=config.fix_feet)
        out = None
        try:
            skeleton_of = (lambda g: source_skeleton(plan, g, sources)) if config.store == "alignment" else \
                (lambda g: _shard_skeleton(plan, g, sink, shard_dir))
            out, merged = open_output(sink, config, plan, work, run, overwrite, skeleton_of, sources)
            remove_merged_shards(shard_dir, sink, plan.tasks[:merged], config.layout)
            if any(not (shard_dir / sink.shard_name(t.id)).exists() for t in plan.tasks[merged:]):
                raise TorchspliceError(f"{output}: the merge's staged output could not be resumed and some shards it "
                                       "held are gone; run the whole job once without {shard} to splice them again",
                                       options=("shard",))
            summary.resumed = sum(t.size for t in plan.tasks[:merged])
            merge = OutputMerge(out, sink, config, plan, plan.tasks, shard_dir, merged, {t.id for t in plan.tasks},
                                skeleton_of)
            bar = progress_bar(len(plan.pairs), summary.resumed, progress)
            try:
                for t in plan.tasks[merged:]:
                    merge.flush(limit=1)
                    bar.update(t.size)
                    check_stop()
                merge.finish(sources, summary)
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

        summary.index = refresh_database_index(output, write=index)  # never an earlier run's left beside it
    summary.seconds = summary.compute_seconds = time.perf_counter() - t0
    return summary


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


class OutputMerge:
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
            elif part is None:  # a shard that is a part (an alignment store's), or None: the sink reads it
                part = self.sink.load_shard(self.shard_dir / name, lambda: self.group_skeleton(task.group)[0])
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

    def finish(self, sources: Sources, summary: JobSummary) -> None:
        """After the last task: the source clips (``copy_sources``), the run record, the shards
        of a virtual output moved into place, the output renamed into place, and what it holds
        in ``summary``. The run (:class:`~torchsplice.job.run.SpliceJob`) and :func:`merge_job`
        end here alike."""
        c = self.config
        self.flush()
        if self.next != len(self.tasks):
            raise TorchspliceError(f"{c.output}: task {self.tasks[self.next].id} has no shard; rerun to finish the job")
        self.checkpoint()
        self.close()
        check_stop()  # a signal that a library swallowed while the last tasks joined: stop before the output is whole
        if c.copy_sources:
            self.out.copy_sources(source_rows(self.plan, sources))
        self.out.set_spliced(self.out.clips)
        replaced = MotionDatabase.virtual_files(c.output)  # the frames of the output this one replaces (a virtual one's)
        mine = run_shards(c, self.plan)
        check_stop()  # ... or while the sources were copied: the output is not put in place
        if c.layout == "virtual":
            shards.install_shards(self.shard_dir, mine, [self.sink.shard_name(t.id) for t in self.tasks])
        self.out.close()  # the new output is in place: the old one's shards are its no more
        remove_shard_files([f for f in replaced if f.parent != mine], c.shards_folder)
        summarise_output(summary, self.out, self)


def open_output(sink, config: JobConfig, plan: Plan, work: Path, run: dict, overwrite: bool, group_skeleton,
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
        discard_staging(work)
    skeletons = _output_skeletons(plan, group_skeleton, sources if config.copy_sources else None)
    banks = output_banks(plan, sources, config) if config.store == "alignment" else ()
    out = sink.open_output(config.output, config.compression, run, overwrite, staging, skeletons, store=config.store,
                           banks=banks)
    out.expect_plan = plan.digest()
    return out, 0


def checkpointed_tasks(work: Path, plan: Plan) -> int:
    """How many tasks the staged output's last checkpoint holds (0 when none or another plan's)."""
    note = MotionDatabase.checkpoint_note(work / STAGING) or {}
    tasks = note.get("tasks")
    return tasks if note.get("plan") == plan.digest() and isinstance(tasks, int) and 0 <= tasks <= len(plan.tasks) else 0


def discard_staging(work: Path) -> None:
    for f in (work / STAGING, work / f"{STAGING}.commit"):
        f.unlink(missing_ok=True)


def task_finished(shard_dir: Path, sink, task) -> bool:
    """Whether a task's results wait on disk: its shard, or its part file."""
    return (shard_dir / sink.shard_name(task.id)).exists() or (shard_dir / sink.part_name(task.id)).exists()


def remove_merged_shards(shard_dir: Path, sink, tasks: list, layout: str) -> None:
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
    out, seen = [], set()
    for t in plan.tasks:
        if t.group not in seen:
            seen.add(t.group)
            sk, spec = group_skeleton(t.group)
            if sk is not None:
                out.append((sk, spec))
    if sources is not None:
        for db, rows in source_rows(plan, sources):
            ks = db.clip_table().skeleton
            for r in rows:
                k = int(ks[r])
                out.append((db.skeletons[k], db.stored_spec(k)))
    return out


def output_banks(plan: Plan, sources: Sources, config: JobConfig) -> list[dict]:
    """The banks of source clips an alignment store holds: each bank the job's groups splice
    from (:meth:`~torchsplice.job.sources.Sources.bank`, built here where not yet), once, with
    its clips' keys, names and rate and the joint tables its clips are assembled with."""
    out, seen = [], set()
    options = config.splice_options()
    for n, g in enumerate(plan.groups):
        backend = config.splice_backend()
        skeleton = sources.motion(g.clips[0]).skeleton
        roles = g.roles(skeleton)
        bank, index = sources.bank(n, g.clips, g.fps, roles, options, backend)
        if id(bank) in seen:
            continue
        seen.add(id(bank))
        arrays = backend.assembly_bank(bank)
        if arrays is None:
            raise TorchspliceError(f"{config.output}: the {backend.name} splicer gives no alignments to store; "
                                   "write {store} motion", options=("store",))
        st = sources.standing_tables(n, roles, skeleton, g.fps)
        keys = sorted(index, key=index.get)
        names = [plan.clips[k].name + (" (retargeted)" if retargeted_parts(k) else "") if k in plan.clips else k
                 for k in keys]
        tables = {"upper": arrays["upper"], "pelvis": arrays["pelvis"],
                  "standing_upper": [int(j) for j in np.flatnonzero(st.upper)], "spine": [int(j) for j in st.spine],
                  "arms": [[int(j) for j in np.flatnonzero(st.arms[a])] for a in range(len(LIMBS))],
                  "blend": int(st.blend), "moved": _moved_joints(skeleton, roles)}
        out.append({"rotations": arrays["rotations"], "translations": arrays["translations"],
                    "lengths": arrays["lengths"], "names": names, "keys": keys, "fps": g.fps, "tables": tables})
    return out


def _moved_joints(skeleton, roles) -> list[int]:
    """The joints whose rotations keeping hands out of the body replaces (``assembly_arms``)."""
    return [int(j) for j in arms_of(skeleton, roles, body_of(skeleton, roles)).moved]


def source_skeleton(plan: Plan, g: int, sources: Sources):
    """A locomotion group's skeleton and spec, from its first clip."""
    group = plan.groups[g]
    return sources.motion(group.clips[0]).skeleton, DatasetSpec.from_json(group.spec)


def _shard_skeleton(plan: Plan, g: int, sink, shard_dir: Path):
    """A locomotion group's skeleton and spec, from the first of its shards that holds clips."""
    for t in plan.tasks:
        path = shard_dir / sink.shard_name(t.id)
        if t.group == g and path.exists():
            with MotionDatabase.open(path) as shard:
                if len(shard):
                    return shard.skeletons[0], DatasetSpec.from_json(plan.groups[g].spec)
    return None, None


def summarise_output(summary: JobSummary, out, merge: OutputMerge) -> None:
    summary.merged_shards = merge.appended
    c = merge.config
    folder = run_shards(c, merge.plan)
    summary.written = c.output.stat().st_size + (sum(f.stat().st_size for f in folder.iterdir())
                                                 if c.layout == "virtual" and folder.is_dir() else 0)
    summary.spliced, summary.flagged, summary.flagged_clips, summary.copied, summary.timings = (
        out.clips, out.flagged, out.flagged_clips, out.copied, out.timings)
    for why, n in out.skipped.items():
        summary.skipped[why] = summary.skipped.get(why, 0) + n


def source_rows(plan: Plan, sources: Sources) -> list:
    """``(database, rows)`` of the source clips a ``copy_sources`` output holds: locomotions
    first, then actions and references (one database when both are one file)."""
    pairs = plan.pairs
    needs = np.array([get_method(m).needs_reference for m in pairs.methods], dtype=bool)[pairs.column("method")]
    refs = pairs.column("reference")[needs & (pairs.column("reference") >= 0)]
    return [(sources.db("L"), np.unique(pairs.column("loco")).tolist()),
            (sources.db("A"), np.unique(np.concatenate([pairs.column("action"), refs])).tolist())]
