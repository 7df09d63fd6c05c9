"""torchsplice.data: batches and loading: collate_motion's padding and its refusal of mixed
skeletons, DataLoader with workers, pickling, preloading, batched fetch, assembling on a device,
a damaged chunk, datasets of mixed skeletons, and training splits (their ratios, and the same
split as the export's)."""

from __future__ import annotations

import pickle
import shutil

import h5py
import pytest
import torch
from torch.utils.data import DataLoader

from dataset_clips import ALL_FEATURES
from torchsplice import export_clips, splice_all
from torchsplice.core.errors import TorchspliceError
from torchsplice.data import DatasetError, MotionDataset, collate_motion


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
    assert MotionDataset(two_skeleton_db, where={"skeleton": 1}).skeleton.names == ("J0", "J1", "J2")


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
    assert clone._db is None and clone._db_pid is None
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


# --------------------------------------------------------------------------------------------
# training splits
# --------------------------------------------------------------------------------------------
def test_split_ratios_that_are_not_finite_numbers_are_one_line():
    from torchsplice.core.errors import TorchspliceError
    from torchsplice.data.splits import parse_ratios

    assert parse_ratios("0.8,0.1,0.1") == (0.8, 0.1, 0.1)
    for bad in ("nan,1,1", "nan,nan,nan", (float("nan"), 0.5, 0.5), "inf,-inf,1", "0.9,0.1,nan"):
        with pytest.raises(TorchspliceError, match="three numbers"):
            parse_ratios(bad)


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
