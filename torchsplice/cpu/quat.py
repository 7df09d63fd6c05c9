"""Scalar quaternion algebra for compiled kernels (numba), on 4-tuples ``(w, x, y, z)``.

Same conventions and formulas as :mod:`torchsplice.core.rotations`: unit quaternions in WXYZ
order (scalar first), ``qmul(p, q)`` applies ``q`` first, ``qrot(q, v)`` rotates a 3-tuple;
those two are :mod:`torchsplice.core.quat_formulas` itself, compiled.
Tuples stay in registers, so these helpers cost nothing beyond their arithmetic.
"""

from __future__ import annotations

import math

from numba import njit

from ..core import quat_formulas as formulas

__all__ = ["qmul", "qconj", "qrot", "qnormalize", "qcanonical", "qslerp", "qarc", "qslerp_arc", "rotmat_to_q", "qload", "qstore"]


@njit(cache=True, inline="always")
def qload(a, t, j):
    """``a[t, j]`` of a ``(T, J, 4)`` array as a tuple."""
    return (a[t, j, 0], a[t, j, 1], a[t, j, 2], a[t, j, 3])


@njit(cache=True, inline="always")
def qstore(a, t, j, q):
    """``a[t, j] = q``."""
    a[t, j, 0] = q[0]
    a[t, j, 1] = q[1]
    a[t, j, 2] = q[2]
    a[t, j, 3] = q[3]


qmul = njit(cache=True, inline="always")(formulas.qmul)
"""Hamilton product ``p * q`` (:func:`torchsplice.core.quat_formulas.qmul`, compiled)."""


@njit(cache=True, inline="always")
def qconj(q):
    """Conjugate (inverse of a unit quaternion)."""
    return (q[0], -q[1], -q[2], -q[3])


qrot = njit(cache=True, inline="always")(formulas.qrot)
"""The 3-tuple ``v`` rotated by unit ``q`` (:func:`torchsplice.core.quat_formulas.qrot`, compiled)."""


@njit(cache=True, inline="always")
def qnormalize(q):
    """``q / max(|q|, 1e-12)``."""
    n = max(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), 1e-12)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@njit(cache=True, inline="always")
def qcanonical(q):
    """The representative with ``w >= 0``."""
    if q[0] < 0:
        return (-q[0], -q[1], -q[2], -q[3])
    return q


@njit(cache=True, inline="always")
def qarc(p, q):
    """``(theta, s)`` of the slerp from ``p`` to ``q`` along the shorter arc: the angle between
    them in 4D (``acos |p . q|``) and its sine, the sine's sign negative (``-s``, ``-0.0`` kept)
    where ``q`` is flipped to ``-q``. What :func:`qslerp` computes once per pair; a reader that
    samples the same pair many times takes it from a table (:func:`torchsplice.cpu.assemble.arc_table`)."""
    d = p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3]
    flip = d < 0
    if flip:
        d = -d
    d = min(d, 1.0)
    theta = math.acos(d)
    s = math.sin(theta)
    return theta, (-s if flip else s)


@njit(cache=True, inline="always")
def qslerp_arc(p, q, t, theta, s):
    """:func:`qslerp` of ``p``, ``q`` at ``t`` with their :func:`qarc` given: the same bits."""
    if t == 0.0:
        return p
    if math.copysign(1.0, s) < 0:
        q = (-q[0], -q[1], -q[2], -q[3])
        s = -s
    if s < 1e-6:
        wp, wq = 1.0 - t, t
    else:
        wp, wq = math.sin((1.0 - t) * theta) / s, math.sin(t * theta) / s
    return qnormalize((wp * p[0] + wq * q[0], wp * p[1] + wq * q[1], wp * p[2] + wq * q[2], wp * p[3] + wq * q[3]))


@njit(cache=True, inline="always")
def qslerp(p, q, t):
    """Slerp along the shorter arc as :func:`~torchsplice.core.rotations.quat_slerp` (``t = 0``
    gives ``p`` exactly; nearly equal rotations use normalised linear interpolation)."""
    if t == 0.0:
        return p
    theta, s = qarc(p, q)
    return qslerp_arc(p, q, t, theta, s)


@njit(cache=True)
def rotmat_to_q(m00, m01, m02, m10, m11, m12, m20, m21, m22):
    """Rotation matrix (column vectors) to a unit quaternion with ``w >= 0`` (Shepperd's method,
    as :func:`~torchsplice.core.rotations.rotmat_to_quat`)."""
    s0 = 1.0 + m00 + m11 + m22
    s1 = 1.0 + m00 - m11 - m22
    s2 = 1.0 - m00 + m11 - m22
    s3 = 1.0 - m00 - m11 + m22
    if s0 >= s1 and s0 >= s2 and s0 >= s3:
        q = (s0, m21 - m12, m02 - m20, m10 - m01)
    elif s1 >= s2 and s1 >= s3:
        q = (m21 - m12, s1, m10 + m01, m02 + m20)
    elif s2 >= s3:
        q = (m02 - m20, m10 + m01, s2, m12 + m21)
    else:
        q = (m10 - m01, m20 + m02, m21 + m12, s3)
    return qcanonical(qnormalize(q))
