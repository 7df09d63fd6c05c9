"""The Kovar et al. 2002 (Motion Graphs) frame distance, as whole batched grids.

A frame is a point cloud of ``K`` corresponding landmarks (Heck et al. 2006, Section 3.1:
the root and both knees; the set is the caller's). The distance between clouds ``a`` and
``b`` is

    D(a, b) = min over theta, t of  sum_k w_k |a_k - (R(theta) b_k + t)|^2

where ``R(theta)`` rotates about the vertical (up) axis and ``t`` translates in the floor
plane only (heights are not free). Weights default to uniform ``1/K`` and are used as
given in the cost (not renormalised); the optimal ``t`` is the difference of the weighted
centroids (weights normalised to sum 1 for the centroid).

Conventions:

- ``up_axis`` is 0, 1 or 2 (default 1: Y up). The floor-plane axes are
  ``a1 = (up_axis + 1) % 3`` and ``a2 = (up_axis + 2) % 3`` (Y up: ``a1 = Z``, ``a2 = X``).
- Rotating by ``theta`` about the up axis takes ``e_a1`` to ``cos(theta) e_a1 + sin(theta) e_a2``
  (a right-handed rotation about ``+up``; for Y up this is the usual ``R_y``: Z towards X).
- The heading of a floor direction ``d`` is ``atan2(d[a2], d[a1])`` (Y up: ``atan2(d_x, d_z)``,
  0 = facing +Z), so rotating by ``theta`` adds ``theta`` to every heading, and the ``theta``
  that aligns ``b`` onto ``a`` is close to ``heading_a - heading_b``.
- Angles are radians; returned angles are wrapped to ``[-pi, pi)``.

Closed form. With the floor coordinates of each cloud centred on its weighted centroid
(``ha_k``, ``hb_k``, 2-vectors in ``(a1, a2)`` order) and heights ``ya_k``, ``yb_k``::

    D = sum w (|ha|^2 + |hb|^2) + sum w (ya - yb)^2 - 2 max_theta (C cos theta + S sin theta)
    C = sum_k w_k ha_k . hb_k,   S = sum_k w_k (hb_k x ha_k)   (2D cross: hb_u ha_v - hb_v ha_u)

Unconstrained the maximum is ``sqrt(C^2 + S^2)`` at ``theta* = atan2(S, C)``. All of ``C``,
``S``, the height cross term and the norms are bilinear in the two frames' coordinates, so
a whole ``Ta x Tb`` grid is a couple of batched matrix products.

Mirror pitfall and heading restriction. With root and two knees the centred cloud is
nearly ``(0, v, -v)``: a half turn maps a pose onto its mirror half a stride later (left
knee forward <-> right knee forward), so the unconstrained metric cannot tell left from
right. Given per-frame headings (e.g. :func:`heading_from_hips`), ``theta`` is restricted to
``|wrap(theta - (heading_a - heading_b))| <= max_heading_deviation``; the maximiser is then
``theta*`` if it is allowed, else the nearer end of the allowed arc, and the maximum becomes
``sqrt(C^2 + S^2) cos(e - clamp(e))`` with ``e = wrap(theta* - (heading_a - heading_b))``,
still closed form over the whole grid.
"""

from __future__ import annotations

import math

import torch

from ..kinematics.heading import floor_axes, heading_from_hips  # the conventions above, defined with the heading frame

__all__ = ["wrap_angle", "floor_axes", "rotate_about_up", "heading_from_hips", "distance_grid", "align_frames"]


def wrap_angle(x: torch.Tensor) -> torch.Tensor:
    """Angles (radians) wrapped to ``[-pi, pi)``, any shape."""
    return torch.remainder(x + math.pi, 2 * math.pi) - math.pi


def rotate_about_up(points: torch.Tensor, theta: torch.Tensor | float, up_axis: int = 1) -> torch.Tensor:
    """Rotate ``(..., 3)`` points by ``theta`` (radians, float or tensor broadcast over ``(...)``) about the up axis.

    ``e_a1 -> cos(theta) e_a1 + sin(theta) e_a2`` (see the module docstring); the up
    coordinate is unchanged.
    """
    if points.shape[-1:] != (3,):
        raise ValueError(f"points must have shape (..., 3), got {tuple(points.shape)}")
    a1, a2 = floor_axes(up_axis)
    theta = torch.as_tensor(theta, dtype=points.dtype, device=points.device)
    c, s = torch.cos(theta), torch.sin(theta)
    u, v = points[..., a1], points[..., a2]
    out = [None, None, None]
    out[a1], out[a2] = c * u - s * v, s * u + c * v
    out[up_axis] = points[..., up_axis].expand_as(out[a1])
    return torch.stack(out, dim=-1)


def _check_clouds(a: torch.Tensor, b: torch.Tensor, min_dim: int, what: str) -> int:
    if a.dim() < min_dim or a.shape[-1] != 3:
        raise ValueError(f"a must have shape {what}, got {tuple(a.shape)}")
    if b.dim() < min_dim or b.shape[-1] != 3 or b.shape[-2] != a.shape[-2]:
        raise ValueError(f"b must have shape {what} with K={a.shape[-2]}, got {tuple(b.shape)}")
    if b.dtype != a.dtype:
        raise ValueError(f"a and b must share a dtype, got {a.dtype} and {b.dtype}")
    return a.shape[-2]


def _weights(weights, K: int, like: torch.Tensor) -> torch.Tensor:
    """``(..., K)`` weights (uniform ``1/K`` by default) and a check of their shape."""
    if weights is None:
        return like.new_full((K,), 1.0 / K)
    w = torch.as_tensor(weights, dtype=like.dtype, device=like.device)
    if w.dim() < 1 or w.shape[-1] != K:
        raise ValueError(f"weights must have shape (K={K},) or (..., K), got {tuple(w.shape)}")
    return w


def _centred(x: torch.Tensor, w: torch.Tensor, up_axis: int, ref: torch.Tensor):
    """Floor coordinates ``(..., K, 2)`` centred on the weighted centroid, heights ``(..., K)`` minus ``ref``, centroid ``(..., 2)``."""
    a1, a2 = floor_axes(up_axis)
    floor = x[..., [a1, a2]]
    wn = w / w.sum(-1, keepdim=True).clamp_min(torch.finfo(x.dtype).tiny)
    centroid = (wn[..., None] * floor).sum(-2)
    return floor - centroid[..., None, :], x[..., up_axis] - ref, centroid


def _embed(floor: torch.Tensor, up_axis: int) -> torch.Tensor:
    """``(..., 2)`` floor coordinates ``(a1, a2)`` to ``(..., 3)`` points with 0 on the up axis."""
    a1, a2 = floor_axes(up_axis)
    out = [None, None, None]
    out[a1], out[a2], out[up_axis] = floor[..., 0], floor[..., 1], torch.zeros_like(floor[..., 0])
    return torch.stack(out, dim=-1)


def _perp(h: torch.Tensor) -> torch.Tensor:
    """``(u, v) -> (v, -u)``, so that ``perp(ha) . hb = hb x ha`` (the ``S`` term)."""
    return torch.stack((h[..., 1], -h[..., 0]), dim=-1)


def _check_headings(heading_a, heading_b, max_dev: float) -> None:
    if (heading_a is None) != (heading_b is None):
        raise ValueError("give both heading_a and heading_b, or neither")
    if not max_dev >= 0:
        raise ValueError(f"max_heading_deviation must be >= 0, got {max_dev}")


def _best_rotation(C, S, delta, max_dev: float):
    """Maximum of ``C cos(theta) + S sin(theta)`` and its argmax, optionally with
    ``|wrap(theta - delta)| <= max_dev`` (``delta`` ``None`` for unconstrained)."""
    r = torch.hypot(C, S)
    theta = torch.atan2(S, C)
    if delta is None:
        return r, wrap_angle(theta)
    e = wrap_angle(theta - delta)
    ec = e.clamp(-max_dev, max_dev)
    return r * torch.cos(e - ec), wrap_angle(delta + ec)


def _check_inputs(a, b, weights, up_axis, heading_a, heading_b, max_dev, min_dim: int, shape: str) -> torch.Tensor:
    """Validate the arguments shared by :func:`distance_grid` and :func:`align_frames`; the weights."""
    K = _check_clouds(a, b, min_dim, shape)
    floor_axes(up_axis)
    _check_headings(heading_a, heading_b, max_dev)
    return _weights(weights, K, a)


def distance_grid(
    a: torch.Tensor,
    b: torch.Tensor,
    weights: torch.Tensor | None = None,
    up_axis: int = 1,
    heading_a: torch.Tensor | None = None,
    heading_b: torch.Tensor | None = None,
    max_heading_deviation: float = math.pi / 2,
) -> torch.Tensor:
    """``(..., Ta, Tb)`` distance between every frame ``i`` of ``a`` and every frame ``j`` of ``b``.

    Args:
        a: ``(..., Ta, K, 3)`` landmark positions of clip A, one cloud per frame.
        b: ``(..., Tb, K, 3)`` the same landmarks in clip B (batch dims broadcast with ``a``'s).
        weights: ``(K,)`` or ``(..., K)`` per-landmark weights (same for every frame), or
            ``None`` for uniform ``1/K``.
        up_axis: 0, 1 or 2 (default Y up); see the module docstring.
        heading_a, heading_b: optional ``(..., Ta)`` and ``(..., Tb)`` headings in radians (both
            or neither); when given, the rotation aligning ``b[j]`` onto ``a[i]`` is restricted to
            within ``max_heading_deviation`` of ``heading_a[i] - heading_b[j]``.
        max_heading_deviation: half-width of the allowed arc, radians (``>= pi``: unrestricted).

    Returns the minimum of ``sum_k w_k |a_ik - (R(theta) b_jk + t)|^2`` over rotations about
    up and floor translations, via a few batched matrix products; tiny negative round-off is
    clamped to 0.
    """
    w = _check_inputs(a, b, weights, up_axis, heading_a, heading_b, max_heading_deviation, 3, "(..., T, K, 3)")[..., None, :]  # (..., 1, K): same for every frame
    ref = a[..., up_axis].mean(dim=(-2, -1), keepdim=True)  # common height origin (round-off)
    ha, ya, _ = _centred(a, w, up_axis, ref)
    hb, yb, _ = _centred(b, w, up_axis, ref)
    Ta, Tb = a.shape[-3], b.shape[-3]
    wa = torch.cat((w[..., None] * ha, w[..., None] * _perp(ha)), dim=-3)  # (..., 2Ta, K, 2)
    CS = wa.flatten(-2) @ hb.flatten(-2).transpose(-1, -2)  # (..., 2Ta, Tb)
    C, S = CS[..., :Ta, :], CS[..., Ta:, :]
    Y = (w * ya) @ yb.transpose(-1, -2)
    na = (w * (ha.square().sum(-1) + ya.square())).sum(-1)
    nb = (w * (hb.square().sum(-1) + yb.square())).sum(-1)
    delta = None
    if heading_a is not None:
        ha_, hb_ = _check_heading_shape(heading_a, Ta, a), _check_heading_shape(heading_b, Tb, a)
        delta = ha_[..., :, None] - hb_[..., None, :]
    M, _ = _best_rotation(C, S, delta, max_heading_deviation)
    return (na[..., :, None] + nb[..., None, :] - 2.0 * (Y + M)).clamp_min(0.0)


def _check_heading_shape(h, T: int, like: torch.Tensor) -> torch.Tensor:
    h = torch.as_tensor(h, dtype=like.dtype, device=like.device)
    if h.dim() < 1 or h.shape[-1] != T:
        raise ValueError(f"headings must have shape (..., T={T}), got {tuple(h.shape)}")
    return h


def align_frames(
    a: torch.Tensor,
    b: torch.Tensor,
    weights: torch.Tensor | None = None,
    up_axis: int = 1,
    heading_a: torch.Tensor | None = None,
    heading_b: torch.Tensor | None = None,
    max_heading_deviation: float = math.pi / 2,
):
    """Distance and optimal transform between corresponding clouds ``a`` and ``b``.

    Args:
        a, b: ``(..., K, 3)`` corresponding clouds (batch dims broadcast).
        weights: ``(K,)`` or ``(..., K)``, or ``None`` (uniform ``1/K``).
        up_axis: 0, 1 or 2 (default Y up).
        heading_a, heading_b: optional ``(...)`` headings, radians (both or neither); restrict
            ``theta`` as in :func:`distance_grid`.
        max_heading_deviation: half-width of the allowed arc, radians.

    Returns ``(distance, theta, translation)``: ``(...)``, ``(...)`` radians in ``[-pi, pi)``,
    ``(..., 3)`` with 0 on the up axis, such that
    ``rotate_about_up(b, theta[..., None], up_axis) + translation[..., None, :]`` is the best fit of ``b`` onto
    ``a`` and ``distance = sum_k w_k |a_k - that_k|^2`` (evaluated directly).
    """
    w = _check_inputs(a, b, weights, up_axis, heading_a, heading_b, max_heading_deviation, 2, "(..., K, 3)")
    zero = a.new_zeros(())
    ha, _, ca = _centred(a, w, up_axis, zero)
    hb, _, cb = _centred(b, w, up_axis, zero)
    C = (w * (ha * hb).sum(-1)).sum(-1)
    S = (w * (_perp(ha) * hb).sum(-1)).sum(-1)
    delta = None
    if heading_a is not None:
        delta = torch.as_tensor(heading_a).to(a) - torch.as_tensor(heading_b).to(a)
    _, theta = _best_rotation(C, S, delta, max_heading_deviation)
    t = _embed(ca, up_axis) - rotate_about_up(_embed(cb, up_axis), theta, up_axis)
    fitted = rotate_about_up(b, theta[..., None], up_axis) + t[..., None, :]
    dist = (w * (a - fitted).square().sum(-1)).sum(-1)
    return dist, theta, t
