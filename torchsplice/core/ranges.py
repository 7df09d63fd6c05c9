"""Packed clips: clips stored back to back in one ``(N, ...)`` array of frames, clip ``i``
being rows ``starts[i] : starts[i] + lengths[i]``; ``C`` clips, ``N = lengths.sum()`` frames.
Starts, lengths and rows are int64 numpy arrays.

- :func:`lengths_to_starts`: where each clip starts when the clips are packed in order;
- :func:`ranges_to_rows`: the rows of several ranges, concatenated (a gather's indices).
"""

from __future__ import annotations

import numpy as np

__all__ = ["lengths_to_starts", "ranges_to_rows"]


def lengths_to_starts(lengths) -> np.ndarray:
    """``(C,)`` lengths -> ``(C,)`` first rows of the clips packed in order: ``0, l0, l0 + l1, ...``."""
    lengths = np.asarray(lengths, np.int64).reshape(-1)
    return np.cumsum(lengths) - lengths


def ranges_to_rows(starts, lengths) -> np.ndarray:
    """``(C,)`` starts and ``(C,)`` lengths -> ``(lengths.sum(),)`` rows: ``starts[0] + 0 ..
    starts[0] + lengths[0] - 1``, then the second range's rows, and so on (empty ranges give none)."""
    starts = np.asarray(starts, np.int64).reshape(-1)
    lengths = np.asarray(lengths, np.int64).reshape(-1)
    return np.repeat(starts - lengths_to_starts(lengths), lengths) + np.arange(int(lengths.sum()), dtype=np.int64)
