"""What the command line says to a newcomer: a file that is not BVH, an output suffix no format
writes, a mistyped command, choice or flag ("did you mean"), the selection language on every
command that takes clips, a wrong spec on a folder, one of anything in the singular, progress
lines for long commands, and what ``info`` shows of Bandai Namco's skeletons as the docs say."""

from __future__ import annotations

import pytest

from cli_helpers import error_line, run
from realdata import BANDAI
from torchsplice.cli import main
from torchsplice.store.database import MotionDatabase


def test_9_a_file_that_is_not_bvh_says_so(tmp_path, capsys):
    md = tmp_path / "README.md"
    md.write_text("# My clips\n\nSome notes.\n")
    rc, _, err = run(capsys, "import", md, "-o", tmp_path / "x.h5")
    assert rc == 2 and "README.md:1: not a BVH file: it starts with '#'" in err and "MOTION section (truncated" not in err
    cut = tmp_path / "cut.bvh"
    cut.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n")
    rc, _, err = run(capsys, "import", cut, "-o", tmp_path / "y.h5")
    assert rc == 2 and "missing MOTION section (truncated file?)" in err


def test_9_an_output_suffix_no_format_writes_names_the_formats(sample_db, tmp_path, capsys):
    rc, _, err = run(capsys, "export", sample_db, "walk_straight", "-o", tmp_path / "walk.fbx")
    line = error_line(err)
    assert rc == 2 and "no export format writes .fbx files" in line and "bvh (.bvh)" in line and "--format" in line
    rc, _, err = run(capsys, "export", sample_db, "walk_straight", "-o", tmp_path / "walk.fbx", "--format", "bvh")
    assert rc == 2 and "the output is BVH, so its name must end in .bvh" in error_line(err)


def test_9_a_mistyped_command_or_choice_gets_did_you_mean(capsys):
    with pytest.raises(SystemExit):
        main(["splce-all", "a.h5", "-o", "b.h5"])
    assert "did you mean 'splice-all'?" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["export", "a.h5", "--all", "-o", "x", "--format", "hmanml3d"])
    assert "did you mean 'humanml3d'?" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["zzz"])
    assert "did you mean" not in capsys.readouterr().err


def test_a_mistyped_flag_gets_did_you_mean_and_its_commands_help(capsys):
    for argv, flag, command in ((["splice-all", "a.h5", "-o", "b.h5", "--wrokers", "2"], "--workers", "splice-all"),
                                (["info", "a.h5", "--jsno"], "--json", "info"),
                                (["export", "a.h5", "--all", "-o", "x", "--pakced"], "--packed", "export")):
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        err = capsys.readouterr().err
        assert exit_.value.code == 2 and len(err.strip().splitlines()) == 1, err
        assert f"did you mean '{flag}'?" in err and f"(see torchsplice {command} --help)" in err, err
    with pytest.raises(SystemExit):
        main(["info", "a.h5", "--zzzzzzzz"])
    err = capsys.readouterr().err
    assert "unrecognized arguments: --zzzzzzzz" in err and "did you mean" not in err


def test_3_export_and_info_take_the_selection_language(sample_db, tmp_path, capsys):
    import json

    spliced = tmp_path / "sp.h5"
    assert main(["splice-all", str(sample_db), "-o", str(spliced), "-q", "--method", "splice,naive"]) == 0
    rc, out, _ = run(capsys, "export", spliced, "role:spliced", "-o", tmp_path / "all")
    assert rc == 0 and len(list((tmp_path / "all").glob("*.bvh"))) == 50
    rc, out, _ = run(capsys, "export", spliced, "--all", "--select", "method:naive", "--select", "action:wave",
                     "-o", tmp_path / "naive_waves")
    names = sorted(f.stem for f in (tmp_path / "naive_waves").glob("*.bvh"))
    assert rc == 0 and len(names) == 5 and all(n.endswith("+wave.naive") for n in names), names
    rc, out, err = run(capsys, "export", spliced, "--select", "method:naive", "--select", "action:wave",
                       "-o", tmp_path / "select_alone")  # --select alone, as retarget and mirror take it
    assert rc == 0 and sorted(f.stem for f in (tmp_path / "select_alone").glob("*.bvh")) == names, err
    rc, _, _ = run(capsys, "export", spliced, "walk_curve+wave", "jog+*", "-o", tmp_path / "mix", "--format", "npz")
    assert rc == 0 and len(list((tmp_path / "mix").glob("*.npz"))) == 1 + 10  # one named, jog's ten by a glob
    rc, _, err = run(capsys, "export", spliced, "nothing*", "-o", tmp_path / "none")
    assert rc == 2 and "'nothing*' selects no clip" in error_line(err) and not (tmp_path / "none").exists()
    rc, out, _ = run(capsys, "info", spliced, "label:action.content=punch", "--json", "--select", "method:splice")
    assert rc == 0 and [c["name"] for c in json.loads(out)["clips"]] == [
        "walk_straight+punch", "walk_curve+punch", "turn_sharp+punch", "sidestep+punch", "jog+punch"]
    rc, out, _ = run(capsys, "info", spliced, "--limit", "3")
    lines = out.splitlines()
    assert rc == 0 and lines[-1] == "... 47 more clips (--limit; select some with CLIP or --select)"
    assert sum(1 for ln in lines if "+" in ln.split()[0]) == 3


def test_3_render_view_and_evaluate_take_the_selection_language_too(sample_db, tmp_path, capsys):
    spliced = tmp_path / "sp.h5"
    assert main(["splice-all", str(sample_db), "-o", str(spliced), "-q"]) == 0
    rc, out, _ = run(capsys, "render", spliced, "walk_curve+*", "jog+wave", "-o", tmp_path / "r.png", "--frames", "2")
    assert rc == 0 and "6 clips" in out  # five by the glob, one by name
    rc, out, _ = run(capsys, "view", spliced, "action:wave", "-o", tmp_path / "v.html")
    assert rc == 0 and "v.html" in out
    rc, out, _ = run(capsys, "evaluate", spliced, "-o", tmp_path / "r.md", "--no-pictures", "--select", "action:wave",
                     "--select", "locomotion:walk_*", "--json", tmp_path / "r.json")
    import json

    assert rc == 0 and sorted(c["name"] for c in json.loads((tmp_path / "r.json").read_text())["clips"]) == [
        "walk_curve+wave", "walk_straight+wave"]
    rc, _, err = run(capsys, "render", spliced, "zz*", "-o", tmp_path / "z.png")
    assert rc == 2 and "'zz*' selects no clip" in error_line(err)


def test_12_files_a_generic_spec_reads_can_be_given_their_units(sample_db, tmp_path, capsys):
    bvh = tmp_path / "bvh"
    assert main(["export", str(sample_db), "walk_straight", "jog", "-o", str(bvh), "-q"]) == 0
    rc, _, err = run(capsys, "import", bvh, "-o", tmp_path / "a.h5", "--spec", "generic", "--units", "m")
    assert rc == 2 and "cannot" in err.lower() and not (tmp_path / "a.h5").exists()
    rc, _, err = run(capsys, "import", bvh, "-o", tmp_path / "b.h5", "--spec", "generic", "--file-units", "cm",
                     "--units", "m", "-q")
    assert rc == 0, err
    with MotionDatabase.open(tmp_path / "b.h5") as d, MotionDatabase.open(sample_db) as s:
        assert d.skeleton_info(0).units == "m"
        a, b = d.read("walk_straight"), s.read("walk_straight")
    assert float((a.global_positions() * 100 - b.global_positions()).abs().max()) < 1e-3
    rc, _, err = run(capsys, "import", bvh, "-o", tmp_path / "c.h5", "--spec", "sample", "--file-units", "m")
    assert rc == 2 and "its spec 'sample' says its units are 'cm', not 'm'" in err
    rc, _, err = run(capsys, "import", bvh, "-o", tmp_path / "d.h5", "--file-units", "furlong")
    assert rc == 2 and "--file-units: unknown length unit 'furlong'" in error_line(err)


def test_a_wrong_spec_on_a_folder_is_said_once_with_the_count_and_the_spec_auto_picks(mocap_dir, tmp_path, capsys):
    folder = tmp_path / "takes"
    folder.mkdir()
    takes = sorted((mocap_dir / BANDAI).glob("*walk*.bvh"))[:6]
    for f in takes:
        (folder / f.name).symlink_to(f)
    rc, _, err = run(capsys, "import", folder, "--spec", "lafan1", "-o", tmp_path / "x.h5")
    lines = [ln for ln in err.splitlines() if ln.startswith("skipped")]
    assert rc == 2 and len(lines) == 1, err
    assert lines[0].startswith(f"skipped {len(takes)} files (") and "--spec auto picks 'bandai_namco' for them" in lines[0]


def test_one_of_anything_is_said_in_the_singular(sample_db, tmp_path, capsys):
    args = ["splice-all", sample_db, "--locomotions", "jog", "--actions", "wave", "--method", "naive", "--workers", "1"]
    rc, out, err = run(capsys, *args, "-o", tmp_path / "one.h5", "--dry-run")
    assert rc == 0 and "1 spliced clip in 1 task" in out, out + err
    rc, out, err = run(capsys, *args, "-o", tmp_path / "one.h5")
    assert rc == 0 and "1 spliced clip in" in out and "1 spliced clips" not in out, out + err
    for argv, words in ((["export", tmp_path / "one.h5", "--all", "--packed", "-o", tmp_path / "one.npz"], "1 clip packed"),
                        (["export", tmp_path / "one.h5", "--all", "-o", tmp_path / "bvh"], "jog+wave.naive, 150 frames"),
                        (["export", tmp_path / "one.h5", "--all", "--format", "humanml3d", "-o", tmp_path / "h"],
                         "1 clip as HumanML3D, 1 motion")):
        rc, out, err = run(capsys, *argv)
        assert rc == 0 and words in out, out + err


def test_long_commands_print_progress_lines_to_a_log(sample_db, tmp_path, capsys, monkeypatch):
    """Not on a terminal (a pipe, a log, capsys here), export and splice-all print progress
    lines (every 30 s; here every update) instead of nothing; --quiet prints none."""
    monkeypatch.setenv("TORCHSPLICE_PROGRESS_SECONDS", "0")
    rc, _, err = run(capsys, "export", sample_db, "--all", "-o", tmp_path / "bvh")
    assert rc == 0 and "export bvh: 10/10 files (100%)" in err, err
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", tmp_path / "s.h5", "--locomotions", "jog", "--workers", "1")
    assert rc == 0 and "splice-all: " in err and "splices (100%)" in err, err
    rc, _, err = run(capsys, "export", sample_db, "--all", "-o", tmp_path / "q", "-q")
    assert rc == 0 and "export bvh" not in err


def test_10_the_docs_say_what_info_shows_of_bandai_namcos_skeletons(bandai_namco_db, capsys):
    """The figures of docs/mixing.md (clips per skeleton and dataset, the Head End Sites' distance)
    are what importing the Bandai Namco clips of ../shared/mocap gives and ``info`` prints."""
    import re

    from realdata import REPO

    said = re.search(r"shows skeleton 0 \((\d+) clips of dataset 1\) and\s+skeleton 1 \((\d+) of dataset 1 and (\d+) "
                     r"of dataset 2\): the same (\d+) joints, their Head End Site (\d+) cm\s+apart",
                     (REPO / "docs" / "mixing.md").read_text())
    assert said, "docs/mixing.md no longer says what info shows of Bandai Namco's skeletons"
    db = bandai_namco_db  # ../shared/mocap's Bandai Namco clips as `torchsplice import FOLDER` makes them
    rc, text, _ = run(capsys, "info", db, "--limit", "0")
    assert rc == 0
    with MotionDatabase.open(db) as d:
        table = d.clip_table()
        count = {}
        for k, labels in zip(table.skeleton, table.labels):
            count[(int(k), labels["dataset"])] = count.get((int(k), labels["dataset"]), 0) + 1
        heads = [sk.end_site_offsets[sk.end_site_parents.index(sk.names.index("Head"))] for sk in d.skeletons]
        joints = {sk.num_joints for sk in d.skeletons}
    zero, one_1, one_2, n_joints, apart = map(int, said.groups())
    assert count == {(0, "1"): zero, (1, "1"): one_1, (1, "2"): one_2} and joints == {n_joints}
    assert round(float((heads[0] - heads[1]).norm())) == apart
    assert f"skeleton 0: {n_joints} joints" in text and f"{zero} clips" in text and f"{one_1 + one_2} clips" in text
