"""What a local worker process starts with: the job's modules and the compiled kernels, loaded
once in the fork server (:class:`~torchsplice.job.engines.local.LocalEngine`), so that every worker
forked from it starts splicing at once.

Workers compute with one thread each; their kernels use numba's ``workqueue`` threading layer,
which survives a fork (GNU OpenMP, numba's usual layer, does not).
"""

import numba

numba.config.THREADING_LAYER = "workqueue"

from .task import run_task  # noqa: E402,F401 (imports torch, numba's kernels and the splicer)

try:
    from ..splice.backends import available_backends, get_backend

    for _name in available_backends():
        if get_backend(_name).available():
            get_backend(_name).preload()
except Exception:  # a worker then loads the kernels itself, on first use
    pass
