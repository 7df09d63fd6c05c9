"""The engines' names, registered once: name -> the engine's factory (an :class:`~.base.Engine` subclass, or a function
:class:`~.base.EngineContext` -> :class:`~.base.Engine`; a built-in by its
``"module:attribute"`` path, imported when the job makes it). Imports nothing of the job, so that
:class:`~torchsplice.job.config.JobConfig` checks an engine's name, and the command line lists
the engines, without the job's modules (and without torch)."""

from __future__ import annotations

import importlib
import re
from typing import Any, Callable

from ...core.errors import TorchspliceError

__all__ = ["register_engine", "available_engines", "engine_factory"]

_ENGINES: dict[str, str | Callable[[Any], Any]] = {
    "local": "torchsplice.job.engines.local:make_local_engine",
    "ray": "torchsplice.job.engines.ray_cluster:RayEngine",
}


def register_engine(name: str, factory: Callable[[Any], Any], replace_existing: bool = False) -> None:
    """Make ``factory`` (an :class:`Engine` subclass, or a function ``EngineContext -> Engine``)
    the engine ``name`` (lower case letters, digits, ``_`` and ``-``)."""
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


def engine_factory(name: str) -> Callable[[Any], Any]:
    """The factory registered as ``name`` (a built-in's module imported now)."""
    factory = _ENGINES.get(name)
    if factory is None:
        raise TorchspliceError(f"unknown engine {name!r}; choose one of {', '.join(_ENGINES)}", options=("engine",))
    if isinstance(factory, str):
        module, _, attr = factory.partition(":")
        factory = getattr(importlib.import_module(module), attr)
    return factory
