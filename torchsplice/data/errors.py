"""The dataset's error (kept apart so that every module of :mod:`torchsplice.data` can raise it)."""

from ..core.errors import DatabaseError

__all__ = ["DatasetError"]


class DatasetError(DatabaseError, ValueError):
    """A dataset asked for something the database does not have (a column, a clip, a feature).

    Both a :class:`~torchsplice.core.errors.DatabaseError` and a ``ValueError``.
    """
