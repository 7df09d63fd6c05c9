"""Headings for compiled kernels (numba): the character's facing from its hips, one frame at a time.

The twins of :mod:`torchsplice.kinematics.heading`, same formulas (see its docstring for why the
frame and the angle are two formulas): :func:`heading_q` is
:func:`~torchsplice.kinematics.heading.heading_frame` (posture transfer, :mod:`.splice`) and
:func:`heading_cos_sin` the cosine and sine of
:func:`~torchsplice.kinematics.heading.heading_from_hips` (the distance grid's heading
restriction, :mod:`.grid`, which needs no ``atan2``). Positions are ``pos (T, J, 3)``; ``lh``,
``rh`` the left and right hip joints; ``up`` the up axis (0, 1 or 2).
"""

from __future__ import annotations

import math

from numba import njit

from .quat import rotmat_to_q

__all__ = ["heading_q", "heading_cos_sin"]


@njit(cache=True, nogil=True, inline="always")
def _pick(c, lat, up, l, u, o):
    """Component of column ``c`` of the heading matrix: the lateral, up or third axis."""
    return l if c == lat else (u if c == up else o)


@njit(cache=True, nogil=True)
def heading_q(pos, t, lh, rh, up):
    """Heading frame (WXYZ, heading-frame to world) at frame ``t`` from the hips, as
    :func:`torchsplice.kinematics.heading.heading_frame`: columns lateral (the floor projection
    of left hip minus right hip), up, and their cross product (sign keeping it right-handed)."""
    lat = 1 if up == 0 else 0
    ux, uy, uz = (1.0 if up == 0 else 0.0), (1.0 if up == 1 else 0.0), (1.0 if up == 2 else 0.0)
    vx, vy, vz = pos[t, lh, 0] - pos[t, rh, 0], pos[t, lh, 1] - pos[t, rh, 1], pos[t, lh, 2] - pos[t, rh, 2]
    d = vx * ux + vy * uy + vz * uz
    vx, vy, vz = vx - d * ux, vy - d * uy, vz - d * uz
    nn = max(math.sqrt(vx * vx + vy * vy + vz * vz), 1e-12)
    lx, ly, lz = vx / nn, vy / nn, vz / nn
    sgn = 1.0 if (up - lat) % 3 == 1 else -1.0
    ox, oy, oz = sgn * (ly * uz - lz * uy), sgn * (lz * ux - lx * uz), sgn * (lx * uy - ly * ux)
    return rotmat_to_q(_pick(0, lat, up, lx, ux, ox), _pick(1, lat, up, lx, ux, ox), _pick(2, lat, up, lx, ux, ox),
                       _pick(0, lat, up, ly, uy, oy), _pick(1, lat, up, ly, uy, oy), _pick(2, lat, up, ly, uy, oy),
                       _pick(0, lat, up, lz, uz, oz), _pick(1, lat, up, lz, uz, oz), _pick(2, lat, up, lz, uz, oz))


@njit(cache=True, nogil=True, inline="always")
def heading_cos_sin(pos, t, lh, rh, up):
    """``(cos, sin)`` of the heading at frame ``t``, as
    :func:`torchsplice.kinematics.heading.heading_from_hips`: ``atan2(-d[a1], d[a2])`` for
    ``d = left hip - right hip`` and floor axes ``a1 = (up + 1) % 3``, ``a2 = (up + 2) % 3``;
    ``(1, 0)`` where the hips coincide on the floor."""
    a1, a2 = (up + 1) % 3, (up + 2) % 3
    y = -(pos[t, lh, a1] - pos[t, rh, a1])
    x = pos[t, lh, a2] - pos[t, rh, a2]
    r = math.sqrt(x * x + y * y)
    if r > 0.0:
        return x / r, y / r
    return 1.0, 0.0
