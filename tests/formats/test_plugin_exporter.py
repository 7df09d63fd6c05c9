"""Export formats are plug-ins: a toy format (tests/helpers/toy_exporter.py, one CSV of root positions
per clip, one module that registers itself) works through the command line (``--plugin``,
``--format toy``) and through the Python API, with nothing else changed in the package; and an
export from Python that fails midway (a format raising on the third clip, a full disk, an
interrupt, a rename failing while the files are installed) leaves no file of it, no temporary,
no folder it made, and every file it would have replaced as it was."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from cli_helpers import error_line, run
from realdata import REPO

INDEX = ["index.csv", "test.txt", "train.txt", "val.txt"]  # beside every export of several clips
from torchsplice.core.errors import OutputExistsError, TorchspliceError  # noqa: E402
from torchsplice.formats.exporters import available_exporters, export_clips, get_exporter  # noqa: E402
from torchsplice.store.database import MotionDatabase  # noqa: E402


def read_csv(path: Path) -> list[list[float]]:
    lines = path.read_text().splitlines()
    assert lines[0] == "frame,x,y,z"
    return [[float(v) for v in ln.split(",")[1:]] for ln in lines[1:]]


def everything(folder: Path) -> list[str]:
    """Every entry under ``folder`` (hidden ones too), relative."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def check_clips(db: Path, folder: Path, names: list[str]) -> None:
    with MotionDatabase.open(db) as d:
        for name in names:
            m = d.read(name, dtype=torch.float64)
            assert read_csv(folder / f"{name}.csv") == m.root_translation.tolist()


@pytest.fixture
def toy():
    import toy_exporter

    return toy_exporter.ToyExporter


def test_the_toy_format_through_the_command_line(sample_db, tmp_path):
    """In a fresh process, as a user runs it: ``--plugin toy_exporter`` adds ``toy`` to ``--format``."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "tests" / "helpers")])}
    out = tmp_path / "csv"

    def cli(*argv):
        return subprocess.run([sys.executable, "-m", "torchsplice", *map(str, argv)], capture_output=True, text=True,
                              env=env, timeout=300)

    p = cli("--plugin", "toy_exporter", "export", sample_db, "--all", "--format", "toy", "-o", out)
    assert p.returncode == 0, p.stderr
    with MotionDatabase.open(sample_db) as d:
        names, frames = d.names, int(d.clip_table().length.sum())
    assert f"{len(names)} clips as root CSV, {frames} frames; index.csv, train/val/test " in p.stdout
    assert sorted(f.name for f in out.iterdir()) == sorted([f"{n}.csv" for n in names] + INDEX)
    check_clips(sample_db, out, names)
    help_text = cli("--plugin", "toy_exporter", "export", "--help").stdout
    assert "{bvh,npz,humanml3d,toy}" in help_text
    env["TORCHSPLICE_PLUGINS"] = "toy_exporter"  # or named in the environment
    assert "{bvh,npz,humanml3d,toy}" in cli("export", "--help").stdout
    del env["TORCHSPLICE_PLUGINS"]
    p = cli("export", sample_db, "--all", "--format", "toy", "-o", tmp_path / "other")  # no plug-in: no such format
    assert p.returncode == 2 and "invalid choice: 'toy'" in p.stderr and not (tmp_path / "other").exists()


def test_a_plug_in_formats_option_is_a_flag(sample_db, tmp_path, capsys):
    """The toy format declares one option (``decimals``, an int): ``--plugin toy_exporter`` makes it
    export's flag ``--decimals N``, listed in ``--help`` after the format's name, read as an int,
    and given to the format, which then writes that many digits; without it, its default."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "tests" / "helpers")])}
    help_text = subprocess.run([sys.executable, "-m", "torchsplice", "--plugin", "toy_exporter", "export", "--help"],
                               capture_output=True, text=True, env=env, timeout=300).stdout
    assert "--decimals N" in help_text and "toy: digits after the point" in " ".join(help_text.split())
    assert "--decimals" not in subprocess.run([sys.executable, "-m", "torchsplice", "export", "--help"],
                                              capture_output=True, text=True, env=env, timeout=300).stdout
    rc, _, err = run(capsys, "--plugin", "toy_exporter", "export", sample_db, "walk_curve", "-o", tmp_path / "w.csv",
                     "--decimals", "2")
    assert rc == 0, err
    rows = (tmp_path / "w.csv").read_text().splitlines()[1:]
    with MotionDatabase.open(sample_db) as d:
        m = d.read("walk_curve", dtype=torch.float64)
    assert rows[0] == "0," + ",".join(f"{v:.2f}" for v in m.root_translation[0].tolist())
    with pytest.raises(SystemExit) as exc:  # a usage mistake: argparse's one line, exit code 2
        run(capsys, "--plugin", "toy_exporter", "export", sample_db, "walk_curve", "-o", tmp_path / "d.csv",
            "--decimals", "two")
    assert exc.value.code == 2 and "--decimals: invalid int value: 'two'" in capsys.readouterr().err
    rc, _, err = run(capsys, "--plugin", "toy_exporter", "export", sample_db, "walk_curve", "-o", tmp_path / "n.npz",
                     "--decimals", "2")  # the option chooses its format (toy): a .npz output is refused in one line
    assert rc == 2 and "must end in .csv" in error_line(err) and not (tmp_path / "n.npz").exists()


def test_the_toy_format_in_process_one_clip_to_a_file(sample_db, tmp_path, capsys):
    rc, out, err = run(capsys, "--plugin", "toy_exporter", "export", sample_db, "walk_curve", "-o", tmp_path / "w.csv")
    assert rc == 0, err
    with MotionDatabase.open(sample_db) as d:
        m = d.read("walk_curve", dtype=torch.float64)
    assert out.strip() == f"wrote {tmp_path / 'w.csv'}: walk_curve, {m.num_frames} frames at {m.fps:g} fps"
    assert read_csv(tmp_path / "w.csv") == m.root_translation.tolist()
    rc, _, err = run(capsys, "--plugin", "toy_exporter", "export", sample_db, "walk_curve", "--packed", "--format", "toy",
                     "-o", tmp_path / "p.csv")
    assert rc == 2 and "--packed needs --format npz" in error_line(err)


def test_the_toy_format_from_python(sample_db, tmp_path, toy):
    assert "toy" in available_exporters() and get_exporter("toy") is toy
    with MotionDatabase.open(sample_db) as d:
        names = d.names
    r = export_clips(sample_db, None, format="toy", out=tmp_path / "all")
    assert r.format == "toy" and r.names == names and [f.name for f in r.files] == [f"{n}.csv" for n in names]
    check_clips(sample_db, tmp_path / "all", names)
    assert everything(tmp_path) == sorted(["all", *(f"all/{n}.csv" for n in names), *(f"all/{i}" for i in INDEX)])
    one = export_clips(sample_db, ["carry_box"], out=tmp_path / "box.csv")  # the format from the suffix
    assert one.format == "toy" and one.files == [tmp_path / "box.csv"]
    with pytest.raises(OutputExistsError):
        export_clips(sample_db, ["carry_box"], out=tmp_path / "box.csv")
    export_clips(sample_db, ["carry_box"], out=tmp_path / "box.csv", overwrite=True)
    with pytest.raises(TorchspliceError, match=r"must end in \.csv"):  # the format named, the suffix another's
        export_clips(sample_db, ["walk_curve"], format="toy", out=tmp_path / "w.txt")
    assert not (tmp_path / "w.txt").exists()
    with pytest.raises(TorchspliceError, match="unknown export format .tox.; choose one of bvh, npz"):
        export_clips(sample_db, None, format="tox", out=tmp_path / "x")
    with pytest.raises(TorchspliceError, match="packed needs format npz"):
        export_clips(sample_db, None, format="toy", out=tmp_path / "x", packed=True)


def test_a_clip_whose_file_would_be_the_index_is_refused_whatever_its_case(tmp_path, toy, capsys):
    """The toy format writes CSV files, so a clip named ``INDEX`` would overwrite ``index.csv`` on
    a case-blind disk: refused before any work, naming the option that gets past it (the
    library's ``index=False``, the command line's ``--no-index``)."""
    from dataclasses import replace

    from torchsplice.sample import sample_motions
    from torchsplice.specs import load_spec

    db = tmp_path / "db.h5"
    walk, box = sample_motions()[:2]
    with MotionDatabase.create(db) as w:
        w.append(replace(walk, name="INDEX"), spec=load_spec("sample"))
        w.append(box, spec=load_spec("sample"))
    with pytest.raises(TorchspliceError, match=r"INDEX\.csv: a clip's file would have the name of the export's index; "
                       r".* without an index \(index=False\)$"):
        export_clips(db, None, format="toy", out=tmp_path / "out")
    rc, _, err = run(capsys, "--plugin", "toy_exporter", "export", db, "--all", "--format", "toy", "-o", tmp_path / "out")
    assert rc == 2 and error_line(err).endswith("without an index (--no-index)") and not (tmp_path / "out").exists()
    r = export_clips(db, None, format="toy", out=tmp_path / "out", index=False)
    assert sorted(f.name for f in r.files) == ["INDEX.csv", f"{box.name}.csv"] and not r.index_files


@pytest.mark.parametrize("failure", ["raises", "disk full", "interrupt"])
@pytest.mark.parametrize("folder_exists", [False, True])
def test_an_export_failing_midway_leaves_nothing(sample_db, tmp_path, toy, monkeypatch, failure, folder_exists):
    out = tmp_path / "out"
    if folder_exists:
        out.mkdir()
    real, calls = toy.write, []

    def third_fails(self, motion, path):
        calls.append(path)
        if len(calls) == 3:
            if failure == "raises":
                raise RuntimeError("the toy format cannot write this clip")
            if failure == "disk full":
                path.write_text("half a fi")
                raise OSError(errno.ENOSPC, "No space left on device")
            raise KeyboardInterrupt
        real(self, motion, path)

    monkeypatch.setattr(toy, "write", third_fails)
    expected = KeyboardInterrupt if failure == "interrupt" else TorchspliceError
    with pytest.raises(expected) as e:
        export_clips(sample_db, None, format="toy", out=out)
    if failure == "raises":
        assert str(e.value).startswith("format 'toy' (toy_exporter) failed writing ")
        assert "RuntimeError: the toy format cannot write this clip; nothing written" in str(e.value)
    elif failure == "disk full":
        assert str(e.value).endswith(": no space left on the device") and "Traceback" not in str(e.value)
    assert len(calls) == 3
    assert everything(tmp_path) == (["out"] if folder_exists else [])  # no file, no temporary, no lock, no folder
    monkeypatch.undo()
    r = export_clips(sample_db, None, format="toy", out=out)  # the same export then runs as it was
    assert len(r.files) + len(r.index_files) == len(list(out.iterdir())) and len(r.index_files) == len(INDEX)


def test_a_rename_failing_while_installing_puts_everything_back(sample_db, tmp_path, toy, monkeypatch):
    """The files are in place but the third rename fails: the two installed are taken back and the
    files they replaced (``overwrite=True``) are put back as they were."""
    out = tmp_path / "out"
    first = export_clips(sample_db, None, format="toy", out=out)
    before = {f.name: f.read_bytes() for f in out.iterdir()}
    with MotionDatabase.open(sample_db) as d:
        names = d.names
    import torchsplice.formats.staging as staging

    real, installs = os.replace, []

    def third_install_fails(src, dst):
        src_name = Path(src).name
        if ".staged-" in src_name and ".old.staged-" not in src_name and ".staged-" not in Path(dst).name:  # installed
            installs.append(dst)
            if len(installs) == 3:
                raise OSError(errno.EIO, "Input/output error")
        return real(src, dst)

    monkeypatch.setattr(staging.os, "replace", third_install_fails)

    def changed(self, motion, path):
        path.write_text("new\n")

    monkeypatch.setattr(toy, "write", changed)
    with pytest.raises(TorchspliceError, match="Input/output error"):
        export_clips(sample_db, list(reversed(names)), format="toy", out=out, overwrite=True)
    monkeypatch.undo()
    assert len(installs) == 3
    assert {f.name: f.read_bytes() for f in out.iterdir()} == before  # every file as it was
    assert everything(tmp_path) == sorted(["out", *(f"out/{f.name}" for f in first.files + first.index_files)])


def test_the_docs_format_snippet_runs(sample_db, tmp_path, monkeypatch):
    """The export format snippet of docs/plugins.md registers a format and exports with it."""
    import re
    import shutil

    page = REPO / "docs" / "plugins.md"
    text = page.read_text()
    start = text.index("**Exports from Python, and other formats.**")
    code = re.search(r"```python\n(.*?)```", text[start:], re.S).group(1)
    shutil.copy(sample_db, tmp_path / "sample.h5")
    monkeypatch.chdir(tmp_path)
    exec(compile(code, str(page), "exec"), {})
    with MotionDatabase.open(sample_db) as d:
        names = d.names
        walk = d.read("walk_curve", dtype=torch.float64)
    assert sorted(f.name for f in (tmp_path / "roots").iterdir()) == sorted([f"{n}.csv" for n in names] + INDEX)
    rows = [[float(v) for v in ln.split(",")] for ln in (tmp_path / "roots" / "walk_curve.csv").read_text().splitlines()]
    assert rows == walk.root_translation.tolist()
