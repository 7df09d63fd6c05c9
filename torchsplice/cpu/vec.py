"""3-vectors as tuples in compiled kernels, and the closest points of two segments.

The helpers the body test (:mod:`.body`) and the correction (:mod:`.hands`) share: ``dot``,
``sub``, ``add``, ``scale``, ``cross``, ``length``, ``normalized`` of ``(x, y, z)`` tuples,
``row`` (a row of an ``(n, 3)`` array as one), and :func:`segment_closest` /
:func:`segment_distance`, the closed form of :func:`torchsplice.ops.body.segment_closest`
with the same branches.
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["dot", "sub", "add", "scale", "cross", "length", "normalized", "row", "segment_closest",
           "segment_distance"]


@njit(cache=True, inline="always")
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, inline="always")
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(cache=True, inline="always")
def scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


@njit(cache=True, inline="always")
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, inline="always")
def length(a):
    return math.sqrt(dot(a, a))


@njit(cache=True, inline="always")
def normalized(v, fallback):
    """``v`` made unit length; ``fallback`` made so where ``v`` has none."""
    n = length(v)
    if n > 1e-12:
        return scale(v, 1.0 / n)
    return scale(fallback, 1.0 / max(length(fallback), 1e-300))


@njit(cache=True, inline="always")
def row(a, i):
    """Row ``i`` of an ``(n, 3)`` array as a tuple."""
    return (a[i, 0], a[i, 1], a[i, 2])


@njit(cache=True, nogil=True)
def segment_closest(p0, p1, q0, q1):
    """``(s, t)``: where segments ``p0 p1`` and ``q0 q1`` come closest, as shares along each
    (:func:`torchsplice.ops.body.segment_closest`, the same branches)."""
    d1, d2, r = sub(p1, p0), sub(q1, q0), sub(p0, q0)
    a, e, b = dot(d1, d1), dot(d2, d2), dot(d1, d2)
    c, f = dot(d1, r), dot(d2, r)
    eps = 1e-12 * max(a + e, 1e-300)
    pa, pe = a > eps, e > eps
    denom = a * e - b * b
    s = 0.0
    if pa and pe and denom > eps * (a + e):
        s = (b * f - c * e) / denom
    if pa and not pe:
        s = -c / a
    s = min(max(s, 0.0), 1.0)
    t = (b * s + f) / e if pe else 0.0
    if pa and t < 0.0:
        s = min(max(-c / a, 0.0), 1.0)
    if pa and t > 1.0:
        s = min(max((b - c) / a, 0.0), 1.0)
    return s, min(max(t, 0.0), 1.0)


@njit(cache=True, nogil=True)
def segment_distance(p0, p1, q0, q1):
    """The shortest distance between segments ``p0 p1`` and ``q0 q1``."""
    s, t = segment_closest(p0, p1, q0, q1)
    return length(sub(add(p0, scale(sub(p1, p0), s)), add(q0, scale(sub(q1, q0), t))))
