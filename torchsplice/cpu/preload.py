"""Load the compiled kernels a job's task runs from numba's cache, before a fork (see :func:`preload`)."""

from __future__ import annotations

import numpy as np

__all__ = ["job_kernels", "preload"]


def preload(dtype=np.float32) -> None:
    """Load the kernels a job's task runs (:func:`job_kernels`) from numba's cache, by type
    signature, running none of them: a process forked after this starts splicing at once, and
    no parallel region (whose threads would not survive a fork) has run."""
    from numba import typeof

    for kernel, args in job_kernels(dtype).items():
        kernel.compile(tuple(typeof(a) for a in args))


def job_kernels(dtype=np.float32) -> dict:
    """The compiled kernels a job's task runs, each with arguments of the types a task passes it
    (``dtype``: the splicer's output rotations'): kernel -> argument tuple. A kernel whose
    arguments change changes here too (tests/cpu/test_preload.py runs a job after
    :func:`preload` and finds no kernel compiled again)."""
    from . import bank as bank_mod
    from . import splice as splice_mod
    from . import standing as standing_mod
    from .body import inside_clips
    from .figures import figures_clips
    from .hands import hands_out_clips
    from .fk import fk_clips

    f8, i8 = np.zeros((1, 1, 1)), np.zeros(1, np.int64)
    v8, m8 = np.zeros(1), np.zeros((1, 1))
    out = np.zeros((1, 1, 1), dtype)
    joints = (i8, np.zeros(1, np.bool_), i8, i8, i8, i8, i8, i8, 0, 0, 0)
    opts = (0.0,) * 8
    kernels = {
        splice_mod.splice_batch: ((f8, f8, f8, f8), (f8, m8, v8, v8, v8), i8, i8, 0, i8, i8, i8, joints, opts, True, 0.0, i8,
                                  out, out, v8, v8, m8, np.zeros((1, 1, 2), np.int64), i8, i8, i8, v8, i8, v8),
        splice_mod.compact: (out, out, v8, v8, m8, i8, i8, i8, out, out, v8, v8, m8),
        fk_clips: (f8, f8, i8, i8, i8, f8, f8),
        bank_mod._features: (f8, i8, i8, i8, i8, 0, f8, m8, v8, v8, v8),
        standing_mod.standing_batch: (f8, f8, i8, i8, 0, 0, i8, i8, m8, np.zeros((1, 2), np.bool_), np.zeros((1, 2), np.int64),
                                      (np.zeros(1, np.bool_), i8, np.zeros((1, 1), np.bool_), 0, i8, i8, 0, 0, f8, f8), i8,
                                      out, out, v8, i8, i8),
        standing_mod.loop_points_batch: (f8, f8, i8, i8, i8, m8, 0, i8, i8, 0, np.zeros((1, 2), np.int64)),
        inside_clips: (out, out, i8, i8, i8, i8, v8, v8, i8, i8, 0.0, 0.0, i8, i8, v8, v8, v8),
        figures_clips: (out, out, i8, i8, i8, i8, 0, 0, 0.0, 0.0, 0.0, 0.0, 0, i8, i8, v8, v8, v8, v8, v8),
        hands_out_clips: (out, out, i8, i8, i8, i8, i8, v8, v8, i8, i8, np.zeros(1, np.bool_), 0, i8, i8, i8, i8, i8,
                          i8, i8,
                          v8, i8, 0.0, 0, 0.0, 0.0, v8, 0.0, out, i8, np.zeros(0, np.uint8)),
    }
    return kernels
