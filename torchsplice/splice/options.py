"""The options of every splicing method (:class:`SpliceOptions`), the time alignment's
(:class:`AlignOptions`, which :mod:`.heck` uses and re-exports), and how they map onto the
compiled kernels' arguments (:func:`bank_kwargs`, the one place that does, so that an option
cannot reach one code path and miss the other)."""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from .defaults import (DEFAULT_ACTING_LIMBS, DEFAULT_BACKEND, DEFAULT_DEVICE, DEFAULT_FORCE, DEFAULT_MAX_RUN,
                       DEFAULT_POSTURE, DEFAULT_TIMING, DEFAULT_TWIST)

__all__ = ["AlignOptions", "SpliceOptions", "bank_kwargs", "align_kwargs"]


@dataclass(frozen=True)
class AlignOptions:
    """Parameters of time alignment (defaults follow the paper where it gives them).

    Attributes:
        max_run: slope limit ``L``: at most this many consecutive frames of one clip while the
            other stands still.
        landmarks: roles whose joints form the lower-body point cloud (``root``, ``hips``,
            ``knees``, ``feet``, ``toes``); the paper uses root and knees.
        heading_window_deg: the rotation that aligns two frames must stay within this many
            degrees of their relative heading (from the hips), which tells left from right;
            ``None`` gives the paper's unrestricted metric.
        crop: crop the action's start to bring it in phase with the locomotion.
        crop_context_s: cropping compares windows of this many seconds, not single frames,
            so that a frame is not taken for its mirror half a stride later.
        crop_window_s: the local minimum for cropping must be the smallest within this many
            seconds on either side (robustness to small noise).
        knot_spacing_s: seconds of locomotion per span of the alignment B-spline.
        dp_backend: the DP's implementation in :func:`time_align` (see
            :func:`~torchsplice.align.timewarp.timewarp`; both give the same bits).
    """

    max_run: int = DEFAULT_MAX_RUN
    landmarks: tuple[str, ...] = ("root", "knees")
    heading_window_deg: float | None = 60.0
    crop: bool = True
    crop_context_s: float = 0.5
    crop_window_s: float = 0.2
    knot_spacing_s: float = 0.25
    dp_backend: str = "auto"


@dataclass(frozen=True)
class SpliceOptions:
    """Options for every method.

    Attributes:
        align: time-alignment parameters (:class:`AlignOptions`).
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
            ``"compiled"``, ``"torch"`` or a registered one (see :mod:`torchsplice.splice.backends`).
        timing: how an action that does not locomote (a standing action) fills the
            locomotion: ``"loop"`` (default), ``"hold"`` or ``"fit"`` (see
            :mod:`torchsplice.splice.standing`).
        acting_limbs: the arms standing actions act with (``None``: found per clip from the
            data; ``()``: none, only the spine and head come from the action).
    """

    align: AlignOptions = field(default_factory=AlignOptions)
    posture: bool = DEFAULT_POSTURE
    twist: float = DEFAULT_TWIST
    force: bool = DEFAULT_FORCE
    check_locomotion: bool = True
    min_seconds: float = 0.5
    dtype: torch.dtype = torch.float32
    device: str | None = DEFAULT_DEVICE
    backend: str = DEFAULT_BACKEND
    timing: str = DEFAULT_TIMING
    acting_limbs: tuple[str, ...] | None = DEFAULT_ACTING_LIMBS


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
