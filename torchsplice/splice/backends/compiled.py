"""The compiled CPU backend (numba kernels of :mod:`torchsplice.cpu`)."""

from __future__ import annotations

import sys
import time

import numpy as np

__all__ = ["warm_up"]


def warm_up(quiet: bool = False) -> float:
    """Run every kernel of the default paths once on the built-in sample; returns the seconds taken."""
    from ...cpu import warm

    if warm():
        return 0.0
    t0 = time.perf_counter()
    if not quiet:
        print("setup: compiling the CPU splicer for this machine (once; one to three minutes)", file=sys.stderr, flush=True)
    from ...cpu.bank import ClipBank, splice_bank, standing_bank
    from ...sample import sample_motions
    from ...specs import load_spec
    from ..standing import standing_tables

    clips = sample_motions()[:4]
    roles = load_spec("sample").bind(clips[0].skeleton)
    bank = ClipBank.from_motions(clips, clips[0].skeleton, roles)
    tables = standing_tables(roles, clips[0].skeleton, clips[0].fps)
    for method in ("splice", "naive", "cpmc"):
        splice_bank(bank, np.array([0, 1]), np.array([2, 3]), method, ref=np.array([0, 1]))
        for timing in ("loop", "hold", "fit"):
            standing_bank(bank, np.array([0, 1]), np.array([2, 3]), np.array([[True, False], [True, True]]), tables,
                          method, timing)
    import torch

    from ...align.timewarp import timewarp

    timewarp(torch.rand(2, 8, 9), max_run=3)
    return time.perf_counter() - t0
