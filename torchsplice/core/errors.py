"""Errors torchsplice raises for a user's mistake.

Every :class:`TorchspliceError` carries a one-line message that names the file or clip and
what is wrong with it. The command line prints that line and exits non-zero instead of
showing a traceback; library callers can catch the class (or one of its subclasses).

Errors are structured, so that the library never names command-line flags:

- ``hint``: a key saying what would get past the error (:data:`HINTS` lists them with the
  library's wording, e.g. ``"overwrite"``: pass ``overwrite=True``); the command line says the
  same with its flags (``--force``). Subclasses set it: :class:`OutputExistsError`
  (``"overwrite"``), :class:`NotLocomotingError` (``"force_locomotion"``),
  :class:`UnfinishedJobError` (``"restart"``).
- ``options``: names of the options the message speaks of, written ``{name}`` in the message
  (``"{max_length_ratio} must be at least 1"``); ``str(exc)`` shows them as the library's
  names (``max_length_ratio``), the command line as its flags (``--max-length-ratio``).

``exc.message`` is the message without hint; ``str(exc)`` adds the library's hint.
"""

from __future__ import annotations

__all__ = [
    "TorchspliceError",
    "BVHError",
    "DatabaseError",
    "SpecError",
    "MotionError",
    "OutputExistsError",
    "NotLocomotingError",
    "UnfinishedJobError",
    "HINTS",
    "SPELLINGS",
    "render_message",
]

HINTS = {
    "overwrite": "pass overwrite=True to replace it",
    "force_locomotion": "force=True splices it anyway",
    "restart": "restart=True discards it",
}
"""Hint keys, with what a library caller can do (the command line says it with its flags)."""


SPELLINGS = {"no_index": "index=False", "info": "MotionDatabase.summary()"}
"""Options a message names by a setting rather than a name (``{no_index}``: ``index=False``;
the command line's flag ``--no-index``), and ``{info}``: where a database's clips and skeletons are
listed (``MotionDatabase.summary()``; the command line's ``torchsplice info``)."""


def render_message(message: str, options=(), option_name=lambda o: SPELLINGS.get(o, o)) -> str:
    """``message`` with each ``{option}`` of ``options`` written as ``option_name(option)``."""
    for o in options:
        message = message.replace("{" + o + "}", option_name(o))
    return message


class TorchspliceError(Exception):
    """Base class: a problem with the user's input, reported as one line.

    Attributes:
        message: the problem (``{option}`` placeholders for ``options``), without hint.
        hint: ``None`` or a key of :data:`HINTS`: what would get past the error.
        options: names of the options written ``{name}`` in ``message``.
    """

    hint: str | None = None

    def __init__(self, message: str = "", *, hint: str | None = None, options: tuple[str, ...] = ()):
        super().__init__(message)
        self.message = str(message)
        if hint is not None:
            self.hint = hint
        self.options = tuple(options)

    def __str__(self) -> str:
        text = render_message(self.message, self.options)
        extra = HINTS.get(self.hint) if self.hint else None
        return f"{text} ({extra})" if extra else text

    def __reduce__(self):  # keep hint and options across processes (worker pools, Ray)
        return (_rebuild, (type(self), self.message, self.hint, self.options, self.__dict__))


def _rebuild(cls, message, hint, options, state):
    exc = TorchspliceError.__new__(cls)
    Exception.__init__(exc, message)
    exc.__dict__.update(state)
    exc.message, exc.options = message, tuple(options)
    if hint is not None:
        exc.hint = hint
    return exc


class BVHError(TorchspliceError, ValueError):
    """A BVH file that cannot be read: ``"FILE:LINE: problem"``."""

    def __init__(self, path, problem: str, line: int | None = None):
        where = f"{path}:{line}" if line is not None else f"{path}"
        super().__init__(f"{where}: {problem}")
        self.path, self.line, self.problem = path, line, problem


class DatabaseError(TorchspliceError):
    """A motion database that cannot be read or written as asked."""


class SpecError(TorchspliceError, ValueError):
    """A dataset spec that is malformed or does not fit the skeleton it is used with."""


class MotionError(TorchspliceError, ValueError):
    """A clip whose contents cannot be used (NaN, too short, wrong skeleton, ...)."""


class OutputExistsError(DatabaseError):
    """An output file that exists already (hint ``"overwrite"``)."""

    hint = "overwrite"


class LockedError(TorchspliceError):
    """An output another writer holds the lock of (:mod:`torchsplice.store.lock`): the message
    names the holder (host, process, start, command)."""


class NotLocomotingError(MotionError):
    """A clip that does not locomote, refused unless forced (hint ``"force_locomotion"``)."""

    hint = "force_locomotion"


class UnfinishedJobError(TorchspliceError):
    """An unfinished job in the way of a new one: resume it as it was, or discard it (hint ``"restart"``)."""

    hint = "restart"
