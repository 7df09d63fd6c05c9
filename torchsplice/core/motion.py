"""A motion clip: a skeleton plus per-frame local joint rotations and translations.

Shapes (``T`` frames, ``J`` joints, any float dtype, one device):

- ``rotations``: ``(T, J, 4)`` local joint rotations, unit quaternions, **WXYZ**; joint ``j``'s
  rotation maps vectors from its own frame to its parent's frame.
- ``root_translation``: ``(T, 3)`` the root joint's (joint 0's) position in the world, file units.
- ``translations``: ``(T, J, 3)`` or ``None``: every joint's local translation in its parent's
  frame, present when the BVH file animates the translation of a non-root joint (Bandai Namco
  animates every joint). Joints whose translation is not animated hold their rest offset;
  row 0 is ignored in favour of ``root_translation``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import torch

from .errors import MotionError
from .fk import forward_kinematics
from .skeleton import Skeleton

__all__ = ["Motion"]


@dataclass(eq=False)
class Motion:
    """One clip on one skeleton (see the module docstring for shapes and conventions).

    Attributes:
        skeleton: the :class:`Skeleton` the clip is animated on.
        rotations: ``(T, J, 4)`` local rotations, unit quaternions, WXYZ.
        root_translation: ``(T, 3)`` world position of joint 0.
        fps: frames per second.
        translations: ``(T, J, 3)`` local joint translations, or ``None`` (offsets are used).
        name: the clip's name (a file's stem by default).
        source: where it came from (a file path), for provenance.
        role: ``"locomotion"``, ``"action"``, ``"both"``, ``"spliced"`` or ``""`` (unknown).
        labels: free-form string labels, e.g. ``{"content": "walk", "style": "proud"}``.
    """

    skeleton: Skeleton
    rotations: torch.Tensor
    root_translation: torch.Tensor
    fps: float
    translations: torch.Tensor | None = None
    name: str = ""
    source: str = ""
    role: str = ""
    labels: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        J = self.skeleton.num_joints
        T = self.rotations.shape[0] if self.rotations.dim() == 3 else -1
        if self.rotations.shape != (T, J, 4):
            raise MotionError(f"clip {self.name!r}: rotations must be (T, {J}, 4), got {tuple(self.rotations.shape)}")
        if self.root_translation.shape != (T, 3):
            raise MotionError(
                f"clip {self.name!r}: root_translation must be ({T}, 3), got {tuple(self.root_translation.shape)}"
            )
        if self.translations is not None and self.translations.shape != (T, J, 3):
            raise MotionError(
                f"clip {self.name!r}: translations must be ({T}, {J}, 3), got {tuple(self.translations.shape)}"
            )
        if not self.fps > 0:
            raise MotionError(f"clip {self.name!r}: fps must be positive, got {self.fps}")
        self.fps = float(self.fps)

    @property
    def num_frames(self) -> int:
        """Number of frames ``T``."""
        return self.rotations.shape[0]

    @property
    def duration(self) -> float:
        """Length in seconds, ``T / fps``."""
        return self.num_frames / self.fps

    @property
    def dtype(self) -> torch.dtype:
        return self.rotations.dtype

    @property
    def device(self) -> torch.device:
        return self.rotations.device

    def local_translations(self) -> torch.Tensor:
        """``(T, J, 3)`` local translation of every joint, root included (root row = root_translation)."""
        if self.translations is not None:
            t = self.translations.clone()
        else:
            t = self.skeleton.offsets.to(self.rotations).expand(self.num_frames, -1, -1).clone()
        t[:, 0] = self.root_translation
        return t

    def to(self, *args, **kwargs) -> "Motion":
        """A copy with every tensor moved or cast as by ``Tensor.to`` (e.g. ``torch.float64``, ``"cuda"``)."""
        return replace(
            self,
            rotations=self.rotations.to(*args, **kwargs),
            root_translation=self.root_translation.to(*args, **kwargs),
            translations=None if self.translations is None else self.translations.to(*args, **kwargs),
            labels=dict(self.labels),
        )

    def slice(self, start: int, stop: int) -> "Motion":
        """Frames ``start:stop`` as a new clip (views, no copy)."""
        return replace(
            self,
            rotations=self.rotations[start:stop],
            root_translation=self.root_translation[start:stop],
            translations=None if self.translations is None else self.translations[start:stop],
            labels=dict(self.labels),
        )

    def window_starts(self, seconds: float, overlap: float = 0.0) -> list[int]:
        """First frames of the windows :meth:`windows` cuts (``[0]`` for a clip that fits in one)."""
        if not seconds > 0 or not 0 <= overlap < seconds:
            raise ValueError(f"windows need seconds > 0 and 0 <= overlap < seconds, got {seconds} and {overlap}")
        n, T = max(2, int(round(seconds * self.fps))), self.num_frames
        if T <= n * 1.25:  # a take a little longer than a window stays whole
            return [0]
        step = max(1, n - int(round(overlap * self.fps)))
        starts = list(range(0, T - n + 1, step))
        if starts[-1] != T - n:
            starts.append(T - n)  # the last window ends with the take (it overlaps its neighbour more)
        return starts

    def windows(self, seconds: float, overlap: float = 0.0) -> list["Motion"]:
        """The clip cut into windows of ``seconds`` that overlap by ``overlap`` seconds.

        Windows are named ``NAME#k`` (k = 0, 1, ...; three digits) and carry the clip's labels plus
        ``split_from`` (the clip's name) and ``split_frame`` (the window's first frame in the take). The
        last window ends with the take; a clip no longer than 1.25 windows is returned whole,
        unchanged. Views, no copy.
        """
        starts = self.window_starts(seconds, overlap)
        if starts == [0]:
            return [self]
        n = max(2, int(round(seconds * self.fps)))
        out = []
        for k, s in enumerate(starts):
            w = self.slice(s, s + n)
            out.append(
                replace(
                    w,
                    name=f"{self.name}#{k:03d}",
                    labels={**self.labels, "split_from": self.name, "split_frame": str(s)},
                )
            )
        return out

    def check_finite(self) -> "Motion":
        """Raise :class:`MotionError` naming the clip and frame if any value is NaN or infinite."""
        for what, t in (
            ("rotation", self.rotations),
            ("root translation", self.root_translation),
            ("translation", self.translations),
        ):
            if t is None:
                continue
            bad = ~torch.isfinite(t.reshape(t.shape[0], -1)).all(dim=1)
            if bool(bad.any()):
                f = int(bad.nonzero()[0])
                raise MotionError(f"clip {self.name!r}: non-finite {what} value at frame {f}")
        return self

    def global_positions(self) -> torch.Tensor:
        """``(T, J, 3)`` world positions of the joints, by forward kinematics."""
        pos, _ = forward_kinematics(
            self.rotations,
            self.root_translation,
            self.skeleton.offsets.to(self.rotations),
            self.skeleton.parents,
            self.translations,
        )
        return pos

    def __repr__(self) -> str:
        return (
            f"Motion({self.name!r}, {self.num_frames} frames at {self.fps:g} fps, "
            f"{self.skeleton.num_joints} joints, role={self.role!r})"
        )
