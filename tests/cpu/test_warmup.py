"""``python -m torchsplice.warmup``: its arguments, and a warm cache left as it is."""

from __future__ import annotations

import os

import numpy as np
import pytest

from torchsplice.cpu import cache_dir, warm
from torchsplice.splice.backends.compiled import WARM_PARTS, kernels_cached, mark_cached
from torchsplice.warmup import main


def test_an_unknown_part_gets_the_usage_line(capsys):
    assert main(["--part", "everything"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "[--float64] [--part splicer|others]" in err and "everything" in err
    assert WARM_PARTS == ("splicer", "others")
    assert main(["--float64", "--float64"]) == 2 and "usage:" in capsys.readouterr().err


def _stamps():
    return sorted(p.stat().st_mtime_ns for p in cache_dir().rglob("*.nbi"))


def test_a_warm_cache_is_left_as_it_is(capsys):
    assert warm() and kernels_cached()  # the suite's kernels are compiled by now (scripts/test.sh)
    before = _stamps()
    assert main([]) == 0
    assert capsys.readouterr().err == ""
    assert _stamps() == before


def test_the_float64_warm_up_is_recorded_and_then_left_as_it_is(capsys):
    # scripts/test.sh runs it before the tests (and CI with it): its record is there, and a second run does nothing
    if not kernels_cached(np.float64):
        reason = "python -m torchsplice.warmup --float64 has not run on this cache (scripts/test.sh runs it)"
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            pytest.fail(reason, pytrace=False)
        pytest.skip(reason)
    before = _stamps()
    assert main(["--float64"]) == 0
    assert capsys.readouterr().err == ""
    assert _stamps() == before


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_kernels_cached_only_once_a_whole_warm_up_recorded_them(tmp_path, monkeypatch, dtype):
    # a cache holding some kernels (a first splice, a warm-up cut short) is not a warm one: the set-up's
    # next warm-up compiles the rest rather than taking it for done
    import torchsplice.cpu

    monkeypatch.setattr(torchsplice.cpu, "cache_dir", lambda: tmp_path)
    (tmp_path / "splice.splice_batch-294.py311.nbi").write_bytes(b"")
    assert not kernels_cached(dtype)
    mark_cached(dtype)
    assert kernels_cached(dtype) and not kernels_cached(np.float64 if dtype == np.float32 else np.float32)
