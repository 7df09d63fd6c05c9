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
from torchsplice.core.errors import TorchspliceError
from torchsplice.formats.bvh import read_bvh
from torchsplice.formats.importer import import_bvh
from torchsplice.job.pair import splice_pair
from torchsplice.job.run import splice_all
from torchsplice.splice import SpliceOptions
from torchsplice.store.database import MotionDatabase
from cli_helpers import run
from realdata import BANDAI


@pytest.fixture(scope="module")
def lafan(mocap_dir) -> Path:
    return mocap_dir / "lafan1_via_pypi_bvhtools"


def _windows(take_frames: int, n: int = 600, step: int = 540) -> list[int]:
    """The first frames of the 20 s windows (2 s overlap, 30 fps) of a take of ``take_frames``."""
    expect = list(range(0, take_frames - n + 1, step))
    return expect + ([take_frames - n] if expect[-1] != take_frames - n else [])


def test_window_cuts_long_takes_into_overlapping_windows_equal_to_the_take(lafan, tmp_path):
    out = tmp_path / "w.h5"
    report = import_bvh([lafan / "test.bvh"], out, window=20, window_overlap=2)
    take = read_bvh(lafan / "test.bvh")
    T, n = take.num_frames, 600
    expect = _windows(T, n)
    assert [(c.name, c.windows) for c in report.cut] == [("test", len(expect))]
    assert report.window == 20 and report.clips == len(expect)  # the clips written, not the files
    with MotionDatabase.open(out) as db:
        assert db.names == [f"test#{k:03d}" for k in range(len(expect))]
        for k, s in enumerate(expect):
            w = db.read(f"test#{k:03d}")
            assert w.num_frames == n
            assert w.labels["split_from"] == "test" and int(w.labels["split_frame"]) == s
            assert torch.equal(w.rotations, take.rotations[s:s + n])
            assert torch.equal(w.root_translation, take.root_translation[s:s + n])
    assert expect[-1] + n == T  # the last window ends with the take


def test_short_takes_stay_whole_and_bad_window_arguments_are_refused(mocap_dir, tmp_path):
    walk = sorted((mocap_dir / BANDAI).glob("dataset-1_walk_normal*.bvh"))[0]
    report = import_bvh([walk], tmp_path / "a.h5", window=60)
    assert report.cut == [] and report.clips == 1
    with MotionDatabase.open(tmp_path / "a.h5") as db:
        assert db.names == [walk.stem] and "split_from" not in db.read(walk.stem).labels
    with pytest.raises(TorchspliceError, match="window_overlap"):
        import_bvh([walk], tmp_path / "b.h5", window=5, window_overlap=5)
    assert not (tmp_path / "b.h5").exists()


def test_cli_says_what_the_window_cut_and_names_its_flags(lafan, mocap_dir, tmp_path, capsys):
    rc, text, err = run(capsys, "import", lafan / "test.bvh", "-o", tmp_path / "w.h5", "--window", "20",
                        "--window-overlap", "2")
    assert rc == 0, err
    count = len(_windows(read_bvh(lafan / "test.bvh").num_frames))
    assert f"1 long take cut into {count} windows of 20 s" in text
    assert text.startswith(f"imported {count} clips from 1 file ")  # the clips written, not the files
    walk = sorted((mocap_dir / BANDAI).glob("dataset-1_walk_normal*.bvh"))[0]
    rc, text, _ = run(capsys, "import", walk, "-o", tmp_path / "a.h5", "--window", "60")
    assert rc == 0 and "cut" not in text
    rc, _, err = run(capsys, "import", walk, "-o", tmp_path / "b.h5", "--window", "5", "--window-overlap", "5")
    assert rc == 2 and "--window-overlap" in err
    with pytest.raises(SystemExit) as done:  # "split" is the exports' train/val/test: not listed here
        main(["import", "--help"])
    text = capsys.readouterr().out
    assert done.value.code == 0 and "--window SECONDS" in text and "--split" not in text.replace("--split-ratios", "")


def test_max_length_ratio_skips_pairs_of_very_different_lengths(lafan, tmp_path):
    db = tmp_path / "mixed.h5"
    import_bvh([lafan / "test.bvh"], db)
    import_bvh([lafan / "test2.bvh"], db, append=True, window=20)  # the earlier name
    import_bvh([lafan / "test.bvh"], db, append=True, window=20)
    summary = splice_all(db, tmp_path / "o.h5", locomotions="test,test#000,test2#000", actions="test2#00[1-2]",
                         max_length_ratio=3, force_locomotion=True, workers=1)
    text = "\n".join(summary.lines())
    assert "2 x lengths differ by more than max_length_ratio 3" in text  # 244 s against 20 s
    assert "2 x windows of one take are not spliced onto each other" in text  # test2#000 onto test2#001, #002
    assert summary.spliced == 2
    with MotionDatabase.open(tmp_path / "o.h5") as out:
        assert sorted(out.names) == ["test#000+test2#001", "test#000+test2#002"]
        assert json.loads(out.attrs["run"])["max_length_ratio"] == 3


def test_splicing_two_whole_long_takes_is_flagged_as_a_poor_alignment(lafan, tmp_path):
    """``splice_pair`` (what the ``splice`` command runs on one pair, printing each note) notes the
    poor alignment in its result's ``notes``."""
    db = tmp_path / "takes.h5"
    import_bvh([lafan], db)
    result = splice_pair(db, "test", "test2", options=SpliceOptions(force=True))
    note = [n for n in result.notes if "poor alignment" in n]
    assert len(note) == 1 and "leg lengths, above 0.1" in note[0] and "cut long takes into windows on import" in note[0]
