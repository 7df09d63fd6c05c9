"""Quality metrics (foot skate, arm-leg phase, posture): known answers that can fail.

Each metric is checked against a value built independently here: a synthetic leg rig whose
stance foot slides at a known speed, the sample's gait parameters, a walk whose upper body is
moved half a gait cycle in time, the sample's box carry (which leans back), real Bandai Namco
walks. Tolerances are claimed in float64.
"""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
import torch

from torchsplice.core.motion import Motion
from torchsplice.core.rotations import axis_angle_to_quat, quat_apply, quat_mul
from torchsplice.core.skeleton import Skeleton
from torchsplice.evaluation.metrics import (
    ArmLegPhase, FootSkate, arm_leg_phase, arm_leg_phase_stats, foot_skate, foot_skate_stats, gait_period,
    leg_length, phase_range, posture_kept, posture_offset,
)
from torchsplice.formats.bvh import read_bvh
from torchsplice.specs import SkeletonRoles, load_spec
from torchsplice.splice import SpliceOptions, splice
from torchsplice.splice.clips import ClipTensors, clips_to_tensors

F64 = torch.float64
BANDAI = "bandai_namco_research_motiondataset"
REAL_WALKS = ("dataset-1_walk_normal_001", "dataset-2_walk_normal_008", "dataset-2_walk_elderly_006",
              "dataset-2_walk_masculine_022", "dataset-2_walk-turn-left_normal_025")
WALKS = ("walk_straight", "walk_curve", "turn_sharp")


# ------------------------------------------------------------------------------ fixtures, helpers


@pytest.fixture(scope="module")
def real(mocap_dir):
    """A few real Bandai Namco walks (float64) and their roles."""
    clips = [read_bvh(mocap_dir / BANDAI / f"{n}.bvh", dtype=F64) for n in REAL_WALKS]
    return clips, load_spec("bandai_namco").bind(clips[0].skeleton)


def moved(m: Motion, degrees: float, shift) -> Motion:
    """``m`` turned about the up (Y) axis by ``degrees`` about the origin, then translated."""
    q = axis_angle_to_quat(torch.tensor([0.0, math.radians(degrees), 0.0], dtype=m.dtype))
    rot = m.rotations.clone()
    rot[:, 0] = quat_mul(q.expand_as(rot[:, 0]), rot[:, 0])
    root = quat_apply(q.expand_as(rot[:, 0]), m.root_translation) + torch.tensor(shift, dtype=m.dtype)
    return replace(m, rotations=rot, root_translation=root)


def upper_shifted(m: Motion, roles: SkeletonRoles, frames: int) -> Motion:
    """``m`` with its upper-body local rotations taken ``frames`` later (the clip shortened)."""
    up = list(roles.upper_body)
    rot = m.rotations[:-frames].clone()
    rot[:, up] = m.rotations[frames:, up]
    trans = None if m.translations is None else m.translations[:-frames]
    return replace(m, rotations=rot, root_translation=m.root_translation[:-frames], translations=trans)


# A two-legged rig: legs straight down (thigh 45, shin 45 cm), every joint unrotated; each
# foot is put in place by animating its hip's local translation.
RIG_NAMES = ("Root", "LHip", "LKnee", "LFoot", "RHip", "RKnee", "RFoot", "Spine", "LArm", "RArm")
RIG = Skeleton(
    names=RIG_NAMES, parents=(-1, 0, 1, 2, 0, 4, 5, 0, 7, 7),
    offsets=[(0, 0, 0), (10, 90, 0), (0, -45, 0), (0, -45, 0), (-10, 90, 0), (0, -45, 0), (0, -45, 0),
             (0, 95, 0), (15, 45, 0), (-15, 45, 0)],
    channels=(("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),)
    + (("Zrotation", "Xrotation", "Yrotation"),) * 9,
)
RIG_ROLES = SkeletonRoles(root=0, pelvis=7, spine=(7,), hips=(1, 4), knees=(2, 5), feet=(3, 6), shoulders=(8, 9),
                          toes=None, hands=None, head=None, upper_body=(7, 8, 9), lower_body=tuple(range(7)),
                          up_axis=1, units="cm")


def sliding_gait(slide: float, swing: float = 150.0, cycle: int = 40, stance: int = 24, T: int = 150,
                 fps: float = 30.0) -> Motion:
    """Feet on :data:`RIG`: in stance (on the floor) each slides forward at ``slide`` cm/s, in
    swing it arcs 15 cm high moving forward at ``swing`` cm/s; the right foot half a cycle later."""
    t = torch.arange(T, dtype=F64)
    trans = RIG.offsets.expand(T, -1, -1).clone()
    for side, hip, lateral in ((0, 1, 10.0), (1, 4, -10.0)):
        u = torch.remainder(t - side * cycle // 2, cycle)
        in_swing = u >= stance
        speed = torch.where(in_swing, torch.tensor(swing, dtype=F64), torch.tensor(slide, dtype=F64))
        forward = torch.cumsum(speed, 0) / fps
        height = torch.where(in_swing, 15.0 * torch.sin(math.pi * (u - stance + 1) / (cycle - stance + 1)), torch.zeros(T, dtype=F64))
        trans[:, hip] = torch.stack((torch.full((T,), lateral, dtype=F64), height + 90.0, forward), -1)
    rot = torch.zeros(T, len(RIG_NAMES), 4, dtype=F64)
    rot[..., 0] = 1.0
    return Motion(RIG, rot, torch.zeros(T, 3, dtype=F64), fps, translations=trans, name=f"slide_{slide}")


# ------------------------------------------------------------------------------ foot skate


@pytest.mark.parametrize("slide", [0.0, 8.0, 20.0])
def test_sliding_stance_foot_measures_its_speed(slide):
    m = sliding_gait(slide)
    s = foot_skate_stats([m], RIG_ROLES)
    assert isinstance(s, FootSkate) and s.joints == (3, 6)
    assert float(leg_length(clips_to_tensors([m], RIG, F64).positions, RIG_ROLES)) == pytest.approx(90.0)
    assert float(s.speed[0]) == pytest.approx(slide, rel=0.03, abs=1e-9)
    # stance is 24 of 40 frames; the first and last stance frames mix in the swing's speed
    assert 0.45 < float(s.contact_fraction[0]) < 0.6


def test_no_contact_is_zero_not_nan():
    m = sliding_gait(60.0, swing=200.0)  # sliding faster than 0.3 leg lengths per second: never contact
    s = foot_skate_stats([m], RIG_ROLES)
    assert int(s.contact_frames[0]) == 0 and float(s.speed[0]) == 0.0 and float(s.contact_fraction[0]) == 0.0


def test_sample_walks_keep_their_feet_planted(sample_f64):
    clips, _, roles = sample_f64
    s = foot_skate_stats([clips[n] for n in WALKS], roles)
    assert s.joints == roles.feet + roles.toes
    assert (s.speed < 5.0).all(), s.speed  # measured 3.3-3.4 cm/s (heel rocker and heel-off)
    assert ((s.contact_fraction > 0.4) & (s.contact_fraction < 0.7)).all(), s.contact_fraction


def test_real_walks_skate_little(real):
    clips, roles = real
    s = foot_skate_stats(clips, roles)
    assert ((s.speed > 1.0) & (s.speed < 8.0)).all(), s.speed  # measured 3.9-4.9 cm/s
    assert (s.contact_fraction > 0.3).all(), s.contact_fraction


def test_metrics_ignore_where_the_clip_is_in_the_world(sample_f64):
    clips, _, roles = sample_f64
    base = [clips["walk_curve"], clips["carry_box"]]
    away = [moved(m, 73.0, (250.0, 12.0, -400.0)) for m in base]
    for metric in (foot_skate, arm_leg_phase, gait_period):
        torch.testing.assert_close(metric(away, roles), metric(base, roles), rtol=1e-9, atol=1e-9)
    torch.testing.assert_close(posture_offset(away, roles), posture_offset(base, roles), rtol=1e-9, atol=1e-9)
    # a real change is seen: the same clip sliding forward 30 cm/s skates more
    slid = replace(base[0], root_translation=base[0].root_translation + torch.arange(base[0].num_frames, dtype=F64)[:, None] * torch.tensor([0.0, 0.0, 0.5], dtype=F64))
    assert float(foot_skate([slid], roles)[0]) > float(foot_skate(base[:1], roles)[0]) + 5.0


# ------------------------------------------------------------------------------ gait period, arm-leg phase


def test_gait_period_matches_the_sample_cadence(sample_f64):
    clips, _, roles = sample_f64
    period = gait_period([clips["walk_straight"], clips["jog"], clips["carry_box"]], roles)
    expected = torch.tensor([1 / 0.95, 1 / 1.35, 1 / 0.86], dtype=F64)  # cadences of the generator
    torch.testing.assert_close(period, expected, rtol=0.03, atol=0.0)


def test_sample_walk_is_in_phase_and_deterministic(sample_f64):
    clips, _, roles = sample_f64
    w = clips["walk_straight"]
    s = arm_leg_phase_stats([w, w], roles)
    assert isinstance(s, ArmLegPhase)
    assert float(s.lag[0]) == float(s.lag[1]) == float(arm_leg_phase([w], roles)[0])
    assert abs(float(s.lag[0])) < 0.05  # measured -0.016
    assert (s.correlation > 0.9).all()
    for n in WALKS:
        assert abs(float(arm_leg_phase([clips[n]], roles)[0])) < 0.05


def test_half_cycle_upper_body_is_out_of_phase(sample_f64, real):
    clips, _, roles = sample_f64
    w = clips["walk_straight"]
    half = round(float(gait_period([w], roles)[0]) * w.fps / 2)
    assert half == 16  # 1.057 s cycle at 30 fps
    s = arm_leg_phase_stats([upper_shifted(w, roles, half)], roles)
    assert 0.45 < abs(float(s.lag[0])) <= 0.5, s.lag  # measured 0.48 (wrapped to [-0.5, 0.5))
    assert 0.45 < abs(float(s.left[0])) and 0.45 < abs(float(s.right[0]))
    low, high = phase_range(*real)
    assert not low <= float(s.lag[0]) <= high
    assert low - 0.05 <= float(arm_leg_phase([w], roles)[0]) <= high + 0.05


@pytest.mark.parametrize("frames", [4, 8, 12, 19, 26])
def test_upper_body_moved_in_time_moves_the_lag(sample_f64, frames):
    """Upper body taken ``frames`` later: the arms lead by frames / cycle more, wrapped to [-0.5, 0.5)."""
    clips, _, roles = sample_f64
    w = clips["walk_straight"]
    base = float(arm_leg_phase([w], roles)[0])
    cycle = float(gait_period([w], roles)[0]) * w.fps
    lag = float(arm_leg_phase([upper_shifted(w, roles, frames)], roles)[0])
    expected = (base - frames / cycle + 0.5) % 1.0 - 0.5
    assert -0.5 <= lag < 0.5
    assert abs((lag - expected + 0.5) % 1.0 - 0.5) < 0.02, (lag, expected)


def test_real_walks_lie_in_a_plausible_band(real):
    clips, roles = real
    s = arm_leg_phase_stats(clips, roles)
    assert ((s.period > 0.9) & (s.period < 1.4)).all(), s.period  # measured 1.00-1.21 s
    assert ((s.lag > -0.12) & (s.lag < 0.06)).all(), s.lag  # measured -0.064 to +0.011
    assert (s.correlation > 0.85).all(), s.correlation
    low, high = phase_range(clips, roles)
    assert low == pytest.approx(float(s.lag.min())) and high == pytest.approx(float(s.lag.max()))
    assert phase_range(clips, roles, margin=0.1) == pytest.approx((low - 0.1, high + 0.1))
    # the same walk, its upper body half a cycle late
    half = round(float(s.period[1]) * clips[1].fps / 2)
    shifted = float(arm_leg_phase([upper_shifted(clips[1], roles, half)], roles)[0])
    assert abs(shifted) > 0.4 and not low <= shifted <= high


def test_standing_still_has_no_gait_cycle(sample_f64):
    clips, _, roles = sample_f64
    w = clips["walk_straight"]
    still = replace(w, rotations=w.rotations[:1].expand(90, -1, -1).clone(), root_translation=w.root_translation[:1].expand(90, -1).clone())
    assert math.isnan(float(gait_period([still], roles)[0]))
    assert math.isnan(float(arm_leg_phase([still], roles)[0]))
    assert float(foot_skate([still], roles)[0]) == 0.0
    assert phase_range([still, w], roles) == pytest.approx((float(arm_leg_phase([w], roles)[0]),) * 2)
    with pytest.raises(ValueError, match="gait cycle"):
        phase_range([still], roles)


# ------------------------------------------------------------------------------ posture


def test_posture_of_a_clip_against_itself_is_kept(sample_f64):
    clips, _, roles = sample_f64
    ms = [clips[n] for n in ("walk_straight", "carry_box", "wave")]
    assert posture_kept(ms, ms, roles).abs().max() == 0.0


def test_box_carry_leans_back(sample_f64):
    clips, _, roles = sample_f64
    walk, box = posture_offset([clips["walk_straight"], clips["carry_box"]], roles)
    assert 30.0 < float(walk[1]) < 40.0  # shoulders about 36 cm above the pelvis joint
    assert float(walk[2] - box[2]) > 6.0  # measured 9.2 cm further back
    assert abs(float(walk[0] - box[0])) < 1.0
    assert float(posture_kept([clips["carry_box"]], [clips["walk_straight"]], roles)[0]) > 6.0


def test_splice_keeps_the_action_posture_and_posture_off_does_not(sample_f64):
    clips, spec, roles = sample_f64
    walk, box = clips["walk_straight"], clips["carry_box"]
    kept = splice(walk, box, spec, options=SpliceOptions(dtype=F64)).motion
    lost = splice(walk, box, spec, options=SpliceOptions(dtype=F64, posture=False)).motion
    d = posture_kept([kept, lost], [box, box], roles)
    assert float(d[0]) < 1.0  # measured 0.07 cm
    assert float(d[1]) > 6.0  # measured 9.2 cm: the walk's upright posture
    # the lower body is the walk's: its foot skate stays the walk's
    assert float(foot_skate([kept], roles)[0]) == pytest.approx(float(foot_skate([walk], roles)[0]), abs=0.5)


# ------------------------------------------------------------------------------ batching


def test_padded_batch_equals_single_clips(sample_f64):
    clips, _, roles = sample_f64
    names = ("jog", "walk_curve", "carry_box", "walk_straight")  # 150, 210, 210, 180 frames
    ms = [clips[n] for n in names]
    ct = clips_to_tensors(ms, ms[0].skeleton, dtype=F64)
    assert len(set(ct.lengths.tolist())) > 1
    # garbage on the padding: it must not leak into any clip's value
    pad = torch.arange(ct.positions.shape[1])[None, :] >= ct.lengths[:, None]
    noisy = torch.where(pad[..., None, None], torch.randn_like(ct.positions) * 500, ct.positions)
    ct = ClipTensors(ct.rotations, ct.translations, ct.lengths, noisy, ct.global_rotations)
    batch = {"skate": foot_skate_stats(ct, roles, 30.0), "phase": arm_leg_phase_stats(ct, roles, 30.0),
             "posture": posture_offset(ct, roles)}
    for b, m in enumerate(ms):
        one_s, one_p = foot_skate_stats([m], roles), arm_leg_phase_stats([m], roles)
        for key in ("speed", "contact_fraction", "contact_frames"):
            torch.testing.assert_close(getattr(batch["skate"], key)[b], getattr(one_s, key)[0], rtol=1e-9, atol=1e-9)
        for key in ("lag", "left", "right", "period", "correlation"):
            torch.testing.assert_close(getattr(batch["phase"], key)[b], getattr(one_p, key)[0], rtol=1e-9, atol=1e-9)
        torch.testing.assert_close(batch["posture"][b], posture_offset([m], roles)[0], rtol=1e-9, atol=1e-9)


def test_clip_tensors_need_a_frame_rate_and_motions_their_own(sample_f64):
    clips, _, roles = sample_f64
    w = clips["walk_straight"]
    with pytest.raises(ValueError, match="fps"):
        foot_skate(clips_to_tensors([w], w.skeleton, dtype=F64), roles)
    with pytest.raises(ValueError, match="frame rates"):
        foot_skate([w], roles, fps=60.0)
    assert float(foot_skate([w], roles, fps=30.0)[0]) == float(foot_skate([w], roles)[0])
