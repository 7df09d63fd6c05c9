"""Compiled CPU kernels (numba): the fast path of every per-pair stage of splicing.

Why compiled kernels: the slope-limited DP is sequential along each pair's rows, and the
other stages (distance grids, per-frame Horn rotations, curve fits, resampling, FK) are many
small elementwise passes per pair. As torch code they become thousands of tiny ops, each a
parallel region over all threads; on a busy machine every region waits for a descheduled
thread. Here each pair runs start to end in one thread, pairs are spread over threads
(coarse-grained: one pair per task), and inner loops over frames are vectorised by LLVM.

Why numba rather than a C++ extension: it installs from a wheel on every platform torch
supports, needs no compiler on the user's machine, and its compiled code is cached after the
first run (in ``__pycache__/numba/<hash of the kernel sources>`` beside them, or the user's
cache folder when that is read-only), so later runs start at once and a changed kernel is
never served from a stale cache.

The torch implementations (:mod:`torchsplice.align`, :mod:`torchsplice.splice.heck`) stay:
they run on CUDA and are the reference the kernels are tested against (the DP gives the same
bits on the same grid; the whole splice agrees to float32 rounding).

Modules: :mod:`.quat` (quaternion algebra on tuples), :mod:`.fk`, :mod:`.grid` (distance
grids, phase crop), :mod:`.timewarp` (the DP), :mod:`.curve` (B-spline fit, resampling),
:mod:`.horn`, :mod:`.heading` (headings from the hips), :mod:`.splice` (whole pairs, in
parallel), :mod:`.standing` (standing actions), :mod:`.bank` (the Python side), :mod:`.preload` (loading them before a fork). This package imports
nothing above the skeleton roles: the splicer calls it through :mod:`torchsplice.splice.backends`.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

__all__ = ["available", "set_threads", "get_threads", "cache_dir", "warm"]


def _kernel_hash() -> str:
    """A hash of every kernel source here and of what they compile from core (the formulas of
    :mod:`torchsplice.core.quat_formulas`, the method codes of :mod:`torchsplice.core.method_table`):
    numba re-validates a cached function against its own file only, so a change in a function it
    calls, or a constant it freezes, from another file would go unseen."""
    h = hashlib.sha256()
    here = Path(__file__).parent
    for f in [*sorted(here.glob("*.py")), here.parent / "core" / "quat_formulas.py", here.parent / "core" / "method_table.py"]:
        h.update(f.name.encode() + f.read_bytes())
    return h.hexdigest()[:16]


def _cache_root() -> Path:
    """Where compiled kernels are cached: beside the sources when writable, else the user's cache."""
    here = Path(__file__).parent / "__pycache__" / "numba"
    try:
        here.mkdir(parents=True, exist_ok=True)
        if os.access(here, os.W_OK):
            return here
    except OSError:
        pass
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "torchsplice" / "numba"


def _set_cache_dir() -> Path:
    """Point numba's cache at a folder named by the kernels' hash (old folders are removed)."""
    root = Path(os.environ["NUMBA_CACHE_DIR"]) if os.environ.get("NUMBA_CACHE_DIR") else _cache_root()
    path = root / _kernel_hash()
    try:
        import numba

        path.mkdir(parents=True, exist_ok=True)
        numba.config.CACHE_DIR = str(path)
        if not os.environ.get("NUMBA_CACHE_DIR") and root == Path(__file__).parent / "__pycache__" / "numba":
            # beside the sources: other versions' folders are stale (a shared user cache is left alone)
            for old in root.iterdir():
                if old.is_dir() and old.name != path.name:
                    shutil.rmtree(old, ignore_errors=True)
    except Exception:  # no numba, or a read-only disk: numba then compiles without caching
        pass
    return path


def cache_dir() -> Path:
    """The folder holding this version's compiled kernels."""
    return _CACHE


_CACHE = _set_cache_dir()


def warm() -> bool:
    """Whether this version's kernels are already compiled and cached."""
    return any(cache_dir().rglob("*.nbi"))

_AVAILABLE: bool | None = None


def available() -> bool:
    """Whether numba can be imported (the compiled backend is then used on the CPU)."""
    global _AVAILABLE
    if _AVAILABLE is None:
        if os.environ.get("TORCHSPLICE_BACKEND", "") == "torch":
            _AVAILABLE = False
        else:
            try:
                import numba  # noqa: F401

                _AVAILABLE = True
            except Exception:  # pragma: no cover - depends on the install
                _AVAILABLE = False
    return _AVAILABLE


def set_threads(n: int | None) -> int:
    """Use ``n`` threads for the compiled kernels (``None``: every core); returns the number set.

    Results do not depend on it: each pair is computed by one thread, alone.
    """
    import numba

    n = numba.config.NUMBA_NUM_THREADS if n is None else max(1, min(int(n), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(n)
    return n


def get_threads() -> int:
    """Threads the compiled kernels use now."""
    import numba

    return numba.get_num_threads()
