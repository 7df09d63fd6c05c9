"""A damaged database gives one line ``torchsplice: error: ...`` naming the file, never a traceback
(issue 10): every command that reads a database, on copies of a good one damaged with h5py."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from torchsplice import splice_all
from torchsplice.cli import main
from torchsplice.core.errors import DatabaseError
from torchsplice.store.database import MotionDatabase

LOCO, ACTION = "walk_straight", "wave"
_STR = h5py.string_dtype()


# --------------------------------------------------------------------------------------------
# damage, one function per case: each takes the path of a copy and damages it in place
# --------------------------------------------------------------------------------------------
def _attrs(path, target, key, value):
    with h5py.File(path, "r+") as f:
        f[target].attrs[key] = value


def _edit(path, name, change):
    """Replace dataset ``name`` by ``change(its values)`` (strings as str)."""
    with h5py.File(path, "r+") as f:
        ds = f[name]
        values = ds.asstr()[()] if h5py.check_string_dtype(ds.dtype) else ds[()]
        new = change(values)
        del f[name]
        f[name] = np.array(new, dtype=object).astype(_STR) if new.dtype.kind in "OU" else new


def _set(name, row, value):
    def damage(path):
        def change(v):
            v = v.copy()
            v[row] = value
            return v
        _edit(path, name, change)
    return damage


def _delete(name):
    def damage(path):
        with h5py.File(path, "r+") as f:
            del f[name]
    return damage


def _shorten(name):
    return lambda path: _edit(path, name, lambda v: v[:-1])


def _declare(kind, column):
    def damage(path):
        with h5py.File(path, "r+") as f:
            extra = json.loads(f.attrs["extra_columns"])
            if kind == "clip":
                extra["clip"][column] = "float"
            else:
                extra["frame"].append(column)
            f.attrs["extra_columns"] = json.dumps(extra)
    return damage


def _past_end(path):
    with h5py.File(path, "r+") as f:
        f["clips/length"][-1] = f["clips/length"][-1] + 1000


def _wrong_joints(path):
    _edit(path, "skeletons/0/rotations", lambda v: np.ascontiguousarray(v[:, :-1]))


def _flip_bytes(name):
    """Flip bytes in the middle of the first (compressed) chunk of dataset ``name``."""
    def damage(path):
        with h5py.File(path, "r") as f:
            ds = f[name]
            assert ds.compression is not None
            info = ds.id.get_chunk_info(0)
        with open(path, "r+b") as fh:
            fh.seek(info.byte_offset + info.size // 2)
            raw = fh.read(min(64, info.size // 4))
            fh.seek(info.byte_offset + info.size // 2)
            fh.write(bytes(b ^ 0xFF for b in raw))
        with h5py.File(path, "r") as f, pytest.raises(OSError):
            f[name][:8]  # the damage really breaks reading
    return damage


CASES = {  # name: (damage, a word the error line must hold)
    "schema_version_text": (lambda p: _attrs(p, "/", "schema_version", "one"), "schema"),
    "schema_version_array": (lambda p: _attrs(p, "/", "schema_version", [1, 1]), "schema"),
    "extra_columns_not_json": (lambda p: _attrs(p, "/", "extra_columns", "{clip: [oops" + "x" * 500), "extra_columns"),
    "extra_columns_wrong_kind": (lambda p: _attrs(p, "/", "extra_columns", json.dumps({"clip": {"a": "blob"}})), "extra_columns"),
    "spec_not_json": (lambda p: _attrs(p, "skeletons/0", "spec", "not json {"), "spec"),
    "unknown_channel": (_set("skeletons/0/channels", 2, "Xrotation Wobble Zrotation"), "channels"),
    "parent_out_of_range": (_set("skeletons/0/parents", 3, 99), "parent"),
    "parent_not_topological": (_set("skeletons/0/parents", 1, 5), "parent"),
    "two_roots": (_set("skeletons/0/parents", 4, -1), "root"),
    "end_site_parent_out_of_range": (_set("skeletons/0/end_site_parents", 0, 99), "End Site"),
    "no_names": (_delete("skeletons/0/names"), "names"),
    "no_rotations": (_delete("skeletons/0/rotations"), "rotations"),
    "no_root_translation": (_delete("skeletons/0/root_translation"), "root_translation"),
    "rotations_wrong_joints": (_wrong_joints, "rotations"),
    "short_name": (_shorten("clips/name"), "rows"),
    "short_labels": (_shorten("clips/labels"), "clips/labels"),
    "short_fps": (_shorten("clips/fps"), "clips/fps"),
    "short_start": (_shorten("clips/start"), "clips/start"),
    "short_length": (_shorten("clips/length"), "clips/length"),
    "short_skeleton": (_shorten("clips/skeleton"), "clips/skeleton"),
    "no_labels": (_delete("clips/labels"), "clips/labels"),
    "no_fps": (_delete("clips/fps"), "clips/fps"),
    "no_clips_group": (_delete("clips"), "clips"),
    "declared_column_missing": (_declare("clip", "ghost"), "ghost"),
    "declared_frame_column_missing": (_declare("frame", "ghost_frames"), "ghost_frames"),
    "no_such_skeleton": (_set("clips/skeleton", 1, 7), "skeleton 7"),
    "negative_start": (_set("clips/start", 0, -5), "start"),
    "past_the_end": (_past_end, "frames"),
    "zero_fps": (_set("clips/fps", 0, 0.0), "fps"),
    "labels_not_json": (lambda p: _edit(p, "clips/labels", lambda v: np.array(["{oops"] * len(v), dtype=object)), "labels"),
    "flipped_bytes": (_flip_bytes("skeletons/0/rotations"), "cannot read"),
}
MORE = {"flipped_action_frame": _flip_bytes("skeletons/0/action_frame")}  # a splice-all output's per-frame column

COMMANDS = {  # name: (database it damages, argv after the database path; OUT is the output)
    "info": ("sample", ["info", "DB"]),
    "info-json": ("sample", ["info", "DB", "--json"]),
    "export": ("sample", ["export", "DB", LOCO, "-o", "OUT.bvh", "-q"]),
    "splice": ("sample", ["splice", "DB", "--locomotion", LOCO, "--action", ACTION, "-o", "OUT.bvh", "-q"]),
    "splice-all": ("sample", ["splice-all", "DB", "-o", "OUT.h5", "--workers", "1", "-q"]),
    "render": ("sample", ["render", "DB", LOCO, "-o", "OUT.png", "-q"]),
    "view": ("sample", ["view", "DB", LOCO, "-o", "OUT.html", "-q"]),
    "evaluate": ("spliced", ["evaluate", "DB", "-o", "OUT.md", "--no-pictures", "-q"]),
}
# info reads no frame data, so a damaged frame chunk is for the commands that read frames
_SKIP = {("flipped_bytes", "info"), ("flipped_bytes", "info-json")}


@pytest.fixture(scope="module")
def good(sample_db, tmp_path_factory) -> dict[str, Path]:
    """The session's sample database and a small splice_all output of it (gzip: damage breaks a
    chunk); both only read and copied."""
    spliced = tmp_path_factory.mktemp("good") / "spliced.h5"
    splice_all(sample_db, spliced, workers=1, compression="gzip", locomotions=f"{LOCO},jog",
               actions=f"{ACTION},punch", methods="naive")
    return {"sample": sample_db, "spliced": spliced}


@pytest.fixture(scope="module")
def damaged(good, tmp_path_factory):
    """``damaged(case, kind)``: a damaged copy of a good database, made once per module."""
    d = tmp_path_factory.mktemp("damaged")
    made: dict[tuple[str, str], Path] = {}

    def get(case: str, kind: str) -> Path:
        if (case, kind) not in made:
            p = d / f"db{len(made)}.h5"  # a neutral name: the error line must say what is wrong
            shutil.copyfile(good[kind], p)
            (MORE[case] if case in MORE else CASES[case][0])(p)
            made[case, kind] = p
        return made[case, kind]

    return get


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("case", list(CASES))
def test_damaged_database_gives_one_line(case, command, damaged, tmp_path, capsys, request):
    if (case, command) in _SKIP:
        pytest.skip("this command reads no frames")
    kind, argv = COMMANDS[command]
    db = damaged(case, kind)
    out = None
    args = []
    for a in argv:
        if a == "DB":
            a = str(db)
        elif a.startswith("OUT"):
            out = tmp_path / f"out{a[3:]}"
            a = str(out)
        args.append(a)
    capsys.readouterr()
    rc = main(args)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert rc == 2, err
    assert "Traceback" not in err
    assert len(lines) == 1 and lines[0].startswith("torchsplice: error: "), err
    assert str(db) in lines[0], lines[0]
    assert CASES[case][1].lower() in lines[0].replace(str(db), "").lower(), lines[0]
    assert len(lines[0]) < 400, lines[0]
    if out is not None:
        assert not out.exists()
        assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(f".{out.name}.partial")]


def test_open_names_the_first_problem(damaged):
    with pytest.raises(DatabaseError) as e:
        MotionDatabase.open(damaged("short_fps", "sample"))
    msg = str(e.value)
    assert msg.endswith("damaged database: clips/fps has 9 rows, clips/name 10"), msg
    with pytest.raises(DatabaseError, match=r"clip 'walk_straight' starts at row -5"):
        MotionDatabase.open(damaged("negative_start", "sample"))
    with pytest.raises(DatabaseError, match=r"not valid JSON \('\{clip: \[oopsxxx[x]*\.\.\.'\)"):
        MotionDatabase.open(damaged("extra_columns_not_json", "sample"))


@pytest.mark.parametrize("reader", ["read", "read_many", "read_batch", "batches", "packed", "read_frame_column"])
def test_every_read_path_maps_a_damaged_chunk(reader, damaged):
    p = damaged("flipped_action_frame" if reader == "read_frame_column" else "flipped_bytes", "spliced")
    with MotionDatabase.open(p) as db:
        first = db.names[0]
        calls = {
            "read": lambda: db.read(first),
            "read_many": lambda: db.read_many([first]),
            "read_batch": lambda: db.read_batch([first]),
            "batches": lambda: list(db.batches()),
            "packed": lambda: db.packed(0),
            "read_frame_column": lambda: db.read_frame_column(first, "action_frame"),
        }
        with pytest.raises(DatabaseError) as e:
            calls[reader]()
    msg = str(e.value)
    assert str(p) in msg and "cannot read" in msg and ("packed" == reader or repr(first) in msg), msg
    assert "\n" not in msg


def test_missing_shards_of_a_virtual_output_are_named(good, tmp_path):
    """HDF5 reads the frames of a missing virtual source as NaN without a word: open says so (and
    ``info`` in one line: tests/cli/test_command_words.py)."""
    out = tmp_path / "virtual.h5"
    splice_all(good["sample"], out, workers=1, layout="virtual", locomotions=LOCO, actions=ACTION, methods="naive")
    with MotionDatabase.open(out) as db:
        assert len(db) >= 1
    (tmp_path / "virtual.h5.shards").rename(tmp_path / "elsewhere")
    with pytest.raises(DatabaseError, match="missing") as caught:
        MotionDatabase.open(out)
    line = str(caught.value)
    assert "\n" not in line and line.startswith(f"{out}: ") and "virtual.h5.shards/" in line


def test_open_stays_fast_on_many_clips(tmp_path):
    from torchsplice.core.skeleton import Skeleton

    C, T = 100_000, 2
    ch = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    sk = Skeleton(["A", "B"], [-1, 0], [[0, 0, 0], [0, 1, 0]], [ch, ch[3:]])
    rot = np.zeros((C * T, 2, 4), np.float32)
    rot[..., 0] = 1
    p = tmp_path / "many.h5"
    with MotionDatabase.create(p, compression="lzf") as db:
        db.append_packed(sk, rot, np.zeros((C * T, 3), np.float32), None, np.full(C, T),
                         [f"c{i}" for i in range(C)], 30.0, check=False)
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        with MotionDatabase.open(p) as db:
            assert len(db) == C
        best = min(best, time.perf_counter() - t0)
    assert best < 0.25, f"opening {C} clips took {best:.3f} s"
