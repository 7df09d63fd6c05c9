"""Alignment curves and resampling of clips at fractional frame times.

The timewarp gives a discrete, monotone path of cells ``(i, j)``: frame ``i`` of the
locomotion corresponds to frame ``j`` of the action. :func:`fit_alignment_curve` turns it into
the time alignment curve ``lambda(t)`` of Heck et al. 2006: a cubic B-spline, strictly
increasing and endpoint interpolating (``lambda(0) = j_first``, ``lambda(i_last) = j_last``),
evaluated at every locomotion frame ``t = 0 .. i_last``. Clips are then resampled at those
fractional frame times: positions linearly, rotations by slerp.

Batches hold pairs of different lengths: per-pair sizes come as ``(B,)`` tensors and outputs
are padded (curves with their last value, frames by repeating the last frame). Curves are
computed in float64.
"""

from __future__ import annotations

from dataclasses import replace

import torch

from ..core.rotations import quat_slerp

__all__ = ["bspline_basis", "fit_alignment_curve", "interpolate_frames", "slerp_frames", "resample_times",
           "resample_motion"]

_DEGREE = 3


def _clamped_knots(n_ctrl: torch.Tensor, n_max: int) -> torch.Tensor:
    """``(B, n_max + 4)`` clamped uniform cubic knot vectors on [0, 1]; knots past a pair's own
    ``n_ctrl + 4`` are 2.0 (outside the domain, so their spans never hold a sample)."""
    m = torch.arange(n_max + _DEGREE + 1, dtype=torch.float64, device=n_ctrl.device)
    n = n_ctrl.to(torch.float64)[:, None]
    inner = (m - _DEGREE) / (n - _DEGREE)  # uniform interior spacing
    knots = inner.clamp(0.0, 1.0)
    return torch.where(m < n + _DEGREE + 1, knots, torch.full_like(knots, 2.0))


def bspline_basis(u: torch.Tensor, n_ctrl: torch.Tensor, n_max: int | None = None) -> torch.Tensor:
    """Cubic clamped-uniform B-spline basis values.

    Args:
        u: ``(B, P)`` parameters in [0, 1].
        n_ctrl: ``(B,)`` number of control points per pair (at least 4).
        n_max: width of the output (default ``n_ctrl.max()``).

    Returns:
        ``(B, P, n_max)`` basis values; columns past a pair's ``n_ctrl`` are zero and each row
        of a pair's own columns sums to one (partition of unity). ``u = 1`` evaluates the limit
        from the left, so the curve interpolates its last control point.
    """
    n_max = int(n_ctrl.max()) if n_max is None else n_max
    knots = _clamped_knots(n_ctrl, n_max)  # (B, M)
    u = u.to(torch.float64)
    # the last span of each pair is closed on the right so that u = 1 falls inside it
    last = (n_ctrl - 1).to(torch.long)  # index of the last non-empty span: knots[last] < knots[last + 1] = 1
    k = torch.arange(knots.shape[1] - 1, device=u.device)
    lo, hi = knots[:, None, :-1], knots[:, None, 1:]
    N = ((u[..., None] >= lo) & (u[..., None] < hi)).to(torch.float64)
    is_last = (k[None, None, :] == last[:, None, None]).to(torch.float64)
    N = torch.where(u[..., None] >= 1.0, is_last, N)
    for d in range(1, _DEGREE + 1):
        t0, t1 = knots[:, None, : -d - 1], knots[:, None, d:-1]  # t_k, t_{k+d}
        s0, s1 = knots[:, None, 1:-d], knots[:, None, d + 1:]  # t_{k+1}, t_{k+d+1}
        left = torch.where(t1 > t0, (u[..., None] - t0) / (t1 - t0).clamp_min(1e-300), torch.zeros(()))
        right = torch.where(s1 > s0, (s1 - u[..., None]) / (s1 - s0).clamp_min(1e-300), torch.zeros(()))
        N = left * N[..., :-1] + right * N[..., 1:]
    return N[..., :n_max]


def _second_difference_penalty(n_ctrl: torch.Tensor, n_max: int) -> torch.Tensor:
    """``(B, n, n)`` matrix ``D^T D`` of divided second differences of each pair's coefficients.

    Differences are taken against the Greville abscissae, so the penalty vanishes exactly on
    straight lines (whose control points lie on the line at those abscissae).
    """
    knots = _clamped_knots(n_ctrl, n_max)
    greville = (knots[:, 1:n_max + 1] + knots[:, 2:n_max + 2] + knots[:, 3:n_max + 3]) / 3.0  # (B, n)
    B = n_ctrl.shape[0]
    rows = torch.arange(max(n_max - 2, 0), device=n_ctrl.device)
    valid = (rows[None, :] + 2 < n_ctrl[:, None]).to(torch.float64)
    h0 = (greville[:, 1:-1] - greville[:, :-2]).clamp_min(1e-9)  # spacing k -> k+1
    h1 = (greville[:, 2:] - greville[:, 1:-1]).clamp_min(1e-9)  # spacing k+1 -> k+2
    scale = 1.0 / (n_ctrl[:, None].to(torch.float64) - 1)  # keep the penalty's size independent of n
    D = torch.zeros(B, rows.numel(), n_max, dtype=torch.float64, device=n_ctrl.device)
    D[:, rows, rows] = valid * scale / h0
    D[:, rows, rows + 1] = -valid * scale * (1 / h0 + 1 / h1)
    D[:, rows, rows + 2] = valid * scale / h1
    return D.transpose(1, 2) @ D


def fit_alignment_curve(
    cells: torch.Tensor,
    length: torch.Tensor,
    knot_spacing: float = 8.0,
    smoothing: float = 1e-2,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Fit the time alignment curve to timewarp paths and evaluate it at every frame.

    Args:
        cells: ``(B, P, 2)`` long path cells ``(i, j)`` (locomotion frame, action frame),
            monotone, padded with -1 past ``length``.
        length: ``(B,)`` number of cells on each path (at least 2).
        knot_spacing: frames of the locomotion per B-spline span (about 0.25 s is right for
            human motion); the number of control points is ``round(i_last / knot_spacing) + 3``,
            at least 4.
        smoothing: weight of a second-difference penalty on the control points (P-spline),
            relative to the data term per path cell.

    Returns:
        ``curve`` ``(B, T)`` float64 with ``T = max(i_last) + 1``: ``curve[b, t]`` is the action
        frame matched to locomotion frame ``t``, strictly increasing over ``t = 0 .. i_last[b]``
        and padded with its last value after; and ``frames`` ``(B,)`` = ``i_last + 1``.

    The control points are fitted by least squares with the first and last fixed to the path's
    end values (so the curve interpolates its endpoints), then made strictly increasing, which
    makes the cubic B-spline strictly increasing. A straight path gives a straight line exactly.
    """
    if cells.dim() != 3 or cells.shape[-1] != 2:
        raise ValueError(f"cells must be (B, P, 2), got {tuple(cells.shape)}")
    B, P, _ = cells.shape
    dev = cells.device
    if bool((length < 2).any()):
        raise ValueError("every path needs at least 2 cells")
    idx = torch.arange(P, device=dev)
    valid = idx[None, :] < length[:, None]
    last = (length - 1).clamp_min(0)
    end = cells[torch.arange(B, device=dev), last]  # (B, 2)
    i_last, j_last = end[:, 0].to(torch.float64), end[:, 1].to(torch.float64)
    j_first = cells[:, 0, 1].to(torch.float64)
    if bool((i_last <= 0).any()) or bool((j_last <= j_first).any()):
        raise ValueError("the alignment does not advance in both clips")
    n_ctrl = (torch.round(i_last / knot_spacing) + _DEGREE).clamp_min(_DEGREE + 1).to(torch.long)
    n = int(n_ctrl.max())
    u = torch.where(valid, cells[..., 0].to(torch.float64) / i_last[:, None], torch.zeros(()))
    y = cells[..., 1].to(torch.float64)
    Bm = bspline_basis(u, n_ctrl, n) * valid[..., None]  # (B, P, n); padding rows contribute nothing
    cols = torch.arange(n, device=dev)
    fixed = torch.zeros(B, n, dtype=torch.float64, device=dev)
    fixed[:, 0] = j_first
    fixed.scatter_(1, (n_ctrl - 1)[:, None], j_last[:, None])
    free = ((cols[None, :] > 0) & (cols[None, :] < n_ctrl[:, None] - 1)).to(torch.float64)  # (B, n)
    pen = smoothing * _second_difference_penalty(n_ctrl, n)
    rhs_y = (y - (Bm @ fixed[..., None])[..., 0]) * valid
    A = Bm.transpose(1, 2) @ Bm + pen
    A = free[:, :, None] * A * free[:, None, :] + torch.diag_embed(1.0 - free)
    b = free * ((Bm.transpose(1, 2) @ rhs_y[..., None])[..., 0] - (pen @ fixed[..., None])[..., 0])
    coef = torch.linalg.solve(A, b[..., None])[..., 0] * free + fixed
    coef = _strictly_increasing(coef, n_ctrl, j_first, j_last)
    T = int(i_last.max()) + 1
    t = torch.arange(T, dtype=torch.float64, device=dev)
    ut = (t[None, :] / i_last[:, None]).clamp(max=1.0)
    curve = (bspline_basis(ut, n_ctrl, n) @ coef[..., None])[..., 0]
    return curve, (i_last + 1).to(torch.long)


def _strictly_increasing(coef: torch.Tensor, n_ctrl: torch.Tensor, first: torch.Tensor, last: torch.Tensor) -> torch.Tensor:
    """Raise/lower control points as little as needed so each pair's own are strictly increasing
    from ``first`` to ``last`` (steps of at least 1% of the mean step)."""
    n = coef.shape[1]
    k = torch.arange(n, dtype=torch.float64, device=coef.device)[None, :]
    eps = 0.01 * (last - first)[:, None] / (n_ctrl[:, None] - 1)
    inside = k < n_ctrl[:, None]
    c = torch.where(inside, coef, last[:, None] + eps * (k - n_ctrl[:, None] + 1))
    c = torch.cummax(c - eps * k, dim=1).values + eps * k  # c_k >= c_{k-1} + eps
    top = last[:, None] - eps * (n_ctrl[:, None] - 1 - k)  # c_k <= last - eps * (steps left)
    c = torch.minimum(c, torch.where(inside, top, c))
    c[:, 0] = first
    return torch.where(inside, c, torch.zeros_like(c))


def _gather_frames(x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``x[b, index[b, t]]`` for ``x`` ``(B, T, ...)`` and ``index`` ``(B, T')``."""
    shape = index.shape + x.shape[2:]
    flat = index.reshape(index.shape + (1,) * (x.dim() - 2)).expand(shape)
    return torch.gather(x, 1, flat)


def _split_times(times: torch.Tensor, lengths: torch.Tensor | None, T: int):
    top = (lengths - 1) if lengths is not None else torch.full(times.shape[:1], T - 1, device=times.device)
    t = torch.minimum(times.clamp_min(0.0), top[:, None].to(times.dtype))
    i0 = torch.floor(t).to(torch.long)
    i1 = torch.minimum(i0 + 1, top[:, None].to(torch.long))
    return i0, i1, (t - i0.to(t.dtype))


def interpolate_frames(x: torch.Tensor, times: torch.Tensor, lengths: torch.Tensor | None = None) -> torch.Tensor:
    """Linear interpolation of ``x`` ``(B, T, ...)`` at fractional frame ``times`` ``(B, T')``.

    Times are clamped to each clip's ``[0, lengths - 1]``. Returns ``(B, T', ...)`` in ``x``'s dtype.
    """
    if x.shape[0] != times.shape[0]:
        raise ValueError(f"x (B={x.shape[0]}) and times (B={times.shape[0]}) must have the same batch size")
    i0, i1, w = _split_times(times, lengths, x.shape[1])
    w = w.to(x.dtype).reshape(w.shape + (1,) * (x.dim() - 2))
    a, b = _gather_frames(x, i0), _gather_frames(x, i1)
    return a + w * (b - a)


def slerp_frames(q: torch.Tensor, times: torch.Tensor, lengths: torch.Tensor | None = None) -> torch.Tensor:
    """Slerp of rotations ``q`` ``(B, T, ..., 4)`` (unit WXYZ) at fractional frame ``times`` ``(B, T')``.

    Takes the shorter arc; times that fall on a frame return that frame's quaternion exactly.
    Returns ``(B, T', ..., 4)``.
    """
    if q.shape[-1] != 4:
        raise ValueError(f"q must end in 4 (WXYZ), got {tuple(q.shape)}")
    i0, i1, w = _split_times(times, lengths, q.shape[1])
    w = w.to(q.dtype).reshape(w.shape + (1,) * (q.dim() - 3))
    return quat_slerp(_gather_frames(q, i0), _gather_frames(q, i1), w)


def resample_times(num_frames: int, fps_from: float, fps_to: float) -> torch.Tensor:
    """Fractional frame times (float64) at which to sample a ``num_frames`` clip at ``fps_from``
    to play it at ``fps_to``: ``k * fps_from / fps_to`` for every ``k`` that stays inside the clip."""
    count = int((num_frames - 1) * fps_to / fps_from + 1e-9) + 1
    return torch.arange(count, dtype=torch.float64) * (fps_from / fps_to)


def resample_motion(motion, fps: float):
    """A :class:`~torchsplice.core.motion.Motion` played at ``fps``: rotations by slerp, the root
    and translations by linear interpolation, at :func:`resample_times` (so bone lengths stay
    exact); the clip itself if it is at ``fps`` already."""
    if abs(motion.fps - fps) <= 1e-6 * fps:
        return motion
    times = resample_times(motion.num_frames, motion.fps, fps).to(motion.device)[None]
    lengths = torch.tensor([motion.num_frames], device=motion.device)
    rot = slerp_frames(motion.rotations[None], times, lengths)[0]
    root = interpolate_frames(motion.root_translation[None], times, lengths)[0]
    trans = None if motion.translations is None else interpolate_frames(motion.translations[None], times, lengths)[0]
    return replace(motion, rotations=rot, root_translation=root, translations=trans, fps=fps, labels=dict(motion.labels))
