"""``export --format humanml3d --shards N``: every tar member is byte for byte the folder export's
file (``ID.npy`` its ``new_joint_vecs/ID.npy``, ``ID.txt`` its ``texts/ID.txt``), and ``Mean.npy``,
``Std.npy``, the split lists and ``index.csv`` are the folder export's too: both compute the same
batches (each split's clips in plan order, ``READ_BATCH`` clips a batch). ``N`` counts tars (each
split its share, at least one, cut between batches), not bytes."""

from __future__ import annotations

import tarfile

import pytest

from torchsplice.formats import humanml3d_exporter as hx
from torchsplice.formats.exporters import export_clips
from torchsplice.job import splice_all

OPTIONS = dict(mirror=True, window=2.5, split_ratios="0.6,0.2,0.2")


@pytest.fixture(scope="module")
def spliced(sample_db, tmp_path_factory):
    out = tmp_path_factory.mktemp("shards") / "spliced.h5"
    splice_all(sample_db, out, store="alignment", methods="splice,naive", index=False, workers=1)
    return out


def _members(folder) -> dict[str, tuple[str, bytes]]:
    out = {}
    for tar in sorted(folder.glob("*.tar")):
        with tarfile.open(tar) as t:
            for m in t.getmembers():
                assert m.name not in out
                out[m.name] = (tar.name, t.extractfile(m).read())
    return out


@pytest.mark.parametrize("batch, shards", [(3, 5), (64, 3)])
def test_every_member_is_the_folder_exports_bytes(spliced, tmp_path, monkeypatch, batch, shards):
    """With batches of 3 clips the export has many batches and tars cut between them; with the
    default's 64, a split of the sample is one batch (hence one tar)."""
    monkeypatch.setattr(hx, "READ_BATCH", batch)
    folder, sharded = tmp_path / "folder", tmp_path / "sharded"
    export_clips(spliced, None, out=folder, format="humanml3d", **OPTIONS)
    export_clips(spliced, None, out=sharded, format="humanml3d", shards=shards, **OPTIONS)
    members = _members(sharded)
    ids = [p.stem for p in (folder / "new_joint_vecs").glob("*.npy")]
    assert len(ids) > 60 and sorted(members) == sorted([f"{i}.npy" for i in ids] + [f"{i}.txt" for i in ids])
    for i in ids:
        assert members[f"{i}.npy"][1] == (folder / "new_joint_vecs" / f"{i}.npy").read_bytes(), i
        assert members[f"{i}.txt"][1] == (folder / "texts" / f"{i}.txt").read_bytes(), i
    for name in ("Mean.npy", "Std.npy", "index.csv", "train.txt", "val.txt", "test.txt", "train_val.txt", "all.txt"):
        assert (sharded / name).read_bytes() == (folder / name).read_bytes(), name
    # each tar holds one split's motions; each split with motions has a tar; N tars, give or take a split's
    split_of = {i: s for s in ("train", "val", "test") for i in (folder / f"{s}.txt").read_text().split()}
    tars = {tar for tar, _ in members.values()}
    for name, (tar, _) in members.items():
        assert tar.startswith(split_of.get(name.split(".")[0], "nosplit") + "-")
    splits = {tar.split("-")[0] for tar in tars}
    assert splits == set(split_of.values()) | ({"nosplit"} if len(split_of) < len(ids) else set())
    assert len(splits) <= len(tars) <= shards + 3
    if batch == 3:
        assert len(tars) > len(splits)  # a split of several batches is cut into several tars
        # a batch's clips are in one tar (the same batch as the folder export computed)
        exporter = hx.HumanML3DExporter(spliced, shards=shards, **OPTIONS)
        for b in exporter._plan["batches"]:
            assert len({members[f"{item['id']}.npy"][0] for item in b}) == 1
