"""Compile (or load) the CPU kernels ahead of use: ``python -m torchsplice.cpu.warmup``.

numba compiles a kernel the first time it is called and caches the machine code (see
:func:`torchsplice.cpu.cache_dir`). The whole-pair splicer takes about a minute to compile on
two cores, so ``scripts/setup_env.sh`` runs this once after installing, rather than leaving
the wait to a user's first splice. A warm cache makes it a no-op.
"""

from __future__ import annotations

import sys
import time

import numpy as np

__all__ = ["warm", "warm_up", "preload"]


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
    from ..sample import sample_motions
    from ..specs import load_spec
    from .bank import ClipBank, splice_bank, standing_bank

    clips = sample_motions()[:4]
    roles = load_spec("sample").bind(clips[0].skeleton)
    bank = ClipBank.from_motions(clips, clips[0].skeleton, roles)
    from ..splice.standing import standing_tables

    tables = standing_tables(roles, clips[0].skeleton, clips[0].fps)
    for method in ("splice", "naive", "cpmc"):
        splice_bank(bank, np.array([0, 1]), np.array([2, 3]), method, ref=np.array([0, 1]))
        for timing in ("loop", "hold", "fit"):
            standing_bank(bank, np.array([0, 1]), np.array([2, 3]), np.array([[True, False], [True, True]]), tables,
                          method, timing)
    from ..align.timewarp import timewarp

    import torch

    timewarp(torch.rand(2, 8, 9), max_run=3)
    return time.perf_counter() - t0


if __name__ == "__main__":
    seconds = warm_up()
    if seconds:
        print(f"setup: compiled in {seconds:.0f} s", file=sys.stderr)


def preload(dtype=np.float32) -> None:
    """Load the kernels a job's task runs from numba's cache, by type signature, running none of
    them: a process forked after this starts splicing at once, and no parallel region (whose
    threads would not survive a fork) has run."""
    from numba import typeof

    from . import bank as bank_mod
    from . import splice as splice_mod
    from . import standing as standing_mod
    from .fk import fk_clips

    f8, i8 = np.zeros((1, 1, 1)), np.zeros(1, np.int64)
    v8, m8 = np.zeros(1), np.zeros((1, 1))
    out = np.zeros((1, 1, 1), dtype)
    joints = (i8, np.zeros(1, np.bool_), i8, i8, i8, i8, i8, i8, 0, 0, 0)
    opts = (0.0,) * 8
    kernels = {
        splice_mod.splice_batch: ((f8, f8, f8, f8), (f8, m8, v8, v8, v8), i8, i8, 0, i8, i8, i8, joints, opts, True, 0.0, i8,
                                  out, out, v8, v8, np.zeros((1, 1, 2), np.int64), i8, i8, i8, v8, i8, v8),
        splice_mod.compact: (out, out, v8, v8, i8, i8, i8, out, out, v8, v8),
        fk_clips: (f8, f8, i8, i8, i8, f8, f8),
        bank_mod._features: (f8, i8, i8, i8, i8, 0, f8, m8, v8, v8, v8),
        standing_mod.standing_batch: (f8, f8, i8, i8, 0, 0, i8, i8, m8, np.zeros((1, 2), np.bool_), np.zeros((1, 2), np.int64),
                                      (np.zeros(1, np.bool_), i8, np.zeros((1, 1), np.bool_), 0, i8, i8, 0, 0, f8, f8), i8,
                                      out, out, v8, i8),
        standing_mod.loop_points_batch: (f8, f8, i8, i8, i8, m8, 0, i8, i8, 0, np.zeros((1, 2), np.int64)),
    }
    for kernel, args in kernels.items():
        kernel.compile(tuple(typeof(a) for a in args))
