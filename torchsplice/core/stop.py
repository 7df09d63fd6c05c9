"""A stop asked for by a signal, seen by long work between its steps.

The command line turns SIGTERM into :class:`Terminated` (handled like Ctrl-C: finished work
kept, outputs discarded). Python delivers a signal's exception wherever the main thread is, and
where that is inside a finalizer the exception is only printed and lost; so the handler also
records the stop here (:func:`ask_stop`), and the n x m job checks it after each task
(:func:`check_stop`), stopping as the signal asked.
"""

from __future__ import annotations

__all__ = ["Terminated", "ask_stop", "stop_asked", "check_stop", "clear_stop"]


class Terminated(KeyboardInterrupt):
    """SIGTERM (a scheduler or ``kill`` stopping the process): handled like Ctrl-C."""


_ASKED = [False]


def ask_stop() -> None:
    """Record that a SIGTERM arrived."""
    _ASKED[0] = True


def stop_asked() -> bool:
    """Whether a SIGTERM arrived since :func:`clear_stop`."""
    return _ASKED[0]


def clear_stop() -> None:
    _ASKED[0] = False


def check_stop() -> None:
    """Raise :class:`Terminated` when a SIGTERM arrived (one a library swallowed too)."""
    if _ASKED[0]:
        raise Terminated()
