"""The main job: splice every selected (locomotion, action) pair into a new motion database.

    torchsplice splice-all DB.h5 -o OUT.h5 [--locomotions SELECT] [--actions SELECT] [--method splice,naive]

How it runs:

1. **Plan.** Select locomotions and actions (see :mod:`torchsplice.job.select`), check that
   their skeletons match, check once per clip that it locomotes, find ``cpmc`` references,
   and list the pairs, each with a reason when it is skipped.
2. **Sources.** Every selected clip is read once and prepared once per locomotion skeleton
   and frame rate (resampled, forward kinematics, grid features: a
   :class:`~torchsplice.cpu.bank.ClipBank`), so no per-pair work repeats per clip. The
   locomotion checks run on the same kinematics.
3. **Batches.** Pairs are cut into batches whose size follows a memory budget, so peak memory
   stays bounded whatever n x m is. On the CPU each batch runs through the compiled splicer
   (:func:`torchsplice.cpu.bank.splice_bank`: one pair per thread, in parallel over pairs); on
   CUDA through :func:`torchsplice.splice.splice_pairs`. A batch's results stay packed in
   whole arrays, its output columns are computed at once, and a background thread writes it
   while the next batch computes. On the CPU each pair's result depends on that pair alone, so
   the output does not depend on the batch size, the thread count or the load. Memory grows
   with the selected clips (n + m, prepared once) and the batch, not with n x m.
4. **Resumable.** Each finished batch becomes a small database ``part-NNNNNN.h5`` in the work
   folder ``.OUT.h5.parts/``, written atomically, so a kill at any moment loses at most the
   batches in flight. A rerun with the same arguments skips finished batches; with other
   arguments it refuses to mix and says so. Batches are cut the same way every time, so a
   resumed run writes the same bits as an uninterrupted one.
5. **Output.** The writer appends each batch, whole arrays at a time, to ``OUT.h5`` in batch
   order (parts an earlier run finished are appended from their files). The output is written
   beside its path and renamed into place, so it exists only once complete, with a run record;
   the work folder is then removed. A pair that cannot be aligned is skipped, with its reason
   in the summary, and the others still land.

The output has the input's schema plus per-clip columns (source names and rows, method and
parameters, alignment cost and quality figures) and a per-frame ``action_frame`` column (the
alignment curve).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import sys
import time
from contextlib import contextmanager
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from .. import __version__
from ..core.errors import TorchspliceError
from ..core.motion import Motion
from ..io.database import COMPRESSIONS, MotionDatabase
from ..io.spec import DatasetSpec, SkeletonRoles, detect_spec
from ..splice import METHODS, AlignOptions, SpliceOptions, splice_pairs
from ..splice.api import align_kwargs, resolve_backend
from ..splice.clips import ClipTensors, clips_to_tensors, resample_motion
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
        device: torch device for the tensor work (``None``/``"cpu"``: the compiled CPU splicer).
        threads: threads of the compiled splicer (``None``: every core); results do not depend on it.
        compression: the output's compression (see :meth:`MotionDatabase.create`): ``"auto"``
            (LZF on everything but rotations: fast, read by h5py), ``"lzf"``, ``"gzip"`` (read by
            every HDF5 tool, several times slower to write) or ``None``.
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
    threads: int | None = None
    compression: str | None = "auto"



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


@dataclass
class _Part:
    """One batch's results, packed along frames (see :meth:`MotionDatabase.append_packed`)."""

    skeleton: object
    names: list
    lengths: np.ndarray
    fps: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    labels: list
    extra: dict
    action_frame: np.ndarray
    flags: list
    skipped: dict = field(default_factory=dict)  # pairs that could not be aligned, by reason


class _Output:
    """The output database being written, with what the closing summary counts."""

    def __init__(self, db: MotionDatabase):
        self.db = db
        self.clips = self.flagged_clips = self.copied = 0
        self.flagged: dict[str, int] = {}
        self.skipped: dict[str, int] = {}

    def add_skipped(self, skipped: dict) -> None:
        for why, n in skipped.items():
            self.skipped[why] = self.skipped.get(why, 0) + int(n)

    def append(self, skeleton, spec, rotations, root, translations, lengths, names, fps, sources, roles, labels,
               extra, action_frame) -> None:
        for f in extra["flags"]:
            kinds = {_flag_kind(x) for x in str(f).split(FLAG_SEPARATOR) if x}
            for kind in kinds:
                self.flagged[kind] = self.flagged.get(kind, 0) + 1
            self.flagged_clips += bool(kinds)
        self.db.append_packed(skeleton, rotations, root, translations, lengths, names, fps, spec=spec, sources=sources,
                              roles=roles, labels=labels, extra=extra, frame_extra={"action_frame": action_frame},
                              check=False)
        self.clips += len(names)


class _Sources:
    """The selected clips, each read once, and one :class:`ClipBank` per locomotion group.

    Clips are keyed ``("L", row)`` in the locomotion database and ``("A", row)`` in the action
    database (``"L"`` for both when they are one file). A group is a locomotion skeleton and
    frame rate; its bank holds the group's locomotions and every action or reference of the
    same topology, resampled to the group's rate, with kinematics computed once per clip.
    """

    def __init__(self, loco_db: MotionDatabase, act_db: MotionDatabase):
        self.dbs = {"L": loco_db, "A": act_db}
        self.same = act_db is loco_db
        self.motions: dict[tuple[str, int], Motion] = {}
        self.banks: dict[tuple[int, float], tuple] = {}

    def key(self, tag: str, row: int) -> tuple[str, int]:
        return ("L" if self.same else tag, int(row))

    def motion(self, key: tuple[str, int]) -> Motion:
        if key not in self.motions:
            self.load([key])
        return self.motions[key]

    def skeleton_of(self, key: tuple[str, int]):
        return self.motion(key).skeleton

    def load(self, keys) -> None:
        """Read the clips not read yet, a database at a time."""
        for tag in ("L", "A"):
            rows = sorted({k[1] for k in keys if k[0] == tag and k not in self.motions})
            for row, m in zip(rows, self.dbs[tag].read_many(rows)):
                self.motions[(tag, row)] = m

    def bank(self, group: tuple[int, float], keys: list, roles: SkeletonRoles, landmarks) -> tuple:
        """``(bank, index)`` of a group (built on first use): ``index`` maps a clip key to its bank row."""
        if group not in self.banks:
            self.load(keys)
            motions = [self.motion(k) for k in keys]
            fps = group[1]
            skeleton = motions[0].skeleton
            from ..cpu.bank import ClipBank

            bank = ClipBank.from_motions([resample_motion(m, fps) for m in motions], skeleton, roles, landmarks)
            self.banks[group] = (bank, {k: i for i, k in enumerate(keys)})
        return self.banks[group]


class SpliceJob:
    """Plan and run one splice job (see the module docstring)."""

    def __init__(self, config: JobConfig, progress: bool = True, restart: bool = False, overwrite: bool = False,
                 command: str | None = None):
        self.config, self.progress, self.restart, self.overwrite = config, progress, restart, overwrite
        self.command = command or "torchsplice.job.SpliceJob (Python API)"
        self._checks: dict = {}
        if config.compression == "none":
            config = self.config = replace(config, compression=None)
        if config.compression not in COMPRESSIONS:
            raise TorchspliceError(f"unknown compression {config.compression!r}; choose auto, lzf, gzip or none")
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
        if act_db is not loco_db:
            for key in ("units", "up_axis"):
                a, b = str(loco_db.attrs.get(key) or ""), str(act_db.attrs.get(key) or "")
                if a and b and a != b:
                    raise TorchspliceError(f"{c.actions_db}: {key} {b!r} differs from {c.database}'s {a!r}; "
                                           "splice clips of one unit and up axis")
        context = self._skeleton_context(loco_db, tl, locos)
        refs = self._references(act_db, ta, acts, context) if "cpmc" in c.methods else {}
        self._sources = _Sources(loco_db, act_db)
        self._groups = self._group_clips(tl, ta, locos, acts, refs, sk_l, sk_a)
        checks = self._checks = self._locomotion_checks(tl, ta, context)
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

    def _group_clips(self, tl, ta, locos, acts, refs, sk_l, sk_a) -> dict:
        """Locomotion groups ``(skeleton id, fps) -> clip keys``: the group's locomotions, then every
        selected action and reference of the same topology."""
        src = self._sources
        others = sorted({int(j) for j in acts} | {int(r) for r in refs.values() if r is not None})
        groups: dict = {}
        for i in locos:
            groups.setdefault((int(tl["skeleton"][i]), float(tl["fps"][i])), []).append(src.key("L", i))
        for (k, _), keys in groups.items():
            for j in others:
                key = src.key("A", j)
                if key not in keys and sk_l[k].same_topology(sk_a[int(ta["skeleton"][j])]):
                    keys.append(key)
        return groups

    def _locomotion_checks(self, tl, ta, context) -> dict:
        """``("L" | "A", row) -> LocomotionCheck`` for every clip of every group, at the clip's own
        frame rate (from the group's bank where the rates agree, else by torch FK)."""
        src = self._sources
        out: dict = {}
        tables = {"L": tl, "A": ta}
        for (k, fps), keys in self._groups.items():
            roles = context[k]["roles"]
            native = [key for key in keys if float(tables[key[0]]["fps"][key[1]]) == fps]
            if _compiled(self.config):
                bank, index = src.bank((k, fps), keys, roles, AlignOptions().landmarks)
                for b in range(0, len(native), 256):
                    chunk = native[b:b + 256]
                    pos, lengths = bank.padded_positions([index[key] for key in chunk])
                    for key, chk in zip(chunk, check_locomotion(ClipTensors(None, None, lengths, pos, None), roles, fps)):
                        out[key] = chk
            rest = [key for key in keys if key not in out]
            by_rate: dict = {}
            for key in rest:
                by_rate.setdefault(float(tables[key[0]]["fps"][key[1]]), []).append(key)
            for rate, ks in by_rate.items():
                for b in range(0, len(ks), 64):
                    chunk = ks[b:b + 64]
                    motions = [src.motion(key) for key in chunk]
                    clips = clips_to_tensors(motions, motions[0].skeleton)
                    for key, chk in zip(chunk, check_locomotion(clips, roles, rate)):
                        out[key] = chk
        return out

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
            for key, name in ((self._sources.key("L", i), str(tl["name"][i])), (self._sources.key("A", j), str(ta["name"][j]))):
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

    def _references(self, act_db: MotionDatabase, ta, acts, context) -> dict[int, int | None]:
        """Action row -> reference row (in the action database) for ``cpmc``."""
        names = [str(n) for n in ta["name"]]
        cands = [(names[i], str(ta["role"][i]), json.loads(ta["labels"][i] or "{}")) for i in range(len(names))]
        index = {n: i for i, n in enumerate(names)}
        spec = next(iter(context.values()))["spec"]  # actions are named by the locomotions' dataset rules
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
        J = max(sk.num_joints for sk in self._sources.dbs["L"].skeletons)
        if _compiled(c):
            # each thread holds one pair's grid (float64) and back-pointers: 11 bytes a cell
            from ..cpu import get_threads

            threads = c.threads or get_threads()
            scratch = threads * 11 * t_l * t_a
            left = c.memory_budget_mb * 2**20 - scratch
            if left <= 0:
                log.warning("the longest pair's alignment tables (%d x %d frames) take %.0f MB on %d threads, over "
                            "--memory-budget %d MB", t_l, t_a, scratch / 2**20, threads, c.memory_budget_mb)
            per_pair = 2 * t_l * (J * 28 + 16) + 16 * (t_l + t_a)  # its result twice (double buffers), its path
            return int(min(256, max(1, left // per_pair)))
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
            "copy_sources": c.copy_sources, "device": c.device or "cpu", "compression": c.compression,
            "backend": "compiled" if _compiled(c) else "torch",
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
        with MotionDatabase.open(c.database) as loco_db, _compute_threads(c):
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
        bar = _progress(len(pairs), summary.resumed, self.progress)
        out = self._open_output(signature, len(pairs))
        pending: Future | None = None
        compute = 0.0
        # One writer thread, fed in batch order: it writes each new part (for resuming) and
        # appends every part, new or resumed, to the output, while the next batch computes.
        with ThreadPoolExecutor(max_workers=1) as writer:
            try:
                for k, chunk in enumerate(batches):
                    if k in done:
                        part = None
                    else:
                        t1 = time.perf_counter()
                        part = self._splice_batch(chunk, tl, ta, context)
                        compute += time.perf_counter() - t1
                    if pending is not None:
                        pending.result()
                    pending = writer.submit(self._write_and_append, k, part, context, out)
                    if part is not None:
                        bar.update(len(chunk))
                if pending is not None:
                    pending.result()
                if c.copy_sources:
                    out.copied = self._copy_sources(out.db, loco_db, act_db, pairs)
                out.db.close()
            except BaseException:
                while pending is not None and not pending.done():
                    try:
                        pending.result()  # keep the batch that was being written (a second Ctrl-C waits on)
                    except KeyboardInterrupt:
                        continue
                    except BaseException:
                        break
                out.db.abort()
                bar.close()
                raise
        bar.close()
        summary.compute_seconds = compute
        summary.spliced, summary.flagged, summary.flagged_clips, summary.copied = out.clips, out.flagged, out.flagged_clips, out.copied
        for why, n in out.skipped.items():
            summary.skipped[why] = summary.skipped.get(why, 0) + n
        shutil.rmtree(self.work, ignore_errors=True)
        return summary

    def _batches(self, pairs: list[Pair], tl, size: int) -> list[list[Pair]]:
        """Consecutive chunks of at most ``size`` pairs sharing method, locomotion skeleton and frame rate."""
        out, cur, key = [], [], None
        for p in pairs:
            k = (p.method, int(tl["skeleton"][p.loco]), float(tl["fps"][p.loco]))
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

    def _splice_batch(self, chunk: list[Pair], tl, ta, context) -> _Part:
        """Splice one batch (one method, locomotion skeleton and rate); its results packed."""
        c = self.config
        src = self._sources
        method, k, fps = chunk[0].method, int(tl["skeleton"][chunk[0].loco]), float(tl["fps"][chunk[0].loco])
        ctx = context[k]
        align = AlignOptions(max_run=c.max_run)
        lkeys = [src.key("L", p.loco) for p in chunk]
        akeys = [src.key("A", p.action) for p in chunk]
        rkeys = [src.key("A", p.reference) for p in chunk] if method == "cpmc" else None
        if _compiled(c):
            from ..cpu.bank import Buffers, splice_bank

            bank, index = src.bank((k, fps), self._groups[(k, fps)], ctx["roles"], align.landmarks)
            # two sets of output buffers, alternating: the writer reads one while the next batch fills the other
            self._buffers = getattr(self, "_buffers", None) or (Buffers(), Buffers())
            self._parity = 1 - getattr(self, "_parity", 1)
            out = splice_bank(bank, [index[x] for x in lkeys], [index[x] for x in akeys], method,
                              ref=[index[x] for x in rkeys] if rkeys else None, posture=c.posture,
                              buffers=self._buffers[self._parity], on_error="keep", **align_kwargs(align, fps))
            from ..cpu.splice import STATUS

            failed = {b: STATUS[int(st)] for b, st in enumerate(out.status) if st != 0}
            ok = out.status == 0
            frames, rot, trans = out.frames[ok], out.rotations, out.translations
            curve, corr, crop, cost, posture = out.curve, out.correction, out.crop[ok].astype(np.float64), out.cost[ok], out.posture[ok]
        else:
            opts = SpliceOptions(align=align, posture=c.posture, force=True, check_locomotion=False, device=c.device)
            pairs = [(src.motion(a), src.motion(b)) for a, b in zip(lkeys, akeys)]
            refs = [src.motion(r) for r in rkeys] if rkeys else None
            failed = {}
            try:
                results = splice_pairs(pairs, ctx["spec"], method=method, references=refs, options=opts)
            except (ValueError, TorchspliceError):  # one pair cannot be aligned: the others still are
                results = []
                for b in range(len(pairs)):
                    try:
                        results += splice_pairs(pairs[b:b + 1], ctx["spec"], method=method,
                                                references=refs[b:b + 1] if refs else None, options=opts)
                    except (ValueError, TorchspliceError) as exc:
                        failed[b] = str(exc)
            akeys = [a for b, a in enumerate(akeys) if b not in failed]
            scale_back = np.array([fps / src.motion(a).fps for a in akeys])
            frames = np.array([r.motion.num_frames for r in results], dtype=np.int64)
            rot = torch.cat([r.motion.rotations for r in results]).float().cpu().numpy()
            trans = torch.cat([r.motion.local_translations() for r in results]).float().cpu().numpy()
            curve = np.concatenate([r.curve.numpy() for r in results]) * np.repeat(scale_back, frames)
            corr = np.radians(np.concatenate([r.pelvis_correction.numpy() for r in results]))
            crop = np.array([r.crop for r in results], dtype=np.float64) * scale_back
            cost = np.array([r.cost for r in results])
            posture = np.radians([r.posture_deg for r in results])
        skipped: dict[str, int] = {}
        for b in failed:
            why = f"the alignment failed ({failed[b]})"
            skipped[why] = skipped.get(why, 0) + 1
            log.warning("%s + %s: %s", tl["name"][chunk[b].loco], ta["name"][chunk[b].action], why)
        chunk = [p for b, p in enumerate(chunk) if b not in failed]
        part = self._pack(chunk, method, fps, frames, rot, trans, curve, corr, crop, cost, posture, tl, ta, ctx, align)
        part.skipped = skipped
        return part

    def _pack(self, chunk, method, fps, frames, rot, trans, curve, corr, crop, cost, posture, tl, ta, ctx, align) -> _Part:
        """A batch's output columns, computed at once (``curve``, ``crop`` at the locomotion's rate)."""
        c = self.config
        src = self._sources
        lnames = [str(tl["name"][p.loco]) for p in chunk]
        anames = [str(ta["name"][p.action]) for p in chunk]
        scale = np.array([float(ta["fps"][p.action]) / fps for p in chunk])  # to the action's own frames
        starts = np.concatenate(([0], np.cumsum(frames)[:-1])).astype(np.int64)
        corr_deg = np.degrees(corr)
        mean_corr = np.add.reduceat(corr_deg, starts) / frames if len(corr_deg) else np.zeros(len(chunk))
        loco_frames = np.array([int(tl["length"][p.loco]) for p in chunk])
        params = json.dumps({"max_run": c.max_run, "posture": c.posture, "heading_window_deg": align.heading_window_deg,
                             "force_locomotion": c.force_locomotion})
        leg = ctx["leg"]
        dist = np.sqrt(np.maximum(cost, 0.0)) / leg
        poor = np.isfinite(cost) & (dist > POOR_ALIGNMENT)
        flags = []
        for b, p in enumerate(chunk):
            f = [f"{name} does not locomote ({chk.reason})"
                 for key, name in ((src.key("L", p.loco), lnames[b]), (src.key("A", p.action), anames[b]))
                 if (chk := self._checks.get(key)) is not None and not chk.locomoting]
            if poor[b]:
                f.append(f"poor alignment (mean landmark distance {dist[b]:.2f} leg lengths)")
            flags.append(f)
        suffix = "" if method == "splice" else f".{method}"
        names = [f"{lo}+{ac}{suffix}" for lo, ac in zip(lnames, anames)]
        labels = [json.dumps({"method": method, "locomotion": lo, "action": ac}, sort_keys=True) for lo, ac in zip(lnames, anames)]
        refs = [str(ta["name"][p.reference]) if method == "cpmc" else "" for p in chunk]
        extra = {
            "locomotion": lnames, "action": anames, "reference": refs, "method": [method] * len(chunk),
            "params": [params] * len(chunk), "flags": [FLAG_SEPARATOR.join(f) for f in flags],
            "locomotion_id": [p.loco for p in chunk], "action_id": [p.action for p in chunk],
            "crop": np.round(crop * scale).astype(np.int64), "cost": cost, "posture_deg": np.degrees(posture),
            "pelvis_correction_deg": mean_corr, "coverage": frames / loco_frames,
        }
        skeleton = self._sources.skeleton_of(self._sources.key("L", chunk[0].loco)) if chunk else None
        return _Part(skeleton, names, frames, np.full(len(chunk), fps), rot, trans, labels, extra,
                     (curve * np.repeat(scale, frames)).astype(np.float32), flags)

    def _write_part(self, k: int, part: _Part, context) -> None:
        spec = self._spec_of(part.skeleton, context)
        with MotionDatabase.create(self._part(k), overwrite=True, columns=OUTPUT_COLUMNS, frame_columns=FRAME_COLUMNS,
                                   compression=None, attrs={"skipped": json.dumps(part.skipped)}) as db:
            if not part.names:
                return
            db.append_packed(part.skeleton, part.rotations, part.translations[:, 0], part.translations, part.lengths,
                             part.names, part.fps, spec=spec, sources=[f"splice:{m}" for m in part.extra["method"]],
                             roles="spliced", labels=part.labels, extra=part.extra,
                             frame_extra={"action_frame": part.action_frame})

    def _spec_of(self, skeleton, context):
        for ctx in context.values():
            if ctx["spec"].binds(skeleton):
                return ctx["spec"]
        return None

    def _open_output(self, signature: dict, pairs: int) -> "_Output":
        """The output database, written beside its path and renamed into place when complete."""
        c = self.config
        run = {**signature, "command": self.command, "started": self._started, "pairs_spliced": pairs}
        # 256-frame chunks: random training windows decompress little (see torchsplice.data)
        db = MotionDatabase.create(c.output, overwrite=self.overwrite, columns=OUTPUT_COLUMNS, chunk_frames=256,
                                   compression=c.compression, frame_columns=FRAME_COLUMNS, attrs={"run": json.dumps(run)})
        return _Output(db)

    def _write_and_append(self, k: int, part: "_Part | None", context, out: "_Output") -> None:
        """Write batch ``k``'s part (a new batch), then append it to the output (from memory, or
        from its part file when an earlier run wrote it)."""
        if part is not None:
            self._write_part(k, part, context)
            out.add_skipped(part.skipped)
            if not part.names:
                return
            out.append(part.skeleton, self._spec_of(part.skeleton, context), part.rotations, part.translations[:, 0],
                       part.translations, part.lengths, part.names, part.fps, [f"splice:{m}" for m in part.extra["method"]],
                       "spliced", part.labels, part.extra, part.action_frame)
            return
        with MotionDatabase.open(self._part(k)) as db:
            out.add_skipped(json.loads(str(db.attrs.get("skipped", "")) or "{}"))
            if len(db) == 0:
                return
            spec = DatasetSpec.from_json(db.spec_json(0)) if db.spec_json(0) else None
            t, frames = db.table(), db.packed(0)
            out.append(db.skeletons[0], spec, frames["rotations"], frames["root_translation"], frames.get("translations"),
                       t["length"], t["name"], t["fps"], t["source"], t["role"], t["labels"],
                       {col: t[col] for col in OUTPUT_COLUMNS}, frames["action_frame"])

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


@contextmanager
def _compute_threads(config: JobConfig):
    """On the compiled path the job's parallelism is over pairs: the compiled splicer's threads are
    set to ``config.threads`` and torch's intra-op threads to one while it runs (no fine-grained
    parallel regions). The torch path keeps torch's threads."""
    old_torch = torch.get_num_threads()
    old = None
    if _compiled(config):
        torch.set_num_threads(1)
        from ..cpu import get_threads, set_threads

        old = get_threads()
        set_threads(config.threads)
    try:
        yield
    finally:
        torch.set_num_threads(old_torch)
        if old is not None:
            from ..cpu import set_threads

            set_threads(old)


def _compiled(config: JobConfig) -> bool:
    """Whether the job runs the compiled CPU splicer (else torch, e.g. on CUDA)."""
    return resolve_backend(SpliceOptions(device=config.device)) == "compiled"


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
