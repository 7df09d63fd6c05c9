"""Hostile clip and method names (``adversary_corpus.py``): control characters never reach a
database, a terminal or a report; Markdown and HTML in legal names stay plain text in reports.
Through the Python API (:func:`import_bvh`, :func:`splice_all`, :func:`evaluate_database`,
:func:`export_clips`); the command line where what reaches the terminal is the subject, and for
``info --csv``, a table only the command writes."""

from __future__ import annotations

import re
import warnings
from dataclasses import replace

import shutil

import h5py
import pytest

from adversary_corpus import CONTROL_NAMES, MARKUP_NAMES
from torchsplice import export_clips, import_bvh, splice_all
from torchsplice.cli import main
from torchsplice.evaluation.report import evaluate_database
from torchsplice.core.errors import DatabaseError, TorchspliceError
from torchsplice.core.names import control_character, printable
from torchsplice.formats.bvh import write_bvh
from torchsplice.store.database import MotionDatabase
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec

RAW_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")  # all but \t and \n


def test_printable_escapes_every_control_character_and_keeps_the_rest():
    for name, code in CONTROL_NAMES.items():
        assert control_character(name) == f"control character {code}"
        shown = printable(name)
        assert not RAW_CONTROL.search(shown) and "\n" not in shown and "\t" not in shown, repr(shown)
    assert printable("dataset-1_walk_normal_001 é 走る") == "dataset-1_walk_normal_001 é 走る"
    assert control_character("dataset-1_walk_normal_001 é 走る") is None
    assert printable("x" * 50, limit=10) == "xxxxxxx..."


def _control_named_files(tmp_path):
    """A folder of BVH files: ``good.bvh`` and one named after each of :data:`CONTROL_NAMES`."""
    folder = tmp_path / "bvh"
    folder.mkdir()
    walk = sample_motions()[0]
    write_bvh(walk, folder / "good.bvh")
    for name in CONTROL_NAMES:
        write_bvh(walk, folder / f"{name}.bvh")
    return folder


def test_import_skips_files_named_with_control_characters_saying_why(tmp_path):
    report = import_bvh([_control_named_files(tmp_path)], tmp_path / "db.h5", spec="sample")
    assert len(report.skipped) == len(CONTROL_NAMES) and len(report.imported) == 1
    reasons = [why for _, why in report.skipped]
    assert not any(RAW_CONTROL.search(why) or "\n" in why for why in reasons), reasons
    for code in set(CONTROL_NAMES.values()):
        assert any(f"contains control character {code}; rename the file" in why for why in reasons), code
    with MotionDatabase.open(tmp_path / "db.h5") as db:
        assert db.names == ["good"]


def test_import_skips_files_named_with_control_characters_in_one_clean_line_each(tmp_path, capsys):
    folder = _control_named_files(tmp_path)
    rc = main(["import", str(folder), "-o", str(tmp_path / "db.h5"), "--spec", "sample"])
    cap = capsys.readouterr()
    assert rc == 1
    assert not RAW_CONTROL.search(cap.out + cap.err), repr(cap.err)
    lines = cap.err.splitlines()
    skipped = [line for line in lines if line.startswith("skipped ")]
    assert len(skipped) == len(CONTROL_NAMES), cap.err
    for code in set(CONTROL_NAMES.values()):
        assert any(f"contains control character {code}; rename the file" in line for line in skipped), code
    assert all(line.startswith(("skipped ", f"{len(CONTROL_NAMES)} input(s) skipped")) for line in lines), cap.err
    with MotionDatabase.open(tmp_path / "db.h5") as db:
        assert db.names == ["good"]


@pytest.mark.parametrize("name", list(CONTROL_NAMES))
def test_every_database_writer_refuses_a_name_with_a_control_character(tmp_path, name):
    walk = sample_motions()[0]
    spec = load_spec("sample")
    with MotionDatabase.create(tmp_path / "a.h5") as db:
        with pytest.raises(DatabaseError, match=re.escape(f"contains control character {CONTROL_NAMES[name]}")):
            db.append(replace(walk, name=name), spec=spec)
        with pytest.raises(DatabaseError, match=re.escape(f"contains control character {CONTROL_NAMES[name]}")):
            db.append_packed(walk.skeleton, walk.rotations, walk.root_translation, None, [walk.num_frames], [name],
                             walk.fps, spec=spec)
        db.append(walk, spec=spec)  # the database is still usable
    with MotionDatabase.open(tmp_path / "a.h5") as db:
        assert len(db) == 1


def test_a_database_holding_a_control_name_is_refused_on_open_in_one_line(sample_db, tmp_path, capsys):
    """A file written by another tool: opening it names the clip (escaped) and the character."""
    db = tmp_path / "forged.h5"
    shutil.copy(sample_db, db)
    with h5py.File(db, "r+") as f:
        f["clips/name"][0] = "forged\x1b]0;owned\x07\nwrote everything"
    with pytest.raises(DatabaseError, match=r"row 0\) contains control character U\+001B"):
        MotionDatabase.open(db)
    capsys.readouterr()
    assert main(["info", str(db)]) == 2
    cap = capsys.readouterr()
    assert len(cap.err.splitlines()) == 1 and "U+001B" in cap.err and not RAW_CONTROL.search(cap.out + cap.err)


def test_method_names_must_be_plain_and_a_replaced_method_is_announced():
    from torchsplice.splice.registry import Method, get_method, register_method

    builtin = get_method("naive")
    for bad in ("evil\n", "evil\x1b[2J", "Evil", "", "1abc"):
        with pytest.raises(TorchspliceError, match="must be lower case letters"):
            register_method(replace(builtin, name=bad))
    mine = Method(name="adversary-twin", run=lambda inp: builtin.run(inp), description="a twin")
    register_method(mine)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        register_method(replace(mine, run=lambda inp: builtin.run(inp)), replace_existing=True)
    assert any("'adversary-twin'" in str(w.message) and "replaced" in str(w.message) for w in caught)


@pytest.fixture(scope="module")
def markup_job(tmp_path_factory):
    """The sample with its clips renamed after :data:`MARKUP_NAMES`, spliced (splice, naive)."""
    d = tmp_path_factory.mktemp("markup")
    spec = load_spec("sample")
    clips = sample_motions()
    db, out = d / "db.h5", d / "out.h5"
    with MotionDatabase.create(db) as w:
        for k, m in enumerate(clips):
            name = MARKUP_NAMES[k % len(MARKUP_NAMES)] + ("" if k < len(MARKUP_NAMES) else f" {k}")
            w.append(replace(m, name=name), spec=spec)
    splice_all(db, out, methods="splice,naive")
    return out


def test_markup_in_names_stays_plain_text_in_the_report(markup_job, tmp_path):
    report = tmp_path / "r.md"
    evaluate_database(markup_job, report, pictures=False)
    text = report.read_text()
    for raw in ("<img", "<svg", "<!--", " [link](", "`code`", "**bold**"):
        assert raw not in text, raw
    assert "&lt;img src=x onerror=alert(1)&gt;" in text  # shown, as text
    tables = [b.splitlines() for b in text.split("\n\n") if b.startswith("|")]
    assert len(tables) >= 3
    for rows in tables:  # no name adds a table cell: each row has its header's cells
        want = len(re.findall(r"(?<!\\)\|", rows[0]))
        for row in rows:
            assert len(re.findall(r"(?<!\\)\|", row)) == want, row


FORMULAS = ("=cmd|' /C calc'!A0", "+1+1", "-2+3", "@SUM(1)", "=HYPERLINK(\"http://x\")")


def test_a_name_that_starts_like_a_formula_is_text_in_every_csv(tmp_path, capsys):
    """CSV formula injection: index.csv (job, export, HumanML3D), info --csv and evaluate --csv
    write a cell starting with = + - @ with a leading apostrophe; numbers stay numbers."""
    import csv

    from torchsplice.core.names import spreadsheet_cell
    from torchsplice.formats.index import write_rows_csv

    assert [spreadsheet_cell(v) for v in ("=1", "-x", "\tx", "walk", -0.5, 3)] == ["'=1", "'-x", "'\tx", "walk", -0.5, 3]
    spec = load_spec("sample")
    db, out = tmp_path / "db.h5", tmp_path / "out.h5"
    with MotionDatabase.create(db) as w:
        for k, m in enumerate(sample_motions()):
            w.append(replace(m, name=FORMULAS[k] if k < len(FORMULAS) else m.name), spec=spec)
    splice_all(db, out, methods="naive")
    with MotionDatabase.open(out) as o:  # what `info --csv` writes
        write_rows_csv(tmp_path / "info.csv", o.summary()["clips"])
    evaluate_database(out, tmp_path / "r.md", pictures=False, csv=tmp_path / "ev.csv")
    export_clips(out, out=tmp_path / "h3d", format="humanml3d")
    capsys.readouterr()
    files = [out.with_name("out.h5.index.csv"), tmp_path / "info.csv", tmp_path / "ev.csv", tmp_path / "h3d" / "index.csv"]
    def formula(c):  # what a spreadsheet would evaluate: a formula start that is not a number
        try:
            float(c)
            return False
        except ValueError:
            return c.startswith(("=", "+", "-", "@"))

    for f in files:
        rows = list(csv.reader(open(f)))
        cells = [c for r in rows[1:] for c in r]
        assert not any(formula(c) for c in cells), (f.name, [c for c in cells if formula(c)][:3])
        escaped = [c for c in cells if c[:1] == "'" and c[1:2] in "=+-@"]  # the names are there, kept text
        assert any(any(c[1:].startswith(x) for x in FORMULAS) for c in escaped), (f.name, cells[:8])


def test_report_escaping_known_answers():
    from torchsplice.evaluation.report import md

    assert md("<img src=x onerror=alert(1)>") == "&lt;img src=x onerror=alert(1)&gt;"
    assert md("<!-- hidden") == "&lt;!-- hidden" and md("[link](javascript:x)") == "\\[link\\](javascript:x)"
    assert md("pipe|cell") == "pipe\\|cell"
    assert md("# heading") == "\\# heading" and md("- item") == "\\- item" and md("12. x") == "12\\. x"
    assert md("walk_curve+carry_box") == "walk_curve+carry_box"  # "a_b" is never emphasis
    assert md("_em_") == "\\_em\\_" and md("a\x1bb") == "a\\\\x1bb"


def test_exported_file_names_are_safe_everywhere_and_unique_whatever_the_case(tmp_path):
    from adversary_corpus import FILE_NAMES
    from torchsplice.formats.bvh import read_bvh

    spec = load_spec("sample")
    clips = sample_motions()
    db = tmp_path / "db.h5"
    with MotionDatabase.create(db) as w:  # clip k is sample clip k % 10, so each file can be told apart
        for k, name in enumerate(FILE_NAMES):
            w.append(replace(clips[k % len(clips)], name=name), spec=spec)
    export_clips(db, out=tmp_path / "bvh")
    files = sorted(p.name for p in (tmp_path / "bvh").glob("*.bvh"))  # and the index beside them
    assert len(files) == len(FILE_NAMES) and len({f.casefold() for f in files}) == len(files)
    for f in files:
        stem = f[:-4]
        assert not re.search(r'[<>:"/\\|?*\x00-\x1f]', f) and not stem.endswith((".", " ")), f
        assert stem.split(".")[0].upper() not in {"CON", "PRN", "AUX", "NUL"}, f
    from torchsplice.formats.exporters import clip_filenames

    for k, (name, f) in enumerate(zip(FILE_NAMES, clip_filenames(FILE_NAMES, ".bvh"))):
        got = read_bvh(tmp_path / "bvh" / f)
        assert got.num_frames == clips[k % len(clips)].num_frames, (name, f)
    assert clip_filenames(["dup", "DUP", "Dup"], ".bvh") == ["dup.bvh", "DUP~2.bvh", "Dup~3.bvh"]
    long = clip_filenames(["x" * 300, "x" * 300 + "y"], ".npz")
    assert len(set(long)) == 2 and all(len(f.encode()) <= 200 for f in long)
