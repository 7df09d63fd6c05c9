"""The built-in sample: procedurally generated walking clips on a standard humanoid skeleton.

A newcomer's first run needs motion without downloads; this module makes it. Every clip is
generated from a handful of gait and path parameters, deterministically (fixed seeds; the same
output on every call), and vectorised over frames with numpy (the only Python loops run over
joints, feet and clips).

Longer than 600 lines because the skeleton, the gait, the arm swing and each of the sample's
actions are written out here, one after another, and read best as one procedure.

Conventions:

- **Y up, centimetres**, the floor is ``y = 0``; the character faces **+Z** at frame 0 and its
  left is **+X**. Every clip starts at the origin.
- Rotations are unit quaternions in **WXYZ** order (scalar first), local to the parent joint,
  continuous in time (no sign flips between frames).
- 30 frames per second.

The skeleton (:func:`sample_skeleton`) is a 22-joint human, about 175 cm tall, whose rest
pose stands upright with the **arms hanging straight down** and every joint's local axes
aligned with the world (X left, Y up, Z forward). Consequences used throughout: a joint's
rotation about its local X axis pitches the bone below it forward or back (negative X swings
an arm forward and flexes an elbow; positive X flexes a knee and lifts a heel); rotation about
Z raises the arms sideways (positive Z for the left arm, negative for the right).

How the clips are made (:func:`sample_motions`):

1. A ground path (position and heading, integrated from a speed and a turn rate on a fine
   time grid) and a gait cycle coordinate ``c(t)`` (one unit = one gait cycle = two steps;
   the left foot strikes the ground at integer ``c``, the right at half-integers).
2. Foot plants: each stance of each foot gets one fixed ground position beside the path,
   taken where the pelvis passes over it. During stance the foot rolls heel - flat - toe
   (heel rocker, planted ankle, heel-off pivoting about the ball), so the ankle is exactly
   still through flat foot; during swing it follows a smooth arc to the next plant.
3. The pelvis follows the path with sway, transverse twist, list and tilt; its height is a
   nominal bob softly clipped (smooth minimum) to what both legs can reach, then smoothed
   from below (never higher than the legs allow), so it dips in double support as real
   walkers do.
4. Analytic two-bone IK puts each hip-knee-ankle chain onto its foot target, the knee
   pointing along the foot; the foot and toe take the rolled foot orientation.
5. The upper body: spine counter-rotation against the pelvis (thorax twist opposite the
   pelvis, so each arm swings forward with the opposite leg), a per-clip trunk lean, the head
   looking into turns, and the arms either swinging or doing the clip's action.

Every joint's rotation keeps its middle BVH Euler angle (X, of the ``Zrotation Xrotation
Yrotation`` channels) under about 82 degrees: knees and elbows flex about X, and beyond 90
the Euler channels of a written BVH file would flip through gimbal lock. So the jog's knees
bend a little less than a real jogger's, and the punch's guard (elbows past 90) turns each
upper arm 90 degrees about its length so that the elbow hinges about its local Z instead.

Clips (name: role): ``walk_straight``, ``walk_curve``, ``turn_sharp``, ``sidestep``, ``jog``
(locomotion); ``carry_box``, ``carry_cup``, ``wave``, ``punch``, ``arms_out`` (actions,
performed while walking, so their lower bodies are real locomotion too). Gait parameters
(stride, cadence, phase at frame 0, slow cadence wobble) differ per clip, so that time
alignment has something to do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from ..core.motion import Motion
from ..core.rotations import rotmat_to_quat
from ..core.skeleton import Skeleton

__all__ = [
    "SAMPLE_FPS",
    "SAMPLE_SOURCE",
    "SAMPLE_CLIPS",
    "sample_skeleton",
    "sample_motions",
    "sample_motion",
]

SAMPLE_FPS = 30.0
"""Frame rate of every sample clip."""

SAMPLE_SOURCE = "torchsplice.sample"
"""The ``source`` every sample clip carries."""

# ---------------------------------------------------------------------------------------------
# Skeleton
# ---------------------------------------------------------------------------------------------

_ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
_JOINT_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")

# name, parent, offset in the parent's frame (cm). Rest pose: standing, arms straight down.
_JOINTS: tuple[tuple[str, str | None, tuple[float, float, float]], ...] = (
    ("Hips", None, (0.0, 98.0, 0.0)),
    ("LeftUpLeg", "Hips", (9.0, -5.0, 0.0)),
    ("LeftLeg", "LeftUpLeg", (0.0, -44.0, 0.0)),
    ("LeftFoot", "LeftLeg", (0.0, -42.0, 0.0)),
    ("LeftToe", "LeftFoot", (0.0, -4.0, 13.0)),
    ("RightUpLeg", "Hips", (-9.0, -5.0, 0.0)),
    ("RightLeg", "RightUpLeg", (0.0, -44.0, 0.0)),
    ("RightFoot", "RightLeg", (0.0, -42.0, 0.0)),
    ("RightToe", "RightFoot", (0.0, -4.0, 13.0)),
    ("Spine", "Hips", (0.0, 8.0, 0.0)),
    ("Spine1", "Spine", (0.0, 12.0, 0.0)),
    ("Spine2", "Spine1", (0.0, 12.0, 0.0)),
    ("Neck", "Spine2", (0.0, 16.0, 0.0)),
    ("Head", "Neck", (0.0, 10.0, 0.0)),
    ("LeftShoulder", "Spine2", (3.0, 12.0, 0.0)),
    ("LeftArm", "LeftShoulder", (15.0, 0.0, 0.0)),
    ("LeftForeArm", "LeftArm", (0.0, -30.0, 0.0)),
    ("LeftHand", "LeftForeArm", (0.0, -26.0, 0.0)),
    ("RightShoulder", "Spine2", (-3.0, 12.0, 0.0)),
    ("RightArm", "RightShoulder", (-15.0, 0.0, 0.0)),
    ("RightForeArm", "RightArm", (0.0, -30.0, 0.0)),
    ("RightHand", "RightForeArm", (0.0, -26.0, 0.0)),
)
# End sites: toe tips, top of the head, fingertips (in the parent joint's frame, cm).
_END_SITES: tuple[tuple[str, tuple[float, float, float]], ...] = (
    ("LeftToe", (0.0, 0.0, 6.0)),
    ("RightToe", (0.0, 0.0, 6.0)),
    ("Head", (0.0, 19.0, 0.0)),
    ("LeftHand", (0.0, -18.0, 0.0)),
    ("RightHand", (0.0, -18.0, 0.0)),
)
_NAMES = tuple(j[0] for j in _JOINTS)
_J = {n: i for i, n in enumerate(_NAMES)}

# Leg geometry (cm), read off the table above.
_THIGH = 44.0
_SHIN = 42.0
_HIP_OFFSET = {0: np.array([9.0, -5.0, 0.0]), 1: np.array([-9.0, -5.0, 0.0])}  # left, right
_ANKLE_HEIGHT = 7.0  # ankle above the floor with the foot flat (98 - 5 - 44 - 42)
_BALL = np.array([0.0, -4.0, 13.0])  # ball of the foot (the toe joint) in the foot frame
_HEEL = np.array([0.0, -_ANKLE_HEIGHT, -4.0])  # heel contact point in the foot frame
_REACH = 0.997 * (_THIGH + _SHIN)  # the pelvis never rises so high that a leg exceeds this


def sample_skeleton() -> Skeleton:
    """The sample's 22-joint human skeleton (Y up, cm, facing +Z, about 175 cm tall).

    Rest pose: standing upright, arms hanging straight down at the sides, every joint's local
    axes aligned with the world (X left, Y up, Z forward); the root ``Hips`` rests 98 cm above
    the floor, the ankles 7 cm, the top of the head (an end site) at 175 cm.

    Joints, in topological order: ``Hips``; ``LeftUpLeg LeftLeg LeftFoot LeftToe``;
    ``RightUpLeg RightLeg RightFoot RightToe``; ``Spine Spine1 Spine2 Neck Head``;
    ``LeftShoulder LeftArm LeftForeArm LeftHand``; ``RightShoulder RightArm RightForeArm
    RightHand``. ``Hips`` has the channels ``Xposition Yposition Zposition Zrotation Xrotation
    Yrotation``, every other joint ``Zrotation Xrotation Yrotation``. End sites hang from the
    toes, the head and the hands (one per leaf joint).

    Returns:
        A new :class:`Skeleton` (offsets ``(22, 3)`` float64, end-site offsets ``(5, 3)``).
    """
    names = _NAMES
    parents = tuple(-1 if p is None else _J[p] for _, p, _ in _JOINTS)
    offsets = torch.tensor([o for _, _, o in _JOINTS], dtype=torch.float64)
    channels = tuple(_ROOT_CHANNELS if p is None else _JOINT_CHANNELS for _, p, _ in _JOINTS)
    ends = sorted(_END_SITES, key=lambda e: _J[e[0]])
    return Skeleton(
        names=names,
        parents=parents,
        offsets=offsets,
        channels=channels,
        end_site_parents=tuple(_J[n] for n, _ in ends),
        end_site_offsets=torch.tensor([o for _, o in ends], dtype=torch.float64),
    )


# ---------------------------------------------------------------------------------------------
# Small numpy helpers (float64). Angles in degrees unless a name says radians.
# ---------------------------------------------------------------------------------------------


def _rx(deg) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` about X by ``deg`` degrees (array ``(...)``)."""
    a = np.radians(np.asarray(deg, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    m[..., 0, 0] = 1.0
    m[..., 1, 1], m[..., 1, 2], m[..., 2, 1], m[..., 2, 2] = c, -s, s, c
    return m


def _ry(deg) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` about Y (up) by ``deg`` degrees; +Z turns toward +X."""
    a = np.radians(np.asarray(deg, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    m[..., 1, 1] = 1.0
    m[..., 0, 0], m[..., 0, 2], m[..., 2, 0], m[..., 2, 2] = c, s, -s, c
    return m


def _rz(deg) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` about Z by ``deg`` degrees; +Y turns toward -X."""
    a = np.radians(np.asarray(deg, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    m[..., 2, 2] = 1.0
    m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1] = c, -s, s, c
    return m


def _apply(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors: ``(..., 3, 3)`` matrices times broadcastable ``(..., 3)`` vectors."""
    return np.einsum("...ij,...j->...i", m, v)


def _tr(m: np.ndarray) -> np.ndarray:
    """Transpose (inverse) of ``(..., 3, 3)`` rotation matrices."""
    return np.swapaxes(m, -1, -2)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    """Cubic ease ``3x^2 - 2x^3`` of ``x`` clipped to [0, 1] (zero slope at both ends)."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _minjerk(x: np.ndarray) -> np.ndarray:
    """Minimum-jerk ease ``10x^3 - 15x^4 + 6x^5`` of ``x`` clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10.0 + x * (-15.0 + 6.0 * x))


def _cumtrapz(y: np.ndarray, dt: float) -> np.ndarray:
    """Cumulative trapezoidal integral of samples ``y`` ``(N, ...)`` spaced ``dt``, starting at 0."""
    out = np.zeros_like(y)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * dt, axis=0)
    return out


def _smooth_below(y: np.ndarray, radius: int) -> np.ndarray:
    """A smooth curve ``(T,)`` that never exceeds ``y`` ``(T,)``.

    A running minimum over ``2 * radius + 1`` samples, then a Hann-window average of the same
    width: each output averages values that are each at most the input at that sample, so
    ``out <= y`` everywhere, while short dips become wide smooth ones.
    """
    pad = np.pad(y, radius, mode="edge")
    low = np.lib.stride_tricks.sliding_window_view(pad, 2 * radius + 1).min(-1)
    kernel = np.hanning(2 * radius + 3)[1:-1]
    kernel /= kernel.sum()
    return np.convolve(np.pad(low, radius, mode="edge"), kernel, mode="valid")


def _interp(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """``np.interp`` applied to every column of ``fp`` ``(N,)`` or ``(N, C)``; ``x`` any shape."""
    if fp.ndim == 1:
        return np.interp(x, xp, fp)
    return np.stack([np.interp(x, xp, fp[:, k]) for k in range(fp.shape[1])], axis=-1)


def _noise(rng: np.random.Generator, t: np.ndarray, amp: float, n: int = 3) -> np.ndarray:
    """Smooth pseudo-random signal ``(T,)`` of RMS about ``amp``: ``n`` slow sinusoids (0.15-0.8 Hz)."""
    freq = rng.uniform(0.15, 0.8, n)
    phase = rng.uniform(0.0, 2.0 * math.pi, n)
    weight = rng.uniform(0.5, 1.0, n)
    weight *= amp * math.sqrt(2.0) / np.sqrt((weight**2).sum())
    return (weight * np.sin(2.0 * math.pi * freq * t[:, None] + phase)).sum(-1)


def _forward(theta_deg: np.ndarray) -> np.ndarray:
    """Horizontal unit forward vectors ``(..., 3)`` for headings in degrees (0 = +Z)."""
    a = np.radians(theta_deg)
    return np.stack((np.sin(a), np.zeros_like(a), np.cos(a)), axis=-1)


def _left(theta_deg: np.ndarray) -> np.ndarray:
    """Horizontal unit left vectors ``(..., 3)`` for headings in degrees (0 = +X)."""
    a = np.radians(theta_deg)
    return np.stack((np.cos(a), np.zeros_like(a), -np.sin(a)), axis=-1)


# ---------------------------------------------------------------------------------------------
# Clip parameters
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Gait:
    """Lower-body parameters of one clip (cm, seconds, degrees; phases in gait cycles)."""

    speed: float  # mean speed along the path, cm/s
    cadence: float  # gait cycles (two steps) per second
    phase0: float  # cycle coordinate at frame 0, [0, 1)
    stance: float = 0.62  # fraction of the cycle a foot is on the ground
    mid: float = 0.19  # stance phase at which the pelvis passes over the planted ankle
    rocker: float = 0.07  # heel rocker ends (foot flat) at this phase
    heel_off: float = 0.33  # heel lifts (pivot about the ball) from this phase
    strike_pitch: float = 12.0  # toe-up angle at heel strike
    toeoff_pitch: float = 50.0  # heel-up angle at toe-off
    width: float = 10.0  # lateral distance of each foot from the path centre line
    toe_out: float = 5.0  # outward yaw of the feet
    lift: float = 12.0  # extra ankle lift at mid-swing
    height: float = 96.5  # nominal root (Hips) height
    bob: float = 1.2  # nominal root bob amplitude (twice per cycle)
    bob_sign: float = 1.0  # +1: highest at mid-stance (walk); -1: lowest at mid-stance (run)
    sway: float = 2.0  # lateral pelvis sway toward the stance foot
    twist: float = 5.0  # pelvis transverse rotation amplitude
    roll: float = 3.0  # pelvis list amplitude (swing side drops)
    tilt: float = 3.0  # pelvis anterior tilt
    wobble: float = 0.03  # relative cadence variation
    wobble_period: float = 3.7  # its period, s


@dataclass(frozen=True)
class _Path:
    """Ground path: ``kind`` in straight / curve / turn / scurve / side, with its parameters."""

    kind: str = "straight"
    rate: float = 0.0  # curve: turn rate deg/s; scurve: peak turn rate deg/s
    ramp: float = 1.0  # curve: seconds to reach the rate
    angle: float = 0.0  # turn: total heading change, deg (positive = left)
    at: float = 0.0  # turn: start time, s
    over: float = 1.0  # turn: duration, s; scurve: period, s
    slow: float = 0.0  # turn: fractional speed dip at mid-turn
    travel: float = 0.0  # travel direction relative to heading, deg (side: +90 = to the left)


@dataclass(frozen=True)
class _Upper:
    """Upper-body parameters: ``action`` picks the arm behaviour; angles in degrees."""

    action: str = "walk"  # walk / jog / side / carry_box / carry_cup / wave / punch / arms_out
    lean: float = 2.0  # pitch of the upper trunk (Spine2) from vertical, forward positive
    thorax: float = 6.0  # thorax twist amplitude (opposite the pelvis)
    arm_swing: float = 18.0  # shoulder flexion amplitude
    arm_mean: float = 3.0  # mean shoulder flexion (forward)
    arm_lag: float = 0.05  # arm swing lag behind the opposite leg, cycles
    elbow: float = 15.0  # elbow flexion, mean
    elbow_swing: float = 12.0  # extra elbow flexion when the arm is forward
    abduction: float = 6.0  # arms held this far from the sides


@dataclass(frozen=True)
class _Clip:
    """One sample clip: name, role, labels, length in seconds, gait, path, upper body, noise seed."""

    name: str
    role: str
    labels: dict
    duration: float
    gait: _Gait
    path: _Path = _Path()
    upper: _Upper = _Upper()
    seed: int = 0


_CLIPS: tuple[_Clip, ...] = (
    _Clip(
        "walk_straight", "locomotion", {"content": "walk", "kind": "locomotion", "path": "straight"}, 6.0,
        _Gait(speed=120.0, cadence=0.95, phase0=0.10),
        seed=11,
    ),
    _Clip(
        "walk_curve", "locomotion", {"content": "walk", "kind": "locomotion", "path": "curve_left"}, 7.0,
        _Gait(speed=112.0, cadence=0.92, phase0=0.55, width=10.5, wobble=0.04, wobble_period=4.3),
        _Path("curve", rate=27.0, ramp=1.2),
        seed=12,
    ),
    _Clip(
        "turn_sharp", "locomotion", {"content": "walk", "kind": "locomotion", "path": "turn_right_120"}, 6.0,
        _Gait(speed=112.0, cadence=0.97, phase0=0.30, wobble=0.02),
        _Path("turn", angle=-120.0, at=1.9, over=2.0, slow=0.25),
        seed=13,
    ),
    _Clip(
        "sidestep", "locomotion", {"content": "sidestep", "kind": "locomotion", "path": "left"}, 6.0,
        _Gait(
            speed=44.0, cadence=1.0, phase0=0.20, stance=0.66, mid=0.33, rocker=0.0, heel_off=0.5,
            strike_pitch=0.0, toeoff_pitch=15.0, width=17.5, toe_out=8.0, lift=8.0, height=95.5,
            bob=0.8, sway=1.0, twist=1.5, roll=2.0, tilt=2.0, wobble=0.02,
        ),
        _Path("side", travel=90.0),
        _Upper("side", lean=1.0, thorax=1.5, arm_swing=3.0, arm_mean=2.0, elbow=12.0, elbow_swing=2.0, abduction=10.0),
        seed=14,
    ),
    _Clip(
        "jog", "locomotion", {"content": "jog", "kind": "locomotion", "path": "straight"}, 5.0,
        _Gait(
            speed=230.0, cadence=1.35, phase0=0.75, stance=0.38, mid=0.13, rocker=0.04, heel_off=0.22,
            strike_pitch=6.0, toeoff_pitch=40.0, width=8.0, lift=11.0, height=95.0, bob=3.5, bob_sign=-1.0,
            sway=1.5, twist=7.0, roll=4.0, tilt=6.0, wobble=0.02, wobble_period=2.9,
        ),
        upper=_Upper("jog", lean=7.0, thorax=8.0, arm_swing=30.0, arm_mean=6.0, arm_lag=0.03, elbow=66.0, elbow_swing=10.0, abduction=8.0),
        seed=15,
    ),
    _Clip(
        "carry_box", "action", {"content": "carry_box", "kind": "action", "gait": "walk"}, 7.0,
        _Gait(speed=88.0, cadence=0.86, phase0=0.65, stance=0.64, width=12.0, lift=10.0, height=96.0,
              sway=2.8, twist=3.0, roll=3.5, tilt=-2.0, wobble=0.03, wobble_period=5.1),
        upper=_Upper("carry_box", lean=-15.0, thorax=1.5),
        seed=21,
    ),
    _Clip(
        "carry_cup", "action", {"content": "carry_cup", "kind": "action", "gait": "walk"}, 6.5,
        _Gait(speed=104.0, cadence=0.90, phase0=0.40, wobble=0.035, wobble_period=3.3),
        _Path("scurve", rate=14.0, over=6.0),
        _Upper("carry_cup", lean=1.0, thorax=3.0),
        seed=22,
    ),
    _Clip(
        "wave", "action", {"content": "wave", "kind": "action", "gait": "walk"}, 5.5,
        _Gait(speed=118.0, cadence=0.97, phase0=0.85),
        upper=_Upper("wave", lean=1.0),
        seed=23,
    ),
    _Clip(
        "punch", "action", {"content": "punch", "kind": "action", "gait": "walk"}, 6.5,
        _Gait(speed=94.0, cadence=0.88, phase0=0.20, width=11.0, wobble=0.04, wobble_period=2.7),
        upper=_Upper("punch", lean=4.0, thorax=2.0),
        seed=24,
    ),
    _Clip(
        "arms_out", "action", {"content": "arms_out", "kind": "action", "gait": "walk"}, 5.5,
        _Gait(speed=110.0, cadence=0.93, phase0=0.95, wobble=0.03, wobble_period=4.1),
        upper=_Upper("arms_out", lean=0.0, thorax=4.0),
        seed=25,
    ),
)

SAMPLE_CLIPS: tuple[str, ...] = tuple(c.name for c in _CLIPS)
"""Names of the sample clips, in the order :func:`sample_motions` returns them."""


# ---------------------------------------------------------------------------------------------
# Path and gait timing
# ---------------------------------------------------------------------------------------------


def _path_rates(path: _Path, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Speed multiplier ``(N,)`` and turn rate ``(N,)`` in deg/s along ``path`` at times ``t``."""
    mult = np.ones_like(t)
    rate = np.zeros_like(t)
    if path.kind == "curve":
        rate = path.rate * _smoothstep(t / path.ramp)
    elif path.kind == "turn":
        x = (t - path.at) / path.over
        inside = (x >= 0.0) & (x <= 1.0)
        bump = np.where(inside, 1.0 - np.cos(2.0 * math.pi * x), 0.0)  # mean 1 over the window
        rate = path.angle / path.over * bump
        mult = 1.0 - 0.5 * path.slow * bump
    elif path.kind == "scurve":
        rate = path.rate * np.sin(2.0 * math.pi * t / path.over)
    elif path.kind not in ("straight", "side"):
        raise ValueError(f"unknown path kind {path.kind!r}")
    return mult, rate


@dataclass
class _Timeline:
    """A clip's path and gait clock, on a fine grid (for plants) and at the frames.

    Fine arrays (``N`` samples from before the clip to after it): ``tf`` times, ``cf`` cycle
    coordinate, ``gf`` ``(N, 3)`` ground path (y = 0), ``hf`` heading in degrees.
    Frame arrays (``T``): ``t``, ``c``, ``g`` ``(T, 3)``, ``heading``, ``speed`` (cm/s),
    ``omega`` (deg/s).
    """

    tf: np.ndarray
    cf: np.ndarray
    gf: np.ndarray
    hf: np.ndarray
    t: np.ndarray
    c: np.ndarray
    g: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    omega: np.ndarray

    def at_cycle(self, cyc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Time ``(...)``, ground position ``(..., 3)`` and heading ``(...)`` where ``c`` equals ``cyc``."""
        t = np.interp(cyc, self.cf, self.tf)
        return t, _interp(t, self.tf, self.gf), np.interp(t, self.tf, self.hf)


def _timeline(clip: _Clip, num_frames: int, fps: float) -> _Timeline:
    """Integrate ``clip``'s path and gait clock (see :class:`_Timeline`); deterministic."""
    gait, path = clip.gait, clip.path
    dt = 1.0 / 240.0
    pad = 3.0
    tf = np.arange(-pad, clip.duration + pad + dt, dt)
    i0 = int(round(pad / dt))  # tf[i0] == 0
    mult, rate = _path_rates(path, tf)
    speed = gait.speed * mult
    hf = _cumtrapz(rate, dt)
    hf -= hf[i0]
    travel = _forward(hf + path.travel) * speed[:, None]
    gf = _cumtrapz(travel, dt)
    gf -= gf[i0]
    freq = gait.cadence * mult**0.3 * (1.0 + gait.wobble * np.sin(2.0 * math.pi * tf / gait.wobble_period + 1.3 * clip.seed))
    cf = _cumtrapz(freq, dt)
    cf += gait.phase0 - cf[i0]
    t = np.arange(num_frames) / fps
    return _Timeline(
        tf=tf, cf=cf, gf=gf, hf=hf, t=t,
        c=np.interp(t, tf, cf), g=_interp(t, tf, gf), heading=np.interp(t, tf, hf),
        speed=np.interp(t, tf, speed), omega=np.interp(t, tf, rate),
    )


# ---------------------------------------------------------------------------------------------
# Feet
# ---------------------------------------------------------------------------------------------


def _stance_pose(plant: np.ndarray, yaw: np.ndarray, u: np.ndarray, gait: _Gait) -> tuple[np.ndarray, np.ndarray]:
    """Ankle position ``(N, 3)`` and foot pitch ``(N,)`` (deg, + = heel up) at stance phase ``u``.

    ``plant`` ``(N, 3)`` is the ankle's position with the foot flat, ``yaw`` ``(N,)`` the foot's
    heading in degrees. Phases below ``gait.rocker`` roll about the heel (toe up at 0), between
    rocker and heel-off the foot is flat and the ankle exactly at ``plant``, after heel-off the
    foot pivots about the ball up to ``gait.toeoff_pitch`` at ``u = gait.stance``.
    """
    ry = _ry(yaw)
    if gait.rocker > 0.0:
        pitch_r = -gait.strike_pitch * (1.0 - _smoothstep(u / gait.rocker))
    else:
        pitch_r = np.zeros_like(u)
    heel = plant + _apply(ry, _HEEL)
    ankle_r = heel + _apply(ry @ _rx(pitch_r), -_HEEL)
    pitch_t = gait.toeoff_pitch * _smoothstep((u - gait.heel_off) / (gait.stance - gait.heel_off))
    ball = plant + _apply(ry, _BALL)
    ankle_t = ball + _apply(ry @ _rx(pitch_t), -_BALL)
    rock, toe = u < gait.rocker, u >= gait.heel_off
    ankle = np.where(rock[:, None], ankle_r, np.where(toe[:, None], ankle_t, plant))
    pitch = np.where(rock, pitch_r, np.where(toe, pitch_t, 0.0))
    return ankle, pitch


def _foot_targets(tl: _Timeline, gait: _Gait, side: int) -> dict[str, np.ndarray]:
    """Per-frame target of one foot (``side`` 0 left, 1 right).

    Returns a dict of ``ankle`` ``(T, 3)``, ``yaw`` ``(T,)`` and ``pitch`` ``(T,)`` in degrees
    (the foot's world orientation is ``R_y(yaw) R_x(pitch)``), ``stance`` ``(T,)`` bool.
    """
    offset = 0.5 * side  # the right foot runs half a cycle behind the left
    lateral = gait.width if side == 0 else -gait.width
    toe_out = gait.toe_out if side == 0 else -gait.toe_out
    ci = tl.c - offset
    k = np.floor(ci)
    u = ci - k

    def plant(step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flat-foot ankle position ``(T, 3)`` and foot yaw ``(T,)`` (deg) of stance number ``step``."""
        _, g, h = tl.at_cycle(step + gait.mid + offset)
        return g + lateral * _left(h) + np.array([0.0, _ANKLE_HEIGHT, 0.0]), h + toe_out

    p0, yaw0 = plant(k)
    p1, yaw1 = plant(k + 1.0)
    st_ankle, st_pitch = _stance_pose(p0, yaw0, u, gait)
    a0, q0 = _stance_pose(p0, yaw0, np.full_like(u, gait.stance), gait)
    a1, q1 = _stance_pose(p1, yaw1, np.zeros_like(u), gait)
    s = np.clip((u - gait.stance) / (1.0 - gait.stance), 0.0, 1.0)
    m = _minjerk(s)
    # the ankle travels with a cubic ease (it gets going sooner than minimum jerk, so it does
    # not fall behind the pelvis just after toe-off) and rises and falls with zero slope
    sw_ankle = a0 + (a1 - a0) * _smoothstep(s)[:, None]
    sw_ankle[:, 1] += gait.lift * s**2 * (1.0 - s) ** 3 / 0.03456  # peaks (= lift) at s = 0.4
    sw_pitch = q0 + (q1 - q0) * m
    sw_yaw = yaw0 + (yaw1 - yaw0) * m
    stance = u < gait.stance
    return {
        "ankle": np.where(stance[:, None], st_ankle, sw_ankle),
        "pitch": np.where(stance, st_pitch, sw_pitch),
        "yaw": np.where(stance, yaw0, sw_yaw),
        "stance": stance,
    }


def _two_bone_ik(hip: np.ndarray, ankle: np.ndarray, pole: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global thigh and shin rotations ``(T, 3, 3)`` putting the ankle on its target.

    ``hip``, ``ankle``, ``pole`` are ``(T, 3)``: the hip joint, the ankle target and the
    direction the knee should point (horizontal foot forward). The bones' rest direction is
    -Y; the knee hinges about the shared local X axis (positive = flexion). Targets beyond
    reach are clamped along the hip-ankle line.
    """
    d_vec = ankle - hip
    d_raw = np.linalg.norm(d_vec, axis=-1, keepdims=True)
    e = d_vec / d_raw
    d = np.clip(d_raw, abs(_THIGH - _SHIN) + 1e-3, 0.9999 * (_THIGH + _SHIN))
    cos_a = np.clip((_THIGH**2 + d**2 - _SHIN**2) / (2.0 * _THIGH * d), -1.0, 1.0)
    sin_a = np.sqrt(1.0 - cos_a**2)
    n = pole - (pole * e).sum(-1, keepdims=True) * e
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    knee_dir = cos_a * e + sin_a * n
    y_t = -knee_dir
    z_t = n - (n * y_t).sum(-1, keepdims=True) * y_t
    z_t /= np.linalg.norm(z_t, axis=-1, keepdims=True)
    x_t = np.cross(y_t, z_t)
    thigh = np.stack((x_t, y_t, z_t), axis=-1)  # columns are the local axes in the world
    shin_dir = e * d - _THIGH * knee_dir
    y_s = -shin_dir / np.linalg.norm(shin_dir, axis=-1, keepdims=True)
    z_s = np.cross(x_t, y_s)
    shin = np.stack((x_t, y_s, z_s), axis=-1)
    return thigh, shin


# ---------------------------------------------------------------------------------------------
# One clip
# ---------------------------------------------------------------------------------------------


def _pulse(t: np.ndarray, period: float, start: float, out: float = 0.13, hold: float = 0.08, back: float = 0.30) -> np.ndarray:
    """Punch profile ``(T,)`` in [0, 1]: every ``period`` s from ``start``, rise in ``out`` s, hold, return."""
    x = np.mod(t - start, period)
    rise = _smoothstep(x / out)
    fall = 1.0 - _smoothstep((x - out - hold) / back)
    return np.where(x < out, rise, np.where(x < out + hold, 1.0, fall)) * (t >= start)


def _generate(clip: _Clip) -> tuple[np.ndarray, np.ndarray]:
    """Local rotation matrices ``(T, 22, 3, 3)`` and root translations ``(T, 3)`` of one clip."""
    fps = SAMPLE_FPS
    T = int(round(clip.duration * fps))
    gait, up = clip.gait, clip.upper
    rng = np.random.default_rng(clip.seed)
    tl = _timeline(clip, T, fps)
    t, c, th = tl.t, tl.c, tl.heading
    two_pi = 2.0 * math.pi

    # ---- feet
    feet = [_foot_targets(tl, gait, side) for side in (0, 1)]

    # ---- pelvis (root) orientation and horizontal position
    p_twist = -gait.twist * np.cos(two_pi * c)  # left hip forward at left heel strike
    p_roll = gait.roll * np.cos(two_pi * (c - gait.mid))  # swing side drops
    p_tilt = gait.tilt + 0.8 * np.cos(2.0 * two_pi * (c - gait.mid))
    r_root = _ry(th + p_twist) @ _rx(p_tilt) @ _rz(p_roll)
    sway = gait.sway * np.cos(two_pi * (c - gait.mid))  # toward the stance foot
    root = tl.g + sway[:, None] * _left(th)

    # ---- pelvis height: nominal bob, softly clipped to what both legs reach
    nominal = gait.height + gait.bob_sign * gait.bob * np.cos(2.0 * two_pi * (c - gait.mid))
    limits = [nominal]
    for side, foot in enumerate(feet):
        off = _apply(r_root, _HIP_OFFSET[side])
        dh = np.linalg.norm((foot["ankle"] - root - off)[:, [0, 2]], axis=-1)
        limits.append(foot["ankle"][:, 1] + np.sqrt(np.maximum(_REACH**2 - dh**2, 0.0)) - off[:, 1])
    k = 0.8  # softness (cm) of the smooth minimum; it never exceeds the true minimum
    root[:, 1] = _smooth_below(-k * np.logaddexp.reduce(-np.stack(limits) / k, axis=0), 2)

    local = np.broadcast_to(np.eye(3), (T, len(_NAMES), 3, 3)).copy()
    local[:, 0] = r_root

    # ---- legs
    names = (("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToe"), ("RightUpLeg", "RightLeg", "RightFoot", "RightToe"))
    for side, foot in enumerate(feet):
        hip = root + _apply(r_root, _HIP_OFFSET[side])
        pole = _forward(foot["yaw"]) + _forward(th)
        thigh, shin = _two_bone_ik(hip, foot["ankle"], pole)
        r_foot = _ry(foot["yaw"]) @ _rx(foot["pitch"])
        upleg, leg, ft, toe = (_J[n] for n in names[side])
        local[:, upleg] = _tr(r_root) @ thigh
        local[:, leg] = _tr(thigh) @ shin
        local[:, ft] = _tr(shin) @ r_foot
        local[:, toe] = _rx(-np.maximum(foot["pitch"], 0.0))  # toes stay level on the ground

    # ---- trunk: thorax twists opposite the pelvis; lean; lean into turns; counter the list
    lean_turn = -np.degrees(np.arctan(tl.speed * np.radians(tl.omega) / 981.0))  # lean into the curve
    thorax_yaw = up.thorax * np.cos(two_pi * c)  # right shoulder forward at left heel strike
    extra_yaw = np.zeros(T)
    if up.action == "punch":
        p_right = _pulse(t, 1.3, 0.45)
        p_left = _pulse(t, 1.3, 1.1)
        extra_yaw = 16.0 * (p_right - p_left)  # turn the trunk into each punch
    twist_w = (0.3, 0.35, 0.35)  # twist spreads evenly; lean bends mostly the lower back
    lean_w = (0.5, 0.3, 0.2)
    for w, wl, name in zip(twist_w, lean_w, ("Spine", "Spine1", "Spine2")):
        yaw = w * (thorax_yaw + extra_yaw - p_twist) + _noise(rng, t, 0.6)
        pitch = wl * (up.lean - p_tilt) + _noise(rng, t, 0.5)
        roll = w * (lean_turn - 0.9 * p_roll) + _noise(rng, t, 0.5)
        local[:, _J[name]] = _ry(yaw) @ _rx(pitch) @ _rz(roll)
    look = np.clip(0.35 * tl.omega, -25.0, 25.0)  # look ahead into turns
    nod = 1.0 * np.cos(2.0 * two_pi * (c - gait.mid - 0.1))
    for name in ("Neck", "Head"):
        yaw = -0.45 * (thorax_yaw + extra_yaw) + 0.5 * look + _noise(rng, t, 1.0)
        pitch = -0.35 * up.lean + 0.5 * nod + _noise(rng, t, 1.0)
        roll = -0.4 * lean_turn + _noise(rng, t, 0.6)
        local[:, _J[name]] = _ry(yaw) @ _rx(pitch) @ _rz(roll)

    # ---- arms: default swing, each arm forward with the opposite leg
    def swing(side: int) -> tuple[np.ndarray, np.ndarray]:
        """Shoulder flexion and elbow flexion ``(T,)`` (deg) of a swinging arm (0 left, 1 right)."""
        ph = two_pi * (c - (0.5 if side == 0 else 0.0) - up.arm_lag)
        fwd = up.arm_mean + up.arm_swing * np.cos(ph)
        elbow = up.elbow + up.elbow_swing * 0.5 * (1.0 + np.cos(ph))
        return fwd, elbow

    arm_names = (("LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"), ("RightShoulder", "RightArm", "RightForeArm", "RightHand"))
    for side in (0, 1):
        sgn = 1.0 if side == 0 else -1.0  # mirror Z rotations (abduction, clavicle elevation)
        clav, arm, fore, hand = (_J[n] for n in arm_names[side])
        fwd, elbow = swing(side)
        abd = np.full(T, up.abduction)
        arm_twist = np.zeros(T)
        fore_z = np.zeros(T)
        hand_x = -4.0 - 0.3 * (fwd - up.arm_mean)
        elev = 2.0 + np.zeros(T)
        noisy = True
        elbow_about_z = False
        hand_y = np.zeros(T)
        steady = False  # hold the upper arm fixed in the heading frame (the cup)
        if up.action == "carry_box":
            bounce = 1.5 * np.cos(2.0 * two_pi * (c - gait.mid))
            fwd, elbow, abd = 22.0 + bounce, 62.0 - bounce, np.full(T, -6.0)
            hand_x = np.full(T, 12.0)
            arm_twist = np.full(T, -sgn * 10.0)
            elev = np.full(T, 4.0)
            noisy = False
        elif up.action == "carry_cup" and side == 1:
            fwd, elbow, abd = np.full(T, 26.0), np.full(T, 74.0), np.full(T, 8.0)
            hand_x = np.full(T, 10.0)  # keeps the hand level
            arm_twist = np.full(T, 8.0)
            noisy, steady = False, True
        elif up.action == "wave" and side == 1:
            wv = np.sin(two_pi * 1.7 * t)
            fwd, elbow, abd = np.full(T, 8.0) + 3.0 * wv, np.full(T, 22.0), 150.0 + 8.0 * wv
            fore_z = 28.0 * np.sin(two_pi * 1.7 * t + 0.5)
            hand_x = np.full(T, -5.0)
            elev = np.full(T, 14.0)
        elif up.action == "punch":
            p = _pulse(t, 1.3, 0.45) if side == 1 else _pulse(t, 1.3, 1.1)
            fwd = 35.0 + (75.0 - 35.0) * p + 2.0 * np.cos(two_pi * c)
            elbow = 115.0 + (4.0 - 115.0) * p
            abd = -12.0 + 6.0 * p
            # the upper arm turned 90 degrees about its length: the elbow then hinges about
            # the forearm's local Z, so a guard flexion past 90 stays clear of gimbal lock
            arm_twist = np.full(T, sgn * 90.0)
            elbow_about_z = True
            hand_x = np.full(T, 5.0)
            hand_y = -sgn * 60.0 * p  # the fist turns palm down on impact
            elev = 3.0 + 3.0 * p
        elif up.action == "arms_out":
            fwd = 4.0 + 1.5 * np.cos(two_pi * (c - 0.5 * side))
            abd = 86.0 + 3.0 * np.cos(2.0 * two_pi * (c - gait.mid - 0.15))
            elbow = np.full(T, 8.0)
            hand_x = np.full(T, 0.0)
            elev = np.full(T, 6.0)
        elif up.action == "side":
            abd = up.abduction + 4.0 * np.cos(two_pi * (c - gait.mid))
        n_arm = _noise(rng, t, 1.5 if noisy else 0.0)
        n_el = _noise(rng, t, 2.0 if noisy else 0.0)
        local[:, clav] = _rz(sgn * elev)
        local[:, arm] = _rz(sgn * abd) @ _rx(-fwd + n_arm) @ _ry(arm_twist)
        if elbow_about_z:  # see the punch: the hinge is local Z (+X of the untwisted arm)
            local[:, fore] = _rz(-sgn * (elbow - n_el))
        else:
            local[:, fore] = _rz(fore_z) @ _rx(-elbow + n_el)
        local[:, hand] = _rx(hand_x) @ _ry(hand_y)
        if steady:
            # the same arm pose, but relative to the heading frame instead of the swaying,
            # twisting trunk: undo the clavicle's global rotation (the trunk's included)
            parent = r_root
            for name in ("Spine", "Spine1", "Spine2", arm_names[side][0]):
                parent = parent @ local[:, _J[name]]
            local[:, arm] = _tr(parent) @ _ry(th) @ local[:, arm]

    return local, root


def _to_quaternions(local: np.ndarray, dtype: torch.dtype) -> torch.Tensor:
    """``(T, J, 3, 3)`` rotation matrices to ``(T, J, 4)`` WXYZ quaternions, sign-continuous in time."""
    q = rotmat_to_quat(torch.from_numpy(local))
    dots = (q[1:] * q[:-1]).sum(-1)
    flips = torch.cat((torch.ones_like(q[:1, :, 0]), torch.where(dots < 0, -1.0, 1.0).to(q)))
    q = q * torch.cumprod(flips, dim=0)[..., None]
    return q.to(dtype)


def _make_motion(clip: _Clip, skeleton: Skeleton, dtype: torch.dtype) -> Motion:
    """Generate ``clip`` on ``skeleton`` as a :class:`Motion` with tensors of ``dtype``."""
    local, root = _generate(clip)
    return Motion(
        skeleton=skeleton,
        rotations=_to_quaternions(local, dtype),
        root_translation=torch.from_numpy(root).to(dtype),
        fps=SAMPLE_FPS,
        name=clip.name,
        source=SAMPLE_SOURCE,
        role=clip.role,
        labels=dict(clip.labels),
    )


def sample_motions(dtype: torch.dtype = torch.float32) -> list[Motion]:
    """Every sample clip, generated afresh (deterministic: the same values on every call).

    Clips, in :data:`SAMPLE_CLIPS` order, all 30 fps, 5-7 s, starting at the origin facing +Z
    (Y up, cm):

    - locomotion (``role="locomotion"``): ``walk_straight``; ``walk_curve`` (a left curve, about
      27 deg/s after a ramp, some 160 degrees in all); ``turn_sharp`` (a 120-degree turn to the
      right within 2 s, slowing down); ``sidestep`` (facing +Z, travelling left along +X);
      ``jog`` (with flight phases);
    - actions while walking (``role="action"``): ``carry_box`` (trunk leaning back, the
      hips-to-neck line some 10-11 degrees behind vertical against about 2 forward when
      walking, both arms holding a box in front, slower shorter steps); ``carry_cup`` (right
      forearm raised and held steady in the heading frame, gentle S-curve path); ``wave``
      (right arm waving overhead); ``punch`` (alternating punches, the trunk turning into
      each); ``arms_out`` (arms held out sideways).

    Each :class:`Motion` has ``rotations`` ``(T, 22, 4)`` (local, unit WXYZ quaternions,
    sign-continuous in time), ``root_translation`` ``(T, 3)`` (cm), ``translations=None``,
    ``fps=30``, ``name``, ``role``, ``labels`` (``content``, ``kind`` and ``path`` or ``gait``)
    and ``source="torchsplice.sample"``; all share one :func:`sample_skeleton`.

    Args:
        dtype: floating dtype of the returned tensors (computed in float64).
    """
    skeleton = sample_skeleton()
    return [_make_motion(clip, skeleton, dtype) for clip in _CLIPS]


def sample_motion(name: str, dtype: torch.dtype = torch.float32) -> Motion:
    """One sample clip by name (one of :data:`SAMPLE_CLIPS`); see :func:`sample_motions`."""
    for clip in _CLIPS:
        if clip.name == name:
            return _make_motion(clip, sample_skeleton(), dtype)
    raise KeyError(f"no sample clip {name!r}; the sample has: {', '.join(SAMPLE_CLIPS)}")
