"""The built-in procedural sample (torchsplice.sample): checks that can fail.

Everything is measured on forward-kinematics output (Y up, cm, quaternions WXYZ), not on the
generator's internals: foot plants, floor, arm-leg phase, trunk lean, heading along the paths.
"""

from __future__ import annotations

import fnmatch
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
import torch

from torchsplice.core.motion import Motion
from torchsplice.core.rotations import quat_to_euler
from torchsplice.sample import SAMPLE_CLIPS, SAMPLE_FPS, sample_motion, sample_motions, sample_skeleton
from torchsplice.core.fk import end_site_positions, forward_kinematics

SPEC = Path(__file__).resolve().parents[2] / "datasets_spec" / "sample.toml"
LOCOMOTION = ("walk_straight", "walk_curve", "turn_sharp", "sidestep", "jog")
ACTIONS = ("carry_box", "carry_cup", "wave", "punch", "arms_out")


@pytest.fixture(scope="module")
def clips() -> dict[str, Motion]:
    """Every sample clip by name, float64."""
    return {m.name: m for m in sample_motions(dtype=torch.float64)}


@pytest.fixture(scope="module")
def fk(clips) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per clip: joint positions ``(T, J, 3)`` and end-site positions ``(T, E, 3)``, numpy, cm."""
    out = {}
    for name, m in clips.items():
        sk = m.skeleton
        pos, rot = forward_kinematics(m.rotations, m.root_translation, sk.offsets, sk.parents)
        ends = end_site_positions(pos, rot, sk.end_site_parents, sk.end_site_offsets)
        out[name] = (pos.numpy(), ends.numpy())
    return out


def _j(name: str) -> int:
    return sample_skeleton().index(name)


def _facing(pos: np.ndarray) -> np.ndarray:
    """``(T, 3)`` horizontal unit facing from the hip joints (left hip minus right hip, crossed with up)."""
    lr = pos[:, _j("LeftUpLeg")] - pos[:, _j("RightUpLeg")]
    f = np.stack((-lr[:, 2], np.zeros(len(lr)), lr[:, 0]), axis=-1)  # cross(lr, +Y)
    return f / np.linalg.norm(f, axis=-1, keepdims=True)


def _heading(pos: np.ndarray) -> np.ndarray:
    """``(T,)`` unwrapped heading in degrees, 0 = +Z, positive toward +X (a left turn)."""
    f = _facing(pos)
    return np.degrees(np.unwrap(np.arctan2(f[:, 0], f[:, 2])))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, length)`` of every run of True in a 1-D bool array."""
    padded = np.concatenate(([False], mask, [False])).astype(int)
    d = np.diff(padded)
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return list(zip(starts.tolist(), (stops - starts).tolist()))


def _horizontal_speed(p: np.ndarray, fps: float) -> np.ndarray:
    """``(T-1,)`` horizontal speed (cm/s) of a ``(T, 3)`` track, by forward differences."""
    return np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=-1) * fps


# ---------------------------------------------------------------------------------------------
# Skeleton, determinism, bookkeeping
# ---------------------------------------------------------------------------------------------


def test_skeleton_layout():
    sk = sample_skeleton()
    assert sk.num_joints == 22
    assert sk.names[0] == "Hips"
    assert sk.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    assert all(ch == ("Zrotation", "Xrotation", "Yrotation") for ch in sk.channels[1:])
    leaves = {j for j in range(sk.num_joints) if not sk.children(j)}
    assert set(sk.end_site_parents) == leaves == set(sk.indices(["Head", "LeftHand", "RightHand", "LeftToe", "RightToe"]))
    pos, ends = sk.rest_positions()
    allp = torch.cat((pos, ends))
    assert 165.0 <= float(allp[:, 1].max()) <= 185.0  # top of the head, standing on y = 0
    assert 0.0 <= float(allp[:, 1].min()) <= 5.0
    # arms hang down at the sides; left is +X; toes point +Z
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        arm, hand, toe = pos[sk.index(f"{side}Arm")], pos[sk.index(f"{side}Hand")], pos[sk.index(f"{side}Toe")]
        assert hand[1] < arm[1] - 40.0 and abs(hand[0] - arm[0]) < 1.0
        assert sign * arm[0] > 10.0 and sign * pos[sk.index(f"{side}UpLeg"), 0] > 5.0
        assert toe[2] > 5.0


def test_deterministic():
    a, b = sample_motions(), sample_motions()
    assert [m.name for m in a] == [m.name for m in b] == list(SAMPLE_CLIPS)
    for x, y in zip(a, b):
        assert torch.equal(x.rotations, y.rotations)
        assert torch.equal(x.root_translation, y.root_translation)
        assert x.labels == y.labels and x.role == y.role
    one = sample_motion("punch")
    assert torch.equal(one.rotations, next(m for m in a if m.name == "punch").rotations)
    with pytest.raises(KeyError, match="walk_straight"):
        sample_motion("moonwalk")


def test_clips_are_valid(clips):
    assert list(clips) == list(SAMPLE_CLIPS) == list(LOCOMOTION + ACTIONS)
    sk = sample_skeleton()
    for name, m in clips.items():
        assert m.role == ("locomotion" if name in LOCOMOTION else "action")
        assert m.labels["kind"] == m.role and m.labels["content"]
        assert m.source == "torchsplice.sample" and m.fps == SAMPLE_FPS == 30.0
        assert m.translations is None
        assert m.skeleton.matches(sk) and m.skeleton.same_topology(sk)
        assert 4.0 <= m.duration <= 8.0
        m.check_finite()
        norms = m.rotations.norm(dim=-1)
        assert torch.allclose(norms, torch.ones_like(norms), atol=1e-6)
        # sign-continuous quaternions: consecutive frames on the same hemisphere
        assert bool(((m.rotations[1:] * m.rotations[:-1]).sum(-1) > 0).all())
        # starts at the origin, on the floor's scale (cm)
        assert torch.allclose(m.root_translation[0, [0, 2]], torch.zeros(2, dtype=m.dtype), atol=3.0)
        assert 85.0 < float(m.root_translation[:, 1].min()) and float(m.root_translation[:, 1].max()) < 100.0
    f32 = sample_motions()[0]
    assert f32.rotations.dtype == torch.float32 and f32.root_translation.dtype == torch.float32


def test_euler_channels_stay_clear_of_gimbal_lock(clips):
    # every joint's BVH channels are Z X Y: the middle (X) angle must stay well inside +-90
    # degrees, or a written BVH file's Euler curves flip (exact per frame, but unusable to edit)
    for name, m in clips.items():
        middle = quat_to_euler(m.rotations, "ZXY")[..., 1].abs()
        worst = int(middle.max(0).values.argmax())
        assert float(middle.max()) < 85.0, f"{name}: {m.skeleton.names[worst]} reaches {float(middle.max()):.1f} deg"


def test_spec_matches_the_sample(clips):
    spec = tomllib.loads(SPEC.read_text())
    assert spec["dataset"]["name"] == "sample"
    assert spec["dataset"]["up_axis"] == "y" and spec["dataset"]["units"] == "cm"
    sk = sample_skeleton()
    joints = spec["joints"]
    named = []
    for value in joints.values():
        named += value if isinstance(value, list) else [value]
    for n in named:
        sk.index(n)  # raises for an unknown joint
    assert joints["root"] == sk.names[0]
    upper = set(sk.descendants(sk.index(joints["pelvis"])))
    assert set(sk.indices(joints["spine"] + joints["shoulders"] + joints["hands"] + [joints["head"]])) <= upper
    assert not set(sk.indices(joints["hips"] + joints["knees"] + joints["feet"] + joints["toes"])) & upper
    assert all(len(joints[k]) == 2 and joints[k][0].startswith("Left") for k in ("hips", "knees", "feet", "toes", "shoulders", "hands"))
    for name, m in clips.items():
        role = spec["clips"]["default_role"]
        for rule in spec["clips"].get("role", []):
            if any(fnmatch.fnmatchcase(name, g) for g in rule["names"]):
                role = rule["role"]
        assert role == m.role, name


# ---------------------------------------------------------------------------------------------
# Lower body: contacts, floor, pelvis
# ---------------------------------------------------------------------------------------------


def test_nothing_goes_below_the_floor(fk):
    for name, (pos, ends) in fk.items():
        lowest = min(pos[..., 1].min(), ends[..., 1].min())
        assert lowest > -1.0, f"{name}: lowest point {lowest:.2f} cm"


@pytest.mark.parametrize("name", SAMPLE_CLIPS)
def test_stance_feet_stay_planted(fk, name):
    pos, _ = fk[name]
    root_speed = _horizontal_speed(pos[:, 0], SAMPLE_FPS)
    assert root_speed.mean() > 30.0, "the body should travel"
    counts = []
    for foot in ("LeftFoot", "RightFoot"):
        p = pos[:, _j(foot)]
        speed = _horizontal_speed(p, SAMPLE_FPS)
        planted = [(s, n) for s, n in _runs(speed < 3.0) if n >= 3]  # >= 4 frames still
        # a plant every gait cycle (at least 0.74 s apart for the jog), on the ground
        assert len(planted) >= 4, f"{foot}: stance phases {planted}"
        for s, n in planted:
            assert p[s : s + n + 1, 1].max() < 10.0, f"{foot} still in the air at frame {s}"
            assert root_speed[s : s + n].mean() > 20.0, "the body moves over the planted foot"
        counts.append(len(planted))
    assert abs(counts[0] - counts[1]) <= 1


def test_feet_alternate_and_gaits_differ(fk):
    periods, first = [], []
    for name in SAMPLE_CLIPS:
        pos, _ = fk[name]
        starts = {}
        for foot in ("LeftFoot", "RightFoot"):
            speed = _horizontal_speed(pos[:, _j(foot)], SAMPLE_FPS)
            starts[foot] = [s for s, n in _runs(speed < 3.0) if n >= 3]
        merged = sorted((s, f) for f, ss in starts.items() for s in ss)
        assert len(starts["LeftFoot"]) >= 2 and len(starts["RightFoot"]) >= 2, f"{name}: {starts}"
        feet = [f for _, f in merged]
        assert all(a != b for a, b in zip(feet, feet[1:])), f"{name}: feet do not alternate: {merged}"
        periods.append(np.diff(starts["LeftFoot"]).mean() / SAMPLE_FPS)
        first.append(merged[0][0])
    # cadence and the phase at frame 0 vary, so time alignment has work to do
    assert len({round(p, 2) for p in periods}) >= 6, periods
    assert len(set(first)) >= 5, first


def test_pelvis_bobs_and_sways(fk):
    pos, _ = fk["walk_straight"]
    hips = pos[:, 0]
    bob = hips[:, 1].max() - hips[:, 1].min()
    assert 1.0 < bob < 7.0, bob
    f = _facing(pos).mean(0)
    left = np.array([f[2], 0.0, -f[0]])
    lateral = (hips - hips[0]) @ left
    assert 2.0 < lateral.max() - lateral.min() < 10.0
    # the sway has the gait period: it reverses sign several times
    centred = lateral - lateral.mean()
    assert np.count_nonzero(np.diff(np.sign(centred)) != 0) >= 8


# ---------------------------------------------------------------------------------------------
# Upper body
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["walk_straight", "walk_curve", "jog"])
def test_arms_swing_with_the_opposite_leg(fk, name):
    pos, _ = fk[name]
    f = _facing(pos)
    hips = pos[:, 0]
    for side in ("Left", "Right"):
        hand = ((pos[:, _j(f"{side}Hand")] - hips) * f).sum(-1)
        foot = ((pos[:, _j(f"{side}Foot")] - hips) * f).sum(-1)
        corr = np.corrcoef(hand, foot)[0, 1]
        assert corr < -0.5, f"{side} hand vs {side} foot forward swing: correlation {corr:.2f}"
        assert np.ptp(hand) > 15.0  # a visible swing


def _lean(pos: np.ndarray) -> np.ndarray:
    """``(T,)`` sagittal angle (deg) of the hips-to-neck vector from vertical, forward positive."""
    v = pos[:, _j("Neck")] - pos[:, 0]
    fwd = (v * _facing(pos)).sum(-1)
    return np.degrees(np.arctan2(fwd, v[:, 1]))


def test_carry_box_leans_back(fk):
    walk, box = _lean(fk["walk_straight"][0]), _lean(fk["carry_box"][0])
    assert box.mean() <= walk.mean() - 8.0, (walk.mean(), box.mean())
    assert box.mean() < -8.0 and box.max() < 0.0  # clearly back, the whole time
    # both hands in front of the chest, at about the same height (holding one box)
    pos, _ = fk["carry_box"]
    f = _facing(pos)
    for side in ("Left", "Right"):
        ahead = ((pos[:, _j(f"{side}Hand")] - pos[:, _j("Spine2")]) * f).sum(-1)
        assert ahead.min() > 15.0
    dy = pos[:, _j("LeftHand"), 1] - pos[:, _j("RightHand"), 1]
    assert np.abs(dy).max() < 3.0


def test_action_arms(fk):
    # wave: right hand above the head, moving; left arm still swinging
    pos, ends = fk["wave"]
    sk = sample_skeleton()
    head_top = ends[:, list(sk.end_site_parents).index(_j("Head")), 1]
    rh = pos[:, _j("RightHand")]
    assert (rh[:, 1] > head_top).all()
    assert np.ptp(rh[:, 0]) > 10.0 or np.ptp(rh[:, 2]) > 10.0
    # arms out: hands at shoulder height, far out to the sides
    pos, _ = fk["arms_out"]
    f = _facing(pos)
    left = np.stack((f[:, 2], np.zeros(len(f)), -f[:, 0]), axis=-1)
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        hand = pos[:, _j(f"{side}Hand")]
        assert (np.abs(hand[:, 1] - pos[:, _j(f"{side}Arm"), 1]) < 12.0).all()
        assert (sign * ((hand - pos[:, 0]) * left).sum(-1) > 60.0).all()
    # punch: each hand reaches far forward at some point, and not both at once
    pos, _ = fk["punch"]
    f = _facing(pos)
    reach = {s: ((pos[:, _j(f"{s}Hand")] - pos[:, _j("Spine2")]) * f).sum(-1) for s in ("Left", "Right")}
    for s in reach:
        assert reach[s].max() > 45.0 and reach[s].min() < 30.0
    assert not ((reach["Left"] > 45.0) & (reach["Right"] > 45.0)).any()
    # carry cup: right forearm about horizontal, the hand steadier than the swinging left hand
    pos, _ = fk["carry_cup"]
    fore = pos[:, _j("RightHand")] - pos[:, _j("RightForeArm")]
    assert np.abs(np.degrees(np.arcsin(fore[:, 1] / np.linalg.norm(fore, axis=-1)))).max() < 25.0
    f = _facing(pos)
    rel = {s: ((pos[:, _j(f"{s}Hand")] - pos[:, 0]) * f).sum(-1) for s in ("Left", "Right")}
    assert np.ptp(rel["Right"]) < 0.5 * np.ptp(rel["Left"])


# ---------------------------------------------------------------------------------------------
# Paths and heading
# ---------------------------------------------------------------------------------------------


def _window_mean_angle(h: np.ndarray, frames: slice) -> float:
    return float(h[frames].mean())


def test_straight_walk_faces_and_travels_plus_z(fk):
    pos, _ = fk["walk_straight"]
    h = _heading(pos)
    assert np.abs(h).max() < 10.0  # only the pelvis twist
    d = pos[-1, 0] - pos[0, 0]
    assert d[2] > 400.0 and abs(d[0]) < 0.05 * d[2]


def test_curved_walk_heading_follows_the_path(fk):
    pos, _ = fk["walk_curve"]
    h = _heading(pos)
    assert np.abs(np.diff(h)).max() < 3.0  # smooth: no jumps from frame to frame
    total = _window_mean_angle(h, slice(-30, None)) - _window_mean_angle(h, slice(0, 30))
    assert 100.0 < total < 200.0, total  # a left turn
    # facing follows the path tangent (one-second windows average out the gait)
    f = _facing(pos)
    for s in range(0, len(pos) - 30, 15):
        d = pos[s + 30, 0] - pos[s, 0]
        fm = f[s : s + 31].mean(0)
        cos = (d @ fm) / (np.linalg.norm(d) * np.linalg.norm(fm))
        assert cos > math.cos(math.radians(15.0)), (s, math.degrees(math.acos(min(cos, 1.0))))


def test_sharp_turn_turns_by_the_intended_amount(fk):
    pos, _ = fk["turn_sharp"]
    h = _heading(pos)
    before = _window_mean_angle(h, slice(0, 30))
    after = _window_mean_angle(h, slice(-30, None))
    assert abs((after - before) - (-120.0)) < 12.0, after - before
    assert np.abs(np.diff(h)).max() < 8.0
    # the heading change happens within about two seconds, mid-clip
    t = np.arange(len(h)) / SAMPLE_FPS
    mid = (t > 1.7) & (t < 4.1)
    assert abs(h[mid][-1] - h[mid][0]) > 0.8 * abs(after - before)


def test_sidestep_travels_sideways(fk):
    pos, _ = fk["sidestep"]
    d = pos[-1, 0] - pos[0, 0]
    d[1] = 0.0
    assert np.linalg.norm(d) > 150.0
    f = _facing(pos)
    cos = (d @ f.mean(0)) / (np.linalg.norm(d) * np.linalg.norm(f.mean(0)))
    assert abs(cos) < 0.2, cos
    h = _heading(pos)
    assert np.ptp(h) < 10.0  # keeps facing while travelling
    left = np.array([f.mean(0)[2], 0.0, -f.mean(0)[0]])
    assert d @ left > 0.0  # to its left
