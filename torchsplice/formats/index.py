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

``splice-all`` (and ``merge``, ``materialize``) write the same index beside the job's output
database, ``NAME.h5.index.csv`` (:func:`write_database_index`), whose ``file`` is the database's
name. A database of more clips than a spreadsheet opens (:data:`SPREADSHEET_ROWS`) gets it
gzip-compressed instead, ``NAME.h5.index.csv.gz``, the same text: pandas, polars and DuckDB read
it as they read the plain file, in a tenth of the disk or less (3.1 million clips: 0.23 GB,
2.95 GB as plain text).

Splits are by source clip (:mod:`torchsplice.data.splits`: seeded, ``split_ratios`` of the
source clips in train, val and test, a result in a split only when all its sources are; the
same splits as the HumanML3D export's and ``MotionDataset(split=...)``'s, computed over the
whole database so that a selection keeps its clips' splits). A clip whose sources are in
different splits has an empty ``split`` and is in no list.

This module imports no torch.
"""

from __future__ import annotations

import csv
import gzip
import io
import json
from pathlib import Path
from typing import Sequence

from ..core.errors import TorchspliceError
from ..core.names import spreadsheet_cell
from ..data.splits import DEFAULT_RATIOS, SPLITS, parse_seed, streamed_splits, table_splits
from ..store.atomic import atomic_path

__all__ = ["INDEX_NAME", "SPREADSHEET_ROWS", "index_path", "database_index_path", "index_targets", "index_files",
           "rows_csv", "write_database_index", "refresh_database_index"]

INDEX_NAME = "index.csv"
"""The index's name in an export's folder (beside a file: :func:`index_path`)."""


def index_targets(out, folder_export: bool) -> dict[str, Path]:
    """The files an export's index writes: ``{"index": ..., "train": ..., ...}`` (split lists
    for a folder export only); ``out`` is the export's folder or packed file."""
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


SPREADSHEET_ROWS = 1_048_576
"""The most rows a spreadsheet opens (Excel's and LibreOffice Calc's limit, the header included).
A database index of as many clips or more is written gzip-compressed (:func:`database_index_path`):
no spreadsheet opens it whole, and as plain text it would take about a third of the database's
own size."""

GZIP_LEVEL = 3
"""zlib's level for a compressed index: 8x to 13x smaller than the text at about 250 MB/s on one
core (level 6, gzip's default, is a little smaller at 100 MB/s: seconds more on a job's last step
for little)."""


def database_index_path(database, clips: int) -> Path:
    """The index :func:`write_database_index` writes beside the database ``database`` of ``clips``
    clips: :func:`index_path`'s ``NAME.h5.index.csv``, or ``NAME.h5.index.csv.gz`` from
    :data:`SPREADSHEET_ROWS` clips on."""
    plain, packed = _index_kinds(database)
    return packed if clips >= SPREADSHEET_ROWS else plain


def _index_kinds(database) -> tuple[Path, Path]:
    """The two names a database's index may have: plain ``NAME.h5.index.csv`` and compressed ``NAME.h5.index.csv.gz``."""
    plain = index_path(database)
    return plain, plain.with_name(plain.name + ".gz")


def _text_file(path: Path, compressed: bool):
    """``path`` opened for writing CSV text (UTF-8), through gzip when ``compressed``: the same
    bytes on every run (no time or name in the gzip header), so a rerun's index is the same file."""
    if not compressed:
        return path.open("w", newline="", encoding="utf-8")
    raw = path.open("wb")
    try:
        packed = gzip.GzipFile(filename="", mode="wb", fileobj=raw, compresslevel=GZIP_LEVEL, mtime=0)
    except BaseException:
        raw.close()
        raise
    return _Closing(io.TextIOWrapper(packed, encoding="utf-8", newline=""), raw)


class _Closing:
    """A text stream over a gzip stream over a file: closing it closes all three (GzipFile leaves
    a file object it was given open)."""

    def __init__(self, text, raw):
        self.text, self.raw = text, raw

    def write(self, s):
        return self.text.write(s)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        try:
            self.text.close()
        finally:
            self.raw.close()


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
    with atomic_path(path) as tmp:
        Path(tmp).write_text(rows_csv(rows))
    return Path(path)


def index_files(database, names: Sequence[str] | None, files: Sequence[Path], targets: dict[str, Path],
                split_ratios=None, split_seed: int | None = None) -> dict[Path, str]:
    """The text of each of ``targets`` (:func:`index_targets`) for clips ``names`` (``None``: every
    clip, in the database's order) exported to ``files`` (one per clip, or one packed file for all)."""
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


def _slice_columns(columns: list[str], cols: dict, splits, file: str) -> dict[str, list]:
    """The index rows of a slice of the clip table (:meth:`~torchsplice.store.database.MotionDatabase.table_slice`),
    column by column as CSV cells: the keys, order and values :func:`index_files` makes from
    ``summary()`` and :func:`csv_row` writes, made a column at a time (a job's index has
    millions of rows: a cell at a time, writing it took a third of the default job)."""
    import numpy as np

    from ..store.table import decode_labels, json_value

    names = [str(x) for x in cols["name"].tolist()]
    length = np.asarray(cols["length"]).astype(np.int64)
    fps = np.asarray(cols["fps"], dtype=np.float64)
    out = {"file": [file] * len(names), "clip": names, "split": [str(x) for x in splits],
           "frames": length.tolist(), "fps": fps.tolist(),
           "duration_s": [round(d, 3) for d in (length / fps).tolist()],  # Python's round, as summary() rounds
           "role": [str(x) for x in cols["role"].tolist()],
           "labels": [json.dumps(decode_labels(file, text, name), sort_keys=True)
                      for text, name in zip(cols["labels"].tolist(), names)],
           "skeleton": np.asarray(cols["skeleton"]).astype(np.int64).tolist(),
           "source": [str(x) for x in cols["source"].tolist()]}
    text = {"file", "clip", "split", "role", "labels", "source"}
    for name in columns:
        values = np.asarray(cols[name])
        if values.dtype.kind == "f":
            out[name] = [None if v != v else v for v in values.tolist()]  # NaN as an empty cell, as json_value
        elif values.dtype.kind in "iub":
            out[name] = values.tolist()
        else:
            out[name] = [json_value(v) for v in values]
            text.add(name)
    return {k: [spreadsheet_cell(v) for v in column] if k in text else column for k, column in out.items()}


def write_database_index(database, split_ratios=None, split_seed: int | None = None) -> Path:
    """Write the index beside the database ``database`` (every clip's row, in the database's order;
    see the module docstring), atomically: ``NAME.h5.index.csv``, or gzip-compressed
    ``NAME.h5.index.csv.gz`` for :data:`SPREADSHEET_ROWS` clips or more (the other kind, if one
    lies beside it, is removed); returns its path. The rows
    are made and written :data:`CHUNK_ROWS` at a time, so memory stays bounded for millions of
    clips. An OS error (a full disk) is one line naming the index and saying the database itself
    is complete."""
    from ..store.database import MotionDatabase

    database = Path(database)
    with MotionDatabase.open(database) as db:
        C = len(db)
        target = database_index_path(database, C)
        try:
            with atomic_path(target) as tmp, _text_file(Path(tmp), target.suffix == ".gz") as f:
                slices = lambda: (db.table_slice(s, min(s + CHUNK_ROWS, C)) for s in range(0, C, CHUNK_ROWS))  # noqa: E731
                splits = streamed_splits(slices(), DEFAULT_RATIOS if split_ratios is None else split_ratios,
                                         0 if split_seed is None else parse_seed(split_seed))
                writer = None
                for s, cols in zip(range(0, C, CHUNK_ROWS), slices()):
                    cells = _slice_columns(list(db.columns), cols, splits[s:s + CHUNK_ROWS], database.name)
                    if writer is None:
                        writer = csv.writer(f, lineterminator="\n")
                        writer.writerow(list(cells))
                    writer.writerows(zip(*cells.values()))
                if writer is None:
                    f.write("file,clip,split\n")
        except TorchspliceError as exc:
            raise TorchspliceError(f"{exc.message}; {database} itself is complete (its index not written: "
                                   "torchsplice.formats.index.write_database_index writes it)") from None
    _remove([p for p in _index_kinds(database) if p != target])  # an earlier index of the other kind disagrees
    return target


def refresh_database_index(database, write: bool = True) -> Path | None:
    """After a database ``database`` was (re)written: remove any earlier ``NAME.h5.index.csv``
    or ``NAME.h5.index.csv.gz`` beside it (an earlier run's, with its splits and costs), then with
    ``write`` write its own (:func:`write_database_index`); returns the index written, or ``None``."""
    _remove(_index_kinds(database))
    return write_database_index(database) if write else None


def _remove(paths) -> None:
    """Remove earlier indexes at ``paths``: one that cannot be is written over or left for the
    user, not worth failing a finished output."""
    for path in paths:
        try:
            path.unlink(missing_ok=True)
        except OSError:
            pass
