"""Compile (or load) the CPU kernels ahead of use: ``python -m torchsplice.cpu.warmup``.

numba compiles a kernel the first time it is called and caches the machine code (see
:func:`torchsplice.cpu.cache_dir`). The whole-pair splicer takes about a minute to compile on
two cores, so ``scripts/setup_env.sh`` runs this once after installing, rather than leaving
the wait to a user's first splice. A warm cache makes it a no-op.
"""

from __future__ import annotations

import sys
import time

__all__ = ["warm", "warm_up"]


def warm() -> bool:
    """Whether this version's kernels are already compiled and cached."""
    from . import cache_dir

    return any(cache_dir().rglob("*.nbi"))


def warm_up(quiet: bool = False) -> float:
    """Run every kernel of the default paths once on the built-in sample; returns the seconds taken."""
    if warm():
        return 0.0
    t0 = time.perf_counter()
    if not quiet:
        print("setup: compiling the CPU splicer for this machine (once; about a minute)", file=sys.stderr, flush=True)
    import numpy as np

    from ..io.sample import sample_motions
    from ..io.spec import load_spec
    from .bank import ClipBank, splice_bank

    clips = sample_motions()[:4]
    roles = load_spec("sample").bind(clips[0].skeleton)
    bank = ClipBank.from_motions(clips, clips[0].skeleton, roles)
    for method in ("splice", "naive", "cpmc"):
        splice_bank(bank, np.array([0, 1]), np.array([2, 3]), method, ref=np.array([0, 1]))
    from ..align.timewarp import timewarp

    import torch

    timewarp(torch.rand(2, 8, 9), max_run=3)
    return time.perf_counter() - t0


if __name__ == "__main__":
    seconds = warm_up()
    if seconds:
        print(f"setup: compiled in {seconds:.0f} s", file=sys.stderr)
