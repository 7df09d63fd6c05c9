"""torchsplice.data: MotionDataset items, windows, filters, derived features, collation, workers."""

from __future__ import annotations

import math
import pickle
import shutil

import h5py
import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from torchsplice import export_clips, splice_all
from torchsplice.core.errors import DatabaseError, TorchspliceError
from torchsplice.core.motion import Motion
from torchsplice.core.skeleton import Skeleton
from torchsplice.data import DatasetError, MotionDataset, collate_motion
from torchsplice.store.database import MotionDatabase
from torchsplice.sample import sample_motions
from torchsplice.core.fk import forward_kinematics

ALL_FEATURES = ("rotations", "root_translation", "translations", "positions", "global_rotations", "velocities")
SPLICED_COLUMNS = {"locomotion": "str", "action": "str", "method": "str", "cost": "float", "crop": "int"}


# --------------------------------------------------------------------------------------------
# databases
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def motions() -> list[Motion]:
    return sample_motions()


@pytest.fixture(scope="module")
def plain_db(tmp_path_factory, motions):
    """The ten sample clips; small chunks so that windows straddle chunk boundaries."""
    path = tmp_path_factory.mktemp("plain") / "sample.h5"
    with MotionDatabase.create(path, chunk_frames=64) as db:
        for m in motions:
            db.append(m)
    return path


def spliced_records(motions):
    """(motion, extra, frame_extra) of a database shaped like the splice job's output.

    Three input clips (role locomotion/action) and 3 x 3 spliced clips with extra columns and
    a per-frame ``action_frame``; one spliced clip is cut to 40 frames.
    """
    by = {m.name: m for m in motions}
    records = []
    for name in ("walk_straight", "jog", "wave"):
        records.append((by[name], {}, {}))
    styles = {"walk_straight": "elderly", "walk_curve": "proud"}  # jog carries no style label
    for i, loco in enumerate(("walk_straight", "walk_curve", "jog")):
        for j, act in enumerate(("wave", "punch", "carry_box")):
            lm, am = by[loco], by[act]
            T = min(lm.num_frames, am.num_frames)
            if (i, j) == (2, 2):
                T = 40
            rot = lm.rotations[:T].clone()
            rot[:, 11:] = am.rotations[:T, 11:]  # some upper body from the action
            labels = {"content": act}
            if loco in styles:
                labels["style"] = styles[loco]
            m = Motion(lm.skeleton, rot, lm.root_translation[:T].clone(), 30.0, name=f"{loco}+{act}",
                       source="splice", role="spliced", labels=labels)
            extra = {"locomotion": loco, "action": act, "method": "splice" if j < 2 else "naive",
                     "cost": float(i * 3 + j), "crop": j}
            frames = {"action_frame": np.arange(T, dtype=np.float32) * 0.5 + i}
            records.append((m, extra, frames))
    return records


@pytest.fixture(scope="module")
def spliced_db(tmp_path_factory, motions):
    path = tmp_path_factory.mktemp("spliced") / "spliced.h5"
    with MotionDatabase.create(path, chunk_frames=128, columns=SPLICED_COLUMNS, frame_columns=("action_frame",)) as db:
        for m, extra, frames in spliced_records(motions):
            db.append(m, extra=extra, frame_extra=frames)
    return path


CH6 = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
CH3 = ("Zrotation", "Xrotation", "Yrotation")


def animated_skeleton() -> Skeleton:
    """Five joints, one non-root joint with animated translation (stored ``translations``)."""
    return Skeleton(
        names=["Pelvis", "Spine", "Head", "LLeg", "RLeg"], parents=[-1, 0, 1, 0, 0],
        offsets=[[0, 90, 0], [0, 10, 0], [0, 50, 0], [10, -5, 0], [-10, -5, 0]],
        channels=[CH6, CH6, CH3, CH3, CH3],
    )


def chain_skeleton() -> Skeleton:
    return Skeleton(names=["A", "B", "C"], parents=[-1, 0, 1], offsets=[[0, 0, 0], [0, 1, 0], [0, 1, 0.5]],
                    channels=[CH6, CH3, CH3])


def random_clip(sk: Skeleton, T: int, name: str, seed: int) -> Motion:
    g = torch.Generator().manual_seed(seed)
    J = sk.num_joints
    rot = torch.nn.functional.normalize(torch.randn(T, J, 4, generator=g), dim=-1)
    root = torch.randn(T, 3, generator=g) * 10
    trans = None
    if sk.has_joint_translations:
        trans = sk.offsets.float().expand(T, J, 3).clone()
        trans[:, 1] += torch.randn(T, 3, generator=g)
        trans[:, 0] = root
    return Motion(sk, rot, root, 24.0, trans, name=name, role="locomotion")


@pytest.fixture(scope="module")
def two_skeleton_db(tmp_path_factory):
    """Clips on two skeletons; skeleton 0 animates a non-root translation."""
    path = tmp_path_factory.mktemp("two") / "two.h5"
    with MotionDatabase.create(path, chunk_frames=16) as db:
        db.append(random_clip(animated_skeleton(), 50, "anim_a", 1))
        db.append(random_clip(chain_skeleton(), 30, "chain_a", 2))
        db.append(random_clip(animated_skeleton(), 1, "anim_one_frame", 3))
        db.append(random_clip(animated_skeleton(), 37, "anim_b", 4))
    return path


def velocities_of(pos: torch.Tensor, fps: float) -> torch.Tensor:
    """Reference finite differences, written out frame by frame."""
    v = torch.zeros_like(pos)
    for t in range(1, pos.shape[0]):
        v[t] = (pos[t] - pos[t - 1]) * fps
    if pos.shape[0] > 1:
        v[0] = v[1]
    return v


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
    """Each item reads exactly its rows (and the one before, for velocities) from the file."""

    class Recorder:
        def __init__(self, ds):
            self.ds, self.calls = ds, []

        def __getitem__(self, key):
            self.calls.append((key.start, key.stop))
            return self.ds[key]

        def gather(self, starts, lengths):  # the rows of several ranges (one read each, or their span)
            self.calls += [(int(s), int(s + n)) for s, n in zip(starts, lengths)]
            return self.ds.gather(starts, lengths)

    for features, ctx in ((("rotations", "root_translation"), 0), (("velocities",), 1)):
        ds = MotionDataset(plain_db, clips=["walk_curve"], window=40, stride=30, features=features)
        ds[0]  # opens the file and the datasets
        for key in list(ds._datasets):
            ds._datasets[key] = Recorder(ds._datasets[key])
        with MotionDatabase.open(plain_db) as db:
            row0 = db.clip_info("walk_curve")["start"]
        item = ds[2]
        assert item["start"] == 60
        calls = [c for r in ds._datasets.values() for c in r.calls]
        assert calls and all(c == (row0 + 60 - ctx, row0 + 100) for c in calls)
        ds.close()


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


# --------------------------------------------------------------------------------------------
# features
# --------------------------------------------------------------------------------------------
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


def test_positions_and_global_rotations_are_forward_kinematics(plain_db, motions):
    ds = MotionDataset(plain_db, window=45, stride=40, features=("positions", "global_rotations"))
    with MotionDatabase.open(plain_db) as db:
        full = {}
        for m in motions:
            r = db.read(m.name)
            full[m.name] = (r.global_positions(), forward_kinematics(r.rotations, r.root_translation,
                                                                      r.skeleton.offsets.float(), r.skeleton.parents)[1])
    for i in range(0, len(ds), 3):
        item = ds[i]
        s = item["start"]
        pos, grot = full[item["name"]]
        assert item["positions"].shape == (45, 22, 3) and item["global_rotations"].shape == (45, 22, 4)
        torch.testing.assert_close(item["positions"], pos[s:s + 45], rtol=0, atol=1e-4)
        torch.testing.assert_close(item["global_rotations"], grot[s:s + 45], rtol=0, atol=1e-6)
    assert "rotations" not in ds[0]


def test_features_with_animated_translations(two_skeleton_db):
    ds = MotionDataset(two_skeleton_db, where={"skeleton": 0}, features=("translations", "positions", "velocities"))
    assert ds.names == ["anim_a", "anim_one_frame", "anim_b"]
    with MotionDatabase.open(two_skeleton_db) as db:
        for i in range(len(ds)):
            item = ds[i]
            ref = db.read(item["name"])
            assert ref.translations is not None
            assert torch.equal(item["translations"], ref.local_translations())
            assert not torch.equal(item["translations"][:, 1], ref.skeleton.offsets[1].float().expand(item["length"], 3))
            torch.testing.assert_close(item["positions"], ref.global_positions(), rtol=0, atol=1e-5)
            torch.testing.assert_close(item["velocities"], velocities_of(ref.global_positions(), 24.0), rtol=0, atol=1e-3)
    assert torch.equal(ds[1]["velocities"], torch.zeros(1, 5, 3))  # one frame: no motion to measure


def test_translations_are_offsets_where_not_animated(plain_db):
    item = MotionDataset(plain_db, clips=["wave"], features=("translations", "root_translation"))[0]
    sk = MotionDataset(plain_db, clips=["wave"]).skeleton
    assert torch.equal(item["translations"][:, 0], item["root_translation"])
    assert torch.equal(item["translations"][:, 1:], sk.offsets[1:].float().expand(item["length"], -1, -1))


def test_velocities_are_finite_differences(plain_db, motions):
    whole = MotionDataset(plain_db, features=("velocities", "positions"))
    windows = MotionDataset(plain_db, window=30, stride=25, features=("velocities",))
    clip_vel = {}
    for i in range(len(whole)):
        item = whole[i]
        v, p = item["velocities"], item["positions"].double()
        ref = velocities_of(p, item["fps"])
        torch.testing.assert_close(v.double(), ref, rtol=1e-5, atol=1e-3)
        assert torch.equal(v[0], v[1])
        clip_vel[item["name"]] = v
    for i in range(len(windows)):
        item = windows[i]
        s = item["start"]
        # a window inside a clip uses the frame before it: its velocities are the clip's
        torch.testing.assert_close(item["velocities"], clip_vel[item["name"]][s:s + 30], rtol=0, atol=1e-4)


def test_per_frame_column_feature(spliced_db):
    ds = MotionDataset(spliced_db, where={"role": "spliced"}, window=32, stride=50, features=("action_frame", "rotations"))
    with MotionDatabase.open(spliced_db) as db:
        for i in range(len(ds)):
            item = ds[i]
            s = item["start"]
            col = torch.from_numpy(db.read_frame_column(item["name"], "action_frame"))
            assert item["action_frame"].shape == (32,)
            assert torch.equal(item["action_frame"], col[s:s + 32])
            assert torch.equal(item["action_frame"], torch.arange(s, s + 32) * 0.5 + item["action_frame"][0] - s * 0.5)
    inputs = MotionDataset(spliced_db, where={"role": "locomotion"}, features=("action_frame",))
    assert torch.isnan(inputs[0]["action_frame"]).all()  # not given for input clips


# --------------------------------------------------------------------------------------------
# collation
# --------------------------------------------------------------------------------------------
def test_collate_pads_by_repeating_the_last_frame(spliced_db):
    ds = MotionDataset(spliced_db, where={"locomotion": "jog"}, features=("rotations", "positions", "action_frame"))
    items = [ds[i] for i in range(len(ds))]
    lengths = [it["length"] for it in items]
    assert len(set(lengths)) > 1 and 40 in lengths
    batch = collate_motion(items)
    B, T = len(items), max(lengths)
    assert batch["rotations"].shape == (B, T, 22, 4) and batch["positions"].shape == (B, T, 22, 3)
    assert batch["action_frame"].shape == (B, T)
    assert batch["lengths"].dtype == torch.int64 and batch["lengths"].tolist() == lengths
    assert batch["mask"].dtype == torch.bool and batch["mask"].shape == (B, T)
    assert batch["fps"].dtype == torch.float64 and batch["fps"].tolist() == [30.0] * B
    assert batch["name"] == [it["name"] for it in items]
    assert batch["index"] == [it["index"] for it in items] and batch["start"] == [0] * B
    for b, it in enumerate(items):
        n = it["length"]
        assert batch["mask"][b].tolist() == [True] * n + [False] * (T - n)
        for key in ("rotations", "positions", "action_frame"):
            assert torch.equal(batch[key][b, :n], it[key])
            assert torch.equal(batch[key][b, n:], it[key][-1:].expand(T - n, *it[key].shape[1:]))
    assert "length" not in batch


def test_collate_refuses_mixed_skeletons(two_skeleton_db):
    ds = MotionDataset(two_skeleton_db)
    assert [ds[i]["skeleton"] for i in range(4)] == [0, 1, 0, 0]
    with pytest.raises(ValueError, match="clips on skeletons of other joints"):
        collate_motion([ds[0], ds[1]])
    with pytest.raises(DatasetError, match="skeletons"):
        ds.skeleton  # noqa: B018
    assert MotionDataset(two_skeleton_db, where={"skeleton": 1}).skeleton.names == ("A", "B", "C")


# --------------------------------------------------------------------------------------------
# workers, pickling, preloading
# --------------------------------------------------------------------------------------------
def test_dataloader_with_workers_yields_every_window_once(spliced_db):
    ds = MotionDataset(spliced_db, where={"role": "spliced"}, window=48, stride=20,
                       features=("rotations", "positions", "action_frame"))
    reference = {(ds[i]["name"], ds[i]["start"]): ds[i] for i in range(len(ds))}  # the parent has the file open
    assert len(reference) == len(ds) and ds._db is not None
    loader = DataLoader(ds, batch_size=7, shuffle=True, collate_fn=collate_motion, num_workers=2,
                        generator=torch.Generator().manual_seed(0))
    seen = []
    for batch in loader:
        assert batch["rotations"].shape[1:] == (48, 22, 4) and bool(batch["mask"].all())
        for b, (name, start) in enumerate(zip(batch["name"], batch["start"])):
            seen.append((name, start))
            ref = reference[(name, start)]
            for key in ("rotations", "positions", "action_frame"):
                assert torch.equal(batch[key][b], ref[key])
    assert sorted(seen) == sorted(reference)
    assert len(seen) == len(set(seen)) == len(ds)
    assert [n for n, _ in seen] != [n for n, _ in sorted(seen)]  # shuffled


def test_pickle_drops_the_file_handle(plain_db):
    ds = MotionDataset(plain_db, window=60, features=("rotations", "velocities"))
    first = ds[3]
    assert ds._db is not None
    clone = pickle.loads(pickle.dumps(ds))
    assert clone._db is None and clone._datasets == {}
    again = clone[3]
    assert again["name"] == first["name"] and torch.equal(again["velocities"], first["velocities"])
    ds.close()
    assert ds._db is None and torch.equal(ds[3]["rotations"], first["rotations"])  # reopens


def assert_same_item(got: dict, want: dict, i: int) -> None:
    """Item ``got`` holds exactly ``want``'s keys and values (tensors bit for bit, NaN equal to NaN)."""
    assert got.keys() == want.keys()
    for key, value in want.items():
        if isinstance(value, torch.Tensor):
            torch.testing.assert_close(got[key], value, rtol=0, atol=0, equal_nan=True, msg=f"{key} of item {i}")
        else:
            assert got[key] == value


def test_preload_gives_identical_items(spliced_db, two_skeleton_db):
    for path, kwargs in ((spliced_db, dict(where={"cost": lambda c: c < 8 or c != c}, window=40, stride=33,
                                            features=(*ALL_FEATURES, "action_frame"))),
                         (two_skeleton_db, dict(features=ALL_FEATURES))):
        lazy = MotionDataset(path, **kwargs)
        pre = MotionDataset(path, preload=True, **kwargs)
        assert pre._db is None and len(pre) == len(lazy) > 0
        for i in range(len(lazy)):
            assert_same_item(pre[i], lazy[i], i)
        assert pre._db is None  # never touched the file again
        item = pre[0]
        item["rotations"].zero_()  # items do not alias the preloaded memory
        assert not torch.equal(pre[0]["rotations"], item["rotations"])


def test_batched_fetch_equals_single_items(spliced_db, two_skeleton_db):
    """``__getitems__`` (what DataLoader calls) gives exactly ``[ds[i] for i in indices]``."""
    cases = ((spliced_db, dict(window=25, stride=40, features=(*ALL_FEATURES, "action_frame"))),
             (two_skeleton_db, dict(features=ALL_FEATURES)),  # two skeletons, a one-frame clip
             (two_skeleton_db, dict(window=1, stride=9, features=("velocities", "positions"))))
    for path, kwargs in cases:
        ds = MotionDataset(path, **kwargs)
        order = torch.randperm(len(ds), generator=torch.Generator().manual_seed(1)).tolist()
        batch = ds.__getitems__(order)
        assert len(batch) == len(order)
        for i, b in zip(order, batch):
            assert_same_item(b, ds[i], i)


DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.gpu)]
READ_AS_STORED = {"rotations", "root_translation", "translations", "action_frame", "lengths", "mask"}


@pytest.mark.parametrize("device", DEVICES)
def test_a_dataset_assembling_on_a_device_gives_the_batches_it_gives_here(spliced_db, two_skeleton_db, device):
    """``MotionDataset(assemble_on=device)`` through a ``DataLoader`` (one skeleton per batch):
    every tensor of each batch on ``device``, and the batch of the same items collated as usual
    from ``__getitems__``: the frames as stored (NaN where stored), the mask and lengths bit for
    bit; the derived features (forward kinematics, trajectory, velocities, 6D rotations) within
    1e-5 of their scale (float32 computed on the device), 3e-4 for velocities (differences of
    positions times the rate)."""
    from torchsplice.data import collate_motion

    cases = ((spliced_db, dict(window=25, stride=40, features=(*ALL_FEATURES, "rotations_6d", "action_frame"))),
             (spliced_db, dict(features=("rotations", "positions", "velocities", "trajectory"))),
             (two_skeleton_db, dict(features=ALL_FEATURES)))  # two skeletons, a one-frame clip
    for path, kwargs in cases:
        ds, plain = MotionDataset(path, assemble_on=device, **kwargs), MotionDataset(path, **kwargs)
        batches = list(ds.batch_sampler(5))
        loader = DataLoader(ds, batch_sampler=batches, collate_fn=ds.collate)
        n = 0
        for indices, got in zip(batches, loader):
            want = collate_motion(plain.__getitems__(indices))
            assert got.keys() == want.keys()
            for key, w in want.items():
                g = got[key]
                if not isinstance(w, torch.Tensor):
                    assert g == w, key
                elif key == "fps":
                    assert torch.equal(g, w)
                elif key in READ_AS_STORED:
                    assert g.device.type == device, (path.name, key)
                    torch.testing.assert_close(g.cpu(), w, rtol=0, atol=0, equal_nan=True, msg=f"{path.name}: {key}")
                else:
                    assert g.device.type == device and g.dtype == w.dtype and g.shape == w.shape, (path.name, key)
                    assert torch.equal(g.isnan().cpu(), w.isnan()), (path.name, key)
                    scale = float(w.abs().nan_to_num().max()) + 1.0
                    tol = (3e-4 if key == "velocities" else 1e-5) * scale
                    assert float((g.cpu() - w).abs().nan_to_num().max()) <= tol, (path.name, key)
            n += len(indices)
        assert n == len(ds) > 0

def test_a_window_longer_than_every_clip_is_refused_in_one_line(plain_db, motions):
    longest = max(m.num_frames for m in motions)
    assert len(MotionDataset(plain_db, window=longest)) >= 1  # the longest clip still gives one window
    with pytest.raises(DatasetError, match=f"no selected clip is as long as window={longest + 1} frames .*has {longest}\\)"):
        MotionDataset(plain_db, window=longest + 1)


def test_split_ratios_that_are_not_finite_numbers_are_one_line():
    from torchsplice.core.errors import TorchspliceError
    from torchsplice.data.splits import parse_ratios

    assert parse_ratios("0.8,0.1,0.1") == (0.8, 0.1, 0.1)
    for bad in ("nan,1,1", "nan,nan,nan", (float("nan"), 0.5, 0.5), "inf,-inf,1", "0.9,0.1,nan"):
        with pytest.raises(TorchspliceError, match="three numbers"):
            parse_ratios(bad)


@pytest.mark.parametrize("preload", [False, True])
def test_a_training_dataset_over_a_damaged_chunk_raises_one_clear_error(sample_db, tmp_path, preload):
    from torchsplice.core.errors import DatabaseError
    from torchsplice.data import MotionDataset

    db = tmp_path / "damaged.h5"
    shutil.copy(sample_db, db)
    with h5py.File(db, "r") as f:
        info = f["skeletons/0/rotations"].id.get_chunk_info(0)
    with open(db, "r+b") as fh:
        fh.seek(info.byte_offset + info.size // 2)
        raw = fh.read(64)
        fh.seek(info.byte_offset + info.size // 2)
        fh.write(bytes(b ^ 0xFF for b in raw))
    with pytest.raises(DatabaseError, match="damaged database: cannot read /skeletons/0/rotations"):
        ds = MotionDataset(db, preload=preload)
        ds[0]


def test_5_a_mixed_dataset_batches_one_skeleton_topology_at_a_time(mixed):
    from torch.utils.data import DataLoader

    ds = MotionDataset(mixed, window=30, stride=30, features=("rotations",))
    with pytest.raises(DatasetError) as info:
        collate_motion([ds[0], ds[len(ds) - 1]])
    text = str(info.value)
    assert "\n" not in text and "cmu_12_01_walk" in text and "batch_sampler" in text and "where={'skeleton'" in text
    sampler = ds.batch_sampler(4, shuffle=True, seed=3)
    seen = []
    for batch in DataLoader(ds, batch_sampler=sampler, collate_fn=collate_motion):
        joints = {ds.skeletons[k].num_joints for k in batch["skeleton"]}
        assert len(joints) == 1 and batch["rotations"].shape[2] == joints.pop()
        seen += list(zip(batch["index"], batch["start"]))
    assert len(seen) == len(ds) == len(set(seen))  # every item once an epoch
    first, again = [list(b) for b in sampler], [list(b) for b in sampler]
    assert first != again and len(first) == len(sampler)
    assert sorted(sum(first, [])) == sorted(sum(again, [])) == list(range(len(ds)))
    fixed = ds.batch_sampler(4, shuffle=True, seed=3)
    assert [list(b) for b in fixed] == [list(b) for b in ds.batch_sampler(4, shuffle=True, seed=3)]
    assert all(len(b) == 4 for b in ds.batch_sampler(4, drop_last=True))


def test_9_a_skeleton_mismatch_names_a_clip_of_each_skeleton(mixed, tmp_path):
    with pytest.raises(TorchspliceError, match="cannot pack clips of different skeletons") as caught:
        export_clips(mixed, None, out=tmp_path / "all.npz", packed=True)
    line = str(caught.value)
    assert "\n" not in line and "cmu_12_01_walk" in line and "dataset-1_walk_normal_001" in line, line
    ds = MotionDataset(mixed, features=("rotations",))
    with pytest.raises(DatasetError) as info:
        ds.statistics(("rotations",))
    assert "cmu_12_01_walk" in str(info.value) and "dataset-1_walk_normal_001" in str(info.value), str(info.value)


def test_training_splits_by_source_clip_in_the_dataset_match_the_export(sample_db, tmp_path):
    import csv

    spliced = tmp_path / "sp.h5"
    splice_all(sample_db, spliced)
    ratios = (0.4, 0.3, 0.3)
    parts = {s: MotionDataset(spliced, split=s, split_ratios=ratios, split_seed=5, features=("labels",))
             for s in ("train", "val", "test")}
    sources = {s: {(lab["locomotion"], lab["action"]) for lab in (ds[i]["labels"] for i in range(len(ds)))}
               for s, ds in parts.items()}
    locos = {s: {a for a, _ in v} for s, v in sources.items()}
    acts = {s: {b for _, b in v} for s, v in sources.items()}
    for a in ("train", "val", "test"):
        for b in ("train", "val", "test"):
            if a != b:
                assert not locos[a] & locos[b] and not acts[a] & acts[b], (a, b)
    out = tmp_path / "h"
    export_clips(spliced, out=out, format="humanml3d", split_ratios=ratios, split_seed=5)
    exported = {r["clip"]: r["split"] for r in csv.DictReader(open(out / "index.csv"))}
    for s, ds in parts.items():
        assert all(exported[n] == s for n in ds.names), s
    loco = sorted(locos["train"])[0]
    some = MotionDataset(spliced, split="train", split_ratios=ratios, split_seed=5, select=f"locomotion:{loco}")
    assert set(some.names) == {n for n in parts["train"].names if n.startswith(loco + "+")} != set()
    with pytest.raises(DatasetError, match="split must be one of train, val, test"):
        MotionDataset(spliced, split="dev")
