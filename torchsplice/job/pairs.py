"""The plan's pairs, held as columns.

A job plans one pair per (method, locomotion, action) it splices: the default job of the whole
Bandai Namco dataset plans 3.1 M of them. As Python objects they took 0.7 GB in the driver and
again in every worker that read the plan. :class:`PairTable` holds them as six ``int32`` columns
(24 bytes a pair), writes them into the plan's JSON as base64 of their little-endian bytes, and
gives :class:`Pair` objects only for the slice a task splices. :func:`form_pairs` forms them:
each skip reason decided once per clip (or skeleton pair) and combined over the locomotions x
actions grid by array operations.

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

from ..splice import SpliceOptions
from ..splice.registry import get_method
from .config import JobConfig
from .sources import clip_key, retargeted_parts

__all__ = ["Pair", "PairTable", "MODES", "COLUMNS", "MIN_SECONDS", "form_pairs"]

MIN_SECONDS = SpliceOptions().min_seconds

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


def form_pairs(config: JobConfig, loco_rows, action_rows, same_db: bool, loco_table, action_table, skeleton_pairs,
               clip_checks, references):
    """Every (method, locomotion, action) of the selections: the pairs to splice, method by method,
    time-aligned ones first, each locomotion against each action; and, for the rest, the
    number of pairs per skip reason. Each reason is decided once per clip, per skeleton pair or
    per clip pair, and combined over the ``L x A`` grid by array operations; the first reason
    wins, in this order: a clip onto itself (or a window onto another window of its take),
    skeletons (``skeleton_pairs``: pairs on other skeletons are retargeted where they can be), too
    short, length ratio, damaged, not locomoting, no reference.

    Args:
        config: the job's configuration (its methods, ``max_length_ratio``, ``force_locomotion``).
        loco_rows, action_rows: the selected rows of the locomotion and action databases.
        same_db: whether locomotions and actions come from one database.
        loco_table, action_table: the two databases' clip tables (names, lengths, frame rates,
            skeletons, labels).
        skeleton_pairs: ``[loco skeleton, action skeleton]`` -> why such pairs are not formed (a
            string), the skeleton the action is retargeted onto (an int), or ``None`` (as it is).
        clip_checks: clip key (:func:`~.sources.clip_key`) -> the clip's check (``finite``,
            ``locomoting``, ``reason``); a retargeted action's under its retargeted key.
        references: action row -> its ``cpmc`` reference row, or ``None``.

    Returns ``(PairTable, {reason: pairs skipped for it})``.
    """
    L, A = np.asarray(loco_rows, dtype=np.int64), np.asarray(action_rows, dtype=np.int64)
    grid = _ReasonGrid(len(L), len(A))
    if same_db:
        _skip_same_takes(grid, L, A, loco_table, action_table)
    pair_target = _skip_skeleton_pairs(grid, L, A, loco_table, action_table, skeleton_pairs)
    _skip_too_short(grid, L, A, loco_table, action_table)
    if config.max_length_ratio is not None:
        _skip_length_ratio(grid, L, A, loco_table, action_table, config.max_length_ratio)
    key_l = {int(i): clip_key("L", i, same_db) for i in L}
    key_a = _action_check_keys(A, same_db, clip_checks)
    _skip_damaged(grid, L, A, loco_table, action_table, clip_checks, key_l, key_a)
    if not config.force_locomotion:
        _skip_not_locomoting(grid, L, loco_table, clip_checks, key_l)
    return _pairs_by_method(config, grid, L, A, action_table, clip_checks, references, key_a, pair_target)


class _ReasonGrid:
    """The ``L x A`` grid of skip reasons: ``codes[l, a]`` is 1 + the index of the pair's reason in
    ``reasons``, 0 while it has none; the first reason given to a pair stays."""

    def __init__(self, n_locos: int, n_actions: int):
        self.reasons: list[str] = []
        self.codes = np.zeros((n_locos, n_actions), dtype=np.int32)

    def code(self, text: str) -> int:
        """A new code for the reason ``text``."""
        self.reasons.append(text)
        return len(self.reasons)

    def put(self, codes) -> None:
        """Give the pairs not skipped yet the reason codes ``codes`` (broadcast to the grid; 0: none)."""
        np.copyto(self.codes, np.broadcast_to(codes, self.codes.shape), where=self.codes == 0)

    def per_clip(self, rows, why) -> np.ndarray:
        """Codes ``(len(rows),)``: ``why(row)`` gives a clip's reason text, or ``None``."""
        out = np.zeros(len(rows), dtype=np.int64)
        for n, r in enumerate(rows.tolist()):
            text = why(r)
            if text is not None:
                out[n] = self.code(text)
        return out


def _skip_same_takes(grid: _ReasonGrid, L, A, tl, ta) -> None:
    """One database: a clip is not spliced onto itself, nor a window onto another of its take."""
    grid.put(np.where(L[:, None] == A[None, :], grid.code("a clip is not spliced onto itself"), 0))
    # windows of one take (import --split: label split_from) are one performance, like a clip itself
    takes: dict[str, int] = {}
    tk_l = np.array([takes.setdefault(tl.labels[r].get("split_from", ""), len(takes)) if tl.labels[r].get("split_from")
                     else -1 for r in L.tolist()], dtype=np.int64)
    tk_a = np.array([takes.setdefault(ta.labels[r].get("split_from", ""), len(takes)) if ta.labels[r].get("split_from")
                     else -2 for r in A.tolist()], dtype=np.int64)
    if takes:
        grid.put(np.where(tk_l[:, None] == tk_a[None, :], grid.code("windows of one take are not spliced onto each other"), 0))


def _skip_skeleton_pairs(grid: _ReasonGrid, L, A, tl, ta, kinds) -> np.ndarray:
    """Pairs whose skeletons are not paired (a reason per skeleton pair); returns ``(L, A)`` the
    skeleton each pair's action is retargeted onto, -1 for none."""
    kl, ka = np.asarray(tl.skeleton, dtype=np.int64)[L], np.asarray(ta.skeleton, dtype=np.int64)[A]
    xs, ys = np.unique(kl).tolist(), np.unique(ka).tolist()
    by_pair = np.zeros((max(xs) + 1, max(ys) + 1), dtype=np.int64)
    target = np.full(by_pair.shape, -1, dtype=np.int32)  # the skeleton an action is retargeted onto; -1: none
    for x in xs:
        for y in ys:
            kind = kinds[x, y]
            if isinstance(kind, str):
                by_pair[x, y] = grid.code(kind)
            elif kind is not None:
                target[x, y] = kind
    grid.put(by_pair[kl[:, None], ka[None, :]])
    return target[kl[:, None], ka[None, :]]


def _skip_too_short(grid: _ReasonGrid, L, A, tl, ta) -> None:
    """Clips shorter than :data:`MIN_SECONDS` (at least 4 frames)."""
    def too_short(table):
        def why(r):
            need = max(4, int(MIN_SECONDS * float(table.fps[r])))
            n = int(table.length[r])
            return f"{table.name[r]} is too short to splice ({n} frames, at least {need})" if n < need else None
        return why

    grid.put(grid.per_clip(L, too_short(tl))[:, None])
    grid.put(grid.per_clip(A, too_short(ta))[None, :])


def _skip_length_ratio(grid: _ReasonGrid, L, A, tl, ta, max_length_ratio: float) -> None:
    """Pairs whose durations differ by more than ``max_length_ratio``."""
    dl = np.asarray(tl.length, dtype=np.float64)[L] / np.asarray(tl.fps, dtype=np.float64)[L]
    da = np.asarray(ta.length, dtype=np.float64)[A] / np.asarray(ta.fps, dtype=np.float64)[A]
    apart = np.maximum(dl[:, None], da[None, :]) > max_length_ratio * np.minimum(dl[:, None], da[None, :])
    grid.put(np.where(apart, grid.code(f"lengths differ by more than {{max_length_ratio}} {max_length_ratio:g}"), 0))


def _action_check_keys(A, same_db: bool, checks: dict) -> dict:
    """Action row -> the key of its checks: of its own clip, else of it retargeted (the first group's)."""
    moved: dict[str, str] = {}
    for k in sorted(checks):
        parts = retargeted_parts(k)
        if parts is not None:
            moved.setdefault(parts[1], k)
    return {j: key if key in checks else moved.get(key, key) for j, key in
            ((j, clip_key("A", j, same_db)) for j in A.tolist())}


def _skip_damaged(grid: _ReasonGrid, L, A, tl, ta, checks: dict, key_l: dict, key_a: dict) -> None:
    """Clips whose frames are not all finite."""
    def damaged(table, keys):
        def why(r):
            check = checks.get(keys[r])
            return f"{table.name[r]} {check.reason}" if check is not None and not check.finite else None
        return why

    grid.put(grid.per_clip(L, damaged(tl, key_l))[:, None])
    grid.put(grid.per_clip(A, damaged(ta, key_a))[None, :])


def _skip_not_locomoting(grid: _ReasonGrid, L, tl, checks: dict, key_l: dict) -> None:
    """Locomotions that do not locomote (unless forced through)."""
    def still(r):
        check = checks.get(key_l[r])
        return (f"{tl.name[r]} does not locomote ({check.reason}; {{force_locomotion}} splices it)"
                if check is not None and not check.locomoting else None)
    grid.put(grid.per_clip(L, still)[:, None])


def _pairs_by_method(c: JobConfig, grid: _ReasonGrid, L, A, ta, checks: dict, refs: dict, key_a: dict,
                     pair_target: np.ndarray):
    """Per method, the pairs of the grid not skipped (a method that needs a reference skips the
    time-aligned actions without one), time-aligned first, then standing ones; and the skipped
    pairs counted per reason over all methods."""
    base = grid.codes.copy()
    ref_of = np.array([-1 if refs.get(j) is None else refs[j] for j in A.tolist()], dtype=np.int32)
    L32, A32 = L.astype(np.int32), A.astype(np.int32)
    blocks: list[dict] = []
    skipped: dict[str, int] = {}
    for m, method in enumerate(c.methods):
        grid.codes[:] = base
        standing = np.array([_mode(c, checks, key_a[int(j)], method) == "standing" for j in A], dtype=bool)
        if get_method(method).needs_reference:
            noref = np.zeros(len(A), dtype=np.int64)
            for n, j in enumerate(A.tolist()):
                if refs.get(j) is None and not standing[n]:
                    noref[n] = grid.code(f"no plain-locomotion reference for {ta.name[j]} ({method})")
            grid.put(noref[None, :])
        per = np.bincount(grid.codes.reshape(-1), minlength=len(grid.reasons) + 1)
        for r in np.nonzero(per[1:])[0].tolist():
            skipped[grid.reasons[r]] = skipped.get(grid.reasons[r], 0) + int(per[r + 1])
        for mode, want in (("timewarp", ~standing), ("standing", standing)):
            rows, cols = np.nonzero((grid.codes == 0) & want[None, :])
            blocks.append({"method": np.full(len(rows), m, np.int32), "loco": L32[rows], "action": A32[cols],
                           "reference": ref_of[cols] if mode == "timewarp" else np.full(len(rows), -1, np.int32),
                           "mode": np.full(len(rows), MODES.index(mode), np.int32), "target": pair_target[rows, cols]})
            del rows, cols
    return PairTable.concat(c.methods, blocks), skipped


def _mode(c: JobConfig, checks: dict, action_key: str, method: str) -> str:
    """``"standing"`` for an action that does not locomote (unless forced through the timewarp,
    or the method has no standing variant: its own function then takes the pair)."""
    check = checks.get(action_key)
    standing = check is not None and not check.locomoting and not c.force_locomotion
    return "standing" if standing and get_method(method).standing is not None else "timewarp"
