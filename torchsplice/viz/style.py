"""The pictures' inks: the side colours of the bones, the grid, the trail, the grey of clips drawn
over another, the text, and the opacity of a clip past its end.

Colours are matplotlib colour strings (``"#rrggbb"``). :data:`COLORS` maps a side (:data:`CENTER`,
:data:`LEFT`, :data:`RIGHT`: the character's own, read from joint names by
:func:`~torchsplice.viz.stick_figure.side_of`) to its colour. The GIF writer's fixed palette
(:mod:`torchsplice.viz.writers`) is made of these inks, so anything drawn in another colour
would be mapped to the nearest of them.
"""

from __future__ import annotations

__all__ = ["CENTER", "LEFT", "RIGHT", "COLORS", "GRID_COLOR", "DOT_COLOR", "TRAIL_COLOR", "GHOST_COLOR",
           "ENDED_ALPHA", "TEXT_COLORS"]

CENTER, LEFT, RIGHT = 0, 1, 2
COLORS = {CENTER: "#2b2b2b", LEFT: "#1f6fb4", RIGHT: "#d0342c"}
GRID_COLOR = "#cfd3d8"
DOT_COLOR = "#a9b0b8"  # the grid's crossings in a GIF, a little darker than its lines
TRAIL_COLOR = "#8fb9d9"
GHOST_COLOR = "#9b9b9b"  # the further clips of an overlay panel
ENDED_ALPHA = 0.5
"""Opacity of a figure past its clip's end (a quarter step, so the GIF palette holds it)."""

TEXT_COLORS = ("#000000", "#333333", "#444444", "#b5b5b5")
"""The text: titles, the clock, the time labels, the panels' edges."""
