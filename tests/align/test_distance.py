"""Kovar et al. 2002 frame distance: every grid cell against brute force, transforms, invariances, mirror pitfall."""

import math

import pytest
import torch

from torchsplice.align.distance import (
    align_frames, distance_grid, floor_axes, heading_from_hips, rotate_about_up, wrap_angle,
)
from torchsplice.core.rotations import axis_angle_to_quat, quat_apply

DTYPES = [(torch.float32, 1e-4), (torch.float64, 1e-9)]


def fit_cost(a, b, w, theta, t, up):
    """``sum_k w_k |a_k - (R(theta) b_k + t)|^2``: a, b ``(..., K, 3)``, theta ``(...)``, t ``(..., 3)``."""
    fitted = rotate_about_up(b, theta[..., None], up) + t[..., None, :]
    return (w * (a - fitted).square().sum(-1)).sum(-1)


def best_translation(a, b, w, theta, up):
    """Optimal floor translation ``(..., 3)`` for each theta: the weighted centroid difference after rotation."""
    diff = a - rotate_about_up(b, theta[..., None], up)
    t = (w[..., None] * diff).sum(-2) / w.sum(-1, keepdim=True)
    t[..., up] = 0.0
    return t


def brute_force(a, b, w, up, centre=None, half_width=math.pi):
    """Per cell, minimum over a dense theta grid (7200 steps a turn, refined 3 times) on ``centre +- half_width``.

    a, b: ``(M, K, 3)`` cells (computed in float64); centre ``(M,)`` or None (0). Returns the
    minimal cost ``(M,)``, its theta ``(M,)`` and translation ``(M, 3)``.
    """
    a, b, w = a.double()[:, None], b.double()[:, None], w.double()
    centre = torch.zeros(a.shape[0], dtype=torch.float64) if centre is None else centre.double()
    lo, hi = centre - half_width, centre + half_width
    steps = math.ceil(7200 * half_width / math.pi)  # 7200 steps on the whole circle
    thetas = lo[:, None] + (hi - lo)[:, None] * torch.linspace(0, 1, steps + 1, dtype=torch.float64)
    step = 2 * half_width / steps
    for _ in range(4):
        costs = fit_cost(a, b, w, thetas, best_translation(a, b, w, thetas, up), up)
        best = thetas.gather(1, costs.argmin(1, keepdim=True))
        thetas = torch.minimum(torch.maximum(best + step * torch.linspace(-1, 1, 201, dtype=torch.float64), lo[:, None]), hi[:, None])
        step = step / 100
    best = best[:, 0]
    t = best_translation(a[:, 0], b[:, 0], w, best, up)
    return fit_cost(a[:, 0], b[:, 0], w, best, t, up), best, t


def cells(a, b):
    """All ``(..., Ta, Tb)`` cells of two clips ``(..., T, K, 3)`` as ``(M, K, 3)`` pairs, in grid order."""
    ta, tb = torch.broadcast_tensors(a[..., :, None, :, :], b[..., None, :, :, :])
    return ta.reshape(-1, *a.shape[-2:]), tb.reshape(-1, *a.shape[-2:])


def random_clips(g, shape, dtype, offset=(3.0, 1.0, -2.0)):
    return (torch.randn(*shape, 3, dtype=torch.float64, generator=g) + torch.tensor(offset, dtype=torch.float64)).to(dtype)


@pytest.mark.parametrize("up", [0, 1, 2])
@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_every_grid_cell_matches_brute_force(up, dtype, tol):
    g = torch.Generator().manual_seed(10 + up)
    a, b = random_clips(g, (2, 3, 4), dtype), random_clips(g, (2, 4, 4), dtype, offset=(-1.0, 0.5, 4.0))
    w = torch.rand(4, dtype=torch.float64, generator=g).to(dtype) + 0.2
    ca, cb = cells(a, b)
    for weights in (None, w):
        grid = distance_grid(a, b, weights, up_axis=up)
        assert grid.shape == (2, 3, 4) and grid.dtype == dtype
        ww = torch.full((4,), 0.25, dtype=torch.float64) if weights is None else w.double()
        ref, theta, t = brute_force(ca, cb, ww, up)
        assert ((grid.reshape(-1).double() - ref).abs() <= tol * (1 + ref)).all()
        # no floor translation near the brute-force optimum does better
        nudge = torch.randn(24, 100, 3, dtype=torch.float64, generator=g) * torch.logspace(-4, 0, 100, dtype=torch.float64)[:, None]
        nudge[..., up] = 0.0
        worse = fit_cost(ca.double()[:, None], cb.double()[:, None], ww, theta[:, None].expand(24, 100), t[:, None] + nudge, up)
        assert (worse >= ref[:, None] - 1e-12).all()


@pytest.mark.parametrize("up", [0, 1, 2])
@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_heading_restricted_grid_matches_brute_force_on_the_allowed_arc(up, dtype, tol):
    g = torch.Generator().manual_seed(20 + up)
    a, b = random_clips(g, (3, 3), dtype), random_clips(g, (4, 3), dtype)
    ha = (torch.rand(3, dtype=torch.float64, generator=g) * 8 - 4).to(dtype)
    hb = (torch.rand(4, dtype=torch.float64, generator=g) * 8 - 4).to(dtype)
    w = torch.full((3,), 1 / 3, dtype=torch.float64)
    ca, cb = cells(a, b)
    free = distance_grid(a, b, up_axis=up)
    for dev in (0.3, 1.0, math.pi / 2):
        grid = distance_grid(a, b, up_axis=up, heading_a=ha, heading_b=hb, max_heading_deviation=dev)
        assert (grid >= free - tol * (1 + free)).all()
        ref, theta, _ = brute_force(ca, cb, w, up, centre=(ha[:, None] - hb[None, :]).reshape(-1), half_width=dev)
        assert ((grid.reshape(-1).double() - ref).abs() <= tol * (1 + ref)).all()


def test_heading_extremes_are_unconstrained_and_fixed_rotation():
    g = torch.Generator().manual_seed(30)
    a, b = random_clips(g, (3, 4), torch.float64), random_clips(g, (5, 4), torch.float64)
    ha, hb = torch.rand(3, dtype=torch.float64) * 6, torch.rand(5, dtype=torch.float64) * 6
    free = distance_grid(a, b)
    assert torch.allclose(distance_grid(a, b, heading_a=ha, heading_b=hb, max_heading_deviation=math.pi), free, atol=1e-10)
    fixed = distance_grid(a, b, heading_a=ha, heading_b=hb, max_heading_deviation=0.0)
    w = torch.full((4,), 0.25, dtype=torch.float64)
    for i in range(3):
        for j in range(5):
            theta = (ha[i] - hb[j]).reshape(1)
            ref = fit_cost(a[i], b[j], w, theta, best_translation(a[i], b[j], w, theta, 1), 1)
            assert abs(fixed[i, j].item() - ref.item()) < 1e-9


@pytest.mark.parametrize("up", [0, 1, 2])
def test_rotation_convention_right_handed_about_up(up):
    """theta rotates e_a1 towards e_a2: a right-handed rotation about +up (Y up: Z -> X, the usual R_y)."""
    a1, a2 = floor_axes(up)
    theta = torch.tensor([0.3, -1.2, 2.5], dtype=torch.float64)
    pts = torch.randn(3, 3, dtype=torch.float64)
    axis = torch.zeros(3, 3, dtype=torch.float64)
    axis[:, up] = theta
    assert torch.allclose(rotate_about_up(pts, theta, up), quat_apply(axis_angle_to_quat(axis), pts), atol=1e-12)
    e1, e2 = torch.eye(3, dtype=torch.float64)[a1], torch.eye(3, dtype=torch.float64)[a2]
    assert torch.allclose(rotate_about_up(e1, math.pi / 2, up), e2, atol=1e-12)
    assert floor_axes(1) == (2, 0)


def test_theta_sign_recovered_by_align_frames_y_up():
    """b along +Z, a the same along +X: b must be turned by +pi/2 (Z -> X)."""
    b = torch.tensor([[0.0, 1.0, 0.0], [0.0, 1.0, 2.0], [0.0, 0.0, -1.0]], dtype=torch.float64)
    a = rotate_about_up(b, math.pi / 2)
    d, theta, t = align_frames(a, b)
    assert d.item() < 1e-12 and abs(theta.item() - math.pi / 2) < 1e-12
    assert torch.allclose(a[1], torch.tensor([2.0, 1.0, 0.0], dtype=torch.float64), atol=1e-12)


@pytest.mark.parametrize("up", [0, 1, 2])
@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_align_frames_recovers_known_transform(up, dtype, tol):
    g = torch.Generator().manual_seed(40 + up)
    b = random_clips(g, (6, 5, 4), dtype)
    theta0 = (torch.rand(6, 5, dtype=torch.float64, generator=g) * 2 * math.pi - math.pi).to(dtype)
    t0 = torch.randn(6, 5, 3, dtype=torch.float64, generator=g).to(dtype) * 3
    t0[..., up] = 0.0
    a = rotate_about_up(b, theta0[..., None], up) + t0[..., None, :]
    w = torch.rand(4, dtype=dtype, generator=g) + 0.1
    d, theta, t = align_frames(a, b, w, up_axis=up)
    assert d.shape == theta.shape == (6, 5) and t.shape == (6, 5, 3)
    assert d.abs().max() < 100 * tol
    assert wrap_angle(theta - theta0).abs().max() < 10 * tol ** 0.5
    assert torch.allclose(t, t0, atol=100 * tol ** 0.5)
    assert (t[..., up] == 0).all()


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_align_frames_achieves_the_grid_distance(dtype, tol):
    g = torch.Generator().manual_seed(50)
    a, b = random_clips(g, (2, 5, 3), dtype), random_clips(g, (2, 6, 3), dtype)
    ha, hb = torch.randn(2, 5, dtype=dtype, generator=g), torch.randn(2, 6, dtype=dtype, generator=g)
    for kw in ({}, {"heading_a": ha[:, :, None], "heading_b": hb[:, None, :], "max_heading_deviation": 0.4}):
        grid_kw = {} if not kw else {"heading_a": ha, "heading_b": hb, "max_heading_deviation": 0.4}
        grid = distance_grid(a, b, **grid_kw)
        d, theta, t = align_frames(a[:, :, None], b[:, None], **kw)
        assert torch.allclose(d, grid, rtol=tol, atol=tol * 10)
        fitted = rotate_about_up(b[:, None], theta[..., None]) + t[..., None, :]
        assert torch.allclose(((a[:, :, None] - fitted).square().sum(-1)).mean(-1), d, rtol=tol, atol=tol * 10)
        if kw:
            assert (wrap_angle(theta - (ha[:, :, None] - hb[:, None, :])).abs() <= 0.4 + 10 * tol).all()


@pytest.mark.parametrize("up", [0, 1, 2])
def test_invariant_to_moving_clip_b_on_the_floor_but_not_vertically(up):
    g = torch.Generator().manual_seed(60 + up)
    a, b = random_clips(g, (4, 3), torch.float64), random_clips(g, (5, 3), torch.float64)
    ha, hb = torch.randn(4, dtype=torch.float64, generator=g), torch.randn(5, dtype=torch.float64, generator=g)
    shift = torch.tensor([4.0, -2.0, 7.0], dtype=torch.float64)
    floor_shift = shift.clone()
    floor_shift[up] = 0.0
    moved = rotate_about_up(b, 2.1, up) + floor_shift
    base = distance_grid(a, b, up_axis=up)
    assert torch.allclose(distance_grid(a, moved, up_axis=up), base, atol=1e-9)
    restricted = distance_grid(a, b, up_axis=up, heading_a=ha, heading_b=hb)
    assert torch.allclose(distance_grid(a, moved, up_axis=up, heading_a=ha, heading_b=hb + 2.1), restricted, atol=1e-9)
    dy = 1.5
    lifted = b.clone()
    lifted[..., up] += dy
    # sum w (ya - yb - dy)^2 = sum w (ya - yb)^2 - 2 dy sum w (ya - yb) + dy^2 sum w
    mean_gap = a[..., up].mean(-1)[:, None] - b[..., up].mean(-1)[None, :]
    assert torch.allclose(distance_grid(a, lifted, up_axis=up), base - 2 * dy * mean_gap + dy**2, atol=1e-9)


def test_zero_weight_landmark_is_ignored():
    g = torch.Generator().manual_seed(70)
    a, b = random_clips(g, (3, 4), torch.float64), random_clips(g, (4, 4), torch.float64)
    w = torch.tensor([0.5, 0.2, 0.0, 0.3], dtype=torch.float64)
    b2 = b.clone()
    b2[:, 2] += 100.0
    assert torch.allclose(distance_grid(a, b, w), distance_grid(a, b2, w), atol=1e-9)
    assert torch.allclose(distance_grid(a, b, w), distance_grid(a[:, [0, 1, 3]], b[:, [0, 1, 3]], w[[0, 1, 3]]), atol=1e-9)


def test_heading_from_hips_conventions():
    left = torch.tensor([[9.0, 90.0, 0.0]], dtype=torch.float64)
    right = torch.tensor([[-9.0, 90.0, 0.0]], dtype=torch.float64)
    assert abs(heading_from_hips(left, right).item()) < 1e-12  # left hip towards +X: facing +Z
    thetas = torch.linspace(-3, 3, 13, dtype=torch.float64)
    for up in (0, 1, 2):
        a1, _ = floor_axes(up)
        l, r = torch.zeros(3, dtype=torch.float64), torch.zeros(3, dtype=torch.float64)
        l[(up + 2) % 3], r[(up + 2) % 3] = 1.0, -1.0  # facing e_a1: heading 0
        h = heading_from_hips(rotate_about_up(l, thetas, up), rotate_about_up(r, thetas, up), up)
        assert torch.allclose(wrap_angle(h - thetas), torch.zeros_like(thetas), atol=1e-12)
        forward = rotate_about_up(torch.eye(3, dtype=torch.float64)[a1], thetas, up)
        heading = torch.atan2(forward[:, (up + 2) % 3], forward[:, a1])
        assert torch.allclose(wrap_angle(heading - h), torch.zeros_like(h), atol=1e-12)


def walker(knee_forward: float, lateral: float = 0.0):
    """Y-up walk-like frame facing +Z: root, left knee, right knee (left side is +X), and the two hips."""
    cloud = torch.tensor([[0.0, 90.0, 0.0], [lateral, 50.0, knee_forward], [-lateral, 50.0, -knee_forward]], dtype=torch.float64)
    hips = torch.tensor([[9.0, 90.0, 0.0], [-9.0, 90.0, 0.0]], dtype=torch.float64)
    return cloud, hips


def test_mirror_pitfall_synthetic():
    pose, hips = walker(15.0)
    mirror, mhips = walker(-15.0)  # half a stride later: the other knee forward
    turn, move = 0.7, torch.tensor([30.0, 0.0, 80.0], dtype=torch.float64)
    mirror, mhips = rotate_about_up(mirror, turn) + move, rotate_about_up(mhips, turn) + move
    same = rotate_about_up(pose, turn) + move  # a full stride later
    clip_b = torch.stack((mirror, same))
    h_a = heading_from_hips(hips[0], hips[1]).reshape(1)
    h_b = heading_from_hips(torch.stack((mhips[0], mhips[0])), torch.stack((mhips[1], mhips[1])))
    free = distance_grid(pose[None], clip_b)[0]
    restricted = distance_grid(pose[None], clip_b, heading_a=h_a, heading_b=h_b)[0]
    assert free[0] < 1e-9 and free[1] < 1e-9  # unconstrained: mirror indistinguishable
    assert restricted[1] < 1e-9
    assert restricted[0] > 100.0  # = 2 * sum w |h|^2 here: the best allowed turn is 90 degrees off
    _, theta, _ = align_frames(pose, mirror)  # turns the mirror back onto the pose: -(turn + pi)
    assert abs(wrap_angle(theta + turn + math.pi).item()) < 1e-9  # the unconstrained fit turns it around
    _, theta, _ = align_frames(pose, mirror, heading_a=h_a[0], heading_b=h_b[0])
    assert abs(wrap_angle(theta + turn).abs().item() - math.pi / 2) < 1e-9  # an end of the allowed arc (a tie)


def test_mirror_pitfall_real_walk(mocap_dir):
    from torchsplice.formats.bvh import read_bvh

    path = mocap_dir / "bandai_namco_research_motiondataset" / "dataset-2_walk_normal_008.bvh"
    if not path.exists():
        pytest.skip(f"{path.name} not found")
    motion = read_bvh(path, dtype=torch.float64)
    names, pos = motion.skeleton.names, motion.global_positions()
    cloud = pos[:, [names.index(n) for n in ("Hips", "LowerLeg_L", "LowerLeg_R")]]
    heading = heading_from_hips(pos[:, names.index("UpperLeg_L")], pos[:, names.index("UpperLeg_R")])
    forward = torch.stack((torch.sin(heading), torch.cos(heading)), -1)  # (x, z), Y up
    knee_lead = ((cloud[:, 1] - cloud[:, 2])[:, [0, 2]] * forward).sum(-1)  # > 0: left knee ahead
    fps = motion.fps
    i = int(knee_lead[10:40].abs().argmax()) + 10  # a double-support frame, knees far apart
    free = distance_grid(cloud[i:i + 1], cloud)[0]
    kw = dict(heading_a=heading[i:i + 1], heading_b=heading)
    half_arc = distance_grid(cloud[i:i + 1], cloud, **kw)[0]
    quarter_arc = distance_grid(cloud[i:i + 1], cloud, max_heading_deviation=math.pi / 4, **kw)[0]
    half = i + round(0.4 * fps) + int(free[i + round(0.4 * fps): i + round(0.73 * fps)].argmin())
    full = i + round(0.9 * fps) + int(free[i + round(0.9 * fps): i + round(1.3 * fps)].argmin())
    stride_max = free[i:full].max()
    assert knee_lead[i] * knee_lead[half] < 0 and knee_lead[i] * knee_lead[full] > 0  # knees swapped, then back
    # unconstrained: the mirror half a stride later is a deep local minimum, reached by turning around
    assert free[half] < 0.7 * stride_max and free[half] < free[half - 4] and free[half] < free[half + 4]
    _, theta, _ = align_frames(cloud[i], cloud[half])
    assert wrap_angle(theta - (heading[i] - heading[half])).abs() > math.pi / 2
    # heading-restricted: the mirror gets far (the default pi/2 arc only pushes it up a little)
    assert half_arc[half] >= free[half]
    assert quarter_arc[half] > 2.5 * free[half] and quarter_arc[half] > 1.2 * stride_max
    # one full stride later: near in every metric
    for grid in (free, half_arc, quarter_arc):
        assert grid[full] < 0.02 * stride_max


@pytest.mark.parametrize("dtype,tol", DTYPES)
def test_batch_of_pairs_equals_per_pair_grids(dtype, tol):
    g = torch.Generator().manual_seed(80)
    a, b = random_clips(g, (3, 5, 4), dtype), random_clips(g, (3, 7, 4), dtype)
    w = torch.rand(3, 4, dtype=dtype, generator=g) + 0.1
    ha, hb = torch.randn(3, 5, dtype=dtype, generator=g), torch.randn(3, 7, dtype=dtype, generator=g)
    grid = distance_grid(a, b, w, heading_a=ha, heading_b=hb)
    assert grid.shape == (3, 5, 7)
    for n in range(3):
        one = distance_grid(a[n], b[n], w[n], heading_a=ha[n], heading_b=hb[n])
        assert torch.allclose(grid[n], one, rtol=tol, atol=tol)
    # clip A shared by every pair: batch dims broadcast
    shared = distance_grid(a[0], b, w[0])
    assert shared.shape == (3, 5, 7)
    assert torch.allclose(shared[2], distance_grid(a[0], b[2], w[0]), rtol=tol, atol=tol)


def test_grid_is_non_negative_and_zero_on_the_diagonal_of_a_clip_with_itself():
    g = torch.Generator().manual_seed(90)
    a = random_clips(g, (20, 3), torch.float32, offset=(300.0, 90.0, -500.0))
    grid = distance_grid(a, a)
    assert (grid >= 0).all()
    assert grid.diagonal().abs().max() < 1e-2


def test_bad_shapes_and_arguments_raise():
    a, b = torch.zeros(4, 3, 3), torch.zeros(5, 3, 3)
    bad = [
        lambda: distance_grid(torch.zeros(3, 3), b),
        lambda: distance_grid(a, torch.zeros(5, 2, 3)),
        lambda: distance_grid(torch.zeros(4, 3, 2), torch.zeros(5, 3, 2)),
        lambda: distance_grid(a, b.double()),
        lambda: distance_grid(a, b, torch.ones(2)),
        lambda: distance_grid(a, b, up_axis=3),
        lambda: distance_grid(a, b, heading_a=torch.zeros(4)),
        lambda: distance_grid(a, b, heading_a=torch.zeros(3), heading_b=torch.zeros(5)),
        lambda: distance_grid(a, b, heading_a=torch.zeros(4), heading_b=torch.zeros(5), max_heading_deviation=-0.1),
        lambda: align_frames(torch.zeros(3), torch.zeros(3)),
        lambda: align_frames(torch.zeros(3, 3), torch.zeros(2, 3)),
        lambda: rotate_about_up(torch.zeros(2), 0.1),
        lambda: heading_from_hips(torch.zeros(2), torch.zeros(2)),
    ]
    for call in bad:
        with pytest.raises(ValueError):
            call()


@pytest.mark.gpu
def test_cuda_matches_cpu():
    g = torch.Generator().manual_seed(100)
    a, b = random_clips(g, (2, 30, 3), torch.float64), random_clips(g, (2, 40, 3), torch.float64)
    ha, hb = torch.randn(2, 30, dtype=torch.float64), torch.randn(2, 40, dtype=torch.float64)
    cpu = distance_grid(a, b, heading_a=ha, heading_b=hb)
    gpu = distance_grid(a.cuda(), b.cuda(), heading_a=ha.cuda(), heading_b=hb.cuda())
    assert gpu.is_cuda
    assert torch.allclose(gpu.cpu(), cpu, atol=1e-9)
    d, theta, t = align_frames(a[:, :3].cuda(), b[:, :3].cuda())
    assert d.is_cuda and theta.is_cuda and t.is_cuda
