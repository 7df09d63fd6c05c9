"""Where task results go, and how they become the output: the job's ``Sink`` seam.

A sink writes each task's :class:`~torchsplice.job.task.Part` as a *shard* (one file per task,
named by the task's id, written under a temporary name and renamed into place) and joins the
shards, in plan order, into the output as they finish. The output is written at a staging
path in the job's work folder and checkpointed after each shard, so that a killed job resumes
into it (:meth:`Sink.resume_output`) and merges only the shards it does not hold yet; a
shard whose clips a checkpoint holds is deleted. The plan, the engines and the merge only
call the methods of :class:`Sink`, so another output format plugs in here without touching
them.

:class:`HDF5Sink` writes torchsplice motion databases (resumable ones, see
:meth:`~torchsplice.store.database.MotionDatabase.checkpoint`). Shards are written without
compression (they live until the merge reads them, seconds later) unless the output is
*virtual*: then they are compressed like the output and stay beside it in ``OUT.shards/``,
and the output's frame datasets are HDF5 virtual datasets over them, so nothing is copied.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..core.errors import DatabaseError
from ..store.assembly import KIND_CODES
from ..store.database import MotionDatabase
from ..specs import DatasetSpec
from .task import FRAME_COLUMNS, OUTPUT_COLUMNS, Part

__all__ = ["Sink", "HDF5Sink", "AlignmentSink", "OutputWriter", "make_sink"]


class Sink:
    """The interface a sink implements (see the module docstring)."""

    def shard_name(self, task_id: str) -> str:
        raise NotImplementedError

    def part_name(self, task_id: str) -> str:
        """The file of a task's part on its way to the merge (:meth:`~torchsplice.job.task.Part.save`)."""
        return f"part-{task_id}.part"

    def write_shard(self, part: Part, path: Path, compression) -> None:
        raise NotImplementedError

    def shard_skipped(self, path: Path) -> dict:
        raise NotImplementedError

    def load_shard(self, path: Path, skeleton) -> Part | None:
        """A shard as a :class:`Part` on the group's ``skeleton`` (a callable giving it), for sinks
        whose shards are parts; ``None`` where :meth:`OutputWriter.append_shard` reads the file."""
        return None

    def open_output(self, path: Path, compression, run: dict, overwrite: bool, staging: Path,
                    skeletons=(), store: str = "motion", banks=()) -> "OutputWriter":
        """A new output written at ``staging``, holding ``skeletons`` (``(Skeleton, spec)``) first;
        an alignment store (``store``) holds the ``banks`` of source clips too."""
        raise NotImplementedError

    def resume_output(self, path: Path, staging: Path, overwrite: bool) -> "tuple[OutputWriter, dict] | None":
        """The output staged at ``staging`` at its last checkpoint, and that checkpoint's note;
        ``None`` when there is none to resume."""
        raise NotImplementedError


class OutputWriter:
    """The output being joined; counts what the closing summary reports."""

    def __init__(self, db: MotionDatabase):
        self.db = db
        self.clips = self.flagged_clips = self.copied = 0
        self.flagged: dict[str, int] = {}
        self.skipped: dict[str, int] = {}
        self.timings: dict[str, int] = {}  # clips by timing: "timewarp", or a standing action's "loop", "hold", "fit"
        self.expect_plan: str | None = None  # the plan digest every shard must carry
        self.banks: dict = db.bank_index() if db.store == "alignment" else {}  # (bank, key, fps) -> row
        self.bank_of: dict = {}  # (key, fps) -> the banks holding it
        for b, key, fps in self.banks:
            self.bank_of.setdefault((key, fps), []).append(b)

    def add_banks(self, banks: list[dict]) -> None:
        """Store an alignment store's banks of source clips (:func:`~torchsplice.job.merge.output_banks`)."""
        for bank in banks:
            b = self.db.add_bank(bank["rotations"], bank["translations"], bank["lengths"], bank["names"], bank["keys"],
                                 bank["fps"], bank["tables"])
            for r, k in enumerate(bank["keys"]):
                self.banks[(b, str(k), float(bank["fps"]))] = r
                self.bank_of.setdefault((str(k), float(bank["fps"])), []).append(b)

    def _append_parts(self, part: Part, virtual: tuple | None = None) -> None:
        """A part's clips as their parts (an alignment store): source keys become bank rows.
        ``virtual``: ``(source, refer_as)`` of the shard holding their per-frame parts."""
        p, fps = part.parts, float(part.fps[0])
        keys = {}  # each source clip looked up once: its (bank, row) where one bank holds it, else None
        for k in set(p["locomotion"]) | set(p["action"]):
            held = self.bank_of.get((k, fps), [])
            keys[k] = (held[0], self.banks[(held[0], k, fps)]) if len(held) == 1 else None
        if all(keys[k] is not None for k in keys):
            def rows(names):  # (bank, row) of each clip, by its distinct names
                distinct, which = np.unique(np.asarray(names, dtype=str), return_inverse=True)
                return np.array([keys[str(k)] for k in distinct], np.int64).reshape(-1, 2)[which.reshape(-1)].T

            (lo_b, lo), (ac_b, ac) = rows(p["locomotion"]), rows(p["action"])
            bank = lo_b if np.array_equal(lo_b, ac_b) else None
        else:
            bank = None
        if bank is None:  # a clip in several banks (groups of other specs), or a pair across banks
            found = []
            for lk, ak in zip(p["locomotion"], p["action"]):
                both = [b for b in self.bank_of.get((lk, fps), []) if (b, ak, fps) in self.banks]
                if not both:
                    raise DatabaseError(f"{self.db.path}: no bank of the output holds the source clips {lk} and {ak}")
                found.append((both[0], self.banks[(both[0], lk, fps)], self.banks[(both[0], ak, fps)]))
            bank, lo, ac = np.array(found, np.int64).reshape(-1, 3).T
        parts = {"assembly_kind": [KIND_CODES[k] for k in p["kind"]], "assembly_bank": bank,
                 "assembly_locomotion": lo, "assembly_action": ac,
                 **{f"assembly_{k}": p[k] for k in ("crop", "method", "timing", "window", "loop_start", "loop_end",
                                                     "acting")}}
        self.db.append_parts(part.skeleton, part.lengths, part.names, part.fps, curve=p.get("curve"), pelvis=p.get("pelvis"),
                             arms=part.dense_arms(), parts=parts, spec=DatasetSpec.from_json(part.spec), sources=part.sources, roles="spliced",
                             labels=part.labels, extra=part.extra, frame_extra={"action_frame": part.action_frame},
                             virtual=virtual)

    def counts(self) -> dict:
        """What the closing summary reports so far (kept in each checkpoint)."""
        return {"clips": self.clips, "flagged_clips": self.flagged_clips, "copied": self.copied,
                "flagged": self.flagged, "skipped": self.skipped, "timings": self.timings}

    def checkpoint(self, note: dict) -> None:
        """Make the clips appended so far survive a killed job, with ``note`` and the counts."""
        self.db.checkpoint({**note, "counts": self.counts()})

    def restore(self, note: dict) -> None:
        """The counts of a resumed output (from its checkpoint's ``note``)."""
        c = note.get("counts", {})
        self.clips, self.flagged_clips, self.copied = int(c.get("clips", 0)), int(c.get("flagged_clips", 0)), int(c.get("copied", 0))
        self.flagged, self.skipped, self.timings = dict(c.get("flagged", {})), dict(c.get("skipped", {})), dict(c.get("timings", {}))

    def set_spliced(self, n: int) -> None:
        """Record the clips actually spliced in the run record (pairs can fail to align)."""
        self.db.update_run_record({"pairs_spliced": int(n)})

    def _count(self, flags, skipped: dict, timings=()) -> None:
        for t in timings:
            t = str(t) or "timewarp"
            self.timings[t] = self.timings.get(t, 0) + 1
        for f in flags:
            kinds = {x for x in str(f).split(",") if x}
            for kind in kinds:
                self.flagged[kind] = self.flagged.get(kind, 0) + 1
            self.flagged_clips += bool(kinds)
        for why, n in skipped.items():
            self.skipped[why] = self.skipped.get(why, 0) + int(n)

    def append_shard(self, path: Path, part: Part | None = None, virtual: bool = False, refer_as: Path | None = None) -> None:
        """Append a shard's clips: from ``part`` when it is still in memory, else from the file;
        with ``virtual``, only the shard's table (its frames stay in the shard, which the output
        refers to as ``refer_as``, where it will be once the output is complete)."""
        # a part in memory; for a virtual alignment store, its table rows (its frames stay in the shard)
        if part is not None and (not virtual or self.db.store == "alignment"):
            if self.expect_plan is not None and part.plan and part.plan != self.expect_plan:
                raise DatabaseError(f"{path}: this shard belongs to another plan of the job; rerun with {{restart}}",
                                    options=("restart",))
            self._count(part.extra["flags"], part.skipped, part.extra["timing"])
            if part.names and part.parts is not None:
                self._append_parts(part, virtual=(path, refer_as) if virtual else None)
                self.clips += len(part.names)
            elif part.names and virtual:
                self.db.append_virtual(path, part.skeleton, part.lengths, part.names, part.fps,
                                       spec=DatasetSpec.from_json(part.spec), refer_as=refer_as, sources=part.sources,
                                       roles="spliced", labels=part.labels, extra=part.extra)
                self.clips += len(part.names)
            elif part.names:
                self.db.append_packed(part.skeleton, part.rotations, part.translations[:, 0], part.translations,
                                      part.lengths, part.names, part.fps, spec=DatasetSpec.from_json(part.spec),
                                      sources=part.sources, roles="spliced", labels=part.labels, extra=part.extra,
                                      frame_extra={"action_frame": part.action_frame}, check=False)
                self.clips += len(part.names)
            return
        with MotionDatabase.open(path) as shard:
            made_for = str(shard.attrs.get("plan", ""))
            if self.expect_plan is not None and made_for != self.expect_plan:
                raise DatabaseError(f"{path}: this shard belongs to another plan of the job; rerun with {{restart}}",
                                    options=("restart",))
            skipped = json.loads(str(shard.attrs.get("skipped", "")) or "{}")
            if len(shard) == 0:
                self._count([], skipped)
                return
            spec = shard.stored_spec(0)
            t = shard.table()
            self._count(t["flags"], skipped, t["timing"])
            extra = {col: t[col] for col in OUTPUT_COLUMNS}
            if virtual:
                self.db.append_virtual(path, shard.skeletons[0], t["length"], t["name"], t["fps"], spec=spec, refer_as=refer_as,
                                       sources=t["source"], roles=t["role"], labels=t["labels"], extra=extra)
            else:
                f = shard.packed(0)
                self.db.append_packed(shard.skeletons[0], f["rotations"], f["root_translation"], f.get("translations"),
                                      t["length"], t["name"], t["fps"], spec=spec, sources=t["source"], roles=t["role"],
                                      labels=t["labels"], extra=extra, frame_extra={n: f[n] for n in FRAME_COLUMNS},
                                      check=False)
            self.clips += len(t["name"])

    def copy_sources(self, dbs: list[tuple[MotionDatabase, list[int]]]) -> None:
        """Copy source clips (database, rows) into the output, each name once."""
        for db, rows in dbs:
            for r in rows:
                m = db.read(r)
                if m.name in self.db:
                    continue
                self.db.append(m, spec=db.stored_spec(db.clip_info(r)["skeleton"]))
                self.copied += 1

    def close(self) -> None:
        self.db.close()

    def abort(self) -> None:
        self.db.abort()


class HDF5Sink(Sink):
    """Shards and output as torchsplice motion databases (see the module docstring)."""

    def shard_name(self, task_id: str) -> str:
        return f"part-{task_id}.h5"

    def write_shard(self, part: Part, path: Path, compression) -> None:
        with MotionDatabase.create(path, overwrite=True, columns=OUTPUT_COLUMNS, frame_columns=FRAME_COLUMNS,
                                   compression=compression, chunk_frames=256 if compression else 1024,
                                   attrs={"skipped": json.dumps(part.skipped, sort_keys=True), "task": part.task,
                                          "plan": part.plan}) as db:
            if part.names:
                db.append_packed(part.skeleton, part.rotations, part.translations[:, 0], part.translations, part.lengths,
                                 part.names, part.fps, spec=DatasetSpec.from_json(part.spec), sources=part.sources,
                                 roles="spliced", labels=part.labels, extra=part.extra,
                                 frame_extra={"action_frame": part.action_frame}, check=False)

    def shard_skipped(self, path: Path) -> dict:
        with MotionDatabase.open(path) as db:
            return json.loads(str(db.attrs.get("skipped", "")) or "{}")

    def open_output(self, path: Path, compression, run: dict, overwrite: bool, staging: Path,
                    skeletons=(), store: str = "motion", banks=()) -> OutputWriter:
        # 256-frame chunks: random training windows decompress little (see torchsplice.data)
        db = MotionDatabase.create(path, overwrite=overwrite, columns=OUTPUT_COLUMNS, chunk_frames=256,
                                   compression=compression, frame_columns=FRAME_COLUMNS, attrs={"run": json.dumps(run)},
                                   staging=staging, store=store)
        try:
            for skeleton, spec in skeletons:  # before the first checkpoint: every write is then crash-safe
                db.add_skeleton(skeleton, spec)
            out = OutputWriter(db)
            out.add_banks(list(banks))
        except BaseException:
            db.abort(failed=True)
            raise
        return out

    def resume_output(self, path: Path, staging: Path, overwrite: bool) -> tuple[OutputWriter, dict] | None:
        resumed = MotionDatabase.resume(path, staging, overwrite)
        if resumed is None:
            return None
        out = OutputWriter(resumed[0])
        out.restore(resumed[1])
        return out, resumed[1]


class AlignmentSink(HDF5Sink):
    """The sink of an alignment store: its output is an alignment store (:class:`HDF5Sink`'s
    output with ``store="alignment"``), and its shards (``--shard`` runs) are the tasks' parts
    as :meth:`Part.save` writes them (a task's parts are kilobytes; their source clips are the
    output's banks, which the merge writes once). For a ``virtual`` output a shard is also an
    HDF5 file of the clips' per-frame parts (:meth:`MotionDatabase.append_frame_source`),
    ``part-ID.h5``, written after the part beside it (``part-ID.shard``, which gives the
    output its table rows), that the output's frame datasets read as virtual datasets."""

    def __init__(self, virtual: bool = False):
        self.virtual = virtual

    def shard_name(self, task_id: str) -> str:
        return f"part-{task_id}.h5" if self.virtual else f"part-{task_id}.shard"

    @staticmethod
    def _part_file(path: Path) -> Path:
        return Path(path).with_suffix(".shard")

    def write_shard(self, part: Part, path: Path, compression) -> None:
        if not self.virtual:
            part.save(path)
            return
        part.save(self._part_file(path))  # first: a shard file whole means its part is there

        arrays = {"action_frame": np.asarray(part.action_frame, np.float32)}
        if part.parts is not None:
            for name, key in (("assembly_curve", "curve"), ("assembly_pelvis", "pelvis")):
                if part.parts.get(key) is not None:
                    arrays[name] = part.parts[key]
            if (arms := part.dense_arms()) is not None:
                arrays["assembly_arms"] = arms
        else:
            arrays.update(rotations=part.rotations, root_translation=part.translations[:, 0],
                          translations=part.translations)
        with MotionDatabase.create(path, overwrite=True, columns=OUTPUT_COLUMNS, frame_columns=FRAME_COLUMNS,
                                   compression=compression, chunk_frames=256, store="alignment",
                                   attrs={"task": part.task, "plan": part.plan}) as db:
            db.append_frame_source(part.skeleton, DatasetSpec.from_json(part.spec), arrays)

    def shard_skipped(self, path: Path) -> dict:
        return Part.header(self._part_file(path))["meta"]["skipped"]

    def load_shard(self, path: Path, skeleton) -> Part:
        return Part.load(self._part_file(path), skeleton())


def make_sink(config) -> Sink:
    """The sink of a job of ``config`` (the one place the job, its workers and the merge get it):
    an :class:`AlignmentSink` for ``store="alignment"``, an :class:`HDF5Sink` otherwise."""
    if getattr(config, "store", "motion") == "alignment":
        return AlignmentSink(virtual=getattr(config, "layout", "copy") == "virtual")
    return HDF5Sink()
