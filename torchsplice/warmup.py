"""Compile (or load) the CPU kernels ahead of use: ``python -m torchsplice.warmup``.

numba compiles a kernel the first time it is called and caches the machine code (see
:func:`torchsplice.cpu.cache_dir`). The kernels take one to two minutes to compile on two cores,
so ``scripts/setup_env.sh`` runs this once after installing, rather than leaving the wait to a
user's first splice. A warm cache makes it a no-op. With two cores or more, the two halves of
the work (:data:`~torchsplice.splice.backends.compiled.WARM_PARTS`: the whole-pair splicer, and
the rest) compile at once, the second in a child process (``--part others``).
"""

from __future__ import annotations

import subprocess
import sys
import time

from .job.defaults import usable_cores
from .splice.backends.compiled import WARM_PARTS, kernels_cached, warm_up

__all__ = ["warm_up", "main"]


def main(argv: list[str] | None = None) -> int:
    """``python -m torchsplice.warmup [--part splicer|others]``: compile what the cache lacks."""
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--part"] and len(argv) == 2 and argv[1] in WARM_PARTS:
        warm_up(quiet=True, parts=(argv[1],), force=True)
        return 0
    if argv:
        print(f"usage: python -m torchsplice.warmup [--part {'|'.join(WARM_PARTS)}] (got {' '.join(argv)})",
              file=sys.stderr)
        return 2
    if kernels_cached():
        return 0
    if usable_cores() < 2:
        seconds = warm_up()
    else:
        print("setup: compiling the CPU splicer for this machine (once; one to two minutes)", file=sys.stderr,
              flush=True)
        t0 = time.perf_counter()
        child = subprocess.Popen([sys.executable, "-m", "torchsplice.warmup", "--part", WARM_PARTS[1]],
                                 stderr=subprocess.PIPE, text=True)
        try:
            warm_up(quiet=True, parts=WARM_PARTS[:1], force=True)
        finally:
            _, err = child.communicate()
        if child.returncode != 0:
            sys.stderr.write(err)
            return child.returncode or 1
        seconds = time.perf_counter() - t0
    print(f"setup: compiled in {seconds:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
