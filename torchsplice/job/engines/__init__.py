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

Modules: :mod:`.registry` (the engines' names: it imports nothing of the job, so the job's
config checks a name, and the command line lists them, without torch) and :mod:`.base` (the
context, the base class and :func:`make_engine`); the engines themselves (:mod:`.local`,
:mod:`.inline`, :mod:`.ray_cluster`, and :mod:`.forkserver`, the local engine's early start).
The names below are imported on first use.
"""

from typing import TYPE_CHECKING

from ...core.lazy import lazy_names

if TYPE_CHECKING:  # pragma: no cover
    from .base import MAX_ATTEMPTS, Engine, EngineContext, make_engine, one_thread_worker, shard_compression
    from .registry import available_engines, register_engine

__all__ = ["shard_compression", "one_thread_worker", "Engine", "EngineContext", "register_engine", "available_engines",
           "make_engine", "MAX_ATTEMPTS"]

__getattr__, __dir__ = lazy_names(__name__, {
    "MAX_ATTEMPTS": ".base", "Engine": ".base", "EngineContext": ".base", "make_engine": ".base",
    "one_thread_worker": ".base", "shard_compression": ".base",
    "register_engine": ".registry", "available_engines": ".registry",
})
