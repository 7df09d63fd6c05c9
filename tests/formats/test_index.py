"""Indexes of what was written: every export of several clips and every job output gets an index
of its clips (split, metrics) and train/val/test lists that split by source clip as the dataset
does; indexes are named after their whole output and never meet; a full disk while writing the
job's index says the output itself is complete; an index of more clips than a spreadsheet opens
is gzip-compressed."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_helpers import error_line, run
from torchsplice.core.errors import TorchspliceError
from torchsplice.data import MotionDataset
from torchsplice.formats.exporters import export_clips
from torchsplice.job import splice_all
from torchsplice.store.database import MotionDatabase


def test_every_export_of_several_clips_writes_an_index_and_splits_by_source_clip(sample_db, tmp_path):
    """A BVH folder: index.csv (each file's clip, split and metrics, in export order) and
    train/val/test.txt, the splits the dataset gives (no locomotion or action in two splits); a
    packed file: NAME.npz.index.csv beside it; one clip or index=False: none; a bad ratio: nothing."""
    import csv

    spliced = tmp_path / "sp.h5"
    splice_all(sample_db, spliced, workers=1, methods="splice,naive")
    out = tmp_path / "bvh"
    result = export_clips(spliced, None, out=out, split_ratios=(0.4, 0.3, 0.3), split_seed=5)
    text = result.summary
    assert sorted(p.name for p in result.index_files) == ["index.csv", "test.txt", "train.txt", "val.txt"]
    with MotionDatabase.open(spliced) as d:
        names, cost = d.names, {n: float(c) for n, c in zip(d.names, d.clip_table().extra["cost"])}
    rows = list(csv.DictReader(open(out / "index.csv")))
    assert [r["clip"] for r in rows] == names and all((out / r["file"]).is_file() for r in rows)
    for r in rows:  # a naive splice has no cost (NaN in the table, empty here)
        c = cost[r["clip"]]
        assert (r["cost"] == "") if c != c else abs(float(r["cost"]) - c) <= 1e-9 * max(1.0, c)
    assert any(r["cost"] for r in rows)
    assert {"flags", "coverage", "alignment_distance", "locomotion", "action", "method"} <= set(rows[0])
    for s in ("train", "val", "test"):
        listed = (out / f"{s}.txt").read_text().split()
        assert listed == [r["file"] for r in rows if r["split"] == s]
        ds = MotionDataset(spliced, split=s, split_ratios=(0.4, 0.3, 0.3), split_seed=5, features=("rotations",))
        assert sorted(ds.names) == sorted(r["clip"] for r in rows if r["split"] == s)
    by = {s: [r for r in rows if r["split"] == s] for s in ("train", "val", "test")}
    for a in by:
        for b in by:
            if a != b:  # no source clip in two splits
                assert not {r["locomotion"] for r in by[a]} & {r["locomotion"] for r in by[b]}
                assert not {r["action"] for r in by[a]} & {r["action"] for r in by[b]}
    assert f"index.csv, train/val/test {len(by['train'])}/{len(by['val'])}/{len(by['test'])}" in text
    export_clips(spliced, select="method:naive", packed=True, out=tmp_path / "naive.npz")
    packed = list(csv.DictReader(open(tmp_path / "naive.npz.index.csv")))
    assert {r["file"] for r in packed} == {"naive.npz"} and all(r["method"] == "naive" for r in packed)
    assert export_clips(spliced, None, out=tmp_path / "plain", index=False).index_files == []
    assert not list((tmp_path / "plain").glob("*.csv")) and not list((tmp_path / "plain").glob("*.txt"))
    assert export_clips(spliced, names[:1], out=tmp_path / "one.bvh").index_files == []
    assert sorted(p.name for p in tmp_path.glob("one*")) == ["one.bvh"]
    for index in (True, False):  # with no index too
        with pytest.raises(TorchspliceError, match="split_ratios") as caught:
            export_clips(spliced, None, out=tmp_path / "bad", split_ratios=(0.5, 0.5), index=index)
        assert "\n" not in str(caught.value) and not (tmp_path / "bad").exists()
        with pytest.raises(TorchspliceError, match="split_seed must be a whole number, got 'x'"):
            export_clips(spliced, None, out=tmp_path / "bad", split_seed="x", index=index)
    packed_one = export_clips(spliced, names[:1], out=tmp_path / "one.npz", packed=True)  # a packed file, even of one
    assert [p.name for p in packed_one.index_files] == ["one.npz.index.csv"]


def test_cli_refuses_bad_split_ratios_in_one_line_naming_its_flag(sample_db, tmp_path, capsys):
    """The command line's words for export_clips' refusal of ``split_ratios``, index or not."""
    for extra in ((), ("--no-index",)):
        rc, _, err = run(capsys, "export", sample_db, "--all", "-o", tmp_path / "bad", "--split-ratios", "0.5,0.5", *extra)
        assert rc == 2 and "--split-ratios" in error_line(err) and not (tmp_path / "bad").exists(), err


def test_indexes_are_named_after_their_whole_output_and_never_meet(sample_db, tmp_path):
    """a.h5 and a.hdf5, t.npz and t.h5, out.h5 and out.npz: each output's index is its own, and
    no command writes, replaces or removes another output's."""
    splice_all(sample_db, tmp_path / "a.h5", locomotions="jog", workers=1)
    first = (tmp_path / "a.h5.index.csv").read_bytes()
    splice_all(sample_db, tmp_path / "a.hdf5", locomotions="walk_curve", workers=1)
    assert (tmp_path / "a.h5.index.csv").read_bytes() == first and (tmp_path / "a.hdf5.index.csv").is_file()
    export_clips(sample_db, out=tmp_path / "t.npz", format="npz", packed=True)
    packed = (tmp_path / "t.npz.index.csv").read_bytes()
    splice_all(sample_db, tmp_path / "t.h5", locomotions="jog", workers=1, index=False)
    splice_all(sample_db, tmp_path / "t.h5", locomotions="jog", workers=1, overwrite=True)
    assert (tmp_path / "t.npz.index.csv").read_bytes() == packed and (tmp_path / "t.h5.index.csv").is_file()
    export_clips(tmp_path / "a.h5", None, out=tmp_path / "a.npz", packed=True)
    assert (tmp_path / "a.npz.index.csv").is_file() and (tmp_path / "a.h5.index.csv").read_bytes() == first


def test_every_job_output_gets_an_index_of_its_clips_metrics_and_splits(sample_db, tmp_path):
    """``splice_all`` writes ``OUT.h5.index.csv`` beside its output (every clip's cost, flags,
    coverage, labels and split by source clip, as the exports' index and ``info --csv``), and
    so does ``merge_job`` after sliced runs; ``index=False`` (``--no-index``) writes none."""
    import csv

    from torchsplice.data.splits import table_splits
    from torchsplice.formats.index import rows_csv
    from torchsplice.job import merge_job

    out = tmp_path / "sp.h5"
    summary = splice_all(sample_db, out, workers=1, methods="splice,naive")
    assert summary.index == tmp_path / "sp.h5.index.csv"
    assert "every clip's metrics and split in sp.h5.index.csv" in "\n".join(summary.lines())
    rows = list(csv.DictReader(open(tmp_path / "sp.h5.index.csv")))
    with MotionDatabase.open(out) as d:
        table = d.clip_table()
        names, cost = list(table.names), [float(c) for c in table.extra["cost"]]
        splits = table_splits(table)
    assert [r["clip"] for r in rows] == names and {r["file"] for r in rows} == {"sp.h5"}
    assert [r["split"] for r in rows] == splits and {"train", "val", "test"} & set(splits)
    assert all((r["cost"] == "") if c != c else abs(float(r["cost"]) - c) <= 1e-9 * max(1.0, c) for r, c in zip(rows, cost))
    assert {"flags", "coverage", "alignment_distance", "locomotion", "action", "method", "labels"} <= set(rows[0])
    with MotionDatabase.open(out) as d:  # what info --csv writes
        (tmp_path / "info.csv").write_text(rows_csv(d.summary()["clips"]))
    info = list(csv.DictReader(open(tmp_path / "info.csv")))
    assert [{k: r["clip" if k == "name" else k] for k in info[0]} for r in rows] == info  # the same values
    splice_all(sample_db, tmp_path / "plain.h5", locomotions="jog", workers=1, index=False)
    assert sorted(p.name for p in tmp_path.glob("plain*")) == ["plain.h5"]
    summary = splice_all(sample_db, out, workers=1, locomotions="jog", overwrite=True, index=False)
    assert summary.index is None and not (tmp_path / "sp.h5.index.csv").exists()  # an earlier run's index is not left beside it
    for k in (1, 2):
        splice_all(sample_db, tmp_path / "sliced.h5", locomotions="jog", workers=1, shard=f"{k}/2")
    assert not (tmp_path / "sliced.h5.index.csv").exists()  # a slice writes no output, so no index
    merged_summary = merge_job(tmp_path / "sliced.h5", progress=False)
    assert "sliced.h5.index.csv" in "\n".join(merged_summary.lines())
    merged = list(csv.DictReader(open(tmp_path / "sliced.h5.index.csv")))
    with MotionDatabase.open(tmp_path / "sliced.h5") as d:
        assert [r["clip"] for r in merged] == list(d.names)


def test_an_index_of_more_clips_than_a_spreadsheet_opens_is_gzip_compressed(sample_db, tmp_path, monkeypatch):
    """From SPREADSHEET_ROWS clips on, the job's index is NAME.h5.index.csv.gz: the same text as
    the plain index, the same bytes on a rerun; either kind replaces the other beside a rewritten
    output, and merge and materialize name it the same way."""
    import gzip

    from torchsplice.formats import index
    from torchsplice.job.materialize import materialize

    out = tmp_path / "sp.h5"
    splice_all(sample_db, out, workers=1, locomotions="jog,walk", store="alignment")
    plain = (tmp_path / "sp.h5.index.csv").read_bytes()
    with MotionDatabase.open(out) as d:
        clips = len(d)
    assert index.database_index_path(out, clips).name == "sp.h5.index.csv"
    monkeypatch.setattr(index, "SPREADSHEET_ROWS", clips)  # this output has as many clips as a spreadsheet opens
    assert index.database_index_path(out, clips - 1).name == "sp.h5.index.csv"
    assert index.database_index_path(out, clips).name == "sp.h5.index.csv.gz"
    summary = splice_all(sample_db, out, workers=1, locomotions="jog,walk", store="alignment", overwrite=True)
    packed = tmp_path / "sp.h5.index.csv.gz"
    assert summary.index == packed and not (tmp_path / "sp.h5.index.csv").exists()  # the plain one is not left
    assert "every clip's metrics and split in sp.h5.index.csv.gz" in "\n".join(summary.lines())
    assert gzip.decompress(packed.read_bytes()) == plain and len(packed.read_bytes()) < len(plain) / 3
    first = packed.read_bytes()
    assert index.write_database_index(out) == packed and packed.read_bytes() == first  # no time in its header
    materialize(out, tmp_path / "motion.h5", progress=False)
    assert (tmp_path / "motion.h5.index.csv.gz").is_file() and not (tmp_path / "motion.h5.index.csv").exists()
    monkeypatch.setattr(index, "SPREADSHEET_ROWS", clips + 1)
    assert index.refresh_database_index(out) == tmp_path / "sp.h5.index.csv"
    assert (tmp_path / "sp.h5.index.csv").read_bytes() == plain and not packed.exists()
    packed.write_bytes(first)  # a stale index of the other kind beside it: writing the index alone removes it
    assert index.write_database_index(out) == tmp_path / "sp.h5.index.csv" and not packed.exists()


def test_a_full_disk_while_writing_the_jobs_index_says_the_output_is_complete(sample_db, tmp_path, monkeypatch):
    import errno

    real = Path.open

    class Full:  # a file on a full disk: every write fails
        def __init__(self, f):
            self.f = f

        def write(self, text):
            raise OSError(errno.ENOSPC, "No space left on device")

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    def full(self, mode="r", *a, **k):
        f = real(self, mode, *a, **k)
        return Full(f) if ".index.csv" in self.name and "w" in mode else f

    monkeypatch.setattr(Path, "open", full)
    out = tmp_path / "sp.h5"
    with pytest.raises(TorchspliceError, match="sp.h5.index.csv") as caught:
        splice_all(sample_db, out, locomotions="jog", workers=1)
    line = str(caught.value)
    assert "\n" not in line and "no space left" in line.lower() and "sp.h5 itself is complete" in line
    assert out.is_file() and sorted(p.name for p in tmp_path.iterdir()) == ["sp.h5"]  # no temporary left
