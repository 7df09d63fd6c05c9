"""The job's plan: which pairs to splice, grouped into tasks, and which are skipped and why.

:func:`make_plan` turns a :class:`~torchsplice.job.config.JobConfig` and its databases into a
:class:`Plan`, deterministically: the same inputs and settings give the same plan, on any
machine with the inputs at the same paths. It selects the clips, checks once per clip that it locomotes, finds ``cpmc``
references, lists the pairs (method by method, each locomotion against each action) with a
reason for every skipped one, and cuts the pairs into tasks: consecutive blocks of one method
and one locomotion group (skeleton and frame rate), each with a stable id. The plan is saved
as JSON in the job's work folder, so every worker, a resume and ``torchsplice merge`` see
exactly the same plan. The pairs are held as int32 columns (:class:`~torchsplice.job.pairs.PairTable`),
formed and cut into tasks by array operations: a plan of 3.1 M pairs takes 71 MB, not 0.7 GB.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..core.version import __version__
from ..core.errors import TorchspliceError, UnfinishedJobError
from ..store.lock import temp_path
from ..specs import DatasetSpec, SkeletonRoles
from ..splice.clips import clips_to_tensors
from ..splice.locomotion import check_locomotion
from ..splice.references import find_reference
from ..splice.registry import get_method
from ..splice.standing import LIMBS, acting_limbs
from .config import JobConfig
from .pairs import MIN_SECONDS, MODES, Pair, PairTable, form_pairs  # noqa: F401 (re-exported)
from ..store.select import select_clips
from .source_figures import source_figures
from .sources import Sources, clip_key, retargeted_key, retargeted_parts

__all__ = ["Pair", "Task", "Group", "Plan", "PlanClip", "ClipColumns", "make_plan", "PLAN_VERSION", "MIN_SECONDS", "SKELETONS_DIFFER"]

PLAN_VERSION = 8
SKELETONS_DIFFER = "skeletons differ: "
"""How the skip reasons of pairs not formed because their clips' skeletons differ begin: each
such reason names the two skeletons (``skeletons differ: locomotions on skeleton 0 (bandai_namco,
22 joints) x actions on skeleton 2 (cmu, 31 joints)``), so the summary counts them by skeleton."""


@dataclass
class Task:
    """Pairs ``start:stop`` of the plan, all of one method, locomotion group and mode."""

    id: str
    method: str
    group: int
    start: int
    stop: int
    mode: str = "timewarp"

    @property
    def size(self) -> int:
        return self.stop - self.start


@dataclass
class Group:
    """A locomotion skeleton (its row in the locomotion database) and frame rate, with its clips
    (keys, locomotions first), dataset spec (JSON) and leg length (file units)."""

    skeleton: int
    fps: float
    clips: list[str]
    spec: str
    leg: float

    def roles(self, skeleton) -> SkeletonRoles:
        return DatasetSpec.from_json(self.spec).bind(skeleton)


@dataclass
class PlanClip:
    """A source clip of the plan, as the tasks need it without reading it: its name, frames,
    frame rate, labels and, for a standing action, the arms it acts with (``None``: not found);
    the figures its results are judged against (:mod:`.source_figures`)."""

    name: str
    frames: int
    fps: float
    labels: dict = field(default_factory=dict)
    acting: list[str] | None = None
    penetration: float = 0.0
    penetration_depth: float = 0.0
    jerk: float = 0.0

    def to_dict(self) -> dict:
        out = {"name": self.name, "frames": self.frames, "fps": self.fps, "labels": self.labels,
               "penetration": self.penetration, "penetration_depth": self.penetration_depth, "jerk": self.jerk}
        if self.acting is not None:
            out["acting"] = list(self.acting)
        return out


@dataclass(frozen=True)
class ClipColumns:
    """The plan's clips as columns, for a task to gather its pairs' figures at once: ``row``
    maps a clip key to its row; per row its ``name``, ``frames``, ``fps``, ``penetration``,
    ``penetration_depth`` (the skeleton's units), ``jerk``, its ``acting`` limbs (a tuple, empty
    where none were found; ``acting_text`` the same joined by commas), ``acting_bits`` (bit ``i`` for :data:`~torchsplice.splice.standing.LIMBS`
    ``[i]``) and whether it is ``flagged`` as not locomoting (:attr:`Plan.flags`)."""

    row: dict
    name: np.ndarray
    frames: np.ndarray
    fps: np.ndarray
    penetration: np.ndarray
    penetration_depth: np.ndarray
    jerk: np.ndarray
    acting: list
    acting_text: np.ndarray
    acting_bits: np.ndarray
    flagged: np.ndarray

    @classmethod
    def of(cls, clips: dict, flags: dict) -> "ClipColumns":
        cs = list(clips.values())
        acting = [tuple(c.acting or ()) for c in cs]
        return cls(row={k: i for i, k in enumerate(clips)}, name=np.array([c.name for c in cs], dtype=object),
                   frames=np.array([c.frames for c in cs], np.int64), fps=np.array([c.fps for c in cs], np.float64),
                   penetration=np.array([c.penetration for c in cs], np.float64),
                   penetration_depth=np.array([c.penetration_depth for c in cs], np.float64),
                   jerk=np.array([c.jerk for c in cs], np.float64), acting=acting,
                   acting_text=np.array([",".join(a) for a in acting], dtype=object),
                   acting_bits=np.array([sum(1 << i for i, limb in enumerate(LIMBS) if limb in a) for a in acting], np.int64),
                   flagged=np.array([k in flags for k in clips], bool))

    def rows(self, keys) -> np.ndarray:
        """``(n,)`` int64 the rows of clip ``keys``."""
        row = self.row
        return np.array([row[k] for k in keys], np.int64)


@dataclass
class Plan:
    """What a job does (see the module docstring). ``clips`` maps a clip key (:func:`clip_key`)
    to its :class:`PlanClip`; ``flags`` a key to why the clip does not locomote (for forced clips)."""

    key: dict
    pairs: PairTable
    tasks: list[Task]
    groups: list[Group]
    skipped: dict[str, int]
    clips: dict[str, PlanClip]
    flags: dict[str, str] = field(default_factory=dict)
    sizing: dict = field(default_factory=dict)  # what set the tasks' size: batch_pairs, memory_budget_mb
    version: int = PLAN_VERSION

    def clip_columns(self) -> ClipColumns:
        """:attr:`clips` and :attr:`flags` as :class:`ClipColumns` (made once, on first use)."""
        if getattr(self, "_clip_columns", None) is None:
            self._clip_columns = ClipColumns.of(self.clips, self.flags)
        return self._clip_columns

    def pair_keys(self, p: Pair, same_db: bool) -> tuple[str, str, str | None]:
        ref = p.reference is not None and get_method(p.method).needs_reference
        return (clip_key("L", p.loco, same_db), action_key(p.action, p.target, same_db),
                action_key(p.reference, p.target, same_db) if ref else None)

    @property
    def retargeted(self) -> int:
        """Pairs whose action (and reference) are retargeted onto the locomotion's skeleton."""
        return int(np.count_nonzero(self.pairs.column("target") >= 0))

    @property
    def same_db(self) -> bool:
        return self.key["actions_db"] is None

    def digest(self) -> str:
        """A hash of the whole plan: two runs with the same digest write the same output
        (computed once, over :meth:`to_json`'s text as it is made, never holding it whole)."""
        if getattr(self, "_digest", None) is None:
            h = hashlib.sha256()
            for chunk in self._json_chunks():
                h.update(chunk.encode())
            self._digest = h.hexdigest()
        return self._digest

    def _json_chunks(self):
        """:meth:`to_json`'s text, in the pieces ``json`` makes it in (each pair column one piece)."""
        return json.JSONEncoder(sort_keys=True, separators=(",", ":")).iterencode(
            {"version": self.version, "key": self.key, "skipped": self.skipped, "flags": self.flags,
             "sizing": self.sizing, "groups": [asdict(g) for g in self.groups],
             "clips": {k: c.to_dict() for k, c in self.clips.items()}, "tasks": [asdict(t) for t in self.tasks],
             "pairs": self.pairs.to_dict()})

    def to_json(self) -> str:
        return "".join(self._json_chunks())

    @classmethod
    def from_json(cls, text: str) -> "Plan":
        d = json.loads(text)
        if not isinstance(d, dict):
            raise ValueError(f"a JSON {type(d).__name__}, not an object")
        if d.get("version") != PLAN_VERSION:
            raise UnfinishedJobError(f"the unfinished job's plan has version {d.get('version')}, this torchsplice writes "
                                     f"{PLAN_VERSION}: finish it with the torchsplice that started it")
        return cls(key=d["key"], pairs=PairTable.from_dict(d["pairs"]), tasks=[Task(**t) for t in d["tasks"]],
                   groups=[Group(**g) for g in d["groups"]], skipped=d["skipped"],
                   clips={k: PlanClip(**c) for k, c in d["clips"].items()}, flags=d["flags"],
                   sizing=d["sizing"], version=d["version"])

    def made_for(self, config: JobConfig) -> bool:
        """Whether this plan is the one :func:`make_plan` would make for ``config`` now: the same
        inputs (paths, sizes, times), settings, tool and sizing (a resumed job reuses its plan)."""
        key = {k: v for k, v in self.key.items() if k != "task_pairs"}
        return key == json.loads(json.dumps(plan_key(config))) and self.sizing == plan_sizing(config)

    def save(self, path: Path) -> None:
        """Write the plan atomically (a plan written at the same moment by another process of the
        same job holds the same text), a piece at a time, hashing it on the way (:meth:`digest`)."""
        tmp = temp_path(path)
        h = hashlib.sha256()
        with open(tmp, "wb") as f:
            for chunk in self._json_chunks():
                data = chunk.encode()
                h.update(data)
                f.write(data)
        self._digest = h.hexdigest()
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: Path) -> "Plan":
        try:
            return cls.from_json(Path(path).read_text())
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise UnfinishedJobError(f"{path}: not a readable job plan ({type(exc).__name__}: {exc}); its job "
                                     "cannot be resumed") from None


def _fingerprint(path: Path) -> dict:
    st = path.stat()
    return {"path": str(path.resolve()), "size": st.st_size, "mtime_ns": st.st_mtime_ns}


def plan_key(config: JobConfig) -> dict:
    """What defines a job: the settings of :meth:`JobConfig.plan_key`, the inputs and the tool."""
    return {"tool": f"torchsplice {__version__}", "database": _fingerprint(config.database),
            "actions_db": _fingerprint(config.actions_db) if config.actions_db else None, **config.plan_key()}


def plan_sizing(config: JobConfig) -> dict:
    """The settings that size the tasks (see :func:`_task_size`)."""
    return {"batch_pairs": config.batch_pairs, "memory_budget_mb": config.memory_budget_mb}


def leg_length(skeleton, roles: SkeletonRoles) -> float:
    """Hip-to-ankle bone length of the left leg (offset norms), in file units."""
    j, total = roles.feet[0], 0.0
    while j not in (roles.hips[0], -1):
        total += float(skeleton.offsets[j].norm())
        j = skeleton.parents[j]
    return total


def make_plan(config: JobConfig, sources: Sources) -> Plan:
    """The plan of ``config`` (see the module docstring); ``sources`` reads (and keeps) the clips."""
    c = config
    loco_db, act_db = sources.db("L"), sources.db("A")
    same = act_db is loco_db or c.actions_db is None
    tl = loco_db.clip_table()
    ta = tl if same else act_db.clip_table()
    locos = select_clips(tl, c.locomotions, "{locomotions}", str(c.database))
    acts = select_clips(ta, c.actions, "{actions}", str(c.actions_db or c.database))
    sk_l, sk_a = loco_db.skeletons, act_db.skeletons
    described = (_describe_skeletons(loco_db, None), _describe_skeletons(act_db, None if same else c.actions_db),
                 _skeleton_units(loco_db), _skeleton_units(act_db))
    if not same:
        for k in ("units", "up_axis") if not c.retarget else ():  # retargeting converts units and up axes
            a, b = str(loco_db.attrs.get(k) or ""), str(act_db.attrs.get(k) or "")
            if a and b and a != b and "mixed" not in (a, b):
                raise TorchspliceError(f"{c.actions_db}: {k.replace('_', ' ')} {b!r} differs from {c.database}'s {a!r}; "
                                       "splice clips of one unit and up axis, or let retargeting convert them "
                                       "({retarget} is off)", options=("retarget",))
    specs = {}
    for k in sorted({int(tl.skeleton[i]) for i in locos}):
        specs[k] = loco_db.spec(k)  # the stored spec, else one detected
    needs_ref = any(get_method(m).needs_reference for m in c.methods)
    refs = _references(ta, acts, next(iter(specs.values()))) if needs_ref else {}
    others = sorted({int(j) for j in acts} | {int(r) for r in refs.values() if r is not None})
    # skeleton pairs: on one skeleton already (None), retargeted (the target's id), or why not formed (text)
    kinds = _skeleton_pairs(c, sources, same, sorted(specs), sorted({int(ta.skeleton[j]) for j in others}), sk_l, sk_a,
                            described)
    if all(isinstance(kinds[int(tl.skeleton[i]), int(ta.skeleton[j])], str) for i in locos for j in acts):
        x, y = int(tl.skeleton[locos[0]]), int(ta.skeleton[acts[0]])
        raise TorchspliceError(f"the selected locomotions ({c.database}) and actions ({c.actions_db or c.database}) "
                               f"have no skeleton in common and cannot be retargeted: {kinds[x, y]}", options=("retarget",))
    # groups: a locomotion skeleton and rate, its locomotions, then every action and reference of its topology
    # and units, and every other one retargeted onto it
    by_group: dict[tuple[int, float], list[str]] = {}
    for i in locos:
        by_group.setdefault((int(tl.skeleton[i]), float(tl.fps[i])), []).append(clip_key("L", i, same))
    groups: list[Group] = []
    for (k, fps), keys in by_group.items():
        for j in others:
            key = clip_key("A", j, same)
            kind = kinds[k, int(ta.skeleton[j])]
            if kind is None and key not in keys:
                keys.append(key)
            elif isinstance(kind, int):
                keys.append(retargeted_key(key, k))
                ref = refs.get(j)
                if ref is not None and not isinstance(kinds[k, int(ta.skeleton[ref])], str):  # its reference too
                    keys.append(retargeted_key(clip_key("A", ref, same), k))
        roles = specs[k].bind(sk_l[k])
        groups.append(Group(k, fps, list(dict.fromkeys(keys)), specs[k].to_json(), leg_length(sk_l[k], roles)))
    sources.share_banks(groups)
    tables = {"L": tl, "A": ta}
    clips = {}
    for g in groups:
        for key in g.clips:
            moved = retargeted_parts(key)
            tag, row = (moved[1] if moved else key).split(":")
            t = tables[tag]
            labels = dict(t.labels[int(row)])
            if moved:
                labels.update(sources.retargeting_for(tag, int(t.skeleton[int(row)]), moved[0]).labels)
            clips[key] = PlanClip(str(t.name[int(row)]), int(t.length[int(row)]), float(t.fps[int(row)]), labels)
    checks = _locomotion_checks(c, sources, groups, clips, sk_l)

    pairs, skipped = form_pairs(c, loco_rows=locos, action_rows=acts, same_db=same, loco_table=tl, action_table=ta,
                                skeleton_pairs=kinds, clip_checks=checks, references=refs)
    _acting(c, sources, groups, clips, sk_l, _standing_action_keys(pairs, same))
    source_figures(c, sources, groups, clips, sk_l)
    if not len(pairs):
        reasons = "; ".join(f"{n} x {w}" for w, n in skipped.items())
        raise TorchspliceError(f"no pair to splice: every selected pair was skipped ({reasons})")
    size = _task_size(c, pairs, groups, tl, ta)
    group_of = {(g.skeleton, g.fps): n for n, g in enumerate(groups)}
    loco = pairs.column("loco")
    rows, at = np.unique(loco, return_inverse=True)
    group = np.array([group_of[(int(tl.skeleton[r]), float(tl.fps[r]))] for r in rows.tolist()], dtype=np.int64)[at]
    tasks = _cut_tasks(pairs, group, size)
    flags = {k: chk.reason for k, chk in checks.items() if not chk.locomoting}
    key = plan_key(c)
    key["task_pairs"] = size
    return Plan(key=key, pairs=pairs, tasks=tasks, groups=groups, skipped=skipped, clips=clips, flags=flags,
                sizing=plan_sizing(c))


def _references(ta, acts, spec: DatasetSpec) -> dict[int, int | None]:
    """Action row -> reference row (in the action database) for ``cpmc``."""
    names = [str(n) for n in ta.name]
    cands = ta.captures()
    index = {n: i for i, n in enumerate(names)}
    out = {}
    for j in acts:
        ref = find_reference(names[j], dict(ta.labels[j]), cands, spec)
        out[int(j)] = index[ref] if ref is not None else None
    return out


def _locomotion_checks(config: JobConfig, sources: Sources, groups: list[Group], clips: dict, sk_l) -> dict:
    """Clip key -> :class:`LocomotionCheck`, each clip at its own frame rate (from its group's bank
    when the rates agree and the compiled splicer runs, else by torch FK)."""
    out: dict = {}
    options, backend = config.splice_options(), config.splice_backend()
    for n, g in enumerate(groups):
        roles = g.roles(sk_l[g.skeleton])
        # clips in order of length, so that each padded batch holds clips of about one length
        native = sorted((k for k in g.clips if clips[k].fps == g.fps and k not in out), key=lambda k: clips[k].frames)
        if backend.prepares_once:
            bank, index = sources.bank(n, g.clips, g.fps, roles, options, backend)
            for chunk in _padded_chunks(native, [clips[k].frames for k in native]):
                out.update(zip(chunk, backend.locomotion_checks(bank, [index[k] for k in chunk], [], roles, g.fps,
                                                                options)[0]))
        rest: dict[float, list[str]] = {}
        for k in sorted(g.clips, key=lambda k: clips[k].frames):
            if k not in out:
                rest.setdefault(clips[k].fps, []).append(k)
        for rate, keys in rest.items():
            for b in range(0, len(keys), 64):
                chunk = keys[b:b + 64]
                motions = [sources.motion(k) for k in chunk]
                for k, chk in zip(chunk, check_locomotion(clips_to_tensors(motions, motions[0].skeleton), roles, rate)):
                    out[k] = chk
    return out


def _padded_chunks(keys: list[str], frames: list[int], budget: int = 65_536, most: int = 256) -> list[list[str]]:
    """``keys`` (in order of length, ``frames`` each) cut into consecutive chunks of at most
    ``most`` clips whose padded batch (clips x the longest) holds at most ``budget`` frames (a
    longer clip alone): checked in one batch each, so that long takes never pad 256 clips to
    their length."""
    chunks: list[list[str]] = []
    longest = 0  # of the last chunk
    for k, n in zip(keys, frames):
        longest = max(n, longest)
        if chunks and len(chunks[-1]) < most and (len(chunks[-1]) + 1) * longest <= budget:
            chunks[-1].append(k)
        else:
            chunks.append([k])
            longest = n
    return chunks


def _acting(config: JobConfig, sources: Sources, groups: list[Group], clips: dict, sk_l, keys: set[str]) -> None:
    """Record in ``clips[key].acting`` the arms each standing action acts with (found once per
    clip from its own frames, or ``config.acting_limbs``)."""
    for g in groups:
        todo = sorted((k for k in g.clips if k in keys and clips[k].acting is None), key=lambda k: clips[k].frames)
        if config.acting_limbs is not None:
            for k in todo:
                clips[k].acting = list(config.acting_limbs)
            continue
        roles = g.roles(sk_l[g.skeleton])
        for b in range(0, len(todo), 64):
            chunk = todo[b:b + 64]
            motions = [sources.motion(k) for k in chunk]
            by_rate: dict[float, list[int]] = {}
            for m_i, m in enumerate(motions):
                by_rate.setdefault(m.fps, []).append(m_i)
            for idx in by_rate.values():
                found = acting_limbs(clips_to_tensors([motions[i] for i in idx], motions[idx[0]].skeleton), roles,
                                     motions[idx[0]].skeleton)
                for i, (limbs, _measure) in zip(idx, found):
                    clips[chunk[i]].acting = list(limbs)


def _skeleton_units(db) -> dict[int, tuple[str, str]]:
    """Skeleton id -> its ``(units, up_axis)`` as stored (``""`` where not recorded)."""
    return {k: (str(info.units or ""), str(info.up_axis or ""))
            for k, info in ((k, db.skeleton_info(k)) for k in range(len(db.skeletons)))}


def _describe_skeletons(db, path) -> dict[int, str]:
    """Skeleton id -> ``skeleton K (spec, J joints)`` (``of FILE`` added when ``path`` is given)."""
    out = {}
    for k, sk in enumerate(db.skeletons):
        spec = db.skeleton_info(k).spec_name or "no spec"
        out[k] = f"skeleton {k}{f' of {Path(path).name}' if path else ''} ({spec}, {sk.num_joints} joints)"
    return out


def action_key(action: int, target: int | None, same: bool) -> str:
    """The key of an action clip (row ``action``) as its group holds it: retargeted onto
    skeleton ``target``, if set."""
    key = clip_key("A", action, same)
    return key if target is None else retargeted_key(key, target)


def _skeleton_pairs(c: JobConfig, sources: Sources, same: bool, kls, kas, sk_l, sk_a, described) -> dict:
    """``(locomotion skeleton, action skeleton) -> None`` (one skeleton: same joints, units and up
    axis), the locomotion skeleton's id (the actions are retargeted onto it, turned onto its up
    axis), or the reason its
    pairs are not formed (text beginning :data:`SKELETONS_DIFFER`, ``units differ`` or ``up axes differ``), by
    :func:`torchsplice.retarget.clips.needs_retargeting`. Each retargeting map is built here,
    once per process (a skeleton that is not a humanoid says what it lacks)."""
    from ..retarget.clips import needs_retargeting  # loaded by jobs that may retarget, not by every worker

    out: dict = {}
    for x in kls:
        for y in kas:
            (ul, upl), (ua, upa) = described[2][x], described[3][y]
            topology = sk_l[x].same_topology(sk_a[y])
            if not needs_retargeting(sk_a[y], ua, sk_l[x], ul, upa, upl):
                out[x, y] = None
                continue
            if topology:  # one topology, two units or up axes
                what = "units differ" if ul and ua and ul != ua else "up axes differ"
                why = (f"{what}: locomotions on {described[0][x]} in {'/'.join(v or '?' for v in described[2][x])} "
                       f"x actions on {described[1][y]} in {'/'.join(v or '?' for v in described[3][y])}")
            else:
                why = f"{SKELETONS_DIFFER}locomotions on {described[0][x]} x actions on {described[1][y]}"
            if not c.retarget:
                out[x, y] = f"{why} ({{retarget}} is off)"
            else:
                try:
                    sources.retargeting_for("L" if same else "A", y, x)
                    out[x, y] = x
                except TorchspliceError as exc:
                    out[x, y] = f"{why}, not retargeted: {exc}"
    return out


def _standing_action_keys(pairs: PairTable, same: bool) -> set[str]:
    """The keys of the actions of the standing pairs (each as its group holds it)."""
    on = pairs.column("mode") == MODES.index("standing")
    both = np.unique(np.stack([pairs.column("action")[on], pairs.column("target")[on]], axis=1), axis=0)
    return {action_key(a, None if t < 0 else t, same) for a, t in both.tolist()}


def _cut_tasks(pairs: PairTable, group: np.ndarray, size: int) -> list[Task]:
    """The plan's tasks: runs of pairs of one method, locomotion group (``group``, ``(N,)``) and
    mode, each run cut into blocks of ``size`` pairs, numbered in order."""
    method, mode = pairs.column("method"), pairs.column("mode")
    change = np.nonzero((method[1:] != method[:-1]) | (group[1:] != group[:-1]) | (mode[1:] != mode[:-1]))[0] + 1
    edges = np.concatenate([[0], change, [len(pairs)]]).tolist()
    tasks: list[Task] = []
    for a, b in zip(edges[:-1], edges[1:]):
        for start in range(a, b, size):
            tasks.append(Task(f"{len(tasks):06d}", pairs.methods[int(method[a])], int(group[a]), start,
                              min(start + size, b), MODES[int(mode[a])]))
    return tasks


def _task_size(c: JobConfig, pairs: PairTable, groups, tl, ta) -> int:
    """Pairs per task: ``batch_pairs``, or what fits the memory budget (one worker's alignment
    tables for the longest pair, and a task's results)."""
    if c.batch_pairs is not None:
        return max(1, int(c.batch_pairs))
    locos, acts = np.unique(pairs.column("loco")), np.unique(pairs.column("action"))
    t_l = int(np.asarray(tl.length, dtype=np.int64)[locos].max())
    fps = max(g.fps for g in groups)
    t_a = max(int(ta.length[j] * fps / float(ta.fps[j])) + 1 for j in acts.tolist())
    J = 64  # a generous joint count: the budget is a bound, not an estimate
    if c.splice_backend().prepares_once:  # the compiled splicer: one pair's tables per thread, float64
        left = c.memory_budget_mb * 2**20 - 11 * t_l * t_a
        per_pair = 2 * t_l * (J * 28 + 16) + 16 * (t_l + t_a)
        return int(min(256, max(1, left // per_pair)))
    per_pair = 40 * t_l * t_a + 2000 * 32 * (t_l + t_a)  # torch: grid, DP tables, clip tensors
    return int(min(256, max(1, c.memory_budget_mb * 2**20 // per_pair)))
