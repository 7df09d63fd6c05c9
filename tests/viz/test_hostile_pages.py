"""The viewer and the exports under attack: names and labels that look like HTML or the page
template's placeholders, a database whose name is a placeholder, clips with values that are not
finite, a packed export into a folder, a folder that cannot be made. Through the Python API
(:func:`build_viewer`, :func:`write_viewer`, :func:`export_clips`, :func:`read_clips`,
:func:`evaluate_database`); the command line only where its words are the subject."""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from torchsplice import export_clips, splice_all
from torchsplice.core.errors import DatabaseError, MotionError, TorchspliceError
from torchsplice.evaluation.report import evaluate_database
from torchsplice.store.database import MotionDatabase
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.viz.render import render
from torchsplice.viz.sources import read_clips
from torchsplice.viz.viewer import build_viewer, write_viewer

EVIL = ["</script><script>alert(1)</script>", "a\"b'c", "ünï©ødé ☃ \u2028x", "<img src=x onerror=alert(1)>",
        "__DATA__", "__TITLE__", "__IMPORTMAP__"]


def _db(path: Path, nan_clip: bool = False) -> Path:
    """The sample's clips renamed to EVIL (labels with markup), plus ``nanclip`` with a NaN frame."""
    ms = sample_motions()
    spec = load_spec("sample")
    with MotionDatabase.create(path, overwrite=True) as db:
        for m, n in zip(ms, EVIL):
            db.append(replace(m, name=n, labels={"style": "</script><b>x</b>", "<k>": "&amp;"}), spec=spec)
        if nan_clip:
            db.append(replace(ms[-1], name="nanclip"), spec=spec)
    if nan_clip:
        with h5py.File(path, "a") as f:
            s, n = int(f["clips/start"][len(EVIL)]), int(f["clips/length"][len(EVIL)])
            r = f["skeletons/0/rotations"]
            x = r[s:s + n]
            x[5] = np.nan
            r[s:s + n] = x
    return path


def _data(html: str) -> dict:
    m = re.search(r'<script id="viewer-data" type="application/json">(.*?)</script>', html, re.S)
    return json.loads(m.group(1))


@pytest.mark.parametrize("db_name", ["evil.h5", "__DATA__.h5", "__IMPORTMAP__.h5", "__TITLE__.h5"])
def test_names_and_labels_cannot_break_out_of_the_page(tmp_path, db_name):
    html, contents = build_viewer(_db(tmp_path / db_name))
    template = (Path(__file__).parents[2] / "torchsplice/viz/viewer_template.html").read_text()
    assert html.count("<script") == template.count("<script") and html.count("</script>") == template.count("</script>")
    title = re.search(r"<title>(.*?)</title>", html, re.S).group(1)
    assert title == f"torchsplice view: {db_name}"  # a placeholder in the name stays a name
    data = _data(html)
    assert [c["name"] for c in data["clips"]] == EVIL and data["database"] == db_name
    assert all(c["labels"] == {"style": "</script><b>x</b>", "<k>": "&amp;"} for c in data["clips"])
    assert html.count('<script type="importmap">') == 1 and len(html) < 2 * len(template) + 3_000_000


def test_a_clip_with_values_that_are_not_finite_is_refused_in_one_line(tmp_path):
    db = _db(tmp_path / "nan.h5", nan_clip=True)
    out = tmp_path / "v.html"
    with pytest.raises(MotionError) as exc:
        write_viewer(db, out, quiet=True)
    err = str(exc.value)
    assert not out.exists()
    assert "\n" not in err and "nanclip" in err and "frame 5" in err and str(db) in err, err
    assert write_viewer(db, out, clips=[EVIL[0]], quiet=True).names == [EVIL[0]]  # the other clips still view
    assert out.exists()


def test_feature_statistics_over_a_clip_that_is_not_finite_name_that_clip(tmp_path):
    db = _db(tmp_path / "nan.h5", nan_clip=True)
    for out, options in ((tmp_path / "f", dict(format="npz", features="6d")),
                         (tmp_path / "p.npz", dict(packed=True, features="6d")),
                         (tmp_path / "q.npz", dict(packed=True))):
        with pytest.raises(TorchspliceError) as exc:
            export_clips(db, out=out, **options)
        err = str(exc.value)
        assert "\n" not in err and "'nanclip'" in err and "frame 5" in err, err
    assert not (tmp_path / "f").exists() and not (tmp_path / "p.npz").exists() and not (tmp_path / "q.npz").exists()


def test_packed_export_into_a_folder_is_refused(tmp_path, sample_db):
    for folder, why in ((tmp_path / "folder", "must end in .npz"), (tmp_path / "out.npz", "is a folder")):
        folder.mkdir()
        with pytest.raises(TorchspliceError, match=re.escape(why)):
            export_clips(sample_db, out=folder, packed=True)
        assert list(folder.iterdir()) == []


def test_a_folder_that_cannot_be_made_is_one_line(tmp_path, sample_db, monkeypatch):
    real = Path.mkdir

    def refuse(self, *a, **k):
        if self.name == "clips":
            raise PermissionError(13, "Permission denied", str(self))
        return real(self, *a, **k)

    monkeypatch.setattr(Path, "mkdir", refuse)
    for fmt in ("bvh", "npz", "humanml3d"):
        with pytest.raises(TorchspliceError) as exc:
            export_clips(sample_db, out=tmp_path / "clips", format=fmt)
        err = str(exc.value)
        assert "\n" not in err and "permission denied" in err and "clips" in err, err


@pytest.fixture(scope="module")
def spliced(sample_db, tmp_path_factory):
    d = tmp_path_factory.mktemp("spliced")
    shutil.copy(sample_db, d / "sample.h5")
    splice_all(d / "sample.h5", d / "sp.h5", workers=1, locomotions="walk_curve", actions="carry_box,wave")
    (d / "notes.txt").write_text("not a database")
    return d


@pytest.mark.parametrize("command", ["evaluate", "render"])
def test_sources_that_are_not_databases_are_one_line(spliced, tmp_path, command):
    out = tmp_path / ("r.md" if command == "evaluate" else "r.png")

    def run(sources):
        if command == "evaluate":
            return evaluate_database(spliced / "sp.h5", out, sources=sources, pictures=False)
        clips, spec = read_clips(spliced / "sp.h5", ["walk_curve+carry_box"], sources=sources)
        return render(clips, out, up_axis=spec.up_axis)

    for bad, why in ((spliced / "notes.txt", "not an HDF5 file"), (tmp_path / "nope.h5", "no such file")):
        with pytest.raises(DatabaseError) as exc:
            run([bad])
        err = str(exc.value)
        assert "\n" not in err and why in err and str(bad) in err, err
        assert not out.exists()


def test_evaluate_takes_its_sources(spliced, tmp_path):
    out = tmp_path / "r.md"
    agg = evaluate_database(spliced / "sp.h5", out, sources=[spliced / "sample.h5"], pictures=False)
    assert out.exists() and agg


def test_dataset_statistics_refuse_values_that_are_not_finite_naming_the_clip(tmp_path, spliced):
    from torchsplice.data import MotionDataset

    db = _db(tmp_path / "nan.h5", nan_clip=True)
    with pytest.raises(TorchspliceError, match=r"clip 'nanclip': non-finite value in rotations at frame 5"):
        MotionDataset(db, features=("rotations",)).statistics()
    s = MotionDataset(db, clips=EVIL, features=("rotations",)).statistics()  # the finite clips still do
    assert torch_finite(s["rotations"].mean)
    out = tmp_path / "copied.h5"  # sources copied in: their action_frame is NaN ("not given")
    assert splice_all(spliced / "sample.h5", out, workers=1, copy_sources=True, locomotions="walk_curve",
                      actions="carry_box").spliced > 0
    with pytest.raises(TorchspliceError, match=r"clip 'walk_curve': non-finite value in action_frame"):
        MotionDataset(out).statistics(("action_frame",))
    s = MotionDataset(out, where={"role": "spliced"}).statistics(("action_frame",))
    assert torch_finite(s["action_frame"].mean)


def torch_finite(x) -> bool:
    import torch

    return bool(torch.isfinite(x).all())


@pytest.mark.parametrize("fmt", ["bvh", "npz"])
def test_an_export_of_several_clips_is_all_or_nothing(tmp_path, monkeypatch, fmt):
    """A clip that cannot be written (not finite), or an interrupt half-way, leaves no file of the
    export and no folder: the same call then runs again without overwrite."""
    db = _db(tmp_path / "nan.h5", nan_clip=True)
    out = tmp_path / "clips"
    with pytest.raises(TorchspliceError, match="'nanclip'"):
        export_clips(db, out=out, format=fmt)
    assert not out.exists()
    import torchsplice.formats.bvh as bvh
    import torchsplice.formats.npz as npz

    calls = []
    real = bvh.format_bvh if fmt == "bvh" else npz.write_npz  # what each format's exporter calls per clip

    def interrupted(*a, **k):
        calls.append(1)
        if len(calls) % 3 == 0:  # the third file of each run
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(bvh if fmt == "bvh" else npz, "format_bvh" if fmt == "bvh" else "write_npz", interrupted)
    with pytest.raises(KeyboardInterrupt):
        export_clips(db, EVIL, out=out, format=fmt)
    assert not out.exists()
    out.mkdir()
    with pytest.raises(KeyboardInterrupt):
        export_clips(db, EVIL, out=out, format=fmt)
    assert list(out.iterdir()) == []  # an existing folder stays, empty
    monkeypatch.undo()
    export_clips(db, EVIL, out=out, format=fmt)
    assert len(list(out.glob(f"*.{fmt}"))) == len(EVIL)  # and the index beside them


def test_read_npz_of_files_that_are_not_exports_is_one_line(tmp_path):
    from torchsplice.core.errors import TorchspliceError
    from torchsplice.formats.npz import read_npz

    np.savez(tmp_path / "pickled.npz", a=np.array([{"x": 1}], dtype=object))
    np.save(tmp_path / "array.npy", np.zeros(3))
    (tmp_path / "text.npz").write_text("not a zip")
    for name, why in (("pickled.npz", "not a torchsplice .npz export"), ("array.npy", "not a torchsplice .npz export"),
                      ("text.npz", "not a torchsplice .npz export"), ("missing.npz", "no such file")):
        with pytest.raises(TorchspliceError, match=why):
            read_npz(tmp_path / name)


def _damaged_source(sample_db: Path, tmp_path: Path) -> tuple[Path, Path]:
    """A spliced output whose run record names a source database damaged since: (source, output)."""
    db, out = tmp_path / "sample.h5", tmp_path / "out.h5"
    shutil.copy(sample_db, db)
    splice_all(db, out, locomotions="walk_curve", actions="carry_box", workers=1)
    db.write_bytes(b"not a database any more")
    return db, out


def test_a_damaged_recorded_source_is_skipped_with_one_warning(sample_db, tmp_path):
    """The run record names the job's input; damaged since, it is skipped with one warning (the
    spliced clips still render and view), and only a clip that needed it is refused."""
    db, out = _damaged_source(sample_db, tmp_path)
    with pytest.warns(UserWarning) as caught:
        clips, spec = read_clips(out, ["walk_curve+carry_box"])
    lines = [str(w.message) for w in caught]
    assert len(lines) == 1 and "\n" not in lines[0] and str(db) in lines[0], lines
    render(clips, tmp_path / "x.png", up_axis=spec.up_axis)
    assert (tmp_path / "x.png").exists()
    with pytest.warns(UserWarning, match=re.escape(str(db))):
        write_viewer(out, tmp_path / "v.html", quiet=True)
    assert (tmp_path / "v.html").exists()
    with pytest.warns(UserWarning), pytest.raises(DatabaseError, match="walk_curve") as exc:
        read_clips(out, ["walk_curve"])
    assert "\n" not in str(exc.value)
    with pytest.raises(DatabaseError):  # named explicitly: refused
        read_clips(out, ["walk_curve+carry_box"], sources=[db])


def test_the_warning_of_a_damaged_source_is_one_line_of_the_command(sample_db, tmp_path, capsys):
    """On the command line that warning is one ``torchsplice: warning:`` line naming the file."""
    from cli_helpers import run

    db, out = _damaged_source(sample_db, tmp_path)
    rc, _, err = run(capsys, "render", out, "walk_curve+carry_box", "-o", tmp_path / "x.png", "-q")
    lines = err.strip().splitlines()
    assert rc == 0 and len(lines) == 1 and lines[0].startswith("torchsplice: warning:") and str(db) in lines[0], err
