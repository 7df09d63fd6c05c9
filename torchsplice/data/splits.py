"""Train, validation and test splits without leakage: by source clips, not by results.

In an n x m spliced database every action appears in about n results and every locomotion in
about m, so a random split of the results puts the same action in train and in test. Here the
*source* clips are split (seeded, in the ratios asked for): the actions among themselves, then
the locomotions not split already (a clip that is both keeps one split), and a result is in a
split only when all its sources are (:func:`clip_split`): no locomotion or action of the test
split occurs in train. A result whose sources fall in different splits is in none (it is
exported, and listed in ``all``). A source clip's windows (``split_from``) are one performance
and split together, as are a mirrored copy and its original (``mirror_of``); a source whose
labels give it a split (``split``: an imported HumanML3D motion's) keeps it, so that a model
is never trained on the format's own test motions.

With ratios ``(train, val, test)`` of the sources, about ``train^2`` of the results are in
train and ``test^2`` in test; each split with a ratio above 0 gets at least one source of each
kind where there are enough.
"""

from __future__ import annotations

import json
import math
import random
from typing import Sequence

from ..core.errors import TorchspliceError

__all__ = ["SPLITS", "DEFAULT_RATIOS", "parse_ratios", "parse_seed", "split_sources", "clip_sources", "clip_split", "table_splits"]

SPLITS = ("train", "val", "test")
DEFAULT_RATIOS = (0.8, 0.1, 0.1)
"""Of the source clips: train, validation, test."""


def parse_ratios(value) -> tuple[float, float, float]:
    """``(train, val, test)`` from three numbers (a sequence, or text ``"0.8,0.1,0.1"``), each at
    least 0, train above 0, summing to 1 (within 1e-6); one-line error naming ``split_ratios``."""
    try:
        items = [float(v) for v in (value.replace(":", ",").split(",") if isinstance(value, str) else value)]
    except (TypeError, ValueError):
        items = []
    # every comparison with NaN is false: a ratio is checked to be a finite number first
    if len(items) != 3 or not all(math.isfinite(v) for v in items) or min(items) < 0 or items[0] <= 0 \
            or abs(sum(items) - 1.0) > 1e-6:
        raise TorchspliceError(f"{{split_ratios}} must be three numbers train,val,test that sum to 1 (such as "
                               f"0.8,0.1,0.1), got {value!r}", options=("split_ratios",))
    return items[0], items[1], items[2]


def parse_seed(value) -> int:
    """The split's seed: a whole number (``3``, ``"3"``); one-line error naming ``split_seed``."""
    try:
        if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
            raise ValueError
        return int(value)
    except (TypeError, ValueError):
        raise TorchspliceError(f"{{split_seed}} must be a whole number, got {value!r}", options=("split_seed",)) from None


def _counts(n: int, ratios: Sequence[float]) -> list[int]:
    """``n`` items over the splits by largest remainder, each split with a ratio above 0 getting
    at least one where ``n`` allows (taken from the largest)."""
    raw = [n * r for r in ratios]
    counts = [int(x) for x in raw]
    for i in sorted(range(len(raw)), key=lambda i: counts[i] - raw[i])[:n - sum(counts)]:
        counts[i] += 1
    for i, r in enumerate(ratios):
        if r > 0 and counts[i] == 0 and n >= sum(1 for q in ratios if q > 0):
            counts[max(range(len(counts)), key=lambda j: counts[j])] -= 1
            counts[i] += 1
    return counts


def split_sources(groups: Sequence[Sequence[str]], ratios: Sequence[float] = DEFAULT_RATIOS,
                  seed: int = 0, fixed: dict[str, str] | None = None) -> dict[str, str]:
    """Each source clip's split: those ``fixed`` gives (a split the clip already has, such as an
    imported HumanML3D motion's) kept; then each group (the actions, then the locomotions)
    shuffled with ``seed`` and cut in ``ratios``; a name already split keeps its split."""
    out: dict[str, str] = {k: v for k, v in (fixed or {}).items() if v in SPLITS}
    for k, group in enumerate(groups):
        names = sorted(set(n for n in group if n not in out))
        random.Random(f"{seed}:{k}").shuffle(names)
        start = 0
        for split, count in zip(SPLITS, _counts(len(names), ratios)):
            for name in names[start:start + count]:
                out[name] = split
            start += count
    return out


def _source(labels: dict, prefix: str, own: str) -> tuple[str, str]:
    """``(key, fixed split)`` of one source: a mirrored copy and its original are one source
    (``mirror_of``), as are a take's windows (``split_from``); a ``split`` label fixes its split."""
    key = labels.get(prefix + "mirror_of") or labels.get(prefix + "split_from") or own
    split = labels.get(prefix + "split", "")
    return key, split if split in SPLITS else ""


def clip_sources(name: str, role: str, info: dict) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """``(actions, locomotions)``: the source clips a clip comes from (a spliced clip's two; a
    source clip itself, or the take it was cut from), each ``(key, fixed split or "")``."""
    labels = info.get("labels", {})
    if role == "spliced":
        loco = info.get("locomotion") or labels.get("locomotion", "")
        action = info.get("action") or labels.get("action", "")
        return [_source(labels, "action.", action)], [_source(labels, "locomotion.", loco)]
    own = _source(labels, "", name)
    return ([own], []) if role == "action" else ([], [own])


def clip_split(sources: Sequence[str], assigned: dict[str, str]) -> str | None:
    """The split of a clip made of ``sources``: theirs when they agree, else ``None``."""
    splits = {assigned[s] for s in sources}
    return splits.pop() if len(splits) == 1 else None


def streamed_splits(slices, ratios: Sequence[float] = DEFAULT_RATIOS, seed: int = 0) -> Sequence[str]:
    """:func:`table_splits` of a clip table given as ``slices`` (an iterable of column dicts of
    consecutive rows: ``name``, ``role``, ``labels`` as JSON text, ``locomotion`` and ``action``
    where the table has them), in memory bounded by the source clips, not the rows: ``(C,)`` the
    same splits (``""``: none)."""
    import numpy as np  # here: the exports import this module without numpy

    ratios, seed = parse_ratios(ratios), parse_seed(seed)
    ids: dict[str, int] = {}
    rows_a, rows_l, fixed = [], [], {}
    for cols in slices:
        for r, (name, role, text) in enumerate(zip(cols["name"], cols["role"], cols["labels"])):
            info = {"labels": json.loads(text or "{}"),
                    **{c: str(cols[c][r]) for c in ("locomotion", "action") if c in cols}}
            a, l = clip_sources(str(name), str(role), info)
            for k, f in a + l:
                if f:
                    fixed[k] = f
            rows_a.append(ids.setdefault(a[0][0], len(ids)) if a else -1)
            rows_l.append(ids.setdefault(l[0][0], len(ids)) if l else -1)
    a, l = np.array(rows_a, np.int64), np.array(rows_l, np.int64)
    keys = list(ids)
    assigned = split_sources([[keys[i] for i in np.unique(a[a >= 0])], [keys[i] for i in np.unique(l[l >= 0])]],
                             ratios, seed, fixed)
    code = np.array([SPLITS.index(assigned[k]) if k in assigned else -1 for k in keys] + [-2], np.int64)
    sa, sl = code[a], code[l]  # -2: no such source
    out = np.where((sa == -2) | (sl == -2) | (sa == sl), np.where(sa == -2, sl, sa), -1)
    names = np.array([*SPLITS, ""], dtype=object)
    return names[np.where(out < 0, len(SPLITS), out)]


def table_splits(table, ratios: Sequence[float] = DEFAULT_RATIOS, seed: int = 0) -> list[str]:
    """Every clip's split (``""``: its sources are in different splits) of a database's clip
    ``table`` (:class:`~torchsplice.store.table.ClipTable`): sources split once over the whole
    table, so that a selection of its clips keeps their splits (the HumanML3D export and
    ``MotionDataset(split=...)`` both read this)."""
    ratios, seed = parse_ratios(ratios), parse_seed(seed)
    extra = table.extra
    infos = []
    for r, (name, role) in enumerate(zip(table.names, table.role)):
        info = {"labels": table.labels[r], **{c: str(extra[c][r]) for c in ("locomotion", "action") if c in extra}}
        infos.append(clip_sources(name, str(role), info))
    fixed = {k: f for a, l in infos for k, f in a + l if f}
    assigned = split_sources([[k for a, _ in infos for k, _ in a], [k for _, l in infos for k, _ in l]], ratios, seed,
                             fixed)
    return [clip_split([k for k, _ in a + l], assigned) or "" for a, l in infos]
