"""Compiled CPU kernels (numba, torchsplice.cpu) against the torch reference implementations.

Each kernel is run on the same inputs as its torch counterpart: the DP gives the same bits,
the float64 stages agree to round-off, and whole splices agree method by method on sample and
real clips. Then the compiled splicer's results must not depend on batching or thread count.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from tests.align.test_timewarp import brute_force, check_valid_path
from torchsplice.align.curve import fit_alignment_curve, interpolate_frames, slerp_frames
from torchsplice.align.distance import distance_grid, heading_from_hips
from torchsplice.align.horn import cross_covariance, horn_rotation
from torchsplice.align.timewarp import cumulative_cost, timewarp
from torchsplice.core.rotations import quat_angle, quat_apply, random_quat
from torchsplice.cpu import get_threads, set_threads
from torchsplice.cpu.bank import ClipBank, splice_bank
from torchsplice.cpu.curve import fit_curve, resample_clip
from torchsplice.cpu.fk import fk_clip, fk_clips, joint_closure
from torchsplice.cpu.grid import clip_features, distance_row_block, phase_crop_pair
from torchsplice.cpu.horn import horn_batch, horn_cloud, horn_from_h
from torchsplice.cpu.timewarp import timewarp_batch
from torchsplice.core.fk import forward_kinematics
from torchsplice.splice import SpliceOptions, splice_pairs
from torchsplice.splice.heck import landmark_indices, phase_crop

F64 = torch.float64
WALKS = ("dataset-2_walk_normal_008", "dataset-2_walk-turn-left_normal_025", "dataset-2_walk_elderly_006",
         "dataset-1_walk_happy_001", "dataset-1_walk_normal_001")


# ------------------------------------------------------------------------------ fixtures, helpers


def clips_of(request, source: str):
    """``(clips by name, spec, roles)`` of ``source``: ``"sample"`` (the ``sample_f64`` fixture) or
    ``"bandai"`` (:data:`WALKS` of the ``bandai_f64`` fixture; only the real one needs the mocap)."""
    if source == "sample":
        return request.getfixturevalue("sample_f64")
    read, spec = request.getfixturevalue("bandai_f64")
    clips = {n: read(n) for n in WALKS}
    return clips, spec, spec.bind(clips[WALKS[0]].skeleton)


def dp_kernel(grid: np.ndarray, la, lb, max_run: int):
    """:func:`timewarp_batch` called directly: ``(cells (B, Ta+Tb-1, 2), length (B,), total (B,))``."""
    B, Ta, Tb = grid.shape
    cells = np.full((B, Ta + Tb - 1, 2), -1, dtype=np.int64)
    length = np.zeros(B, dtype=np.int64)
    total = np.zeros(B, dtype=grid.dtype)
    timewarp_batch(grid, np.asarray(la, dtype=np.int64), np.asarray(lb, dtype=np.int64), max_run, cells, length, total)
    return cells, length, total


def assert_same_warp(got, want) -> None:
    """Two :class:`WarpPath` results identical bit for bit (shapes, dtypes, values)."""
    assert got.cells.shape == want.cells.shape and got.cells.dtype == want.cells.dtype
    assert torch.equal(got.cells, want.cells)
    assert torch.equal(got.length, want.length)
    assert got.total.dtype == want.total.dtype and torch.equal(got.total, want.total)
    assert torch.equal(got.cost, want.cost)


def make_grid(kind: str, shape, dtype, gen: torch.Generator) -> torch.Tensor:
    """Random cost grids: continuous, integer-valued (many exact ties), constant, or with +inf
    cells off the diagonal (the diagonal path stays open, so no pair is blocked)."""
    if kind == "random":
        g = torch.rand(shape, generator=gen, dtype=torch.float64)
    elif kind == "ties":
        g = torch.randint(0, 3, shape, generator=gen).double()
    elif kind == "flat":
        g = torch.full(shape, 0.75, dtype=torch.float64)
    elif kind == "inf":
        g = torch.randint(0, 4, shape, generator=gen).double()
        blocked = torch.rand(shape, generator=gen) < 0.3
        i = torch.arange(shape[-2])[:, None]
        j = torch.arange(shape[-1])[None, :]
        g = torch.where(blocked & (i != j), torch.full_like(g, math.inf), g)
    else:
        raise ValueError(kind)
    return g.to(dtype)


PAIR_SIZES = [(23, 31), (31, 9), (1, 5), (17, 17), (4, 1), (31, 31), (2, 2), (12, 30)]


def padded_batch(kind, dtype, gen, pad=math.nan):
    """``(B, 31, 31)`` grid of :data:`PAIR_SIZES` pairs, padding filled with ``pad``."""
    B, T = len(PAIR_SIZES), 31
    grid = torch.full((B, T, T), pad, dtype=dtype)
    for b, (la, lb) in enumerate(PAIR_SIZES):
        grid[b, :la, :lb] = make_grid(kind, (la, lb), dtype, gen)
    la = torch.tensor([s[0] for s in PAIR_SIZES])
    lb = torch.tensor([s[1] for s in PAIR_SIZES])
    return grid, la, lb


# ------------------------------------------------------------------------------ 1. DP timewarp


@pytest.mark.parametrize("kind", ["random", "ties", "flat", "inf"])
@pytest.mark.parametrize("max_run", [1, 2, 3, 5])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_dp_kernel_gives_the_torch_bits_on_padded_batches(kind, max_run, dtype):
    gen = torch.Generator().manual_seed(100 + 7 * max_run + len(kind))
    grid, la, lb = padded_batch(kind, dtype, gen)                   # NaN padding: must never be read
    want = timewarp(grid, la, lb, max_run=max_run, backend="torch")
    got = timewarp(grid, la, lb, max_run=max_run, backend="compiled")
    assert_same_warp(got, want)
    # the kernel itself, on the NaN-padded numpy grid
    cells, length, total = dp_kernel(grid.numpy(), la, lb, max_run)
    P = int(want.length.max())
    assert np.array_equal(length, want.length.numpy())
    assert total.dtype == grid.numpy().dtype and np.array_equal(total, want.total.numpy())
    assert np.array_equal(cells[:, :P], want.cells.numpy()) and (cells[:, P:] == -1).all()
    for b, (a, c) in enumerate(PAIR_SIZES):
        path = got.path(b)
        check_valid_path(path, a, c, max_run)
        assert torch.isfinite(grid[b, path[:, 0], path[:, 1]]).all()


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_dp_equal_on_larger_grids_and_the_padding_value_is_irrelevant(dtype):
    gen = torch.Generator().manual_seed(7)
    la, lb = torch.tensor([150, 97, 150, 40]), torch.tensor([220, 220, 61, 200])
    grid = torch.rand(4, 150, 220, generator=gen, dtype=torch.float64).to(dtype)
    grid[0, 0, :] = 0.0                                            # lures for long runs
    grid[1, :, 0] = 0.0
    want = timewarp(grid, la, lb, max_run=3, backend="torch")
    got = timewarp(grid, la, lb, max_run=3, backend="compiled")
    assert_same_warp(got, want)
    for pad in (math.nan, math.inf, -1.0, 0.0):
        padded = grid.clone()
        for b in range(4):
            padded[b, int(la[b]):] = pad
            padded[b, :, int(lb[b]):] = pad
        assert_same_warp(timewarp(padded, la, lb, max_run=3, backend="compiled"), want)


@pytest.mark.parametrize("max_run", [1, 3, 100])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_dp_unbatched_grids(max_run, dtype):
    gen = torch.Generator().manual_seed(11)
    for shape in [(1, 1), (1, 9), (9, 1), (8, 11), (40, 13), (13, 40)]:
        for kind in ("random", "ties"):
            g = make_grid(kind, shape, dtype, gen)
            want = timewarp(g, max_run=max_run, backend="torch")
            got = timewarp(g, max_run=max_run, backend="compiled")
            assert got.cells.dim() == 2 and got.length.dim() == 0 and got.total.dim() == 0 and got.cost.dim() == 0
            assert_same_warp(got, want)


@pytest.mark.parametrize("max_run", [1, 2, 3])
def test_dp_kernel_matches_exhaustive_search_on_small_grids(max_run):
    gen = torch.Generator().manual_seed(40 + max_run)
    shapes = [(1, 1), (1, 5), (4, 1), (2, 2), (3, 5), (5, 3), (4, 4), (5, 6), (6, 4), (2, 7)]
    for Ta, Tb in shapes:
        for kind in ("random", "ties"):
            g = make_grid(kind, (Ta, Tb), F64, gen)
            cell_min, avg, total, cells = brute_force(g, max_run)
            r = timewarp(g, max_run=max_run, backend="compiled")
            assert math.isclose(float(r.cost), avg, abs_tol=1e-12), (Ta, Tb, kind)
            if kind == "random":    # a unique optimum: the same path (ties are broken by rule, not by search order)
                assert math.isclose(float(r.total), total, abs_tol=1e-12)
                assert r.path().tolist() == [list(c) for c in cells]
            assert math.isclose(float(g[r.path()[:, 0], r.path()[:, 1]].sum()), float(r.total), abs_tol=1e-12)
            check_valid_path(r.path(), Ta, Tb, max_run)
            got = cumulative_cost(g, max_run=max_run, backend="compiled")
            assert torch.equal(torch.isinf(got), torch.isinf(cell_min))
            fin = torch.isfinite(cell_min)
            assert torch.allclose(got[fin], cell_min[fin], atol=1e-12, rtol=0)


@pytest.mark.parametrize("kind", ["random", "ties", "inf"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_cumulative_cost_compiled_equals_torch_exactly(kind, dtype):
    gen = torch.Generator().manual_seed(3)
    for max_run in (1, 2, 5):
        grid, la, lb = padded_batch(kind, dtype, gen)
        want = cumulative_cost(grid, la, lb, max_run=max_run, backend="torch")
        got = cumulative_cost(grid, la, lb, max_run=max_run, backend="compiled")
        assert got.dtype == want.dtype and torch.equal(got, want)
        g = grid[0, :23, :31]
        assert torch.equal(cumulative_cost(g, max_run=max_run, backend="compiled"),
                           cumulative_cost(g, max_run=max_run, backend="torch"))


def test_dp_slope_limits_of_64_and_more():
    x = torch.rand(100, 120, generator=torch.Generator().manual_seed(0), dtype=F64)
    x[0, :] = 0.0
    x[:, 0] = 0.0                                                   # lures for runs longer than 64
    for max_run in (63, 64, 80):
        want = timewarp(x, max_run=max_run, backend="torch")
        check_valid_path(want.path(), 100, 120, max_run)
        assert_same_warp(timewarp(x, max_run=max_run, backend="compiled"), want)


def test_dp_blocked_pair_is_named_by_the_compiled_backend():
    g = torch.rand(3, 6, 6, generator=torch.Generator().manual_seed(2), dtype=F64)
    g[1, 1:, :] = math.inf
    g[1, 0, 1:] = math.inf                                          # pair 1: only (0, 0) passable
    with pytest.raises(ValueError, match="pair 1"):
        timewarp(g, backend="compiled")
    with pytest.raises(ValueError, match="pair 1"):
        timewarp(g, backend="torch")
    # the kernel flags the pair and still solves the others as torch does
    cells, length, total = dp_kernel(g.numpy(), [6, 6, 6], [6, 6, 6], 3)
    assert length[1] == -1 and math.isnan(total[1]) and (cells[1] == -1).all()
    for b in (0, 2):
        want = timewarp(g[b], max_run=3, backend="torch")
        assert length[b] == int(want.length) and total[b] == float(want.total)
        assert np.array_equal(cells[b, : length[b]], want.cells.numpy())
    cum = cumulative_cost(g, max_run=3, backend="compiled")
    assert torch.equal(cum, cumulative_cost(g, max_run=3, backend="torch"))
    assert torch.isinf(cum[1]).sum() == 35


# ------------------------------------------------------------------------------ 2. Horn


def horn_np(source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """:func:`horn_batch` on ``(N, K, 3)`` clouds (their dtype), ``(K,)`` weights: ``(N, 4)`` float64."""
    out = np.full((source.shape[0], 4), np.nan)
    horn_batch(source.numpy(), target.numpy(), weights.numpy(), out)
    return torch.from_numpy(out)


def check_unit_canonical(q: torch.Tensor) -> None:
    assert torch.isfinite(q).all()
    assert float((q.norm(dim=-1) - 1).abs().max()) < 1e-12
    assert (q[..., 0] >= 0).all()


@pytest.mark.parametrize("dtype,tol", [(torch.float64, 1e-10), (torch.float32, 1e-5)])
def test_horn_recovers_known_rotations(dtype, tol):
    g = torch.Generator().manual_seed(0)
    q = random_quat((300,), dtype=F64, generator=g)
    source = torch.randn(300, 7, 3, dtype=F64, generator=g).to(dtype)
    target = quat_apply(q[:, None].to(dtype), source)
    w = (torch.rand(7, dtype=F64, generator=g) + 0.1).to(dtype)
    got = horn_np(source, target, w)
    check_unit_canonical(got)
    assert float(quat_angle(got, q).max()) < tol
    for n in (0, 17, 299):                                          # one cloud at a time: the same rotation
        one = torch.tensor(horn_cloud(source[n].numpy(), target[n].numpy(), w.numpy()), dtype=F64)
        assert torch.allclose(one, got[n], atol=1e-14, rtol=0)


@pytest.mark.parametrize("K", [2, 3, 4, 5, 6])
def test_horn_equals_the_svd_form_on_arbitrary_clouds(K):
    g = torch.Generator().manual_seed(10 + K)
    for trial in range(4):
        w = torch.rand(K, dtype=F64, generator=g)
        if trial == 1:
            w[0] = 0.0                                              # a point that does not count
        if trial == 2:
            w = w * 1e3
        source = torch.randn(200, K, 3, dtype=F64, generator=g) * 30 + 5
        target = torch.randn(200, K, 3, dtype=F64, generator=g) * 30 - 5   # unrelated: poor fit, unique
        got = horn_np(source, target, w)
        want = horn_rotation(source, target, w)
        check_unit_canonical(got)
        assert float(quat_angle(got, want).max()) < 1e-8, (K, trial)


def test_horn_mirror_image_targets_give_the_best_proper_rotation():
    g = torch.Generator().manual_seed(3)
    source = torch.randn(64, 8, 3, dtype=F64, generator=g)
    q = random_quat((64,), dtype=F64, generator=g)
    for axis in range(3):
        flip = torch.ones(3, dtype=F64)
        flip[axis] = -1.0
        target = quat_apply(q[:, None], source) * flip             # a reflection: no rotation fits
        w = torch.full((8,), 1.0 / 8, dtype=F64)
        got = horn_np(source, target, w)
        check_unit_canonical(got)
        assert float(quat_angle(got, horn_rotation(source, target, w)).max()) < 1e-9


def test_horn_degenerate_clouds():
    g = torch.Generator().manual_seed(5)
    ident = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=F64)
    generic = torch.randn(5, 3, dtype=F64, generator=g)
    planar = generic * torch.tensor([1.0, 1.0, 0.0], dtype=F64)
    collinear = torch.linspace(-1, 2, 5, dtype=F64)[:, None] * torch.tensor([0.3, -0.5, 0.8], dtype=F64)
    w5 = torch.full((5,), 0.2, dtype=F64)

    def one(s, t, w=None):
        w = torch.full((s.shape[0],), 1.0 / s.shape[0], dtype=F64) if w is None else w
        q = torch.tensor(horn_cloud(s.numpy(), t.numpy(), w.numpy()), dtype=F64)
        check_unit_canonical(q)
        assert float(quat_angle(q, horn_rotation(s, t, w))) < 1e-9   # the SVD form's answer
        return q

    # identical clouds: the identity
    for cloud in (generic, planar, collinear, generic[:1]):
        assert float(quat_angle(one(cloud, cloud), ident)) < 1e-9
    # nothing to fit: exactly the identity
    zeros = torch.zeros(5, 3, dtype=F64)
    assert torch.equal(one(zeros, zeros), ident)
    assert torch.equal(one(generic, generic, torch.zeros(5, dtype=F64)), ident)
    assert horn_from_h(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) == (1.0, 0.0, 0.0, 0.0)
    # collinear clouds: the rotation takes the source line onto the target line
    u = torch.tensor([1.0, 2.0, -2.0], dtype=F64) / 3
    v = torch.tensor([0.0, -0.6, 0.8], dtype=F64)
    lam = torch.tensor([-1.0, 0.5, 2.0, 3.0], dtype=F64)
    for tdir in (v, -v, -u, u, torch.tensor([0.0, 0.0, 1.0], dtype=F64)):
        s, t = lam[:, None] * u, lam[:, None] * tdir
        q = one(s, t)
        assert float((quat_apply(q, s) - t).abs().max()) < 1e-12
    # a single point (any weight): onto its target
    for _ in range(5):
        p = torch.randn(1, 3, dtype=F64, generator=g) * 20
        t = quat_apply(random_quat((), dtype=F64, generator=g), p)
        q = one(p, t, torch.tensor([0.37], dtype=F64))
        assert float((quat_apply(q, p) - t).abs().max()) < 1e-11
    # the batch kernel agrees on every degenerate case at once
    clouds = torch.stack([generic, planar, collinear, zeros])
    got = horn_np(clouds, clouds, w5)
    check_unit_canonical(got)
    assert float(quat_angle(got, ident).max()) < 1e-9


def test_horn_from_cross_covariance_entries():
    g = torch.Generator().manual_seed(8)
    source = torch.randn(50, 6, 3, dtype=F64, generator=g) * 10
    target = torch.randn(50, 6, 3, dtype=F64, generator=g) * 10
    w = torch.rand(6, dtype=F64, generator=g)
    H = cross_covariance(source, target, w)                         # (50, 3, 3): H[a, b] = S_ab
    got = torch.tensor([horn_from_h(*h.flatten().tolist()) for h in H], dtype=F64)
    check_unit_canonical(got)
    assert torch.allclose(got, horn_np(source, target, w), atol=1e-12, rtol=0)
    assert float(quat_angle(got, horn_rotation(source, target, w)).max()) < 1e-8


@pytest.mark.parametrize("scale", [1e-3, 1e-6, 1e-30, 1e6, 1e30, 1e100])
def test_horn_unit_norm_on_clouds_of_any_size(scale):
    g = torch.Generator().manual_seed(1)
    source = torch.randn(1, 6, 3, dtype=F64, generator=g) * scale   # e.g. millimetre-sized clouds in metres
    target = quat_apply(random_quat((), dtype=F64, generator=g), source)
    got = horn_np(source, target, torch.full((6,), 1.0 / 6, dtype=F64))
    assert float(quat_angle(got, horn_rotation(source, target)).max()) < 1e-9
    check_unit_canonical(got)


# ------------------------------------------------------------------------------ 3. forward kinematics


def fk_torch(m):
    """Reference FK ``(positions, global rotations)`` of a clip."""
    return forward_kinematics(m.rotations, m.root_translation, m.skeleton.offsets.to(m.rotations),
                              m.skeleton.parents, m.translations)


def fk_packed(motions):
    """:func:`fk_clips` of clips packed along frames (NaN-filled outputs); per-clip views."""
    rot = np.ascontiguousarray(np.concatenate([m.rotations.numpy() for m in motions]))
    trans = np.ascontiguousarray(np.concatenate([m.local_translations().numpy() for m in motions]))
    lengths = np.array([m.num_frames for m in motions], dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1])).astype(np.int64)
    pos, grot = np.full(trans.shape, np.nan), np.full(rot.shape, np.nan)
    parents = np.array(motions[0].skeleton.parents, dtype=np.int64)
    fk_clips(rot, trans, parents, starts, lengths, pos, grot)
    return [(torch.from_numpy(pos[s:s + n]), torch.from_numpy(grot[s:s + n])) for s, n in zip(starts, lengths)]


@pytest.mark.parametrize("source", ["sample", "bandai"])
def test_fk_clips_equal_forward_kinematics(request, source):
    clips, _, _ = clips_of(request, source)
    motions = list(clips.values())
    size = motions[0].skeleton.size()
    for m, (pos, grot) in zip(motions, fk_packed(motions)):
        want_pos, want_rot = fk_torch(m)
        assert float((pos - want_pos).abs().max()) <= 1e-10 * size, m.name
        assert float((grot - want_rot).abs().max()) <= 1e-10, m.name


def test_fk_clip_on_a_joint_subset(sample_f64):
    clips, _, roles = sample_f64
    m = clips["wave"]
    sk = m.skeleton
    parents = np.array(sk.parents, dtype=np.int64)
    subset = joint_closure(parents, [sk.index("RightHand"), sk.index("Head"), roles.hips[0]])
    assert subset.dtype == np.int64 and (np.diff(subset) > 0).all()
    assert all(parents[j] < 0 or parents[j] in subset for j in subset)   # closed under parents
    assert set(subset.tolist()) == {0, 9, 10, 11, 12, 13, 18, 19, 20, 21, 1}
    T, n = m.num_frames, m.num_frames - 10
    pos, grot = np.full((T, sk.num_joints, 3), 123.25), np.full((T, sk.num_joints, 4), -7.5)
    fk_clip(m.rotations.numpy(), m.local_translations().numpy(), parents, subset, n, pos, grot)
    want_pos, want_rot = fk_torch(m)
    assert float((torch.from_numpy(pos[:n, subset]) - want_pos[:n, subset]).abs().max()) <= 1e-10 * sk.size()
    assert float((torch.from_numpy(grot[:n, subset]) - want_rot[:n, subset]).abs().max()) <= 1e-10
    others = np.setdiff1d(np.arange(sk.num_joints), subset)
    assert (pos[:, others] == 123.25).all() and (grot[:, others] == -7.5).all()   # untouched
    assert (pos[n:] == 123.25).all() and (grot[n:] == -7.5).all()                # frames past n too


# ------------------------------------------------------------------------------ 4. distance grid, phase crop


def features(pos: np.ndarray, landmarks, hips, up: int):
    """:func:`clip_features` of frames ``(T, J, 3)`` (NaN-filled first): ``(floor, height, norm, hcos, hsin)``."""
    T, K = pos.shape[0], len(landmarks)
    feat = (np.full((K, 2, T), np.nan), np.full((K, T), np.nan), np.full(T, np.nan), np.full(T, np.nan), np.full(T, np.nan))
    clip_features(pos, np.asarray(landmarks, dtype=np.int64), np.asarray(hips, dtype=np.int64), up, T, *feat)
    return feat


def grid_kernel(feat, sa: int, la: int, sb: int, lb: int, max_dev: float, shape=None) -> torch.Tensor:
    """:func:`distance_row_block` between packed frames ``sa..sa+la-1`` and ``sb..sb+lb-1`` of
    ``feat``, into a NaN-filled array of ``shape`` (default ``(la, lb)``)."""
    out = np.full(shape or (la, lb), np.nan)
    distance_row_block(feat, sa, la, sb, lb, max_dev, out)
    return torch.from_numpy(out)


def grid_torch(pa, pb, landmarks, hips, up, max_dev, headings=True) -> torch.Tensor:
    ha = heading_from_hips(pa[:, hips[0]], pa[:, hips[1]], up) if headings else None
    hb = heading_from_hips(pb[:, hips[0]], pb[:, hips[1]], up) if headings else None
    return distance_grid(pa[:, landmarks], pb[:, landmarks], up_axis=up, heading_a=ha, heading_b=hb,
                         max_heading_deviation=max_dev)


def assert_grid_close(got: torch.Tensor, want: torch.Tensor) -> None:
    scale = float(want.abs().max())
    assert float((got - want).abs().max()) <= 1e-9 * scale


@pytest.mark.parametrize("landmarks", [[0, 2, 5], [0, 2, 3, 5], [3], [0, 1, 2, 3, 4, 5]], ids=["K3", "K4", "K1", "K6"])
@pytest.mark.parametrize("up", [0, 1, 2])
@pytest.mark.parametrize("max_dev_deg", [10.0, 60.0, 180.0])
def test_distance_grid_on_random_clouds(landmarks, up, max_dev_deg):
    g = torch.Generator().manual_seed(20 + up)
    hips = [1, 4]
    offset = torch.tensor([250.0, -40.0, 90.0], dtype=F64)
    pa = torch.randn(37, 6, 3, dtype=F64, generator=g) * 20 + offset
    pb = torch.randn(29, 6, 3, dtype=F64, generator=g) * 20 - offset
    max_dev = math.radians(max_dev_deg)
    # both clips packed along frames, b first: a starts at frame 29
    feat = features(np.concatenate((pb.numpy(), pa.numpy())), landmarks, hips, up)
    # headings from the hips, as torch computes them
    h = heading_from_hips(pa[:, hips[0]], pa[:, hips[1]], up)
    assert torch.allclose(torch.from_numpy(feat[3][29:]), torch.cos(h), atol=1e-14)
    assert torch.allclose(torch.from_numpy(feat[4][29:]), torch.sin(h), atol=1e-14)
    want = grid_torch(pa, pb, landmarks, hips, up, max_dev)
    got = grid_kernel(feat, 29, 37, 0, 29, max_dev)
    assert_grid_close(got, want)
    assert_grid_close(grid_kernel(feat, 0, 29, 29, 37, max_dev), grid_torch(pb, pa, landmarks, hips, up, max_dev))
    if max_dev_deg == 180.0:                                        # no restriction = no headings
        assert_grid_close(got, grid_torch(pa, pb, landmarks, hips, up, math.pi, headings=False))
    elif len(landmarks) > 1:                                        # the restriction is active somewhere
        assert float((got - grid_torch(pa, pb, landmarks, hips, up, math.pi)).max()) > 1.0
    # part of the clips: only the (la, lb) block is written
    part = grid_kernel(feat, 29, 20, 0, 11, max_dev, shape=(37, 29))
    assert torch.equal(part[:20, :11], got[:20, :11]) and torch.isnan(part[20:]).all() and torch.isnan(part[:, 11:]).all()
    # frames inside the packed clips: an offset block of the same grid
    assert torch.equal(grid_kernel(feat, 29 + 5, 12, 3, 20, max_dev), got[5:17, 3:23])


def bank_grid(bank: ClipBank, a: int, b: int, max_dev: float) -> torch.Tensor:
    """The compiled grid between bank clips ``a`` and ``b`` from the bank's features."""
    return grid_kernel(bank.feat, int(bank.starts[a]), int(bank.lengths[a]), int(bank.starts[b]), int(bank.lengths[b]), max_dev)


@pytest.mark.parametrize("source, names", [
    ("sample", ("walk_curve", "carry_box", "jog")),
    ("bandai", (WALKS[1], WALKS[2], WALKS[0])),
])
def test_distance_grid_and_phase_crop_on_real_clip_pairs(request, source, names):
    clips, _, roles = clips_of(request, source)
    motions = [clips[n] for n in names]
    bank = ClipBank.from_motions(motions, motions[0].skeleton, roles)
    landmarks = landmark_indices(roles, ("root", "knees"))
    for a, b in ((0, 1), (2, 0), (1, 2)):
        pa, pb = motions[a].global_positions(), motions[b].global_positions()
        for max_dev in (math.radians(60.0), math.pi):
            want = grid_torch(pa, pb, landmarks, roles.hips, roles.up_axis, max_dev)
            got = bank_grid(bank, a, b, max_dev)
            assert_grid_close(got, want)
            la, lb = want.shape
            for context, window, depth in ((15, 6, 0.25), (5, 2, 0.5), (30, 10, 0.1), (1, 1, 1.0)):
                c_got = phase_crop_pair(got.numpy(), la, lb, context, window, depth)
                c_want = phase_crop(want[None], torch.tensor([la]), torch.tensor([lb]), context, window, depth)
                assert c_got == int(c_want[0]), (names[a], names[b], context, window, depth)
    # default parameters find a real crop on at least one pair (the test is not all zeros)
    crops = [phase_crop_pair(bank_grid(bank, a, b, math.radians(60.0)).numpy(), int(bank.lengths[a]), int(bank.lengths[b]),
                             15, 6, 0.25) for a, b in ((0, 1), (2, 0), (1, 2))]
    assert max(crops) > 0


def test_phase_crop_on_random_and_periodic_grids():
    g = torch.Generator().manual_seed(9)
    sizes = [(40, 60), (60, 40), (9, 30), (30, 9), (3, 3), (50, 50), (2, 7), (1, 1), (1, 2), (5, 1), (1, 8)]
    Ta, Tb = 60, 60
    for kind in ("random", "periodic"):
        grid = torch.rand(len(sizes), Ta, Tb, generator=g, dtype=F64)   # finite padding (torch reads it, masked)
        if kind == "periodic":                                          # a gait-like valley every 16 frames, phase 5
            i = torch.arange(Ta, dtype=F64)[:, None]
            j = torch.arange(Tb, dtype=F64)[None, :]
            grid = 1.0 - torch.cos(2 * math.pi * (j - i - 5.0) / 16.0) + 0.2 * grid
        la = torch.tensor([s[0] for s in sizes])
        lb = torch.tensor([s[1] for s in sizes])
        for context, window, depth in ((15, 6, 0.25), (4, 1, 0.25), (8, 3, 0.05), (100, 2, 1.0)):
            want = phase_crop(grid, la, lb, context, window, depth)
            for b, (a, c) in enumerate(sizes):
                got = phase_crop_pair(np.ascontiguousarray(grid[b].numpy()), a, c, context, window, depth)
                assert got == int(want[b]), (kind, b, context, window, depth)
            if kind == "periodic" and context == 15:
                assert int(want[0]) == 5


# ------------------------------------------------------------------------------ 5. alignment curve, resampling


def valley_grid(Ta: int, Tb: int, gen: torch.Generator) -> torch.Tensor:
    """Noise over a valley along a smooth monotone warp from corner to corner (paths reach the end)."""
    t = torch.linspace(0, 1, Tb, dtype=F64)
    w = (Ta - 1) * (t + 0.08 * torch.sin(2 * math.pi * t))
    i = torch.arange(Ta, dtype=F64)[:, None]
    return ((i - w[None]) / max(3.0, 0.02 * Ta)) ** 2 + torch.rand(Ta, Tb, generator=gen, dtype=F64)


@pytest.mark.parametrize("shape", [(5, 7), (12, 30), (61, 45), (300, 260), (2000, 2300)])
def test_fit_curve_equals_the_torch_fit(shape):
    gen = torch.Generator().manual_seed(shape[0])
    paths = [timewarp(valley_grid(*shape, gen), max_run=3, backend="compiled").path(),
             timewarp(torch.rand(shape, generator=gen, dtype=F64), max_run=2, backend="compiled").path()]
    if shape[0] >= 2000:
        assert int(paths[0][-1, 0]) >= shape[0] - 10               # a curve of about 2000 frames
    for cells in paths:
        n = cells.shape[0]
        for knot_spacing in (2.0, 7.5, 8.0, 31.0, 1e4):
            for smoothing in (1e-2, 1.0):
                curve = np.full(shape[0] + 3, np.nan)
                frames = fit_curve(cells.numpy(), n, knot_spacing, smoothing, curve)
                want, want_frames = fit_alignment_curve(cells[None], torch.tensor([n]), knot_spacing, smoothing)
                assert frames == int(want_frames[0]) == int(cells[-1, 0]) + 1
                assert float(np.abs(curve[:frames] - want[0, :frames].numpy()).max()) <= 1e-9
                assert np.isnan(curve[frames:]).all()


def test_fit_curve_in_a_batch_and_paths_that_do_not_advance():
    gen = torch.Generator().manual_seed(2)
    paths = [timewarp(valley_grid(a, b, gen), max_run=3, backend="compiled").path() for a, b in ((90, 70), (20, 44), (150, 150))]
    P = max(p.shape[0] for p in paths)
    cells = torch.full((3, P, 2), -1, dtype=torch.long)
    for b, p in enumerate(paths):
        cells[b, : p.shape[0]] = p
    length = torch.tensor([p.shape[0] for p in paths])
    want, frames = fit_alignment_curve(cells, length, 7.5, 1e-2)
    for b, _path in enumerate(paths):
        curve = np.empty(200)
        n = fit_curve(cells[b].numpy(), int(length[b]), 7.5, 1e-2, curve)
        assert n == int(frames[b]) and float(np.abs(curve[:n] - want[b, :n].numpy()).max()) <= 1e-9
    # the shortest paths
    for short in ([[0, 0], [1, 1]], [[0, 0], [0, 1], [1, 1]], [[0, 3], [1, 4], [2, 4], [3, 7]]):
        c = torch.tensor(short)
        curve = np.full(6, np.nan)
        n = fit_curve(c.numpy(), len(short), 7.5, 1e-2, curve)
        want, frames = fit_alignment_curve(c[None], torch.tensor([len(short)]), 7.5, 1e-2)
        assert n == int(frames[0]) and float(np.abs(curve[:n] - want[0, :n].numpy()).max()) <= 1e-9
    # the action stands still (or only the locomotion's frame 0 is used): refused by both
    for bad in ([[0, 0], [1, 0], [2, 0]], [[0, 0], [0, 1], [0, 2]]):
        c = torch.tensor(bad)
        assert fit_curve(c.numpy(), 3, 7.5, 1e-2, np.empty(5)) == -1
        with pytest.raises(ValueError, match="advance"):
            fit_alignment_curve(c[None], torch.tensor([3]), 7.5, 1e-2)


def test_resample_clip_equals_slerp_and_interpolate_frames():
    g = torch.Generator().manual_seed(4)
    T, J, start = 40, 6, 7
    rot = random_quat((T, J), dtype=F64, generator=g)
    rot[11] = rot[10]                                               # equal neighbours: the linear branch
    rot[21] = -rot[20]                                              # the same rotation, opposite sign
    rot[30, 2] = torch.tensor([0.0, 1.0, 0.0, 0.0], dtype=F64)      # a half turn from ...
    rot[31, 2] = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=F64)      # ... the identity: dot = 0
    trans = torch.randn(T, J, 3, dtype=F64, generator=g) * 50
    times = torch.cat([torch.tensor([0.0, 0.5, 10.25, 20.5, 20.0, 30.5, 39.0, 39.0 - 1e-12, -3.0, 45.0], dtype=F64),
                       torch.rand(60, generator=g, dtype=F64) * 44 - 2])
    # the clip packed at row ``start`` of larger arrays (NaN around it: never read)
    big_rot = np.full((T + 12, J, 4), np.nan)
    big_trans = np.full((T + 12, J, 3), np.nan)
    big_rot[start:start + T], big_trans[start:start + T] = rot.numpy(), trans.numpy()
    joints = np.array([0, 2, 3, 5], dtype=np.int64)
    n_t = times.shape[0]
    out_rot, out_trans = np.full((n_t + 2, J, 4), np.nan), np.full((n_t + 2, J, 3), np.nan)
    resample_clip(big_rot, big_trans, start, T, times.numpy(), n_t, joints, out_rot, out_trans)
    lengths = torch.tensor([T])
    want_rot = slerp_frames(rot[None], times[None], lengths)[0]
    want_trans = interpolate_frames(trans[None], times[None], lengths)[0]
    got_rot, got_trans = torch.from_numpy(out_rot[:n_t]), torch.from_numpy(out_trans[:n_t])
    assert torch.allclose(got_rot[:, joints], want_rot[:, joints], atol=1e-12, rtol=0)
    assert torch.allclose(got_trans[:, joints], want_trans[:, joints], atol=1e-12 * 50, rtol=0)
    assert torch.equal(got_rot[0, joints], rot[0, joints])          # t = 0 gives the frame exactly
    others = np.setdiff1d(np.arange(J), joints)
    assert np.isnan(out_rot[:, others]).all() and np.isnan(out_trans[:, others]).all() and np.isnan(out_rot[n_t:]).all()


# ------------------------------------------------------------------------------ 6. whole splices


SPLICE_PAIRS = {
    "sample": [("walk_curve", "carry_box"), ("jog", "wave"), ("turn_sharp", "punch"), ("sidestep", "arms_out")],
    "bandai": [(WALKS[1], WALKS[2]), (WALKS[0], WALKS[3]), (WALKS[4], WALKS[0])],
}
REFERENCES = {"sample": "walk_straight", "bandai": WALKS[4]}


@pytest.mark.parametrize("method", ["splice", "naive", "cpmc", "splice-twist"])
@pytest.mark.parametrize("source", ["sample", "bandai"])
def test_whole_splice_compiled_equals_torch(request, source, method):
    clips, spec, _ = clips_of(request, source)
    pairs = [(clips[a], clips[b]) for a, b in SPLICE_PAIRS[source]]
    twist = 0.5 if method == "splice-twist" else 0.0          # a share of the locomotion's twist
    method = method.split("-")[0]
    refs = [clips[REFERENCES[source]]] * len(pairs) if method == "cpmc" else None
    size = pairs[0][0].skeleton.size()
    comp = splice_pairs(pairs, spec, method, refs, SpliceOptions(backend="compiled", dtype=F64, force=True, twist=twist))
    ref = splice_pairs(pairs, spec, method, refs, SpliceOptions(backend="torch", dtype=F64, force=True, twist=twist))
    assert len(comp) == len(ref) == len(pairs)
    for x, y in zip(comp, ref):
        assert (x.motion.name, x.locomotion, x.action, x.reference) == (y.motion.name, y.locomotion, y.action, y.reference)
        assert x.motion.num_frames == y.motion.num_frames and x.motion.rotations.dtype == F64
        assert torch.equal(x.path, y.path) and x.crop == y.crop
        assert math.degrees(float(quat_angle(x.motion.rotations, y.motion.rotations).max())) < 1e-7
        assert float((x.motion.local_translations() - y.motion.local_translations()).abs().max()) <= 1e-9 * size
        assert float((x.motion.root_translation - y.motion.root_translation).abs().max()) <= 1e-9 * size
        assert x.curve.shape == y.curve.shape and float((x.curve - y.curve).abs().max()) <= 1e-9
        assert x.pelvis_correction.shape == y.pelvis_correction.shape
        assert float((x.pelvis_correction - y.pelvis_correction).abs().max()) <= 1e-7
        assert abs(x.posture_deg - y.posture_deg) <= 1e-7
        if method == "naive":
            assert math.isnan(x.cost) and math.isnan(y.cost)
        else:
            assert x.cost == pytest.approx(y.cost, rel=1e-9, abs=0)
    if method != "naive":                                           # the alignment had work to do
        assert any(x.crop > 0 for x in comp) and all(x.path.shape[0] > 10 for x in comp)
    if method == "splice":
        assert max(float(x.pelvis_correction.max()) for x in comp) > 0.1 and max(x.posture_deg for x in comp) > 0.1
    if twist:                                                     # the twist changed the posture
        plain = splice_pairs(pairs, spec, method, refs, SpliceOptions(backend="compiled", dtype=F64, force=True))
        assert max(abs(x.posture_deg - y.posture_deg) for x, y in zip(comp, plain)) > 0.1


# ------------------------------------------------------------------------------ 7. determinism


def per_pair(out, b: int) -> dict:
    """Pair ``b``'s part of :class:`PackedSplices`, copied."""
    s, n, pl = int(out.start[b]), int(out.frames[b]), int(out.path_length[b])
    if pl:                                                          # (naive leaves cells unwritten)
        assert (out.cells[b, pl:] == -1).all()
    return dict(rotations=out.rotations[s:s + n].copy(), translations=out.translations[s:s + n].copy(),
                curve=out.curve[s:s + n].copy(), correction=out.correction[s:s + n].copy(), cells=out.cells[b, :pl].copy(),
                cost=out.cost[b], crop=out.crop[b], frames=out.frames[b], posture=out.posture[b], path_length=pl)


def assert_identical(x: dict, y: dict) -> None:
    for k in x:
        assert np.array_equal(x[k], y[k], equal_nan=True), k


@pytest.mark.parametrize("method", ["splice", "naive", "cpmc"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_splice_bank_is_bit_identical_alone_in_any_batch_and_on_any_thread_count(sample_f64, method, dtype):
    clips, _, roles = sample_f64
    names = list(clips)
    bank = ClipBank.from_motions(list(clips.values()), clips["walk_straight"].skeleton, roles)
    idx = {n: k for k, n in enumerate(names)}
    loco = [idx[n] for n in ("walk_curve", "jog", "turn_sharp", "sidestep", "walk_straight", "jog")]
    act = [idx[n] for n in ("carry_box", "wave", "punch", "arms_out", "carry_cup", "carry_box")]
    ref = [idx["walk_straight"]] * len(loco) if method == "cpmc" else None

    def run(order):
        out = splice_bank(bank, [loco[k] for k in order], [act[k] for k in order], method,
                          None if ref is None else [ref[k] for k in order], dtype=dtype)
        assert out.rotations.dtype == dtype
        return {k: per_pair(out, b) for b, k in enumerate(order)}

    before = get_threads()
    try:
        set_threads(2)
        batch = run(list(range(len(loco))))
        shuffled = run([4, 1, 5, 0, 3, 2])
        alone = {k: run([k])[k] for k in range(len(loco))}
        set_threads(1)
        single_thread = run(list(range(len(loco))))
    finally:
        set_threads(before)
    assert get_threads() == before
    for k in range(len(loco)):
        for other in (shuffled, alone, single_thread):
            assert_identical(batch[k], other[k])
    assert len({batch[k]["frames"] for k in batch}) > 2                  # pairs really differ
