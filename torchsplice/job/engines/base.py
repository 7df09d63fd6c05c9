"""What an engine is given and what it is: :class:`EngineContext`, the :class:`Engine` base class
(see :mod:`torchsplice.job.engines` for the contract), :func:`make_engine` (the engine a job's
config names, from :mod:`.registry`), and what every engine's workers share."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import torch

from ..config import JobConfig
from ..plan import Plan, Task
from ..sink import Sink
from ..sources import Sources
from ...core.errors import TorchspliceError
from .registry import engine_factory

__all__ = ["MAX_ATTEMPTS", "EngineContext", "Engine", "make_engine", "one_thread_worker", "shard_compression"]

MAX_ATTEMPTS = 3
"""Tries of a task whose worker dies (local workers: pool breaks in a row; Ray: retries)."""


@dataclass
class EngineContext:
    """What an engine runs: the job's ``config`` and ``plan`` (saved at ``plan_path``), its
    ``sources`` (the clips, in the driver), the ``sink`` that writes shards into ``shard_dir``,
    and whether each task's shard is kept (``keep_shards``: the slices of a ``--shard`` run, and a
    virtual output's frames)."""

    config: JobConfig
    plan: Plan
    plan_path: Path
    sources: Sources
    sink: Sink
    shard_dir: Path
    keep_shards: bool = True

    def shard_compression(self):
        return shard_compression(self.config)

    def write_shard(self, task: Task, part) -> None:
        """Write ``task``'s shard from ``part`` (when shards are kept)."""
        if self.keep_shards:
            self.sink.write_shard(part, self.shard_dir / self.sink.shard_name(task.id), self.shard_compression())


class Engine:
    """Runs a job's tasks (see the module docstring for the contract)."""

    name = ""

    def __init__(self, ctx: EngineContext):
        self.ctx = ctx
        self.config, self.plan = ctx.config, ctx.plan

    def describe(self) -> str:
        return self.name

    def alive(self) -> int:
        return 1

    def run(self, tasks: list[Task], done: Callable) -> None:
        raise NotImplementedError

    def close(self) -> None:
        pass


def make_engine(ctx: EngineContext) -> Engine:
    """The engine ``ctx.config.engine`` names, made for ``ctx``."""
    name = ctx.config.engine
    engine = engine_factory(name)(ctx)
    if not isinstance(engine, Engine):
        raise TorchspliceError(f"engine {name!r} made a {type(engine).__name__}, not a torchsplice Engine")
    return engine


def one_thread_worker(config) -> None:
    """What every engine's worker process starts with: one compute thread, for torch and for the
    job's splicing backend (workers run in parallel with each other, not within themselves)."""
    torch.set_num_threads(1)
    config.splice_backend().set_threads(1)


def shard_compression(config):
    """Shards of a virtual output are the output's frames: compressed like it; otherwise raw."""
    return config.compression if config.layout == "virtual" else None
