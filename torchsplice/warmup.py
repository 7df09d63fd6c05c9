"""Compile (or load) the CPU kernels ahead of use: ``python -m torchsplice.warmup``.

numba compiles a kernel the first time it is called and caches the machine code (see
:func:`torchsplice.cpu.cache_dir`). The kernels take one to two minutes to compile on two cores,
so ``scripts/setup_env.sh`` runs this once after installing, rather than leaving the wait to a
user's first splice. A warm cache makes it a no-op: a finished warm-up leaves its record in the
cache (:func:`~torchsplice.splice.backends.compiled.mark_cached`), so that one cut short compiles
the rest next time. With two cores or more, the two halves of the work (:data:`~torchsplice.splice.backends.compiled.WARM_PARTS`: the whole-pair splicer, and
the rest) compile at once, the second in a child process (``--part others``).

``--float64`` compiles the same kernels for float64 frames (numba compiles a kernel once per
argument type): for work in float64 (``SpliceOptions(dtype=torch.float64)``, float64 clips),
which would otherwise compile them on first use, in every process. The test suite's
known-answer tests run in float64, and ``scripts/test.sh`` runs it once before them.
"""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np

from .job.defaults import usable_cores
from .splice.backends.compiled import WARM_PARTS, kernels_cached, mark_cached, warm_up

__all__ = ["warm_up", "main"]


USAGE = f"usage: python -m torchsplice.warmup [--float64] [--part {'|'.join(WARM_PARTS)}]"


def main(argv: list[str] | None = None) -> int:
    """``python -m torchsplice.warmup [--float64] [--part splicer|others]``: compile what the cache lacks."""
    argv = sys.argv[1:] if argv is None else argv
    f64 = "--float64" in argv
    rest = [a for a in argv if a != "--float64"]
    dtype = np.float64 if f64 else np.float32
    if rest[:1] == ["--part"] and len(rest) == 2 and rest[1] in WARM_PARTS:
        warm_up(quiet=True, parts=(rest[1],), force=True, dtype=dtype)
        return 0
    if rest or argv.count("--float64") > 1:
        print(f"{USAGE} (got {' '.join(argv)})", file=sys.stderr)
        return 2
    if kernels_cached(dtype):
        return 0
    what = "the CPU splicer's float64 kernels" if f64 else "the CPU splicer"
    minutes = "two" if usable_cores() >= 2 else "three"
    print(f"setup: compiling {what} for this machine (once; one to {minutes} minutes)", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    if usable_cores() < 2:
        warm_up(quiet=True, force=True, dtype=dtype)  # every part: it records them itself
    else:
        child = subprocess.Popen([sys.executable, "-m", "torchsplice.warmup", *(["--float64"] if f64 else []),
                                  "--part", WARM_PARTS[1]], stderr=subprocess.PIPE, text=True)
        try:
            warm_up(quiet=True, parts=WARM_PARTS[:1], force=True, dtype=dtype)
        finally:
            _, err = child.communicate()
        if child.returncode != 0:
            sys.stderr.write(err)
            return child.returncode or 1
        mark_cached(dtype)
    seconds = time.perf_counter() - t0
    print(f"setup: compiled in {seconds:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
