"""The database's allowed compressions, declared once: :mod:`.schema` (and so
:meth:`~.database.MotionDatabase.create` and the checks on open) take them from here, and so do
the job's configuration and the command line. Standard library only (see
:mod:`torchsplice.splice.defaults` for the ``defaults`` modules' convention)."""

from __future__ import annotations

__all__ = ["COMPRESSIONS"]

COMPRESSIONS = ("gzip", "lzf", "auto", None)
"""The compressions a database is written with (``None``: none)."""
