"""Importing a HumanML3D folder (``import_bvh``, ``torchsplice import DIR``): each motion a clip on the SMPL body, its
captions kept, so that HumanML3D motions splice with each other and with any humanoid's.

Known answers: importing an export gives back the exported positions (1e-5 m; the target is 1e-4); imported
motions splice, and their results' captions compose the sources' captions; every kind of bad
motion is one line naming its file, and the others land.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import torch

from cli_helpers import run
from torchsplice.core.errors import TorchspliceError
from torchsplice.formats.exporters import export_clips
from torchsplice.formats.importer import NothingImportedError, import_bvh
from torchsplice.job import splice_all
from torchsplice.formats.humanml3d_import import positions_to_motion, read_humanml3d_motion, read_humanml3d_motions
from torchsplice.store.database import MotionDatabase


@pytest.fixture(scope="module")
def exported(sample_db, tmp_path_factory) -> Path:
    """The spliced sample, exported as a HumanML3D folder with mirrors."""
    folder = tmp_path_factory.mktemp("h3i")
    spliced = folder / "spliced.h5"
    splice_all(sample_db, spliced)
    out = folder / "HumanML3D"
    export_clips(spliced, out=out, format="humanml3d", mirror=True)
    return out


def test_importing_an_export_gives_back_its_positions_and_captions(exported, tmp_path):
    db = tmp_path / "back.h5"
    report = import_bvh([exported], db)
    assert report.ok and report.clips == len(report.imported) == 50
    with MotionDatabase.open(db) as d:
        assert d.skeleton_info(0).spec_name == "smpl22" and d.skeleton_info(0).units == "m"
        worst = 0.0
        for name in d.names:
            m = d.read(name, dtype=torch.float64)
            joints = torch.from_numpy(np.load(exported / "new_joints" / f"{name}.npy")).double()
            assert m.fps == 20.0 and m.num_frames == joints.shape[0] and m.role == "both"
            worst = max(worst, float((m.global_positions() - joints).abs().max()))
            lines = (exported / "texts" / f"{name}.txt").read_text().splitlines()
            assert m.labels["captions"].splitlines() == lines
        assert worst < 1e-5, worst  # the target: 1e-4 m
        splits = {r["id"]: r["split"] for r in csv.DictReader(open(exported / "index.csv"))}
        for name in d.names:
            assert d.clip_info(name)["labels"].get("split", "") == splits[name]


def test_motions_read_together_are_bit_for_bit_those_read_one_at_a_time(exported, tmp_path, monkeypatch):
    """``import`` turns positions into rotations for a batch of motions at once: the same bits as
    one motion at a time, a mirrored copy still on the mirrored body, whatever the batch size."""
    import torchsplice.formats.importer as importer
    from torchsplice.specs.smpl import smpl22_skeleton

    ids = sorted(f.stem for f in (exported / "new_joint_vecs").glob("*.npy"))
    together = read_humanml3d_motions([(exported, i, None) for i in ids] + [(exported, "missing", None)])
    assert isinstance(together[-1], TorchspliceError) and "missing" in str(together[-1])
    mirrored = smpl22_skeleton(mirrored=True).offsets
    for i, got in zip(ids, together):
        alone = read_humanml3d_motion(exported, i)
        assert torch.equal(got.rotations, alone.rotations) and torch.equal(got.root_translation, alone.root_translation)
        assert torch.equal(got.skeleton.offsets, alone.skeleton.offsets) and got.labels == alone.labels
        assert torch.equal(got.skeleton.offsets, mirrored) == i.startswith("M"), i
    dbs = []
    for batch in (7, importer.HUMANML3D_BATCH):
        monkeypatch.setattr(importer, "HUMANML3D_BATCH", batch)
        dbs.append(tmp_path / f"b{batch}.h5")
        importer.import_bvh([exported], dbs[-1], format="humanml3d")
    with MotionDatabase.open(dbs[0]) as a, MotionDatabase.open(dbs[1]) as b:
        assert a.names == b.names and len(a) == len(ids)
        for name in a.names:
            assert torch.equal(a.read(name).rotations, b.read(name).rotations), name


def test_positions_back_from_a_motion_are_exact_on_the_standard_body():
    """FK of the motion made from positions gives the positions (they are on the body's lengths)."""
    from torchsplice.ops.retarget import retarget_map, retarget_motions
    from torchsplice.sample import sample_motions
    from torchsplice.specs import load_spec
    from torchsplice.specs.smpl import smpl22_skeleton

    ms = [m.to(torch.float64) for m in sample_motions()[:3]]
    sk = smpl22_skeleton()
    rmap = retarget_map(ms[0].skeleton, load_spec("sample").bind(ms[0].skeleton), sk, load_spec("smpl22").bind(sk))
    for m in retarget_motions(ms, rmap):
        p = m.global_positions()
        back = positions_to_motion(p, m.name, m.fps)
        assert float((back.global_positions() - p).abs().max()) < 1e-9


def test_imported_motions_splice_and_their_captions_compose(exported, tmp_path):
    db = tmp_path / "h.h5"
    assert import_bvh([exported], db).ok
    index = {r["clip"]: r["id"] for r in csv.DictReader(open(exported / "index.csv")) if r["mirrored"] == "0"}
    loco, action = index["walk_curve+carry_cup"], index["walk_straight+wave"]
    spliced = tmp_path / "s.h5"
    assert splice_all(db, spliced, locomotions=loco, actions=action).spliced == 1
    out = tmp_path / "again"
    export_clips(spliced, out=out, format="humanml3d")
    lines = [ln.split("#")[0] for ln in (out / "texts" / "000000.txt").read_text().splitlines()]
    assert lines and all(("walks in a curve to the left" in ln or "curving left" in ln) for ln in lines), lines
    assert all(ln.count(" while ") == 1 and "waving" in ln and "cup" not in ln for ln in lines), lines


def _damaged(exported: Path, tmp_path: Path) -> Path:
    """A copy of the export with one of each kind of bad motion."""
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(exported, bad)
    np.save(bad / "new_joint_vecs" / "000001.npy", np.zeros((30, 251), np.float32))  # wrong width
    nan = np.load(bad / "new_joint_vecs" / "000002.npy")
    nan[5, 7] = np.nan
    np.save(bad / "new_joint_vecs" / "000002.npy", nan)
    (bad / "texts" / "000003.txt").unlink()                                           # no text
    (bad / "texts" / "000004.txt").write_text("a person walks#a/DET person walk/VERB#0.0#0.0\n")  # malformed
    (bad / "new_joint_vecs" / "000005.npy").unlink()                                  # listed, no motion
    huge = np.load(bad / "new_joint_vecs" / "000007.npy")
    huge[3, 1] = 1e30                                                                 # a root velocity of 1e30
    np.save(bad / "new_joint_vecs" / "000007.npy", huge)
    (bad / "new_joint_vecs" / "000006.npy").write_bytes(b"not numpy")
    return bad


def skipped_lines(report) -> list[str]:
    """``PATH: why`` of every input the import skipped (one line each)."""
    lines = [f"{path}: {why}" for path, why in report.skipped]
    assert all("\n" not in ln for ln in lines), lines
    return lines


def test_bad_motions_are_one_line_each_and_the_others_land(exported, tmp_path):
    bad = _damaged(exported, tmp_path)
    db = tmp_path / "b.h5"
    report = import_bvh([bad], db)
    assert not report.ok and report.imported
    lines = err = skipped_lines(report)
    expect = {
        "000001.npy": "expected (frames, 263) features, got shape (30, 251)",
        "000002.npy": "not finite (NaN or infinity) at frame 5",
        "000003.txt": "missing",
        "000004.txt": "token 'person' is not word/POS",
        "000006.npy": "not a NumPy array file",
        "000007.npy": "an absurd value (beyond 1e+12) at frame 3",
    }
    for f, words in expect.items():
        assert any(f in ln and words in ln for ln in lines), (f, err)
    assert any("all.txt" in ln and "'000005'" in ln and "no motion" in ln for ln in lines), err
    with MotionDatabase.open(db) as d:
        names = set(d.names)
    assert {"000000", "000008", "M000001"} <= names and not names & {"000001", "000002", "000003", "000004", "000006",
                                                                   "000007"}


def test_the_format_option_and_its_errors(exported, tmp_path):
    with pytest.raises(NothingImportedError, match="no BVH files to import") as caught:
        import_bvh([exported], tmp_path / "x.h5", format="bvh")
    assert any("folder holds no .bvh files" in ln for ln in skipped_lines(caught.value.report))
    with pytest.raises(NothingImportedError, match="no HumanML3D motions to import") as caught:
        import_bvh([tmp_path], tmp_path / "y.h5", format="humanml3d")
    assert any("not a HumanML3D folder" in ln for ln in skipped_lines(caught.value.report))
    with pytest.raises(TorchspliceError, match="format must be one of auto, bvh, humanml3d, got 'fbx'"):
        import_bvh([exported], tmp_path / "z.h5", format="fbx")
    assert not (tmp_path / "x.h5").exists() and not (tmp_path / "y.h5").exists() and not (tmp_path / "z.h5").exists()
    assert import_bvh([exported], tmp_path / "cm.h5", units="cm").ok
    with MotionDatabase.open(tmp_path / "cm.h5") as d:
        assert d.skeleton_info(0).units == "cm"
        m = d.read(d.names[0], dtype=torch.float64)
    joints = torch.from_numpy(np.load(exported / "new_joints" / f"{m.name}.npy")).double()
    assert float((m.global_positions() / 100.0 - joints).abs().max()) < 1e-4


def test_an_imported_folders_splits_and_mirrors_hold_when_exported_again(exported, tmp_path):
    """Imported motions keep their split, and a mirrored copy splits with its original, so a
    re-export never puts a test motion (or its mirror) in train."""
    db = tmp_path / "h.h5"
    assert import_bvh([exported], db).ok
    first = {r["id"]: r["split"] for r in csv.DictReader(open(exported / "index.csv"))}
    for seed in (0, 1, 2):
        out = tmp_path / f"again{seed}"
        export_clips(db, out=out, format="humanml3d", split_seed=seed, split_ratios=(0.34, 0.33, 0.33))
        again = {r["clip"]: r["split"] for r in csv.DictReader(open(out / "index.csv"))}
        for name, split in again.items():
            if first[name]:
                assert split == first[name], (seed, name)
            if name.startswith("M"):
                assert split == again[name[1:]], (seed, name)


def test_an_npz_archive_named_npy_is_one_line(exported, tmp_path):
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(exported, bad)
    np.savez(bad / "new_joint_vecs" / "000003.npy", x=np.zeros(3))
    (bad / "new_joint_vecs" / "000003.npy.npz").rename(bad / "new_joint_vecs" / "000003.npy")
    report = import_bvh([bad], tmp_path / "b.h5")
    err = skipped_lines(report)
    assert report.imported and err and not any("unexpected" in ln for ln in err)
    assert any("000003.npy" in ln and "a NumPy .npz archive, not one array" in ln for ln in err), err


def test_two_folders_with_the_same_ids_share_a_database_by_a_name_prefix(exported, tmp_path):
    db = tmp_path / "two.h5"
    assert import_bvh([exported], db).ok
    with pytest.raises(NothingImportedError) as caught:  # every motion of the second: skipped, one line each
        import_bvh([exported], db, append=True)
    err = skipped_lines(caught.value.report)
    assert len(err) == 50 and all("already in the database" in ln for ln in err)
    report = import_bvh([exported], db, append=True, name_prefix="again_")
    assert report.ok, report.skipped
    with MotionDatabase.open(db) as d:
        names = set(d.names)
        mirrored = d.clip_info("again_M000003")["labels"]
    assert len(names) == 100 and {"000003", "again_000003", "again_M000003"} <= names
    assert mirrored["mirror_of"] == "again_000003"
    with pytest.raises(TorchspliceError, match="name_prefix 'a:b' must be text without control characters, commas or colons"):
        import_bvh([exported], tmp_path / "x.h5", name_prefix="a:b")


def test_cli_refuses_an_unknown_format_and_a_bad_name_prefix_in_its_words(exported, tmp_path, capsys):
    """The command line's words for import_bvh's refusals: argparse's choices, the flag's name."""
    with pytest.raises(SystemExit) as exit_:
        run(capsys, "import", exported, "-o", tmp_path / "z.h5", "--format", "fbx")
    assert exit_.value.code == 2 and "invalid choice: 'fbx'" in capsys.readouterr().err
    rc, _, err = run(capsys, "import", exported, "-o", tmp_path / "x.h5", "--name-prefix", "a:b")
    assert rc == 2 and "--name-prefix 'a:b' must be text without control characters, commas or colons" in err
    assert not (tmp_path / "z.h5").exists() and not (tmp_path / "x.h5").exists()


def test_an_id_in_two_split_lists_is_one_line_and_the_unlisted_motions_land_with_no_split(exported, tmp_path):
    """An ID in train.txt and test.txt is not silently put in test: it is skipped in one line
    naming both lists. A motion that no list names (an exported result in no split) is
    imported, with no split."""
    import shutil

    folder = tmp_path / "twice"
    shutil.copytree(exported, folder)
    train = (folder / "train.txt").read_text().split()
    (folder / "test.txt").write_text((folder / "test.txt").read_text() + train[0] + "\n")
    listed = set((folder / "all.txt").read_text().split())
    unlisted = sorted(f.stem for f in (folder / "new_joint_vecs").glob("*.npy") if f.stem not in listed)
    assert unlisted  # the sample's export has results in no split
    report = import_bvh([folder], tmp_path / "t.h5")
    lines = err = skipped_lines(report)
    assert report.imported and len(lines) == 1 and f"{train[0]}.npy" in lines[0] and "train.txt and test.txt" in lines[0], err
    with MotionDatabase.open(tmp_path / "t.h5") as db:
        assert train[0] not in db.names and set(unlisted) <= set(db.names)
        t = db.clip_table()
        split = {n: dict(l).get("split", "") for n, l in zip(t.names, t.labels)}
    assert all(split[u] == "" for u in unlisted) and split[train[1]] == "train"


def test_fifos_links_out_of_the_folder_and_endless_files_are_one_line_each_never_read(exported, tmp_path):
    """A FIFO named like a motion or a caption file would block the import forever, a symlink
    out of the folder would pull a file from elsewhere into the captions, /dev/zero would eat
    the memory: each is skipped in one line, and the other motions land."""
    import os
    import shutil

    folder = tmp_path / "hostile"
    shutil.copytree(exported, folder)
    (folder / "new_joint_vecs" / "000001.npy").unlink()
    os.mkfifo(folder / "new_joint_vecs" / "000001.npy")
    (folder / "texts" / "000002.txt").unlink()
    os.mkfifo(folder / "texts" / "000002.txt")
    secret = tmp_path / "secret.txt"
    secret.write_text("a person walks#a/DET person/NOUN walk/VERB#0.0#0.0\n")
    (folder / "texts" / "000003.txt").unlink()
    (folder / "texts" / "000003.txt").symlink_to(secret)
    (folder / "texts" / "000004.txt").unlink()
    (folder / "texts" / "000004.txt").symlink_to("/dev/zero")
    report = import_bvh([folder], tmp_path / "h.h5")
    lines = err = skipped_lines(report)
    for name, words in (("000001.npy", "named pipe (FIFO)"), ("000002.txt", "named pipe (FIFO)"),
                        ("000003.txt", "leads out of"), ("000004.txt", "not a regular file")):
        assert any(name in ln and words in ln for ln in lines), (name, err)
    assert report.imported and not report.ok
    with MotionDatabase.open(tmp_path / "h.h5") as db:
        names = set(db.names)
        assert "000000" in names and not names & {"000001", "000002", "000003", "000004"}
        assert all("secret" not in str(db.clip_info(n)["labels"]) for n in names)
    zero = tmp_path / "zero.json"
    zero.symlink_to("/dev/zero")
    from torchsplice.formats.captions import read_captions

    with pytest.raises(TorchspliceError, match="not a regular file|more than"):
        read_captions(zero)
    os.mkfifo(tmp_path / "fifo.json")
    with pytest.raises(TorchspliceError, match="named pipe"):
        read_captions(tmp_path / "fifo.json")
