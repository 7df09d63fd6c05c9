"""The plan's pairs, held as columns.

A job plans one pair per (method, locomotion, action) it splices: the default job of the whole
Bandai Namco dataset plans 3.1 M of them. As Python objects they took 0.7 GB in the driver and
again in every worker that read the plan. :class:`PairTable` holds them as six ``int32`` columns
(24 bytes a pair), writes them into the plan's JSON as base64 of their little-endian bytes, and
gives :class:`Pair` objects only for the slice a task splices.

Columns, each ``(N,)`` ``int32``, in the plan's order:

- ``method``: index into :attr:`PairTable.methods` (the job's methods, in its order);
- ``loco``, ``action``: rows of the locomotion and action databases;
- ``reference``: row of the ``cpmc`` reference in the action database, ``-1`` for none;
- ``mode``: index into :data:`MODES`;
- ``target``: the locomotion skeleton the action (and reference) are retargeted onto, ``-1``
  when they are on it already.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass

import numpy as np

__all__ = ["Pair", "PairTable", "MODES", "COLUMNS"]

MODES = ("timewarp", "standing")
"""A pair's mode: ``"timewarp"`` (time-aligned) or ``"standing"`` (an action that does not locomote)."""
COLUMNS = ("method", "loco", "action", "reference", "mode", "target")


@dataclass
class Pair:
    """One planned pair: rows in the locomotion and action databases, method, reference row;
    ``target``: the locomotion skeleton the action (and reference) are retargeted onto, ``None``
    when they are on it already."""

    method: str
    loco: int
    action: int
    reference: int | None = None
    mode: str = "timewarp"  # "timewarp" (time-aligned) or "standing" (an action that does not locomote)
    target: int | None = None


class PairTable:
    """The plan's pairs as columns (see the module docstring). ``len(table)`` is the number of
    pairs, ``table[i]`` one :class:`Pair` and ``table[a:b]`` a list of them; ``table.column(name)``
    a column (read-only)."""

    def __init__(self, methods, columns: dict):
        self.methods = tuple(str(m) for m in methods)
        n = {len(columns[k]) for k in COLUMNS}
        if len(n) != 1:
            raise ValueError(f"pair columns of unequal lengths {sorted(n)}")
        self._cols = {k: np.ascontiguousarray(columns[k], dtype=np.int32) for k in COLUMNS}
        for k in COLUMNS:
            self._cols[k].flags.writeable = False

    @classmethod
    def from_pairs(cls, pairs, methods=None) -> "PairTable":
        """The table of a list of :class:`Pair` (``methods``: their order, else as first met)."""
        methods = list(methods) if methods is not None else list(dict.fromkeys(p.method for p in pairs))
        code = {m: n for n, m in enumerate(methods)}
        cols = {"method": [code[p.method] for p in pairs], "loco": [p.loco for p in pairs],
                "action": [p.action for p in pairs],
                "reference": [-1 if p.reference is None else p.reference for p in pairs],
                "mode": [MODES.index(p.mode) for p in pairs],
                "target": [-1 if p.target is None else p.target for p in pairs]}
        return cls(methods, {k: np.asarray(v, dtype=np.int64).reshape(-1) for k, v in cols.items()})

    @classmethod
    def concat(cls, methods, blocks: list[dict]) -> "PairTable":
        """One table of ``blocks`` (dicts of columns, each block's columns of one length), in
        order; the blocks are emptied as their columns are copied."""
        cols = {}
        for k in COLUMNS:  # a column at a time, each block's part let go once copied
            cols[k] = np.concatenate([np.asarray(b.pop(k), dtype=np.int32) for b in blocks]) if blocks else \
                np.zeros(0, dtype=np.int32)
        return cls(methods, cols)

    def __len__(self) -> int:
        return len(self._cols["loco"])

    def column(self, name: str) -> np.ndarray:
        return self._cols[name]

    def _pair(self, i: int) -> Pair:
        c = self._cols
        ref, target = int(c["reference"][i]), int(c["target"][i])
        return Pair(self.methods[int(c["method"][i])], int(c["loco"][i]), int(c["action"][i]),
                    None if ref < 0 else ref, MODES[int(c["mode"][i])], None if target < 0 else target)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self._pair(n) for n in range(*i.indices(len(self)))]
        n = int(i)
        if not -len(self) <= n < len(self):
            raise IndexError(f"pair {n} of {len(self)}")
        return self._pair(n % len(self))

    def __iter__(self):
        return (self._pair(n) for n in range(len(self)))

    def __eq__(self, other) -> bool:
        return (isinstance(other, PairTable) and self.methods == other.methods
                and all(np.array_equal(self._cols[k], other._cols[k]) for k in COLUMNS))

    def count(self, mode: str) -> int:
        """How many pairs are of ``mode`` (:data:`MODES`)."""
        return int(np.count_nonzero(self._cols["mode"] == MODES.index(mode)))

    def to_dict(self) -> dict:
        """The table as JSON-ready values: each column base64 of its little-endian ``int32`` bytes."""
        return {"methods": list(self.methods), "count": len(self),
                **{k: base64.b64encode(self._cols[k].astype("<i4").tobytes()).decode("ascii") for k in COLUMNS}}

    @classmethod
    def from_dict(cls, d: dict) -> "PairTable":
        """The table :meth:`to_dict` wrote (a column of the wrong length raises ``ValueError``)."""
        if not isinstance(d, dict):
            raise ValueError(f"pairs: a JSON {type(d).__name__}, not an object")
        n = int(d["count"])
        cols = {}
        for k in COLUMNS:
            raw = base64.b64decode(d[k], validate=True)
            if len(raw) != 4 * n:
                raise ValueError(f"pairs: column {k} holds {len(raw)} bytes, not 4 x {n}")
            cols[k] = np.frombuffer(raw, dtype="<i4")
        return cls(d["methods"], cols)
