"""What a local worker process starts with: the job's modules and each backend's preload (the
compiled kernels, with a threading layer that survives a fork), loaded once in the fork server
(:class:`~torchsplice.job.engines.local.LocalEngine`), so that every worker forked from it starts
splicing at once. Workers compute with one thread each. A backend whose preload fails costs only
time (each worker then loads its kernels on first use), and says so in one line.
"""

from __future__ import annotations

import sys

from ..splice.backends import available_backends, get_backend
from .task import run_task  # noqa: F401 (imports torch and the splicer)

__all__ = ["preload_backends"]


def preload_backends(stream=None) -> list[str]:
    """Preload every available backend; one line on ``stream`` (default stderr) per backend whose
    preload failed, naming it and the error; returns those lines."""
    failed = []
    for name in available_backends():
        try:
            backend = get_backend(name)
            if backend.available():
                backend.preload()
        except Exception as exc:  # a worker then loads the kernels itself, on first use
            failed.append(f"torchsplice: backend {name!r} was not preloaded before the workers fork "
                          f"({type(exc).__name__}: {exc}); each worker loads its kernels on first use")
    for line in failed:
        print(line, file=sys.stderr if stream is None else stream, flush=True)
    return failed


preload_backends()
