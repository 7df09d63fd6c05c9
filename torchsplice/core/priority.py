"""Choosing among declared implementations: the one rule that ``"auto"`` follows everywhere.

Splicing backends (:mod:`torchsplice.splice.backends`) declare the devices they run on and a
priority, and ``"auto"`` picks with :func:`highest_priority`, so the rule is stated once; the
time alignment's DP (:mod:`torchsplice.align.timewarp`) is the chosen backend's.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Protocol, TypeVar


class Declared(Protocol):
    """What an implementation declares: a priority, whether it runs on a device, and whether it
    can run in this installation."""

    priority: int

    def runs_on(self, device: Any) -> bool: ...

    def available(self) -> bool: ...


T = TypeVar("T", bound=Declared)


def highest_priority(candidates: Iterable[T], device: Any) -> T | None:
    """Among ``candidates`` (in their declared order) that run on ``device`` and are available
    here, the one of highest ``priority``, the first declared of equals; ``None`` if none runs there."""
    best: T | None = None
    for c in candidates:
        if c.runs_on(device) and c.available() and (best is None or c.priority > best.priority):
            best = c
    return best
