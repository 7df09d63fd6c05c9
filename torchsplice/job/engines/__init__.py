"""The seam for engines: what runs a job's tasks. One module per engine, registered by name.

An engine runs the job's tasks through :func:`~torchsplice.job.task.run_task` and hands each
result to the driver, so the output is the same bits whatever the engine. The built-ins:

- ``local`` (:mod:`.local`): worker processes on this machine (``--workers N``, default one per
  core), or this process alone (one worker, or a CUDA device: :mod:`.inline`).
- ``ray`` (:mod:`.ray_cluster`): Ray tasks on a cluster, or on a Ray instance started here.

A new engine is one module with a subclass of :class:`Engine` and one call,
``register_engine("name", MyEngine)`` (at import: load the module with ``--plugin MODULE`` or
``TORCHSPLICE_PLUGINS``, as plug-in methods are); ``splice-all --engine name`` then runs on it.

The contract (what the driver relies on):

- ``Engine(ctx)`` with an :class:`EngineContext`; nothing starts before :meth:`Engine.run`.
- :meth:`Engine.run` ``(tasks, done)`` runs every task of ``tasks`` and calls ``done(task,
  part)`` for each finished one, one call at a time (from any one thread), in order of
  completion, with the task's :class:`~torchsplice.job.task.Part` when it is in memory (else
  ``None``: its part file or shard is on disk, and the merge reads it from there). Shards are
  written only where they outlive the task (``ctx.keep_shards``, :meth:`EngineContext.write_shard`).
  An exception (a ``KeyboardInterrupt`` too) stops it; tasks already handed to ``done`` stay done.
- :meth:`Engine.describe` says what runs the tasks (the closing summary), :meth:`Engine.alive`
  how many workers are alive (the progress bar), :meth:`Engine.close` frees what it holds.

Engines are named in :data:`_ENGINES` (the built-ins by module path, imported when used), so
that the command line lists them without importing torch.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from ...core.errors import TorchspliceError

if TYPE_CHECKING:
    from ..config import JobConfig
    from ..plan import Plan, Task
    from ..sink import Sink
    from ..sources import Sources

__all__ = ["shard_compression", "one_thread_worker", "Engine", "EngineContext", "register_engine", "available_engines", "make_engine", "MAX_ATTEMPTS"]

MAX_ATTEMPTS = 3
"""Tries of a task whose worker dies (local workers: pool breaks in a row; Ray: retries)."""


@dataclass
class EngineContext:
    """What an engine runs: the job's ``config`` and ``plan`` (saved at ``plan_path``), its
    ``sources`` (the clips, in the driver), the ``sink`` that writes shards into ``shard_dir``,
    and whether each task's shard is kept (``keep_shards``: the slices of a ``--shard`` run, and a
    virtual output's frames)."""

    config: "JobConfig"
    plan: "Plan"
    plan_path: Path
    sources: "Sources"
    sink: "Sink"
    shard_dir: Path
    keep_shards: bool = True

    def shard_compression(self):
        return shard_compression(self.config)

    def write_shard(self, task: "Task", part) -> None:
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

    def run(self, tasks: "list[Task]", done: Callable) -> None:
        raise NotImplementedError

    def close(self) -> None:
        pass


_ENGINES: dict[str, "str | Callable[[EngineContext], Engine]"] = {
    "local": "torchsplice.job.engines.local:make_local_engine",
    "ray": "torchsplice.job.engines.ray_cluster:RayEngine",
}


def register_engine(name: str, factory: "Callable[[EngineContext], Engine]", replace_existing: bool = False) -> None:
    """Make ``factory`` (an :class:`Engine` subclass, or a function ``EngineContext -> Engine``)
    the engine ``name`` (lower case letters, digits, ``_`` and ``-``)."""
    import re

    if not isinstance(name, str) or not re.fullmatch(r"[a-z][a-z0-9_-]*", name):
        raise TorchspliceError(f"engine name {name!r} must be lower case letters, digits, '_' or '-', starting with a letter")
    if not callable(factory):
        raise TorchspliceError(f"engine {name!r}: the factory must be an Engine subclass or a function")
    if name in _ENGINES and not replace_existing and _ENGINES[name] is not factory:
        raise TorchspliceError(f"engine {name!r} is already registered; choose another name")
    _ENGINES[name] = factory


def available_engines() -> tuple[str, ...]:
    """The registered engines' names, built-ins first."""
    return tuple(_ENGINES)


def make_engine(ctx: EngineContext) -> Engine:
    """The engine ``ctx.config.engine`` names, made for ``ctx``."""
    name = ctx.config.engine
    factory = _ENGINES.get(name)
    if factory is None:
        raise TorchspliceError(f"unknown engine {name!r}; choose one of {', '.join(_ENGINES)}", options=("engine",))
    if isinstance(factory, str):
        module, _, attr = factory.partition(":")
        factory = getattr(importlib.import_module(module), attr)
    engine = factory(ctx)
    if not isinstance(engine, Engine):
        raise TorchspliceError(f"engine {name!r} made a {type(engine).__name__}, not a torchsplice Engine")
    return engine


def one_thread_worker(config) -> None:
    """What every engine's worker process starts with: one compute thread, for torch and for the
    job's splicing backend (workers run in parallel with each other, not within themselves)."""
    import torch

    torch.set_num_threads(1)
    config.splice_backend().set_threads(1)


def shard_compression(config):
    """Shards of a virtual output are the output's frames: compressed like it; otherwise raw."""
    return config.compression if config.layout == "virtual" else None
