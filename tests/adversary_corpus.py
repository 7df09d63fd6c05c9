"""Hostile inputs for the surfaces past the BVH parser (``bvh_corpus.py`` covers the parser):
clip names, plug-in methods and their results.

- :data:`CONTROL_NAMES`: clip names holding control characters (escape sequences that clear
  the screen, set the window title or forge an output line; bell, newline, DEL, C1, a
  bidirectional override). Every writer refuses them, naming the character.
- :data:`MARKUP_NAMES`: legal clip names that are Markdown or HTML (an image with a script,
  an SVG with ``onload``, a comment that hides the rest of a page, a table pipe, a link, code
  spans, emphasis, a heading or list at the start). They are stored as they are and shown as
  plain text everywhere: reports, the viewer, the terminal.
- :data:`FILE_NAMES`: legal clip names that are not safe file names everywhere (Windows'
  reserved devices and punctuation, names equal but for case): exports make them safe and
  unique without regard to case.
"""

from __future__ import annotations

__all__ = ["CONTROL_NAMES", "MARKUP_NAMES", "FILE_NAMES"]

CONTROL_NAMES = {  # name -> the control character an error must name
    "clear\x1b[2J\x1b[H": "U+001B",
    "title\x1b]0;owned\x07": "U+001B",
    "bell\x07": "U+0007",
    "forged\nwrote out.h5: 0 clips": "U+000A",
    "tab\tname": "U+0009",
    "del\x7f": "U+007F",
    "csi\x9b2J": "U+009B",
    "gnp.exe\u202e": "U+202E",
}

MARKUP_NAMES = [
    "<img src=x onerror=alert(1)>",
    "<svg onload=alert(1)>",
    "<!-- hidden",
    "pipe|cell",
    "[link](javascript:alert(1))",
    "`code` and **bold** _em_",
    "# heading",
    "- item",
    "&amp; entity",
]

FILE_NAMES = ["CON", "nul", "a:b", "a?b", "star*", "quote\"d", "dup", "DUP", "Dup", "trailing.", "lt<gt>"]
