"""Choosing clips of a database by name, role or label.

A selector is a comma-separated list of alternatives, any of which selects a clip:

- ``role:NAME``: the clip's role (``locomotion``, ``action``, ``both``, ``spliced``);
- ``label:KEY=VALUE``: the clip's label ``KEY``, ``VALUE`` being a shell-style glob;
- anything else: a shell-style glob on the clip name (``'*walk*'``), case-sensitive.

Several selectors (a repeated command-line flag) must all select a clip:
``--locomotions role:locomotion --locomotions 'label:style=normal'`` takes the normal-style
locomotions, ``--locomotions '*walk*,*run*'`` takes walks and runs.
"""

from __future__ import annotations

import fnmatch
import json
import re
from typing import Sequence

from ..core.errors import TorchspliceError

__all__ = ["select_clips", "parse_selector"]


def parse_selector(text: str) -> list[tuple[str, str, str]]:
    """The alternatives of one selector as ``(kind, key, pattern)``: kind ``role``, ``label`` or ``name``."""
    alts = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            raise TorchspliceError(f"empty alternative in selector {text!r}")
        if part.startswith("role:"):
            alts.append(("role", "", part[5:]))
        elif part.startswith("label:"):
            key, eq, value = part[6:].partition("=")
            if not eq or not key:
                raise TorchspliceError(f"selector {part!r} must read label:KEY=VALUE")
            alts.append(("label", key, value))
        elif re.match(r"^[A-Za-z]+:", part):
            raise TorchspliceError(f"selector {part!r}: unknown prefix {part.split(':')[0]!r} (use role:NAME, "
                                   "label:KEY=VALUE, or a glob on clip names)")
        else:
            alts.append(("name", "", part))
    return alts


def _matches(alts, name: str, role: str, labels: dict) -> bool:
    for kind, key, pattern in alts:
        if kind == "role" and role == pattern:
            return True
        if kind == "label" and key in labels and fnmatch.fnmatchcase(str(labels[key]), pattern):
            return True
        if kind == "name" and fnmatch.fnmatchcase(name, pattern):
            return True
    return False


def _option(what: str) -> tuple[str, ...]:
    """``("locomotions",)`` for the placeholder ``"{locomotions}"``; ``()`` for plain text."""
    return (what[1:-1],) if what.startswith("{") and what.endswith("}") else ()


def _what_there_is(alts, names: list[str], roles: list[str], labels: list[dict]) -> str:
    """For an error: the database's roles, label keys or first clip names, as the selector asked."""
    kinds = {kind for kind, _, _ in alts}
    if kinds == {"role"}:
        return "its roles: " + (", ".join(sorted({r for r in roles if r})) or "none")
    if kinds == {"label"}:
        keys = {key for _, key, _ in alts}
        values = sorted({str(lab[k]) for lab in labels for k in keys if k in lab})
        if len(keys) == 1 and values:
            return f"its {next(iter(keys))} labels: " + ", ".join(values[:8]) + (", ..." if len(values) > 8 else "")
        return "its label keys: " + (", ".join(sorted({k for lab in labels for k in lab})) or "none")
    return "its clips: " + (", ".join(names[:6]) + (", ..." if len(names) > 6 else "") or "none")


def select_clips(table, selectors: Sequence[str], what: str, source: str) -> list[int]:
    """Rows of a database ``table`` (:meth:`MotionDatabase.table`) that every selector selects.

    ``what`` (e.g. ``"{locomotions}"``, an option placeholder of
    :class:`~torchsplice.core.errors.TorchspliceError`, or plain text) and ``source`` (the
    database path) only serve error messages: a selector that selects nothing is an error
    naming it.
    """
    if isinstance(table, dict):  # MotionDatabase.table(): labels as stored
        names, roles = [str(n) for n in table["name"]], [str(r) for r in table["role"]]
        labels = [json.loads(lab or "{}") for lab in table["labels"]]
    else:  # a ClipTable (MotionDatabase.clip_table()): labels decoded
        names, roles, labels = table.names, [str(r) for r in table.role], table.labels
    rows = list(range(len(names)))
    for text in selectors:
        alts = parse_selector(text)
        hit = [i for i in range(len(names)) if _matches(alts, names[i], roles[i], labels[i])]
        if not hit:
            raise TorchspliceError(f"{what} {text!r} selects no clip of {source} ({_what_there_is(alts, names, roles, labels)})",
                                   options=_option(what))
        keep = set(hit)
        rows = [i for i in rows if i in keep]
    if not rows:
        raise TorchspliceError(f"{what} {' and '.join(repr(s) for s in selectors)} together select no clip of {source}",
                               options=_option(what))
    return rows
