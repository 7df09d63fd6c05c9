"""The n x m job's option defaults and allowed values, declared once: :class:`~.config.JobConfig`,
:func:`~.merge.merge_job` and :func:`~.materialize.materialize` take them from here, and so does
the command line (``splice-all``, ``merge``, ``materialize``). The splice's own options are the
splice's defaults (:mod:`torchsplice.splice.defaults`), retargeting's are retargeting's. Standard
library only (see :mod:`torchsplice.splice.defaults` for the ``defaults`` modules' convention)."""

from __future__ import annotations

import os

from ..splice.defaults import DEFAULT_METHOD

__all__ = ["DEFAULT_LOCOMOTIONS", "DEFAULT_ACTIONS", "LAYOUTS", "STORES", "DEFAULT_ACTIONS_DB", "DEFAULT_METHODS",
           "DEFAULT_MAX_LENGTH_RATIO", "DEFAULT_RETARGET", "DEFAULT_TARGET", "DEFAULT_COPY_SOURCES", "DEFAULT_INDEX",
           "DEFAULT_KEEP_HANDS_OUT", "DEFAULT_COMPRESSION", "DEFAULT_LAYOUT", "DEFAULT_STORE", "DEFAULT_MEMORY_BUDGET_MB",
           "DEFAULT_BATCH_PAIRS", "DEFAULT_ENGINE", "DEFAULT_WORKERS", "DEFAULT_RAY_ADDRESS",
           "usable_cores"]

DEFAULT_LOCOMOTIONS = ("role:locomotion,role:both",)
"""The selectors of the clips giving the lower body."""
DEFAULT_ACTIONS = ("role:action,role:both",)
"""The selectors of the clips giving the upper body."""
LAYOUTS = ("copy", "virtual")
"""How the output holds its frames (``layout``): one self-contained file, or virtual datasets over the shards."""
STORES = ("motion", "alignment")
"""What the output stores (``store``): each spliced clip's frames, or what splicing computed
(:mod:`torchsplice.store.assembly`); the same as :data:`torchsplice.store.assembly.STORES`."""

DEFAULT_ACTIONS_DB: str | None = None
"""Another database holding the actions (``None``: the locomotions' database)."""
DEFAULT_METHODS = (DEFAULT_METHOD,)
DEFAULT_MAX_LENGTH_RATIO: float | None = None
"""Skip pairs whose longer clip lasts more than this many times the shorter (``None``: no limit)."""
DEFAULT_RETARGET = True
"""Pairs on different skeletons are formed by retargeting the action."""
DEFAULT_TARGET: str | None = None
"""The skeleton every clip is brought onto first (``None``: each pair on its locomotion's)."""
DEFAULT_COPY_SOURCES = False
DEFAULT_INDEX = True
"""Write ``NAME.h5.index.csv`` beside the output (the job, ``merge_job``, ``materialize``;
``.csv.gz`` for a million clips or more: :func:`torchsplice.formats.index.database_index_path`)."""
DEFAULT_KEEP_HANDS_OUT = True
DEFAULT_COMPRESSION: str | None = "auto"
"""The output's compression (one of :data:`torchsplice.store.defaults.COMPRESSIONS`)."""
DEFAULT_LAYOUT = "copy"
DEFAULT_STORE = "motion"
DEFAULT_MEMORY_BUDGET_MB = 1024
"""Memory for one task, which sets the pairs per task."""
DEFAULT_BATCH_PAIRS: int | None = None
"""Pairs per task (``None``: from the memory budget)."""
DEFAULT_ENGINE = "local"
DEFAULT_WORKERS: int | None = None
"""Local worker processes (``None``: one per core)."""
DEFAULT_RAY_ADDRESS: str | None = None
"""The Ray cluster (``None``: start a local Ray instance)."""


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one): the
    local engine's worker count when ``workers`` is ``None``."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
