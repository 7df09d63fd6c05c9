"""Streaming training batches (torchsplice.data.stream, torchsplice.formats.humanml3d_stream) and
the HumanML3D export's WebDataset shards: the order is a function of (seed, epoch), every unit
once per epoch, the same batches with workers or without, a resume mid-epoch gives the rest of
the epoch, and the numbers are the export's."""

from __future__ import annotations

import io
import subprocess
import sys
import tarfile
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from torchsplice.core.errors import TorchspliceError
from torchsplice.data import MotionStream
from torchsplice.data.stream import epoch_order
from torchsplice.formats.exporters import export_clips
from torchsplice.formats.humanml3d_stream import HumanML3DStream
from torchsplice.job import splice_all

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def stores(sample_db, tmp_path_factory):
    folder = tmp_path_factory.mktemp("stream")
    out = {}
    for store in ("motion", "alignment"):
        out[store] = folder / f"{store}.h5"
        splice_all(sample_db, out[store], store=store, methods="splice,naive", workers=1, index=False)
    return out


def _same(a: dict, b: dict) -> bool:
    if a.keys() != b.keys():
        return False
    for k in a:
        x, y = a[k], b[k]
        if isinstance(x, torch.Tensor):
            if not torch.equal(x, y):
                return False
        elif x != y:
            return False
    return True


def test_an_epoch_order_is_every_unit_once_and_a_function_of_seed_and_epoch():
    a = epoch_order(1000, 64, 4, seed=7, epoch=0)
    assert sorted(a.tolist()) == list(range(1000))
    assert np.array_equal(a, epoch_order(1000, 64, 4, seed=7, epoch=0))
    assert not np.array_equal(a, epoch_order(1000, 64, 4, seed=7, epoch=1))
    assert not np.array_equal(a, epoch_order(1000, 64, 4, seed=8, epoch=0))
    # shuffled within runs of 4 chunks: each run of 256 units comes from 4 whole chunks
    a = epoch_order(1024, 64, 4, seed=7, epoch=0)
    for s in range(0, 1024, 256):
        assert len({u // 64 for u in a[s:s + 256].tolist()}) == 4


def test_motion_stream_batches_are_the_same_with_workers_and_on_either_store(stores):
    s = MotionStream(stores["alignment"], batch_size=7, chunk=8, seed=3, window=16, stride=8)
    inline = list(s)
    workers = list(DataLoader(s, batch_size=None, num_workers=2))
    motion = list(MotionStream(stores["motion"], batch_size=7, chunk=8, seed=3, window=16, stride=8))
    assert len(inline) == len(workers) == len(motion) == len(s) > 3
    assert all(_same(a, b) for a, b in zip(inline, workers))
    assert all(_same(a, b) for a, b in zip(inline, motion))  # assembled batches are the motion store's
    units = [(n, int(st)) for b in inline for n, st in zip(b["name"], b["start"])]
    assert len(units) == len(set(units)) == len(s.dataset)  # every window once
    assert inline[0]["rotations_6d"].shape[-1] == 6 and "velocities" in inline[0]
    s.set_epoch(1)
    assert [b["name"] for b in s] != [b["name"] for b in inline]


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=pytest.mark.gpu)])
def test_a_stream_assembles_its_batches_on_the_device_it_is_given(stores, device):
    """An alignment store's stream assembled by torch on ``device``: the batches of the compiled
    assembly, their 6D rotations within 1e-5 (float32), on the device."""
    kw = dict(batch_size=7, chunk=8, seed=3, window=16, stride=8)
    on_device = list(MotionStream(stores["alignment"], assemble_on=device, **kw))
    plain = list(MotionStream(stores["alignment"], **kw))
    assert len(on_device) == len(plain) > 3
    for a, b in zip(on_device, plain):
        assert a["rotations_6d"].device.type == a["mask"].device.type == device
        assert a["name"] == b["name"] and torch.equal(a["mask"].cpu(), b["mask"])
        assert float((a["rotations_6d"].cpu() - b["rotations_6d"]).abs().max()) <= 1e-5  # torch's assembly, float32


def test_a_resumed_stream_gives_the_rest_of_the_epoch(stores):
    whole = list(MotionStream(stores["alignment"], batch_size=5, chunk=4, seed=11))
    s = MotionStream(stores["alignment"], batch_size=5, chunk=4, seed=11)
    taken = []
    for batch in DataLoader(s, batch_size=None, num_workers=2):
        taken.append(batch)
        if len(taken) == 3:
            state = s.state_at(batch)
            break
    assert state == {"seed": 11, "epoch": 0, "next_batch": 3}
    again = MotionStream(stores["alignment"], batch_size=5, chunk=4, seed=11)
    again.load_state_dict(state)
    rest = list(DataLoader(again, batch_size=None, num_workers=2))
    assert len(taken) + len(rest) == len(whole)
    assert all(_same(a, b) for a, b in zip(taken + rest, whole))
    with pytest.raises(TorchspliceError, match="seed"):
        MotionStream(stores["alignment"], batch_size=5, seed=12).load_state_dict(state)
    inline = MotionStream(stores["alignment"], batch_size=5, chunk=4, seed=11)
    it = iter(inline)
    next(it), next(it)
    assert inline.state_dict()["next_batch"] == 2


@pytest.fixture(scope="module")
def exported(stores, tmp_path_factory):
    folder = tmp_path_factory.mktemp("hml") / "HumanML3D"
    from torchsplice.formats.exporters import export_clips

    export_clips(stores["alignment"], out=folder, format="humanml3d")
    return folder


def test_the_humanml3d_stream_gives_the_exports_motions_captions_and_splits(stores, exported):
    s = HumanML3DStream(stores["alignment"], batch_size=6, chunk=8, seed=2)
    seen = {}
    for batch in DataLoader(s, batch_size=None, num_workers=2):
        assert batch["motion"].shape[-1] == 263 and batch["mask"].shape == batch["motion"].shape[:2]
        for i, id_ in enumerate(batch["id"]):
            n = int(batch["lengths"][i])
            want = np.load(exported / "new_joint_vecs" / f"{id_}.npy")
            got = batch["motion"][i, :n].numpy()
            assert got.shape == want.shape and not batch["motion"][i, n:].any()
            # the same float64 arithmetic in padded batches of other shapes: the last bits may differ
            np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9)
            lines = (exported / "texts" / f"{id_}.txt").read_text().splitlines()
            assert batch["captions"][i] == lines and batch["caption"][i] in [ln.split("#")[0] for ln in lines]
            seen[id_] = batch["split"][i]
    assert sorted(i for i, s_ in seen.items() if s_) == (exported / "all.txt").read_text().split()
    for split in ("train", "val", "test"):
        assert sorted(i for i, s_ in seen.items() if s_ == split) == (exported / f"{split}.txt").read_text().split()
    train = HumanML3DStream(stores["alignment"], batch_size=4, split="train")
    assert sorted(i for b in train for i in b["id"]) == (exported / "train.txt").read_text().split()
    mean, std = s.statistics
    np.testing.assert_allclose(mean, np.load(exported / "Mean.npy"), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(std, np.load(exported / "Std.npy"), rtol=1e-6, atol=1e-7)
    normed = HumanML3DStream(stores["alignment"], batch_size=6, chunk=8, seed=2, normalize=(mean, std))
    a, b = next(iter(normed)), next(iter(s))
    n = int(a["lengths"][0])
    np.testing.assert_allclose(a["motion"][0, :n].numpy(), ((b["motion"][0, :n].numpy() - mean) / std), rtol=1e-5,
                               atol=1e-5)
    with pytest.raises(TorchspliceError, match="split"):
        HumanML3DStream(stores["alignment"], split="training")


def test_humanml3d_shards_read_back_as_the_folder_export(stores, exported, tmp_path):
    """(The ``export`` command names its ``--shards`` flag: tests/cli/test_command_words.py.)"""
    out = tmp_path / "shards"
    export_clips(stores["alignment"], None, out=out, format="humanml3d", shards=3)
    tars = sorted(out.glob("*.tar"))
    assert 3 <= len(tars) <= 5 and not (out / "new_joint_vecs").exists()
    ids, nosplit = [], set()
    for t in tars:
        split = t.name.split("-")[0]
        with tarfile.open(t) as tar:
            names = tar.getnames()
            assert names[::2] == [n[:-4] + ".npy" for n in names[1::2]]  # ID.npy then ID.txt, WebDataset's pairs
            for name in names:
                key, ext = name.split(".", 1)
                data = tar.extractfile(name).read()
                if ext == "npy":
                    ids.append(key)
                    if split == "nosplit":
                        nosplit.add(key)
                    want = np.load(exported / "new_joint_vecs" / f"{key}.npy")
                    np.testing.assert_allclose(np.load(io.BytesIO(data)), want, rtol=1e-6, atol=1e-9)
                    if split != "nosplit":
                        assert key in (exported / f"{split}.txt").read_text().split()
                else:
                    assert data.decode() == (exported / "texts" / f"{key}.txt").read_text()
    assert sorted(i for i in ids if i not in nosplit) == (exported / "all.txt").read_text().split()
    for name in ("train.txt", "val.txt", "test.txt", "index.csv"):
        assert (out / name).read_text() == (exported / name).read_text()
    with pytest.raises(TorchspliceError, match="shards must be a whole number of at least 1") as caught:
        export_clips(stores["alignment"], None, out=tmp_path / "none", format="humanml3d", shards=0)
    assert "\n" not in str(caught.value) and not (tmp_path / "none").exists()


@pytest.mark.slow
def test_the_training_example_runs_and_resumes(tmp_path):
    ck = tmp_path / "ck.pt"
    cmd = [sys.executable, "scripts/train_from_stream.py", "--steps", "3", "--checkpoint", str(ck), "--workers", "2"]
    first = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr[-2000:]
    assert "step 3: epoch 0 batch 2" in first.stdout and ck.is_file()
    again = subprocess.run(cmd[:3] + ["1"] + cmd[4:], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-2000:]
    assert "resumed at epoch 0, batch 3" in again.stdout and "step 1: epoch 0 batch 3" in again.stdout
