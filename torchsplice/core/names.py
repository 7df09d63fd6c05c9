"""Names users give to clips and methods, and how they are shown.

A clip's name (a BVH file's stem, a ``--split`` window's ``NAME#000``, a spliced clip's
``loco__action__method``) and a plug-in method's name are printed to terminals, written into
Markdown reports and HTML pages, and used as file names by exports. A name must therefore hold
no *control character*: C0 (U+0000-U+001F, newline and tab included), DEL, C1 (U+0080-U+009F),
lone surrogates, and the bidirectional overrides and isolates (U+202A-U+202E, U+2066-U+2069)
that reorder what a reader sees. Printed raw, they move the cursor, clear the screen, set the
window title or forge output lines. Every writer refuses them (:func:`control_character`);
:func:`printable` escapes them where text from elsewhere is shown. In a CSV file a name that
starts like a formula (``=``, ``+``, ``-``, ``@``) would run as one in a spreadsheet:
:func:`spreadsheet_cell` writes it so that spreadsheets read it as text.
"""

from __future__ import annotations

import re

__all__ = ["CONTROL", "control_character", "printable", "quoted", "spreadsheet_cell", "counted"]

CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069\ud800-\udfff]")
"""The characters a name must not hold (see the module docstring)."""


def control_character(name: str) -> str | None:
    """``"control character U+001B"`` for the first control character in ``name``, else ``None``."""
    bad = CONTROL.search(str(name))
    return None if bad is None else f"control character U+{ord(bad.group()):04X}"


def printable(text: str, limit: int | None = None) -> str:
    """``text`` with every control character written as a Python escape (``\\x1b``, ``\\n``,
    ``\\u202e``), cut to ``limit`` characters with ``...`` when given: safe to print."""
    out = CONTROL.sub(
        lambda m: (
            m.group().encode("unicode_escape").decode("ascii")
            if ord(m.group()) < 0xD800 or ord(m.group()) > 0xDFFF
            else f"\\u{ord(m.group()):04x}"
        ),
        str(text),
    )
    return out if limit is None or len(out) <= limit else out[: max(0, limit - 3)] + "..."


def quoted(text: str, limit: int = 60) -> str:
    """``repr(text)``, cut to about ``limit`` characters with an ellipsis (for error messages)."""
    r = repr(text)
    return r if len(r) <= limit else r[: limit - 4] + "..." + r[-1]


FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")
"""What a CSV cell may not start with and stay text in Excel, LibreOffice or Google Sheets."""


def spreadsheet_cell(value):
    """A CSV cell's value that spreadsheets read as text: a string starting with ``=``, ``+``,
    ``-``, ``@``, a tab or a carriage return gets a leading apostrophe (OWASP's advice against
    CSV formula injection: ``=cmd|calc!A0`` becomes ``'=cmd|calc!A0``); other values as they are
    (numbers stay numbers, so ``-0.5`` is still a number)."""
    if isinstance(value, str) and value.startswith(FORMULA_STARTS):
        return "'" + value
    return value


def counted(count: int, word: str) -> str:
    """``"1 clip"``, ``"2 clips"``: a count with its noun, plural unless one (what every
    message that counts says)."""
    return f"{count} {word}{'' if count == 1 else 's'}"
