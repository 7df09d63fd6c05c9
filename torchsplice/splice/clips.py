"""Clips as padded tensors for batched splicing: frame-rate resampling, padding and FK.

:class:`ClipTensors` holds ``B`` clips of one skeleton, padded to ``T`` frames by repeating
each clip's last frame, with their forward kinematics. Shapes: rotations ``(B, T, J, 4)``
(local, unit WXYZ), root translation ``(B, T, 3)``, local translations ``(B, T, J, 3)`` (every
joint, offsets where not animated), positions ``(B, T, J, 3)`` and global rotations
``(B, T, J, 4)`` (world), lengths ``(B,)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..align.curve import interpolate_frames, resample_motion, slerp_frames
from ..core.errors import MotionError
from ..core.motion import Motion
from ..core.skeleton import Skeleton
from ..core.fk import forward_kinematics

__all__ = ["ClipTensors", "clips_to_tensors", "resample_motion", "check_pair", "check_clip", "shift_frames", "with_fk", "without_fk"]


@dataclass
class ClipTensors:
    """A padded batch of clips on one skeleton with their FK (see the module docstring).

    ``positions`` and ``global_rotations`` are ``None`` for results whose FK nobody reads
    (the final spliced clips: callers keep local rotations and translations).
    """

    rotations: torch.Tensor
    translations: torch.Tensor
    lengths: torch.Tensor
    positions: torch.Tensor | None
    global_rotations: torch.Tensor | None

    @property
    def root_translation(self) -> torch.Tensor:
        """``(B, T, 3)`` position of joint 0."""
        return self.translations[:, :, 0]

    def _map(self, fn) -> "ClipTensors":
        """Apply ``fn`` to every per-frame tensor (skipping absent FK), keeping ``lengths``."""
        return ClipTensors(fn(self.rotations), fn(self.translations), self.lengths,
                           *(None if t is None else fn(t) for t in (self.positions, self.global_rotations)))

    def take(self, index: torch.Tensor) -> "ClipTensors":
        """Clips ``index`` ``(B',)`` of the batch (a gather, e.g. to form pairs)."""
        out = self._map(lambda t: t.index_select(0, index))
        out.lengths = self.lengths.index_select(0, index)
        return out

    def shift(self, start: torch.Tensor) -> "ClipTensors":
        """Each clip ``b`` starting at its frame ``start[b]`` (cropping the frames before)."""
        out = self._map(lambda t: shift_frames(t, start, self.lengths))
        out.lengths = self.lengths - start
        return out

    def first_frames(self, T: int) -> "ClipTensors":
        """The first ``T`` frames (lengths capped at ``T``)."""
        out = self._map(lambda t: t[:, :T])
        out.lengths = self.lengths.clamp(max=T)
        return out

    def at_times(self, times: torch.Tensor, lengths: torch.Tensor, skeleton: Skeleton) -> "ClipTensors":
        """Clips sampled at fractional frame ``times`` ``(B, T')`` (slerp and linear), with new FK."""
        rot = slerp_frames(self.rotations, times, self.lengths)
        trans = interpolate_frames(self.translations, times, self.lengths)
        return with_fk(rot, trans, lengths, skeleton)


def shift_frames(x: torch.Tensor, start: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    """``x[b, t + start[b]]`` for ``x`` ``(B, T, ...)``, repeating each clip's last frame at the end."""
    T = x.shape[1]
    idx = torch.minimum(torch.arange(T, device=x.device)[None, :] + start[:, None], (lengths - 1)[:, None])
    return torch.gather(x, 1, idx.reshape(idx.shape + (1,) * (x.dim() - 2)).expand(idx.shape + x.shape[2:]))


def without_fk(rotations: torch.Tensor, translations: torch.Tensor, lengths: torch.Tensor) -> ClipTensors:
    """:class:`ClipTensors` of local rotations and translations only (no FK computed)."""
    return ClipTensors(rotations, translations, lengths, None, None)


def with_fk(rotations: torch.Tensor, translations: torch.Tensor, lengths: torch.Tensor, skeleton: Skeleton) -> ClipTensors:
    """:class:`ClipTensors` from local rotations and translations, computing the FK."""
    pos, grot = forward_kinematics(rotations, translations[:, :, 0], skeleton.offsets.to(rotations),
                                   skeleton.parents, translations)
    return ClipTensors(rotations, translations, lengths, pos, grot)


def clips_to_tensors(motions: list[Motion], skeleton: Skeleton, dtype=torch.float32, device=None) -> ClipTensors:
    """Pad clips (already at a common frame rate) into a :class:`ClipTensors` and run FK once."""
    if not motions:
        raise ValueError("no clips")
    T = max(m.num_frames for m in motions)
    lengths = torch.tensor([m.num_frames for m in motions], device=device)

    def pad(x: torch.Tensor) -> torch.Tensor:
        x = x.to(device=device, dtype=dtype)
        return torch.cat((x, x[-1:].expand((T - x.shape[0],) + x.shape[1:])), 0) if x.shape[0] < T else x

    rot = torch.stack([pad(m.rotations) for m in motions])
    trans = torch.stack([pad(m.local_translations()) for m in motions])
    return with_fk(rot, trans, lengths, skeleton)


def check_clip(m: Motion, min_frames: int) -> None:
    """Clear errors for a clip that cannot be spliced: NaN, too short."""
    m.check_finite()
    if m.num_frames < min_frames:
        raise MotionError(f"clip {m.name!r} is too short to align: {m.num_frames} frames, at least {min_frames} needed")


def check_pair(locomotion: Motion, action: Motion) -> None:
    """A clear error for a pair whose skeletons differ."""
    why = locomotion.skeleton.mismatch(action.skeleton)
    if why is not None and not locomotion.skeleton.same_topology(action.skeleton):
        raise MotionError(f"clips {locomotion.name!r} and {action.name!r} have different skeletons: {why}")
