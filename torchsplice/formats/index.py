"""What every export writes beside its clips: an index of them and split lists.

A training script needs, next to the files, which clip each file holds, what the clip is (its
role, locomotion, action, method, labels) and how good it is (a spliced clip's ``cost``,
``alignment_distance``, ``flags``, ``coverage`` ...), and a train/val/test split that does not
leak: every action appears with every locomotion, so a random split of the results puts the
same action in train and in test. So an export of several clips to a folder (any format whose
export is one file per clip), and every packed file, also writes:

- ``index.csv`` (in the export's folder; beside a packed file ``NAME.npz.index.csv``): one row per
  exported clip, in export order: ``file`` (the file's name in the folder; the packed file's,
  for every row of a packed export), ``clip``, ``split``, then every column ``torchsplice info
  --csv`` writes (frames, fps, duration_s, role, skeleton, source, the clip table's columns;
  labels as JSON);
- ``train.txt``, ``val.txt``, ``test.txt`` (a folder export only): the files of each split, one
  a line.

``splice-all`` (and ``merge``) write the same index beside the job's output database,
``NAME.h5.index.csv`` (:func:`write_database_index`), whose ``file`` is the database's name.

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

from ..core.names import spreadsheet_cell

__all__ = ["INDEX_NAME", "index_path", "index_targets", "index_files", "rows_csv", "write_database_index",
           "refresh_database_index"]

INDEX_NAME = "index.csv"
"""The index's name in an export's folder (beside a file: :func:`index_path`)."""


def index_targets(out, folder_export: bool) -> dict[str, Path]:
    """The files an export's index writes: ``{"index": ..., "train": ..., ...}`` (split lists
    for a folder export only); ``out`` is the export's folder or packed file."""
    from ..data.splits import SPLITS

    out = Path(out)
    if folder_export:
        return {"index": out / INDEX_NAME, **{s: out / f"{s}.txt" for s in SPLITS}}
    return {"index": index_path(out)}


def index_path(output) -> Path:
    """The index beside a file ``output`` (a database or a packed export): named after the whole
    name, ``spliced.h5.index.csv`` beside ``spliced.h5``, so that the indexes of ``a.h5``,
    ``a.hdf5`` and ``a.npz`` never meet and each command touches only its own output's."""
    output = Path(output)
    return output.with_name(output.name + ".index.csv")


def csv_row(row: dict) -> dict:
    """A row as CSV cells: dicts as JSON, strings that start like a formula kept text
    (:func:`~torchsplice.core.names.spreadsheet_cell`)."""
    return {k: spreadsheet_cell(json.dumps(v, sort_keys=True) if isinstance(v, dict) else v) for k, v in row.items()}


def rows_csv(rows: Sequence[dict]) -> str:
    """Rows as CSV text: every key of any row a column (first seen first), dicts as JSON."""
    out = io.StringIO()
    columns = list(dict.fromkeys(k for r in rows for k in r))
    w = csv.DictWriter(out, columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(csv_row(r))
    return out.getvalue()


def write_rows_csv(path, rows: Sequence[dict]) -> Path:
    """``rows`` (a database's :meth:`~torchsplice.store.database.MotionDatabase.summary` ``clips``,
    as ``info --csv`` writes them) as CSV at ``path``, atomically: :func:`rows_csv`'s columns."""
    from ..store.atomic import atomic_path

    with atomic_path(path) as tmp:
        Path(tmp).write_text(rows_csv(rows))
    return Path(path)


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


CHUNK_ROWS = 50_000
"""Rows of a database's index made and written at a time (:func:`write_database_index`)."""


def _slice_rows(columns: list[str], cols: dict, splits, file: str):
    """The index rows of a slice of the clip table (:meth:`~torchsplice.store.database.MotionDatabase.table_slice`),
    as :func:`index_files` makes them from ``summary()``: the same keys, order and values."""
    from ..store.table import decode_labels, json_value

    for i in range(len(cols["name"])):
        length, fps = int(cols["length"][i]), float(cols["fps"][i])
        yield {"file": file, "clip": str(cols["name"][i]), "split": splits[i], "frames": length, "fps": fps,
               "duration_s": round(float(length / fps), 3), "role": str(cols["role"][i]),
               "labels": decode_labels(file, cols["labels"][i], cols["name"][i]), "skeleton": int(cols["skeleton"][i]),
               "source": str(cols["source"][i]), **{n: json_value(cols[n][i]) for n in columns}}


def write_database_index(database, split_ratios=None, split_seed: int | None = None) -> Path:
    """Write ``NAME.h5.index.csv`` beside the database ``database`` (every clip's row, in the
    database's order; see the module docstring), atomically; returns its path. The rows are made
    and written :data:`CHUNK_ROWS` at a time, so memory stays bounded for millions of clips. An
    OS error (a full disk) is one line naming the index and saying the database itself is complete."""
    from ..core.errors import TorchspliceError
    from ..data.splits import DEFAULT_RATIOS, parse_seed, streamed_splits
    from ..store.atomic import atomic_path
    from ..store.database import MotionDatabase

    database = Path(database)
    target = index_path(database)
    try:
        with atomic_path(target) as tmp, MotionDatabase.open(database) as db, \
                Path(tmp).open("w", newline="") as f:
            C = len(db)
            slices = lambda: (db.table_slice(s, min(s + CHUNK_ROWS, C)) for s in range(0, C, CHUNK_ROWS))  # noqa: E731
            splits = streamed_splits(slices(), DEFAULT_RATIOS if split_ratios is None else split_ratios,
                                     0 if split_seed is None else parse_seed(split_seed))
            writer = None
            for s, cols in zip(range(0, C, CHUNK_ROWS), slices()):
                chunk = list(_slice_rows(list(db.columns), cols, splits[s:s + CHUNK_ROWS], database.name))
                if writer is None:
                    writer = csv.DictWriter(f, list(chunk[0]), lineterminator="\n")
                    writer.writeheader()
                writer.writerows(csv_row(r) for r in chunk)
            if writer is None:
                f.write("file,clip,split\n")
    except TorchspliceError as exc:
        raise TorchspliceError(f"{exc.message}; {database} itself is complete (its index not written: "
                               "torchsplice.formats.index.write_database_index writes it)") from None
    return target


def refresh_database_index(database, write: bool = True) -> Path | None:
    """After a database ``database`` was (re)written: remove any earlier ``NAME.h5.index.csv``
    beside it (an earlier run's, with its splits and costs), then with ``write`` write its own
    (:func:`write_database_index`); returns the index written, or ``None``."""
    old = index_path(database)
    try:
        old.unlink(missing_ok=True)
    except OSError:
        pass  # written over below, or left for the user: not worth failing a finished output
    return write_database_index(database) if write else None
