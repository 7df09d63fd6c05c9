"""A stop asked for by a signal, seen by long work between its steps.

The command line turns SIGTERM into :class:`Terminated` (handled like Ctrl-C: finished work
kept, outputs discarded) and SIGINT into ``KeyboardInterrupt``. Python delivers a signal's
exception wherever the main thread is, and where that is inside a finalizer or a weak
reference's callback the exception is only printed and lost; so the handlers also record the
stop here (:func:`ask_stop`), and the n x m job checks it after each task (:func:`check_stop`),
stopping as the signal asked.
"""

from __future__ import annotations

__all__ = ["Terminated", "ask_stop", "stop_asked", "stop_kind", "check_stop", "clear_stop"]


class Terminated(KeyboardInterrupt):
    """SIGTERM (a scheduler or ``kill`` stopping the process): handled like Ctrl-C."""


_ASKED: list[str | None] = [None]  # "terminate" (SIGTERM) or "interrupt" (SIGINT)


def ask_stop(kind: str = "terminate") -> None:
    """Record that a SIGTERM (``"terminate"``) or a SIGINT (``"interrupt"``) arrived; a
    SIGTERM is not turned back into an interrupt by a later SIGINT."""
    if _ASKED[0] != "terminate":
        _ASKED[0] = kind


def stop_asked() -> bool:
    """Whether a SIGTERM or a SIGINT arrived since :func:`clear_stop`."""
    return _ASKED[0] is not None


def stop_kind() -> str | None:
    """``"terminate"``, ``"interrupt"`` or ``None``."""
    return _ASKED[0]


def clear_stop() -> None:
    _ASKED[0] = None


def check_stop() -> None:
    """Raise :class:`Terminated` when a SIGTERM arrived, ``KeyboardInterrupt`` when a SIGINT did
    (one a library swallowed too)."""
    if _ASKED[0] == "terminate":
        raise Terminated()
    if _ASKED[0] == "interrupt":
        raise KeyboardInterrupt()
