"""Compile (or load) the CPU kernels ahead of use: ``python -m torchsplice.warmup``.

numba compiles a kernel the first time it is called and caches the machine code (see
:func:`torchsplice.cpu.cache_dir`). The whole-pair splicer takes one to three minutes to compile
on two cores, so ``scripts/setup_env.sh`` runs this once after installing, rather than leaving
the wait to a user's first splice. A warm cache makes it a no-op.
"""

from __future__ import annotations

import sys

from .splice.backends.compiled import warm_up

__all__ = ["warm_up"]

if __name__ == "__main__":
    seconds = warm_up()
    if seconds:
        print(f"setup: compiled in {seconds:.0f} s", file=sys.stderr)
