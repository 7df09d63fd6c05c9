"""The command line on real data and the built-in sample: import, info, export, sample, errors."""

import json

import pytest
import torch

from cli_helpers import run
from realdata import BANDAI_FOLDER as SOME  # the clips of the bandai_folder fixture
from torchsplice.cli import build_parser, main
from torchsplice.formats.bvh import read_bvh


@pytest.mark.parametrize("command", ["sample", "import", "info", "export"])
def test_help_for_every_command(command, capsys):
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args([command, "--help"])
    assert e.value.code == 0
    assert "usage: torchsplice " + command in capsys.readouterr().out


@pytest.mark.parametrize("argv, says", [
    (["splice-all", "db.h5", "-o", "out.h5", "--workers", "0"], "torchsplice splice-all: error: argument --workers"),
    (["splice", "db.h5", "-o", "x.bvh"], "torchsplice splice: error: the following arguments are required"),
    (["nope"], "torchsplice: error: argument COMMAND: invalid choice: 'nope'"),
])
def test_a_usage_mistake_is_one_line_pointing_at_help(argv, says, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and err.startswith(says) and err.rstrip().endswith("--help)")


def test_import_info_export_round_trip(bandai_folder, tmp_path, capsys):
    db = tmp_path / "db.h5"
    code, out, err = run(capsys, "import", bandai_folder, "--spec", "bandai_namco", "-o", db, "-q")
    assert code == 0, err
    code, out, _ = run(capsys, "info", db, "--json")
    assert code == 0
    info = json.loads(out)
    clips = {c["name"]: c for c in info["clips"]}
    assert set(clips) == set(SOME)
    for c in clips.values():
        assert {"name", "frames", "fps", "role", "labels"} <= set(c)
        assert c["fps"] == 30.0
    assert clips["dataset-2_walk_normal_008"]["frames"] == 255
    assert clips["dataset-2_walk_normal_008"]["role"] == "locomotion"
    assert clips["dataset-2_walk-turn-left_elderly_003"]["role"] == "both"
    assert clips["dataset-2_wave-left-hand_normal_001"]["role"] == "action"
    assert clips["dataset-2_walk-turn-left_elderly_003"]["labels"]["style"] == "elderly"
    assert info["units"] == "cm" and info["up_axis"] == "y" and info["quaternion_order"] == "wxyz"

    code, out, _ = run(capsys, "info", db)
    assert code == 0 and "dataset-2_walk_normal_008" in out and "255" in out

    bvh = tmp_path / "walk.bvh"
    code, _, err = run(capsys, "export", db, "dataset-2_walk_normal_008", "-o", bvh)
    assert code == 0, err
    original = read_bvh(bandai_folder / "dataset-2_walk_normal_008.bvh", dtype=torch.float64)
    back = read_bvh(bvh, dtype=torch.float64)
    err_pos = (original.global_positions() - back.global_positions()).abs().max()
    assert err_pos < 1e-4 * original.skeleton.size()


def test_import_auto_spec_and_append(bandai_folder, mocap_dir, tmp_path, capsys):
    db = tmp_path / "db.h5"
    assert run(capsys, "import", bandai_folder, "-o", db, "-q")[0] == 0
    lafan = mocap_dir / "lafan1_via_pypi_bvhtools" / "test2.bvh"
    code, _, err = run(capsys, "import", lafan, "-o", db, "--append", "-q")
    assert code == 0, err
    info = json.loads(run(capsys, "info", db, "--json")[1])
    assert info["num_clips"] == len(SOME) + 1
    assert sorted(k["spec"] for k in info["skeletons"]) == ["bandai_namco", "lafan1"]
    # importing the same clip again is refused for that file, the database is kept
    code, _, err = run(capsys, "import", lafan, "-o", db, "--append", "-q")
    assert code == 2 and "test2" in err and "already" in err
    assert json.loads(run(capsys, "info", db, "--json")[1])["num_clips"] == len(SOME) + 1


def test_bad_file_is_skipped_with_one_line_and_good_files_land(bandai_folder, tmp_path, capsys):
    bad = bandai_folder / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xrotation Yrotation Qrotation\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0 0 0\n")
    db = tmp_path / "db.h5"
    code, out, err = run(capsys, "import", bandai_folder, "-o", db, "-q")
    assert code == 1
    lines = [l for l in err.splitlines() if l.startswith("skipped")]
    assert len(lines) == 1 and "broken.bvh" in lines[0] and "Qrotation" in lines[0]
    assert "Traceback" not in err
    assert json.loads(run(capsys, "info", db, "--json")[1])["num_clips"] == len(SOME)


def test_errors_are_one_line_without_traceback(tmp_path, capsys):
    code, _, err = run(capsys, "info", tmp_path / "missing.h5")
    assert code == 2 and err.count("\n") == 1 and "missing.h5" in err and "Traceback" not in err
    not_db = tmp_path / "x.h5"
    not_db.write_text("hello")
    code, _, err = run(capsys, "info", not_db)
    assert code == 2 and "not an HDF5 file" in err
    code, _, err = run(capsys, "import", tmp_path / "nothing_here", "-o", tmp_path / "o.h5")
    assert code == 2 and "no BVH files" in err and not (tmp_path / "o.h5").exists()


def test_sample_command_and_export_of_a_sample_clip(tmp_path, capsys):
    db = tmp_path / "sample.h5"
    code, out, err = run(capsys, "sample", "-o", db)
    assert code == 0, err
    info = json.loads(run(capsys, "info", db, "--json")[1])
    roles = {c["role"] for c in info["clips"]}
    assert {"locomotion", "action"} <= roles and info["num_clips"] >= 10
    name = info["clips"][0]["name"]
    code, _, err = run(capsys, "export", db, name, "-o", tmp_path / "c.bvh")
    assert code == 0, err
    assert read_bvh(tmp_path / "c.bvh").num_frames == info["clips"][0]["frames"]
    code, _, err = run(capsys, "export", db, "no_such_clip", "-o", tmp_path / "d.bvh")
    assert code == 2 and "no_such_clip" in err
    # an existing output is not overwritten without --force
    code, _, err = run(capsys, "sample", "-o", db)
    assert code == 2 and "already exists" in err


def test_bvh_writers_refuse_other_file_names_and_misspelt_clips_get_a_hint(tmp_path, capsys):
    db = tmp_path / "s.h5"
    assert main(["sample", "-o", str(db), "-q"]) == 0
    code, _, err = run(capsys, "splice", db, "--locomotion", "walk_curve", "--action", "carry_box", "-o", tmp_path / "x.h5")
    assert code == 2 and "must end in .bvh" in err and not (tmp_path / "x.h5").exists()
    code, _, err = run(capsys, "export", db, "walk_curve", "-o", tmp_path / "w.txt")
    assert code == 2 and "no export format writes .txt files" in err and not (tmp_path / "w.txt").exists()
    code, _, err = run(capsys, "splice", db, "--locomotion", "walk_curve", "--action", "carry_bx", "-o", tmp_path / "y.bvh")
    assert code == 2 and "similar: carry_box" in err


def test_unknown_selector_prefix_is_refused(tmp_path, capsys):
    db = tmp_path / "s.h5"
    assert main(["sample", "-o", str(db), "-q"]) == 0
    code, _, err = run(capsys, "splice-all", db, "-o", tmp_path / "o.h5", "--locomotions", "rol:locomotion")
    assert code == 2 and "unknown prefix 'rol'" in err and not (tmp_path / "o.h5").exists()
