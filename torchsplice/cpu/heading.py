"""Headings for compiled kernels (numba): the character's facing from its hips, one frame at a time.

The twins of :mod:`torchsplice.kinematics.heading`, same formulas (see its docstring for why the
frame and the angle are two formulas): :func:`heading_q` is
:func:`~torchsplice.kinematics.heading.heading_frame` (posture transfer, :mod:`.splice`) and
:func:`heading_cos_sin` the cosine and sine of
:func:`~torchsplice.kinematics.heading.heading_from_hips` (the distance grid's heading
restriction, :mod:`.grid`, which needs no ``atan2``). Positions are ``pos (T, J, 3)``;
``left_hip``, ``right_hip`` the hip joints; ``up`` the up axis (0, 1 or 2).
"""

from __future__ import annotations

import math

from numba import njit

from .quat import rotmat_to_q

__all__ = ["heading_q", "heading_cos_sin"]


@njit(cache=True, nogil=True, inline="always")
def _pick(column, lateral, up, on_lateral, on_up, on_third):
    """Component of column ``column`` of the heading matrix: the lateral axis's (``on_lateral``, in
    column ``lateral``), the up axis's (``on_up``) or the third axis's (``on_third``)."""
    return on_lateral if column == lateral else (on_up if column == up else on_third)


@njit(cache=True, nogil=True)
def heading_q(pos, t, left_hip, right_hip, up):
    """Heading frame (WXYZ, heading-frame to world) at frame ``t`` from the hips, as
    :func:`torchsplice.kinematics.heading.heading_frame`: columns lateral (the floor projection
    of left hip minus right hip), up, and their cross product (sign keeping it right-handed)."""
    lateral = 1 if up == 0 else 0
    ux, uy, uz = (1.0 if up == 0 else 0.0), (1.0 if up == 1 else 0.0), (1.0 if up == 2 else 0.0)
    vx, vy, vz = (pos[t, left_hip, 0] - pos[t, right_hip, 0], pos[t, left_hip, 1] - pos[t, right_hip, 1],
                  pos[t, left_hip, 2] - pos[t, right_hip, 2])
    d = vx * ux + vy * uy + vz * uz
    vx, vy, vz = vx - d * ux, vy - d * uy, vz - d * uz
    norm = max(math.sqrt(vx * vx + vy * vy + vz * vz), 1e-12)
    lx, ly, lz = vx / norm, vy / norm, vz / norm
    sign = 1.0 if (up - lateral) % 3 == 1 else -1.0
    ox, oy, oz = sign * (ly * uz - lz * uy), sign * (lz * ux - lx * uz), sign * (lx * uy - ly * ux)
    return rotmat_to_q(_pick(0, lateral, up, lx, ux, ox), _pick(1, lateral, up, lx, ux, ox),
                       _pick(2, lateral, up, lx, ux, ox),
                       _pick(0, lateral, up, ly, uy, oy), _pick(1, lateral, up, ly, uy, oy),
                       _pick(2, lateral, up, ly, uy, oy),
                       _pick(0, lateral, up, lz, uz, oz), _pick(1, lateral, up, lz, uz, oz),
                       _pick(2, lateral, up, lz, uz, oz))


@njit(cache=True, nogil=True, inline="always")
def heading_cos_sin(pos, t, left_hip, right_hip, up):
    """``(cos, sin)`` of the heading at frame ``t``, as
    :func:`torchsplice.kinematics.heading.heading_from_hips`: ``atan2(-d[a1], d[a2])`` for
    ``d = left hip - right hip`` and floor axes ``a1 = (up + 1) % 3``, ``a2 = (up + 2) % 3``;
    ``(1, 0)`` where the hips coincide on the floor."""
    a1, a2 = (up + 1) % 3, (up + 2) % 3
    y = -(pos[t, left_hip, a1] - pos[t, right_hip, a1])
    x = pos[t, left_hip, a2] - pos[t, right_hip, a2]
    r = math.sqrt(x * x + y * y)
    if r > 0.0:
        return x / r, y / r
    return 1.0, 0.0
