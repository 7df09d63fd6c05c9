"""HumanML3D's 263 features (:mod:`torchsplice.formats.humanml3d_features`), first step of the
HumanML3D export: known answers and properties on clips retargeted onto the SMPL body.

- the positions recovered from the features are the normalized positions (to 1e-5 m);
- the features do not change when the clip is moved or turned about the vertical;
- normalization: on the floor, at the origin, facing +Z;
- contacts: a foot that stands is in contact, one that moves is not;
- the Gaussian smoothing against its closed form.

(Checked in development against the format's own sample clip, ``HumanML3D/new_joints/012314.npy``
and its ``new_joint_vecs``, which is not shipped: features from its positions agree to 4e-3 away
from the last 20 frames and exactly at the first, contacts on every frame, and the positions
recovered from its features equal its ``new_joints`` to 2e-7 m. On short clips, 25 spliced
sample clips of 75 to 134 frames, the format's ``process_file`` gives these features to 2e-4 at
every frame; features re-derived from ``new_joints`` differ by up to 0.046 there, as the format's
own pipeline differs from itself on the same clips, 0.048: ``new_joints`` lacks the last frame.)
"""

from __future__ import annotations

import math

import pytest
import torch

from torchsplice.core.rotations import axis_angle_to_quat, quat_apply
from torchsplice.formats.humanml3d_features import (FEATURES, GROUPS, JOINTS, FeatureStats, features_to_positions,
                                                    gaussian_smooth, normalize_positions, pad_clips,
                                                    positions_to_features)
from torchsplice.ops.retarget import retarget_map, retarget_motions
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.specs.smpl import smpl22_skeleton


def _smpl_clips() -> list[torch.Tensor]:
    """The sample's clips on the SMPL body, as (T, 22, 3) positions in metres."""
    ms = [m.to(torch.float64) for m in sample_motions()]
    sk = smpl22_skeleton()
    rmap = retarget_map(ms[0].skeleton, load_spec("sample").bind(ms[0].skeleton), sk, load_spec("smpl22").bind(sk))
    return [m.global_positions() for m in retarget_motions(ms, rmap)]


CLIPS = _smpl_clips()


@pytest.mark.parametrize("k", range(len(CLIPS)))
def test_the_positions_recovered_from_the_features_are_the_normalized_positions(k):
    p = CLIPS[k]
    f = positions_to_features(p)
    assert f.shape == (p.shape[0] - 1, FEATURES) and bool(torch.isfinite(f).all())
    back = features_to_positions(f)
    assert float((back - normalize_positions(p)[:-1]).abs().max()) < 1e-5


def test_the_features_do_not_change_when_the_clip_is_moved_or_turned_about_the_vertical():
    p = CLIPS[1]  # the curved walk
    turn = axis_angle_to_quat(torch.tensor([0.0, 2.2, 0.0], dtype=torch.float64))
    moved = quat_apply(turn.expand(p.shape[:-1] + (4,)), p) + torch.tensor([3.0, 0.4, -7.0], dtype=torch.float64)
    assert float((positions_to_features(moved) - positions_to_features(p)).abs().max()) < 1e-9


def test_normalization_puts_the_clip_on_the_floor_at_the_origin_facing_plus_z():
    p = normalize_positions(CLIPS[2] + torch.tensor([1.0, 0.3, 2.0], dtype=torch.float64))
    assert float(p[..., 1].min()) == pytest.approx(0.0, abs=1e-12)
    assert float(p[0, 0, 0]) == pytest.approx(0.0, abs=1e-12) and float(p[0, 0, 2]) == pytest.approx(0.0, abs=1e-12)
    across = (p[0, 2] - p[0, 1]) + (p[0, 17] - p[0, 16])  # right minus left, hips and shoulders
    forward = torch.linalg.cross(torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64), across)
    forward = forward / forward.norm()
    assert float(forward[2]) > 1 - 1e-9  # +Z


def test_contacts_are_on_for_a_standing_foot_and_off_for_a_moving_one():
    p = CLIPS[0][:40].clone()
    p[:] = p[0]  # everything still
    f = positions_to_features(p)
    assert bool((f[:, 259:263] == 1).all())
    p[:, 7, 2] += torch.arange(40, dtype=torch.float64) * 0.1  # the left ankle slides 10 cm a frame
    f = positions_to_features(p)
    assert bool((f[:, 259] == 0).all()) and bool((f[:, 260:263] == 1).all())


def test_the_root_height_and_the_yaw_velocity_of_a_known_turn():
    """A figure standing still and turning about the vertical at a constant rate: the yaw feature
    is the half-angle per frame where the heading's smoothing (80 frames each side) reaches no end."""
    p0 = normalize_positions(CLIPS[0])[0]
    T, rate = 300, 0.02  # radians a frame
    turns = axis_angle_to_quat(torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)[None] * (rate * torch.arange(T))[:, None])
    root = p0[0].clone()
    p = quat_apply(turns[:, None].expand(T, JOINTS, 4), (p0 - root).expand(T, JOINTS, 3)) + root
    f = positions_to_features(p)
    assert torch.allclose(f[80:-81, 0], torch.full((T - 162,), -rate / 2, dtype=torch.float64), atol=1e-9)
    assert torch.allclose(f[:, 3], p[:-1, 0, 1] - p[..., 1].min(), atol=1e-9)  # the root's height above the floor
    # it turns past 180 degrees (6 radians in all): the positions still come back (the turn's short
    # quaternion, not the one whose sign flips where the heading crosses 180 degrees)
    assert float((features_to_positions(f) - normalize_positions(p)[:-1]).abs().max()) < 1e-5


def test_gaussian_smoothing_against_its_closed_form():
    x = torch.zeros(101, dtype=torch.float64)
    x[50] = 1.0
    y = gaussian_smooth(x, 3.0)
    t = torch.arange(-12, 13, dtype=torch.float64)
    k = torch.exp(-0.5 * (t / 3.0) ** 2)
    assert torch.allclose(y[38:63], k / k.sum(), atol=1e-15) and float(y.sum()) == pytest.approx(1.0)
    c = torch.full((30, 2), 4.5, dtype=torch.float64)
    assert torch.allclose(gaussian_smooth(c, 20.0), c)  # the ends padded with their own values


def test_shapes_are_checked():
    with pytest.raises(ValueError, match=r"\(\.\.\., T, 22, 3\)"):
        positions_to_features(torch.zeros(10, 21, 3))
    with pytest.raises(ValueError, match="at least 2 frames"):
        positions_to_features(torch.zeros(1, 22, 3))
    with pytest.raises(ValueError, match="263 columns"):
        features_to_positions(torch.zeros(5, 262))
    assert math.isclose(FEATURES, 4 + 63 + 126 + 66 + 4)


def test_resampling_to_20_fps_keeps_bone_lengths_and_lands_on_the_source_frames():
    """The export resamples rotations (align.curve.resample_motion), not positions: interpolating
    positions would shorten a fast limb's bones between frames."""
    from torchsplice.align.curve import resample_motion

    m = sample_motions()[3].to(torch.float64)  # the side-step, 30 fps
    r = resample_motion(m, 20.0)
    assert r.num_frames == int((m.num_frames - 1) * 20 / 30) + 1 and r.fps == 20.0
    p, q = m.global_positions(), r.global_positions()
    assert torch.allclose(q[::2], p[::3][:q[::2].shape[0]], atol=1e-6)  # every second 20 fps frame is a 30 fps one
    sk = m.skeleton
    def bones(x):
        return torch.stack([(x[:, j] - x[:, sk.parents[j]]).norm(dim=-1) for j in range(1, sk.num_joints)], 1)
    assert float((bones(q) - bones(p)[:1]).abs().max()) < 1e-5  # cm; float32 rotations underneath
    assert resample_motion(m, 30.0) is m


def test_the_statistics_are_the_formats_and_do_not_depend_on_how_the_clips_are_cut():
    g = torch.Generator().manual_seed(3)
    clips = [torch.randn(n, FEATURES, generator=g, dtype=torch.float64) * torch.linspace(0.1, 3, FEATURES) + 2
             for n in (7, 40, 13)]
    stats = FeatureStats()
    for c in clips:
        stats.add(c)
    mean, std = stats.result()
    data = torch.cat(clips)
    assert torch.allclose(mean, data.mean(0), atol=1e-12)
    plain = data.std(0, unbiased=False)
    for a, b in GROUPS:  # one value per kind: the mean of its columns' standard deviations
        assert torch.allclose(std[a:b], plain[a:b].mean().expand(b - a), atol=1e-10)
    whole = FeatureStats()
    whole.add(data)
    assert torch.allclose(whole.result()[0], mean, atol=1e-12) and torch.allclose(whole.result()[1], std, atol=1e-12)
    assert [b - a for a, b in GROUPS] == [1, 2, 1, 63, 126, 66, 4]
    with pytest.raises(ValueError, match="no features"):
        FeatureStats().result()


def test_clips_of_other_lengths_in_one_padded_batch_give_each_clip_its_own_features():
    g = torch.Generator().manual_seed(3)
    clips = []
    for k, n in ((0, 7), (1, 40), (2, 133)):
        clips.append(CLIPS[k][:n] + 0.01 * torch.randn(n, 22, 3, generator=g, dtype=torch.float64))
    batch = positions_to_features(pad_clips(clips))
    for i, c in enumerate(clips):
        alone = positions_to_features(c)
        assert torch.allclose(batch[i, :c.shape[0] - 1], alone, atol=1e-12), i


def test_a_heading_along_minus_z_turns_about_the_vertical():
    """Frames facing exactly away from the first frame's heading (a half turn: the smallest rotation
    onto +Z has no unique axis there) still turn about Y, so the positions come back rigidly."""
    p = normalize_positions(CLIPS[0])
    half = axis_angle_to_quat(torch.tensor([0.0, math.pi, 0.0], dtype=torch.float64))
    turned = quat_apply(half.expand(p.shape[:-1] + (4,)), p)
    both = torch.cat([p, turned + (p[-1, 0] - turned[0, 0]) * torch.tensor([1.0, 0.0, 1.0], dtype=torch.float64)])
    back = features_to_positions(positions_to_features(both))
    assert float((back - normalize_positions(both)[:-1]).abs().max()) < 1e-5
