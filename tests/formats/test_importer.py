"""The import pipeline as a library function (:func:`torchsplice.formats.importer.import_bvh`), on
real clips: the report (imported clips, skipped files and why, guessed roles), appending, the
same database as ``torchsplice import``, and nothing written when nothing can be imported."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from cli_helpers import run
from realdata import BANDAI
from torchsplice.cli import main
from torchsplice.core.errors import OutputExistsError, TorchspliceError
from torchsplice.store.database import MotionDatabase
from torchsplice.formats.importer import NothingImportedError, import_bvh
from writers import _digest, names

WALKS = ["dataset-2_walk_normal_008", "dataset-2_walk-turn-left_normal_025"]


@pytest.fixture()
def inputs(mocap_dir, tmp_path):
    files = [mocap_dir / BANDAI / f"{n}.bvh" for n in WALKS]
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    return files, bad


def test_report_of_a_mixed_import(inputs, tmp_path):
    files, bad = inputs
    out = tmp_path / "db.h5"
    report = import_bvh([*files, bad, tmp_path / "missing"], out, spec="bandai_namco")
    assert [c.name for c in report.imported] == WALKS and [c.path for c in report.imported] == [str(f) for f in files]
    with MotionDatabase.open(out) as db:
        assert report.clips == len(db) == 2
        assert [c.frames for c in report.imported] == [db.read(n).num_frames for n in WALKS]
        assert report.frames == sum(db.read(n).num_frames for n in WALKS)
    reasons = dict(report.skipped)
    assert set(reasons) == {str(bad), str(tmp_path / "missing")} and not report.ok
    assert reasons[str(tmp_path / "missing")] == "no such file or folder"
    assert reasons[str(bad)].split(":")[0].isdigit()  # LINE: why, from the BVH reader
    assert report.guessed == []  # the spec names every role
    with pytest.raises(OutputExistsError):
        import_bvh(files, out)


def test_guessed_roles_and_append(mocap_dir, inputs, tmp_path):
    files, _ = inputs
    out = tmp_path / "db.h5"
    import_bvh(files[:1], out, spec="bandai_namco")
    cmu = mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh"
    report = import_bvh([cmu], out, spec="generic", append=True)
    assert [c.name for c in report.imported] == ["cmu_12_01_walk"] and report.clips == 2
    (g,) = report.guessed
    assert g.skeleton == 1 and g.path == str(cmu) and g.spec == "generic" and g.summary
    assert g.roles["pelvis"] and g.roles["left_leg"] and g.roles["right_arm"]
    with MotionDatabase.open(out) as db:
        assert db.summary()["skeletons"][1]["guessed_roles"] == g.roles
    with pytest.raises(TorchspliceError, match="no such database to append to"):
        import_bvh([cmu], tmp_path / "none.h5", append=True)


def test_same_database_as_the_command_line(inputs, tmp_path):
    files, bad = inputs
    a, b = tmp_path / "api.h5", tmp_path / "cli.h5"
    import_bvh([*files, bad], a, window=2.0, window_overlap=0.5)
    assert main(["import", *map(str, files), str(bad), "-o", str(b), "--window", "2", "--window-overlap", "0.5", "-q"]) == 1
    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        names = []
        fa.visit(names.append)
        for n in names:
            if isinstance(fa[n], h5py.Dataset):
                assert np.array_equal(fa[n][()], fb[n][()]), n


def test_nothing_imported_writes_nothing(inputs, tmp_path, capsys):
    _, bad = inputs
    out = tmp_path / "db.h5"
    with pytest.raises(NothingImportedError) as e:
        import_bvh([bad], out)
    assert not out.exists() and [p for p, _ in e.value.report.skipped] == [str(bad)]
    assert main(["import", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"skipped {bad}:") and err[1] == f"torchsplice: error: no clip could be imported; {out} was not written"
    with pytest.raises(TorchspliceError, match="unknown length unit 'furlong'"):  # checked before any work
        import_bvh([bad], out, units="furlong")
    assert not out.exists()


def test_units_convert_every_clip(inputs, tmp_path):
    files, _ = inputs
    import_bvh(files[:1], tmp_path / "cm.h5")
    import_bvh(files[:1], tmp_path / "m.h5", units="m")
    with MotionDatabase.open(tmp_path / "cm.h5") as a, MotionDatabase.open(tmp_path / "m.h5") as b:
        assert a.h5.attrs["units"] == "cm" and b.h5.attrs["units"] == "m"
        ma, mb = a.read(WALKS[0]), b.read(WALKS[0])
    np.testing.assert_allclose(mb.global_positions().numpy() * 100, ma.global_positions().numpy(), rtol=1e-5, atol=1e-3)


def test_an_unexpected_failure_on_one_file_skips_only_that_file(bandai_walks, tmp_path, monkeypatch):
    import torchsplice.formats.bvh as bvh

    real = bvh.read_bvh

    def flaky(path, *a, **kw):
        if Path(path).name == bandai_walks[3].name:
            raise RuntimeError("a bug met on this one file")
        return real(path, *a, **kw)

    monkeypatch.setattr(bvh, "read_bvh", flaky)
    out = tmp_path / "db.h5"
    report = import_bvh(bandai_walks, out)
    assert not report.ok and len(report.skipped) == 1
    ((path, why),) = report.skipped
    assert Path(path).name == bandai_walks[3].name and "RuntimeError" in why
    assert len(report.imported) == 9 and len(names(out)) == 9


def test_a_folder_mixing_datasets_imports_every_file_whatever_the_order(mocap_dir, tmp_path):
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    picks = [*sorted((mocap_dir / "cmu_graphics_lab").glob("*.bvh"))[:2],
             sorted((mocap_dir / BANDAI).glob("dataset-1_walk*.bvh"))[0]]
    for order in (picks, picks[::-1]):
        for f in mixed.iterdir():
            f.unlink()
        for n, f in enumerate(order):
            shutil.copy(f, mixed / f"{n}_{f.name}")
        out = tmp_path / "mixed.h5"
        report = import_bvh([mixed], out, overwrite=True)
        assert report.ok, report.skipped
        with MotionDatabase.open(out) as db:
            info = db.summary()
        assert info["num_clips"] == 3
        units = {k["spec"]: k["units"] for k in info["skeletons"]}
        assert len(set(units.values())) == 2 and info["units"] == "mixed", units


def test_import_gives_the_same_bits_with_any_thread_count(bandai_walks, tmp_path):
    import torch

    before = torch.get_num_threads()
    digests = set()
    try:
        for k in (1, 2, 3):
            torch.set_num_threads(k)
            report = import_bvh(bandai_walks[:4], tmp_path / f"i{k}.h5")
            assert len(report.imported) == 4 and not report.skipped
            digests.add(_digest(tmp_path / f"i{k}.h5"))
    finally:
        torch.set_num_threads(before)
    assert len(digests) == 1


def test_import_prints_the_guessed_roles_once_per_skeleton_and_info_shows_them(mocap_dir, tmp_path, capsys):
    """The command line's words for the guessed roles (the roles as data: test_guessed_roles_and_append)."""
    walk = sorted((mocap_dir / "cmu_graphics_lab").glob("*walk*.bvh"))[0]
    copy = tmp_path / "again.bvh"
    shutil.copy(walk, copy)
    out = tmp_path / "g.h5"
    rc, text, err = run(capsys, "import", walk, copy, "-o", out, "--spec", "generic")
    assert rc == 0, err
    assert text.count("joint roles guessed by the 'generic' spec") == 1
    assert "  left leg: LeftUpLeg > LeftLeg > LeftFoot > LeftToeBase" in text
    with MotionDatabase.open(out) as db:
        roles = db.summary()["skeletons"][0]["guessed_roles"]  # what info --json shows
    assert roles["left_leg"] == ["LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase"] and roles["head"] == "Head"
    rc, text, _ = run(capsys, "import", walk, "-o", tmp_path / "s.h5", "--spec", "cmu")
    assert rc == 0 and "joint roles guessed" not in text


def test_import_warns_about_lines_after_the_declared_frames_and_imports_the_clip(bandai_walks, tmp_path):
    f = tmp_path / "keyframes.bvh"
    f.write_text(bandai_walks[0].read_text().rstrip("\n") + "\n1 5 9 13\n")  # as QAvimator writes keyframe indices
    report = import_bvh([f], tmp_path / "k.h5")
    assert report.ok and len(report.warnings) == 1
    ((path, why),) = report.warnings
    assert path == str(f) and "ignored" in why and "\n" not in why
    assert names(tmp_path / "k.h5") == ["keyframes"]
