"""The one selection language for clips of a database: the job's ``--locomotions`` and
``--actions``, the dataset's ``select=`` and the exports' ``select=`` all read it.

A selector is a comma-separated list of alternatives, any of which selects a clip:

- ``role:NAME``: the clip's role (``locomotion``, ``action``, ``both``, ``spliced``);
- ``label:KEY=VALUE``: the clip's label ``KEY``, ``VALUE`` being a shell-style glob;
- ``skeleton:K``: the clips on skeleton ``K`` of the database;
- ``COLUMN:VALUE``: a text column the database declares (a spliced database's ``method``,
  ``flags``, ``timing``, ``locomotion``, ``action``...), ``VALUE`` a shell-style glob
  (``method:naive``, ``flags:*poor_alignment*``, ``flags:`` for the clips without a flag);
- ``COLUMN<VALUE``, ``<=``, ``>``, ``>=``: a number column the database declares (a spliced
  database's ``penetration``, ``alignment_distance``, ``cost``...) against a number
  (``'penetration<0.01'``, ``'alignment_distance<=0.1'``; NaN selects nothing);
- anything else: a shell-style glob on the clip name (``'*walk*'``), case-sensitive.

A selector that is exactly a clip's name selects that clip, before any splitting, so a name
holding ``,`` or ``:`` (a BVH file named ``x,y.bvh``) is reached as it is; inside a longer
selector, bracket the character (``'x[,]y,walk_*'``): a comma in brackets does not separate.

Several selectors (a repeated command-line flag, or a list) must all select a clip:
``--locomotions role:locomotion --locomotions 'label:style=normal'`` takes the normal-style
locomotions, ``--locomotions '*walk*,*run*'`` takes walks and runs.

Selection reads a database's :class:`~torchsplice.store.table.ClipTable`
(``MotionDatabase.clip_table()``), one pass over the clips per alternative.
"""

from __future__ import annotations

import fnmatch
import re
from typing import Iterable, Sequence

import numpy as np

from ..core.errors import TorchspliceError
from .table import ClipTable

__all__ = ["select_clips", "parse_selector", "names_or_selector", "looks_like_selector"]


_COMPARISON = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)\s*(<=|>=|<|>)\s*(\S+)$")
_OPERATORS = {"<": np.less, "<=": np.less_equal, ">": np.greater, ">=": np.greater_equal}


def parse_selector(text: str, columns: Sequence[str] = (), numbers: Sequence[str] = ()) -> list[tuple[str, str, str]]:
    """The alternatives of one selector as ``(kind, key, pattern)``: kind ``role``, ``label``,
    ``skeleton``, ``column`` (one of ``columns``, the table's text columns), ``number`` (one of
    ``numbers``, its number columns; ``pattern`` the operator and the number) or ``name``."""
    alts = []
    for part in (p.strip() for p in re.split(r",(?![^\[]*\])", text)):  # a comma in [...] is a character
        if not part:
            raise TorchspliceError(f"empty alternative in selector {text!r}")
        prefix = part.split(":", 1)[0] if ":" in part else ""
        compared = _COMPARISON.match(part)
        if compared and compared.group(1) in numbers:
            try:
                float(compared.group(3))
            except ValueError:
                raise TorchspliceError(f"selector {part!r}: {compared.group(3)!r} is not a number") from None
            alts.append(("number", compared.group(1), f"{compared.group(2)} {compared.group(3)}"))
        elif compared and numbers:
            raise TorchspliceError(
                f"selector {part!r}: {compared.group(1)!r} is not a number column (number columns: "
                f"{', '.join(numbers)})"
            )
        elif part.startswith("role:"):
            alts.append(("role", "", part[5:]))
        elif part.startswith("skeleton:"):
            if not part[9:].strip().isdigit():
                raise TorchspliceError(f"selector {part!r} must read skeleton:K, K a skeleton number")
            alts.append(("skeleton", "", str(int(part[9:]))))
        elif prefix and prefix in columns:
            alts.append(("column", prefix, part[len(prefix) + 1 :]))
        elif part.startswith("label:"):
            key, eq, value = part[6:].partition("=")
            if not eq or not key:
                raise TorchspliceError(f"selector {part!r} must read label:KEY=VALUE")
            alts.append(("label", key, value))
        elif re.match(r"^[A-Za-z]+:", part):
            known = "".join(f", {c}:VALUE" for c in columns)
            raise TorchspliceError(
                f"selector {part!r}: unknown prefix {part.split(':')[0]!r} (use role:NAME, "
                f"label:KEY=VALUE, skeleton:K{known}, or a glob on clip names)"
            )
        else:
            alts.append(("name", "", part))
    return alts


def _mask(alt, names, roles: np.ndarray, labels: list[dict], skeletons: np.ndarray, columns: dict) -> np.ndarray:
    """``(C,)`` bool: the clips one alternative ``(kind, key, pattern)`` selects."""
    kind, key, pattern = alt
    if kind == "number":
        op, value = pattern.split(" ")
        with np.errstate(invalid="ignore"):
            return _OPERATORS[op](np.asarray(columns[key], dtype=np.float64), float(value))
    if kind == "role":
        return roles == pattern
    if kind == "skeleton":
        return skeletons == int(pattern)
    match = re.compile(fnmatch.translate(pattern)).match  # fnmatchcase: case-sensitive, whole value
    if kind == "label":
        values = (str(lab[key]) if key in lab else None for lab in labels)
        return np.fromiter((v is not None and match(v) is not None for v in values), bool, len(labels))
    values = columns[key] if kind == "column" else names
    return np.fromiter((match(str(v)) is not None for v in values), bool, len(values))


def _option(what: str) -> tuple[str, ...]:
    """``("locomotions",)`` for the placeholder ``"{locomotions}"``; ``()`` for plain text."""
    return (what[1:-1],) if what.startswith("{") and what.endswith("}") else ()


def _what_there_is(
    alts, names: list[str], roles: Iterable[str], labels: list[dict], skeletons=None, columns: dict | None = None
) -> str:
    """For an error: the database's roles, label keys, skeletons, column values or first clip
    names, as the selector asked."""
    kinds = {kind for kind, _, _ in alts}
    if kinds == {"number"} and columns and len({key for _, key, _ in alts}) == 1:
        key = alts[0][1]
        numbers = np.asarray(columns[key], dtype=np.float64)
        numbers = numbers[np.isfinite(numbers)]
        return f"its {key} values: " + (f"{numbers.min():g} to {numbers.max():g}" if len(numbers) else "none")
    if kinds == {"skeleton"} and skeletons is not None:
        return "its skeletons: " + (", ".join(str(k) for k in sorted({int(k) for k in skeletons})) or "none")
    if kinds == {"column"} and columns and len({key for _, key, _ in alts}) == 1:
        key = alts[0][1]
        values = sorted({str(v) for v in columns[key]})
        return f"its {key} values: " + (
            ", ".join(repr(v) for v in values[:8]) + (", ..." if len(values) > 8 else "") or "none"
        )
    if kinds == {"role"}:
        return "its roles: " + (", ".join(sorted({r for r in roles if r})) or "none")
    if kinds == {"label"}:
        keys = {key for _, key, _ in alts}
        values = sorted({str(lab[k]) for lab in labels for k in keys if k in lab})
        if len(keys) == 1 and values:
            return f"its {next(iter(keys))} labels: " + ", ".join(values[:8]) + (", ..." if len(values) > 8 else "")
        return "its label keys: " + (", ".join(sorted({k for lab in labels for k in lab})) or "none")
    return "its clips: " + (", ".join(names[:6]) + (", ..." if len(names) > 6 else "") or "none")


def select_clips(table: ClipTable, selectors: str | Sequence[str], what: str, source: str) -> list[int]:
    """Rows of a database's clip ``table`` that every selector selects, in row order.

    ``what`` (e.g. ``"{locomotions}"``, an option placeholder of
    :class:`~torchsplice.core.errors.TorchspliceError`, or plain text) and ``source`` (the
    database path) only serve error messages: a selector that selects nothing is an error
    naming it.
    """
    selectors = [selectors] if isinstance(selectors, str) else list(selectors)
    names, labels = table.names, table.labels
    roles, skeletons = np.asarray(table.role, dtype=str), np.asarray(table.skeleton)
    columns = {k: v for k, v in table.extra.items() if table.kinds.get(k) == "str"}
    numbers = tuple(k for k in table.extra if table.kinds.get(k) in ("float", "int"))
    columns.update({k: table.extra[k] for k in numbers})
    keep = np.ones(len(names), dtype=bool)
    known = set(names)
    for text in selectors:
        if text in known:  # a clip's exact name, before any splitting (it may hold "," or ":")
            keep &= np.asarray(names, dtype=object) == text
            continue
        alts = parse_selector(text, tuple(k for k in columns if k not in numbers), numbers)
        hit = np.zeros(len(names), dtype=bool)
        for alt in alts:
            hit |= _mask(alt, names, roles, labels, skeletons, columns)
        if not hit.any():
            raise TorchspliceError(
                f"{what} {text!r} selects no clip of {source} "
                f"({_what_there_is(alts, names, roles, labels, skeletons, columns)})"
                + _colon_hint(text, [k for k in columns if k not in numbers]),
                options=_option(what),
            )
        keep &= hit
    if not keep.any():
        raise TorchspliceError(
            f"{what} {' and '.join(repr(s) for s in selectors)} together select no clip of {source}",
            options=_option(what),
        )
    return np.flatnonzero(keep).tolist()


def _colon_hint(text: str, columns) -> str:
    """``"; did you mean 'role:locomotion'?"`` for a selector written ``role=locomotion`` (a
    prefix of the language followed by ``=`` instead of ``:``), else ``""``."""
    m = re.match(r"^\s*([A-Za-z_]+)\s*=\s*(.*)$", text)
    if m and (m.group(1) in ("role", "skeleton") or m.group(1) in columns):
        return f"; did you mean {m.group(1) + ':' + m.group(2)!r}?"
    if m and m.group(1) != "label":
        return f"; did you mean {'label:' + m.group(1) + '=' + m.group(2)!r}?"
    return ""


def looks_like_selector(text: str) -> bool:
    """Whether a command's clip argument reads as a selector (a glob, a ``PREFIX:`` or
    alternatives) rather than a plain clip name."""
    return re.search(r"[*?\[,:<>]", text) is not None


def names_or_selector(table: ClipTable, items: Sequence[str]) -> tuple[list[str] | None, str | None]:
    """What a command's clip arguments mean: ``(names, None)`` when every item is a clip name of
    ``table`` (kept in their order), else ``(None, selector)``: the items as alternatives of one
    selector (``export db.h5 'role:spliced'``, ``render db.h5 'walk_*'``), clip names among them
    matched exactly. A selector that selects nothing is refused by :func:`select_clips`; an item
    that reads as a plain name (no glob, prefix or comma) but names no clip comes back alone as a
    name, so that reading it gives the database's "no clip named" error."""
    known = set(table.names)
    items = list(items)
    if all(i in known for i in items):
        return items, None
    plain = [i for i in items if i not in known and not looks_like_selector(i)]
    if plain:  # meant as a name: the database's own "no clip named" (with similar names)
        return plain, None
    escaped = [re.sub(r"([*?\[,:])", r"[\1]", i) if i in known else i for i in items]
    return None, ",".join(escaped)
