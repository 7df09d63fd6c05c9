"""Errors torchsplice raises for a user's mistake.

Every :class:`TorchspliceError` carries a one-line message that names the file or clip and
what is wrong with it. The command line prints that line and exits non-zero instead of
showing a traceback; library callers can catch the class (or one of its subclasses).
"""

from __future__ import annotations

__all__ = ["TorchspliceError", "BVHError", "DatabaseError", "SpecError", "MotionError"]


class TorchspliceError(Exception):
    """Base class: a problem with the user's input, reported as one line."""


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
