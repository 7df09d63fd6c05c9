"""Splice one pair or a batch of (locomotion, action) pairs, with any of the three methods.

    from torchsplice.splice import splice, splice_pairs
    result = splice(walk, carry_box, spec)                 # the Heck et al. 2006 splice
    result.motion                                          # the spliced Motion
    results = splice_pairs([(walk, wave), (turn, wave)], spec, method="naive")

Methods come from the registry (:mod:`torchsplice.splice.registry`): the built-in ``"splice"``
(Heck, Kovar & Gleicher 2006), ``"naive"`` (per-bone replacement of the upper body, no
timewarp: what per-bone layer masks do) and ``"cpmc"`` (differencing against a
plain-locomotion ``reference`` of the action's performer, as in Al-Ghreimil & Hahn 2003 and
engines' additive layers), and any plug-in method.

Pairs are batched: clips used by several pairs are prepared (resampled to the locomotion's
frame rate, forward kinematics) once. On the CPU the pairs then run through the compiled
splicer (:mod:`torchsplice.cpu`: one pair per thread, in parallel over pairs); on CUDA, or
with ``SpliceOptions(backend="torch")``, every step runs on padded pair tensors
(:mod:`torchsplice.splice.heck`). Both give the same clips (to float32 rounding). Results
keep the locomotion's skeleton, frame rate, root and lower body.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
import torch

from ..core.errors import MotionError, NotLocomotingError, TorchspliceError
from ..core.motion import Motion
from ..specs import DatasetSpec, SkeletonRoles
from .clips import ClipTensors, check_clip, check_pair, clips_to_tensors, resample_motion
from .heck import AlignOptions
from .locomotion import LocomotionCheck, check_locomotion
from .registry import Method, MethodInput, MethodOutput, get_method, run_checked
from .standing import TIMINGS, acting_limbs

__all__ = ["BACKENDS", "TIMINGS", "SpliceOptions", "SpliceResult", "NotLocomotingError", "splice",
           "splice_pairs", "splice_standing", "resolve_backend"]

BACKENDS = ("auto", "compiled", "torch")


def spliced_labels(method: str, locomotion: str, locomotion_labels: dict, action: str, action_labels: dict) -> dict:
    """A spliced clip's labels: ``method``, the source clips' names (``locomotion``, ``action``)
    and every label of each source, as ``locomotion.KEY`` and ``action.KEY`` (so that
    ``where={"labels.action.style": ["elderly"]}`` selects by the action's style)."""
    out = {f"locomotion.{k}": str(v) for k, v in (locomotion_labels or {}).items()}
    out.update({f"action.{k}": str(v) for k, v in (action_labels or {}).items()})
    out.update({"method": method, "locomotion": locomotion, "action": action})
    return out


@dataclass(frozen=True)
class SpliceOptions:
    """Options for every method.

    Attributes:
        align: time-alignment parameters (:class:`~torchsplice.splice.heck.AlignOptions`).
        posture: apply posture transfer (``splice`` only).
        twist: the share (0 to 1) of the locomotion's torso twist that posture transfer adds to
            the action's posture (``splice`` only; 0, the default, is the paper's transfer; see
            :func:`~torchsplice.splice.heck.twist_target`). On the Bandai Namco ground truth
            0.5 lowers side walks' error by 3% and the median by 4%, and runs' rises by 0.2%.
        force: splice clips that do not locomote instead of refusing them.
        check_locomotion: run the locomotion check at all (a caller that has checked its
            clips already, such as the n x m job, turns it off).
        min_seconds: shortest clip accepted.
        dtype, device: where the tensor work runs (float32 on the CPU by default); the
            compiled backend computes in float64 and returns ``dtype``.
        backend: ``"auto"`` (the compiled splicer on the CPU, torch on other devices),
            ``"compiled"`` or ``"torch"``.
        timing: how an action that does not locomote (a standing action) fills the
            locomotion: ``"loop"`` (default), ``"hold"`` or ``"fit"`` (see
            :mod:`torchsplice.splice.standing`).
        acting_limbs: the arms standing actions act with (``None``: found per clip from the
            data; ``()``: none, only the spine and head come from the action).
    """

    align: AlignOptions = field(default_factory=AlignOptions)
    posture: bool = True
    twist: float = 0.0
    force: bool = False
    check_locomotion: bool = True
    min_seconds: float = 0.5
    dtype: torch.dtype = torch.float32
    device: str | None = None
    backend: str = "auto"
    timing: str = "loop"
    acting_limbs: tuple[str, ...] | None = None


def resolve_backend(options: SpliceOptions) -> str:
    """``"compiled"`` or ``"torch"``: what ``options.backend`` means for ``options.device``."""
    if options.backend not in BACKENDS:
        raise TorchspliceError(f"unknown backend {options.backend!r}; choose one of {', '.join(BACKENDS)}")
    on_cpu = options.device is None or torch.device(options.device).type == "cpu"
    if options.backend == "compiled" and not on_cpu:
        raise TorchspliceError(f"the compiled backend runs on the CPU; device {options.device!r} needs backend 'torch' or 'auto'")
    if options.backend == "auto":
        from ..cpu import available

        return "compiled" if on_cpu and available() else "torch"
    return options.backend


@dataclass
class SpliceResult:
    """One spliced pair.

    Attributes:
        motion: the spliced clip (locomotion's skeleton and frame rate), role ``"spliced"``.
        method: the method's name (``"splice"``, ``"naive"``, ``"cpmc"`` or a plug-in's).
        locomotion, action, reference: source clip names (``reference`` for methods that
            need one, such as ``cpmc``).
        cost: average lower-body frame distance along the alignment path (file units squared);
            NaN for methods that do not align (``naive``).
        curve: ``(T,)`` float64, for each result frame the action frame (at the action's own
            frame rate, from its first frame) whose upper body it carries.
        crop: action frames skipped at the start (at the action's frame rate).
        path: ``(P, 2)`` the DP path (locomotion frame, cropped action frame at the
            locomotion's rate); empty for ``naive``.
        pelvis_correction: ``(T,)`` per-frame angle of the spatial-alignment rotation, degrees.
        posture_deg: angle of the posture-transfer rotation ``q_G``, degrees.
        checks: the locomotion checks of (locomotion, action).
        notes: warnings, e.g. a clip that was forced although it does not locomote.
        timing: ``"timewarp"`` (the two clips were time-aligned) or, for a standing action,
            its timing: ``"loop"``, ``"hold"`` or ``"fit"``.
        acting: for a standing action, the arms taken from it (the others keep the
            locomotion's swing).
    """

    motion: Motion
    method: str
    locomotion: str
    action: str
    reference: str | None
    cost: float
    curve: torch.Tensor
    crop: int
    path: torch.Tensor
    pelvis_correction: torch.Tensor
    posture_deg: float
    checks: tuple[LocomotionCheck, LocomotionCheck] | None = None
    notes: tuple[str, ...] = ()
    timing: str = "timewarp"
    acting: tuple[str, ...] = ()


def splice(locomotion: Motion, action: Motion, spec: DatasetSpec | SkeletonRoles, method: str | Method = "splice",
           reference: Motion | None = None, options: SpliceOptions | None = None) -> SpliceResult:
    """Splice the upper body of ``action`` onto the lower body of ``locomotion``."""
    return splice_pairs([(locomotion, action)], spec, method, None if reference is None else [reference], options)[0]


def _unique(motions: Sequence[Motion]) -> tuple[list[Motion], torch.Tensor]:
    """Distinct clips (by identity) and, per input, its index among them."""
    seen: dict[int, int] = {}
    uniq: list[Motion] = []
    idx = []
    for m in motions:
        if id(m) not in seen:
            seen[id(m)] = len(uniq)
            uniq.append(m)
        idx.append(seen[id(m)])
    return uniq, torch.tensor(idx)


def splice_pairs(pairs: Sequence[tuple[Motion, Motion]], spec: DatasetSpec | SkeletonRoles, method: str | Method = "splice",
                 references: Sequence[Motion] | None = None, options: SpliceOptions | None = None) -> list[SpliceResult]:
    """Splice every ``(locomotion, action)`` pair, batched; results in the order of ``pairs``.

    ``method`` is a registered method's name (see :func:`~torchsplice.splice.registry.available_methods`)
    or a :class:`~torchsplice.splice.registry.Method`. ``references`` (one per pair) are
    required by methods that need them (``cpmc``). Pairs must share one skeleton topology. Raises :class:`~torchsplice.core.errors.MotionError` naming the clip for a pair
    that cannot be spliced, and :class:`NotLocomotingError` for a clip that does not locomote
    (unless ``options.force``).
    """
    options = options or SpliceOptions()
    meth = get_method(method)
    if not pairs:
        return []
    if not meth.needs_reference:
        references = None
    if meth.needs_reference and references is not None and len(references) != len(pairs):
        raise TorchspliceError(f"method {meth.name!r} needs one reference per pair: {len(references)} for {len(pairs)} pairs")
    if meth.needs_reference and references is None:
        references = [None] * len(pairs)
    skeleton = pairs[0][0].skeleton
    roles = spec.bind(skeleton) if isinstance(spec, DatasetSpec) else spec
    groups: dict[float, list[int]] = {}
    clips = _unique([m for p in pairs for m in p] + [r for r in (references or []) if r is not None])[0]
    for m in clips:
        check_clip(m, max(4, int(options.min_seconds * m.fps)))
    for k, (loco, act) in enumerate(pairs):
        for other in (act, references[k] if references is not None else None):
            if other is not None and other.skeleton is not loco.skeleton:
                check_pair(loco, other)
        if not loco.skeleton.same_topology(skeleton):
            raise MotionError(f"clip {loco.name!r} has another skeleton than {pairs[0][0].name!r}; splice one skeleton per call")
        groups.setdefault(loco.fps, []).append(k)
    if options.timing not in TIMINGS:
        raise TorchspliceError(f"unknown timing {options.timing!r}; choose one of {', '.join(TIMINGS)}")
    if not 0.0 <= float(options.twist) <= 1.0:
        raise TorchspliceError(f"twist must be a share from 0 to 1, got {options.twist!r}")
    results: list[SpliceResult | None] = [None] * len(pairs)
    for fps, ks in groups.items():
        standing = _standing_pairs([pairs[k] for k in ks], roles, skeleton, options, fps) if meth.standing else set()
        for part in (standing, None):
            sel = [k for n, k in enumerate(ks) if (n in standing) == (part is not None)]
            if not sel:
                continue
            refs = [references[k] for k in sel] if meth.needs_reference else None
            if part is None and refs is not None and any(r is None for r in refs):
                raise TorchspliceError(f"method {meth.name!r} needs a plain-locomotion reference clip for every action that "
                                       "locomotes (standing actions need none)")
            run = _splice_standing if part is not None else _splice_group
            for k, r in zip(sel, run([pairs[k] for k in sel], refs, roles, meth, options, fps)):
                results[k] = r
    return results  # type: ignore[return-value]


def _standing_pairs(pairs, roles: SkeletonRoles, skeleton, options: SpliceOptions, fps: float) -> set[int]:
    """Indices of the pairs whose action does not locomote (and is not forced through the
    timewarp): they are spliced as standing actions."""
    if options.force or not options.check_locomotion:
        return set()
    acts, ai = _unique([p[1] for p in pairs])
    A = clips_to_tensors([resample_motion(a, fps) for a in acts], skeleton, dtype=options.dtype)
    checks = check_locomotion(A, roles, fps)
    return {b for b in range(len(pairs)) if checks[int(ai[b])].finite and not checks[int(ai[b])].locomoting}


def splice_standing(pairs: Sequence[tuple[Motion, Motion]], spec: DatasetSpec | SkeletonRoles, method: str | Method = "splice",
                    options: SpliceOptions | None = None,
                    acting: Sequence[tuple[str, ...]] | None = None) -> list[SpliceResult]:
    """Splice ``(locomotion, action)`` pairs as standing actions (see :mod:`torchsplice.splice.standing`),
    whether or not the actions locomote; results in the order of ``pairs``, each as long as its
    locomotion. ``acting`` gives each pair's acting arms (default: ``options.acting_limbs``, or
    found from each action). :func:`splice_pairs` calls it for the actions that do not locomote.
    """
    options = options or SpliceOptions()
    method = get_method(method)
    if method.standing is None:
        raise TorchspliceError(f"method {method.name!r} has no standing-action variant; splice_pairs runs its own "
                               "function on every pair")
    if not pairs:
        return []
    roles = spec.bind(pairs[0][0].skeleton) if isinstance(spec, DatasetSpec) else spec
    groups: dict[float, list[int]] = {}
    for k, (loco, _) in enumerate(pairs):
        groups.setdefault(loco.fps, []).append(k)
    results: list[SpliceResult | None] = [None] * len(pairs)
    for fps, ks in groups.items():
        sub = [acting[k] for k in ks] if acting is not None else None
        for k, r in zip(ks, _splice_standing([pairs[k] for k in ks], None, roles, method, options, fps, sub)):
            results[k] = r
    return results  # type: ignore[return-value]


def _splice_standing(pairs, refs, roles: SkeletonRoles, method: Method, options: SpliceOptions, fps: float,
                     acting: list | None = None) -> list[SpliceResult]:
    """Pairs whose action does not locomote (see :mod:`torchsplice.splice.standing`): the compiled
    splicer on the CPU for the built-in methods, else the method's torch function."""
    skeleton = pairs[0][0].skeleton
    locos, li = _unique([p[0] for p in pairs])
    acts, ai = _unique([p[1] for p in pairs])
    acts = [resample_motion(a, fps) for a in acts]
    compiled = method.compiled and resolve_backend(options) == "compiled"
    kw = dict(dtype=options.dtype, device=options.device)
    A = None if compiled and (acting is not None or options.acting_limbs is not None) else clips_to_tensors(acts, skeleton, **kw)
    if compiled:
        from ..cpu.bank import ClipBank, standing_bank

        bank = ClipBank.from_motions(locos + acts, skeleton, roles, options.align.landmarks)
        checks = None
        if options.check_locomotion:
            positions, lengths = bank.padded_positions()
            checks = check_locomotion(ClipTensors(None, None, lengths, positions, None), roles, fps)
        checks_l, checks_a = (checks[:len(locos)], checks[len(locos):]) if checks is not None else (None, None)
    else:
        L = clips_to_tensors(locos, skeleton, **kw)
        checks_l = check_locomotion(L, roles, fps) if options.check_locomotion else None
        checks_a = check_locomotion(A, roles, fps) if options.check_locomotion else None
    notes: list[list[str]] = [[] for _ in pairs]
    for b, (lo, _) in enumerate(pairs):
        check = checks_l[int(li[b])] if checks_l is not None else None
        if check is not None and not check.finite:
            raise NotLocomotingError(f"clip {lo.name!r} {check.reason}")
        if check is not None and not check.locomoting:
            if not options.force:
                raise NotLocomotingError(f"clip {lo.name!r} does not locomote: {check.reason}")
            notes[b].append(f"{lo.name} does not locomote: {check.reason}; spliced anyway (forced)")
    if acting is None:
        found = acting_limbs(A, roles, skeleton) if options.acting_limbs is None else None
        acting = [tuple(options.acting_limbs) if found is None else found[int(ai[b])][0] for b in range(len(pairs))]
    acting = [tuple(a) for a in acting]
    if compiled:
        from .standing import LIMBS, standing_tables

        out = standing_bank(bank, li.numpy(), len(locos) + ai.numpy(), [[n in a for n in LIMBS] for a in acting],
                            standing_tables(roles, skeleton, fps), method.name, options.timing,
                            dtype=np.float64 if options.dtype == torch.float64 else np.float32)
        frames = [(torch.from_numpy(out.rotations[s:s + n]).to(options.dtype),
                   torch.from_numpy(out.translations[s:s + n]).to(options.dtype), torch.from_numpy(out.curve[s:s + n]))
                  for s, n in zip(out.start.tolist(), out.frames.tolist())]
    else:
        clips, times = run_checked(method, method.standing, MethodInput(L.take(li), A.take(ai), None, roles, skeleton,
                                                                        options, fps), options.timing, acting)
        n_ = clips.lengths.tolist()
        frames = [(clips.rotations[b, :n], clips.translations[b, :n], times[b, :n]) for b, n in enumerate(n_)]
    results = []
    for b, (lo, ac) in enumerate(pairs):
        rot, trans, times_b = frames[b]
        n = rot.shape[0]
        limbs = f"; acting limbs: {', '.join(acting[b]) or 'none'}" if method.name == "splice" else ""
        notes[b].append(f"{ac.name} does not locomote: spliced as a standing action ({options.timing}{limbs})")
        motion = Motion(
            skeleton=lo.skeleton, rotations=rot, root_translation=trans[:, 0].clone(),
            translations=trans if lo.skeleton.has_joint_translations else None, fps=fps,
            name=method.clip_name(lo.name, ac.name), source=f"splice:{method.name}", role="spliced",
            labels=spliced_labels(method.name, lo.name, lo.labels, ac.name, ac.labels),
        )
        results.append(SpliceResult(
            motion=motion, method=method.name, locomotion=lo.name, action=ac.name,
            reference=None, cost=float("nan"), curve=(times_b.to(torch.float64) * (ac.fps / fps)).cpu(), crop=0,
            path=torch.zeros(0, 2, dtype=torch.long), pelvis_correction=torch.zeros(n, dtype=torch.float64),
            posture_deg=0.0, checks=(checks_l[int(li[b])], checks_a[int(ai[b])]) if checks_l is not None else None,
            notes=tuple(notes[b]), timing=options.timing, acting=acting[b],
        ))
    return results


def _splice_group(pairs, refs, roles: SkeletonRoles, method: Method, options: SpliceOptions, fps: float) -> list[SpliceResult]:
    """Pairs whose locomotions share a frame rate ``fps``."""
    if method.compiled and resolve_backend(options) == "compiled":
        return _splice_group_compiled(pairs, refs, roles, method, options, fps)
    if options.backend == "torch":  # every step in torch, the DP too
        options = replace(options, align=replace(options.align, dp_backend="torch"))
    skeleton = pairs[0][0].skeleton
    locos, li = _unique([p[0] for p in pairs])
    acts, ai = _unique([p[1] for p in pairs] + (refs or []))
    kw = dict(dtype=options.dtype, device=options.device)
    L = clips_to_tensors(locos, skeleton, **kw)
    A = clips_to_tensors([resample_motion(a, fps) for a in acts], skeleton, **kw)
    ok = LocomotionCheck(True, "", (0, 0), float("nan"), float("nan"))  # not checked
    checks_l = check_locomotion(L, roles, fps) if options.check_locomotion else [ok] * len(locos)
    checks_a = check_locomotion(A, roles, fps) if options.check_locomotion else [ok] * len(acts)
    dev = L.rotations.device
    li, ai = li.to(dev), ai.to(dev)
    B = len(pairs)
    notes: list[list[str]] = [[] for _ in range(B)]
    for b in range(B):
        for clip, check in ((pairs[b][0], checks_l[int(li[b])]), (pairs[b][1], checks_a[int(ai[b])])):
            if not check.finite:
                raise NotLocomotingError(f"clip {clip.name!r} {check.reason}")
            if not check.locomoting:
                if not options.force:
                    raise NotLocomotingError(f"clip {clip.name!r} does not locomote: {check.reason}")
                notes[b].append(f"{clip.name} does not locomote: {check.reason}; spliced anyway (forced)")
    loco, act = L.take(li), A.take(ai[:B])
    out: MethodOutput = run_checked(method, method.run,
                                    MethodInput(loco, act, A.take(ai[B:]) if refs else None, roles, skeleton, options, fps))
    clips, times = out.clips, out.times
    empty = torch.zeros(0, 2, dtype=torch.long)
    corr = out.pelvis_correction if out.pelvis_correction is not None else torch.zeros(times.shape, dtype=torch.float64)
    posture = out.posture_deg if out.posture_deg is not None else torch.zeros(B)
    cost = out.cost if out.cost is not None else torch.full((B,), float("nan"))
    crop = out.crop if out.crop is not None else torch.zeros(B, dtype=torch.long)
    paths = out.paths if out.paths is not None else [empty] * B
    results = []
    for b, (lo, ac) in enumerate(pairs):
        n = int(clips.lengths[b])
        scale = ac.fps / fps  # action frames at its own rate per frame at the locomotion's rate
        motion = Motion(
            skeleton=lo.skeleton,
            rotations=clips.rotations[b, :n],
            root_translation=clips.translations[b, :n, 0],
            translations=clips.translations[b, :n] if lo.skeleton.has_joint_translations else None,
            fps=fps,
            name=method.clip_name(lo.name, ac.name),
            source=f"splice:{method.name}",
            role="spliced",
            labels=spliced_labels(method.name, lo.name, lo.labels, ac.name, ac.labels),
        )
        results.append(SpliceResult(
            motion=motion, method=method.name, locomotion=lo.name, action=ac.name,
            reference=refs[b].name if refs else None, cost=float(cost[b]),
            curve=(times[b, :n].to(torch.float64) * scale).cpu(), crop=int(round(float(crop[b]) * scale)),
            path=paths[b].cpu(), pelvis_correction=corr[b, :n].cpu(), posture_deg=float(posture[b]),
            checks=(checks_l[int(li[b])], checks_a[int(ai[b])]) if options.check_locomotion else None,
            notes=tuple(notes[b]),
        ))
    return results


def _notes_or_raise(pairs, li, ai, checks_l, checks_a, options) -> list[list[str]]:
    """Per pair, the notes on clips that do not locomote; raises unless ``options.force``."""
    notes: list[list[str]] = [[] for _ in pairs]
    for b, (lo, ac) in enumerate(pairs):
        for clip, check in ((lo, checks_l[li[b]]), (ac, checks_a[ai[b]])):
            if not check.finite:
                raise NotLocomotingError(f"clip {clip.name!r} {check.reason}")
            if not check.locomoting:
                if not options.force:
                    raise NotLocomotingError(f"clip {clip.name!r} does not locomote: {check.reason}")
                notes[b].append(f"{clip.name} does not locomote: {check.reason}; spliced anyway (forced)")
    return notes


def _splice_group_compiled(pairs, refs, roles: SkeletonRoles, method: Method, options: SpliceOptions, fps: float) -> list[SpliceResult]:
    """:func:`_splice_group` through the compiled splicer (:mod:`torchsplice.cpu`)."""
    from ..cpu.bank import ClipBank, CompiledSpliceError, splice_bank

    skeleton = pairs[0][0].skeleton
    locos, li = _unique([p[0] for p in pairs])
    acts, ai = _unique([p[1] for p in pairs] + (refs or []))
    bank = ClipBank.from_motions(locos + [resample_motion(a, fps) for a in acts], skeleton, roles, options.align.landmarks)
    ok = LocomotionCheck(True, "", (0, 0), float("nan"), float("nan"))  # not checked
    checks = [ok] * len(bank)
    if options.check_locomotion:
        positions, lengths = bank.padded_positions()
        checks = check_locomotion(ClipTensors(None, None, lengths, positions, None), roles, fps)
    B = len(pairs)
    li, ai = li.tolist(), ai.tolist()
    notes = _notes_or_raise(pairs, li, ai, checks[:len(locos)], checks[len(locos):], options)
    act_idx = [len(locos) + a for a in ai]
    try:
        out = splice_bank(bank, li, act_idx[:B], method.name, ref=act_idx[B:] if method.needs_reference else None,
                          dtype=np.float64 if options.dtype == torch.float64 else np.float32,
                          **bank_kwargs(options, fps))
    except CompiledSpliceError as exc:
        lo, ac = pairs[exc.pair]
        raise MotionError(f"clips {lo.name!r} and {ac.name!r} cannot be aligned: {exc.reason}") from None
    results = []
    deg = 180.0 / math.pi
    for b, (lo, ac) in enumerate(pairs):
        s, n = int(out.start[b]), int(out.frames[b])
        scale = ac.fps / fps
        rot = torch.from_numpy(out.rotations[s:s + n]).to(options.dtype)
        trans = torch.from_numpy(out.translations[s:s + n]).to(options.dtype)
        motion = Motion(
            skeleton=lo.skeleton, rotations=rot, root_translation=trans[:, 0].clone(),
            translations=trans if lo.skeleton.has_joint_translations else None, fps=fps,
            name=method.clip_name(lo.name, ac.name), source=f"splice:{method.name}", role="spliced",
            labels=spliced_labels(method.name, lo.name, lo.labels, ac.name, ac.labels),
        )
        results.append(SpliceResult(
            motion=motion, method=method.name, locomotion=lo.name, action=ac.name,
            reference=refs[b].name if refs else None, cost=float(out.cost[b]),
            curve=torch.from_numpy(out.curve[s:s + n] * scale), crop=int(round(float(out.crop[b]) * scale)),
            path=torch.from_numpy(out.cells[b, : int(out.path_length[b])].copy()),
            pelvis_correction=torch.from_numpy(out.correction[s:s + n] * deg), posture_deg=float(out.posture[b]) * deg,
            checks=(checks[li[b]], checks[act_idx[b]]) if options.check_locomotion else None,
            notes=tuple(notes[b]),
        ))
    return results


def bank_kwargs(options: SpliceOptions, fps: float) -> dict:
    """The compiled splicer's (:func:`~torchsplice.cpu.bank.splice_bank`) method arguments for
    ``options``: posture, twist and the alignment's (:func:`align_kwargs`). The one place that
    maps options to the kernels, for :func:`splice_pairs` and the n x m job alike, so that an
    option cannot reach one and miss the other."""
    return dict(posture=options.posture, twist=options.twist, **align_kwargs(options.align, fps))


def align_kwargs(align: AlignOptions, fps: float) -> dict:
    """The compiled splicer's alignment arguments (frame counts at ``fps``) for ``align``."""
    return dict(max_run=align.max_run, heading_window_deg=align.heading_window_deg, crop=align.crop,
                crop_context=int(round(align.crop_context_s * fps)), crop_window=max(1, int(round(align.crop_window_s * fps))),
                knot_spacing=align.knot_spacing_s * fps)
