"""Heading frames, foot contacts, run counting and gait summaries: known answers on hand-made
inputs, and the gait of the built-in sample's straight walk."""

import math

import pytest
import torch

from torchsplice.core.rotations import axis_angle_to_quat, quat_angle, quat_apply, quat_to_rotmat
from torchsplice.sample import sample_motion
from torchsplice.specs import load_spec
from torchsplice.kinematics.contacts import count_runs, foot_contacts, gait_summary
from torchsplice.kinematics.heading import heading_frame, lateral_axis, to_heading_frame

F64 = torch.float64


def unit(axis: int) -> torch.Tensor:
    e = torch.zeros(3, dtype=F64)
    e[axis] = 1.0
    return e


def about(axis: int, angle: float) -> torch.Tensor:
    """Quaternion of a rotation by ``angle`` radians about world axis ``axis``."""
    return axis_angle_to_quat(unit(axis) * angle)


# ------------------------------------------------------------------------------ heading frames


@pytest.mark.parametrize("up", [0, 1, 2])
def test_heading_frame_identity_when_hips_lie_along_the_lateral_axis(up):
    lat = lateral_axis(up)
    left = 9.0 * unit(lat) + 3.0 * unit(up)  # the hips' height does not matter
    right = -9.0 * unit(lat) + 3.0 * unit(up)
    H = heading_frame(left, right, up)
    assert torch.allclose(quat_to_rotmat(H), torch.eye(3, dtype=F64), atol=1e-12)


def test_heading_frame_y_up_lateral_is_x():
    """For Y up the hips along +x (left) give the identity (the documented convention)."""
    H = heading_frame(torch.tensor([9.0, 95.0, 0.0], dtype=F64), torch.tensor([-9.0, 95.0, 0.0], dtype=F64), 1)
    assert torch.allclose(quat_to_rotmat(H), torch.eye(3, dtype=F64), atol=1e-12)


@pytest.mark.parametrize("up", [0, 1, 2])
@pytest.mark.parametrize("deg", [0.0, 30.0, 73.0, 135.0, -100.0, 179.0])
def test_heading_frame_follows_a_turn_about_the_up_axis(up, deg):
    lat = lateral_axis(up)
    q = about(up, math.radians(deg))
    left = quat_apply(q, 9.0 * unit(lat)) + 2.0 * unit(up)
    right = quat_apply(q, -9.0 * unit(lat)) - 1.0 * unit(up)  # tilted hips: only the floor projection counts
    H = heading_frame(left, right, up)
    assert float(quat_angle(H, q)) < 1e-9


@pytest.mark.parametrize("up", [0, 1, 2])
def test_heading_frame_is_a_proper_rotation_keeping_up(up):
    g = torch.Generator().manual_seed(up)
    left, right = torch.randn(200, 3, dtype=F64, generator=g) * 20, torch.randn(200, 3, dtype=F64, generator=g) * 20
    R = quat_to_rotmat(heading_frame(left, right, up))
    eye = torch.eye(3, dtype=F64).expand_as(R)
    assert torch.allclose(R.transpose(-1, -2) @ R, eye, atol=1e-12)
    assert torch.allclose(torch.linalg.det(R), torch.ones(200, dtype=F64), atol=1e-12)
    # the frame's up column is the world up axis, its lateral column the floor-projected hip vector
    assert torch.allclose(R[:, :, up], unit(up).expand(200, 3), atol=1e-12)
    v = left - right
    v[:, up] = 0
    v = v / v.norm(dim=-1, keepdim=True)
    assert torch.allclose(R[:, :, lateral_axis(up)], v, atol=1e-12)


def test_heading_frame_batched_shapes_and_bad_input():
    left = torch.randn(4, 5, 3, dtype=F64)
    assert heading_frame(left, -left, 1).shape == (4, 5, 4)
    with pytest.raises(ValueError):
        heading_frame(left, left[..., :2], 1)
    with pytest.raises(ValueError):
        heading_frame(left, -left, 3)


@pytest.mark.parametrize("up", [0, 1, 2])
def test_to_heading_frame_origin_and_invariance_to_moving_and_turning(up):
    g = torch.Generator().manual_seed(10 + up)
    lat = lateral_axis(up)
    T, K = 7, 5
    origin = torch.randn(T, 3, dtype=F64, generator=g) * 50
    pts = origin[:, None] + torch.randn(T, K, 3, dtype=F64, generator=g) * 30
    left = origin + quat_apply(about(up, 0.3), 9.0 * unit(lat))
    right = origin - quat_apply(about(up, 0.3), 9.0 * unit(lat))
    H = heading_frame(left, right, up)
    local = to_heading_frame(torch.cat((origin[:, None], pts), 1), origin, H)
    assert torch.allclose(local[:, 0], torch.zeros(T, 3, dtype=F64), atol=1e-12)  # the origin maps to 0
    # distances are kept
    assert torch.allclose(local[:, 1:].norm(dim=-1), (pts - origin[:, None]).norm(dim=-1), atol=1e-9)
    # turning everything about the up axis and moving it gives the same local coordinates
    q = about(up, math.radians(73.0))
    shift = torch.randn(3, dtype=F64, generator=g) * 100
    move = lambda p: quat_apply(q, p) + shift  # noqa: E731
    H2 = heading_frame(move(left), move(right), up)
    local2 = to_heading_frame(move(pts), move(origin), H2)
    assert torch.allclose(local2, local[:, 1:], atol=1e-9)
    # ... while turning the points alone does change them (the check can fail)
    moved_alone = to_heading_frame(move(pts), move(origin), H)
    assert (moved_alone - local[:, 1:]).abs().max() > 1.0


def test_to_heading_frame_known_answer():
    """Hips turned 90 degrees about Y (left hip along -z): a point ahead (+x world) is at +z local."""
    q = about(1, math.pi / 2)  # x -> -z, z -> x
    left, right = quat_apply(q, torch.tensor([9.0, 0, 0], dtype=F64)), quat_apply(q, torch.tensor([-9.0, 0, 0], dtype=F64))
    H = heading_frame(left, right, 1)
    p = to_heading_frame(torch.tensor([[10.0, 5.0, 0.0]], dtype=F64), torch.zeros(3, dtype=F64), H)
    assert torch.allclose(p, torch.tensor([[0.0, 5.0, 10.0]], dtype=F64), atol=1e-12)


# ------------------------------------------------------------------------------ runs


def mask(*rows):
    return torch.tensor([[c == "1" for c in r] for r in rows])


def test_count_runs_known_answers():
    m = mask("0110011101", "1100000011", "0000000000", "1111111111")
    assert count_runs(m).tolist() == [3, 2, 0, 1]
    assert count_runs(m, min_length=2).tolist() == [2, 2, 0, 1]
    assert count_runs(m, min_length=3).tolist() == [1, 0, 0, 1]
    assert count_runs(m, min_length=11).tolist() == [0, 0, 0, 0]
    # interior: runs touching the first or last frame do not count
    assert count_runs(m, interior=True).tolist() == [2, 0, 0, 0]
    assert count_runs(m, min_length=3, interior=True).tolist() == [1, 0, 0, 0]


def test_count_runs_trailing_dimensions():
    m = torch.stack((mask("0101010"), mask("0111000")), -1)  # (1, 7, 2)
    assert count_runs(m).tolist() == [[3, 1]]
    assert count_runs(m, min_length=2).tolist() == [[0, 1]]
    assert count_runs(m, interior=True).tolist() == [[3, 1]]


# ------------------------------------------------------------------------------ contacts


def sliding_foot(speed: float, T: int = 30, fps: float = 30.0) -> torch.Tensor:
    """``(1, T, 1, 3)`` a foot on the floor moving along +x at ``speed`` units per second."""
    t = torch.arange(T, dtype=F64) / fps
    p = torch.zeros(1, T, 1, 3, dtype=F64)
    p[0, :, 0, 0] = speed * t
    p[0, :, 0, 2] = 5.0
    return p


@pytest.mark.parametrize("speed, contact", [(0.0, True), (40.0, True), (55.0, True), (65.0, False), (200.0, False)])
def test_foot_contacts_speed_threshold(speed, contact):
    leg = torch.tensor([100.0], dtype=F64)  # threshold 0.6 leg lengths per second = 60 units/s
    c = foot_contacts(sliding_foot(speed), torch.tensor([30]), 30.0, leg, up_axis=1)
    assert c.shape == (1, 30, 1)
    assert bool(c.all()) is contact and bool(c.any()) is contact


def test_foot_contacts_height_threshold_and_padding():
    T = 20
    p = sliding_foot(0.0, T)
    p[0, 10:, 0, 1] = 20.0  # lifted by 0.2 leg lengths > 0.12
    c = foot_contacts(p, torch.tensor([15]), 30.0, torch.tensor([100.0], dtype=F64))
    assert c[0, :10, 0].all() and not c[0, 10:, 0].any()  # lifted frames and padding (>= 15) are off
    p[0, 10:, 0, 1] = 10.0  # 0.1 leg lengths: still near the floor
    c = foot_contacts(p, torch.tensor([20]), 30.0, torch.tensor([100.0], dtype=F64))
    assert c.all()


# ------------------------------------------------------------------------------ gait summary


@pytest.fixture(scope="module")
def walk():
    m = sample_motion("walk_straight", torch.float64)
    return m, load_spec("sample").bind(m.skeleton)


def summary(positions, roles, fps=30.0, lengths=None):
    lengths = torch.tensor([positions.shape[1]]) if lengths is None else lengths
    return gait_summary(positions, lengths, fps, roles.feet, roles.hips, roles.root, roles.up_axis)


def test_gait_summary_of_the_sample_walk(walk):
    m, roles = walk
    p = m.global_positions()[None]
    g = summary(p, roles)
    assert min(g.swings[0].tolist()) >= 3
    assert float(g.travel[0]) > 3.0
    assert float(g.duration[0]) == pytest.approx(m.num_frames / 30.0)
    # travel is the root's floor path over the leg length
    leg = (p[0, 0, list(roles.hips)] - p[0, 0, list(roles.feet)]).norm(dim=-1).mean()
    step = p[0, 1:, roles.root] - p[0, :-1, roles.root]
    step[:, roles.up_axis] = 0
    assert float(g.travel[0]) == pytest.approx(float(step.norm(dim=-1).sum() / leg), rel=1e-9)
    # the swings alternate: each foot's contact mask has interior gaps
    contacts = foot_contacts(p[:, :, list(roles.feet)], torch.tensor([m.num_frames]), 30.0, leg[None])
    assert bool(contacts[0, :, 0].any()) and not bool(contacts[0, :, 0].all())


def test_gait_summary_of_a_frozen_frame(walk):
    m, roles = walk
    p = m.global_positions()[None, 40:41].expand(1, 90, -1, -1).contiguous()
    g = summary(p, roles)
    assert g.swings[0].tolist() == [0, 0]
    assert float(g.travel[0]) == 0.0


def test_gait_summary_batched_with_padding(walk):
    """A clip padded into a batch gives the same summary as alone; padding adds no travel or steps."""
    m, roles = walk
    p = m.global_positions()
    half = p[:90]
    padded = torch.cat((half, half[-1:].expand(90, -1, -1)))
    both = torch.stack((p, padded))
    g = summary(both, roles, lengths=torch.tensor([180, 90]))
    alone = summary(half[None], roles)
    assert g.swings[1].tolist() == alone.swings[0].tolist()
    assert float(g.travel[1]) == pytest.approx(float(alone.travel[0]), rel=1e-12)
    assert float(g.travel[0]) > 1.8 * float(g.travel[1])
    assert g.duration.tolist() == pytest.approx([6.0, 3.0])


def test_foot_contacts_of_a_padded_clip_equal_the_clip_alone():
    """Padding (the last frame repeated) must not change a clip's contacts: at its last valid
    frame the speed is a backward difference alone, not a central difference with the padding."""
    leg = torch.tensor([100.0], dtype=F64)
    p = sliding_foot(100.0, 20)  # faster than 60 units/s: never in contact
    alone = foot_contacts(p[:, :10], torch.tensor([10]), 30.0, leg)
    padded = p.clone()
    padded[:, 10:] = p[:, 9:10]
    batched = foot_contacts(padded, torch.tensor([10]), 30.0, leg)
    assert not alone.any()
    assert torch.equal(batched[:, :10], alone)


def test_gait_summary_of_a_clip_does_not_depend_on_its_batch(walk):
    """Every truncation of the walk, summarised alone and padded in a batch beside the whole walk."""
    m, roles = walk
    p = m.global_positions()
    T = p.shape[0]
    lengths = list(range(20, T, 1))
    alone = [summary(p[None, :n], roles) for n in lengths]
    padded = torch.stack([torch.cat((p[:n], p[n - 1:n].expand(T - n, -1, -1))) for n in lengths])
    batched = summary(torch.cat((p[None], padded)), roles, lengths=torch.tensor([T] + lengths))
    differ = [(n, a.swings[0].tolist(), batched.swings[1 + k].tolist())
              for k, (n, a) in enumerate(zip(lengths, alone)) if a.swings[0].tolist() != batched.swings[1 + k].tolist()]
    assert differ == [], f"(frames, swings alone, swings batched): {differ}"
