"""What a local worker process starts with: the job's modules and each backend's preload (the
compiled kernels, with a threading layer that survives a fork), loaded once in the fork server
(:class:`~torchsplice.job.engines.local.LocalEngine`), so that every worker forked from it starts
splicing at once. Workers compute with one thread each.
"""

from .task import run_task  # noqa: F401 (imports torch and the splicer)

try:
    from ..splice.backends import available_backends, get_backend

    for _name in available_backends():
        if get_backend(_name).available():
            get_backend(_name).preload()
except Exception:  # a worker then loads the kernels itself, on first use
    pass
