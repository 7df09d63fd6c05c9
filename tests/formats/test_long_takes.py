"""Long takes: cut into windows on import, pairs restricted by length ratio, poor alignment flagged.

LAFAN1's takes last minutes and mix activities; spliced whole they align poorly and cost time
and memory. ``import --split`` cuts them into overlapping windows, ``splice-all
--max-length-ratio`` skips pairs of very different lengths, and a poor alignment is flagged
with its threshold.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from torchsplice.cli import main
from torchsplice.formats.bvh import read_bvh
from torchsplice.store.database import MotionDatabase
from cli_helpers import run


@pytest.fixture(scope="module")
def lafan(mocap_dir) -> Path:
    return mocap_dir / "lafan1_via_pypi_bvhtools"


def test_window_cuts_long_takes_into_overlapping_windows_equal_to_the_take(lafan, tmp_path, capsys):
    out = tmp_path / "w.h5"
    rc, text, err = run(capsys, "import", lafan / "test.bvh", "-o", out, "--window", "20", "--window-overlap", "2")
    assert rc == 0, err
    take = read_bvh(lafan / "test.bvh")
    T, n, step = take.num_frames, 600, 540
    expect = list(range(0, T - n + 1, step))
    expect += [T - n] if expect[-1] != T - n else []
    assert f"1 long take cut into {len(expect)} windows of 20 s" in text
    assert text.startswith(f"imported {len(expect)} clips from 1 file ")  # the clips written, not the files
    with MotionDatabase.open(out) as db:
        assert db.names == [f"test#{k:03d}" for k in range(len(expect))]
        for k, s in enumerate(expect):
            w = db.read(f"test#{k:03d}")
            assert w.num_frames == n
            assert w.labels["split_from"] == "test" and int(w.labels["split_frame"]) == s
            assert torch.equal(w.rotations, take.rotations[s:s + n])
            assert torch.equal(w.root_translation, take.root_translation[s:s + n])
    assert expect[-1] + n == T  # the last window ends with the take


def test_short_takes_stay_whole_and_bad_window_arguments_are_refused(lafan, mocap_dir, tmp_path, capsys):
    walk = sorted((mocap_dir / "bandai_namco_research_motiondataset").glob("dataset-1_walk_normal*.bvh"))[0]
    rc, text, _ = run(capsys, "import", walk, "-o", tmp_path / "a.h5", "--window", "60")
    assert rc == 0 and "cut" not in text
    with MotionDatabase.open(tmp_path / "a.h5") as db:
        assert db.names == [walk.stem] and "split_from" not in db.read(walk.stem).labels
    rc, _, err = run(capsys, "import", walk, "-o", tmp_path / "b.h5", "--window", "5", "--window-overlap", "5")
    assert rc == 2 and "--window-overlap" in err
    with pytest.raises(SystemExit) as done:  # "split" is the exports' train/val/test: not listed here
        main(["import", "--help"])
    text = capsys.readouterr().out
    assert done.value.code == 0 and "--window SECONDS" in text and "--split" not in text.replace("--split-ratios", "")


def test_max_length_ratio_skips_pairs_of_very_different_lengths(lafan, tmp_path, capsys):
    db = tmp_path / "mixed.h5"
    assert main(["import", str(lafan / "test.bvh"), "-o", str(db), "-q"]) == 0
    assert main(["import", str(lafan / "test2.bvh"), "-o", str(db), "-q", "--append", "--split", "20"]) == 0  # the earlier name
    assert main(["import", str(lafan / "test.bvh"), "-o", str(db), "-q", "--append", "--window", "20"]) == 0
    rc, text, err = run(capsys, "splice-all", db, "-o", tmp_path / "o.h5", "--locomotions", "test,test#000,test2#000",
                        "--actions", "test2#00[1-2]", "--max-length-ratio", "3", "--force-locomotion", "--workers", "1")
    assert rc == 0, err
    assert "2 x lengths differ by more than --max-length-ratio 3" in text  # 244 s against 20 s
    assert "2 x windows of one take are not spliced onto each other" in text  # test2#000 onto test2#001, #002
    with MotionDatabase.open(tmp_path / "o.h5") as out:
        assert sorted(out.names) == ["test#000+test2#001", "test#000+test2#002"]
        assert json.loads(out.attrs["run"])["max_length_ratio"] == 3


def test_splicing_two_whole_long_takes_is_flagged_as_a_poor_alignment(lafan, tmp_path, capsys):
    db = tmp_path / "takes.h5"
    assert main(["import", str(lafan), "-o", str(db), "-q"]) == 0
    rc, _, err = run(capsys, "splice", db, "--locomotion", "test", "--action", "test2", "-o", tmp_path / "x.bvh",
                     "--force-locomotion")
    assert rc == 0
    note = [ln for ln in err.splitlines() if "poor alignment" in ln]
    assert len(note) == 1 and "leg lengths, above 0.1" in note[0] and "import --split" in note[0]
