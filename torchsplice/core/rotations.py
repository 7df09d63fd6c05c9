"""Rotation conversions and quaternion algebra on torch tensors.

Conventions, used everywhere in torchsplice:

- **Quaternions are unit quaternions in WXYZ order** (scalar first): ``(..., 4)`` tensors
  ``[w, x, y, z]``. ``q`` and ``-q`` are the same rotation; functions that return quaternions
  return the representative with ``w >= 0`` unless they say otherwise.
- **Rotation matrices act on column vectors**: ``v_parent = R @ v_local``; ``(..., 3, 3)``.
- **Euler angles follow BVH**: an order such as ``"ZXY"`` lists the axes as the channels
  appear in a BVH file, and means ``R = R_Z(a0) @ R_X(a1) @ R_Y(a2)`` (intrinsic rotations, the
  first listed axis outermost). Angles are ``(..., 3)`` tensors in that same order, in degrees
  unless ``degrees=False``.
- **Up axes** (x, y or z: 0, 1, 2; a spec's ``up_axis``): Y-up is the reference. A Z-up world is
  the Y-up one turned +90 degrees about X (Y goes to Z, Z to -Y: the usual Z-up / Y-up exchange),
  an X-up world the Y-up one turned -90 degrees about Z (Y goes to X, X to -Y); a clip changes up
  axis by :func:`up_axis_turn`.
- Any number of leading batch dimensions is accepted; float32 and float64 both work; shapes
  that do not fit raise ``ValueError``.
"""

from __future__ import annotations

import math

import torch

from .quat_formulas import qmul

__all__ = [
    "EULER_ORDERS",
    "quat_between",
    "quat_identity",
    "quat_normalize",
    "quat_canonical",
    "quat_conj",
    "quat_mul",
    "quat_apply",
    "quat_to_rotmat",
    "rotmat_to_quat",
    "axis_angle_to_quat",
    "quat_to_axis_angle",
    "quat_angle",
    "euler_to_quat",
    "euler_to_rotmat",
    "rotmat_to_euler",
    "quat_to_euler",
    "quat_slerp",
    "random_quat",
    "quat_to_6d",
    "rotation_6d_to_rotmat",
    "up_axis_turn",
]

EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
_AXIS = {"X": 0, "Y": 1, "Z": 2}


def _check_last(t: torch.Tensor, n: int, name: str) -> None:
    if t.shape[-1:] != (n,):
        raise ValueError(f"{name} must have shape (..., {n}), got {tuple(t.shape)}")


def _check_order(order: str) -> str:
    order = order.upper()
    if order not in EULER_ORDERS:
        raise ValueError(f"Euler order must be one of {EULER_ORDERS}, got {order!r}")
    return order


def quat_identity(shape=(), dtype=torch.float32, device=None) -> torch.Tensor:
    """Identity quaternions of shape ``(*shape, 4)``, WXYZ."""
    q = torch.zeros(*shape, 4, dtype=dtype, device=device)
    q[..., 0] = 1.0
    return q


def quat_normalize(q: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """Scale ``(..., 4)`` quaternions to unit norm."""
    _check_last(q, 4, "q")
    return q / q.norm(dim=-1, keepdim=True).clamp_min(eps)


def quat_canonical(q: torch.Tensor) -> torch.Tensor:
    """The representative of each ``(..., 4)`` WXYZ quaternion with ``w >= 0``."""
    _check_last(q, 4, "q")
    return torch.where(q[..., :1] < 0, -q, q)


def quat_conj(q: torch.Tensor) -> torch.Tensor:
    """Conjugate (the inverse, for unit quaternions) of ``(..., 4)`` WXYZ quaternions."""
    _check_last(q, 4, "q")
    return q * q.new_tensor([1.0, -1.0, -1.0, -1.0])


def quat_mul(p: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
    """Hamilton product ``p * q`` of broadcastable ``(..., 4)`` WXYZ quaternions.

    As rotations: ``quat_mul(p, q)`` applies ``q`` first, then ``p``.
    """
    _check_last(p, 4, "p")
    _check_last(q, 4, "q")
    return torch.stack(qmul(p.unbind(-1), q.unbind(-1)), dim=-1)


def quat_apply(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate ``(..., 3)`` vectors by broadcastable ``(..., 4)`` unit WXYZ quaternions."""
    _check_last(q, 4, "q")
    _check_last(v, 3, "v")
    batch = torch.broadcast_shapes(q.shape[:-1], v.shape[:-1])
    q, v = q.expand(batch + (4,)), v.expand(batch + (3,))
    w, xyz = q[..., :1], q[..., 1:]
    t = 2.0 * torch.linalg.cross(xyz, v, dim=-1)
    return v + w * t + torch.linalg.cross(xyz, t, dim=-1)


def quat_to_rotmat(q: torch.Tensor) -> torch.Tensor:
    """``(..., 4)`` unit WXYZ quaternions to ``(..., 3, 3)`` rotation matrices."""
    _check_last(q, 4, "q")
    w, x, y, z = q.unbind(-1)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = torch.stack(
        (
            1 - 2 * (yy + zz),
            2 * (xy - wz),
            2 * (xz + wy),
            2 * (xy + wz),
            1 - 2 * (xx + zz),
            2 * (yz - wx),
            2 * (xz - wy),
            2 * (yz + wx),
            1 - 2 * (xx + yy),
        ),
        dim=-1,
    )
    return m.reshape(q.shape[:-1] + (3, 3))


def rotmat_to_quat(m: torch.Tensor) -> torch.Tensor:
    """``(..., 3, 3)`` rotation matrices to ``(..., 4)`` unit WXYZ quaternions with ``w >= 0``.

    Shepperd's method: of the four algebraically equal formulas, each element uses the one
    with the largest (best conditioned) denominator.
    """
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"m must have shape (..., 3, 3), got {tuple(m.shape)}")
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    # 4*w^2, 4*x^2, 4*y^2, 4*z^2
    sq = torch.stack((1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22), dim=-1)
    # each row: 4*c*(w, x, y, z) for the component c chosen
    cand = torch.stack(
        (
            torch.stack((sq[..., 0], m21 - m12, m02 - m20, m10 - m01), dim=-1),
            torch.stack((m21 - m12, sq[..., 1], m10 + m01, m02 + m20), dim=-1),
            torch.stack((m02 - m20, m10 + m01, sq[..., 2], m12 + m21), dim=-1),
            torch.stack((m10 - m01, m20 + m02, m21 + m12, sq[..., 3]), dim=-1),
        ),
        dim=-2,
    )
    best = sq.argmax(dim=-1, keepdim=True)
    q = torch.gather(cand, -2, best[..., None].expand(*best.shape[:-1], 1, 4)).squeeze(-2)
    return quat_canonical(quat_normalize(q))


def axis_angle_to_quat(axis_angle: torch.Tensor) -> torch.Tensor:
    """``(..., 3)`` rotation vectors (axis times angle, radians) to ``(..., 4)`` WXYZ quaternions."""
    _check_last(axis_angle, 3, "axis_angle")
    angle = axis_angle.norm(dim=-1, keepdim=True)
    half = 0.5 * angle
    # sin(half)/angle, with its limit 1/2 near zero
    scale = torch.where(angle > 1e-8, torch.sin(half) / angle.clamp_min(1e-8), 0.5 - angle**2 / 48)
    return torch.cat((torch.cos(half), axis_angle * scale), dim=-1)


def quat_to_axis_angle(q: torch.Tensor) -> torch.Tensor:
    """``(..., 4)`` unit WXYZ quaternions to ``(..., 3)`` rotation vectors (radians, angle <= pi)."""
    q = quat_canonical(q)
    xyz = q[..., 1:]
    s = xyz.norm(dim=-1, keepdim=True)
    angle = 2.0 * torch.atan2(s, q[..., :1])
    scale = torch.where(s > 1e-8, angle / s.clamp_min(1e-8), 2.0 + s**2 / 3)
    return xyz * scale


def quat_between(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """``(..., 4)`` the smallest rotation taking unit vectors ``u`` onto ``v`` (``(..., 3)``);
    for antipodal ``u = -v``, the half turn about a fixed axis perpendicular to ``u``."""
    _check_last(u, 3, "u")
    _check_last(v, 3, "v")
    d = (u * v).sum(-1, keepdim=True)
    c = torch.linalg.cross(u, v, dim=-1)
    # a perpendicular to u: cross with the basis axis least aligned with u
    basis = torch.eye(3, dtype=u.dtype, device=u.device)
    perp = torch.linalg.cross(u, basis[u.abs().argmin(dim=-1)], dim=-1)
    q = torch.cat((1.0 + d, c), dim=-1)
    q = torch.where((1.0 + d) < 1e-6, torch.cat((torch.zeros_like(d), perp), dim=-1), q)
    return quat_normalize(q)


def quat_angle(p: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
    """Geodesic angle in radians, ``(...)``, between rotations given as ``(..., 4)`` WXYZ quaternions."""
    _check_last(p, 4, "p")
    _check_last(q, 4, "q")
    d = (p * q).sum(-1).abs()
    s = quat_mul(quat_conj(p), q)[..., 1:].norm(dim=-1)
    return 2.0 * torch.atan2(s, d)


def euler_to_quat(angles: torch.Tensor, order: str, degrees: bool = True) -> torch.Tensor:
    """``(..., 3)`` Euler angles in BVH ``order`` (e.g. ``"ZXY"``) to ``(..., 4)`` WXYZ quaternions.

    ``q = q_order[0](a0) * q_order[1](a1) * q_order[2](a2)``; not canonicalised, so that
    continuous angle tracks give continuous quaternions.
    """
    _check_last(angles, 3, "angles")
    order = _check_order(order)
    half = angles * (0.5 * math.pi / 180.0 if degrees else 0.5)
    c, s = torch.cos(half), torch.sin(half)
    elementary = torch.zeros(angles.shape + (4,), dtype=angles.dtype, device=angles.device)  # (..., 3, 4)
    elementary[..., 0] = c
    for i, axis in enumerate(order):
        elementary[..., i, 1 + _AXIS[axis]] = s[..., i]
    q0, q1, q2 = elementary.unbind(-2)
    return quat_mul(quat_mul(q0, q1), q2)


def euler_to_rotmat(angles: torch.Tensor, order: str, degrees: bool = True) -> torch.Tensor:
    """``(..., 3)`` Euler angles in BVH ``order`` to ``(..., 3, 3)`` rotation matrices."""
    return quat_to_rotmat(euler_to_quat(angles, order, degrees))


def rotmat_to_euler(m: torch.Tensor, order: str, degrees: bool = True) -> torch.Tensor:
    """``(..., 3, 3)`` rotation matrices to ``(..., 3)`` Euler angles in BVH ``order``.

    The middle angle lies in ``[-90, 90]`` degrees. At gimbal lock (middle angle +-90) the
    third angle is set to zero and the first carries the whole remaining rotation. Near it the
    first angle is ill-conditioned (it comes from entries of the size of the middle angle's
    cosine, which a float32 rotation gets only to 1e-7), so the third is taken from what the
    first two leave of ``m``: the three angles give ``m`` back to rounding, however close to the
    lock (a constant -90 degree spine of a rig retargeted onto SMPL, say).
    """
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"m must have shape (..., 3, 3), got {tuple(m.shape)}")
    order = _check_order(order)
    i, j, k = (_AXIS[a] for a in order)
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # +1 for cyclic orders XYZ, YZX, ZXY
    sin_b = s * m[..., i, k]
    cos_b = torch.hypot(m[..., i, i], m[..., i, j])
    b = torch.atan2(sin_b, cos_b)
    a = torch.atan2(-s * m[..., j, k], m[..., k, k])
    c = torch.atan2(-s * m[..., i, j], m[..., i, i])
    lock = cos_b < (1e-9 if m.dtype == torch.float64 else 1e-5)
    a = torch.where(lock, torch.atan2(s * m[..., k, j], m[..., j, j]), a)
    near = cos_b < 1e-3  # the third angle from the residual R_k(c) = (R_i(a) R_j(b))^T m
    if bool(near.any()):
        ab = euler_to_rotmat(torch.stack((a, b, torch.zeros_like(a)), dim=-1), order, degrees=False)
        rest = ab.transpose(-1, -2) @ m
        c = torch.where(near, torch.atan2(-s * rest[..., i, j], rest[..., i, i]), c)
    out = torch.stack((a, b, c), dim=-1)
    return out * (180.0 / math.pi) if degrees else out


def quat_to_euler(q: torch.Tensor, order: str, degrees: bool = True) -> torch.Tensor:
    """``(..., 4)`` unit WXYZ quaternions to ``(..., 3)`` Euler angles in BVH ``order``."""
    return rotmat_to_euler(quat_to_rotmat(q), order, degrees)


def quat_slerp(p: torch.Tensor, q: torch.Tensor, t: torch.Tensor | float) -> torch.Tensor:
    """Spherical linear interpolation along the shorter arc, ``t`` in [0, 1] broadcast over ``(...)``.

    ``p`` and ``q`` are broadcastable ``(..., 4)`` unit WXYZ quaternions; ``t`` is a float or a
    ``(...)`` tensor. Nearly equal rotations fall back to normalised linear interpolation;
    ``t = 0`` returns ``p`` exactly.
    """
    _check_last(p, 4, "p")
    _check_last(q, 4, "q")
    t = torch.as_tensor(t, dtype=p.dtype, device=p.device)[..., None]
    dot = (p * q).sum(-1, keepdim=True)
    q = torch.where(dot < 0, -q, q)
    dot = dot.abs().clamp(max=1.0)
    theta = torch.acos(dot)
    sin_theta = torch.sin(theta)
    near = sin_theta < 1e-6
    safe = torch.where(near, torch.ones_like(sin_theta), sin_theta)
    wp = torch.where(near, 1.0 - t, torch.sin((1.0 - t) * theta) / safe)
    wq = torch.where(near, t, torch.sin(t * theta) / safe)
    out = quat_normalize(wp * p + wq * q)
    return torch.where(t == 0, p.expand_as(out), out)  # exactly p at t = 0


def random_quat(shape=(), dtype=torch.float32, device=None, generator=None) -> torch.Tensor:
    """Uniformly distributed random unit WXYZ quaternions of shape ``(*shape, 4)``."""
    q = torch.randn(*shape, 4, dtype=dtype, device=device, generator=generator)
    return quat_normalize(q)


def quat_to_6d(q: torch.Tensor) -> torch.Tensor:
    """``(..., 4)`` unit WXYZ quaternions to the ``(..., 6)`` continuous rotation representation
    of Zhou et al. 2019 (*On the Continuity of Rotation Representations in Neural Networks*): the
    first two columns of the rotation matrix, ``(R[0,0], R[1,0], R[2,0], R[0,1], R[1,1], R[2,1])``.

    :func:`rotation_6d_to_rotmat` inverts it (and maps any 6 numbers to a rotation)."""
    m = quat_to_rotmat(q)
    return torch.cat((m[..., :, 0], m[..., :, 1]), dim=-1)


def rotation_6d_to_rotmat(d: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """``(..., 6)`` 6D rotations (two matrix columns, as :func:`quat_to_6d`) to ``(..., 3, 3)``
    rotation matrices by Gram-Schmidt: ``b1 = a1/|a1|``, ``b2`` is ``a2`` less its ``b1`` part,
    normalised, ``b3 = b1 x b2``. Exact for the output of :func:`quat_to_6d`; a network's
    unnormalised output maps to the nearest such frame (:func:`rotmat_to_quat` gives quaternions)."""
    _check_last(d, 6, "d")
    a1, a2 = d[..., :3], d[..., 3:]
    b1 = a1 / a1.norm(dim=-1, keepdim=True).clamp_min(eps)
    b2 = a2 - (b1 * a2).sum(-1, keepdim=True) * b1
    b2 = b2 / b2.norm(dim=-1, keepdim=True).clamp_min(eps)
    b3 = torch.linalg.cross(b1, b2, dim=-1)
    return torch.stack((b1, b2, b3), dim=-1)


_FROM_Y_UP = {
    0: (math.sqrt(0.5), 0.0, 0.0, -math.sqrt(0.5)),
    1: (1.0, 0.0, 0.0, 0.0),
    2: (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0),
}
"""Per up axis, the turn taking a Y-up world to it (see the module docstring)."""


def up_axis_turn(source: int, target: int, dtype=torch.float64) -> torch.Tensor:
    """``(4,)`` the turn taking a world whose up axis is ``source`` (0, 1, 2: x, y, z) to one
    whose up axis is ``target``: it takes ``source``'s unit vector onto ``target``'s, and turning
    ``a`` to ``b`` then ``b`` to ``c`` is turning ``a`` to ``c`` (the identity when they are equal)."""
    if source not in _FROM_Y_UP or target not in _FROM_Y_UP:
        raise ValueError(f"up axes are 0, 1 or 2 (x, y, z), not {source!r} and {target!r}")
    to = torch.tensor(_FROM_Y_UP[int(target)], dtype=dtype)
    back = quat_conj(torch.tensor(_FROM_Y_UP[int(source)], dtype=dtype))
    return quat_canonical(quat_mul(to, back))
