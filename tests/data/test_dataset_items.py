"""torchsplice.data: MotionDataset items (whole clips, float64), windows and the rows they read,
clip selection by filters (where), names, globs and numbers, and the errors of filters, features
and windows."""

from __future__ import annotations

import math

import pytest
import torch

from dataset_clips import ALL_FEATURES, spliced_records
from torchsplice.core.errors import DatabaseError
from torchsplice.data import DatasetError, MotionDataset
from torchsplice.store.database import MotionDatabase


# --------------------------------------------------------------------------------------------
# items and windows
# --------------------------------------------------------------------------------------------
def test_whole_clip_items_equal_the_database(plain_db, motions):
    ds = MotionDataset(plain_db, features=("rotations", "root_translation", "translations"))
    assert ds._db is None  # nothing opened until the first read
    assert len(ds) == len(motions) == ds.num_clips
    assert ds.names == [m.name for m in motions]
    with MotionDatabase.open(plain_db) as db:
        for i, m in enumerate(motions):
            item = ds[i]
            ref = db.read(m.name)
            assert set(item) == {"rotations", "root_translation", "translations", "name", "length", "fps",
                                 "index", "start", "skeleton"}
            assert item["name"] == m.name and item["index"] == i and item["start"] == 0 and item["skeleton"] == 0
            assert item["length"] == m.num_frames and item["fps"] == 30.0
            assert item["rotations"].dtype == torch.float32
            assert torch.equal(item["rotations"], ref.rotations)
            assert torch.equal(item["root_translation"], ref.root_translation)
            assert torch.equal(item["translations"], ref.local_translations())
    assert torch.equal(ds[-1]["rotations"], ds[len(ds) - 1]["rotations"])
    with pytest.raises(IndexError):
        ds[len(ds)]


def test_float64_items(plain_db):
    ds = MotionDataset(plain_db, clips=["jog"], dtype=torch.float64, features=("rotations", "positions"))
    with MotionDatabase.open(plain_db) as db:
        ref = db.read("jog", dtype=torch.float64)
    item = ds[0]
    assert item["rotations"].dtype == item["positions"].dtype == torch.float64
    assert torch.equal(item["rotations"], ref.rotations)
    torch.testing.assert_close(item["positions"], ref.global_positions(), rtol=0, atol=1e-9)


@pytest.mark.parametrize("window,stride", [(60, None), (50, 17), (200, 7), (150, 1000)])
def test_windows_cover_the_right_frames(plain_db, motions, window, stride):
    ds = MotionDataset(plain_db, window=window, stride=stride)
    S = stride or window
    lengths = {m.name: m.num_frames for m in motions}
    expected = sorted((n, k * S) for n, T in lengths.items() if T >= window for k in range((T - window) // S + 1))
    assert len(ds) == sum(math.floor((T - window) / S) + 1 for T in lengths.values() if T >= window) == len(expected)
    assert ds.num_too_short == sum(T < window for T in lengths.values())
    assert set(ds.too_short) == {n for n, T in lengths.items() if T < window}
    got = []
    with MotionDatabase.open(plain_db) as db:
        clips = {m.name: db.read(m.name) for m in motions}
        for i in range(len(ds)):
            item = ds[i]
            s = item["start"]
            got.append((item["name"], s))
            assert item["length"] == window and item["rotations"].shape == (window, 22, 4)
            assert item["index"] == db.index(item["name"])
            assert torch.equal(item["rotations"], clips[item["name"]].rotations[s:s + window])
            assert torch.equal(item["root_translation"], clips[item["name"]].root_translation[s:s + window])
    assert sorted(got) == expected


def test_stride_one_window_one_covers_every_frame(two_skeleton_db):
    ds = MotionDataset(two_skeleton_db, window=1, stride=1)
    assert len(ds) == 50 + 30 + 1 + 37 and ds.num_too_short == 0


def test_window_reads_only_its_frames(plain_db):
    """Each item reads exactly its rows (and the one before, for velocities) from the file, and
    only the arrays its features need."""
    for features, ctx, arrays in ((("rotations", "root_translation"), 0, {"rotations", "root_translation"}),
                                  (("velocities",), 1, {"rotations", "root_translation"})):
        ds = MotionDataset(plain_db, clips=["walk_curve"], window=40, stride=30, features=features)
        ds[0]  # opens the file
        db, calls = ds._database(), []
        read = db.frame_rows

        def recorded(k, name, starts, lengths, read=read, calls=calls):
            calls.extend((name, int(s), int(s + n)) for s, n in zip(starts, lengths))
            return read(k, name, starts, lengths)

        db.frame_rows = recorded
        with MotionDatabase.open(plain_db) as other:
            row0 = other.clip_info("walk_curve")["start"]
        item = ds[2]
        assert item["start"] == 60
        assert calls and all(c[1:] == (row0 + 60 - ctx, row0 + 100) for c in calls)
        assert {c[0] for c in calls} <= arrays
        ds.close()


def test_a_window_longer_than_every_clip_is_refused_in_one_line(plain_db, motions):
    longest = max(m.num_frames for m in motions)
    assert len(MotionDataset(plain_db, window=longest)) >= 1  # the longest clip still gives one window
    with pytest.raises(DatasetError, match=f"no selected clip is as long as window={longest + 1} frames .*has {longest}\\)"):
        MotionDataset(plain_db, window=longest + 1)


# --------------------------------------------------------------------------------------------
# filters
# --------------------------------------------------------------------------------------------
def names_where(motions, pred) -> list[str]:
    """Expected names, in row order, from the records the database was built from."""
    return [m.name for m, extra, _ in spliced_records(motions) if pred(m, extra)]


@pytest.mark.parametrize("where,pred", [
    ({"role": "spliced"}, lambda m, e: m.role == "spliced"),
    ({"role": ["locomotion", "action"]}, lambda m, e: m.role in ("locomotion", "action")),
    ({"labels.style": "elderly"}, lambda m, e: m.labels.get("style") == "elderly"),
    ({"labels.style": None, "role": "spliced"}, lambda m, e: m.role == "spliced" and "style" not in m.labels),
    ({"labels.content": ["wave", "punch"], "role": "spliced"},
     lambda m, e: m.role == "spliced" and m.labels["content"] in ("wave", "punch")),
    ({"method": "splice"}, lambda m, e: e.get("method") == "splice"),
    ({"method": "splice", "labels.style": "proud"}, lambda m, e: e.get("method") == "splice" and m.labels.get("style") == "proud"),
    ({"cost": lambda c: c < 5}, lambda m, e: "cost" in e and e["cost"] < 5),  # NaN (unset) fails c < 5
    ({"crop": 2}, lambda m, e: e.get("crop") == 2),
    ({"crop": -1}, lambda m, e: "crop" not in e),  # unset int columns read -1
    ({"locomotion": lambda s: s.startswith("walk")}, lambda m, e: e.get("locomotion", "").startswith("walk")),
    ({"length": lambda n: n < 100}, lambda m, e: m.num_frames < 100),
    ({"fps": 30.0, "name": lambda n: "+" not in n}, lambda m, e: "+" not in m.name),
    ({"labels": lambda d: len(d) == 1}, lambda m, e: len(m.labels) == 1),
])
def test_where_selects_exactly_the_matching_clips(spliced_db, motions, where, pred):
    expected = names_where(motions, pred)
    assert expected  # every case selects something ...
    assert len(expected) < 12  # ... and not everything
    ds = MotionDataset(spliced_db, where=where)
    assert ds.names == expected
    assert [ds[i]["name"] for i in range(len(ds))] == expected
    with MotionDatabase.open(spliced_db) as db:
        assert ds.indices.tolist() == [db.index(n) for n in expected]


def test_clips_by_name_glob_and_number(spliced_db, motions):
    all_names = names_where(motions, lambda m, e: True)
    ds = MotionDataset(spliced_db, clips=["jog+*", "wave", "walk_?urve+punch"])
    assert ds.names == [n for n in all_names if n.startswith("jog+") or n in ("wave", "walk_curve+punch")]
    ds = MotionDataset(spliced_db, clips=["*+wave", 0], where={"method": "splice"})
    assert ds.names == ["walk_straight+wave", "walk_curve+wave", "jog+wave"]  # row 0 is an input clip
    ds = MotionDataset(spliced_db, clips=["jog", "walk_straight", "jog"])  # row order, no duplicates
    assert ds.names == ["walk_straight", "jog"]


def test_filter_errors(spliced_db):
    with pytest.raises(DatasetError, match="no column 'style'.*labels.KEY") as exc:
        MotionDataset(spliced_db, where={"style": "elderly"})
    assert isinstance(exc.value, ValueError) and isinstance(exc.value, DatabaseError)
    assert "cost" in str(exc.value) and "role" in str(exc.value)
    with pytest.raises(DatasetError, match="per-frame"):
        MotionDataset(spliced_db, where={"action_frame": 3})
    with pytest.raises(DatasetError, match="no clip named 'walk'.*similar"):
        MotionDataset(spliced_db, clips=["walk"])
    with pytest.raises(DatasetError, match="pattern"):
        MotionDataset(spliced_db, clips=["run*"])
    with pytest.raises(DatasetError, match="no clip number"):
        MotionDataset(spliced_db, clips=[99])
    with pytest.raises(DatasetError, match="no clip is selected"):
        MotionDataset(spliced_db, where={"role": "spliced", "method": "nonexistent"})
    with pytest.raises(DatabaseError, match="no such file"):
        MotionDataset(spliced_db.parent / "missing.h5")


def test_feature_errors(spliced_db):
    with pytest.raises(ValueError, match="unknown feature 'joint_positions'") as exc:
        MotionDataset(spliced_db, features=("rotations", "joint_positions"))
    for name in (*ALL_FEATURES, "action_frame"):
        assert name in str(exc.value)
    with pytest.raises(ValueError, match="stride needs a window"):
        MotionDataset(spliced_db, stride=3)
    with pytest.raises(ValueError, match="at least 1"):
        MotionDataset(spliced_db, window=0)
    with pytest.raises(ValueError, match="dtype"):
        MotionDataset(spliced_db, dtype=torch.int64)
