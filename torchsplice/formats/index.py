"""What every export writes beside its clips: an index of them and split lists.

A training script needs, next to the files, which clip each file holds, what the clip is (its
role, locomotion, action, method, labels) and how good it is (a spliced clip's ``cost``,
``alignment_distance``, ``flags``, ``coverage`` ...), and a train/val/test split that does not
leak: every action appears with every locomotion, so a random split of the results puts the
same action in train and in test. So an export of several clips to a folder (any format whose
export is one file per clip), and every packed file, also writes:

- ``index.csv`` (in the export's folder; beside a packed file ``NAME.index.csv``): one row per
  exported clip, in export order: ``file`` (the file's name in the folder; the packed file's,
  for every row of a packed export), ``clip``, ``split``, then every column ``torchsplice info
  --csv`` writes (frames, fps, duration_s, role, skeleton, source, the clip table's columns;
  labels as JSON);
- ``train.txt``, ``val.txt``, ``test.txt`` (a folder export only): the files of each split, one
  a line.

``splice-all`` (and ``merge``) write the same index beside the job's output database,
``NAME.index.csv`` (:func:`write_database_index`), whose ``file`` is the database's name.

Splits are by source clip (:mod:`torchsplice.data.splits`: seeded, ``split_ratios`` of the
source clips in train, val and test, a result in a split only when all its sources are; the
same splits as the HumanML3D export's and ``MotionDataset(split=...)``'s, computed over the
whole database so that a selection keeps its clips' splits). A clip whose sources are in
different splits has an empty ``split`` and is in no list.

This module imports no torch.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Sequence

__all__ = ["INDEX_NAME", "index_targets", "index_files", "rows_csv", "write_database_index",
           "refresh_database_index"]

INDEX_NAME = "index.csv"
"""The index's name in an export's folder (beside a packed file: ``NAME.index.csv``)."""


def index_targets(out, folder_export: bool) -> dict[str, Path]:
    """The files an export's index writes: ``{"index": ..., "train": ..., ...}`` (split lists
    for a folder export only); ``out`` is the export's folder or packed file."""
    from ..data.splits import SPLITS

    out = Path(out)
    if folder_export:
        return {"index": out / INDEX_NAME, **{s: out / f"{s}.txt" for s in SPLITS}}
    return {"index": out.with_name(out.stem + ".index.csv")}


def rows_csv(rows: Sequence[dict]) -> str:
    """Rows as CSV text: every key of any row a column (first seen first), dicts as JSON."""
    out = io.StringIO()
    columns = list(dict.fromkeys(k for r in rows for k in r))
    w = csv.DictWriter(out, columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: json.dumps(v, sort_keys=True) if isinstance(v, dict) else v for k, v in r.items()})
    return out.getvalue()


def index_files(database, names: Sequence[str] | None, files: Sequence[Path], targets: dict[str, Path],
                split_ratios=None, split_seed: int | None = None) -> dict[Path, str]:
    """The text of each of ``targets`` (:func:`index_targets`) for clips ``names`` (``None``: every
    clip, in the database's order) exported to ``files`` (one per clip, or one packed file for all)."""
    from ..data.splits import DEFAULT_RATIOS, SPLITS, parse_seed, table_splits
    from ..store.database import MotionDatabase

    with MotionDatabase.open(database) as db:
        table = db.clip_table()
        splits = table_splits(table, DEFAULT_RATIOS if split_ratios is None else split_ratios,
                              0 if split_seed is None else parse_seed(split_seed))
        by_name = {c["name"]: c for c in db.summary()["clips"]}
        row_of = {n: r for r, n in enumerate(table.names)}
    if names is None:
        names = list(table.names)
    base = targets["index"].parent
    paths = [Path(f) for f in files]
    shown = {f: str(f.relative_to(base)) if f.parent == base else str(f) for f in set(paths)}
    rows = []
    for k, name in enumerate(names):
        f = paths[k] if len(paths) == len(names) else paths[0]
        info = {key: v for key, v in by_name[name].items() if key != "name"}
        rows.append({"file": shown[f], "clip": name, "split": splits[row_of[name]], **info})
    texts = {targets["index"]: rows_csv(rows)}
    for s in SPLITS:
        if s in targets:
            texts[targets[s]] = "".join(f"{r['file']}\n" for r in rows if r["split"] == s)
    return texts


def write_database_index(database, split_ratios=None, split_seed: int | None = None) -> Path:
    """Write ``NAME.index.csv`` beside the database ``database`` (every clip's row, in the
    database's order; see the module docstring), atomically; returns its path. An OS error (a
    full disk) is one line naming the index and saying the database itself is complete."""
    from ..core.errors import TorchspliceError
    from ..store.atomic import atomic_path

    database = Path(database)
    targets = index_targets(database, folder_export=False)
    text = index_files(database, None, [database], targets, split_ratios, split_seed)[targets["index"]]
    try:
        with atomic_path(targets["index"]) as tmp:
            tmp.write_text(text)
    except TorchspliceError as exc:
        raise TorchspliceError(f"{exc.message}; {database} itself is complete (its index not written: "
                               "torchsplice.formats.index.write_database_index writes it)") from None
    return targets["index"]


def refresh_database_index(database, write: bool = True) -> Path | None:
    """After a database ``database`` was (re)written: remove any earlier ``NAME.index.csv``
    beside it (an earlier run's, with its splits and costs), then with ``write`` write its own
    (:func:`write_database_index`); returns the index written, or ``None``."""
    old = index_targets(database, folder_export=False)["index"]
    try:
        old.unlink(missing_ok=True)
    except OSError:
        pass  # written over below, or left for the user: not worth failing a finished output
    return write_database_index(database) if write else None
