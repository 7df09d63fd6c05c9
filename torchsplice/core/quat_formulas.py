"""The quaternion formulas every path computes with, written once on components.

``qmul(p, q)`` and ``qrot(q, v)`` take tuples ``(w, x, y, z)`` and ``(x, y, z)`` of anything
with ``+``, ``-`` and ``*``: floats in the compiled kernels (:mod:`torchsplice.cpu.quat` compiles
these very functions with numba), tensors in torch (:func:`torchsplice.core.rotations.quat_mul`
and the forward kinematics of :mod:`torchsplice.core.fk`). Unit quaternions in WXYZ order
(scalar first); ``qmul(p, q)`` applies ``q`` first, then ``p``.
"""

from __future__ import annotations

__all__ = ["qmul", "qrot"]


def qmul(p, q):
    """Hamilton product ``p * q`` of 4-tuples."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    )


def qrot(q, v):
    """The 3-tuple ``v`` rotated by the unit 4-tuple ``q``: ``t = 2 xyz x v; v + w t + xyz x t``."""
    w, x, y, z = q
    vx, vy, vz = v
    tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty), vy + w * ty + (z * tx - x * tz), vz + w * tz + (x * ty - y * tx))
