"""The local engine's fork server, started early: it imports torch and the compiled kernels for
the workers (:mod:`torchsplice.job.worker`) while the driver plans, so that workers start
splicing at once. Light to import and to call (no torch): the command line calls it before it
imports torch, and choosing the backend (:func:`~torchsplice.splice.backends.resolve_backend`)
loads none.
"""

from __future__ import annotations

import multiprocessing as mp
import sys
from multiprocessing import forkserver

from ...splice.backends import get_backend, resolve_backend
from ..defaults import usable_cores

__all__ = ["prestart"]


def prestart(engine: str, workers: int | None, device: str | None, backend: str = "auto") -> None:
    """Start the fork server if the ``local`` engine will use worker processes: more than one
    worker, and a backend (``backend`` as resolved on ``device``) whose prepared clips the
    workers share (:attr:`~torchsplice.splice.backends.Backend.prepares_once`, the compiled
    splicer's; another backend runs in this process). ``workers`` ``None``: one per core.
    Quietly does nothing where it cannot: the engine starts it later, or says why it cannot.
    This is :meth:`~torchsplice.job.config.JobConfig.uses_worker_processes`'s question, asked
    from the command line's flags before the job's config exists."""
    if workers is None:
        workers = usable_cores()
    if engine != "local" or workers <= 1 or sys.platform == "win32":
        return

    try:
        if not get_backend(resolve_backend(backend, device)).prepares_once:
            return
    except Exception:  # an unknown backend, or one that cannot run there: the job says why
        return

    mp.get_context("forkserver").set_forkserver_preload(["torchsplice.job.worker"])
    try:
        forkserver.ensure_running()
    except Exception:
        pass
