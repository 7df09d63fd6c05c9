"""The sample's clips as parameters: each clip's gait (:class:`Gait`), ground path
(:class:`GroundPath`) and upper body (:class:`Upper`), with its name, role, labels, length and
noise seed (:class:`ClipSpec`); :data:`CLIPS` lists them in the order
:func:`~torchsplice.sample.sample_motions` returns them.

Units: centimetres, seconds, degrees (positive turns are to the left); gait phases in gait
cycles (one cycle = two steps).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Gait", "GroundPath", "Upper", "ClipSpec", "CLIPS", "SAMPLE_CLIPS"]


@dataclass(frozen=True)
class Gait:
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
class GroundPath:
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
class Upper:
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
class ClipSpec:
    """One sample clip: name, role, labels, length in seconds, gait, path, upper body, noise seed."""

    name: str
    role: str
    labels: dict
    duration: float
    gait: Gait
    path: GroundPath = GroundPath()
    upper: Upper = Upper()
    seed: int = 0


CLIPS: tuple[ClipSpec, ...] = (
    ClipSpec(
        "walk_straight", "locomotion", {"content": "walk", "kind": "locomotion", "path": "straight"}, 6.0,
        Gait(speed=120.0, cadence=0.95, phase0=0.10),
        seed=11,
    ),
    ClipSpec(
        "walk_curve", "locomotion", {"content": "walk", "kind": "locomotion", "path": "curve_left"}, 7.0,
        Gait(speed=112.0, cadence=0.92, phase0=0.55, width=10.5, wobble=0.04, wobble_period=4.3),
        GroundPath("curve", rate=27.0, ramp=1.2),
        seed=12,
    ),
    ClipSpec(
        "turn_sharp", "locomotion", {"content": "walk", "kind": "locomotion", "path": "turn_right_120"}, 6.0,
        Gait(speed=112.0, cadence=0.97, phase0=0.30, wobble=0.02),
        GroundPath("turn", angle=-120.0, at=1.9, over=2.0, slow=0.25),
        seed=13,
    ),
    ClipSpec(
        "sidestep", "locomotion", {"content": "sidestep", "kind": "locomotion", "path": "left"}, 6.0,
        Gait(
            speed=44.0, cadence=1.0, phase0=0.20, stance=0.66, mid=0.33, rocker=0.0, heel_off=0.5,
            strike_pitch=0.0, toeoff_pitch=15.0, width=17.5, toe_out=8.0, lift=8.0, height=95.5,
            bob=0.8, sway=1.0, twist=1.5, roll=2.0, tilt=2.0, wobble=0.02,
        ),
        GroundPath("side", travel=90.0),
        Upper("side", lean=1.0, thorax=1.5, arm_swing=3.0, arm_mean=2.0, elbow=12.0, elbow_swing=2.0, abduction=10.0),
        seed=14,
    ),
    ClipSpec(
        "jog", "locomotion", {"content": "jog", "kind": "locomotion", "path": "straight"}, 5.0,
        Gait(
            speed=230.0, cadence=1.35, phase0=0.75, stance=0.38, mid=0.13, rocker=0.04, heel_off=0.22,
            strike_pitch=6.0, toeoff_pitch=40.0, width=8.0, lift=11.0, height=95.0, bob=3.5, bob_sign=-1.0,
            sway=1.5, twist=7.0, roll=4.0, tilt=6.0, wobble=0.02, wobble_period=2.9,
        ),
        upper=Upper("jog", lean=7.0, thorax=8.0, arm_swing=30.0, arm_mean=6.0, arm_lag=0.03, elbow=66.0, elbow_swing=10.0, abduction=8.0),
        seed=15,
    ),
    ClipSpec(
        "carry_box", "action", {"content": "carry_box", "kind": "action", "gait": "walk"}, 7.0,
        Gait(speed=88.0, cadence=0.86, phase0=0.65, stance=0.64, width=12.0, lift=10.0, height=96.0,
              sway=2.8, twist=3.0, roll=3.5, tilt=-2.0, wobble=0.03, wobble_period=5.1),
        upper=Upper("carry_box", lean=-15.0, thorax=1.5),
        seed=21,
    ),
    ClipSpec(
        "carry_cup", "action", {"content": "carry_cup", "kind": "action", "gait": "walk"}, 6.5,
        Gait(speed=104.0, cadence=0.90, phase0=0.40, wobble=0.035, wobble_period=3.3),
        GroundPath("scurve", rate=14.0, over=6.0),
        Upper("carry_cup", lean=1.0, thorax=3.0),
        seed=22,
    ),
    ClipSpec(
        "wave", "action", {"content": "wave", "kind": "action", "gait": "walk"}, 5.5,
        Gait(speed=118.0, cadence=0.97, phase0=0.85),
        upper=Upper("wave", lean=1.0),
        seed=23,
    ),
    ClipSpec(
        "punch", "action", {"content": "punch", "kind": "action", "gait": "walk"}, 6.5,
        Gait(speed=94.0, cadence=0.88, phase0=0.20, width=11.0, wobble=0.04, wobble_period=2.7),
        upper=Upper("punch", lean=4.0, thorax=2.0),
        seed=24,
    ),
    ClipSpec(
        "arms_out", "action", {"content": "arms_out", "kind": "action", "gait": "walk"}, 5.5,
        Gait(speed=110.0, cadence=0.93, phase0=0.95, wobble=0.03, wobble_period=4.1),
        upper=Upper("arms_out", lean=0.0, thorax=4.0),
        seed=25,
    ),
)

SAMPLE_CLIPS: tuple[str, ...] = tuple(c.name for c in CLIPS)
"""Names of the sample clips, in the order :func:`~torchsplice.sample.sample_motions` returns them."""
