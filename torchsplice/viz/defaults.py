"""The pictures' option defaults and allowed values, declared once: :func:`~.render.render`,
:mod:`.camera` and :func:`~.viewer.write_viewer` take them from here, and so does the command
line. Standard library only (see :mod:`torchsplice.splice.defaults` for the ``defaults``
modules' convention)."""

from __future__ import annotations

__all__ = ["SUPPORTED_SUFFIXES", "CAMERAS", "DEFAULT_CAMERA", "DEFAULT_FRAMES", "DEFAULT_MAX_SECONDS",
           "DEFAULT_AZIMUTH", "DEFAULT_ELEVATION", "DEFAULT_MAX_CLIPS", "MAX_FILMSTRIP"]

SUPPORTED_SUFFIXES = (".gif", ".mp4", ".png")
"""Output types :func:`~.render.render` writes, chosen by the output's suffix."""
CAMERAS = ("heading", "world")
"""How the camera turns: with the character's heading, or never (it follows the root in both)."""
DEFAULT_CAMERA = "heading"
"""The camera turns with each character's heading (one of :data:`CAMERAS`)."""
DEFAULT_FRAMES = 8
"""Frames per clip in a PNG filmstrip."""
MAX_FILMSTRIP = 64
"""Most frames per clip in a PNG filmstrip: more would not fit a screen (and took minutes and GBs)."""
DEFAULT_MAX_SECONDS: float | None = None
"""Seconds of each clip shown (``None``: all of it)."""
DEFAULT_AZIMUTH = -55.0
"""The camera's angle about the up axis at the first frame (front right of a character facing +Z)."""
DEFAULT_ELEVATION = 22.0
"""The camera's height above the floor, in degrees."""
DEFAULT_MAX_CLIPS = 100
"""Clips in a viewer page when none are named."""
