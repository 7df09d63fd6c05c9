"""The option defaults of retargeting and mirroring a database's clips, declared once:
:func:`~.clips.retarget_clips` and :func:`~.mirror.mirror_clips` take them from here, and so do
the job's configuration and the command line. Standard library only (see
:mod:`torchsplice.splice.defaults` for the ``defaults`` modules' convention)."""

from __future__ import annotations

__all__ = ["DEFAULT_FIX_FEET", "DEFAULT_ORIGINALS"]

DEFAULT_FIX_FEET = True
"""Retargeted clips' feet held where the source's stand (``retarget_clips``, the job's ``fix_feet``)."""
DEFAULT_ORIGINALS = True
"""``mirror_clips`` writes each original before its mirror image."""
