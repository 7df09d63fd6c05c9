"""Small numpy helpers of the sample's generator: rotation matrices about the axes, easing curves,
integration and smoothing on a time grid, slow pseudo-random noise, heading directions.

Everything is float64 numpy; angles are in degrees unless a name says radians; rotation matrices
are ``(..., 3, 3)`` and act on column vectors; headings are in degrees about +Y (0 = +Z).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["rx", "ry", "rz", "rotate", "tr", "smoothstep", "minjerk", "cumtrapz", "smooth_below", "interp_columns",
           "noise", "forward_of", "left_of"]


def rx(deg) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` about X by ``deg`` degrees (array ``(...)``)."""
    a = np.radians(np.asarray(deg, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    m[..., 0, 0] = 1.0
    m[..., 1, 1], m[..., 1, 2], m[..., 2, 1], m[..., 2, 2] = c, -s, s, c
    return m


def ry(deg) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` about Y (up) by ``deg`` degrees; +Z turns toward +X."""
    a = np.radians(np.asarray(deg, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    m[..., 1, 1] = 1.0
    m[..., 0, 0], m[..., 0, 2], m[..., 2, 0], m[..., 2, 2] = c, s, -s, c
    return m


def rz(deg) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` about Z by ``deg`` degrees; +Y turns toward -X."""
    a = np.radians(np.asarray(deg, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    m[..., 2, 2] = 1.0
    m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1] = c, -s, s, c
    return m


def rotate(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors: ``(..., 3, 3)`` matrices times broadcastable ``(..., 3)`` vectors."""
    return np.einsum("...ij,...j->...i", m, v)


def tr(m: np.ndarray) -> np.ndarray:
    """Transpose (inverse) of ``(..., 3, 3)`` rotation matrices."""
    return np.swapaxes(m, -1, -2)


def smoothstep(x: np.ndarray) -> np.ndarray:
    """Cubic ease ``3x^2 - 2x^3`` of ``x`` clipped to [0, 1] (zero slope at both ends)."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def minjerk(x: np.ndarray) -> np.ndarray:
    """Minimum-jerk ease ``10x^3 - 15x^4 + 6x^5`` of ``x`` clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10.0 + x * (-15.0 + 6.0 * x))


def cumtrapz(y: np.ndarray, dt: float) -> np.ndarray:
    """Cumulative trapezoidal integral of samples ``y`` ``(N, ...)`` spaced ``dt``, starting at 0."""
    out = np.zeros_like(y)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * dt, axis=0)
    return out


def smooth_below(y: np.ndarray, radius: int) -> np.ndarray:
    """A smooth curve ``(T,)`` that never exceeds ``y`` ``(T,)``.

    A running minimum over ``2 * radius + 1`` samples, then a Hann-window average of the same
    width: each output averages values that are each at most the input at that sample, so
    ``out <= y`` everywhere, while short dips become wide smooth ones.
    """
    pad = np.pad(y, radius, mode="edge")
    low = np.lib.stride_tricks.sliding_window_view(pad, 2 * radius + 1).min(-1)
    kernel = np.hanning(2 * radius + 3)[1:-1]
    kernel /= kernel.sum()
    return np.convolve(np.pad(low, radius, mode="edge"), kernel, mode="valid")


def interp_columns(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """``np.interp`` applied to every column of ``fp`` ``(N,)`` or ``(N, C)``; ``x`` any shape."""
    if fp.ndim == 1:
        return np.interp(x, xp, fp)
    return np.stack([np.interp(x, xp, fp[:, k]) for k in range(fp.shape[1])], axis=-1)


def noise(rng: np.random.Generator, t: np.ndarray, amp: float, n: int = 3) -> np.ndarray:
    """Smooth pseudo-random signal ``(T,)`` of RMS about ``amp``: ``n`` slow sinusoids (0.15-0.8 Hz)."""
    freq = rng.uniform(0.15, 0.8, n)
    phase = rng.uniform(0.0, 2.0 * math.pi, n)
    weight = rng.uniform(0.5, 1.0, n)
    weight *= amp * math.sqrt(2.0) / np.sqrt((weight**2).sum())
    return (weight * np.sin(2.0 * math.pi * freq * t[:, None] + phase)).sum(-1)


def forward_of(theta_deg: np.ndarray) -> np.ndarray:
    """Horizontal unit forward vectors ``(..., 3)`` for headings in degrees (0 = +Z)."""
    a = np.radians(theta_deg)
    return np.stack((np.sin(a), np.zeros_like(a), np.cos(a)), axis=-1)


def left_of(theta_deg: np.ndarray) -> np.ndarray:
    """Horizontal unit left vectors ``(..., 3)`` for headings in degrees (0 = +X)."""
    a = np.radians(theta_deg)
    return np.stack((np.cos(a), np.zeros_like(a), -np.sin(a)), axis=-1)
