"""The main job: splice every selected (locomotion, action) pair into a new motion database.

    torchsplice splice-all DB.h5 -o OUT.h5 [--locomotions SELECT] [--actions SELECT] [--method splice,naive]

How it runs:

1. **Plan.** Select locomotions and actions (see :mod:`torchsplice.job.select`), check that
   their skeletons match, check once per clip that it locomotes, find ``cpmc`` references,
   and list the pairs, each with a reason when it is skipped.
2. **Batches.** Pairs are cut into batches whose size follows a memory budget (the distance
   grids and DP tables grow with the clips' lengths), so peak memory stays bounded whatever
   n x m is. Each batch is spliced as tensor operations (:func:`torchsplice.splice.splice_pairs`)
   and written by a background thread while the next batch computes.
3. **Resumable.** Each finished batch becomes a small database ``part-NNNNNN.h5`` in the work
   folder ``.OUT.h5.parts/``, written atomically, so a kill at any moment loses at most the
   batches in flight. A rerun with the same arguments skips finished batches; with other
   arguments it refuses to mix and says so. Batches are cut the same way every time, so a
   resumed run writes the same bits as an uninterrupted one.
4. **Merge.** The parts are merged in order into ``OUT.h5`` (created beside it and renamed into
   place, so the file exists only once complete), with a run record; the work folder is removed.

The output has the input's schema plus per-clip columns (source names and rows, method and
parameters, alignment cost and quality figures) and a per-frame ``action_frame`` column (the
alignment curve).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import shutil
import sys
import time
from collections import OrderedDict
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

from .. import __version__
from ..core.errors import TorchspliceError
from ..core.motion import Motion
from ..io.database import MotionDatabase
from ..io.spec import DatasetSpec, SkeletonRoles, detect_spec
from ..splice import METHODS, AlignOptions, SpliceOptions, splice_pairs
from ..splice.clips import clips_to_tensors
from ..splice.locomotion import check_locomotion
from ..splice.references import find_reference
from .select import select_clips

__all__ = ["JobConfig", "JobSummary", "SpliceJob", "OUTPUT_COLUMNS"]

log = logging.getLogger("torchsplice.job")

OUTPUT_COLUMNS = {
    "locomotion": "str", "action": "str", "reference": "str", "method": "str", "params": "str", "flags": "str",
    "locomotion_id": "int", "action_id": "int", "crop": "int",
    "cost": "float", "posture_deg": "float", "pelvis_correction_deg": "float", "coverage": "float",
}
FRAME_COLUMNS = ("action_frame",)
DEFAULT_LOCOMOTIONS = ("role:locomotion,role:both",)
DEFAULT_ACTIONS = ("role:action,role:both",)
POOR_ALIGNMENT = 0.15  # flag a pair whose mean landmark distance exceeds this many leg lengths
MIN_SECONDS = SpliceOptions().min_seconds
FLAG_SEPARATOR = " | "


@dataclass(frozen=True)
class JobConfig:
    """Everything that defines a job (and, for resuming, whether two runs are the same job).

    Attributes:
        database: the motion database holding the locomotions (and the actions, by default).
        output: the database to write.
        actions_db: another database holding the actions (it must share the skeleton).
        locomotions, actions: selectors, all of which must select a clip.
        methods: one or several of ``splice``, ``naive``, ``cpmc``.
        memory_budget_mb: bound on the memory of one batch's tensors.
        batch_pairs: pairs per batch; ``None`` derives it from the budget.
        force_locomotion: splice clips that do not locomote instead of skipping their pairs.
        copy_sources: copy the selected source clips into the output too.
        max_run, posture: splicing parameters (see :class:`~torchsplice.splice.SpliceOptions`).
        device: torch device for the tensor work.
    """

    database: Path
    output: Path
    actions_db: Path | None = None
    locomotions: tuple[str, ...] = DEFAULT_LOCOMOTIONS
    actions: tuple[str, ...] = DEFAULT_ACTIONS
    methods: tuple[str, ...] = ("splice",)
    memory_budget_mb: int = 1024
    batch_pairs: int | None = None
    force_locomotion: bool = False
    copy_sources: bool = False
    max_run: int = 3
    posture: bool = True
    device: str | None = None


@dataclass
class Pair:
    """One planned pair: rows in the locomotion and action databases, method, reference row."""

    method: str
    loco: int
    action: int
    reference: int | None = None


@dataclass
class JobSummary:
    """What a run did. ``skipped`` maps a reason to the number of pairs it skipped, ``flagged``
    a kind of flag to the number of clips carrying it (``flagged_clips`` clips in all)."""

    output: Path
    pairs: int = 0
    spliced: int = 0
    resumed: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    flagged: dict[str, int] = field(default_factory=dict)
    flagged_clips: int = 0
    copied: int = 0
    seconds: float = 0.0
    compute_seconds: float = 0.0

    def lines(self) -> list[str]:
        """The closing summary, as printed by the command line."""
        rate = (self.spliced - self.resumed) / self.compute_seconds if self.compute_seconds > 0 else float("nan")
        out = [f"wrote {self.output}: {self.spliced} spliced clips"
               + (f" ({self.resumed} from an earlier run)" if self.resumed else "")
               + (f" + {self.copied} source clips" if self.copied else "")
               + f" in {self.seconds:.1f} s ({rate:,.0f} splices/s)"]
        if self.skipped:
            out.append(f"skipped {sum(self.skipped.values())} pairs:")
            out += [f"  {n} x {why}" for why, n in sorted(self.skipped.items(), key=lambda kv: -kv[1])]
        if self.flagged:
            out.append(f"flagged {self.flagged_clips} clips (see the 'flags' column):")
            out += [f"  {n} x {why}" for why, n in sorted(self.flagged.items(), key=lambda kv: -kv[1])]
        return out


def _fingerprint(path: Path) -> dict:
    st = path.stat()
    return {"path": str(path.resolve()), "size": st.st_size, "mtime_ns": st.st_mtime_ns}


def _leg_length(skeleton, roles: SkeletonRoles) -> float:
    """Hip-to-ankle bone length of the left leg (offset norms), in file units."""
    j, total = roles.feet[0], 0.0
    while j not in (roles.hips[0], -1):
        total += float(skeleton.offsets[j].norm())
        j = skeleton.parents[j]
    return total


class _ClipCache:
    """Clips read from a database, least recently used dropped past a byte budget."""

    def __init__(self, db: MotionDatabase, budget: int):
        self.db, self.budget, self.used = db, budget, 0
        self.items: OrderedDict[int, Motion] = OrderedDict()

    def get(self, row: int) -> Motion:
        if row in self.items:
            self.items.move_to_end(row)
            return self.items[row]
        m = self.db.read(row)
        size = m.rotations.numel() * 4 * (2 if m.translations is not None else 1)
        self.items[row] = m
        self.used += size
        while self.used > self.budget and len(self.items) > 1:
            _, old = self.items.popitem(last=False)
            self.used -= old.rotations.numel() * 4 * (2 if old.translations is not None else 1)
        return m


class SpliceJob:
    """Plan and run one splice job (see the module docstring)."""

    def __init__(self, config: JobConfig, progress: bool = True, restart: bool = False, overwrite: bool = False,
                 command: str | None = None):
        self.config, self.progress, self.restart, self.overwrite = config, progress, restart, overwrite
        self.command = command or "torchsplice.job.SpliceJob (Python API)"
        self._checks: dict = {}
        bad = [m for m in config.methods if m not in METHODS]
        if bad or not config.methods:
            raise TorchspliceError(f"unknown method {bad[0] if bad else '(none)'!r}; choose from {', '.join(METHODS)}")
        self.work = config.output.with_name(f".{config.output.name}.parts")

    # -- planning -----------------------------------------------------------------------------
    def plan(self, loco_db: MotionDatabase, act_db: MotionDatabase) -> tuple[list[Pair], dict[str, int], dict]:
        """The pairs to splice, the skip reasons with counts, and per-skeleton context."""
        c = self.config
        tl = loco_db.table()
        ta = tl if act_db is loco_db else act_db.table()
        locos = select_clips(tl, c.locomotions, "--locomotions", str(c.database))
        acts = select_clips(ta, c.actions, "--actions", str(c.actions_db or c.database))
        sk_l, sk_a = loco_db.skeletons, act_db.skeletons
        if not any(sk_l[int(tl["skeleton"][i])].same_topology(sk_a[int(ta["skeleton"][j])]) for i in locos for j in acts):
            a, b = sk_l[int(tl["skeleton"][locos[0]])], sk_a[int(ta["skeleton"][acts[0]])]
            raise TorchspliceError(f"the selected locomotions ({c.database}) and actions ({c.actions_db or c.database}) "
                                   f"have no skeleton in common: {a.mismatch(b)}")
        context = self._skeleton_context(loco_db, tl, locos)
        checks = self._checks = self._locomotion_checks(loco_db, act_db, tl, ta, locos, acts, context)
        refs = self._references(act_db, ta, acts, context) if "cpmc" in c.methods else {}
        pairs, skipped = [], {}

        def skip(why: str) -> None:
            skipped[why] = skipped.get(why, 0) + 1

        same_db = act_db is loco_db
        for method in c.methods:
            for i in locos:
                for j in acts:
                    why = self._skip_reason(method, i, j, same_db, tl, ta, sk_l, sk_a, checks, refs)
                    if why:
                        skip(why)
                    else:
                        pairs.append(Pair(method, i, j, refs.get(j)))
        if not pairs:
            reasons = "; ".join(f"{n} x {w}" for w, n in skipped.items())
            raise TorchspliceError(f"no pair to splice: every selected pair was skipped ({reasons})")
        return pairs, skipped, context

    def _skip_reason(self, method, i, j, same_db, tl, ta, sk_l, sk_a, checks, refs) -> str | None:
        if same_db and i == j:
            return "a clip is not spliced onto itself"
        if not sk_l[int(tl["skeleton"][i])].same_topology(sk_a[int(ta["skeleton"][j])]):
            return "skeletons differ"
        for table, row in ((tl, i), (ta, j)):
            need = max(4, int(MIN_SECONDS * float(table["fps"][row])))
            if int(table["length"][row]) < need:
                return f"{table['name'][row]} is too short to splice ({int(table['length'][row])} frames, at least {need})"
        if not self.config.force_locomotion:
            for key, name in ((("L", i), str(tl["name"][i])), (("A", j), str(ta["name"][j]))):
                check = checks.get(key)
                if check is not None and not check.locomoting:
                    return f"{name} does not locomote ({check.reason}; --force-locomotion splices it)"
        if method == "cpmc" and refs.get(j) is None:
            return f"no plain-locomotion reference for {ta['name'][j]} (cpmc)"
        return None

    def _skeleton_context(self, db: MotionDatabase, table, rows) -> dict:
        """Per locomotion skeleton id: spec, roles, leg length."""
        out = {}
        for k in sorted({int(table["skeleton"][i]) for i in rows}):
            sk = db.skeletons[k]
            text = db.spec_json(k)
            spec = DatasetSpec.from_json(text) if text else detect_spec(sk)
            roles = spec.bind(sk)
            out[k] = {"spec": spec, "roles": roles, "leg": _leg_length(sk, roles)}
        return out

    def _locomotion_checks(self, loco_db, act_db, tl, ta, locos, acts, context) -> dict:
        """``("L" | "A", row) -> LocomotionCheck`` for every selected clip, batched by skeleton and rate."""
        spec = next(iter(context.values()))["spec"]
        out: dict = {}
        for tag, db, table, rows in (("L", loco_db, tl, locos), ("A", act_db, ta, acts)):
            groups: dict = {}
            for r in rows:
                groups.setdefault((int(table["skeleton"][r]), float(table["fps"][r])), []).append(r)
            for (k, fps), rs in groups.items():
                sk = db.skeletons[k]
                if not spec.binds(sk):
                    continue  # another skeleton: its pairs are skipped as "skeletons differ"
                roles = spec.bind(sk)
                for b in range(0, len(rs), 64):
                    chunk = rs[b:b + 64]
                    clips = clips_to_tensors([db.read(r) for r in chunk], sk)
                    for r, chk in zip(chunk, check_locomotion(clips, roles, fps)):
                        out[(tag, r)] = chk
        return out

    def _references(self, act_db: MotionDatabase, ta, acts, context) -> dict[int, int | None]:
        """Action row -> reference row (in the action database) for ``cpmc``."""
        names = [str(n) for n in ta["name"]]
        cands = [(names[i], str(ta["role"][i]), json.loads(ta["labels"][i] or "{}")) for i in range(len(names))]
        index = {n: i for i, n in enumerate(names)}
        spec = next(iter(context.values()))["spec"]
        out = {}
        for j in acts:
            ref = find_reference(names[j], json.loads(ta["labels"][j] or "{}"), cands, spec)
            out[j] = index[ref] if ref is not None else None
        return out

    def _batch_size(self, tl, ta, locos, acts) -> int:
        c = self.config
        if c.batch_pairs is not None:
            return max(1, int(c.batch_pairs))
        t_l = int(max(tl["length"][i] for i in locos))
        t_a = max(int(ta["length"][j] * float(tl["fps"][locos[0]]) / float(ta["fps"][j])) + 1 for j in acts)
        per_pair = 40 * t_l * t_a + 2000 * 32 * (t_l + t_a)  # grid, DP tables, clip tensors
        return int(min(256, max(1, c.memory_budget_mb * 2**20 // per_pair)))

    # -- running ------------------------------------------------------------------------------
    def _signature(self, pairs: list[Pair], batch: int) -> dict:
        c = self.config
        body = json.dumps([asdict(p) for p in pairs]).encode()
        return {
            "tool": f"torchsplice {__version__}",
            "database": _fingerprint(c.database),
            "actions_db": _fingerprint(c.actions_db) if c.actions_db else None,
            "locomotions": list(c.locomotions), "actions": list(c.actions), "methods": list(c.methods),
            "force_locomotion": c.force_locomotion, "max_run": c.max_run, "posture": c.posture,
            "batch_pairs": batch, "pairs": len(pairs), "pair_list_sha256": hashlib.sha256(body).hexdigest(),
            "copy_sources": c.copy_sources, "device": c.device or "cpu",
        }

    def _prepare_work(self, signature: dict) -> None:
        sig_path = self.work / "job.json"
        if self.work.exists() and self.restart:
            shutil.rmtree(self.work)
        if self.work.exists():
            try:
                old = json.loads(sig_path.read_text())
            except (OSError, ValueError):
                old = None
            if old != signature:
                raise TorchspliceError(
                    f"{self.work} holds an unfinished job with other arguments or inputs; rerun it with the same "
                    "arguments to finish it, or pass --restart to discard it")
            for stale in self.work.glob(".part-*"):
                stale.unlink(missing_ok=True)  # half-written parts of a killed run
            return
        self.work.mkdir(parents=True)
        tmp = self.work / ".job.json.tmp"
        tmp.write_text(json.dumps(signature, indent=1))
        os.replace(tmp, sig_path)

    def run(self) -> JobSummary:
        """Plan, splice every batch (resuming finished ones), merge; returns the summary."""
        c = self.config
        t0 = time.perf_counter()
        self._started = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        if c.output.exists() and not self.overwrite:
            raise TorchspliceError(f"{c.output}: already exists (use --force to overwrite)")
        _remove_stale_outputs(c.output)
        if c.actions_db is not None and c.actions_db.resolve() == c.database.resolve():
            c = self.config = JobConfig(**{**asdict(c), "actions_db": None})
        with MotionDatabase.open(c.database) as loco_db:
            act_db = MotionDatabase.open(c.actions_db) if c.actions_db else loco_db
            try:
                summary = self._run(loco_db, act_db, t0)
            finally:
                if act_db is not loco_db:
                    act_db.close()
        summary.seconds = time.perf_counter() - t0
        return summary

    def _run(self, loco_db, act_db, t0) -> JobSummary:
        c = self.config
        pairs, skipped, context = self.plan(loco_db, act_db)
        tl, ta = loco_db.table(), (loco_db.table() if act_db is loco_db else act_db.table())
        batch = self._batch_size(tl, ta, sorted({p.loco for p in pairs}), sorted({p.action for p in pairs}))
        batches = self._batches(pairs, tl, batch)
        signature = self._signature(pairs, batch)
        self._prepare_work(signature)
        summary = JobSummary(output=c.output, pairs=len(pairs), skipped=skipped)
        done = {k for k in range(len(batches)) if self._part(k).exists()}
        summary.resumed = sum(len(batches[k]) for k in done)
        log.info("%d pairs in %d batches of up to %d (%d already done)", len(pairs), len(batches), batch, summary.resumed)
        budget = c.memory_budget_mb * 2**20 // 4
        caches = (_ClipCache(loco_db, budget), _ClipCache(act_db, budget) if act_db is not loco_db else None)
        bar = _progress(len(pairs), summary.resumed, self.progress)
        pending: Future | None = None
        compute = 0.0
        with ThreadPoolExecutor(max_workers=1) as writer:
            try:
                for k, chunk in enumerate(batches):
                    if k in done:
                        continue
                    t1 = time.perf_counter()
                    records = self._splice_batch(chunk, caches, tl, ta, context)
                    compute += time.perf_counter() - t1
                    if pending is not None:
                        pending.result()
                    pending = writer.submit(self._write_part, k, records, context)
                    bar.update(len(chunk))
            except BaseException:
                if pending is not None and not pending.done():
                    pending.result()  # keep the batch that was being written
                bar.close()
                raise
            if pending is not None:
                pending.result()
        bar.close()
        summary.compute_seconds = compute
        summary.spliced, summary.flagged, summary.flagged_clips, summary.copied = self._merge(batches, loco_db, act_db, tl, ta, pairs, signature, t0)
        shutil.rmtree(self.work, ignore_errors=True)
        return summary

    def _batches(self, pairs: list[Pair], tl, size: int) -> list[list[Pair]]:
        """Consecutive chunks of at most ``size`` pairs sharing method and locomotion skeleton."""
        out, cur, key = [], [], None
        for p in pairs:
            k = (p.method, int(tl["skeleton"][p.loco]))
            if cur and (k != key or len(cur) >= size):
                out.append(cur)
                cur = []
            cur.append(p)
            key = k
        if cur:
            out.append(cur)
        return out

    def _part(self, k: int) -> Path:
        return self.work / f"part-{k:06d}.h5"

    def _splice_batch(self, chunk: list[Pair], caches, tl, ta, context) -> list[tuple]:
        c = self.config
        lc, ac = caches[0], caches[1] or caches[0]
        ctx = context[int(tl["skeleton"][chunk[0].loco])]
        opts = SpliceOptions(align=AlignOptions(max_run=c.max_run), posture=c.posture,
                             force=True, check_locomotion=False, device=c.device)  # the plan checked the clips
        pairs = [(lc.get(p.loco), ac.get(p.action)) for p in chunk]
        refs = [ac.get(p.reference) for p in chunk] if chunk[0].method == "cpmc" else None
        results = splice_pairs(pairs, ctx["spec"], method=chunk[0].method, references=refs, options=opts)
        params = json.dumps({"max_run": c.max_run, "posture": c.posture, "heading_window_deg": opts.align.heading_window_deg,
                             "force_locomotion": c.force_locomotion})
        leg = ctx["leg"]
        records = []
        for p, r in zip(chunk, results):
            flags = [f"{name} does not locomote ({chk.reason})" for key, name in ((("L", p.loco), r.locomotion), (("A", p.action), r.action))
                     if (chk := self._checks.get(key)) is not None and not chk.locomoting]
            if math.isfinite(r.cost) and math.sqrt(max(r.cost, 0.0)) > POOR_ALIGNMENT * leg:
                flags.append(f"poor alignment (mean landmark distance {math.sqrt(r.cost) / leg:.2f} leg lengths)")
            loco_frames = int(tl["length"][p.loco])
            extra = {
                "locomotion": r.locomotion, "action": r.action, "reference": r.reference or "", "method": r.method,
                "params": params, "flags": FLAG_SEPARATOR.join(flags), "locomotion_id": p.loco, "action_id": p.action,
                "crop": r.crop, "cost": r.cost, "posture_deg": r.posture_deg,
                "pelvis_correction_deg": float(r.pelvis_correction.mean()) if r.pelvis_correction.numel() else 0.0,
                "coverage": r.motion.num_frames / loco_frames,
            }
            records.append((r.motion.to("cpu"), extra, {"action_frame": r.curve}, flags))
        return records

    def _write_part(self, k: int, records, context) -> None:
        spec = next(iter(context.values()))["spec"]
        part = self._part(k)
        with MotionDatabase.create(part, overwrite=True, columns=OUTPUT_COLUMNS, frame_columns=FRAME_COLUMNS,
                                   compression=None) as db:
            for motion, extra, frames, _ in records:
                db.append(motion, spec=spec, extra=extra, frame_extra=frames)

    def _merge(self, batches, loco_db, act_db, tl, ta, pairs, signature, t0) -> tuple[int, dict, int]:
        c = self.config
        run = {**signature, "command": self.command, "started": self._started,
               "pairs_spliced": len(pairs)}
        flagged: dict[str, int] = {}
        n = copied = flagged_clips = 0
        # 256-frame chunks: random training windows decompress little (see torchsplice.data)
        with MotionDatabase.create(c.output, overwrite=self.overwrite, columns=OUTPUT_COLUMNS, chunk_frames=256,
                                   frame_columns=FRAME_COLUMNS, attrs={"run": json.dumps(run)}) as out:
            for k in range(len(batches)):
                with MotionDatabase.open(self._part(k)) as part:
                    spec = DatasetSpec.from_json(part.spec_json(0)) if part.spec_json(0) else None
                    for motion, extra, frames in part.read_all():
                        kinds = {_flag_kind(f) for f in (extra["flags"] or "").split(FLAG_SEPARATOR) if f}
                        for f in kinds:
                            flagged[f] = flagged.get(f, 0) + 1
                        flagged_clips += bool(kinds)
                        out.append(motion, spec=spec, extra=extra, frame_extra=frames)
                        n += 1
            if c.copy_sources:
                copied = self._copy_sources(out, loco_db, act_db, pairs)
        return n, flagged, flagged_clips, copied

    def _copy_sources(self, out: MotionDatabase, loco_db, act_db, pairs) -> int:
        count = 0
        for db, rows in ((loco_db, sorted({p.loco for p in pairs})), (act_db, sorted({p.action for p in pairs} | {p.reference for p in pairs if p.reference is not None}))):
            for r in rows:
                m = db.read(r)
                if m.name in out._index_map():
                    continue
                spec_text = db.spec_json(db.clip_info(r)["skeleton"])
                out.append(m, spec=DatasetSpec.from_json(spec_text) if spec_text else None)
                count += 1
        return count


def _flag_kind(flag: str) -> str:
    """The kind of a flag, without the clip-specific details in parentheses."""
    return flag.split(" (")[0].split(": ")[0] if " does not locomote" not in flag else "clip does not locomote"


def _remove_stale_outputs(output: Path) -> None:
    """Delete ``.OUT.h5.partial-PID`` files of merges whose process is gone (killed mid-merge)."""
    for f in output.parent.glob(f".{output.name}.partial-*"):
        try:
            os.kill(int(f.name.rsplit("-", 1)[1]), 0)
        except ProcessLookupError:
            f.unlink(missing_ok=True)
        except (ValueError, PermissionError, OSError):
            pass


def _progress(total: int, initial: int, show: bool):
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="splice", desc="splice-all", disable=True if not show else None,
                file=sys.stderr, dynamic_ncols=True, smoothing=0.1)
