"""The sample's lower body: the ground path and gait clock of a clip, each foot's target (plants,
the heel-flat-toe roll of stance, the swing arc), the pelvis following the path within what the
legs reach, and two-bone IK of the legs onto the feet.

Conventions (those of :mod:`torchsplice.sample.generate`): Y up, centimetres, the floor at
``y = 0``; times in seconds, angles in degrees, the gait cycle coordinate ``c`` in cycles (the
left foot strikes at integer ``c``, the right at half-integers). Arrays are float64 numpy over
``T`` frames (or ``N`` samples of the fine time grid); rotation matrices ``(T, 3, 3)`` have the
local axes as columns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .clips import ClipSpec, Gait, GroundPath
from .numeric import cumtrapz, forward_of, interp_columns, left_of, minjerk, rotate, rx, ry, rz, smooth_below, \
    smoothstep, tr
from .skeleton import ANKLE_HEIGHT, BALL, HEEL, HIP_OFFSET, JOINT, REACH, SHIN, THIGH

__all__ = ["path_rates", "Timeline", "timeline", "stance_pose", "foot_targets", "two_bone_ik", "Pelvis",
           "pelvis_motion", "leg_rotations"]


def path_rates(path: GroundPath, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Speed multiplier ``(N,)`` and turn rate ``(N,)`` in deg/s along ``path`` at times ``t``."""
    mult = np.ones_like(t)
    rate = np.zeros_like(t)
    if path.kind == "curve":
        rate = path.rate * smoothstep(t / path.ramp)
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
class Timeline:
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
        return t, interp_columns(t, self.tf, self.gf), np.interp(t, self.tf, self.hf)


def timeline(clip: ClipSpec, num_frames: int, fps: float) -> Timeline:
    """Integrate ``clip``'s path and gait clock (see :class:`Timeline`); deterministic."""
    gait, path = clip.gait, clip.path
    dt = 1.0 / 240.0
    pad = 3.0
    tf = np.arange(-pad, clip.duration + pad + dt, dt)
    i0 = int(round(pad / dt))  # tf[i0] == 0
    mult, rate = path_rates(path, tf)
    speed = gait.speed * mult
    hf = cumtrapz(rate, dt)
    hf -= hf[i0]
    travel = forward_of(hf + path.travel) * speed[:, None]
    gf = cumtrapz(travel, dt)
    gf -= gf[i0]
    freq = gait.cadence * mult**0.3 * (1.0 + gait.wobble * np.sin(2.0 * math.pi * tf / gait.wobble_period + 1.3 * clip.seed))
    cf = cumtrapz(freq, dt)
    cf += gait.phase0 - cf[i0]
    t = np.arange(num_frames) / fps
    return Timeline(
        tf=tf, cf=cf, gf=gf, hf=hf, t=t,
        c=np.interp(t, tf, cf), g=interp_columns(t, tf, gf), heading=np.interp(t, tf, hf),
        speed=np.interp(t, tf, speed), omega=np.interp(t, tf, rate),
    )


def stance_pose(plant: np.ndarray, yaw: np.ndarray, u: np.ndarray, gait: Gait) -> tuple[np.ndarray, np.ndarray]:
    """Ankle position ``(N, 3)`` and foot pitch ``(N,)`` (deg, + = heel up) at stance phase ``u``.

    ``plant`` ``(N, 3)`` is the ankle's position with the foot flat, ``yaw`` ``(N,)`` the foot's
    heading in degrees. Phases below ``gait.rocker`` roll about the heel (toe up at 0), between
    rocker and heel-off the foot is flat and the ankle exactly at ``plant``, after heel-off the
    foot pivots about the ball up to ``gait.toeoff_pitch`` at ``u = gait.stance``.
    """
    r_yaw = ry(yaw)
    if gait.rocker > 0.0:
        pitch_r = -gait.strike_pitch * (1.0 - smoothstep(u / gait.rocker))
    else:
        pitch_r = np.zeros_like(u)
    heel = plant + rotate(r_yaw, HEEL)
    ankle_r = heel + rotate(r_yaw @ rx(pitch_r), -HEEL)
    pitch_t = gait.toeoff_pitch * smoothstep((u - gait.heel_off) / (gait.stance - gait.heel_off))
    ball = plant + rotate(r_yaw, BALL)
    ankle_t = ball + rotate(r_yaw @ rx(pitch_t), -BALL)
    rock, toe = u < gait.rocker, u >= gait.heel_off
    ankle = np.where(rock[:, None], ankle_r, np.where(toe[:, None], ankle_t, plant))
    pitch = np.where(rock, pitch_r, np.where(toe, pitch_t, 0.0))
    return ankle, pitch


def foot_targets(tl: Timeline, gait: Gait, side: int) -> dict[str, np.ndarray]:
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
        return g + lateral * left_of(h) + np.array([0.0, ANKLE_HEIGHT, 0.0]), h + toe_out

    p0, yaw0 = plant(k)
    p1, yaw1 = plant(k + 1.0)
    st_ankle, st_pitch = stance_pose(p0, yaw0, u, gait)
    a0, q0 = stance_pose(p0, yaw0, np.full_like(u, gait.stance), gait)
    a1, q1 = stance_pose(p1, yaw1, np.zeros_like(u), gait)
    s = np.clip((u - gait.stance) / (1.0 - gait.stance), 0.0, 1.0)
    m = minjerk(s)
    # the ankle travels with a cubic ease (it gets going sooner than minimum jerk, so it does
    # not fall behind the pelvis just after toe-off) and rises and falls with zero slope
    sw_ankle = a0 + (a1 - a0) * smoothstep(s)[:, None]
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


def two_bone_ik(hip: np.ndarray, ankle: np.ndarray, pole: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global thigh and shin rotations ``(T, 3, 3)`` putting the ankle on its target.

    ``hip``, ``ankle``, ``pole`` are ``(T, 3)``: the hip joint, the ankle target and the
    direction the knee should point (horizontal foot forward). The bones' rest direction is
    -Y; the knee hinges about the shared local X axis (positive = flexion). Targets beyond
    reach are clamped along the hip-ankle line.
    """
    d_vec = ankle - hip
    d_raw = np.linalg.norm(d_vec, axis=-1, keepdims=True)
    e = d_vec / d_raw
    d = np.clip(d_raw, abs(THIGH - SHIN) + 1e-3, 0.9999 * (THIGH + SHIN))
    cos_a = np.clip((THIGH**2 + d**2 - SHIN**2) / (2.0 * THIGH * d), -1.0, 1.0)
    sin_a = np.sqrt(1.0 - cos_a**2)
    n = pole - (pole * e).sum(-1, keepdims=True) * e
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    knee_dir = cos_a * e + sin_a * n
    y_t = -knee_dir
    z_t = n - (n * y_t).sum(-1, keepdims=True) * y_t
    z_t /= np.linalg.norm(z_t, axis=-1, keepdims=True)
    x_t = np.cross(y_t, z_t)
    thigh = np.stack((x_t, y_t, z_t), axis=-1)  # columns are the local axes in the world
    shin_dir = e * d - THIGH * knee_dir
    y_s = -shin_dir / np.linalg.norm(shin_dir, axis=-1, keepdims=True)
    z_s = np.cross(x_t, y_s)
    shin = np.stack((x_t, y_s, z_s), axis=-1)
    return thigh, shin


@dataclass
class Pelvis:
    """The pelvis (the root, ``Hips``) over a clip's frames: its world ``rotation`` ``(T, 3, 3)``,
    its ``position`` ``(T, 3)`` (cm) and the angles it is made of, ``(T,)`` degrees each:
    ``twist`` (transverse rotation), ``roll`` (list) and ``tilt`` (anterior tilt)."""

    rotation: np.ndarray
    position: np.ndarray
    twist: np.ndarray
    roll: np.ndarray
    tilt: np.ndarray


def pelvis_motion(tl: Timeline, gait: Gait, feet: list[dict[str, np.ndarray]]) -> Pelvis:
    """The pelvis following the path with sway, twist, list and tilt; its height a nominal bob
    softly clipped (smooth minimum) to what both legs reach to their ``feet`` (:func:`foot_targets`,
    left then right), then smoothed from below."""
    c, th = tl.c, tl.heading
    two_pi = 2.0 * math.pi

    # ---- pelvis (root) orientation and horizontal position
    p_twist = -gait.twist * np.cos(two_pi * c)  # left hip forward at left heel strike
    p_roll = gait.roll * np.cos(two_pi * (c - gait.mid))  # swing side drops
    p_tilt = gait.tilt + 0.8 * np.cos(2.0 * two_pi * (c - gait.mid))
    r_root = ry(th + p_twist) @ rx(p_tilt) @ rz(p_roll)
    sway = gait.sway * np.cos(two_pi * (c - gait.mid))  # toward the stance foot
    root = tl.g + sway[:, None] * left_of(th)

    # ---- pelvis height: nominal bob, softly clipped to what both legs reach
    nominal = gait.height + gait.bob_sign * gait.bob * np.cos(2.0 * two_pi * (c - gait.mid))
    limits = [nominal]
    for side, foot in enumerate(feet):
        off = rotate(r_root, HIP_OFFSET[side])
        dh = np.linalg.norm((foot["ankle"] - root - off)[:, [0, 2]], axis=-1)
        limits.append(foot["ankle"][:, 1] + np.sqrt(np.maximum(REACH**2 - dh**2, 0.0)) - off[:, 1])
    k = 0.8  # softness (cm) of the smooth minimum; it never exceeds the true minimum
    root[:, 1] = smooth_below(-k * np.logaddexp.reduce(-np.stack(limits) / k, axis=0), 2)
    return Pelvis(rotation=r_root, position=root, twist=p_twist, roll=p_roll, tilt=p_tilt)


_LEG_JOINTS = (("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToe"), ("RightUpLeg", "RightLeg", "RightFoot", "RightToe"))


def leg_rotations(local: np.ndarray, tl: Timeline, pelvis: Pelvis, feet: list[dict[str, np.ndarray]]) -> None:
    """Write the legs' local rotations into ``local`` ``(T, 22, 3, 3)``: two-bone IK of each
    hip-knee-ankle chain onto its foot's target, the knee pointing along the foot; the foot and
    toe take the rolled foot orientation, the toes staying level on the ground."""
    th, r_root, root = tl.heading, pelvis.rotation, pelvis.position
    for side, foot in enumerate(feet):
        hip = root + rotate(r_root, HIP_OFFSET[side])
        pole = forward_of(foot["yaw"]) + forward_of(th)
        thigh, shin = two_bone_ik(hip, foot["ankle"], pole)
        r_foot = ry(foot["yaw"]) @ rx(foot["pitch"])
        upleg, leg, ft, toe = (JOINT[n] for n in _LEG_JOINTS[side])
        local[:, upleg] = tr(r_root) @ thigh
        local[:, leg] = tr(thigh) @ shin
        local[:, ft] = tr(shin) @ r_foot
        local[:, toe] = rx(-np.maximum(foot["pitch"], 0.0))  # toes stay level on the ground
