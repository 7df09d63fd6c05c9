"""The sample's upper body: the trunk twisting against the pelvis and leaning (into turns too),
the head looking into turns, and the arms either swinging with the gait or doing the clip's
action (carrying a box or a cup, waving, punching, holding the arms out).

Conventions (those of :mod:`torchsplice.sample.generate`): angles in degrees; the rotation
about a joint's local X pitches the bone below it (negative X swings an arm forward and flexes an
elbow), about Z raises the arms sideways (positive for the left arm); arrays are float64 numpy
over ``T`` frames, local rotations ``(T, 22, 3, 3)``. Noise is drawn from the clip's generator in
a fixed order (trunk, head, then left and right arm), so every clip is the same on every call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .clips import Gait, Upper
from .locomotion import Pelvis, Timeline
from .numeric import noise, rx, ry, rz, smoothstep, tr
from .skeleton import JOINT

__all__ = ["pulse", "trunk_and_head", "ArmPose", "arm_pose", "arms"]


def pulse(t: np.ndarray, period: float, start: float, out: float = 0.13, hold: float = 0.08, back: float = 0.30) -> np.ndarray:
    """Punch profile ``(T,)`` in [0, 1]: every ``period`` s from ``start``, rise in ``out`` s, hold, return."""
    x = np.mod(t - start, period)
    rise = smoothstep(x / out)
    fall = 1.0 - smoothstep((x - out - hold) / back)
    return np.where(x < out, rise, np.where(x < out + hold, 1.0, fall)) * (t >= start)


def trunk_and_head(local: np.ndarray, tl: Timeline, gait: Gait, up: Upper, pelvis: Pelvis,
                   rng: np.random.Generator) -> None:
    """Write the spine's, neck's and head's local rotations into ``local``: the thorax twists
    opposite the pelvis, the trunk leans (per clip, and into turns) and counters the pelvis's
    list; the head looks ahead into turns and nods with the steps."""
    t, c = tl.t, tl.c
    T = len(t)
    two_pi = 2.0 * math.pi
    p_twist, p_roll, p_tilt = pelvis.twist, pelvis.roll, pelvis.tilt
    lean_turn = -np.degrees(np.arctan(tl.speed * np.radians(tl.omega) / 981.0))  # lean into the curve
    thorax_yaw = up.thorax * np.cos(two_pi * c)  # right shoulder forward at left heel strike
    extra_yaw = np.zeros(T)
    if up.action == "punch":
        p_right = pulse(t, 1.3, 0.45)
        p_left = pulse(t, 1.3, 1.1)
        extra_yaw = 16.0 * (p_right - p_left)  # turn the trunk into each punch
    twist_w = (0.3, 0.35, 0.35)  # twist spreads evenly; lean bends mostly the lower back
    lean_w = (0.5, 0.3, 0.2)
    for w, wl, name in zip(twist_w, lean_w, ("Spine", "Spine1", "Spine2")):
        yaw = w * (thorax_yaw + extra_yaw - p_twist) + noise(rng, t, 0.6)
        pitch = wl * (up.lean - p_tilt) + noise(rng, t, 0.5)
        roll = w * (lean_turn - 0.9 * p_roll) + noise(rng, t, 0.5)
        local[:, JOINT[name]] = ry(yaw) @ rx(pitch) @ rz(roll)
    look = np.clip(0.35 * tl.omega, -25.0, 25.0)  # look ahead into turns
    nod = 1.0 * np.cos(2.0 * two_pi * (c - gait.mid - 0.1))
    for name in ("Neck", "Head"):
        yaw = -0.45 * (thorax_yaw + extra_yaw) + 0.5 * look + noise(rng, t, 1.0)
        pitch = -0.35 * up.lean + 0.5 * nod + noise(rng, t, 1.0)
        roll = -0.4 * lean_turn + noise(rng, t, 0.6)
        local[:, JOINT[name]] = ry(yaw) @ rx(pitch) @ rz(roll)


@dataclass
class ArmPose:
    """One arm's angles over the frames, ``(T,)`` degrees each: shoulder flexion ``fwd``
    (forward), ``elbow`` flexion, abduction ``abd``, the upper arm's ``twist`` about its length,
    the forearm's ``fore_z``, the hand's ``hand_x`` and ``hand_y``, the clavicle's elevation
    ``elev``; ``noisy``: add noise to shoulder and elbow; ``elbow_about_z``: the elbow hinges
    about the forearm's local Z (the upper arm turned 90 degrees); ``steady``: the upper arm held
    fixed in the heading frame rather than the trunk's."""

    fwd: np.ndarray
    elbow: np.ndarray
    abd: np.ndarray
    twist: np.ndarray
    fore_z: np.ndarray
    hand_x: np.ndarray
    hand_y: np.ndarray
    elev: np.ndarray
    noisy: bool = True
    elbow_about_z: bool = False
    steady: bool = False


def arm_pose(tl: Timeline, gait: Gait, up: Upper, side: int) -> ArmPose:
    """The pose of arm ``side`` (0 left, 1 right): the default swing, each arm forward with the
    opposite leg, or the clip's action (``up.action``)."""
    t, c = tl.t, tl.c
    T = len(t)
    two_pi = 2.0 * math.pi
    sgn = 1.0 if side == 0 else -1.0  # mirror Z rotations (abduction, clavicle elevation)
    ph = two_pi * (c - (0.5 if side == 0 else 0.0) - up.arm_lag)
    fwd = up.arm_mean + up.arm_swing * np.cos(ph)
    elbow = up.elbow + up.elbow_swing * 0.5 * (1.0 + np.cos(ph))
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
        p = pulse(t, 1.3, 0.45) if side == 1 else pulse(t, 1.3, 1.1)
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
    return ArmPose(fwd=fwd, elbow=elbow, abd=abd, twist=arm_twist, fore_z=fore_z, hand_x=hand_x, hand_y=hand_y,
                   elev=elev, noisy=noisy, elbow_about_z=elbow_about_z, steady=steady)


_ARM_JOINTS = (("LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand"),
               ("RightShoulder", "RightArm", "RightForeArm", "RightHand"))


def arms(local: np.ndarray, tl: Timeline, gait: Gait, up: Upper, pelvis: Pelvis, rng: np.random.Generator) -> None:
    """Write both arms' local rotations into ``local`` (after the trunk's: a steady arm is held
    in the heading frame through them), left then right, each :func:`arm_pose` with its noise."""
    t, th = tl.t, tl.heading
    for side in (0, 1):
        sgn = 1.0 if side == 0 else -1.0  # mirror Z rotations (abduction, clavicle elevation)
        clav, arm, fore, hand = (JOINT[n] for n in _ARM_JOINTS[side])
        pose = arm_pose(tl, gait, up, side)
        n_arm = noise(rng, t, 1.5 if pose.noisy else 0.0)
        n_el = noise(rng, t, 2.0 if pose.noisy else 0.0)
        local[:, clav] = rz(sgn * pose.elev)
        local[:, arm] = rz(sgn * pose.abd) @ rx(-pose.fwd + n_arm) @ ry(pose.twist)
        if pose.elbow_about_z:  # see the punch: the hinge is local Z (+X of the untwisted arm)
            local[:, fore] = rz(-sgn * (pose.elbow - n_el))
        else:
            local[:, fore] = rz(pose.fore_z) @ rx(-pose.elbow + n_el)
        local[:, hand] = rx(pose.hand_x) @ ry(pose.hand_y)
        if pose.steady:
            # the same arm pose, but relative to the heading frame instead of the swaying,
            # twisting trunk: undo the clavicle's global rotation (the trunk's included)
            parent = pelvis.rotation
            for name in ("Spine", "Spine1", "Spine2", _ARM_JOINTS[side][0]):
                parent = parent @ local[:, JOINT[name]]
            local[:, arm] = tr(parent) @ ry(th) @ local[:, arm]
