"""``python -m torchsplice.warmup``: its arguments, and a warm cache left as it is."""

from __future__ import annotations

from torchsplice.cpu import cache_dir, warm
from torchsplice.splice.backends.compiled import WARM_PARTS
from torchsplice.warmup import main


def test_an_unknown_part_gets_the_usage_line(capsys):
    assert main(["--part", "everything"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--part splicer|others" in err and "everything" in err
    assert WARM_PARTS == ("splicer", "others")


def test_a_warm_cache_is_left_as_it_is(capsys):
    assert warm()  # the suite's kernels are compiled by now
    before = sorted(p.stat().st_mtime_ns for p in cache_dir().rglob("*.nbi"))
    assert main([]) == 0
    assert capsys.readouterr().err == ""
    assert sorted(p.stat().st_mtime_ns for p in cache_dir().rglob("*.nbi")) == before
