"""The torch backend: each method's torch function on padded pair tensors, on any device.

Prepared clips are the clips themselves; each call pads the batch's distinct locomotions and
distinct actions (and references) into :class:`~torchsplice.splice.clips.ClipTensors` and runs
the method's function (checked by :func:`~torchsplice.splice.registry.run_checked`). It runs
every method, plug-ins too, on CPU or CUDA, in the options' dtype. With
``SpliceOptions(backend="torch")`` the time alignment's DP runs in torch as well.

Torch and the torch code of the splicer are imported where used: choosing a backend
(:func:`~torchsplice.splice.backends.resolve_backend`, which asks every registered backend its
devices and priority) loads no torch, so the job can decide early whether it starts workers.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from ...core.errors import TorchspliceError
from ...core.ranges import lengths_to_starts
from ..registry import MethodFailedError, MethodInput, run_checked
from . import Backend, SplicedBatch

if TYPE_CHECKING:
    import torch

__all__ = ["TorchBackend", "TorchClips", "BACKEND"]


@dataclass
class TorchClips:
    """Prepared clips of the torch backend: the clips (one skeleton, one frame rate), their roles,
    and the padded tensors made of them so far (the locomotion check and the splice of one call
    pad the same rows: once)."""

    motions: list
    skeleton: object
    roles: object
    padded: dict = field(default_factory=dict)


def _distinct(rows) -> tuple[list[int], torch.Tensor]:
    """Distinct clip rows in order of first use, and per input its index among them."""
    import torch

    seen: dict[int, int] = {}
    for r in rows:
        seen.setdefault(int(r), len(seen))
    return list(seen), torch.tensor([seen[int(r)] for r in rows], dtype=torch.long)


class TorchBackend(Backend):
    """The torch implementation (see the module docstring)."""

    name = "torch"

    def prepare(self, motions, skeleton, roles, options):
        return TorchClips(list(motions), skeleton, roles)

    def _tensors(self, prepared: TorchClips, rows, options):
        from ..clips import clips_to_tensors

        key = (tuple(int(r) for r in rows), options.dtype, options.device)
        if key not in prepared.padded:
            prepared.padded[key] = clips_to_tensors([prepared.motions[r] for r in key[0]], prepared.skeleton,
                                                    dtype=options.dtype, device=options.device)
        return prepared.padded[key]

    def positions(self, prepared, rows=None):
        import torch

        from ..options import SpliceOptions

        rows = range(len(prepared.motions)) if rows is None else rows
        t = self._tensors(prepared, list(rows), SpliceOptions(dtype=torch.float32))
        return t.positions, t.lengths

    def locomotion_checks(self, prepared, loco_rows, action_rows, roles, fps, options):
        from ..locomotion import check_locomotion

        L = self._tensors(prepared, loco_rows, options)
        A = self._tensors(prepared, action_rows, options)
        return check_locomotion(L, roles, fps), check_locomotion(A, roles, fps)

    def splice(self, prepared, loco, action, reference, method, options, fps, *, buffers=None, keep_going=False):
        B = len(loco)
        try:
            return self._splice(prepared, loco, action, reference, method, options, fps)
        except (ValueError, TorchspliceError) as exc:
            if not keep_going:
                raise
            if B == 1:  # this pair cannot be spliced: no frames, and why
                why = str(exc) if isinstance(exc, MethodFailedError) else f"the alignment failed ({exc})"
                return _failed(prepared, why, options)
        parts = [self.splice(prepared, loco[b:b + 1], action[b:b + 1],
                             reference[b:b + 1] if reference is not None else None, method, options, fps, keep_going=True)
                 for b in range(B)]
        return SplicedBatch.concat(parts)

    def _splice(self, prepared, loco, action, reference, method, options, fps) -> SplicedBatch:
        if options.backend == "torch":  # every step in torch, the DP too
            options = replace(options, align=replace(options.align, dp_backend="torch"))
        B = len(loco)
        refs = list(reference) if method.needs_reference and reference is not None else []
        lu, li = _distinct(loco)
        au, ai = _distinct(list(action) + refs)
        L = self._tensors(prepared, lu, options)
        A = self._tensors(prepared, au, options)
        li, ai = li.to(L.rotations.device), ai.to(L.rotations.device)
        out = run_checked(method, method.run, MethodInput(L.take(li), A.take(ai[:B]), A.take(ai[B:]) if refs else None,
                                                          prepared.roles, prepared.skeleton, options, fps))
        return _pack(out.clips.rotations, out.clips.translations, out.times, out.clips.lengths, out.pelvis_correction,
                     crop=out.crop.detach().cpu().double().numpy() if out.crop is not None else np.zeros(B),
                     cost=out.cost.detach().cpu().double().numpy() if out.cost is not None else np.full(B, np.nan),
                     posture=out.posture_deg.detach().cpu().double().numpy() if out.posture_deg is not None else np.zeros(B),
                     paths=[p.detach().cpu().numpy() for p in out.paths] if out.paths is not None
                     else [np.zeros((0, 2), np.int64)] * B)

    def standing(self, prepared, loco, action, acting, tables, method, options, fps, *, buffers=None, keep_going=False):
        try:
            return self._standing(prepared, loco, action, acting, method, options, fps)
        except (ValueError, TorchspliceError) as exc:
            if not keep_going:
                raise
            if len(loco) == 1:
                return _failed(prepared, str(exc) if isinstance(exc, MethodFailedError) else f"the alignment failed ({exc})",
                               options)
        return SplicedBatch.concat([self.standing(prepared, loco[b:b + 1], action[b:b + 1], acting[b:b + 1], tables, method,
                                                  options, fps, keep_going=True) for b in range(len(loco))])

    def _standing(self, prepared, loco, action, acting, method, options, fps) -> SplicedBatch:
        lu, li = _distinct(loco)
        au, ai = _distinct(action)
        L = self._tensors(prepared, lu, options)
        A = self._tensors(prepared, au, options)
        clips, times = run_checked(method, method.standing, MethodInput(L.take(li), A.take(ai), None, prepared.roles,
                                                                        prepared.skeleton, options, fps),
                                   options.timing, [tuple(a) for a in acting])
        B = len(clips.lengths)
        return _pack(clips.rotations, clips.translations, times, clips.lengths, None, crop=np.zeros(B),
                     cost=np.full(B, np.nan), posture=np.zeros(B), paths=[np.zeros((0, 2), np.int64)] * B)

    def threads(self):
        import torch

        return torch.get_num_threads()

    def set_threads(self, n):
        import torch

        if n is not None:
            torch.set_num_threads(max(1, int(n)))


def _pack(rotations, translations, times, lengths, correction, crop, cost, posture, paths) -> SplicedBatch:
    """A :class:`SplicedBatch` from padded ``(B, T, ...)`` method outputs (``lengths`` ``(B,)``,
    ``correction`` ``(B, T)`` or ``None``): each array packed by one mask, pair after pair."""
    import torch

    def packed(x: torch.Tensor) -> torch.Tensor:
        valid = torch.arange(x.shape[1], device=x.device)[None, :] < lengths.to(x.device)[:, None]
        return x[valid]

    frames = lengths.detach().cpu().numpy().astype(np.int64)
    start = lengths_to_starts(frames)
    curve = packed(times.detach()).to(torch.float64).cpu().numpy()
    corr = packed(correction.detach()).to(torch.float64).cpu().numpy() if correction is not None else np.zeros(len(curve))
    return SplicedBatch(start, frames, packed(rotations), packed(translations), curve, corr, crop, cost, posture,
                        list(paths), {})


def _failed(prepared: TorchClips, why: str, options) -> SplicedBatch:
    """One pair that could not be spliced: no frames."""
    import torch

    J = prepared.skeleton.num_joints
    kw = dict(dtype=options.dtype, device=options.device)
    return SplicedBatch(np.zeros(1, np.int64), np.zeros(1, np.int64), torch.zeros(0, J, 4, **kw), torch.zeros(0, J, 3, **kw),
                        np.zeros(0), np.zeros(0), np.zeros(1), np.full(1, np.nan), np.zeros(1),
                        [np.zeros((0, 2), np.int64)], {0: why})


BACKEND = TorchBackend()
