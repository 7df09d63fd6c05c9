"""Exports (``export_clips``; ``torchsplice export`` for its one-line mistakes) to NumPy .npz (per clip and packed, with 6D features and statistics),
several clips to BVH, and ``MotionDataset``'s ``labels`` feature and ``statistics``.

On real clips: Bandai Namco (two capture sessions: two skeletons of one topology, a trajectory
joint ``Hips`` under a still ``joint_Root``, animated joint translations) and a CMU clip (another
topology), imported in centimetres. Round trips read back what the database holds; positions
match forward kinematics; packed offsets slice back each clip; statistics equal a brute-force
NumPy computation from independently computed features.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from realdata import BANDAI
from torchsplice.cli.common import cli_message
from torchsplice.core.errors import OutputExistsError, TorchspliceError
from torchsplice.core.rotations import quat_to_6d, quat_to_rotmat, random_quat, rotation_6d_to_rotmat
from torchsplice.data import MotionDataset, collate_motion
from torchsplice.formats.bvh import read_bvh
from torchsplice.formats.exporters import export_clips
from torchsplice.formats.importer import import_bvh
from torchsplice.store.database import MotionDatabase
from torchsplice.formats.npz import NpzExport, clip_of_packed, read_npz, write_npz
from torchsplice.core.fk import forward_kinematics
from cli_helpers import run, error_line
from writers import nan_copy

F64 = torch.float64
CLIPS = ["dataset-1_walk_proud_001", "dataset-1_bye_normal_001", "dataset-2_walk_normal_008",
         "dataset-2_wave-left-hand_normal_001", "dataset-2_walk-turn-left_normal_025"]


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".") or "partial" in p.name)


@pytest.fixture(scope="module")
def db(mocap_dir, tmp_path_factory) -> Path:
    """Five Bandai Namco clips (skeletons of both sessions) and the CMU walk, in centimetres."""
    folder = mocap_dir / BANDAI
    files = [folder / f"{n}.bvh" for n in CLIPS if (folder / f"{n}.bvh").is_file()]
    assert len(files) == len(CLIPS)
    out = tmp_path_factory.mktemp("npz") / "mixed.h5"
    assert import_bvh([*files, mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh"], out, units="cm").ok
    return out


@pytest.fixture(scope="module")
def bandai_names(db) -> list[str]:
    with MotionDatabase.open(db) as d:
        return [n for n in d.names if n.startswith("dataset-")]


def clip_fk(m) -> torch.Tensor:
    """``(T, J, 3)`` float64 world positions of a database clip."""
    m = m.to(F64)
    return forward_kinematics(m.rotations, m.root_translation, m.skeleton.offsets, m.skeleton.parents, m.translations)[0]


# --------------------------------------------------------------------------------------------
# per clip
# --------------------------------------------------------------------------------------------
def test_per_clip_npz_reads_back_the_database_and_positions_are_fk(db, tmp_path):
    out = tmp_path / "clips"
    msg = export_clips(db, None, format="npz", out=out).summary
    with MotionDatabase.open(db) as d:
        index = ["index.csv", "test.txt", "train.txt", "val.txt"]  # beside every export of several clips
        assert sorted(p.name for p in out.iterdir()) == sorted([f"{n}.npz" for n in d.names] + index)
        for name in d.names:
            z = read_npz(out / f"{name}.npz")
            m = d.read(name)
            info = d.clip_info(name)
            assert z["layout"] == "clip" and z["name"] == name and z["role"] == m.role and z["labels"] == m.labels
            assert z["fps"] == m.fps and z["units"] == "cm" and z["up_axis"] == "y"
            assert list(z["joint_names"]) == list(m.skeleton.names) and z["parents"].tolist() == list(m.skeleton.parents)
            np.testing.assert_array_equal(z["joint_offsets"], m.skeleton.offsets.numpy())
            np.testing.assert_array_equal(z["end_site_offsets"], m.skeleton.end_site_offsets.numpy())
            assert z["rotations"].dtype == np.float32 and z["rotations"].shape == (info["length"], m.skeleton.num_joints, 4)
            np.testing.assert_array_equal(z["rotations"], m.rotations.numpy())
            np.testing.assert_array_equal(z["root_translation"], m.root_translation.numpy())
            np.testing.assert_array_equal(z["translations"], m.local_translations().numpy())
            # positions: FK of the file's own arrays, and of the database clip
            pos = forward_kinematics(torch.from_numpy(z["rotations"]).double(), torch.from_numpy(z["root_translation"]).double(),
                                     torch.from_numpy(z["joint_offsets"]), z["parents"].tolist(),
                                     torch.from_numpy(z["translations"]).double())[0]
            np.testing.assert_allclose(z["positions"], pos.numpy(), rtol=0, atol=1e-3)
            np.testing.assert_allclose(z["positions"], clip_fk(m).numpy(), rtol=0, atol=1e-3)
            j = z["trajectory_joint"]
            assert m.skeleton.names[j] == "Hips"
            if name.startswith("dataset-"):  # Bandai Namco: Hips, under a joint_Root that stands still
                assert m.skeleton.names[0] == "joint_Root" and j != 0 and not z["root_translation"].any()
            else:  # CMU: the BVH root
                assert j == 0
            np.testing.assert_array_equal(z["trajectory"], z["positions"][:, j])
            assert "rotations_6d" not in z and "positions_mean" not in z
    assert leftovers(out) == [] and leftovers(tmp_path) == []
    assert f"{len(list(out.glob('*.npz')))} clips as .npz" in msg


def test_one_clip_to_a_file_and_to_a_folder(db, bandai_names, tmp_path):
    name = bandai_names[0]
    assert export_clips(db, [name], out=tmp_path / "one.npz").format == "npz"  # the format from the suffix
    (tmp_path / "f").mkdir()
    assert export_clips(db, [name], out=tmp_path / "f", format="npz").files == [tmp_path / "f" / f"{name}.npz"]
    a, b = read_npz(tmp_path / "one.npz"), read_npz(tmp_path / "f" / f"{name}.npz")
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a if isinstance(a[k], np.ndarray))


# --------------------------------------------------------------------------------------------
# packed
# --------------------------------------------------------------------------------------------
def test_packed_offsets_slice_back_each_clip_in_the_order_asked(db, bandai_names, tmp_path):
    names = bandai_names[::-1]  # not row order
    export_clips(db, names, out=tmp_path / "p.npz", packed=True)
    p = read_npz(tmp_path / "p.npz")
    assert p["layout"] == "packed" and list(p["names"]) == names
    with MotionDatabase.open(db) as d:
        lengths = [d.clip_info(n)["length"] for n in names]
        assert p["offsets"].tolist() == [0, *np.cumsum(lengths).tolist()] and p["offsets"].dtype == np.int64
        assert len(p["offsets"]) == len(names) + 1 and p["rotations"].shape[0] == p["offsets"][-1]
        assert len({d.clip_info(n)["skeleton"] for n in names}) == 2  # two skeletons of one topology pack together
        for i, n in enumerate(names):
            c = clip_of_packed(p, i)
            m = d.read(n)
            assert c["name"] == n and c["fps"] == m.fps and c["labels"] == m.labels and c["role"] == m.role
            np.testing.assert_array_equal(c["rotations"], m.rotations.numpy())
            np.testing.assert_array_equal(c["translations"], m.local_translations().numpy())
            np.testing.assert_array_equal(c["joint_offsets"], m.skeleton.offsets.numpy())
            np.testing.assert_allclose(c["positions"], clip_fk(m).numpy(), rtol=0, atol=1e-3)
            np.testing.assert_array_equal(c["trajectory"], c["positions"][:, p["trajectory_joint"]])
            np.testing.assert_array_equal(p["end_site_offsets"][i], m.skeleton.end_site_offsets.numpy())
            assert p["skeleton"][i] == d.clip_info(n)["skeleton"]
    # the per-clip files hold the same frames
    export_clips(db, names, out=tmp_path / "each", format="npz")
    for i, n in enumerate(names):
        one, c = read_npz(tmp_path / "each" / f"{n}.npz"), clip_of_packed(p, i)
        for k in ("rotations", "root_translation", "trajectory", "translations", "positions"):
            np.testing.assert_array_equal(one[k], c[k])


def test_clips_of_different_skeletons_are_not_packed(db, tmp_path):
    with pytest.raises(TorchspliceError, match="cannot pack clips of different skeletons") as caught:
        export_clips(db, None, out=tmp_path / "p.npz", packed=True)
    line = str(caught.value)
    assert "cmu" in line and "\n" not in line
    assert "skeletons with one id" in line  # export_clips' own keyword
    assert cli_message(caught.value).count("--skeleton with one id") == 1  # the command line's flag
    assert not (tmp_path / "p.npz").exists() and leftovers(tmp_path) == []
    with pytest.raises(TorchspliceError, match="feature statistics"):
        export_clips(db, None, out=tmp_path / "f", features="6d")
    assert not (tmp_path / "f").exists()
    with MotionDatabase.open(db) as d:
        k = d.clip_info("cmu_12_01_walk")["skeleton"]
    export_clips(db, None, out=tmp_path / "cmu.npz", packed=True, skeletons=[k])
    assert list(read_npz(tmp_path / "cmu.npz")["names"]) == ["cmu_12_01_walk"]


# --------------------------------------------------------------------------------------------
# features and statistics
# --------------------------------------------------------------------------------------------
def numpy_6d(q: np.ndarray) -> np.ndarray:
    """First two columns of the rotation matrix of WXYZ quaternions, written out by hand."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    c0 = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)], -1)
    c1 = np.stack([2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)], -1)
    return np.concatenate([c0, c1], -1)


def numpy_velocity(x: np.ndarray, fps: float) -> np.ndarray:
    v = np.zeros_like(x)
    v[1:] = np.diff(x, axis=0) * fps
    v[0] = v[1] if len(x) > 1 else 0
    return v


def test_feature_statistics_equal_a_brute_force_numpy_computation(db, bandai_names, tmp_path):
    export_clips(db, bandai_names, out=tmp_path / "p.npz", packed=True, features="6d")
    p = read_npz(tmp_path / "p.npz")
    feats: dict[str, list[np.ndarray]] = {}
    with MotionDatabase.open(db) as d:
        for n in bandai_names:
            m = d.read(n, dtype=F64)
            pos = clip_fk(m).numpy()
            j = int(p["trajectory_joint"])
            one = {"rotations": m.rotations.numpy(), "root_translation": m.root_translation.numpy(),
                   "translations": m.local_translations().numpy(), "positions": pos, "trajectory": pos[:, j],
                   "rotations_6d": numpy_6d(m.rotations.numpy()), "velocities": numpy_velocity(pos, m.fps),
                   "trajectory_velocity": numpy_velocity(pos[:, j], m.fps),
                   "root_velocity": numpy_velocity(m.root_translation.numpy(), m.fps)}
            for k, v in one.items():
                feats.setdefault(k, []).append(v)
    assert p["statistics_frames"] == p["offsets"][-1] and p["statistics_clips"] == len(bandai_names)
    for k, parts in feats.items():
        x = np.concatenate(parts)
        assert p[f"{k}_mean"].dtype == np.float64 and p[f"{k}_mean"].shape == x.shape[1:]
        np.testing.assert_allclose(p[f"{k}_mean"], x.mean(0), rtol=1e-9, atol=1e-9, err_msg=k)
        np.testing.assert_allclose(p[f"{k}_std"], x.std(0), rtol=1e-9, atol=1e-9, err_msg=k)
        # the exported feature arrays themselves
        np.testing.assert_allclose(p[k], x, rtol=1e-5, atol=2e-3 if k in ("positions", "trajectory") else 2e-2)
    assert (p["root_translation_std"] == 0).all()  # joint_Root stands still: a dimension to leave unscaled
    # per-clip files carry the same statistics, over the whole exported set
    export_clips(db, bandai_names, out=tmp_path / "each", features="6d")
    one = read_npz(tmp_path / "each" / f"{bandai_names[1]}.npz")
    for k in feats:
        np.testing.assert_array_equal(one[f"{k}_mean"], p[f"{k}_mean"])
        np.testing.assert_array_equal(one[f"{k}_std"], p[f"{k}_std"])
    # and MotionDataset.statistics gives the same numbers, whatever its batches
    ds = MotionDataset(db, clips=bandai_names, window=30, stride=10, features=("rotations_6d", "labels"))
    for batch in (1 << 16, 100):
        st = ds.statistics(list(feats), batch_frames=batch)
        for k in feats:
            assert st[k].frames == p["offsets"][-1]  # whole clips, each frame once, whatever the windows
            torch.testing.assert_close(st[k].mean, torch.from_numpy(p[f"{k}_mean"]), rtol=1e-10, atol=1e-10)
            torch.testing.assert_close(st[k].std, torch.from_numpy(p[f"{k}_std"]), rtol=1e-10, atol=1e-10)
    assert set(ds.statistics()) == {"rotations_6d"}  # the dataset's own features, labels left out


def test_6d_representation_round_trips_and_is_the_matrix_columns():
    q = random_quat((500,), dtype=F64, generator=torch.Generator().manual_seed(3))
    d = quat_to_6d(q)
    m = quat_to_rotmat(q)
    torch.testing.assert_close(d, torch.cat([m[:, :, 0], m[:, :, 1]], -1), rtol=0, atol=0)
    torch.testing.assert_close(rotation_6d_to_rotmat(d), m, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(d.numpy(), numpy_6d(q.numpy()), atol=1e-12)
    # any 6 numbers map to a rotation (a network's raw output)
    r = rotation_6d_to_rotmat(torch.randn(100, 6, dtype=F64, generator=torch.Generator().manual_seed(4)))
    torch.testing.assert_close(r @ r.transpose(-1, -2), torch.eye(3, dtype=F64).expand(100, 3, 3), rtol=0, atol=1e-12)
    assert bool((torch.linalg.det(r) > 0).all())


def test_statistics_refuse_mixed_skeletons(db):
    with pytest.raises(TorchspliceError, match="one skeleton topology"):
        MotionDataset(db, features=("positions",)).statistics()
    with pytest.raises(ValueError, match="unknown feature"):
        MotionDataset(db, where={"skeleton": 0}).statistics(["nope"])


def test_labels_feature_collates_as_a_list_of_dicts(db, bandai_names):
    ds = MotionDataset(db, clips=bandai_names, features=("rotations", "labels"))
    with MotionDatabase.open(db) as d:
        want = [d.read(n).labels for n in ds.names]
    items = [ds[i] for i in range(len(ds))]
    assert [it["labels"] for it in items] == want and all(it["labels"]["dataset"] in ("1", "2") for it in items)
    batch = collate_motion(items)
    assert batch["labels"] == want and batch["rotations"].shape[0] == len(want)
    items[0]["labels"]["content"] = "changed"  # an item's dict is its own
    assert ds[0]["labels"] == want[0]


# --------------------------------------------------------------------------------------------
# BVH, outputs and errors
# --------------------------------------------------------------------------------------------
def test_several_clips_as_bvh_into_a_folder(db, bandai_names, tmp_path):
    out = tmp_path / "bvh"
    result = export_clips(db, bandai_names[:3], out=out)
    assert result.format == "bvh" and "3 clips as BVH" in result.summary
    with MotionDatabase.open(db) as d:
        for n in bandai_names[:3]:
            back, m = read_bvh(out / f"{n}.bvh", dtype=F64), d.read(n, dtype=F64)
            torch.testing.assert_close(back.global_positions(), m.global_positions(), rtol=0, atol=1e-3)
    assert leftovers(out) == []
    with pytest.raises(OutputExistsError, match="already exists"):  # exists: overwrite=True
        export_clips(db, bandai_names[:3], out=out)
    export_clips(db, bandai_names[:3], out=out, overwrite=True)


@pytest.mark.parametrize("argv, why", [
    (["{clip}", "{clip2}", "-o", "{tmp}/x.npz"], "go to a folder"),
    (["{clip}", "{clip2}", "-o", "{tmp}/x.bvh"], "go to a folder"),
    (["{clip}", "--packed", "--format", "bvh", "-o", "{tmp}/x.bvh"], "needs --format npz"),
    (["{clip}", "--all", "-o", "{tmp}/x"], "not both"),
    ([ "-o", "{tmp}/x"], "or pass --all"),
    (["{clip}", "-o", "{tmp}/x.txt", "--format", "npz"], "must end in .npz"),
    (["{clip}", "-o", "{db}", "--format", "npz"], "must end in .npz"),
    (["nope", "-o", "{tmp}/x.npz"], "no clip named 'nope'; torchsplice info lists the clips"),
    (["--all", "--skeleton", "9", "-o", "{tmp}/x"], "numbered from 0; see torchsplice info)"),
    (["--all", "-o", "{tmp}/no/such/x", "--format", "npz"], "does not exist"),
])
def test_export_mistakes_get_one_line(db, bandai_names, tmp_path, capsys, argv, why):
    fill = {"clip": bandai_names[0], "clip2": bandai_names[1], "tmp": tmp_path, "db": db}
    rc, _, err = run(capsys, "export", db, *[a.format(**fill) for a in argv])
    assert rc == 2 and why in error_line(err)
    assert leftovers(tmp_path) == [] and not any(p.suffix == ".npz" for p in tmp_path.iterdir())


def test_an_existing_npz_is_kept_without_overwrite(db, bandai_names, tmp_path):
    out = tmp_path / "x.npz"
    out.write_bytes(b"keep")
    with pytest.raises(OutputExistsError, match="already exists"):
        export_clips(db, [bandai_names[0]], out=out)
    assert out.read_bytes() == b"keep"
    export_clips(db, [bandai_names[0]], out=out, overwrite=True)
    assert read_npz(out)["name"] == bandai_names[0]


def test_values_that_are_not_finite_are_refused(db, bandai_names, tmp_path):
    with pytest.raises(TorchspliceError, match=r"clip 'c': non-finite value in positions \(row 2\)"):
        write_npz(tmp_path / "w.npz", {"positions": np.array([[0.0], [1.0], [np.nan]])}, what="clip 'c'")
    assert not (tmp_path / "w.npz").exists()
    bad = tmp_path / "nan.h5"
    shutil.copy(db, bad)
    with h5py.File(bad, "r+") as f:
        row = list(f["clips/name"].asstr()[()]).index(bandai_names[0])
        k = int(f["clips/skeleton"][row])
        f[f"skeletons/{k}/rotations"][int(f["clips/start"][row]) + 5, 3, 0] = np.nan
    with pytest.raises(TorchspliceError, match="non-finite") as caught:
        export_clips(bad, [bandai_names[0]], out=tmp_path / "x.npz")
    line = str(caught.value)
    assert bandai_names[0] in line and "frame 5" in line and "\n" not in line
    assert not (tmp_path / "x.npz").exists() and leftovers(tmp_path) == []


def test_library_export_without_the_command_line(db, bandai_names, tmp_path):
    e = NpzExport(db, bandai_names[:2], features="6d")
    assert e.names == bandai_names[:2] and set(e.statistics) >= {"rotations_6d", "velocities", "trajectory_velocity"}
    for name, arrays in e.per_clip():
        write_npz(tmp_path / f"{name}.npz", arrays)
        z = np.load(tmp_path / f"{name}.npz", allow_pickle=False)  # plain numpy reads it, no pickles
        assert str(z["format"]) == "torchsplice.npz" and json.loads(str(z["labels"]))
    with pytest.raises(TorchspliceError, match="unknown feature set"):
        NpzExport(db, features="9d")


def test_the_docs_npz_snippet_runs(db, bandai_names, tmp_path, monkeypatch):
    """The Python block of docs/npz.md reads a packed export and normalises it."""
    import re

    page = Path(__file__).resolve().parents[2] / "docs" / "npz.md"
    text = page.read_text()
    start = text.index("# Exporting for other tools (.npz)")
    code = re.search(r"```python\n(.*?)```", text[start:], re.S).group(1)
    export_clips(db, bandai_names, out=tmp_path / "train.npz", packed=True, features="6d")
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(code, str(page), "exec"), scope)
    x, first, z = scope["x"], scope["first"], scope["z"]
    with MotionDatabase.open(db) as d:
        assert first.shape == (d.clip_info(str(z["names"][0]))["length"], 22, 6)
    moving = z["rotations_6d_std"] > 1e-6
    np.testing.assert_allclose(x.mean(0)[moving], 0, atol=1e-4)  # normalised: zero mean, unit variance
    np.testing.assert_allclose(x.std(0)[moving], 1, atol=1e-4)


def test_window_velocities_are_slices_of_the_clips(db, bandai_names):
    feats = ("trajectory_velocity", "root_velocity", "rotations_6d")
    whole = MotionDataset(db, clips=bandai_names, features=feats, dtype=F64)
    win = MotionDataset(db, clips=bandai_names, features=feats, dtype=F64, window=40, stride=25)
    items = win.__getitems__(list(range(len(win))))
    for it in items:
        c = whole.names.index(it["name"])
        ref = whole[c]
        for f in feats:
            torch.testing.assert_close(it[f], ref[f][it["start"]:it["start"] + 40], rtol=0, atol=1e-9)
    assert any(it["start"] > 0 for it in items)
    assert float(whole[0]["trajectory_velocity"][:, [0, 2]].norm(dim=1).mean()) > 10  # Bandai walks move (cm/s)


def test_a_killed_exports_staged_files_are_removed_by_the_next_export(db, bandai_names, tmp_path):
    """A SIGKILLed export leaves ``.NAME.staged-HOST-PID`` files; the next export into that folder
    removes those of dead processes of this host and keeps the others'."""
    import socket
    import subprocess

    out = tmp_path / "npz"
    out.mkdir()
    p = subprocess.Popen(["true"])
    p.wait()  # a process that is gone
    host = socket.gethostname()
    dead = out / f".{bandai_names[0]}.npz.staged-{host}-{p.pid}"
    alive = out / f".{bandai_names[0]}.npz.staged-{host}-{os.getppid()}"
    other = out / f".{bandai_names[0]}.npz.staged-elsewhere-{p.pid}"
    for f in (dead, alive, other):
        f.write_bytes(b"partial")
    export_clips(db, bandai_names[:2], format="npz", out=out, overwrite=True)
    assert not dead.exists() and alive.exists() and other.exists()
    assert sorted(f.name for f in out.glob("*.npz")) == sorted(f"{n}.npz" for n in bandai_names[:2])


def test_the_streamed_packed_file_holds_what_packed_gives_array_for_array(db, bandai_names, tmp_path):
    """The packed file is written member by member from files of rows (memory flat in the number of
    clips): it equals, array for array, the layout :meth:`NpzExport.packed` makes in memory."""
    export_clips(db, bandai_names, out=tmp_path / "p.npz", packed=True, features="6d")
    want = NpzExport(db, bandai_names, features="6d").packed()
    with np.load(tmp_path / "p.npz", allow_pickle=False) as got:
        assert sorted(got.files) == sorted(want)
        for key, a in want.items():
            assert got[key].dtype == np.asarray(a).dtype and np.array_equal(got[key], a), key
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no row files left


def test_export_refuses_values_that_are_not_finite(sample_db, tmp_path):
    db = nan_copy(sample_db, tmp_path, "wave")
    with pytest.raises(TorchspliceError, match="frame 5") as caught:
        export_clips(db, ["wave"], out=tmp_path / "w.bvh")
    assert "wave" in str(caught.value) and "\n" not in str(caught.value)
    assert not (tmp_path / "w.bvh").exists() and leftovers(tmp_path) == []
