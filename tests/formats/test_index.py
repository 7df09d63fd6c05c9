"""Indexes of what was written: every export of several clips and every job output gets an index
of its clips (split, metrics) and train/val/test lists that split by source clip as the dataset
does; indexes are named after their whole output and never meet; a full disk while writing the
job's index says the output itself is complete."""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_helpers import error_line, run
from torchsplice.cli import main
from torchsplice.core.errors import TorchspliceError
from torchsplice.data import MotionDataset
from torchsplice.formats.exporters import export_clips
from torchsplice.store.database import MotionDatabase


def test_every_export_of_several_clips_writes_an_index_and_splits_by_source_clip(sample_db, tmp_path, capsys):
    """A BVH folder: index.csv (each file's clip, split and metrics, in export order) and
    train/val/test.txt, the splits the dataset gives (no locomotion or action in two splits); a
    packed file: NAME.npz.index.csv beside it; one clip or --no-index: none; a bad ratio: nothing."""
    import csv

    spliced = tmp_path / "sp.h5"
    assert main(["splice-all", str(sample_db), "-o", str(spliced), "-q", "--workers", "1", "--method", "splice,naive"]) == 0
    out = tmp_path / "bvh"
    rc, text, err = run(capsys, "export", spliced, "--all", "-o", out, "--split-ratios", "0.4,0.3,0.3", "--split-seed", "5")
    assert rc == 0, err
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
    rc, _, err = run(capsys, "export", spliced, "method:naive", "--packed", "-o", tmp_path / "naive.npz")
    assert rc == 0, err
    packed = list(csv.DictReader(open(tmp_path / "naive.npz.index.csv")))
    assert {r["file"] for r in packed} == {"naive.npz"} and all(r["method"] == "naive" for r in packed)
    assert run(capsys, "export", spliced, "--all", "-o", tmp_path / "plain", "--no-index")[0] == 0
    assert not list((tmp_path / "plain").glob("*.csv")) and not list((tmp_path / "plain").glob("*.txt"))
    assert run(capsys, "export", spliced, names[0], "-o", tmp_path / "one.bvh")[0] == 0
    assert sorted(p.name for p in tmp_path.glob("one*")) == ["one.bvh"]
    rc, _, err = run(capsys, "export", spliced, "--all", "-o", tmp_path / "bad", "--split-ratios", "0.5,0.5")
    assert rc == 2 and "split-ratios" in error_line(err) and not (tmp_path / "bad").exists()
    rc, _, err = run(capsys, "export", spliced, "--all", "-o", tmp_path / "bad", "--split-ratios", "0.5,0.5", "--no-index")
    assert rc == 2 and "split-ratios" in error_line(err) and not (tmp_path / "bad").exists(), err  # with no index too
    for index in (True, False):
        with pytest.raises(TorchspliceError, match="split_seed must be a whole number, got 'x'"):
            export_clips(spliced, None, out=tmp_path / "bad", split_seed="x", index=index)
    packed_one = export_clips(spliced, names[:1], out=tmp_path / "one.npz", packed=True)  # a packed file, even of one
    assert [p.name for p in packed_one.index_files] == ["one.npz.index.csv"]


def test_indexes_are_named_after_their_whole_output_and_never_meet(sample_db, tmp_path, capsys):
    """a.h5 and a.hdf5, t.npz and t.h5, out.h5 and out.npz: each output's index is its own, and
    no command writes, replaces or removes another output's."""
    from torchsplice.formats.exporters import export_clips
    from torchsplice.job import splice_all

    splice_all(sample_db, tmp_path / "a.h5", locomotions="jog", workers=1)
    first = (tmp_path / "a.h5.index.csv").read_bytes()
    splice_all(sample_db, tmp_path / "a.hdf5", locomotions="walk_curve", workers=1)
    assert (tmp_path / "a.h5.index.csv").read_bytes() == first and (tmp_path / "a.hdf5.index.csv").is_file()
    export_clips(sample_db, out=tmp_path / "t.npz", format="npz", packed=True)
    packed = (tmp_path / "t.npz.index.csv").read_bytes()
    splice_all(sample_db, tmp_path / "t.h5", locomotions="jog", workers=1, index=False)
    splice_all(sample_db, tmp_path / "t.h5", locomotions="jog", workers=1, overwrite=True)
    assert (tmp_path / "t.npz.index.csv").read_bytes() == packed and (tmp_path / "t.h5.index.csv").is_file()
    rc, _, err = run(capsys, "export", tmp_path / "a.h5", "--all", "--packed", "-o", tmp_path / "a.npz", "-q")
    assert rc == 0, err
    assert (tmp_path / "a.npz.index.csv").is_file() and (tmp_path / "a.h5.index.csv").read_bytes() == first


def test_every_job_output_gets_an_index_of_its_clips_metrics_and_splits(sample_db, tmp_path, capsys):
    """``splice-all`` writes ``OUT.h5.index.csv`` beside its output (every clip's cost, flags,
    coverage, labels and split by source clip, as the exports' index and ``info --csv``), and
    so does ``merge`` after sliced runs; ``--no-index`` (``index=False``) writes none."""
    import csv

    from torchsplice.data.splits import table_splits
    from torchsplice.job import splice_all

    out = tmp_path / "sp.h5"
    rc, text, err = run(capsys, "splice-all", sample_db, "-o", out, "--workers", "1", "--method", "splice,naive")
    assert rc == 0, err
    assert "every clip's metrics and split in sp.h5.index.csv" in text
    rows = list(csv.DictReader(open(tmp_path / "sp.h5.index.csv")))
    with MotionDatabase.open(out) as d:
        table = d.clip_table()
        names, cost = list(table.names), [float(c) for c in table.extra["cost"]]
        splits = table_splits(table)
    assert [r["clip"] for r in rows] == names and {r["file"] for r in rows} == {"sp.h5"}
    assert [r["split"] for r in rows] == splits and {"train", "val", "test"} & set(splits)
    assert all((r["cost"] == "") if c != c else abs(float(r["cost"]) - c) <= 1e-9 * max(1.0, c) for r, c in zip(rows, cost))
    assert {"flags", "coverage", "alignment_distance", "locomotion", "action", "method", "labels"} <= set(rows[0])
    rc, _, _ = run(capsys, "info", out, "--csv", tmp_path / "info.csv")
    info = list(csv.DictReader(open(tmp_path / "info.csv")))
    assert rc == 0 and [{k: r["clip" if k == "name" else k] for k in info[0]} for r in rows] == info  # the same values
    splice_all(sample_db, tmp_path / "plain.h5", locomotions="jog", workers=1, index=False)
    assert sorted(p.name for p in tmp_path.glob("plain*")) == ["plain.h5"]
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", out, "--workers", "1", "--locomotions", "jog", "--force",
                     "--no-index", "-q")
    assert rc == 0 and not (tmp_path / "sp.h5.index.csv").exists(), err  # an earlier run's index is not left beside it
    for k in (1, 2):
        assert run(capsys, "splice-all", sample_db, "-o", tmp_path / "sliced.h5", "--locomotions", "jog", "--workers", "1",
                   "--shard", f"{k}/2", "-q")[0] == 0
    assert not (tmp_path / "sliced.h5.index.csv").exists()  # a slice writes no output, so no index
    rc, text, err = run(capsys, "merge", tmp_path / "sliced.h5")
    assert rc == 0 and "sliced.h5.index.csv" in text, err
    merged = list(csv.DictReader(open(tmp_path / "sliced.h5.index.csv")))
    with MotionDatabase.open(tmp_path / "sliced.h5") as d:
        assert [r["clip"] for r in merged] == list(d.names)


def test_a_full_disk_while_writing_the_jobs_index_says_the_output_is_complete(sample_db, tmp_path, capsys, monkeypatch):
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
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", out, "--locomotions", "jog", "--workers", "1", "-q")
    line = error_line(err)
    assert rc != 0 and "sp.h5.index.csv" in line and "no space left" in line.lower() and "sp.h5 itself is complete" in line
    assert out.is_file() and sorted(p.name for p in tmp_path.iterdir()) == ["sp.h5"]  # no temporary left
