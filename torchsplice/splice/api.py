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

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import torch

from ..core.errors import MotionError, NotLocomotingError, TorchspliceError
from ..core.motion import Motion
from ..specs import DatasetSpec, SkeletonRoles
from . import backends
from .backends import PairFailedError, SplicedBatch, backend_for
from .clips import check_clip, check_pair, clips_to_tensors, resample_motion
from .defaults import DEFAULT_METHOD
from .locomotion import LocomotionCheck, check_locomotion
from .options import SpliceOptions
from .registry import Method, get_method
from .standing import TIMINGS, acting_limbs, standing_tables

__all__ = ["TIMINGS", "SpliceOptions", "SpliceResult", "NotLocomotingError", "splice",
           "splice_pairs", "splice_standing", "resolve_backend"]



def spliced_labels(method: str, locomotion: str, locomotion_labels: dict, action: str, action_labels: dict) -> dict:
    """A spliced clip's labels: ``method``, the source clips' names (``locomotion``, ``action``)
    and every label of each source, as ``locomotion.KEY`` and ``action.KEY`` (so that
    ``where={"labels.action.style": ["elderly"]}`` selects by the action's style)."""
    out = {f"locomotion.{k}": str(v) for k, v in (locomotion_labels or {}).items()}
    out.update({f"action.{k}": str(v) for k, v in (action_labels or {}).items()})
    out.update({"method": method, "locomotion": locomotion, "action": action})
    return out


def resolve_backend(options: SpliceOptions) -> str:
    """The backend's name ``options.backend`` means for ``options.device`` (see
    :func:`torchsplice.splice.backends.resolve_backend`)."""
    return backends.resolve_backend(options.backend, options.device)


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


def splice(locomotion: Motion, action: Motion, spec: DatasetSpec | SkeletonRoles, method: str | Method = DEFAULT_METHOD,
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


def splice_pairs(pairs: Sequence[tuple[Motion, Motion]], spec: DatasetSpec | SkeletonRoles,
                 method: str | Method = DEFAULT_METHOD, references: Sequence[Motion] | None = None,
                 options: SpliceOptions | None = None) -> list[SpliceResult]:
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


def splice_standing(pairs: Sequence[tuple[Motion, Motion]], spec: DatasetSpec | SkeletonRoles,
                    method: str | Method = DEFAULT_METHOD, options: SpliceOptions | None = None,
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


@dataclass
class _Prepared:
    """A batch of pairs made ready for a backend: the backend, its prepared clips (the pairs'
    distinct locomotions, then their distinct actions and references, at one frame rate) and,
    per pair, the rows of its locomotion, action and reference among them."""

    backend: object
    clips: object
    loco: list
    action: list
    reference: list | None
    locos: int
    acts: list


def _prepare(pairs, refs, roles: SkeletonRoles, method: Method, options: SpliceOptions, fps: float) -> _Prepared:
    backend = backend_for(method, resolve_backend(options))
    locos, li = _unique([p[0] for p in pairs])
    acts, ai = _unique([p[1] for p in pairs] + list(refs or []))
    acts = [resample_motion(a, fps) for a in acts]
    clips = backend.prepare(locos + acts, pairs[0][0].skeleton, roles, options)
    rows = [len(locos) + a for a in ai.tolist()]
    B = len(pairs)
    return _Prepared(backend, clips, li.tolist(), rows[:B], rows[B:] if refs else None, len(locos), acts)


def _checks(prep: _Prepared, roles: SkeletonRoles, options: SpliceOptions, fps: float):
    """The locomotion checks of the batch's locomotions and actions (``None``: not checked)."""
    if not options.check_locomotion:
        return None, None
    return prep.backend.locomotion_checks(prep.clips, list(range(prep.locos)), list(range(prep.locos, prep.locos + len(prep.acts))),
                                          roles, fps, options)


def _notes_or_raise(pairs, prep: _Prepared, checks_l, checks_a, options: SpliceOptions) -> list[list[str]]:
    """Per pair, the notes on clips that do not locomote (the locomotion, and the action unless
    ``checks_a`` is ``None``); raises unless ``options.force``."""
    notes: list[list[str]] = [[] for _ in pairs]
    if checks_l is None:
        return notes
    for b, (lo, ac) in enumerate(pairs):
        todo = [(lo, checks_l[prep.loco[b]])]
        if checks_a is not None:
            todo.append((ac, checks_a[prep.action[b] - prep.locos]))
        for clip, check in todo:
            if not check.finite:
                raise NotLocomotingError(f"clip {clip.name!r} {check.reason}")
            if not check.locomoting:
                if not options.force:
                    raise NotLocomotingError(f"clip {clip.name!r} does not locomote: {check.reason}")
                notes[b].append(f"{clip.name} does not locomote: {check.reason}; spliced anyway (forced)")
    return notes


def _splice_standing(pairs, refs, roles: SkeletonRoles, method: Method, options: SpliceOptions, fps: float,
                     acting: list | None = None) -> list[SpliceResult]:
    """Pairs whose action does not locomote (see :mod:`torchsplice.splice.standing`)."""
    skeleton = pairs[0][0].skeleton
    prep = _prepare(pairs, None, roles, method, options, fps)
    checks_l, checks_a = _checks(prep, roles, options, fps)
    notes = _notes_or_raise(pairs, prep, checks_l, None, options)
    if acting is None:
        if options.acting_limbs is None:
            found = acting_limbs(clips_to_tensors(prep.acts, skeleton, dtype=options.dtype, device=options.device),
                                 roles, skeleton)
            acting = [found[a - prep.locos][0] for a in prep.action]
        else:
            acting = [tuple(options.acting_limbs)] * len(pairs)
    acting = [tuple(a) for a in acting]
    batch = prep.backend.standing(prep.clips, prep.loco, prep.action, acting, standing_tables(roles, skeleton, fps),
                                  method, options, fps)
    for b, (_loco, ac) in enumerate(pairs):
        limbs = f"; acting limbs: {', '.join(acting[b]) or 'none'}" if method.uses_acting_limbs else ""
        notes[b].append(f"{ac.name} does not locomote: spliced as a standing action ({options.timing}{limbs})")
    return _results(pairs, None, prep, batch, method, options, fps, checks_l, checks_a, notes, options.timing, acting)


def _splice_group(pairs, refs, roles: SkeletonRoles, method: Method, options: SpliceOptions, fps: float) -> list[SpliceResult]:
    """Pairs whose locomotions share a frame rate ``fps``, time-aligned."""
    prep = _prepare(pairs, refs, roles, method, options, fps)
    checks_l, checks_a = _checks(prep, roles, options, fps)
    notes = _notes_or_raise(pairs, prep, checks_l, checks_a, options)
    try:
        batch = prep.backend.splice(prep.clips, prep.loco, prep.action, prep.reference, method, options, fps)
    except PairFailedError as exc:
        lo, ac = pairs[exc.pair]
        raise MotionError(f"clips {lo.name!r} and {ac.name!r} cannot be aligned: {exc.reason}") from None
    return _results(pairs, refs, prep, batch, method, options, fps, checks_l, checks_a, notes)


def _tensor(x, dtype) -> torch.Tensor:
    return torch.from_numpy(x).to(dtype) if isinstance(x, np.ndarray) else x


def _results(pairs, refs, prep: _Prepared, batch: SplicedBatch, method: Method, options: SpliceOptions, fps: float,
             checks_l, checks_a, notes, timing: str = "timewarp", acting=None) -> list[SpliceResult]:
    """Each pair's :class:`SpliceResult` from a backend's packed batch (the one place results are made)."""
    results = []
    for b, (lo, ac) in enumerate(pairs):
        rows = batch.rows(b)
        scale = ac.fps / fps  # action frames at its own rate per frame at the locomotion's rate
        rot = _tensor(batch.rotations[rows], options.dtype)
        trans = _tensor(batch.translations[rows], options.dtype)
        motion = Motion(
            skeleton=lo.skeleton, rotations=rot,
            root_translation=trans[:, 0].clone() if isinstance(batch.translations, np.ndarray) else trans[:, 0],
            translations=trans if lo.skeleton.has_joint_translations else None, fps=fps,
            name=method.clip_name(lo.name, ac.name), source=f"splice:{method.name}", role="spliced",
            labels=spliced_labels(method.name, lo.name, lo.labels, ac.name, ac.labels),
        )
        results.append(SpliceResult(
            motion=motion, method=method.name, locomotion=lo.name, action=ac.name,
            reference=refs[b].name if refs else None, cost=float(batch.cost[b]),
            curve=torch.from_numpy(batch.curve[rows] * scale), crop=int(round(float(batch.crop[b]) * scale)),
            path=torch.from_numpy(np.array(batch.paths[b], dtype=np.int64).reshape(-1, 2)),
            pelvis_correction=torch.from_numpy(batch.correction[rows]), posture_deg=float(batch.posture[b]),
            checks=(checks_l[prep.loco[b]], checks_a[prep.action[b] - prep.locos]) if checks_l is not None else None,
            notes=tuple(notes[b]), timing=timing, acting=acting[b] if acting is not None else (),
        ))
    return results
