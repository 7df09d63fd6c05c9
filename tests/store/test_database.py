"""The HDF5 motion database: round trips, layout, padded batches, atomic writes, errors, scale."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from torchsplice.core.errors import DatabaseError, MotionError
from torchsplice.core.motion import Motion
from torchsplice.core.skeleton import Skeleton
from torchsplice.store.database import SCHEMA_VERSION, ClipBatch, MotionDatabase
from dataset_clips import branching_skeleton, chain_skeleton, random_clip, tiny_clips
from writers import reaped

# --------------------------------------------------------------------------------------------
# synthetic clips
# --------------------------------------------------------------------------------------------


def same_skeleton(a: Skeleton, b: Skeleton) -> None:
    assert a.names == b.names
    assert a.parents == b.parents
    assert a.channels == b.channels
    assert torch.equal(a.offsets, b.offsets)
    assert a.end_site_parents == b.end_site_parents
    assert torch.equal(a.end_site_offsets, b.end_site_offsets)


def assert_same_clip(read: Motion, orig: Motion, atol: float | None = None) -> None:
    """Metadata equal; tensors equal within float32 precision (or exactly with atol=0)."""
    assert read.name == orig.name
    assert read.fps == orig.fps
    assert read.role == orig.role
    assert read.labels == orig.labels
    assert read.source == orig.source
    assert read.num_frames == orig.num_frames
    tol = {} if atol is None else {"rtol": 0.0, "atol": atol}
    for a, b in ((read.rotations, orig.rotations), (read.root_translation, orig.root_translation)):
        if atol is None:
            torch.testing.assert_close(a.double(), b.double(), rtol=2e-7, atol=2e-6 * max(1.0, float(b.abs().max())))
        else:
            torch.testing.assert_close(a.double(), b.double(), **tol)
    assert (read.translations is None) == (orig.translations is None)
    if orig.translations is not None:
        torch.testing.assert_close(read.local_translations().double(), orig.local_translations().double(),
                                   rtol=2e-7, atol=2e-6 * max(1.0, float(orig.translations.abs().max())))


def dir_listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def count_groups(path: Path) -> int:
    groups = []
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: groups.append(name) if isinstance(obj, h5py.Group) else None)
    return len(groups) + 1  # and the root


@pytest.fixture
def two_skeleton_clips() -> list[Motion]:
    a, b = chain_skeleton(3), branching_skeleton()
    return [
        random_clip(a, 10, "a_walk", 1, role="locomotion", labels={"content": "walk", "style": "proud"}),
        random_clip(b, 7, "b wave", 2, fps=120.0, role="action", labels={"content": "wave"}),
        random_clip(a, 1, "a_single_frame", 3, fps=24.5),
        random_clip(b, 30, "b_run", 4, role="both", labels={}),
        random_clip(a, 200, "a_long", 5, role="spliced", labels={"ü": "ünïcode"}),
        random_clip(a, 4, "a_short", 6, role="locomotion"),
    ]


@pytest.fixture
def db_path(tmp_path, two_skeleton_clips) -> Path:
    p = tmp_path / "db" / "motion.h5"
    p.parent.mkdir()
    with MotionDatabase.create(p) as db:
        for m in two_skeleton_clips:
            db.append(m)
    return p


# --------------------------------------------------------------------------------------------
# round trips
# --------------------------------------------------------------------------------------------
def test_round_trip_two_skeletons(db_path, two_skeleton_clips):
    assert dir_listing(db_path.parent) == ["motion.h5"]
    with MotionDatabase.open(db_path) as db:
        assert len(db) == len(two_skeleton_clips)
        assert db.names == [m.name for m in two_skeleton_clips]
        assert len(db.skeletons) == 2
        same_skeleton(db.skeletons[0], two_skeleton_clips[0].skeleton)
        same_skeleton(db.skeletons[1], two_skeleton_clips[1].skeleton)
        for i, m in enumerate(two_skeleton_clips):
            for key in (m.name, i):
                r = db.read(key)
                assert r.dtype == torch.float32
                assert_same_clip(r, m)
                same_skeleton(r.skeleton, m.skeleton)
            info = db.clip_info(m.name)
            assert info["skeleton"] == (0 if m.skeleton.num_joints == 3 else 1)
            assert info["length"] == m.num_frames
        # each skeleton keeps only its own clips, packed in insertion order
        t = db.table()
        assert t["skeleton"].tolist() == [0, 1, 0, 1, 0, 0]
        assert t["start"].tolist() == [0, 0, 10, 7, 11, 211]
        assert db.h5["skeletons/0/rotations"].shape == (215, 3, 4)
        assert db.h5["skeletons/1/rotations"].shape == (37, 5, 4)
        assert db.h5["skeletons/1/translations"].shape == (37, 5, 3)
        assert "translations" not in db.h5["skeletons/0"]


def assert_same_motion(a: Motion, b: Motion) -> None:
    assert (a.name, a.source, a.role, a.labels, a.fps) == (b.name, b.source, b.role, b.labels, b.fps)
    assert a.skeleton is b.skeleton
    assert torch.equal(a.rotations, b.rotations) and torch.equal(a.root_translation, b.root_translation)
    assert (a.translations is None) == (b.translations is None)
    if a.translations is not None:
        assert torch.equal(a.translations, b.translations)


def test_read_many_equals_read_per_clip(db_path, two_skeleton_clips):
    with MotionDatabase.open(db_path) as db:
        order = ["a_long", 1, "a_walk", 5, "b_run", 2, "a_long"]  # both skeletons, names and rows, a repeat
        for got, clip in zip(db.read_many(order), order):
            assert_same_motion(got, db.read(clip))
        assert db.read_many([]) == []
        with pytest.raises(DatabaseError, match=r"no clip named 'nope'; MotionDatabase\.summary\(\) lists the clips$"):
            db.read_many(["a_walk", "nope"])


def test_append_packed_equals_appending_clip_by_clip(tmp_path, two_skeleton_clips):
    """Packed clips of one skeleton land exactly as appended one by one, with extra columns."""
    clips = [m for m in two_skeleton_clips if m.skeleton is two_skeleton_clips[0].skeleton]
    cols, frames = {"cost": "float", "note": "str", "n": "int"}, ("score",)
    extra = {"cost": [0.5, 1.5, 2.5, 3.5], "note": ["x", "", "ü", "y"], "n": [1, 2, 3, 4]}
    score = [np.arange(m.num_frames, dtype=np.float32) for m in clips]
    with MotionDatabase.create(tmp_path / "one.h5", columns=cols, frame_columns=frames) as db:
        for k, m in enumerate(clips):
            db.append(m, extra={c: v[k] for c, v in extra.items()}, frame_extra={"score": score[k]})
    with MotionDatabase.create(tmp_path / "packed.h5", columns=cols, frame_columns=frames) as db:
        db.append_packed(clips[0].skeleton, torch.cat([m.rotations for m in clips]),
                         torch.cat([m.root_translation for m in clips]), None, [m.num_frames for m in clips],
                         [m.name for m in clips], [m.fps for m in clips], sources=[m.source for m in clips],
                         roles=[m.role for m in clips], labels=[m.labels for m in clips], extra=extra,
                         frame_extra={"score": np.concatenate(score)})
    with MotionDatabase.open(tmp_path / "one.h5") as a, MotionDatabase.open(tmp_path / "packed.h5") as b:
        ta, tb = a.table(), b.table()
        assert ta.keys() == tb.keys()
        for c in ta:
            assert np.array_equal(ta[c], tb[c]) or (ta[c].dtype.kind == "f" and np.array_equal(ta[c], tb[c], equal_nan=True)), c
        for m in clips:
            assert torch.equal(a.read(m.name).rotations, b.read(m.name).rotations)
            assert np.array_equal(a.read_frame_column(m.name, "score"), b.read_frame_column(m.name, "score"))


def test_clip_info_from_the_file_and_from_the_read_table_agree(tmp_path, two_skeleton_clips):
    """clip_info answers column by column at first, then from the clip table: the same values of
    the same Python types, the extra columns' unset values included."""
    cols = {"cost": "float", "note": "str", "n": "int"}
    path = tmp_path / "x.h5"
    with MotionDatabase.create(path, columns=cols) as db:
        for k, m in enumerate(two_skeleton_clips):
            db.append(m, extra={"cost": k / 3, "note": "ü" * k, "n": k} if k % 2 else {})
    with MotionDatabase.open(path) as first, MotionDatabase.open(path) as second:
        second.clip_table()
        rows = [*range(len(first)), *range(len(first))] * (1 + MotionDatabase.TABLE_AFTER_INFOS // len(first))
        for row in rows:  # the first ones from the file, the rest from the table it reads after a while
            a, b = first.clip_info(row), second.clip_info(second.names[row])
            nan_free = [{k: "NaN" if isinstance(v, float) and np.isnan(v) else v for k, v in d.items()} for d in (a, b)]
            assert nan_free[0] == nan_free[1] and (a["cost"] == a["cost"]) == bool(row % 2), (a, b)
            assert list(a) == list(b) and [type(v) for v in a.values()] == [type(v) for v in b.values()]
            assert a["labels"] is not b["labels"]
        assert first._info_reads == MotionDatabase.TABLE_AFTER_INFOS and first._clip_table is not None
        info = second.clip_info(0)
        info["labels"]["changed"] = "by the caller"
        assert "changed" not in second.clip_info(0)["labels"]


def test_append_packed_refuses_bad_input(tmp_path, two_skeleton_clips):
    m = two_skeleton_clips[0]
    with MotionDatabase.create(tmp_path / "x.h5") as db:
        db.append(m)
        args = (m.skeleton, m.rotations, m.root_translation, None, [m.num_frames])
        with pytest.raises(DatabaseError, match="already in the database"):
            db.append_packed(*args, [m.name], m.fps)
        with pytest.raises(DatabaseError, match="do not fit"):
            db.append_packed(m.skeleton, m.rotations, m.root_translation, None, [m.num_frames + 1], ["new"], m.fps)
        bad = m.rotations.clone()
        bad[3, 1, 2] = float("nan")
        with pytest.raises(DatabaseError, match="clip 'new' has non-finite rotations at frame 3"):
            db.append_packed(m.skeleton, bad, m.root_translation, None, [m.num_frames], ["new"], m.fps)
        assert len(db) == 1
        with pytest.raises(DatabaseError, match="source needs 1 values, got 2"):
            db.append_packed(*args, ["new"], m.fps, sources=["a", "b"])
        db.append_packed(m.skeleton, m.rotations[:0], m.root_translation[:0], None, [], [], m.fps)  # nothing to add
        db.append_packed(*args, ["new"], m.fps, sources="one source for all")
        assert len(db) == 2 and db.clip_info("new")["source"] == "one source for all"
    with MotionDatabase.open(tmp_path / "x.h5") as db:  # nothing half-written by the refused calls
        t = db.table()
        assert list(t["name"]) == [m.name, "new"] and all(len(col) == 2 for col in t.values())
        assert db.h5["skeletons/0/rotations"].shape[0] == 2 * m.num_frames


def test_same_names_different_offsets_get_their_own_skeleton(tmp_path):
    short, tall = chain_skeleton(3, bone=1.0), chain_skeleton(3, bone=2.0)
    clips = [random_clip(short, 5, "short", 1), random_clip(tall, 6, "tall", 2), random_clip(short, 2, "short2", 3)]
    p = tmp_path / "x.h5"
    with MotionDatabase.create(p) as db:
        for m in clips:
            db.append(m)
    with MotionDatabase.open(p) as db:
        assert len(db.skeletons) == 2
        for m in clips:
            r = db.read(m.name)
            same_skeleton(r.skeleton, m.skeleton)
            torch.testing.assert_close(r.global_positions().double(), m.global_positions(), rtol=0, atol=1e-4)


def test_read_staged_clip_before_close(tmp_path):
    sk = chain_skeleton(3)
    m = random_clip(sk, 5, "staged", 1)
    with MotionDatabase.create(tmp_path / "x.h5") as db:
        assert db.append(m) == 0
        assert len(db) == 1 and db.names == ["staged"]
        assert_same_clip(db.read("staged"), m)
        db.append(random_clip(sk, 3, "second", 2))
        assert db.index("second") == 1
    with MotionDatabase.open(tmp_path / "x.h5") as db:
        assert db.names == ["staged", "second"]


def test_append_mode_adds_clips(db_path, two_skeleton_clips):
    extra = random_clip(chain_skeleton(3), 12, "appended", 9, role="action", labels={"k": "v"})
    new_sk = random_clip(chain_skeleton(4, prefix="K"), 3, "new skeleton", 10)
    with MotionDatabase.open(db_path, "a") as db:
        db.append(extra)
        db.append(new_sk)
    with MotionDatabase.open(db_path) as db:
        assert len(db) == len(two_skeleton_clips) + 2
        assert len(db.skeletons) == 3
        assert db.clip_info("appended")["skeleton"] == 0
        assert_same_clip(db.read("appended"), extra)
        assert_same_clip(db.read("new skeleton"), new_sk)
        for m in two_skeleton_clips:
            assert_same_clip(db.read(m.name), m)


def test_append_through_a_link_updates_the_file_it_names(db_path, tmp_path, two_skeleton_clips):
    """A symbolic link to a database, appended to, stays a link: its target gets the clip, and
    the copy appending works on is made beside the target (none left beside the link)."""
    link = tmp_path / "elsewhere" / "link.h5"
    link.parent.mkdir()
    link.symlink_to(db_path)
    extra = random_clip(chain_skeleton(3), 12, "appended", 9)
    with MotionDatabase.open(link, "a") as db:
        db.append(extra)
    assert link.is_symlink() and link.resolve() == db_path.resolve()
    with MotionDatabase.open(db_path) as db:
        assert db.names == [m.name for m in two_skeleton_clips] + ["appended"]
        assert_same_clip(db.read("appended"), extra)
    assert sorted(p.name for p in link.parent.iterdir()) == ["link.h5"]


REAL = {
    "bandai_namco_research_motiondataset": ["dataset-1_dash_normal_001.bvh", "dataset-2_raise-up-both-hands_normal_001.bvh"],
    "cmu_graphics_lab": ["cmu_12_01_walk.bvh", "131_01.bvh"],
    "lafan1_via_pypi_bvhtools": ["test2.bvh"],
}


@pytest.mark.realdata
def test_real_clips_round_trip(mocap_dir, tmp_path):
    from torchsplice.formats.bvh import read_bvh

    clips = []
    for folder, names in REAL.items():
        for i, n in enumerate(names):
            m = read_bvh(mocap_dir / folder / n)
            m.role, m.labels = ("locomotion", {"source": folder}) if i == 0 else ("action", {})
            clips.append(m)
    p = tmp_path / "real.h5"
    with MotionDatabase.create(p) as db:
        for m in clips:
            db.append(m)
    with MotionDatabase.open(p) as db:
        # Bandai (two: its files differ in End Site offsets, which are part of a clip's identity),
        # CMU MotionBuilder names, CMU 3ds Max names, LAFAN1
        assert len(db.skeletons) == 5
        for m in clips:
            r = db.read(m.name)
            assert_same_clip(r, m, atol=0)  # float32 in, float32 stored: exact
            assert r.skeleton.matches(m.skeleton)
            assert r.skeleton.channels == m.skeleton.channels
            assert r.skeleton.end_site_parents == m.skeleton.end_site_parents
            if m.translations is not None:
                assert torch.equal(r.translations, m.translations)


@pytest.mark.realdata
def test_bandai_datasets_share_one_skeleton(mocap_dir, tmp_path):
    from torchsplice.formats.bvh import read_bvh

    folder = mocap_dir / "bandai_namco_research_motiondataset"
    m1 = read_bvh(folder / "dataset-1_walk_normal_001.bvh", dtype=torch.float64)
    m2 = read_bvh(folder / "dataset-2_walk_normal_008.bvh", dtype=torch.float64)
    hips = m1.skeleton.index("Hips")
    assert not torch.allclose(m1.skeleton.offsets[hips], m2.skeleton.offsets[hips])  # the premise
    assert m1.skeleton.translation_animated[hips]
    p = tmp_path / "bn.h5"
    with MotionDatabase.create(p, dtype=np.float64) as db:
        db.append(m1)
        db.append(m2)
        assert len(db.skeletons) == 1
    with MotionDatabase.open(p) as db:
        assert len(db.skeletons) == 1
        assert db.table()["skeleton"].tolist() == [0, 0]
        for m in (m1, m2):
            r = db.read(m.name, dtype=torch.float64)
            # positions are the file's, whichever Hips offset the stored skeleton carries
            torch.testing.assert_close(r.global_positions(), m.global_positions(), rtol=0, atol=1e-9)


# --------------------------------------------------------------------------------------------
# storage precision
# --------------------------------------------------------------------------------------------
def test_float32_default_and_float64_on_request(tmp_path, two_skeleton_clips):
    p32, p64 = tmp_path / "f32.h5", tmp_path / "f64.h5"
    with MotionDatabase.create(p32) as db:
        for m in two_skeleton_clips:
            db.append(m)
    with MotionDatabase.create(p64, dtype=np.float64) as db:
        for m in two_skeleton_clips:
            db.append(m)
    with h5py.File(p32, "r") as f:
        for k in ("0", "1"):
            assert f[f"skeletons/{k}/rotations"].dtype == np.float32
            assert f[f"skeletons/{k}/root_translation"].dtype == np.float32
        assert f["skeletons/1/translations"].dtype == np.float32
        assert f["skeletons/0/offsets"].dtype == np.float64
    with h5py.File(p64, "r") as f:
        for k in ("0", "1"):
            assert f[f"skeletons/{k}/rotations"].dtype == np.float64
        assert f["skeletons/1/translations"].dtype == np.float64
    with MotionDatabase.open(p64) as db:
        for m in two_skeleton_clips:
            r = db.read(m.name, dtype=torch.float64)
            assert r.dtype == torch.float64
            assert torch.equal(r.rotations, m.rotations)
            assert torch.equal(r.root_translation, m.root_translation)
            if m.translations is not None:
                assert torch.equal(r.local_translations(), m.local_translations())
        # appending to a float64 file keeps float64
    with MotionDatabase.open(p64, "a") as db:
        db.append(random_clip(chain_skeleton(3), 3, "more", 11))
    with MotionDatabase.open(p64) as db:
        m = random_clip(chain_skeleton(3), 3, "more", 11)
        assert torch.equal(db.read("more", dtype=torch.float64).rotations, m.rotations)
    with MotionDatabase.open(p32) as db:
        r = db.read(two_skeleton_clips[0].name, dtype=torch.float64)
        assert r.dtype == torch.float64
        assert not torch.equal(r.rotations, two_skeleton_clips[0].rotations)  # really float32 storage


# --------------------------------------------------------------------------------------------
# the layout, read with plain h5py
# --------------------------------------------------------------------------------------------
def test_layout_readable_with_plain_h5py(db_path, two_skeleton_clips):
    name = "b wave"
    with h5py.File(db_path, "r") as f:
        assert f.attrs["format"] == "torchsplice.motiondb"
        assert int(f.attrs["schema_version"]) == 1 and SCHEMA_VERSION == 2  # motion databases keep schema 1
        assert f.attrs["quaternion_order"] == "wxyz"
        for key in ("units", "up_axis", "created_by"):
            assert key in f.attrs
        clips = f["clips"]
        names = clips["name"].asstr()[()].tolist()
        n_clips = len(names)
        for col in ("name", "source", "role", "labels", "skeleton", "start", "length", "fps"):
            assert clips[col].shape == (n_clips,)
        assert clips["skeleton"].dtype == np.int32
        assert clips["start"].dtype == np.int64 and clips["length"].dtype == np.int64
        assert clips["fps"].dtype == np.float64
        i = names.index(name)
        k = int(clips["skeleton"][i])
        s, n = int(clips["start"][i]), int(clips["length"][i])
        g = f[f"skeletons/{k}"]
        rot = g["rotations"][s:s + n]
        root = g["root_translation"][s:s + n]
        trans = g["translations"][s:s + n]
        fps = float(clips["fps"][i])
        role = clips["role"].asstr()[i]
        source = clips["source"].asstr()[i]
        labels = json.loads(clips["labels"].asstr()[i])
        jnames = g["names"].asstr()[()].tolist()
        parents = g["parents"][()]
        offsets = g["offsets"][()]
        channels = [c.split() for c in g["channels"].asstr()[()]]
        ends = g["end_site_parents"][()], g["end_site_offsets"][()]
        assert parents.dtype == np.int32 and offsets.dtype == np.float64
        assert g["end_site_parents"].dtype == np.int32 and g["end_site_offsets"].dtype == np.float64
        assert "spec" in g.attrs and "units" in g.attrs and "up_axis" in g.attrs
    with MotionDatabase.open(db_path) as db:
        r = db.read(name)
    assert np.array_equal(rot, r.rotations.numpy())
    assert np.array_equal(root, r.root_translation.numpy())
    assert np.array_equal(trans[:, 1:], r.translations[:, 1:].numpy())
    assert (fps, role, source, labels) == (r.fps, r.role, r.source, r.labels)
    sk = r.skeleton
    assert jnames == list(sk.names) and parents.tolist() == list(sk.parents)
    assert np.array_equal(offsets, sk.offsets.numpy())
    assert [tuple(c) for c in channels] == list(sk.channels)
    assert ends[0].tolist() == list(sk.end_site_parents) and np.array_equal(ends[1], sk.end_site_offsets.numpy())
    orig = next(m for m in two_skeleton_clips if m.name == name)
    np.testing.assert_allclose(rot, orig.rotations.numpy(), rtol=1e-6, atol=1e-7)
    # the quaternions are WXYZ: the stored w is the original's first component
    np.testing.assert_allclose(rot[..., 0], orig.rotations[..., 0].numpy(), rtol=1e-6, atol=1e-7)


# --------------------------------------------------------------------------------------------
# padded batches
# --------------------------------------------------------------------------------------------
def _check_batch(batch: ClipBatch, db: MotionDatabase, clips: dict[str, Motion]) -> None:
    B = len(batch)
    T = int(batch.lengths.max())
    J = batch.skeleton.num_joints
    assert batch.rotations.shape == (B, T, J, 4)
    assert batch.root_translation.shape == (B, T, 3)
    assert batch.lengths.dtype == torch.int64 and batch.mask.dtype == torch.bool
    assert batch.mask.shape == (B, T)
    for b, name in enumerate(batch.names):
        n = clips[name].num_frames
        assert int(batch.lengths[b]) == n
        assert batch.mask[b].tolist() == [True] * n + [False] * (T - n)
        assert float(batch.fps[b]) == clips[name].fps
        assert batch.indices[b] == db.index(name)
        # padding repeats the last frame
        for t in range(n, T):
            assert torch.equal(batch.rotations[b, t], batch.rotations[b, n - 1])
            assert torch.equal(batch.root_translation[b, t], batch.root_translation[b, n - 1])
            if batch.translations is not None:
                assert torch.equal(batch.translations[b, t], batch.translations[b, n - 1])
        m, r = batch.motion(b), db.read(name)
        assert m.name == r.name and m.fps == r.fps and m.num_frames == r.num_frames
        assert m.skeleton.matches(r.skeleton)
        assert torch.equal(m.rotations, r.rotations)
        assert torch.equal(m.root_translation, r.root_translation)
        assert (m.translations is None) == (r.translations is None)
        if m.translations is not None:
            assert torch.equal(m.local_translations(), r.local_translations())
        torch.testing.assert_close(m.rotations.double(), clips[name].rotations, rtol=2e-7, atol=2e-6)


def test_read_batch_padding_and_motion(db_path, two_skeleton_clips):
    clips = {m.name: m for m in two_skeleton_clips}
    with MotionDatabase.open(db_path) as db:
        for names in (["a_walk", "a_single_frame", "a_short"],   # close together: one read
                      ["a_short", "a_walk"],                    # out of row order
                      ["a_walk", "a_short"],                    # far apart (a_long between): per-clip reads
                      ["a_long", "a_single_frame"],
                      ["b wave", "b_run"], ["b_run"],
                      [0, "a_short", 2]):                       # by row number too
            batch = db.read_batch(names)
            assert batch.names == [db.names[db.index(n)] for n in names]
            assert batch.translations is None if batch.skeleton.num_joints == 3 else batch.translations.shape[-1] == 3
            _check_batch(batch, db, clips)
        b64 = db.read_batch(["b wave", "b_run"], dtype=torch.float64)
        assert b64.rotations.dtype == b64.root_translation.dtype == b64.translations.dtype == torch.float64
        with pytest.raises(DatabaseError, match="skeleton"):
            db.read_batch(["a_walk", "b wave"])
        with pytest.raises(DatabaseError):
            db.read_batch([])
        with pytest.raises(DatabaseError, match="no_such_clip"):
            db.read_batch(["a_walk", "no_such_clip"])


@pytest.mark.parametrize("sort_by_length", [False, True])
@pytest.mark.parametrize("batch_size", [1, 2, 4, 100])
def test_batches_cover_every_clip_once(db_path, two_skeleton_clips, sort_by_length, batch_size):
    clips = {m.name: m for m in two_skeleton_clips}
    seen = []
    with MotionDatabase.open(db_path) as db:
        for batch in db.batches(batch_size=batch_size, sort_by_length=sort_by_length):
            assert 1 <= len(batch) <= batch_size
            assert len({db.clip_info(n)["skeleton"] for n in batch.names}) == 1
            if sort_by_length:
                assert batch.lengths.tolist() == sorted(batch.lengths.tolist())
            _check_batch(batch, db, clips)
            seen += batch.names
        assert sorted(seen) == sorted(clips) and len(seen) == len(set(seen))
        subset = ["a_short", "b_run", "a_walk"]
        got = [n for b in db.batches(subset, batch_size=batch_size, sort_by_length=sort_by_length) for n in b.names]
        assert sorted(got) == sorted(subset)


def test_batches_sorted_by_length_group_similar_clips(tmp_path):
    sk = chain_skeleton(3)
    lengths = [50, 2, 40, 3, 45, 1, 60, 4]
    p = tmp_path / "x.h5"
    with MotionDatabase.create(p) as db:
        for i, n in enumerate(lengths):
            db.append(random_clip(sk, n, f"c{i}", i))
    with MotionDatabase.open(p) as db:
        batches = list(db.batches(batch_size=4, sort_by_length=True))
        assert [b.lengths.tolist() for b in batches] == [[1, 2, 3, 4], [40, 45, 50, 60]]
        assert [b.rotations.shape[1] for b in batches] == [4, 60]


# --------------------------------------------------------------------------------------------
# atomicity
# --------------------------------------------------------------------------------------------
class Boom(Exception):
    pass


def test_exception_inside_create_leaves_nothing(tmp_path, two_skeleton_clips):
    p = tmp_path / "out.h5"
    with pytest.raises(Boom):
        with MotionDatabase.create(p) as db:
            for m in two_skeleton_clips:
                db.append(m)
            db.flush()
            raise Boom()
    assert not p.exists()
    assert dir_listing(tmp_path) == []


def test_failed_append_leaves_original_byte_identical(db_path, two_skeleton_clips):
    before = db_path.read_bytes()
    stat = db_path.stat()
    with pytest.raises(Boom):
        with MotionDatabase.open(db_path, "a") as db:
            db.append(random_clip(chain_skeleton(3), 5, "doomed", 7))
            db.append(random_clip(chain_skeleton(5, prefix="Z"), 5, "doomed too", 8))
            db.flush()
            raise Boom()
    assert db_path.read_bytes() == before
    assert db_path.stat().st_mtime_ns == stat.st_mtime_ns
    assert dir_listing(db_path.parent) == [db_path.name]
    with MotionDatabase.open(db_path) as db:
        assert db.names == [m.name for m in two_skeleton_clips]


def test_failed_append_by_bad_clip_then_abort(db_path):
    """A refused clip inside an append block, the exception left to propagate: no change."""
    before = db_path.read_bytes()
    nan = random_clip(chain_skeleton(3), 4, "nan clip", 3)
    nan.rotations[2, 1, 0] = float("nan")
    with pytest.raises(MotionError):
        with MotionDatabase.open(db_path, "a") as db:
            db.append(random_clip(chain_skeleton(3), 5, "fine", 7))
            db.append(nan)
    assert db_path.read_bytes() == before
    assert dir_listing(db_path.parent) == [db_path.name]


WRITER = """
import sys, time, torch
from torchsplice.core.motion import Motion
from torchsplice.core.skeleton import Skeleton
from torchsplice.store.database import MotionDatabase

target, mode = sys.argv[1], sys.argv[2]
sk = Skeleton(["A", "B", "C"], [-1, 0, 1], [[0, 0, 0], [0, 1, 0], [0, 1, 0]],
              [["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"],
               ["Zrotation", "Xrotation", "Yrotation"], ["Zrotation", "Xrotation", "Yrotation"]])
db = MotionDatabase.create(target) if mode == "create" else MotionDatabase.open(target, "a")
rot = torch.zeros(100, 3, 4); rot[..., 0] = 1
for i in range(200):
    db.append(Motion(sk, rot, torch.randn(100, 3), 30.0, name=f"killed{i}"))
db.flush()
print("ready", flush=True)
time.sleep(120)
db.close()
"""


def _run_and_kill(tmp_path: Path, target: Path, mode: str) -> None:
    script = tmp_path / "writer.py"
    script.write_text(textwrap.dedent(WRITER))
    proc = subprocess.Popen([sys.executable, str(script), str(target), mode],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    with reaped(proc):
        line = proc.stdout.readline()
        assert line.strip() == "ready", proc.stderr.read() if proc.poll() is not None else line
        partial = [p for p in target.parent.iterdir() if p.name.startswith(f".{target.name}.partial")]
        assert partial and partial[0].stat().st_size > 0  # it really was writing
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        assert proc.returncode == -signal.SIGKILL


def test_killed_writer_leaves_no_file(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    target = out / "db.h5"
    _run_and_kill(tmp_path, target, "create")
    assert not target.exists()
    # a fresh database can still be written at that path
    with MotionDatabase.create(target) as db:
        db.append(random_clip(chain_skeleton(3), 3, "after", 1))
    with MotionDatabase.open(target) as db:
        assert db.names == ["after"]


def test_killed_appender_leaves_original_intact(db_path, tmp_path, two_skeleton_clips):
    before = db_path.read_bytes()
    _run_and_kill(tmp_path, db_path, "append")
    assert db_path.read_bytes() == before
    with MotionDatabase.open(db_path) as db:
        assert db.names == [m.name for m in two_skeleton_clips]


def _one_line_error(exc_info, path: Path) -> str:
    msg = str(exc_info.value)
    assert "\n" not in msg and msg.strip()
    assert str(path) in msg
    return msg


def test_open_non_hdf5_file(tmp_path):
    p = tmp_path / "notes.h5"
    p.write_text("this is not an HDF5 file\n")
    with pytest.raises(DatabaseError) as ei:
        MotionDatabase.open(p)
    assert "HDF5" in _one_line_error(ei, p)
    with pytest.raises(DatabaseError):
        MotionDatabase.open(p, "a")
    assert p.read_text() == "this is not an HDF5 file\n"
    assert dir_listing(tmp_path) == ["notes.h5"]


def test_open_hdf5_that_is_not_a_database(tmp_path):
    p = tmp_path / "other.h5"
    with h5py.File(p, "w") as f:
        f["data"] = np.arange(10)
    for mode in ("r", "a"):
        with pytest.raises(DatabaseError) as ei:
            MotionDatabase.open(p, mode)
        assert "not a torchsplice motion database" in _one_line_error(ei, p)
    assert dir_listing(tmp_path) == ["other.h5"]


def test_open_missing_file(tmp_path):
    p = tmp_path / "missing.h5"
    for mode in ("r", "a"):
        with pytest.raises(DatabaseError) as ei:
            MotionDatabase.open(p, mode)
        assert "no such file" in _one_line_error(ei, p)
    assert not p.exists()


def test_newer_schema_version_is_refused(db_path):
    with h5py.File(db_path, "r+") as f:
        f.attrs["schema_version"] = SCHEMA_VERSION + 1
    with pytest.raises(DatabaseError) as ei:
        MotionDatabase.open(db_path)
    msg = _one_line_error(ei, db_path)
    assert "schema version" in msg and str(SCHEMA_VERSION + 1) in msg


def test_create_refuses_existing_file_unless_overwrite(db_path):
    before = db_path.read_bytes()
    with pytest.raises(DatabaseError, match="already exists"):
        MotionDatabase.create(db_path)
    assert db_path.read_bytes() == before
    with MotionDatabase.create(db_path, overwrite=True) as db:
        db.append(random_clip(chain_skeleton(3), 2, "only", 1))
    with MotionDatabase.open(db_path) as db:
        assert db.names == ["only"]


def test_read_only_refuses_append(db_path):
    with MotionDatabase.open(db_path) as db:
        with pytest.raises(DatabaseError, match="read-only"):
            db.append(random_clip(chain_skeleton(3), 2, "nope", 1))


# --------------------------------------------------------------------------------------------
# clip-level errors
# --------------------------------------------------------------------------------------------
def test_duplicate_clip_name(tmp_path, db_path):
    sk = chain_skeleton(3)
    with MotionDatabase.create(tmp_path / "x.h5") as db:
        db.append(random_clip(sk, 3, "dup", 1))
        with pytest.raises(DatabaseError, match="dup"):
            db.append(random_clip(sk, 4, "dup", 2))
        db.flush()
        with pytest.raises(DatabaseError, match="dup"):
            db.append(random_clip(branching_skeleton(), 4, "dup", 3))
    with MotionDatabase.open(tmp_path / "x.h5") as db:
        assert db.names == ["dup"] and db.read("dup").num_frames == 3
    with MotionDatabase.open(db_path, "a") as db:  # a name already in the file
        with pytest.raises(DatabaseError, match="a_walk"):
            db.append(random_clip(sk, 4, "a_walk", 2))


def test_unknown_clip_name(db_path):
    with MotionDatabase.open(db_path) as db:
        for call in (db.read, db.clip_info, db.index):
            with pytest.raises(DatabaseError) as ei:
                call("no_such_clip")
            assert "'no_such_clip'" in str(ei.value) and str(db_path) in str(ei.value)
        with pytest.raises(DatabaseError, match="99"):
            db.read(99)
        with pytest.raises(DatabaseError):
            db.read(-1)


@pytest.mark.parametrize("where", ["rotations", "root_translation", "translations"])
def test_nan_clip_refused_on_append(tmp_path, where):
    sk = branching_skeleton()
    m = random_clip(sk, 6, "nan clip", 1)
    getattr(m, where)[3, 1] = float("nan")
    with MotionDatabase.create(tmp_path / "x.h5") as db:
        with pytest.raises(MotionError, match="nan clip"):
            db.append(m)
        assert len(db) == 0
        db.append(random_clip(sk, 2, "good", 2))
    with MotionDatabase.open(tmp_path / "x.h5") as db:
        assert db.names == ["good"]
        assert db.h5["skeletons/0/rotations"].shape[0] == 2


# --------------------------------------------------------------------------------------------
# scale
# --------------------------------------------------------------------------------------------
def test_twenty_thousand_tiny_clips(tmp_path):
    N = 20_000
    sk = chain_skeleton(3)
    clips = tiny_clips(N, sk)
    p = tmp_path / "many.h5"
    t0 = time.perf_counter()
    with MotionDatabase.create(p) as db:
        for m in clips:
            db.append(m)
    t_write = time.perf_counter() - t0
    t0 = time.perf_counter()
    with MotionDatabase.open(p) as db:
        assert len(db) == N
        r = db.read(12_345)
        assert r.name == "clip12345"
        assert torch.equal(r.rotations, clips[12_345].rotations)
        assert torch.equal(r.root_translation, clips[12_345].root_translation)
        assert torch.equal(db.read("clip19999").rotations, clips[-1].rotations)
        assert db.index("clip00007") == 7
        batch = db.read_batch([5, 12_345, 19_999])
        assert torch.equal(batch.rotations[1], clips[12_345].rotations)
    t_read = time.perf_counter() - t0
    assert count_groups(p) <= 5  # /, /skeletons, /skeletons/0, /clips: no group per clip
    # "a few seconds": about 2 s on a laptop when append costs microseconds per clip; the bound
    # leaves room for slow CI machines
    assert t_write + t_read < 10, f"writing {N} clips took {t_write:.1f} s, reopening and reading {t_read:.1f} s"
