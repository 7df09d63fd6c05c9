"""Packed clips' ranges (core/ranges.py) against the loop they replace."""

from __future__ import annotations

import numpy as np
import pytest

from torchsplice.core.ranges import lengths_to_starts, ranges_to_rows


@pytest.mark.parametrize("seed", range(5))
def test_rows_are_each_range_in_turn(seed):
    rng = np.random.default_rng(seed)
    lengths = rng.integers(0, 6, size=rng.integers(0, 9))  # empty ranges and no ranges included
    starts = rng.integers(0, 40, size=len(lengths))
    want = [s + i for s, n in zip(starts, lengths) for i in range(n)]
    rows = ranges_to_rows(starts, lengths)
    assert rows.dtype == np.int64 and rows.tolist() == want


def test_starts_of_packed_clips_start_where_the_one_before_ends():
    starts = lengths_to_starts([3, 0, 2, 5])
    assert starts.dtype == np.int64 and starts.tolist() == [0, 3, 3, 5]
    assert lengths_to_starts([]).tolist() == []
    # packed clips' rows are every row once, in order
    assert ranges_to_rows(lengths_to_starts([3, 0, 2, 5]), [3, 0, 2, 5]).tolist() == list(range(10))
