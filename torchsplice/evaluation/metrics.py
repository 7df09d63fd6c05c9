"""Quality metrics of clips (spliced or captured), batched over clips.

Every metric takes a padded :class:`~torchsplice.splice.clips.ClipTensors` batch (with its
frame rate ``fps``, a float or ``(B,)``) or a list of :class:`~torchsplice.core.motion.Motion`
(each at its own frame rate, which ``fps`` may confirm but never changes), and returns one value
per clip. Padding frames (beyond each clip's length) never change a clip's value. No loop runs
over frames; the only Python loops run over skeletons when a list of Motions is batched.

Conventions: positions in file units (cm for the shipped datasets), times in seconds,
quaternions WXYZ. *Heading frame* (see :mod:`torchsplice.kinematics.heading`): origin at the
pelvis joint (``roles.pelvis``), up axis along the world's up axis, lateral axis along the
floor projection of the hip vector (left hip minus right hip); for Y up the components are
x = lateral (left positive), y = up, z = forward.

Metrics:

- :func:`foot_skate`: mean horizontal speed of the feet while in ground contact (file units/s).
- :func:`arm_leg_phase`: lag of each arm's forward/back swing behind the opposite leg's, as a
  fraction of the gait cycle (0 = in phase, as in natural walking; +-0.5 = opposite).
- :func:`posture_offset` / :func:`posture_kept`: mean shoulder-midpoint offset from the pelvis
  in the heading frame, and how far a result's lies from its action's.

The upper-body error against a captured ground truth lives in
:mod:`torchsplice.evaluation.ground_truth` (:func:`~torchsplice.evaluation.ground_truth.upper_body_error`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Union

import torch

from ..core.motion import Motion
from ..specs import SkeletonRoles
from ..kinematics.contacts import floor_speed, foot_contacts
from ..kinematics.heading import heading_points, third_axis
from ..splice.clips import ClipTensors, clips_to_tensors

__all__ = [
    "Clips", "SKATE_HEIGHT_RATIO", "SKATE_SPEED_RATIO", "MIN_PERIOD_S", "MAX_PERIOD_S", "FootSkate", "ArmLegPhase",
    "foot_skate", "foot_skate_stats", "gait_period", "arm_leg_phase", "arm_leg_phase_stats",
    "phase_range", "posture_offset", "posture_kept", "leg_length",
]

Clips = Union[ClipTensors, Sequence[Motion]]
"""A padded batch with its ``fps``, or a list of Motions (each at its own frame rate)."""

SKATE_HEIGHT_RATIO = 0.05
"""A foot point counts as on the ground within this many leg lengths of its lowest height
(about 4 cm for an 85 cm leg): stricter than the splice's contact detection (0.12), so that
an ankle rising through heel-off (rolling about the ball, not skating) is left out."""
SKATE_SPEED_RATIO = 0.3
"""... and when slower than this many leg lengths per second (about 26 cm/s): faster sliding
reads as lost contact, so a clip that skates worse shows as a lower contact fraction."""

MIN_PERIOD_S = 0.5
"""Shortest gait cycle searched for (s): a fast run's cycle is about 0.6 s."""
MAX_PERIOD_S = 2.5
"""Longest gait cycle searched for (s): a very slow walk's cycle is about 2 s."""


# --------------------------------------------------------------------------------------------
# batching
# --------------------------------------------------------------------------------------------
@dataclass
class _Batch:
    """Joint positions ``(B, T, J, 3)``, valid frames ``lengths`` ``(B,)``, ``fps`` ``(B,)``."""

    positions: torch.Tensor
    lengths: torch.Tensor
    fps: torch.Tensor

    @property
    def valid(self) -> torch.Tensor:
        """``(B, T)`` bool, True on each clip's real frames."""
        T = self.positions.shape[1]
        return torch.arange(T, device=self.positions.device)[None, :] < self.lengths[:, None]


def _pad_frames(x: torch.Tensor, T: int) -> torch.Tensor:
    """``x`` ``(B, t, ...)`` padded to ``T`` frames by repeating its last frame."""
    return torch.cat((x, x[:, -1:].expand((x.shape[0], T - x.shape[1]) + x.shape[2:])), 1) if x.shape[1] < T else x


def _batch(clips: Clips, fps=None, need_fps: bool = True, dtype=torch.float64) -> _Batch:
    """Positions, lengths and frame rates of ``clips`` (see :data:`Clips`); a list of Motions
    is batched in ``dtype``. Without ``need_fps`` a ClipTensors batch may come without ``fps``
    (its ``fps`` is then NaN)."""
    if isinstance(clips, ClipTensors):
        if fps is None and need_fps:
            raise ValueError("fps is required with ClipTensors")
        p = clips.positions
        rate = torch.as_tensor(float("nan") if fps is None else fps, dtype=p.dtype, device=p.device)
        return _Batch(p, clips.lengths.to(p.device), rate.expand(p.shape[0]).clone())
    clips = list(clips)
    if not clips:
        raise ValueError("no clips")
    if fps is not None and any(abs(m.fps - float(fps)) > 1e-6 * m.fps for m in clips):
        raise ValueError(f"fps={fps} given, but the clips' frame rates are {sorted({m.fps for m in clips})}")
    groups: dict[int, list[int]] = {}
    for i, m in enumerate(clips):  # one FK per skeleton object
        groups.setdefault(id(m.skeleton), []).append(i)
    T = max(m.num_frames for m in clips)
    parts = {}
    for idx in groups.values():
        ct = clips_to_tensors([clips[i] for i in idx], clips[idx[0]].skeleton, dtype=dtype, device=clips[0].device)
        for k, i in enumerate(idx):
            parts[i] = ct.positions[k : k + 1]
    pos = torch.cat([_pad_frames(parts[i], T) for i in range(len(clips))])
    lengths = torch.tensor([m.num_frames for m in clips], device=pos.device)
    return _Batch(pos, lengths, torch.tensor([float(m.fps) for m in clips], dtype=dtype, device=pos.device))


def _masked_mean(x: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Mean of ``x`` ``(B, T, ...)`` over the frames where ``valid`` ``(B, T)``: ``(B, ...)``."""
    w = valid.reshape(valid.shape + (1,) * (x.dim() - 2)).to(x.dtype)
    return (x * w).sum(1) / w.sum(1).clamp_min(1)


def leg_length(positions: torch.Tensor, roles: SkeletonRoles) -> torch.Tensor:
    """``(B,)`` leg length (file units): hip-knee plus knee-ankle bone, first frame, mean of sides.

    Pose-independent for rigid bones (unlike the hip-ankle distance, which shrinks as the knee bends).
    """
    p = positions[:, 0]
    hip, knee, foot = (p[:, list(j)] for j in (roles.hips, roles.knees, roles.feet))
    return ((hip - knee).norm(dim=-1) + (knee - foot).norm(dim=-1)).mean(-1)


def _heading_points(positions: torch.Tensor, roles: SkeletonRoles, joints) -> torch.Tensor:
    """``(B, T, K, 3)`` joints ``joints`` in the pelvis-centred heading frame of each frame."""
    return heading_points(positions, roles.hips, roles.pelvis, joints, roles.up_axis)[1]


def _forward_axis(up_axis: int) -> int:
    """Index of the heading frame's forward axis (z for Y up)."""
    return third_axis(up_axis)


# --------------------------------------------------------------------------------------------
# foot skate
# --------------------------------------------------------------------------------------------
@dataclass
class FootSkate:
    """Foot skate of ``B`` clips.

    Attributes:
        speed: ``(B,)`` mean horizontal speed (file units per second) of the foot points over
            their contact frames; 0 where a clip has no contact frame (see ``contact_frames``).
        contact_fraction: ``(B,)`` contact frames / (valid frames x foot points), in [0, 1].
        contact_frames: ``(B,)`` int, (point, frame) pairs in contact.
        joints: the foot points used (joint indices): the ankles, and the toes when the roles
            name them.
    """

    speed: torch.Tensor
    contact_fraction: torch.Tensor
    contact_frames: torch.Tensor
    joints: tuple[int, ...]


def foot_skate_stats(clips: Clips, roles: SkeletonRoles, fps=None, height_ratio: float = SKATE_HEIGHT_RATIO,
                     speed_ratio: float = SKATE_SPEED_RATIO) -> FootSkate:
    """Foot skate of each clip, with its contact statistics (:class:`FootSkate`).

    Foot points are the ankles (``roles.feet``) and, when the roles have them, the toes
    (``roles.toes``); each point's contacts come from
    :func:`~torchsplice.kinematics.contacts.foot_contacts` with the clip's :func:`leg_length`:
    within ``height_ratio`` leg lengths of the point's lowest height in the clip, and slower
    than ``speed_ratio`` leg lengths per second (see :data:`SKATE_HEIGHT_RATIO` and
    :data:`SKATE_SPEED_RATIO`). Speeds are floor-plane speeds by central differences (one-sided
    at a clip's ends). Invariant under translations of the clip and rotations about the up axis.
    A clip with no contact frame gets speed 0 and ``contact_frames`` 0 (never NaN).
    """
    b = _batch(clips, fps)
    joints = tuple(roles.feet) + (tuple(roles.toes) if roles.toes is not None else ())
    pts = b.positions[:, :, list(joints)]
    leg = leg_length(b.positions, roles)
    contact = foot_contacts(pts, b.lengths, b.fps, leg, roles.up_axis, height_ratio, speed_ratio)
    speed = floor_speed(pts, b.fps, roles.up_axis, b.lengths)
    n = contact.sum((1, 2))
    total = (speed * contact).sum((1, 2)) / n.clamp_min(1)
    frac = n.to(pts.dtype) / (b.lengths.to(pts.dtype) * len(joints))
    return FootSkate(total, frac, n, joints)


def foot_skate(clips: Clips, roles: SkeletonRoles, fps=None) -> torch.Tensor:
    """``(B,)`` mean horizontal foot speed in contact, file units per second (see :func:`foot_skate_stats`)."""
    return foot_skate_stats(clips, roles, fps).speed


# --------------------------------------------------------------------------------------------
# gait period and arm-leg phase
# --------------------------------------------------------------------------------------------
def _centred(x: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """``x`` ``(B, T, ...)`` minus its mean over valid frames, zero on padding."""
    w = valid.reshape(valid.shape + (1,) * (x.dim() - 2))
    return torch.where(w, x - _masked_mean(x, valid)[:, None], torch.zeros_like(x))


def _correlation(x: torch.Tensor, y: torch.Tensor, lengths: torch.Tensor, max_lag: int) -> torch.Tensor:
    """Normalised cross-correlation ``(B, 2 * max_lag + 1, ...)`` of zero-padded signals.

    ``x``, ``y`` ``(B, T, ...)`` are centred and zero beyond each clip's length. Entry
    ``max_lag + k`` is ``sum_t x[t + k] y[t] / (n - |k|)`` divided by the signals' RMS
    (``n`` the clip's length): near 1 where ``x`` repeats ``y`` ``k`` frames later.
    """
    T = x.shape[1]
    n = 1 << (2 * T - 1).bit_length()
    X = torch.fft.rfft(x, n=n, dim=1)
    Y = torch.fft.rfft(y, n=n, dim=1)
    full = torch.fft.irfft(X * Y.conj(), n=n, dim=1)  # full[k] = sum_t x[t + k] y[t] (k mod n)
    lags = torch.arange(-max_lag, max_lag + 1, device=x.device)
    r = full.index_select(1, lags % n)
    shape = (-1, lags.numel()) + (1,) * (x.dim() - 2)
    overlap = (lengths[:, None] - lags.abs()[None, :]).clamp_min(1).to(x.dtype).reshape(shape)
    rms = ((x * x).sum(1) * (y * y).sum(1)).sqrt() / lengths.to(x.dtype).reshape((-1,) + (1,) * (x.dim() - 2))
    return r / overlap / rms.clamp_min(1e-12)[:, None]


def _refine(values: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """Sub-sample peak position: ``index`` ``(B, ...)`` into dim 1 of ``values`` plus a parabola's
    offset through its two neighbours (clamped to +-0.5; none at the ends)."""
    K = values.shape[1]
    i = index.clamp(1, K - 2)
    g = lambda j: values.gather(1, j.unsqueeze(1)).squeeze(1)  # noqa: E731
    a, c, e = g(i - 1), g(i), g(i + 1)
    den = a - 2 * c + e
    off = torch.where(den < 0, 0.5 * (a - e) / den.where(den < 0, torch.ones_like(den)), torch.zeros_like(den))
    inside = (index >= 1) & (index <= K - 2)
    return index.to(values.dtype) + torch.where(inside, off.clamp(-0.5, 0.5), torch.zeros_like(off))


def _forward_offsets(b: _Batch, roles: SkeletonRoles) -> tuple[torch.Tensor, torch.Tensor]:
    """Forward offsets from the pelvis ``(B, T, 2)`` of the (left, right) hands and feet."""
    arms = roles.hands if roles.hands is not None else roles.shoulders
    h = _heading_points(b.positions, roles, tuple(arms) + tuple(roles.feet))[..., _forward_axis(roles.up_axis)]
    return h[..., :2], h[..., 2:]


def _period_frames(feet: torch.Tensor, b: _Batch) -> torch.Tensor:
    """``(B,)`` gait cycle in frames (NaN if none found) from the feet's forward offsets ``(B, T, 2)``."""
    d = _centred(feet[..., 0] - feet[..., 1], b.valid)  # left minus right: one cycle per period
    max_lag = int(min(float((MAX_PERIOD_S * b.fps).max()), b.positions.shape[1] - 1))
    r = _correlation(d, d, b.lengths, max_lag)[:, max_lag:]  # lags 0..max_lag
    k = torch.arange(r.shape[1], device=r.device)[None, :]
    usable = (k >= MIN_PERIOD_S * b.fps[:, None]) & (k <= MAX_PERIOD_S * b.fps[:, None]) & (3 * k <= 2 * b.lengths[:, None])
    peak = torch.zeros_like(usable)
    peak[:, 1:-1] = (r[:, 1:-1] >= r[:, :-2]) & (r[:, 1:-1] > r[:, 2:])
    good = usable & peak & (r > 0.3)
    first = torch.where(good, k, torch.full_like(k, r.shape[1])).min(1).values
    found = first < r.shape[1]
    period = _refine(r, first.clamp(max=r.shape[1] - 1))
    return torch.where(found, period, torch.full_like(period, float("nan")))


def gait_period(clips: Clips, roles: SkeletonRoles, fps=None) -> torch.Tensor:
    """``(B,)`` gait cycle (two steps) in seconds; NaN where none is found.

    The first autocorrelation peak (correlation > 0.3, between :data:`MIN_PERIOD_S` and
    :data:`MAX_PERIOD_S`, and at most 2/3 of the clip) of the left foot's forward offset minus
    the right foot's, in the pelvis-centred heading frame.
    """
    b = _batch(clips, fps)
    return _period_frames(_forward_offsets(b, roles)[1], b) / b.fps


@dataclass
class ArmLegPhase:
    """Arm-leg coordination of ``B`` clips; lags are fractions of the gait cycle in [-0.5, 0.5).

    Attributes:
        lag: ``(B,)`` circular mean of the two sides' lags.
        left, right: ``(B,)`` lag of the left arm behind the right leg, of the right arm behind
            the left leg: positive when the arm reaches the leg's phase later.
        correlation: ``(B, 2)`` the normalised cross-correlation at each side's lag (near 1
            for a clean periodic swing; low values mean the arm hardly swings).
        period: ``(B,)`` the gait cycle in seconds (:func:`gait_period`).
    """

    lag: torch.Tensor
    left: torch.Tensor
    right: torch.Tensor
    correlation: torch.Tensor
    period: torch.Tensor


def arm_leg_phase_stats(clips: Clips, roles: SkeletonRoles, fps=None) -> ArmLegPhase:
    """Lag of each arm's swing behind the opposite leg's (:class:`ArmLegPhase`).

    Signals: the forward offset from the pelvis, in the heading frame, of each hand
    (``roles.hands``; the shoulders when the roles have no hands) and of each ankle, centred
    over the clip. The lag is the peak of their normalised cross-correlation within
    +-0.6 gait cycles (sub-frame by a parabola), divided by the cycle and wrapped to
    [-0.5, 0.5). In natural walking the left arm swings forward with the right leg: lag near 0.
    NaN where no gait cycle is found (too short or not walking).
    """
    b = _batch(clips, fps)
    arms, feet = _forward_offsets(b, roles)
    period = _period_frames(feet, b)
    max_lag = int(min(float((0.6 * MAX_PERIOD_S * b.fps).max()), b.positions.shape[1] - 1))
    arm = _centred(arms, b.valid)
    leg = _centred(feet.flip(-1), b.valid)  # opposite leg: (right, left)
    r = _correlation(arm, leg, b.lengths, max_lag)  # (B, K, 2)
    lags = torch.arange(-max_lag, max_lag + 1, device=r.device, dtype=r.dtype)[None, :, None]
    span = 0.6 * torch.nan_to_num(period, nan=0.0)[:, None, None]
    best = torch.where(lags.abs() <= span, r, torch.full_like(r, -math.inf)).argmax(1)
    frac = (_refine(r, best) - max_lag) / period[:, None]
    frac = torch.remainder(frac + 0.5, 1.0) - 0.5
    ang = 2 * math.pi * frac
    mean = torch.atan2(ang.sin().sum(-1), ang.cos().sum(-1)) / (2 * math.pi)
    mean = torch.remainder(mean + 0.5, 1.0) - 0.5
    corr = r.gather(1, best.unsqueeze(1)).squeeze(1)
    return ArmLegPhase(mean, frac[:, 0], frac[:, 1], corr, period / b.fps)


def arm_leg_phase(clips: Clips, roles: SkeletonRoles, fps=None) -> torch.Tensor:
    """``(B,)`` arm-leg lag in gait cycles, mean of both sides (see :func:`arm_leg_phase_stats`)."""
    return arm_leg_phase_stats(clips, roles, fps).lag


def phase_range(captured: Clips, roles: SkeletonRoles, fps=None, margin: float = 0.0) -> tuple[float, float]:
    """``(low, high)``: the range of :func:`arm_leg_phase` over captured walks, widened by
    ``margin`` cycles on each side; clips without a gait cycle (NaN) are left out.

    A result's lag lies in the captured range when ``low <= lag <= high``.
    """
    lag = arm_leg_phase(captured, roles, fps)
    lag = lag[~lag.isnan()]
    if lag.numel() == 0:
        raise ValueError("no captured clip has a gait cycle")
    return float(lag.min()) - margin, float(lag.max()) + margin


# --------------------------------------------------------------------------------------------
# posture
# --------------------------------------------------------------------------------------------
def posture_offset(clips: Clips, roles: SkeletonRoles) -> torch.Tensor:
    """``(B, 3)`` mean offset of the shoulder midpoint from the pelvis, in the heading frame.

    File units; components in heading-frame order (Y up: x lateral, left positive; y up;
    z forward), averaged over each clip's frames. A backward lean gives a smaller z.
    """
    b = _batch(clips, need_fps=False)
    mid = _heading_points(b.positions, roles, roles.shoulders).mean(2)
    return _masked_mean(mid, b.valid)


def posture_kept(results: Clips, actions: Clips, roles: SkeletonRoles) -> torch.Tensor:
    """``(B,)`` distance (file units) between each result's :func:`posture_offset` and its action's.

    Results and actions are paired by position. Small means the action's posture (e.g. a
    backward lean while carrying a box) survived the splice.
    """
    return (posture_offset(results, roles) - posture_offset(actions, roles)).norm(dim=-1)
