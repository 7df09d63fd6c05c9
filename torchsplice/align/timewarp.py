"""Dynamic-programming timewarp with a slope limit (Kovar & Gleicher 2003; Heck et al. 2006, §3.1).

Conventions, used by every function here:

- A **cost grid** is ``(B, Ta, Tb)`` (or one unbatched ``(Ta, Tb)`` grid): ``grid[b, i, j]`` is
  the distance between frame ``i`` of clip A (the locomotion, rows) and frame ``j`` of clip B
  (the action, columns) of pair ``b``. Costs are meant to be ``>= 0``; ``+inf`` marks a cell
  no path may use; NaN and ``-inf`` in a valid cell are refused.
- Pair ``b`` uses only the top-left ``lengths_a[b] x lengths_b[b]`` block; the rest is padding
  and is never read (it may hold anything, NaN included). Missing lengths mean the full grid.
- A **path** is a list of cells ``(i, j)`` from ``(0, 0)`` made of steps ``(1, 0)``
  (*vertical*: next frame of A only), ``(0, 1)`` (*horizontal*: next frame of B only) and
  ``(1, 1)`` (*diagonal*), with at most ``max_run`` consecutive horizontal steps and at most
  ``max_run`` consecutive vertical steps (the slope limit ``L``). Its *total* is the sum of its
  cells' costs, its *length* the number of its cells (start and end included), its *cost* the
  average ``total / length``.
- The chosen path (Heck et al.) is found in two stages. For every cell and every final state
  (last step diagonal, or the last ``c`` steps horizontal, or the last ``c`` steps vertical,
  ``1 <= c <= L``) the path of minimal *total* is found by dynamic programming. Then, among
  the cells on the **top edge** (``i = lengths_a - 1``) and the **right edge**
  (``j = lengths_b - 1``) of the pair's own grid and over their states, the path of minimal
  *average* cost is chosen and backtracked.

Tie-breaking (deterministic): when two predecessors give the same total, the one whose last
step is diagonal wins, then horizontal (shorter run first), then vertical (shorter run first).
When two end candidates have the same average, the corner ``(lengths_a-1, lengths_b-1)`` wins,
then the top edge from right to left, then the right edge from top to bottom; within one cell
the state order is again diagonal, horizontal, vertical. (The single-cell path at ``(0, 0)``
counts as ending with a diagonal step.)

Reachability: with slope limit ``L`` a cell ``(i, j)`` is reachable only if
``j <= (L + 1) i + L`` and ``i <= (L + 1) j + L``, so parts of the top or right edge may be out
of reach; those are never chosen. The all-diagonal path from ``(0, 0)`` always reaches the top
or right edge, so with finite costs some end cell is always reachable, whatever the lengths
and ``L``; a pair only fails (``ValueError`` naming it) when ``+inf`` cells block every path.

Two implementations give the same bits: this module's torch code (:data:`TORCH_DP`, any device;
it is what runs on CUDA) and the compiled one of :mod:`torchsplice.cpu.timewarp`
(:data:`COMPILED_DP`, CPU tensors), which runs each pair in one thread and pairs in parallel.
Which one runs is the splicing backends' choice, not this module's: each backend gives the DP it
computes with (:attr:`~torchsplice.splice.backends.Backend.dynamic_program`),
and a ``backend`` name, ``"auto"`` included, means the DP of the registered backend it names
(``"auto"``: the available one of highest priority that runs on the grid's device, the rule of
:func:`~torchsplice.splice.backends.resolve_backend`). So registering a backend (a GPU one, say)
is all it takes for :func:`timewarp` to run that backend's DP on its device. The backends sit in
a layer above this one: their chooser is named by ``"module:function"`` (:data:`CHOOSER`) and
imported when first used, as :mod:`torchsplice.core.method_table` names the methods'
implementations; this module imports nothing above it.

Cost of the torch search: the Python loop runs over the ``Ta`` rows, each step vectorised over the
batch and the columns (plus ``L`` shifts along the row); memory is the grid, three ``int8``
back-pointer arrays ``(B, Ta, Tb)`` and a few ``(B, 2L+1, max(Ta, Tb))`` state arrays.
Backtracking steps every pair back at once, one path step per loop iteration.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

__all__ = ["WarpPath", "DynamicProgram", "TORCH_DP", "COMPILED_DP", "CHOOSER", "timewarp", "cumulative_cost",
           "reachable_mask"]


@dataclass
class WarpPath:
    """The chosen alignment path of each pair.

    Attributes (batched call; an unbatched ``(Ta, Tb)`` grid gives the same without ``B``):
        cells: ``(B, P, 2)`` long, the cells ``(i, j)`` of each path in order from ``(0, 0)``;
            ``P`` is the longest path of the batch and shorter paths are padded with ``-1``.
        length: ``(B,)`` long, the number of cells on each path.
        cost: ``(B,)`` the average cost of the cells on the path (the quantity minimised).
        total: ``(B,)`` the summed cost of the cells on the path.
    """

    cells: torch.Tensor
    length: torch.Tensor
    cost: torch.Tensor
    total: torch.Tensor

    def path(self, b: int = 0) -> torch.Tensor:
        """``(length, 2)`` cells of pair ``b``'s path without padding (``b`` ignored if unbatched)."""
        if self.cells.dim() == 2:
            return self.cells[: int(self.length)]
        return self.cells[b, : int(self.length[b])]


# ----------------------------------------------------------------------------- input checks


def _check_inputs(grid, lengths_a, lengths_b, max_run):
    """Validate and normalise: ``(grid (B, Ta, Tb) float, la (B,), lb (B,), L, unbatched)``."""
    if not isinstance(grid, torch.Tensor):
        grid = torch.as_tensor(grid)
    if isinstance(max_run, bool) or not isinstance(max_run, int) or max_run < 1:
        raise ValueError(f"max_run must be an integer >= 1, got {max_run!r}")
    unbatched = grid.dim() == 2
    if unbatched:
        grid = grid[None]
    if grid.dim() != 3:
        raise ValueError(f"grid must have shape (Ta, Tb) or (B, Ta, Tb), got {tuple(grid.shape)}")
    B, Ta, Tb = grid.shape
    if B == 0 or Ta == 0 or Tb == 0:
        raise ValueError(f"grid must not be empty, got shape {tuple(grid.shape)}")
    if not grid.is_floating_point():
        grid = grid.to(torch.get_default_dtype())
    elif grid.dtype in (torch.float16, torch.bfloat16):
        grid = grid.float()
    la = _check_lengths(lengths_a, "lengths_a", B, Ta, grid.device)
    lb = _check_lengths(lengths_b, "lengths_b", B, Tb, grid.device)
    valid = _valid_mask(la, lb, Ta, Tb)
    bad = valid & (torch.isnan(grid) | (grid == float("-inf")))
    if bool(bad.any()):
        b, i, j = (int(v) for v in bad.nonzero()[0])
        raise ValueError(f"grid of pair {b} has a NaN or -inf cost at cell ({i}, {j})")
    return grid, la, lb, max_run, unbatched


def _check_lengths(lengths, name, B, T, device) -> torch.Tensor:
    """``(B,)`` long valid sizes, all in ``[1, T]``; a scalar is used for every pair, ``None`` means ``T``."""
    if lengths is None:
        return torch.full((B,), T, dtype=torch.long, device=device)
    t = torch.as_tensor(lengths, device=device)
    if t.is_floating_point() or t.is_complex() or t.dtype == torch.bool:
        raise ValueError(f"{name} must hold integers, got dtype {t.dtype}")
    if t.dim() == 0:
        t = t.expand(B)
    if t.shape != (B,):
        raise ValueError(f"{name} must have shape ({B},), got {tuple(t.shape)}")
    t = t.long()
    out = (t < 1) | (t > T)
    if bool(out.any()):
        b = int(out.nonzero()[0])
        raise ValueError(f"{name}[{b}] = {int(t[b])} is out of range [1, {T}]")
    return t


def _valid_mask(la, lb, Ta, Tb) -> torch.Tensor:
    """``(B, Ta, Tb)`` bool, True inside each pair's own ``la x lb`` block."""
    i = torch.arange(Ta, device=la.device)
    j = torch.arange(Tb, device=la.device)
    return (i[None, :, None] < la[:, None, None]) & (j[None, None, :] < lb[:, None, None])


# ----------------------------------------------------------------------------- forward pass


def _forward(grid, la, lb, L, keep_min=False):
    """Row-by-row DP over states ``[D, H1..HL, V1..VL]`` (index ``0``, ``1..L``, ``L+1..2L``).

    Args:
        grid: ``(B, Ta, Tb)`` float costs (padding is masked here to ``+inf``).
        la, lb: ``(B,)`` long valid sizes.
        L: slope limit (effective, ``>= 1``).
        keep_min: also return the ``(B, Ta, Tb)`` minimal total over states of every cell.

    Returns:
        dict with ``bp`` ``(3, B, Ta, Tb)`` back-pointers (predecessor state of D, H1, V1),
        ``top_sum``/``top_cnt`` ``(B, S, Tb)`` the states of each pair's top row,
        ``right_sum``/``right_cnt`` ``(B, S, Ta)`` the states of each pair's right column,
        and ``min`` (or None).
    """
    B, Ta, Tb = grid.shape
    S = 2 * L + 1
    dev, dt = grid.device, grid.dtype
    inf = float("inf")
    bp_dtype = torch.int8 if S <= 127 else torch.int16 if S <= 32767 else torch.int32
    g_all = grid.masked_fill(~_valid_mask(la, lb, Ta, Tb), inf)
    bp = torch.zeros(3, B, Ta, Tb, dtype=bp_dtype, device=dev)
    prev_sum = torch.full((B, S, Tb), inf, dtype=dt, device=dev)
    prev_cnt = torch.zeros((B, S, Tb), dtype=torch.int32, device=dev)
    top_sum, top_cnt = prev_sum.clone(), prev_cnt.clone()
    right_sum = torch.full((B, S, Ta), inf, dtype=dt, device=dev)
    right_cnt = torch.zeros((B, S, Ta), dtype=torch.int32, device=dev)
    cmin = torch.empty((B, Ta, Tb), dtype=dt, device=dev) if keep_min else None
    # H1 may follow D or any V state: positions in prev/cur state order.
    h1_from = torch.tensor([0] + list(range(L + 1, S)), device=dev)
    top_rows = set((la - 1).tolist())
    for i in range(Ta):
        g = g_all[:, i]                                       # (B, Tb)
        cur_sum = torch.empty_like(prev_sum)
        cur_cnt = torch.empty_like(prev_cnt)
        # D from any state at (i-1, j-1); first minimum wins (D, then H, then V).
        m, a = prev_sum.min(dim=1)                            # (B, Tb)
        c = prev_cnt.gather(1, a[:, None])[:, 0]
        cur_sum[:, 0, 0] = inf
        torch.add(g[:, 1:], m[:, :-1], out=cur_sum[:, 0, 1:])
        cur_cnt[:, 0, 0] = 1
        torch.add(c[:, :-1], 1, out=cur_cnt[:, 0, 1:])
        bp[0, :, i, 1:] = a[:, :-1]
        if i == 0:                                            # the start cell counts as D
            cur_sum[:, 0, 0] = g[:, 0]
        # V1 from D or any H state at (i-1, j); V_c from V_{c-1} at (i-1, j).
        m, a = prev_sum[:, : L + 1].min(dim=1)
        torch.add(g, m, out=cur_sum[:, L + 1])
        torch.add(prev_cnt.gather(1, a[:, None])[:, 0], 1, out=cur_cnt[:, L + 1])
        bp[2, :, i] = a
        if L > 1:
            torch.add(g[:, None], prev_sum[:, L + 1: S - 1], out=cur_sum[:, L + 2:])
            torch.add(prev_cnt[:, L + 1: S - 1], 1, out=cur_cnt[:, L + 2:])
        # H1 from D or any V state at (i, j-1); H_c from H_{c-1} at (i, j-1): L shifts.
        m, a = cur_sum[:, h1_from].min(dim=1)
        c = cur_cnt[:, h1_from].gather(1, a[:, None])[:, 0]
        cur_sum[:, 1:L + 1, 0] = inf
        cur_cnt[:, 1:L + 1, 0] = 1
        torch.add(g[:, 1:], m[:, :-1], out=cur_sum[:, 1, 1:])
        torch.add(c[:, :-1], 1, out=cur_cnt[:, 1, 1:])
        bp[1, :, i, 1:] = h1_from[a[:, :-1]]
        for k in range(2, L + 1):
            torch.add(g[:, 1:], cur_sum[:, k - 1, :-1], out=cur_sum[:, k, 1:])
            torch.add(cur_cnt[:, k - 1, :-1], 1, out=cur_cnt[:, k, 1:])
        # What the end-cell choice needs: each pair's top row and right column.
        if i in top_rows:
            at_top = (la - 1 == i)[:, None, None]
            top_sum = torch.where(at_top, cur_sum, top_sum)
            top_cnt = torch.where(at_top, cur_cnt, top_cnt)
        col = (lb - 1)[:, None, None].expand(B, S, 1)
        right_sum[:, :, i] = cur_sum.gather(2, col)[:, :, 0]
        right_cnt[:, :, i] = cur_cnt.gather(2, col)[:, :, 0]
        if keep_min:
            cmin[:, i] = cur_sum.min(dim=1).values
        prev_sum, prev_cnt = cur_sum, cur_cnt
    return dict(bp=bp, top_sum=top_sum, top_cnt=top_cnt, right_sum=right_sum,
                right_cnt=right_cnt, min=cmin)


def _effective_run(L: int, Ta: int, Tb: int) -> int:
    """A run can never exceed ``max(Ta, Tb) - 1`` steps, so a larger limit changes nothing."""
    return max(1, min(L, max(Ta, Tb) - 1))


# ----------------------------------------------------------------------------- end choice


def _choose_end(fw, la, lb, L):
    """Pick each pair's end cell and state: minimal average, ties as in the module docstring.

    Returns ``(i, j, state, total, length)``, each ``(B,)``.
    """
    top_sum, top_cnt, right_sum, right_cnt = fw["top_sum"], fw["top_cnt"], fw["right_sum"], fw["right_cnt"]
    B, S, Tb = top_sum.shape
    Ta = right_sum.shape[2]
    dev = top_sum.device
    j = torch.arange(Tb, device=dev)
    i = torch.arange(Ta, device=dev)
    s = torch.arange(S, device=dev)
    top_ok = (j[None, :] < lb[:, None])[:, None, :].expand(B, S, Tb)
    right_ok = (i[None, :] < la[:, None] - 1)[:, None, :].expand(B, S, Ta)   # corner is in top
    inf = float("inf")
    top_avg = (top_sum / top_cnt.clamp_min(1)).masked_fill(~top_ok, inf)
    right_avg = (right_sum / right_cnt.clamp_min(1)).masked_fill(~right_ok, inf)
    # Priority ranks: corner, top edge right to left, right edge top to bottom; then state.
    top_rank = (lb[:, None] - 1 - j[None, :])[:, None, :] * S + s[None, :, None]
    right_rank = (lb[:, None] + la[:, None] - 2 - i[None, :])[:, None, :] * S + s[None, :, None]
    avg = torch.cat([top_avg.flatten(1), right_avg.flatten(1)], dim=1)      # (B, S*Tb + S*Ta)
    rank = torch.cat([top_rank.expand(B, S, Tb).flatten(1), right_rank.expand(B, S, Ta).flatten(1)], 1)
    best = avg.min(dim=1, keepdim=True).values
    if bool(torch.isinf(best).any()):
        b = int(torch.isinf(best[:, 0]).nonzero()[0])
        raise ValueError(
            f"pair {b}: no cell on the top or right edge of its {int(la[b])}x{int(lb[b])} grid can be "
            f"reached from (0, 0) with slope limit {L} without crossing an infinite cost"
        )
    rank = rank.masked_fill(avg != best, torch.iinfo(rank.dtype).max)
    k = rank.argmin(dim=1)                                                  # (B,)
    in_top = k < S * Tb
    kt, kr = k.clamp_max(S * Tb - 1), (k - S * Tb).clamp_min(0)
    state = torch.where(in_top, kt // Tb, kr // Ta)
    end_i = torch.where(in_top, la - 1, kr % Ta)
    end_j = torch.where(in_top, kt % Tb, lb - 1)
    sums = torch.cat([top_sum.flatten(1), right_sum.flatten(1)], 1)
    cnts = torch.cat([top_cnt.flatten(1), right_cnt.flatten(1)], 1)
    total = sums.gather(1, k[:, None])[:, 0]
    length = cnts.gather(1, k[:, None])[:, 0].long()
    return end_i, end_j, state, total, length


# ----------------------------------------------------------------------------- backtracking


def _backtrack(bp, end_i, end_j, state, length, L):
    """Step every pair back from its end at once; ``(B, P, 2)`` cells from ``(0, 0)``, ``-1`` padded."""
    _, B, Ta, Tb = bp.shape
    dev = bp.device
    P = int(length.max())
    flat = bp.flatten(2).long()                                             # (3, B, Ta*Tb)
    i, j, s = end_i.clone(), end_j.clone(), state.clone()
    rev = torch.empty(B, P, 2, dtype=torch.long, device=dev)
    rev[:, 0, 0], rev[:, 0, 1] = i, j
    for step in range(1, P):
        idx = (i * Tb + j)[None, :, None].expand(3, B, 1)
        pd, ph, pv = flat.gather(2, idx)[:, :, 0]
        is_d, is_h = s == 0, (s >= 1) & (s <= L)
        is_v = s > L
        done = (i == 0) & (j == 0)
        new_s = torch.where(is_d, pd, torch.where(is_h, torch.where(s == 1, ph, s - 1),
                                                  torch.where(s == L + 1, pv, s - 1)))
        ni = torch.where(done, i, i - (is_d | is_v).long())
        nj = torch.where(done, j, j - (is_d | is_h).long())
        s = torch.where(done, s, new_s)
        i, j = ni, nj
        rev[:, step, 0], rev[:, step, 1] = i, j
    # Reverse each path within its own length: cell t of the path is rev[n - 1 - t].
    t = torch.arange(P, device=dev)
    src = (length[:, None] - 1 - t[None, :]).clamp_min(0)
    cells = rev.gather(1, src[:, :, None].expand(B, P, 2))
    return cells.masked_fill((t[None, :] >= length[:, None])[:, :, None], -1)


# ----------------------------------------------------------------------------- implementations


def _timewarp_torch(grid, la, lb, L, unbatched) -> WarpPath:
    """This module's search (any device): forward pass, end choice, backtracking."""
    Le = _effective_run(L, grid.shape[1], grid.shape[2])
    fw = _forward(grid, la, lb, Le)
    end_i, end_j, state, total, length = _choose_end(fw, la, lb, L)
    cells = _backtrack(fw["bp"], end_i, end_j, state, length, Le)
    out = WarpPath(cells=cells, length=length, cost=total / length.to(total.dtype), total=total)
    if unbatched:
        out = WarpPath(cells=cells[0], length=length[0], cost=out.cost[0], total=total[0])
    return out


def _cumulative_torch(grid, la, lb, L, unbatched) -> torch.Tensor:
    out = _forward(grid, la, lb, _effective_run(L, grid.shape[1], grid.shape[2]), keep_min=True)["min"]
    return out[0] if unbatched else out


# The compiled kernels are imported where used, so that importing this module loads no numba.
def _timewarp_compiled(grid, la, lb, L, unbatched) -> WarpPath:
    from ..cpu.timewarp import timewarp_batch

    B, Ta, Tb = grid.shape
    g = grid.detach().contiguous().numpy()
    cells = np.full((B, Ta + Tb - 1, 2), -1, dtype=np.int64)
    length = np.zeros(B, dtype=np.int64)
    total = np.zeros(B, dtype=g.dtype)
    timewarp_batch(g, la.numpy(), lb.numpy(), L, cells, length, total)
    if (length < 0).any():
        b = int(np.nonzero(length < 0)[0][0])
        raise ValueError(
            f"pair {b}: no cell on the top or right edge of its {int(la[b])}x{int(lb[b])} grid can be "
            f"reached from (0, 0) with slope limit {L} without crossing an infinite cost"
        )
    cells_t, length_t, total_t = torch.from_numpy(cells[:, : int(length.max())]), torch.from_numpy(length), torch.from_numpy(total)
    cost = total_t / length_t.to(total_t.dtype)
    if unbatched:
        return WarpPath(cells=cells_t[0], length=length_t[0], cost=cost[0], total=total_t[0])
    return WarpPath(cells=cells_t, length=length_t, cost=cost, total=total_t)


def _cumulative_compiled(grid, la, lb, L, unbatched) -> torch.Tensor:
    from ..cpu.timewarp import cumulative_cost_batch

    out = np.full(tuple(grid.shape), np.inf, dtype=grid.detach().numpy().dtype)
    cumulative_cost_batch(grid.detach().contiguous().numpy(), la.numpy(), lb.numpy(), L, out)
    out = torch.from_numpy(out)
    return out[0] if unbatched else out


@dataclass(frozen=True)
class DynamicProgram:
    """One implementation of the DP: its two entry points, each taking ``(grid (B, Ta, Tb), la (B,),
    lb (B,), L, unbatched)`` as :func:`_check_inputs` gives them and returning :func:`timewarp`'s
    and :func:`cumulative_cost`'s results. A splicing backend gives the one it computes with
    (:attr:`~torchsplice.splice.backends.Backend.dynamic_program`); another (a GPU kernel, say)
    is one more instance, given by its backend."""

    timewarp: Callable[..., WarpPath]
    cumulative: Callable[..., torch.Tensor]


TORCH_DP = DynamicProgram(_timewarp_torch, _cumulative_torch)
"""This module's search: any device (the torch backend's, and every backend's by default)."""

COMPILED_DP = DynamicProgram(_timewarp_compiled, _cumulative_compiled)
"""The compiled search of :mod:`torchsplice.cpu.timewarp`: CPU tensors (the compiled backend's)."""

CHOOSER = "torchsplice.splice.backends:dynamic_program_for"
"""``"module:function"``: ``function(backend, device)`` gives the :class:`DynamicProgram` that a
``backend`` name (``"auto"`` included) means for a grid on ``device``, raising ``ValueError`` for
a name it does not know or a device the backend does not run on (the splicing backends' registry,
imported when first used)."""


def _program(backend: str, grid: torch.Tensor) -> DynamicProgram:
    """The DP ``backend`` names for ``grid``'s device, as the registered splicing backends choose it
    (:data:`CHOOSER`)."""
    module, _, function = CHOOSER.partition(":")
    return getattr(importlib.import_module(module), function)(backend, grid.device)


# ----------------------------------------------------------------------------- public API


def timewarp(grid, lengths_a=None, lengths_b=None, max_run: int = 3, backend: str = "auto") -> WarpPath:
    """Optimal slope-limited time alignment of each pair (Heck et al. 2006, §3.1).

    Args:
        grid: ``(B, Ta, Tb)`` frame distances (rows: frames of clip A, the locomotion; columns:
            frames of clip B, the action), or one unbatched ``(Ta, Tb)`` grid. Float (integers
            are converted to the default dtype; half precision is computed in float32).
        lengths_a: ``(B,)`` integers in ``[1, Ta]``, the valid rows of each pair (a scalar for an
            unbatched grid); None means ``Ta``.
        lengths_b: ``(B,)`` integers in ``[1, Tb]``, the valid columns; None means ``Tb``.
        max_run: the slope limit ``L >= 1``: at most ``L`` consecutive horizontal steps and at
            most ``L`` consecutive vertical steps.
        backend: a splicing backend's name, whose DP runs (:data:`CHOOSER`): ``"auto"`` (the
            registered backends' choice for the grid's device: the compiled DP of
            :mod:`torchsplice.cpu.timewarp` for CPU tensors, this module's torch code otherwise,
            unless a backend of higher priority is registered there), ``"compiled"`` or
            ``"torch"``. Both built-ins give the same paths, lengths and totals, bit for bit.

    Returns:
        A :class:`WarpPath`; for an unbatched grid its fields drop the batch dimension
        (``cells (P, 2)`` and scalar ``length``, ``cost``, ``total``).

    Raises:
        ValueError: bad shapes or lengths, ``max_run < 1``, an empty grid, NaN or ``-inf`` in a
            valid cell, or a pair whose every path to its top or right edge crosses ``+inf``.
    """
    grid, la, lb, L, unbatched = _check_inputs(grid, lengths_a, lengths_b, max_run)
    return _program(backend, grid).timewarp(grid, la, lb, L, unbatched)


def cumulative_cost(grid, lengths_a=None, lengths_b=None, max_run: int = 3, backend: str = "auto") -> torch.Tensor:
    """Minimal summed cost of a slope-limited path from ``(0, 0)`` to every cell.

    Args and conventions as :func:`timewarp`. Returns ``(B, Ta, Tb)`` (``(Ta, Tb)`` for an
    unbatched grid): the minimum over final states of the path totals; ``+inf`` where a cell is
    unreachable under the slope limit, blocked by ``+inf`` costs, or padding.
    """
    grid, la, lb, L, unbatched = _check_inputs(grid, lengths_a, lengths_b, max_run)
    return _program(backend, grid).cumulative(grid, la, lb, L, unbatched)


def reachable_mask(Ta: int, Tb: int, max_run: int = 3, device=None) -> torch.Tensor:
    """``(Ta, Tb)`` bool: cells some path from ``(0, 0)`` reaches with slope limit ``max_run``.

    Closed form: ``j <= (L + 1) i + L`` and ``i <= (L + 1) j + L``.
    """
    if isinstance(max_run, bool) or not isinstance(max_run, int) or max_run < 1:
        raise ValueError(f"max_run must be an integer >= 1, got {max_run!r}")
    if Ta < 1 or Tb < 1:
        raise ValueError(f"Ta and Tb must be >= 1, got {Ta}, {Tb}")
    i = torch.arange(Ta, device=device)[:, None]
    j = torch.arange(Tb, device=device)[None, :]
    L = max_run
    return (j <= (L + 1) * i + L) & (i <= (L + 1) * j + L)
