"""``torchsplice splice`` on the built-in sample database and on imported real clips."""

from __future__ import annotations

import pytest
import torch

from cli_helpers import run, run_any
from torchsplice.cli import build_parser
from torchsplice.core.rotations import quat_angle
from torchsplice.formats.bvh import read_bvh
from torchsplice.store.database import MotionDatabase
from torchsplice.specs import load_spec
from torchsplice.splice import AlignOptions, SpliceOptions, splice

WAVE = "dataset-2_wave-left-hand_normal_001"  # of the bandai_few_db fixture: a wave performed standing in place
WALK = "dataset-2_walk_normal_008"  # and a walk


@pytest.fixture(scope="module")
def clips(sample_db):
    """The database's clips as the command reads them (float32)."""
    with MotionDatabase.open(sample_db) as db:
        return {n: db.read(n) for n in ("walk_straight", "walk_curve", "carry_box", "wave")}


def library(clips, method, reference=None, **opt):
    return splice(clips["walk_curve"], clips["carry_box"], load_spec("sample"), method,
                  None if reference is None else clips[reference], SpliceOptions(**opt))


def assert_bvh_is(path, result):
    """The written BVH holds the library's result: frame count, frame rate and pose."""
    m = read_bvh(path, dtype=torch.float64)
    assert m.num_frames == result.motion.num_frames
    assert m.fps == pytest.approx(result.motion.fps, rel=1e-6)
    want = result.motion.to(torch.float64)
    size = want.skeleton.size()
    assert float((m.global_positions() - want.global_positions()).abs().max()) < 1e-3 * size
    assert float(quat_angle(m.rotations, want.rotations).max()) < 1e-3


@pytest.mark.parametrize("method", ["splice", "naive", "cpmc"])
def test_each_method_writes_a_bvh(sample_db, clips, tmp_path, capsys, method):
    out = tmp_path / f"{method}.bvh"
    code, stdout, err = run(capsys, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box",
                            "--method", method, "-o", out)
    assert code == 0, err
    assert err == ""
    result = library(clips, method, "walk_straight" if method == "cpmc" else None)
    assert_bvh_is(out, result)
    assert f"{method} of carry_box onto walk_curve" in stdout and f"{result.motion.num_frames} frames" in stdout
    if method == "naive":
        assert result.motion.num_frames == min(clips["walk_curve"].num_frames, clips["carry_box"].num_frames)


def test_quiet_prints_nothing(sample_db, tmp_path, capsys):
    code, stdout, err = run(capsys, "splice", sample_db, "--locomotion", "walk_curve", "--action", "wave",
                            "-o", tmp_path / "q.bvh", "-q")
    assert code == 0 and stdout == "" and err == ""
    assert read_bvh(tmp_path / "q.bvh").num_frames > 30


def test_cpmc_reference_automatic_and_overridden(sample_db, clips, tmp_path, capsys):
    auto, named = tmp_path / "auto.bvh", tmp_path / "named.bvh"
    code, stdout, err = run(capsys, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box",
                            "--method", "cpmc", "-o", auto)
    assert code == 0, err
    assert "reference walk_straight" in stdout
    code, stdout, err = run(capsys, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box",
                            "--method", "cpmc", "--reference", "walk_curve", "-o", named)
    assert code == 0, err
    assert "reference walk_curve" in stdout
    assert_bvh_is(auto, library(clips, "cpmc", "walk_straight"))
    assert_bvh_is(named, library(clips, "cpmc", "walk_curve"))
    a, b = read_bvh(auto), read_bvh(named)
    n = min(a.num_frames, b.num_frames)
    assert a.num_frames != b.num_frames or float(quat_angle(a.rotations[:n], b.rotations[:n]).max()) > 1e-3


def test_reference_is_refused_for_other_methods_and_unknown_reference(sample_db, tmp_path, capsys):
    out = tmp_path / "r.bvh"
    code, _, err = run(capsys, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box",
                       "--reference", "walk_straight", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "--reference" in err and not out.exists()
    code, _, err = run(capsys, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box",
                       "--method", "cpmc", "--reference", "no_such_walk", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "no_such_walk" in err and not out.exists()


def test_options_reach_the_library(sample_db, clips, tmp_path, capsys):
    out = tmp_path / "flat.bvh"
    code, stdout, err = run(capsys, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box",
                            "--no-posture", "--max-run", "2", "-o", out)
    assert code == 0, err
    assert "posture rotation 0.0 deg" in stdout
    result = library(clips, "splice", posture=False, align=AlignOptions(max_run=2))
    assert_bvh_is(out, result)
    assert not torch.equal(result.motion.rotations, library(clips, "splice").motion.rotations)


def test_in_place_action_stands_and_in_place_locomotion_is_refused_without_force_locomotion(bandai_few_db, tmp_path,
                                                                                            capsys):
    out = tmp_path / "wave.bvh"
    code, stdout, err = run(capsys, "splice", bandai_few_db, "--locomotion", WAVE, "--action", WALK, "-o", out)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("torchsplice: error: ")
    assert WAVE in err and "does not locomote" in err and "--force-locomotion" in err
    assert "Traceback" not in err and stdout == "" and not out.exists()
    code, stdout, err = run(capsys, "splice", bandai_few_db, "--locomotion", WALK, "--action", WAVE, "-o", out)
    assert code == 0, err
    assert "standing action (loop; acting limbs: left_arm)" in stdout
    from torchsplice.store.database import MotionDatabase

    with MotionDatabase.open(bandai_few_db) as db:
        assert read_bvh(out).num_frames == db.read(WALK).num_frames  # as long as the locomotion
    out.unlink()
    code, stdout, err = run(capsys, "splice", bandai_few_db, "--locomotion", WALK, "--action", WAVE, "-o", out,
                            "--force-locomotion")
    assert code == 0, err
    notes = err.splitlines()
    assert len(notes) == 1 and notes[0].startswith("note: ") and WAVE in notes[0]
    m = read_bvh(out)
    assert m.num_frames > 30 and m.fps == 30.0


def test_unknown_clip_is_one_line(sample_db, tmp_path, capsys):
    out = tmp_path / "u.bvh"
    for which in ("--locomotion", "--action"):
        args = {"--locomotion": "walk_curve", "--action": "carry_box", which: "no_such_clip"}
        code, stdout, err = run(capsys, "splice", sample_db, "--locomotion", args["--locomotion"],
                                "--action", args["--action"], "-o", out)
        assert code == 2 and err.count("\n") == 1 and "no_such_clip" in err and "Traceback" not in err
        assert not out.exists()


def test_existing_output_needs_force(sample_db, tmp_path, capsys):
    out = tmp_path / "exists.bvh"
    out.write_text("keep me")
    argv = ["splice", sample_db, "--locomotion", "walk_curve", "--action", "wave", "-o", out]
    code, _, err = run(capsys, *argv)
    assert code == 2 and err.count("\n") == 1 and "already exists" in err and str(out) in err
    assert out.read_text() == "keep me"
    code, _, err = run(capsys, *argv, "--force", "-q")
    assert code == 0, err
    assert read_bvh(out).num_frames > 30


def test_help(capsys):
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args(["splice", "--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    assert "usage: torchsplice splice" in text
    for opt in ("--locomotion", "--action", "--method", "--reference", "--force-locomotion", "--no-posture", "--max-run"):
        assert opt in text
    with pytest.raises(SystemExit) as e:  # a method that does not exist is a usage error
        build_parser().parse_args(["splice", "db.h5", "--locomotion", "a", "--action", "b", "-o", "x", "--method", "blend"])
    assert e.value.code == 2


@pytest.mark.parametrize("value", ["0", "-2"])
def test_bad_max_run_is_a_usage_error(sample_db, tmp_path, capsys, value):
    out = tmp_path / "m.bvh"
    code, _, err = run_any(capsys, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box",
                           "-o", out, "--max-run", value)
    assert code == 2 and "max" in err and "Traceback" not in err and not out.exists()


def test_unknown_device_is_one_line(sample_db, tmp_path, capsys):
    out = tmp_path / "d.bvh"
    code, _, err = run_any(capsys, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box",
                           "-o", out, "--device", "nonsense")
    assert code == 2 and err.count("\n") == 1 and "nonsense" in err and not out.exists()


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
def test_cuda_device_without_cuda_is_one_line(sample_db, tmp_path, capsys):
    out = tmp_path / "c.bvh"
    code, _, err = run_any(capsys, "splice", sample_db, "--locomotion", "walk_curve", "--action", "carry_box",
                           "-o", out, "--device", "cuda")
    assert code == 2 and err.count("\n") == 1 and "cuda" in err.lower() and not out.exists()
