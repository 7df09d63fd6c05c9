"""Damaged alignment stores are refused in one line naming the file, never read as motions:
source rows overwritten with NaN or infinity, a bank chunk that does not decompress, a
per-frame part overwritten with NaN (``materialize``), and a root ``store`` attribute that
disagrees with the layout (deleted, ``motion``, or neither kind). ``materialize`` then leaves no
output. Each copy is the built-in sample's alignment store with one thing damaged through h5py."""

from __future__ import annotations

import shutil

import h5py
import numpy as np
import pytest

from cli_helpers import error_line, run
from torchsplice.core.errors import DatabaseError
from torchsplice.job import splice_all
from torchsplice.job.materialize import materialize
from torchsplice.store.database import MotionDatabase
from torchsplice.store import assembly

BANK = "assembly/banks/0"


@pytest.fixture(scope="module")
def store(sample_db, tmp_path_factory):
    """The sample's alignment store (splice, naive and cpmc; one bank), and its bank's clips."""
    out = tmp_path_factory.mktemp("damage") / "a.h5"
    splice_all(sample_db, out, store="alignment", methods="splice,naive,cpmc", index=False, workers=1)
    with h5py.File(out, "r") as f:
        g = f[BANK]
        clips = {str(n): (int(s), int(k)) for n, s, k in zip(g["names"].asstr()[()], g["starts"][()], g["lengths"][()])}
    return out, clips


def _copy(store, tmp_path, name: str):
    path = tmp_path / f"{name}.h5"
    shutil.copy(store[0], path)
    return path


def _refused(path, capsys, tmp_path) -> str:
    """The one line every reader gives: the API's read, ``materialize`` (no output left) and the
    command line's ``materialize`` and ``export``."""
    with MotionDatabase.open(path) as db:
        with pytest.raises(DatabaseError) as caught:
            db.read(0)
    line = str(caught.value)
    assert "\n" not in line and line.startswith(f"{path}: damaged alignment store: ")
    out = tmp_path / "motions.h5"
    with pytest.raises(DatabaseError) as again:
        materialize(path, out)
    assert str(again.value) == line and not out.exists()
    rc, _, err = run(capsys, "materialize", path, "-o", out)
    assert rc == 2 and error_line(err) == f"torchsplice: error: {line}" and not out.exists()
    rc, _, err = run(capsys, "export", path, "--all", "-o", tmp_path / "bvh", "--format", "bvh")
    assert rc == 2 and error_line(err) == f"torchsplice: error: {line}" and not (tmp_path / "bvh").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]
    return line


@pytest.mark.parametrize("array, value, clip, frame", [("rotations", np.nan, "walk_curve", 3),
                                                       ("translations", np.inf, "wave", 0),
                                                       ("rotations", -np.inf, "arms_out", 7)])
def test_a_source_row_that_is_not_finite_is_refused_naming_the_bank_and_clip(store, tmp_path, capsys, array, value,
                                                                             clip, frame):
    path = _copy(store, tmp_path, "damaged")
    start, _ = store[1][clip]
    with h5py.File(path, "r+") as f:
        a = f[f"{BANK}/{array}"][()]
        a[start + frame, 1] = value
        f[f"{BANK}/{array}"][...] = a
    line = _refused(path, capsys, tmp_path)
    assert line == (f"{path}: damaged alignment store: bank 0 ({BANK}) holds non-finite {array} in source clip "
                    f"{clip!r} at its frame {frame}")


def test_a_whole_source_clip_of_nan_is_refused(store, tmp_path, capsys):
    path = _copy(store, tmp_path, "nan_clip")
    start, length = store[1]["jog"]
    with h5py.File(path, "r+") as f:
        a = f[f"{BANK}/rotations"][()]
        a[start:start + length] = np.nan
        f[f"{BANK}/rotations"][...] = a
    assert _refused(path, capsys, tmp_path).endswith("holds non-finite rotations in source clip 'jog' at its frame 0")


def test_a_bank_chunk_that_does_not_decompress_is_refused_naming_its_rows(store, tmp_path, capsys):
    path = _copy(store, tmp_path, "flipped")
    with h5py.File(path, "r") as f:
        ds = f[f"{BANK}/rotations"]
        assert ds.chunks[0] < ds.shape[0]  # (more than one chunk: the damaged one is named)
        info = ds.id.get_chunk_info(1)
    with open(path, "r+b") as raw:
        raw.seek(info.byte_offset)
        raw.write(b"\xff" * info.size)
    lo = info.chunk_offset[0]
    clip = next(n for n, (s, k) in store[1].items() if s <= lo < s + k)
    line = _refused(path, capsys, tmp_path)
    assert line.startswith(f"{path}: damaged alignment store: bank 0 ({BANK}) cannot be read from source clip "
                           f"{clip!r} on (rows {lo}:")


def test_a_damaged_per_frame_part_is_refused_by_every_read_naming_the_clip(store, tmp_path, capsys):
    path = _copy(store, tmp_path, "curve")
    with MotionDatabase.open(store[0]) as db:
        t = db.clip_table()
        kinds = db.h5["clips/assembly_kind"][()]
    row = int(np.flatnonzero(kinds == 1)[2])  # a timewarp clip's curve, its frame 5
    with h5py.File(path, "r+") as f:
        curve = f["skeletons/0/assembly_curve"]
        v = curve[()]
        v[int(t.start[row]) + 5] = np.nan
        curve[...] = v
    out = tmp_path / "motions.h5"
    with pytest.raises(DatabaseError) as caught:
        materialize(path, out)
    assert str(caught.value) == (f"{path}: damaged alignment store: clip {t.names[row]!r} has a NaN in its curve at "
                                 "its frame 5")  # refused before the kernels index the action with it
    assert not out.exists()
    with MotionDatabase.open(path) as db:  # every read of the clip, by either assembly
        for read in (lambda: db.read(t.names[row]), lambda: db.assembled_on(0, t.start[row:row + 1],
                                                                            t.length[row:row + 1], "cpu")):
            with pytest.raises(DatabaseError, match="has a NaN in its curve at its frame 5"):
                read()
        other = int(np.flatnonzero(kinds == 1)[0])
        for _ in range(assembly.HOLD_AFTER_READS + 1):  # and every later one, once the store's parts are held
            with pytest.raises(DatabaseError, match="has a NaN in its curve at its frame 5"):
                db.read(t.names[row])
            db.read(t.names[other])  # another timewarp clip reads as ever
    rc, _, err = run(capsys, "materialize", path, "-o", out)
    assert rc == 2 and error_line(err) == f"torchsplice: error: {caught.value}" and not out.exists()


def test_a_part_that_assembles_to_non_finite_frames_is_refused_by_every_read(store, tmp_path):
    """A damaged pelvis rotation: the clip's frames would be NaN; every compiled read (so
    ``materialize`` too) refuses them in one line naming the clip and the frame."""
    path = _copy(store, tmp_path, "pelvis")
    with MotionDatabase.open(store[0]) as db:
        t = db.clip_table()
        kinds = db.h5["clips/assembly_kind"][()]
    row = int(np.flatnonzero(kinds == 1)[1])
    with h5py.File(path, "r+") as f:
        pelvis = f["skeletons/0/assembly_pelvis"]
        v = pelvis[()]
        v[int(t.start[row]) + 7] = np.nan
        pelvis[...] = v
    want = f"{path}: damaged alignment store: clip {t.names[row]!r} assembles to non-finite rotations at its frame 7"
    with MotionDatabase.open(path) as db:
        with pytest.raises(DatabaseError) as caught:
            db.read(t.names[row])
        assert str(caught.value) == want
        db.read(t.names[int(np.flatnonzero(kinds == 1)[0])])  # another clip reads as ever
    with pytest.raises(DatabaseError, match="assembles to non-finite rotations at its frame 7"):
        materialize(path, tmp_path / "motions.h5")
    assert not (tmp_path / "motions.h5").exists()


@pytest.mark.parametrize("attribute", [None, "motion", "alignmnet"])
def test_a_store_attribute_that_disagrees_with_the_layout_is_refused_at_open(store, tmp_path, capsys, attribute):
    path = _copy(store, tmp_path, "attribute")
    with h5py.File(path, "r+") as f:
        assert f.attrs["schema_version"] == 2
        if attribute is None:
            del f.attrs["store"]
        else:
            f.attrs["store"] = attribute
    with pytest.raises(DatabaseError) as caught:
        MotionDatabase.open(path)
    said = {None: "is missing", "motion": "says 'motion'"}
    want = (f"{path}: damaged database: its store attribute is 'alignmnet', neither motion nor alignment"
            if attribute == "alignmnet" else
            f"{path}: damaged database: it holds an alignment store's assembly/banks but its store "
            f"attribute {said[attribute]} (an alignment store's says 'alignment'; as a motion store its spliced "
            "clips would read as zeros)")
    assert str(caught.value) == want
    for argv in (["info", path], ["export", path, "--all", "-o", tmp_path / "out", "--format", "bvh"]):
        rc, out, err = run(capsys, *argv)
        assert rc == 2 and error_line(err) == f"torchsplice: error: {want}" and out == "", argv
    assert not (tmp_path / "out").exists()


def test_clip_parts_without_banks_and_without_the_attribute_are_refused(store, tmp_path):
    path = _copy(store, tmp_path, "parts")
    with h5py.File(path, "r+") as f:
        del f.attrs["store"]
        del f["assembly"]
    with pytest.raises(DatabaseError, match=r"it holds an alignment store's clip parts \(clips/assembly_\*\) but its "
                                            r"store attribute is missing"):
        MotionDatabase.open(path)


def test_an_undamaged_store_still_reads_and_a_motion_store_has_no_store_attribute(store, sample_db):
    with MotionDatabase.open(store[0]) as db:
        assert db.store == "alignment" and np.isfinite(db.read(0).rotations.numpy()).all()
    with MotionDatabase.open(sample_db) as db:
        assert db.store == "motion" and "store" not in db.attrs


def test_every_read_of_a_damaged_store_is_refused_not_only_the_first(store, tmp_path):
    path = _copy(store, tmp_path, "twice")
    start, _ = store[1]["wave"]
    with h5py.File(path, "r+") as f:
        a = f[f"{BANK}/rotations"][()]
        a[start + 2] = np.nan
        f[f"{BANK}/rotations"][...] = a
    with MotionDatabase.open(path) as db:
        for read in (lambda: db.read(0), lambda: db.read(1), lambda: db.packed(0), lambda: next(iter(db.batches(batch_size=4)))):
            with pytest.raises(DatabaseError, match="holds non-finite rotations in source clip 'wave' at its frame 2"):
                read()
