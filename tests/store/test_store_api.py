"""The storage package's public reading API (issue: storage behind one package): the typed clip
table, a skeleton's stored spec or a detected one, what is recorded with each skeleton, rows of
a stored frame array. (``tests/project/test_layout.py`` keeps HDF5 inside ``torchsplice.store``.)"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from torchsplice.core.errors import DatabaseError
from torchsplice.specs import load_spec
from torchsplice.store import ClipTable, FrameArray, MotionDatabase, SkeletonInfo

from dataset_clips import branching_skeleton, chain_skeleton, random_clip

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def db_path(tmp_path) -> Path:
    a, b = chain_skeleton(3), branching_skeleton()
    p = tmp_path / "motion.h5"
    with MotionDatabase.create(p, columns={"cost": "float"}) as db:
        db.append(random_clip(a, 10, "walk", 1, role="locomotion", labels={"style": "proud"}), extra={"cost": 1.5})
        db.append(random_clip(b, 7, "wave", 2, role="action", labels={"style": "proud"}))
        db.append(random_clip(a, 5, "run", 3, labels={}))
    return p


def test_the_clip_table_is_typed_with_labels_decoded_and_read_once(db_path):
    with MotionDatabase.open(db_path) as db:
        t = db.clip_table()
        raw = db.table()
        assert db.clip_table() is t and not t.length.flags.writeable  # kept, shared, read-only
    with h5py.File(db_path, "r") as f:  # what the file holds
        stored = {k: f["clips"][k].asstr()[()] if h5py.check_string_dtype(f["clips"][k].dtype) else f["clips"][k][()]
                  for k in f["clips"]}
    assert isinstance(t, ClipTable) and len(t) == 3
    assert t.names == ["walk", "wave", "run"] and t.role.tolist() == ["locomotion", "action", ""]
    assert t.labels == [{"style": "proud"}, {"style": "proud"}, {}]
    assert t.labels[0] is not t.labels[1]  # each row its own dict
    assert t.skeleton.tolist() == [0, 1, 0] and t.start.tolist() == [0, 0, 10] and t.length.tolist() == [10, 7, 5]
    assert t.extra["cost"][0] == 1.5 and np.isnan(t.extra["cost"][1]) and t.kinds == {"cost": "float"}
    assert t.captures() == [("walk", "locomotion", {"style": "proud"}), ("wave", "action", {"style": "proud"}), ("run", "", {})]
    # table() is the stored columns, labels as stored
    assert list(raw) == ["name", "source", "role", "labels", "skeleton", "start", "length", "fps", "cost"]
    assert set(raw) == set(stored)
    assert all(np.array_equal(raw[k], stored[k], equal_nan=raw[k].dtype.kind == "f") for k in raw)
    assert [json.loads(s) for s in raw["labels"]] == t.labels
    part = t.take([2, 0])
    assert part.names == ["run", "walk"] and part.labels == [{}, {"style": "proud"}] and part.extra["cost"][1] == 1.5


def test_labels_that_are_not_an_object_are_one_line_naming_the_clip(db_path):
    with h5py.File(db_path, "r+") as f:
        f["clips/labels"][1] = "[1, 2]"
    with MotionDatabase.open(db_path) as db, pytest.raises(DatabaseError, match="the labels of clip 'wave' are not a JSON object"):
        db.clip_table()


def test_spec_is_the_stored_one_else_a_detected_one(tmp_path, mocap_dir):
    from torchsplice.formats.bvh import read_bvh

    m = read_bvh(mocap_dir / "bandai_namco_research_motiondataset" / "dataset-2_walk_normal_008.bvh")
    p = tmp_path / "specs.h5"
    with MotionDatabase.create(p) as db:
        db.append(m, spec=load_spec("bandai_namco"))
    with MotionDatabase.open(p) as db:
        assert db.stored_spec(0) == load_spec("bandai_namco") and db.spec(0) == load_spec("bandai_namco")
    q = tmp_path / "nospec.h5"
    with MotionDatabase.create(q) as db:
        db.append(m)
    with MotionDatabase.open(q) as db:
        assert db.stored_spec(0) is None and db.spec(0).name == "bandai_namco"  # detected from the joint names


def test_skeleton_info_and_frame_arrays(db_path):
    with MotionDatabase.open(db_path) as db:
        i0, i1 = db.skeleton_info(0), db.skeleton_info(1)
        assert isinstance(i0, SkeletonInfo) and i0.id == 0 and i0.skeleton is db.skeletons[0]
        assert (i0.units, i0.up_axis, i0.spec_json, i0.spec_name) == ("", "", "", "")
        assert i0.frame_arrays == ("rotations", "root_translation") and i0.dtype == np.float32
        assert "translations" in i1.frame_arrays
        rot = db.frame_array(0, "rotations")
        assert isinstance(rot, FrameArray) and rot.shape == (15, 3, 4) and len(rot) == 15
        walk, run = db.read("walk"), db.read("run")
        assert np.array_equal(rot[0:10], walk.rotations.numpy())
        got = rot.gather(np.array([10, 0]), np.array([5, 10]))
        assert np.array_equal(got, np.concatenate([run.rotations.numpy(), walk.rotations.numpy()]))
        with pytest.raises(DatabaseError, match="stores no per-frame array 'translations'"):
            db.frame_array(0, "translations")
        assert "walk" in db and "nope" not in db and 0 not in db


def test_a_clip_table_kept_is_read_again_once_clips_are_added(tmp_path):
    a = chain_skeleton(3)
    with MotionDatabase.create(tmp_path / "grow.h5") as db:
        db.append(random_clip(a, 10, "walk", 1))
        first = db.clip_table()
        db.append(random_clip(a, 5, "run", 2))
        assert db.clip_table().names == ["walk", "run"] and first.names == ["walk"]
    assert ClipTable.take(first, []).names == []  # an empty selection


def test_virtual_clips_are_checked_like_packed_ones(tmp_path):
    a = chain_skeleton(3)
    with MotionDatabase.create(tmp_path / "src.h5") as db:
        db.append(random_clip(a, 10, "walk", 1))
    out = tmp_path / "virtual.h5"
    with pytest.raises(DatabaseError, match="2 clip names need 2 lengths of at least one frame, got 3"):
        with MotionDatabase.create(out) as db:
            db.append_virtual(tmp_path / "src.h5", a, [4, 3, 3], ["x", "y"], 30.0)
    with pytest.raises(DatabaseError, match="no extra column 'nope' was declared"):
        with MotionDatabase.create(out, overwrite=True) as db:
            db.append_virtual(tmp_path / "src.h5", a, [10], ["x"], 30.0, extra={"nope": [1]})


def test_a_resumable_databases_table_is_written_in_blocks_as_it_was_appended(tmp_path, monkeypatch):
    """The clip table of a resumable database (the job's output) goes from its row log into the
    file a block of rows at a time at close; several blocks give the table one block gives."""
    from torchsplice.store.writing import Writing

    a = chain_skeleton(3)
    tables = []
    original = Writing._write_logged_rows
    for block in (2, 1 << 17):
        monkeypatch.setattr(Writing, "_write_logged_rows", lambda self, b=block: original(self, b))
        path = tmp_path / f"resumable-{block}.h5"
        with MotionDatabase.create(path, staging=tmp_path / f".stage-{block}", columns={"cost": "float"}) as db:
            for i in range(7):
                db.append(random_clip(a, 3 + i, f"clip{i}", i, labels={"i": i}), extra={"cost": 0.5 * i})
                db.checkpoint({"step": i})
        with MotionDatabase.open(path) as db:
            tables.append(db.table())
    assert tables[0]["name"].tolist() == [f"clip{i}" for i in range(7)]
    for col in tables[1]:
        x, y = np.asarray(tables[0][col]), np.asarray(tables[1][col])
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), col
