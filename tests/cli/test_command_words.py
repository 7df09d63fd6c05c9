"""What the commands themselves add to the library: their refusals in one line naming their
flags with exit code 2, their notes, and the work a command does around a library call.

The library's behaviour under these commands is tested through the Python API, by subject
(tests/job, tests/ops, tests/data, tests/store, tests/viz); here only the command line's words,
parsing and exit codes, each on the cheapest database that reaches them.
"""

from __future__ import annotations

import pytest

from cli_helpers import error_line, run
from realdata import BANDAI
from torchsplice.cli import main


# ------------------------------------------------------------------------------ refusals
def test_splice_all_refuses_copy_sources_with_a_virtual_layout_naming_its_flags(sample_db, tmp_path, capsys):
    """splice_all(layout="virtual", copy_sources=True): tests/job/test_engines.py."""
    out = tmp_path / "out.h5"
    code, _, err = run(capsys, "splice-all", sample_db, "-o", out, "--method", "splice,naive,cpmc", "--batch-size", "4",
                       "--copy-sources", "-q", "--layout", "virtual")
    assert code == 2 and "--copy-sources needs --layout copy" in err  # a virtual output holds spliced clips only


def test_splice_all_twist_outside_0_to_1_is_a_usage_error(sample_db, tmp_path, capsys):
    """splice_all(twist=1.5): tests/job/test_job_api.py."""
    with pytest.raises(SystemExit):  # the command's parser refuses it in its own words
        main(["splice-all", str(sample_db), "-o", str(tmp_path / "bad.h5"), "--twist", "2"])
    assert "must be a number from 0 to 1" in capsys.readouterr().err


def test_mirror_of_mirrored_clips_is_one_line_with_exit_code_2(sample_db, tmp_path, capsys):
    """mirror_clips of a database holding mirrors: tests/ops/test_mirror.py."""
    from torchsplice.retarget.mirror import mirror_clips

    out = tmp_path / "m.h5"
    mirror_clips(sample_db, out=out)
    rc, _, err = run(capsys, "mirror", out, "--all", "-o", tmp_path / "again.h5")  # the command: one line, exit 2
    assert rc == 2 and ".mirror.mirror' exists" not in err and "exists already" in error_line(err)
    assert not (tmp_path / "again.h5").exists()


def test_export_names_its_shards_flag(sample_db, tmp_path, capsys):
    """export_clips(format="humanml3d", shards=0): tests/data/test_stream.py."""
    rc, _, err = run(capsys, "export", sample_db, "--all", "--format", "humanml3d", "--shards", "0", "-o",
                     tmp_path / "none")  # the command names its flag
    assert rc != 0 and "--shards must be a whole number of at least 1" in err


def test_materialize_of_a_motion_store_names_the_store_flag(sample_db, tmp_path, capsys):
    """materialize of a motion store: tests/store/test_alignment_store.py."""
    # the command says the library's refusal in one line, its option as the flag
    rc, _, err = run(capsys, "materialize", sample_db, "-o", tmp_path / "again.h5")
    assert rc != 0 and "is a motion store already" in error_line(err) and "--store alignment" in err


def test_info_names_the_missing_shards_of_a_virtual_output(sample_db, tmp_path, capsys):
    """MotionDatabase.open of a virtual output whose shards moved: tests/store/test_database_damaged.py."""
    from torchsplice import splice_all

    out = tmp_path / "virtual.h5"
    splice_all(sample_db, out, workers=1, layout="virtual", locomotions="walk_straight", actions="wave",
               methods="naive")
    assert main(["info", str(out)]) == 0
    (tmp_path / "virtual.h5.shards").rename(tmp_path / "elsewhere")
    capsys.readouterr()  # the command says the library's refusal in one line, its exit code 2
    assert main(["info", str(out)]) == 2
    line = capsys.readouterr().err.strip()
    assert "\n" not in line and line.startswith(f"torchsplice: error: {out}: ") and "virtual.h5.shards/" in line
    assert "missing" in line


# ------------------------------------------------------------------------------ what a command adds
def test_plot_alignment_retargets_an_action_of_another_skeleton(mocap_dir, tmp_path):
    """The command retargets the action onto the locomotion's skeleton before drawing the pair
    (``plot_alignment`` itself takes two clips of one skeleton); ``splice_pair`` and the job
    across skeletons: tests/job/test_cross_dataset.py."""
    from torchsplice.formats.importer import import_bvh

    mixed = tmp_path / "mixed.h5"
    import_bvh([mocap_dir / BANDAI / "dataset-2_walk-turn-left_normal_025.bvh",
                mocap_dir / "lafan1_via_pypi_bvhtools" / "test.bvh"], mixed)
    loco = "dataset-2_walk-turn-left_normal_025"
    assert main(["plot-alignment", str(mixed), "--locomotion", loco, "--action", "test", "-o",
                 str(tmp_path / "a.png"), "-q"]) == 0


def test_a_filmstrip_draws_as_many_frames_as_its_longest_panel_an_overlay_too(tmp_path, capsys):
    """The command, not ``render``, bounds ``--frames`` by the longest panel's frames and says so."""
    from torchsplice.sample import sample_motions
    from torchsplice.specs import load_spec
    from torchsplice.store.database import MotionDatabase

    db = tmp_path / "short.h5"
    walk, box = sample_motions()[:2]
    with MotionDatabase.create(db) as w:
        w.append(walk.slice(0, 5), spec=load_spec("sample"))
        w.append(box.slice(0, 12), spec=load_spec("sample"))
    rc, _, err = run(capsys, "render", db, walk.name, "--overlay", box.name, walk.name, "--frames", "8",
                     "-o", tmp_path / "a.png")
    assert rc == 0 and "note" not in err, err  # the overlay's first clip has 12 frames: 8 fit
    rc, _, err = run(capsys, "render", db, walk.name, "--overlay", box.name, "--frames", "20", "-o", tmp_path / "b.png")
    assert rc == 0 and "more than the 12 frames of the longest clip; drawing 12" in err, err


def test_splice_says_it_moved_an_arm_out_of_the_body_and_keeps_it_when_told(runs_with_raised_hands, tmp_path, capsys):
    """splice_pair(keep_hands_out=...): tests/ops/test_hands.py."""
    import numpy as np

    from torchsplice.store.database import MotionDatabase

    db, _, out = runs_with_raised_hands
    with MotionDatabase.open(out) as o:
        e = o.clip_table().extra
        b = int(np.flatnonzero(np.asarray(e["corrected_frames"]) > 0)[0])
        pair = ["--locomotion", str(e["locomotion"][b]), "--action", str(e["action"][b]), "--force"]
    code, _, err = run(capsys, "splice", db, *pair, "-o", tmp_path / "a.bvh")
    assert code == 0 and "the arm was moved out on" in err and "--no-keep-hands-out" in err
    code, _, err = run(capsys, "splice", db, *pair, "-o", tmp_path / "b.bvh", "--no-keep-hands-out")
    assert code == 0 and "moved out" not in err
