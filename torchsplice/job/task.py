"""One task of the job: splice its pairs, and give back their results packed, with their columns.

:func:`run_task` is all a worker does, whatever the engine: it takes the plan, one task and the
job's :class:`~torchsplice.job.sources.Sources`, splices the task's pairs (the compiled CPU
splicer, or torch on CUDA), and returns a :class:`Part`: every result's frames packed in whole
arrays and every output column computed at once. A task's result depends on its pairs alone,
not on the other tasks, the worker or the engine. A pair that cannot be aligned is left out
with its reason in ``Part.skipped``.
"""

from __future__ import annotations

import json
import logging
import math
import mmap
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from ..core.errors import TorchspliceError
from ..core.method_table import builtin
from ..core.ranges import lengths_to_starts, ranges_to_rows
from ..core.version import __version__
from ..ops.plausibility import penetration_of_frames
from ..ops.units import centimetres
from ..specs import DatasetSpec
from ..store.assembly import TIMING_CODES
from ..store.lock import temp_path
from ..splice.api import spliced_labels
from ..splice.backends import backend_for
from ..splice.clips import resample_motion
from ..splice.registry import get_method, load_plugins
from .config import JobConfig
from .plan import Plan, Task
from .source_figures import scales
from .sources import Sources

__all__ = ["Part", "run_task", "OUTPUT_COLUMNS", "FRAME_COLUMNS", "POOR_ALIGNMENT", "poor_alignment", "FLAG_SEPARATOR",
           "FLAG_CODES", "alignment_distance", "SELF_PENETRATION", "self_penetration"]

log = logging.getLogger("torchsplice.job")

OUTPUT_COLUMNS = {
    "locomotion": "str", "action": "str", "reference": "str", "method": "str", "params": "str", "flags": "str",
    "flag_details": "str", "locomotion_id": "int", "action_id": "int", "crop": "int",
    "cost": "float", "alignment_distance": "float", "posture_deg": "float", "pelvis_correction_deg": "float",
    "coverage": "float", "timing": "str", "acting": "str",
    "penetration": "float", "penetration_depth": "float", "penetration_locomotion": "float",
    "penetration_depth_locomotion": "float", "penetration_action": "float", "penetration_depth_action": "float",
    "corrected_frames": "int", "foot_skate": "float", "foot_slide": "float", "floor": "float", "jerk": "float",
    "jerk_action": "float",
}
FLAG_CODES = {
    "poor_alignment": "the lower bodies align poorly (alignment_distance above 0.10 leg lengths): other locomotion "
                      "types, or a long take of several activities",
    "locomotion_not_locomoting": "the locomotion does not locomote (spliced with force_locomotion)",
    "action_not_locomoting": "the action does not locomote (spliced through the timewarp with force_locomotion)",
    "self_penetration": "a hand or forearm is inside the body (torso, pelvis, head or legs) on a larger share of the "
                        "frames than in either source (penetration above both sources' by more than 0.05)",
}
"""The codes of the ``flags`` column (comma-separated, sorted; ``""``: none) and what each means;
the figures behind them are columns of their own (``alignment_distance``), and ``flag_details``
says each flag in words with its figures and clip names."""
SELF_PENETRATION = 0.05
"""Flag a result whose hand is inside its body (:func:`~torchsplice.ops.plausibility.penetration`)
on a share of its frames larger than both its sources' by more than this: a box held against
the belly, which the action does, is not a defect."""
FRAME_COLUMNS = ("action_frame",)
POOR_ALIGNMENT = 0.10
"""Flag a pair whose aligned lower-body landmarks lie further apart than this, on average, in
leg lengths (``sqrt(cost) / leg``). The 3,540 walk-onto-walk pairs of 60 Bandai Namco walks
give a median of 0.05 and a 95th percentile of 0.10 (99th: 0.12); above it the two gaits match
worse than 95% of those (different locomotion types, or a long take with several activities:
cut those with ``import --split``)."""


def alignment_distance(cost: float, leg: float) -> float:
    """The aligned lower-body landmarks' mean distance in leg lengths, ``sqrt(cost) / leg`` (0
    where it cannot be said)."""
    return math.sqrt(max(cost, 0.0)) / leg if leg > 0 and math.isfinite(cost) else 0.0


def poor_alignment(cost: float, leg: float) -> str:
    """The flag's words for a pair of alignment ``cost`` on legs of length ``leg``, or ``""`` when fine."""
    dist = alignment_distance(cost, leg)
    if dist <= POOR_ALIGNMENT:
        return ""
    return f"poor alignment (mean landmark distance {dist:.2f} leg lengths, above {POOR_ALIGNMENT:g})"


def self_penetration(share: float, locomotion: float, action: float, depth: float) -> str:
    """The flag's words for a result with a hand inside its body on ``share`` of its frames (its
    sources ``locomotion`` and ``action``), ``depth`` cm deep at worst; ``""`` when fine."""
    if not share > max(locomotion, action) + SELF_PENETRATION:
        return ""
    return (f"a hand inside the body on {share:.0%} of the frames (locomotion {locomotion:.0%}, action {action:.0%}), "
            f"up to {depth:.1f} cm deep")


FLAG_SEPARATOR = " | "
"""Between the flags said in words in ``flag_details``."""


@dataclass
class Part:
    """One task's results, packed along frames (see :meth:`MotionDatabase.append_packed`):
    ``rotations (N, J, 4)`` and ``translations (N, J, 3)`` float32 (row 0 the root),
    ``lengths``, ``names``, ``fps``, ``labels`` (JSON), the output ``extra`` columns and the
    per-frame ``action_frame``; ``skipped`` counts the pairs left out, by reason.

    For an alignment store (``JobConfig.store``), ``parts`` holds what the clips are assembled
    from instead of their frames (``rotations`` and ``translations`` then have no rows): per
    clip ``kind`` (see :data:`torchsplice.store.assembly.KIND_CODES`), ``locomotion`` and
    ``action`` (the clips' keys, see :mod:`torchsplice.job.sources`), ``crop``, ``method``,
    ``timing``, ``window``, ``loop_start``, ``loop_end``, ``acting``; per frame ``curve``
    (float64) and ``pelvis`` (``(N, 4)`` float32), both ``None`` for standing clips; the arms
    moved out of the body (:func:`_keep_hands_out`), ``arms_rows`` ``(M,)`` the frames changed
    and ``arms`` ``(M, 4, 4)`` their shoulders' and elbows' rotations, zeros for a joint not changed
    (:meth:`dense_arms`)."""

    task: str
    skeleton: object
    spec: str
    names: list
    lengths: np.ndarray
    fps: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    labels: list
    extra: dict
    action_frame: np.ndarray
    skipped: dict = field(default_factory=dict)
    plan: str = ""  # the digest of the plan it was made for
    parts: dict | None = None

    def dense_arms(self) -> np.ndarray | None:
        """An alignment store's ``assembly_arms`` of the part's frames ``(N, 4, 4)`` float32: the
        moved arms' rotations where a frame's were changed, zeros (no rotation) elsewhere."""
        if self.parts is None or self.parts.get("arms") is None or not len(self.parts["arms"]):
            return None
        out = np.zeros((int(np.sum(self.lengths)), 4, 4), np.float32)
        out[np.asarray(self.parts["arms_rows"], np.int64)] = self.parts["arms"]
        return out

    @property
    def sources(self) -> list[str]:
        return [f"splice:{m}" for m in self.extra["method"]]

    def save(self, path: Path) -> None:
        """Write the part to ``path``: a JSON header (everything but the arrays, and where each
        array lies) then the arrays' raw bytes, under a temporary name renamed into place, so
        that a killed writer leaves no part. (Neither compressed nor checksummed: a part lives
        for the seconds between its task and the merge.)"""
        meta = {"task": self.task, "spec": self.spec, "names": list(self.names), "labels": list(self.labels),
                "skipped": self.skipped, "plan": self.plan,
                "extra": {k: list(map(str, v)) for k, v in self.extra.items() if OUTPUT_COLUMNS[k] == "str"}}
        arrays = {"lengths": np.asarray(self.lengths), "fps": np.asarray(self.fps), "rotations": self.rotations,
                  "translations": self.translations, "action_frame": self.action_frame,
                  **{f"extra.{k}": np.asarray(v) for k, v in self.extra.items() if OUTPUT_COLUMNS[k] != "str"}}
        if self.parts is not None:
            meta["parts"] = {k: list(v) for k, v in self.parts.items() if k in PART_KEYS}
            arrays.update({f"parts.{k}": np.asarray(v) for k, v in self.parts.items() if k not in PART_KEYS and v is not None})
        arrays = {k: np.ascontiguousarray(a) for k, a in arrays.items()}
        at, table = 0, {}
        for k, a in arrays.items():
            table[k] = (at, a.dtype.str, list(a.shape))
            at += a.nbytes
        head = json.dumps({"meta": meta, "arrays": table}).encode()
        tmp = temp_path(path)
        with open(tmp, "wb") as f:
            f.write(len(head).to_bytes(8, "little") + head)
            for a in arrays.values():
                a.tofile(f)
        os.replace(tmp, path)

    @staticmethod
    def header(path: Path) -> dict:
        """The JSON header of a part file (see :meth:`save`): ``meta``, ``arrays`` and ``base``
        (where the arrays start); a file that is not a whole part is one
        :class:`~torchsplice.core.errors.TorchspliceError` line."""
        try:
            size = Path(path).stat().st_size
            with open(path, "rb") as f:
                n = int.from_bytes(f.read(8), "little")
                if not 0 < n <= size - 8:
                    raise ValueError("no header")
                head = json.loads(f.read(n))
            end = 8 + n + max((at + int(np.prod(shape)) * np.dtype(dt).itemsize
                               for at, dt, shape in head["arrays"].values()), default=0)
            if end != size:
                raise ValueError(f"{size} bytes where its arrays end at {end}")
            return {**head, "base": 8 + n}
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise TorchspliceError(f"{path}: not a whole part of the job ({str(exc)[:80]}); delete it and run the job's "
                                   "slice again") from None

    @classmethod
    def load(cls, path: Path, skeleton) -> "Part":
        """A part written by :meth:`save` (on ``skeleton``, its locomotion group's), its arrays
        mapped from the file rather than read: plain arrays over one read-only map of it (a
        ``numpy.memmap`` per array, and its scalars, cost the writer 8% of a job of short clips)."""
        head = cls.header(path)
        base = head["base"]
        with open(path, "rb") as f:
            whole = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        arrays = {k: np.frombuffer(whole, np.dtype(dt), int(np.prod(shape)), base + at).reshape(shape)
                  if int(np.prod(shape)) else np.zeros(shape, np.dtype(dt)) for k, (at, dt, shape) in head["arrays"].items()}
        meta = head["meta"]
        extra = {k: arrays[f"extra.{k}"] for k, kind in OUTPUT_COLUMNS.items() if kind != "str"}
        extra.update(meta["extra"])
        parts = None
        if "parts" in meta:
            parts = {**meta["parts"], "curve": None, "pelvis": None,
                     **{k[6:]: a for k, a in arrays.items() if k.startswith("parts.")}}
        return cls(task=meta["task"], skeleton=skeleton, spec=meta["spec"], names=meta["names"], lengths=arrays["lengths"],
                   fps=arrays["fps"], rotations=arrays["rotations"], translations=arrays["translations"],
                   labels=meta["labels"], extra=extra, action_frame=arrays["action_frame"], skipped=meta["skipped"],
                   plan=meta["plan"], parts=parts)


def run_task(plan: Plan, task: Task, sources: Sources, config: JobConfig, buffers=None) -> Part:
    """Splice the pairs of ``task`` (see the module docstring)."""
    resolved = config.resolved_backend()
    if plan.key["tool"] != f"torchsplice {__version__}" or plan.key["backend"] != resolved:
        raise TorchspliceError(f"this worker runs torchsplice {__version__} with the {resolved} splicer, but the job "
                               f"was planned by {plan.key['tool']} with the {plan.key['backend']} splicer: install the same "
                               "version (and numba) everywhere")
    load_plugins(plan.key.get("plugins", ()))  # plug-in methods register themselves in this process too
    group = plan.groups[task.group]
    pairs = plan.pairs[task.start:task.stop]
    keys = [plan.pair_keys(p, plan.same_db) for p in pairs]
    skeleton = sources.motion(group.clips[0]).skeleton
    roles = group.roles(skeleton)
    fps = group.fps
    method = task.method
    spec_m = get_method(method)
    standing = getattr(task, "mode", "timewarp") == "standing"
    options = config.splice_options()
    backend = backend_for(spec_m, resolved)
    if backend.prepares_once:  # the group's clips, prepared once per job (see Sources.bank)
        prepared, index = sources.bank(task.group, group.clips, fps, roles, options, backend)
    else:  # this task's clips
        wanted = list(dict.fromkeys(c for k in keys for c in k if c))
        prepared = backend.prepare([resample_motion(sources.motion(c), fps) for c in wanted], skeleton, roles, options)
        index = {c: i for i, c in enumerate(wanted)}
    lo, ac = [index[k[0]] for k in keys], [index[k[1]] for k in keys]
    cols = plan.clip_columns()  # the pairs' source figures, gathered by row
    rows_l, rows_a = cols.rows(k[0] for k in keys), cols.rows(k[1] for k in keys)
    if standing:  # actions that do not locomote: looped, held or fitted (see torchsplice.splice.standing)
        acting = [cols.acting[r] for r in rows_a.tolist()]
        batch = backend.standing(prepared, lo, ac, acting, sources.standing_tables(task.group, roles, skeleton, fps),
                                 spec_m, options, fps, buffers=buffers, keep_going=True)
    else:
        ref = [index[k[2]] for k in keys] if spec_m.needs_reference else None
        batch = backend.splice(prepared, lo, ac, ref, spec_m, options, fps, buffers=buffers, keep_going=True)
    failed = batch.failed
    ok = np.array([b not in failed for b in range(len(keys))], dtype=bool)
    kept = np.flatnonzero(ok).tolist()
    frames, rot, trans = batch.frames[ok], _float32(batch.rotations), _float32(batch.translations)
    curve, corr, crop = batch.curve, batch.correction, np.asarray(batch.crop, dtype=np.float64)[ok]
    cost, posture = np.asarray(batch.cost, dtype=np.float64)[ok], np.asarray(batch.posture, dtype=np.float64)[ok]
    skipped: dict[str, int] = {}
    for b, why in failed.items():
        skipped[why] = skipped.get(why, 0) + 1
        log.warning("%s + %s: %s", cols.name[rows_l[b]], cols.name[rows_a[b]], why)
    body = sources.body_model("body", task.group, skeleton, roles)
    inside = _penetration(backend, body, skeleton, frames, rot, trans)
    kept_keys = [keys[b] for b in kept]
    rows = (cols, rows_l[ok], rows_a[ok])  # the kept pairs' sources' rows
    corrected, arms = np.zeros(len(kept), np.int64), None
    if config.keep_hands_out:
        rot, corrected, arms = _keep_hands_out(backend, rows, group, skeleton, body, frames, rot, trans, inside,
                                               lambda: sources.body_model("arms", task.group, skeleton, roles))
    cm = centimetres(DatasetSpec.from_json(group.spec).units)
    inside = (inside[0], inside[1] * cm)  # (share, depth in cm); the frames' deepest no longer needed
    part = _pack(plan, rows, group, config, task, [pairs[b] for b in kept], kept_keys, skeleton,
                 frames, rot, trans, curve, corr, crop, cost, posture, inside)
    part.extra["corrected_frames"] = corrected
    part.extra.update(_figures(backend, group, skeleton, sources.body_model("figures", task.group, skeleton, roles),
                               frames, rot, trans))
    part.extra["jerk_action"] = cols.jerk[rows[2]]
    part.parts = _parts(rows, config, task, kept_keys, batch, ok, standing)
    if part.parts is not None:
        part.parts["arms_rows"], part.parts["arms"] = arms if arms is not None else (
            np.zeros(0, np.int64), np.zeros((0, 4, 4), np.float32))
    if part.parts is not None:  # the clips are their parts: no frames to carry
        part.rotations, part.translations = rot[:0], trans[:0]
    part.skipped = skipped
    part.plan = plan.digest()
    return part


def _penetration(backend, body, skeleton, frames, rot: np.ndarray, trans: np.ndarray) -> tuple:
    """``(share, depth, deepest)``: per result how it puts a hand inside ``body`` (depth in the
    skeleton's units), and per packed frame its deepest, from its packed frames
    (:meth:`~torchsplice.splice.backends.Backend.inside_body`)."""
    if not len(frames):
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return backend.inside_body(rot, trans, frames, skeleton, body, per_frame=True)


def _figures(backend, group, skeleton, joints, frames, rot: np.ndarray, trans: np.ndarray) -> dict:
    """The results' ``foot_skate``, ``foot_slide`` (cm/s), ``floor`` (cm) and ``jerk`` (m/s^3)
    from their packed frames (:meth:`~torchsplice.splice.backends.Backend.figures`; ``joints``:
    :func:`~torchsplice.ops.plausibility.figure_joints`); NaN where the skeleton's units are
    unknown."""
    up, per_metre, _ = scales(group.spec)
    names = ("foot_skate", "foot_slide", "floor", "jerk")
    if not len(frames) or not np.isfinite(per_metre):
        return {k: np.full(len(frames), np.nan if len(frames) else 0.0) for k in names}
    return backend.figures(rot, trans, frames, float(group.fps), skeleton, joints, up, per_metre)


def _keep_hands_out(backend, rows, group, skeleton, body, frames, rot: np.ndarray, trans: np.ndarray,
                    inside: tuple, arms_of) -> tuple:
    """Move the arms of the results whose hand goes deeper inside the body than either source's
    does, or that the ``self_penetration`` flag would report (then out to a quarter of the
    body's margin, whatever the sources do)
    (:meth:`~torchsplice.splice.backends.Backend.keep_hands_out`), in ``rot``, and their ``inside``
    figures anew (in place; only the frames changed are measured again). ``(rot, corrected frames
    per result, (rows, arms))``: ``rows`` the packed frames changed and ``arms`` ``(M, 4, 4)``
    their shoulders' and elbows' new rotations (:attr:`~torchsplice.ops.hands.Arms.moved`), zeros
    for a joint not changed, what an alignment store keeps of them. ``arms_of()`` gives the
    group's :class:`~torchsplice.ops.hands.Arms`
    (:meth:`~torchsplice.job.sources.Sources.body_model`: made once); ``rows`` the plan's
    :class:`~torchsplice.job.plan.ClipColumns` and the results' locomotions' and actions' rows."""
    share, depth, deepest = inside  # depth in the skeleton's units, as the plan's; deepest per packed frame
    corrected = np.zeros(len(frames), np.int64)
    cols, rows_l, rows_a = rows
    allowed = allowed_inside(share, cols.penetration[rows_l], cols.penetration[rows_a], cols.penetration_depth[rows_l],
                             cols.penetration_depth[rows_a])
    todo = np.flatnonzero((share > 0) & (depth > allowed))
    if not len(todo):
        return rot, corrected, None
    frames = np.asarray(frames, np.int64)
    starts = lengths_to_starts(frames)
    n = frames[todo]
    rows = ranges_to_rows(starts[todo], n)
    arms = arms_of()  # the group's Arms (ops.hands.arms_of), made once
    rot = np.array(rot, copy=True) if not rot.flags.writeable else rot
    # corrected where they lie (no copy of their frames): in place, each clip read before it is written;
    # per frame a bit per moved joint whose value changed (a joint written equal keeps the splice's bits)
    changed = np.zeros(len(rot), np.uint8)
    _, count = backend.keep_hands_out(rot, trans, n, float(group.fps), skeleton, body, arms, allowed[todo],
                                      deepest=deepest, starts=starts[todo], out=rot, changed=changed)
    again, arms_now = changed_arms(rot, changed, arms.moved)
    corrected[todo] = np.asarray(count, np.int64)
    if len(again):  # frames are measured one by one: the changed alone, then each result's figures again
        deepest[again] = backend.inside_body(rot[again], trans[again], [len(again)], skeleton, body, per_frame=True)[2]
    s2, d2 = penetration_of_frames(torch.from_numpy(deepest[rows]), n, body.margin)
    share[todo], depth[todo] = s2.numpy(), d2.numpy()
    return rot, corrected, (again, arms_now)


def allowed_inside(share, share_l, share_a, depth_l, depth_a) -> np.ndarray:
    """How deep (the skeleton's units) each result's forearm may stay inside its body before the
    hands correction moves it: as deep as its deeper source goes (``depth_l``, ``depth_a``), and
    not at all where the result is inside on a larger share of its frames (``share``) than both
    its sources (``share_l``, ``share_a``) by :data:`SELF_PENETRATION` (the flag would report it)."""
    often = np.maximum(share_l, share_a)
    return np.where(np.asarray(share) > often + SELF_PENETRATION, 0.0, np.maximum(depth_l, depth_a))


def changed_arms(rot: np.ndarray, changed: np.ndarray, moved) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, arms)``: what an alignment store keeps of a hands correction, from the bits it set
    in ``changed`` ``(N,)`` (:meth:`~torchsplice.splice.backends.Backend.keep_hands_out`): the
    frames changed, ascending, and ``(H, 4, 4)`` their ``moved`` joints' rotations in ``rot``
    ``(N, J, 4)``, zeros for a joint not changed."""
    rows = np.flatnonzero(changed)
    bits = (changed[rows, None] >> np.arange(4, dtype=np.uint8)) & 1  # (H, 4)
    return rows, np.where(bits[:, :, None] > 0, _joint_rows(rot, rows, list(moved)), rot.dtype.type(0))


def _joint_rows(rot: np.ndarray, rows: np.ndarray, joints) -> np.ndarray:
    """``rot[rows[:, None], joints]``, ``(R, len(joints), 4)`` of ``rot`` ``(N, J, 4)``: gathered a
    quaternion at a time (one 16-byte item, not four floats: 3x faster on the frames the hands
    correction changed)."""
    quats = np.ascontiguousarray(rot).view(np.dtype((np.void, 4 * rot.itemsize)))[..., 0]
    return quats[np.asarray(rows)[:, None], list(joints)][..., None].view(rot.dtype)


PART_KEYS = ("kind", "locomotion", "action")
"""The per-clip parts of :attr:`Part.parts` kept as lists (the rest are arrays)."""


def _parts(rows, config: JobConfig, task: Task, keys, batch, ok: np.ndarray, standing: bool) -> dict | None:
    """A task's parts for an alignment store (see :class:`Part`), or ``None`` where its clips keep
    their frames: a motion store, a backend that gives no parts, a plug-in method, or a built-in
    whose table row stores frames (cpmc through the timewarp: its result is a per-joint difference
    on the locomotion, not an alignment)."""
    row = builtin(task.method)
    if config.store != "alignment" or batch.parts is None or row is None or (
            not standing and row.stores == "frames"):
        return None
    p = batch.parts
    C = len(keys)
    cols, _, rows_a = rows
    acting = cols.acting_bits[rows_a] if standing else np.zeros(C, np.int64)
    loops = np.asarray(p["loops"], np.int64)[ok] if standing else np.zeros((C, 2), np.int64)
    return {"kind": ["standing" if standing else "timewarp"] * C, "locomotion": [k[0] for k in keys],
            "action": [k[1] for k in keys], "crop": np.asarray(p["crop"], np.int64)[ok],
            "method": np.full(C, row.code, np.int64),
            "timing": np.full(C, TIMING_CODES[config.timing] if standing else -1, np.int64),
            "window": np.asarray(p["window"], np.int64)[ok], "loop_start": loops[:, 0].copy(),
            "loop_end": loops[:, 1].copy(), "acting": np.asarray(acting, np.int64),
            "curve": None if standing else np.array(p["curve"], np.float64),  # a standing clip's follows from its timing
            "pelvis": None if standing else np.asarray(p["pelvis"], np.float32)}


def _float32(x) -> np.ndarray:
    """Packed result frames as float32 numpy (a torch backend's tensors come from any device)."""
    return x if isinstance(x, np.ndarray) and x.dtype == np.float32 else np.asarray(
        x.detach().float().cpu().numpy() if isinstance(x, torch.Tensor) else x, dtype=np.float32)


def _pack(plan: Plan, rows, group, config: JobConfig, task: Task, pairs, keys, skeleton, frames, rot, trans, curve,
          corr, crop, cost, posture, inside) -> Part:
    """A task's output columns, computed at once (``curve`` and ``crop`` at the locomotion's rate,
    ``corr`` and ``posture`` in degrees, ``inside`` the results' penetration share and depth)."""
    method, fps = task.method, group.fps
    cols, rows_l, rows_a = rows
    lnames, anames = cols.name[rows_l].tolist(), cols.name[rows_a].tolist()
    scale = cols.fps[rows_a] / fps  # to the action's own frames
    starts = lengths_to_starts(frames)
    mean_corr = np.add.reduceat(corr, starts) / frames if len(corr) else np.zeros(len(keys))
    loco_frames = cols.frames[rows_l]
    standing = getattr(task, "mode", "timewarp") == "standing"
    cost = np.asarray(cost, dtype=np.float64)
    distance = np.where(np.isfinite(cost), np.sqrt(np.maximum(cost, 0.0)), 0.0) / group.leg if group.leg > 0 \
        else np.zeros(len(keys))  # alignment_distance, for every pair at once
    poor = distance > POOR_ALIGNMENT
    unmoving = cols.flagged[rows_l] | (cols.flagged[rows_a] & (not standing))
    share, depth = inside
    cm = centimetres(DatasetSpec.from_json(group.spec).units)  # the plan's depths are in the skeleton's units
    of_loco, of_action = cols.penetration[rows_l], cols.penetration[rows_a]
    into = share > np.maximum(of_loco, of_action) + SELF_PENETRATION
    flags, details = [""] * len(keys), [""] * len(keys)
    for b in np.flatnonzero(poor | unmoving | into).tolist():  # words only for the pairs flagged
        k, codes, words = keys[b], [], []
        for key, name, code in ((k[0], lnames[b], "locomotion_not_locomoting"),
                                (k[1], anames[b], "action_not_locomoting"))[:1 if standing else 2]:
            if key in plan.flags:
                codes.append(code)
                words.append(f"{name} does not locomote ({plan.flags[key]})")
        if poor[b]:
            codes.append("poor_alignment")
            words.append(poor_alignment(float(cost[b]), group.leg))
        if into[b]:
            codes.append("self_penetration")
            words.append(self_penetration(float(share[b]), float(of_loco[b]), float(of_action[b]), float(depth[b])))
        flags[b], details[b] = ",".join(sorted(codes)), FLAG_SEPARATOR.join(words)
    named = get_method(method).clip_name
    extra = {
        "locomotion": lnames, "action": anames,
        "reference": [plan.clips[k[2]].name if k[2] else "" for k in keys], "method": [method] * len(keys),
        "params": [config.params()] * len(keys), "flags": flags, "flag_details": details,
        "alignment_distance": distance,
        "locomotion_id": [p.loco for p in pairs], "action_id": [p.action for p in pairs],
        "crop": np.round(crop * scale).astype(np.int64), "cost": cost, "posture_deg": posture,
        "pelvis_correction_deg": mean_corr, "coverage": frames / loco_frames,
        "timing": [config.timing if standing else "timewarp"] * len(keys),
        "acting": cols.acting_text[rows_a].tolist() if standing else [""] * len(keys),
        "penetration": share, "penetration_depth": depth,
        "penetration_locomotion": of_loco,
        "penetration_depth_locomotion": cm * cols.penetration_depth[rows_l],
        "penetration_action": of_action,
        "penetration_depth_action": cm * cols.penetration_depth[rows_a],
    }
    return Part(
        task=task.id, skeleton=skeleton, spec=group.spec,
        names=[named(lo, ac) for lo, ac in zip(lnames, anames)], lengths=frames, fps=np.full(len(keys), fps),
        rotations=rot, translations=trans,
        labels=[json.dumps(spliced_labels(method, plan.clips[k[0]].name, plan.clips[k[0]].labels,
                                          plan.clips[k[1]].name, plan.clips[k[1]].labels), sort_keys=True)
                for k in keys],
        extra=extra, action_frame=(curve * np.repeat(scale, frames)).astype(np.float32),
    )
