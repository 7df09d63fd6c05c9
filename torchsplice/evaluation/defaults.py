"""The report's option defaults, declared once: :func:`~.report.evaluate_database` and the
command line's ``evaluate`` take them from here. Standard library only (see
:mod:`torchsplice.splice.defaults` for the ``defaults`` modules' convention)."""

from __future__ import annotations

__all__ = ["DEFAULT_MAX_ROWS", "DEFAULT_PICTURES"]

DEFAULT_MAX_ROWS = 60
"""Per-clip rows per method in the report."""
DEFAULT_PICTURES = True
"""The report draws pictures of a few example pairs."""
