"""Slope-limited DP timewarp: exact brute force, batching with padding, slope limit, real clip."""

import math

import pytest
import torch

from torchsplice.align.timewarp import WarpPath, cumulative_cost, reachable_mask, timewarp

MOVES = {"D": (1, 1), "H": (0, 1), "V": (1, 0)}


def all_paths(Ta, Tb, L):
    """Every valid path from (0, 0) inside a Ta x Tb grid: (cells, final state) pairs.

    The final state is ("D", 0) for the start alone or a last diagonal step, else
    ("H", run) or ("V", run) with the length of the final run of that step.
    """
    out = []

    def rec(cells, state):
        out.append((list(cells), state))
        i, j = cells[-1]
        for m, (di, dj) in MOVES.items():
            if i + di >= Ta or j + dj >= Tb:
                continue
            run = state[1] + 1 if state[0] == m else 1
            if m != "D" and run > L:
                continue
            cells.append((i + di, j + dj))
            rec(cells, (m, 0 if m == "D" else run))
            cells.pop()

    rec([(0, 0)], ("D", 0))
    return out


def brute_force(g, L):
    """Heck et al.'s rule by exhaustive search on one (Ta, Tb) float64 grid.

    Returns (per-cell minimal totals (Ta, Tb) with inf where unreachable, best average,
    best total, best path cells).
    """
    Ta, Tb = g.shape
    cell_min = torch.full((Ta, Tb), math.inf, dtype=torch.float64)
    group = {}  # (end cell, final state) -> (total, cells): the minimal-total path of that group
    for cells, state in all_paths(Ta, Tb, L):
        total = sum(float(g[c]) for c in cells)
        end = cells[-1]
        cell_min[end] = min(float(cell_min[end]), total)
        key = (end, state)
        if key not in group or total < group[key][0]:
            group[key] = (total, cells)
    best = None
    for (end, _), (total, cells) in group.items():
        if end[0] == Ta - 1 or end[1] == Tb - 1:
            avg = total / len(cells)
            if best is None or avg < best[0]:
                best = (avg, total, cells)
    return cell_min, best[0], best[1], best[2]


def check_valid_path(cells, la, lb, L):
    """Assert cells (n, 2) is a continuous monotone path from (0, 0) to the top or right
    edge of an la x lb grid with runs of at most L horizontal or vertical steps."""
    cells = cells.tolist()
    assert cells[0] == [0, 0]
    assert cells[-1][0] == la - 1 or cells[-1][1] == lb - 1
    run, last = 0, None
    for (i0, j0), (i1, j1) in zip(cells, cells[1:]):
        step = (i1 - i0, j1 - j0)
        assert step in ((1, 1), (0, 1), (1, 0)), f"bad step {step}"
        assert 0 <= i1 < la and 0 <= j1 < lb
        run = run + 1 if step == last else 1
        last = step
        if step != (1, 1):
            assert run <= L, f"run of {run} > {L}"


def max_runs(cells):
    """Longest run of horizontal steps and of vertical steps on a path (n, 2)."""
    d = (cells[1:] - cells[:-1]).tolist()
    best = {(0, 1): 0, (1, 0): 0}
    run, last = 0, None
    for step in map(tuple, d):
        run = run + 1 if step == last else 1
        last = step
        if step in best:
            best[step] = max(best[step], run)
    return best[(0, 1)], best[(1, 0)]


@pytest.mark.parametrize("L", [1, 2, 3])
def test_matches_exhaustive_search_on_small_grids(L):
    gen = torch.Generator().manual_seed(10 + L)
    shapes = [(1, 1), (1, 5), (4, 1), (2, 2), (3, 5), (5, 3), (4, 4), (5, 6), (6, 7), (6, 4), (2, 7)]
    for Ta, Tb in shapes:
        for _ in range(2):
            g = torch.rand(Ta, Tb, generator=gen, dtype=torch.float64)
            cell_min, avg, total, cells = brute_force(g, L)
            got = cumulative_cost(g, max_run=L)
            assert torch.equal(torch.isinf(got), torch.isinf(cell_min)), (Ta, Tb, L)
            fin = torch.isfinite(cell_min)
            assert torch.allclose(got[fin], cell_min[fin], atol=1e-12, rtol=0)
            assert torch.equal(torch.isfinite(got), reachable_mask(Ta, Tb, L))
            r = timewarp(g, max_run=L)
            assert math.isclose(float(r.cost), avg, abs_tol=1e-12), (Ta, Tb, L)
            assert math.isclose(float(r.total), total, abs_tol=1e-12)
            assert r.path().tolist() == [list(c) for c in cells]
            check_valid_path(r.path(), Ta, Tb, L)
            assert math.isclose(float(g[r.path()[:, 0], r.path()[:, 1]].sum()), float(r.total), abs_tol=1e-12)


def test_brute_force_helper_counts_paths():
    # Without an effective slope limit, paths in an m x n grid are the Delannoy numbers summed
    # over end cells; 2 x 2: (0,0), (0,1), (1,0), (1,1) x3, (0,1)->(1,1), (1,0)->(1,1) -> 6.
    assert len(all_paths(2, 2, 5)) == 6
    # L = 1 forbids two horizontal steps in a row: a 1 x 3 row only reaches column 1.
    assert {tuple(c[-1]) for c, _ in all_paths(1, 3, 1)} == {(0, 0), (0, 1)}


@pytest.mark.parametrize("pad", [0.0, 1e30, math.inf, math.nan, -5.0])
def test_batched_with_padding_equals_per_pair(pad):
    gen = torch.Generator().manual_seed(4)
    sizes = [(9, 14), (14, 5), (1, 3), (14, 14), (6, 6), (3, 1)]
    Ta, Tb = 14, 14
    grid = torch.full((len(sizes), Ta, Tb), pad, dtype=torch.float64)
    singles = []
    for b, (la, lb) in enumerate(sizes):
        g = torch.rand(la, lb, generator=gen, dtype=torch.float64)
        grid[b, :la, :lb] = g
        singles.append(timewarp(g, max_run=2))
    la = torch.tensor([s[0] for s in sizes])
    lb = torch.tensor([s[1] for s in sizes])
    r = timewarp(grid, la, lb, max_run=2)
    assert isinstance(r, WarpPath) and r.cells.shape[0] == len(sizes) and r.cells.dtype == torch.long
    assert r.cells.shape[1] == int(r.length.max())
    for b, s in enumerate(singles):
        assert torch.equal(r.path(b), s.path())
        assert (r.cells[b, int(r.length[b]):] == -1).all()
        assert int(r.length[b]) == int(s.length)
        assert float(r.cost[b]) == float(s.cost) and float(r.total[b]) == float(s.total)
    cum = cumulative_cost(grid, la, lb, max_run=2)
    for b, (a, c) in enumerate(sizes):
        assert torch.equal(cum[b, :a, :c], cumulative_cost(grid[b, :a, :c], max_run=2))
        assert torch.isinf(cum[b, a:]).all() and torch.isinf(cum[b, :, c:]).all()


@pytest.mark.parametrize("L", [2, 3])
def test_never_exceeds_slope_limit_on_larger_grids(L):
    gen = torch.Generator().manual_seed(20 + L)
    B, Ta, Tb = 6, 60, 80
    grid = torch.rand(B, Ta, Tb, generator=gen)
    # Pairs 0-1: a cheap first row / first column invites long horizontal / vertical runs;
    # pairs 2-3: a free staircase of slope 1/4 or 4 does the same in the middle of the grid.
    grid[0, 0, :] = 0.0
    grid[1, :, 0] = 0.0
    for t in range(Tb):
        grid[2, min(Ta - 1, t // 4), t] = 0.0
        grid[3, 4 * t: 4 * t + 4, t] = 0.0
    la = torch.tensor([60, 60, 60, 60, 37, 11])
    lb = torch.tensor([80, 80, 80, 80, 80, 50])
    r = timewarp(grid, la, lb, max_run=L)
    for b in range(B):
        p = r.path(b)
        check_valid_path(p, int(la[b]), int(lb[b]), L)
        assert math.isclose(float(grid[b, p[:, 0], p[:, 1]].sum()), float(r.total[b]), rel_tol=1e-5)
        assert math.isclose(float(r.cost[b]), float(r.total[b]) / int(r.length[b]), rel_tol=1e-6)
    # The limit is active, not over-restrictive: the lures are followed with runs of exactly L.
    assert max_runs(r.path(0))[0] == L and max_runs(r.path(1))[1] == L
    assert max_runs(r.path(2))[0] == L and max_runs(r.path(3))[1] == L


def test_zero_diagonal_gives_the_diagonal():
    gen = torch.Generator().manual_seed(5)
    x = torch.randn(40, 9, generator=gen, dtype=torch.float64).cumsum(0)
    g = ((x[:, None] - x[None]) ** 2).sum(-1)
    assert (g.diagonal() == 0).all()
    for L in (1, 3):
        r = timewarp(g, max_run=L)
        assert r.path().tolist() == [[t, t] for t in range(40)]
        assert float(r.cost) == 0.0
    # All-zero grids: every path averages 0; ties go to the corner and the diagonal step.
    r = timewarp(torch.zeros(7, 7))
    assert r.path().tolist() == [[t, t] for t in range(7)]


def test_unreachable_edge_cells_are_never_chosen():
    # 3 x 20 grid with L = 1: top-edge cells beyond column (L+1)(Ta-1)+L = 5 are out of reach.
    g = torch.ones(3, 20)
    g[2, 6:] = 0.0
    r = timewarp(g, max_run=1)
    check_valid_path(r.path(), 3, 20, 1)
    assert int(r.path()[-1, 1]) <= 5
    assert not reachable_mask(3, 20, 1)[2, 6:].any()
    # However different the lengths, the diagonal always reaches an edge: no error.
    r = timewarp(torch.rand(2, 300), max_run=1)
    check_valid_path(r.path(), 2, 300, 1)
    r = timewarp(torch.rand(300, 2), max_run=1)
    check_valid_path(r.path(), 300, 2, 1)


def test_infinite_costs_block_paths_and_a_blocked_pair_is_named():
    g = torch.rand(3, 5, 5)
    g[1, 1:, :] = math.inf
    g[1, 0, 1:] = math.inf          # pair 1: only (0, 0) is passable, and it is on no edge
    with pytest.raises(ValueError, match="pair 1"):
        timewarp(g)
    g[2, 2, :] = math.inf           # pair 2 still fine on its own, restricted to rows 0..1
    r = timewarp(g[2:], lengths_a=[5], lengths_b=[5])
    assert torch.isfinite(r.total).all()
    assert all(int(i) != 2 for i in r.path(0)[:, 0])
    assert r.path(0)[-1].tolist()[1] == 4


def test_unbatched_and_dtypes():
    g = torch.rand(8, 11, dtype=torch.float64)
    r = timewarp(g)
    assert r.cells.dim() == 2 and r.length.dim() == 0 and r.cost.dim() == 0 and r.total.dim() == 0
    rb = timewarp(g[None])
    assert torch.equal(rb.cells[0], r.cells) and float(rb.cost[0]) == float(r.cost)
    r32 = timewarp(g.float())
    assert r32.cost.dtype == torch.float32 and torch.equal(r32.path(), r.path())
    ri = timewarp((g * 1000).long())
    assert ri.cost.is_floating_point()
    r8 = timewarp(torch.rand(8, 11), max_run=100)     # a limit beyond any run is no limit
    check_valid_path(r8.path(), 8, 11, 100)


def test_bad_input_is_refused():
    g = torch.rand(2, 4, 5)
    with pytest.raises(ValueError, match="max_run"):
        timewarp(g, max_run=0)
    with pytest.raises(ValueError, match="max_run"):
        timewarp(g, max_run=1.5)
    with pytest.raises(ValueError, match="shape"):
        timewarp(torch.rand(2, 3, 4, 5))
    with pytest.raises(ValueError, match="empty"):
        timewarp(torch.rand(2, 0, 5))
    with pytest.raises(ValueError, match=r"lengths_a\[1\]"):
        timewarp(g, lengths_a=[4, 5])
    with pytest.raises(ValueError, match=r"lengths_b\[0\]"):
        timewarp(g, lengths_b=[0, 5])
    with pytest.raises(ValueError, match="lengths_b must have shape"):
        timewarp(g, lengths_b=[5, 5, 5])
    with pytest.raises(ValueError, match="integers"):
        timewarp(g, lengths_a=torch.tensor([4.0, 4.0]))
    bad = g.clone()
    bad[1, 2, 3] = math.nan
    with pytest.raises(ValueError, match=r"pair 1 .*\(2, 3\)"):
        timewarp(bad)
    timewarp(bad, lengths_a=[4, 2])    # the NaN is padding there: ignored
    bad[1, 2, 3] = -math.inf
    with pytest.raises(ValueError, match="-inf"):
        timewarp(bad)



DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.gpu)]


@pytest.mark.parametrize("device", DEVICES)
def test_the_dp_on_a_device_gives_the_compiled_bits(device):
    """The DP on ``device`` (``"auto"``: the torch DP on CUDA; the compiled one on the CPU, and
    the torch one asked for by name) gives the compiled DP's paths, lengths and totals, bit for
    bit, on padded float64 and float32 batches; the compiled DP refuses a grid elsewhere."""
    gen = torch.Generator().manual_seed(5)
    for dtype in (torch.float64, torch.float32):
        g = torch.rand(4, 23, 19, generator=gen, dtype=dtype)
        la, lb = torch.tensor([23, 17, 9, 20]), torch.tensor([19, 19, 12, 4])
        want = timewarp(g, la, lb, max_run=3, backend="compiled")
        want_cum = cumulative_cost(g, la, lb, max_run=3, backend="compiled")
        for backend in ("auto", "torch"):
            got = timewarp(g.to(device), la.to(device), lb.to(device), max_run=3, backend=backend)
            assert got.cells.device.type == device
            assert torch.equal(got.cells.cpu(), want.cells) and torch.equal(got.length.cpu(), want.length)
            assert torch.equal(got.total.cpu(), want.total) and got.total.dtype == dtype
            cum = cumulative_cost(g.to(device), la.to(device), lb.to(device), max_run=3, backend=backend)
            assert cum.device.type == device and torch.equal(cum.cpu(), want_cum)
    if device != "cpu":
        with pytest.raises(ValueError, match=r"^the compiled backend runs on CPU tensors, got a grid on cuda:0$"):
            timewarp(g.to(device), backend="compiled")

def test_recovers_a_known_warp_of_a_real_clip(mocap_dir):
    from torchsplice.formats.bvh import read_bvh

    path = mocap_dir / "bandai_namco_research_motiondataset" / "dataset-2_walk_normal_008.bvh"
    if not path.is_file():
        pytest.skip(f"{path} not found")
    motion = read_bvh(path, dtype=torch.float64)
    pos = motion.global_positions()
    pts = pos[:, motion.skeleton.indices(["Hips", "LowerLeg_L", "LowerLeg_R"])]      # (Ta, 3, 3)
    Ta = pts.shape[0]
    Tb = 200
    # Known smooth monotone warp from frames of B to frames of A, slope within [1/L, L].
    t = torch.arange(Tb, dtype=torch.float64)
    s = (Ta - 1) / (Tb - 1)
    w = s * t + 6.0 * torch.sin(2 * math.pi * t / (Tb - 1))
    slope = s + 6.0 * 2 * math.pi / (Tb - 1) * torch.cos(2 * math.pi * t / (Tb - 1))
    assert float(slope.min()) > 1 / 3 and float(slope.max()) < 3
    lo = w.floor().long().clamp(0, Ta - 2)
    frac = (w - lo)[:, None, None]
    warped = (1 - frac) * pts[lo] + frac * pts[lo + 1]                               # (Tb, 3, 3)
    # Pose only: remove each frame's root position in the floor plane (the gait is periodic,
    # so the grid has a valley per step, not just one).
    up = 1  # Bandai Namco is Y-up
    floor = [a for a in range(3) if a != up]

    def centred(p):
        p = p.clone()
        p[..., floor] -= p[:, :1, floor]
        return p.flatten(1)

    grid = torch.cdist(centred(pts), centred(warped)) ** 2                          # (Ta, Tb)
    r = timewarp(grid, max_run=3)
    cells = r.path()
    check_valid_path(cells, Ta, Tb, 3)
    i, j = cells[:, 0].double(), cells[:, 1].double()
    # Each frame j of B is matched to frames of A within one frame of w(j) (the warp's slope is
    # > 1 here, so a column holds one or two rows); and each row to columns near w^-1(i).
    assert float((i - w[cells[:, 1]]).abs().max()) <= 1.0 + 1e-9
    inv = torch.from_numpy(__import__("numpy").interp(i.numpy(), w.numpy(), t.numpy()))
    assert float((j - inv).abs().max()) <= 1.0 + 1e-9
    # And the path spans (nearly) the whole alignment.
    assert int(cells[-1, 0]) == Ta - 1 or int(cells[-1, 1]) >= Tb - 2
