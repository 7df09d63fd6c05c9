"""``torchsplice retarget`` and :func:`torchsplice.retarget.retarget_clips`: clips of a database
written onto another skeleton (a database's, a BVH rig's, the built-in SMPL body's).

Known answers: what the database gets is exactly :func:`~torchsplice.ops.retarget.retarget_motion`
of the stored clips; a clip retargeted onto its own database's skeleton comes back as it was;
the SMPL skeleton carries HumanML3D's bone lengths. Bad input (a target that is not one, a
database of several skeletons without ``:K``, a skeleton that is not a humanoid, a malformed
BVH) gets one line naming it, and no output is left.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import pytest
import torch

from realdata import MOCAP, REPO, _require_mocap
from rigs import armless_sample
from torchsplice.core.errors import TorchspliceError
from torchsplice.formats.bvh_write import write_bvh
from torchsplice.formats.importer import import_bvh
from torchsplice.formats.sample_database import write_sample
from torchsplice.ops.retarget import retarget_map, retarget_motion
from torchsplice.retarget import resolve_target, retarget_clips
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.specs.smpl import SMPL22_NAMES, smpl22_skeleton
from torchsplice.store.database import MotionDatabase


def _sample_db(tmp_path):
    """The built-in sample as a database of the test's own (what ``torchsplice sample`` writes)."""
    path = tmp_path / "sample.h5"
    write_sample(path)
    return path


@pytest.fixture(scope="module")
def real_dbs(tmp_path_factory):
    """A CMU database (two skeletons: both namings) and a Bandai Namco one of two clips."""
    _require_mocap()  # skips without the data, fails under CI
    root = tmp_path_factory.mktemp("rt")
    cmu = root / "cmu.h5"
    import_bvh([MOCAP / "cmu_graphics_lab"], cmu)
    bn = root / "bn.h5"
    import_bvh([MOCAP / "bandai_namco_research_motiondataset" / "dataset-2_walk_normal_008.bvh",
                MOCAP / "bandai_namco_research_motiondataset" / "dataset-2_wave-right-hand_normal_001.bvh"], bn)
    return cmu, bn


def test_the_written_clips_are_the_retargeted_stored_clips_with_their_labels(real_dbs, tmp_path):
    cmu, bn = real_dbs
    out = tmp_path / "cmu_on_bn.h5"
    report = retarget_clips(cmu, to=str(bn), out=out)
    target = resolve_target(str(bn))
    with MotionDatabase.open(cmu) as src, MotionDatabase.open(out) as got:
        assert report.clips == len(src) == len(got) and got.names == src.names
        assert len(got.skeletons) == 1 and got.skeletons[0].names == target.skeleton.names
        assert got.attrs["units"] == "cm" and got.stored_spec(0).name == "bandai_namco"
        for name in src.names:
            m = src.read(name, dtype=torch.float64)
            k = src.clip_info(name)["skeleton"]
            spec = src.spec(k)
            rmap = retarget_map(m.skeleton, spec.bind(m.skeleton), target.skeleton, target.spec.bind(target.skeleton))
            want = retarget_motion(m, rmap, target_heights=target.heights)
            have = got.read(name, dtype=torch.float64)
            # float32 storage: within a micrometre-scale error of the exact result
            assert float((have.global_positions() - want.global_positions()).abs().max()) < 1e-3
            assert have.labels["retargeted_to"] == "bn.h5:0"
            assert have.labels["retargeted_from"] == f"cmu.h5:{k} ({spec.name})"
            assert have.role == m.role and have.fps == m.fps
            assert {k: v for k, v in have.labels.items() if not k.startswith("retargeted")} == m.labels
    # the maps' notes name the joints each source skeleton folds and holds
    assert any("LThumb" in notes["folded"] for notes in report.maps.values())


def test_a_clip_retargeted_onto_its_own_databases_skeleton_comes_back_as_it_was(tmp_path):
    db = _sample_db(tmp_path)
    out = tmp_path / "self.h5"
    retarget_clips(db, ["walk_straight", "wave"], to=str(db), out=out)
    with MotionDatabase.open(db) as a, MotionDatabase.open(out) as b:
        assert b.names == ["walk_straight", "wave"]
        for name in b.names:
            pa, pb = a.read(name).global_positions(), b.read(name).global_positions()
            assert float((pa - pb).abs().max()) < 1e-3  # float32 storage, cm


def test_select_chooses_the_clips_as_everywhere_else(tmp_path):
    db = _sample_db(tmp_path)
    out = tmp_path / "actions.h5"
    retarget_clips(db, to="smpl22", out=out, select="role:action")
    with MotionDatabase.open(db) as a, MotionDatabase.open(out) as b:
        table = a.clip_table()
        assert b.names == [n for n, r in zip(table.names, table.role) if r == "action"]
        assert b.attrs["units"] == "m" and b.skeletons[0].names == SMPL22_NAMES


def test_the_smpl_skeleton_has_humanml3ds_bone_lengths_and_a_standing_height():
    sk = smpl22_skeleton()
    lengths = sk.offsets.norm(dim=-1)
    # thigh and shin of HumanML3D's standard skeleton (metres), and ankle to head of a 1.4-1.8 m person
    assert float(lengths[SMPL22_NAMES.index("left_knee")]) == pytest.approx(0.3936, abs=1e-4)
    assert float(lengths[SMPL22_NAMES.index("left_ankle")]) == pytest.approx(0.4324, abs=1e-4)
    rest, _ = sk.rest_positions()
    height = float(rest[SMPL22_NAMES.index("head"), 1] - rest[SMPL22_NAMES.index("left_ankle"), 1])
    assert 1.4 < height < 1.8
    load_spec("smpl22").bind(sk)  # its shipped spec binds


def test_a_bvh_target_gives_its_skeleton_and_how_high_its_feet_stand(tmp_path):
    m = sample_motions()[0]
    path = tmp_path / "rig.bvh"
    write_bvh(m, path)
    target = resolve_target(str(path))
    assert target.skeleton.names == m.skeleton.names and target.name == "rig.bvh"
    assert target.heights is not None and target.heights.shape == (2, 2)
    pos = m.global_positions()
    feet = load_spec("sample").bind(m.skeleton).feet
    lowest = float(pos[:, list(feet), 1].min())
    assert lowest - 0.5 <= float(target.heights[0, 0]) <= lowest + 3.0  # the ankle's resting height, cm


# ------------------------------------------------------------------------------------------
# bad input: one line, nothing written
# ------------------------------------------------------------------------------------------
def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "torchsplice", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"})


@pytest.mark.slow  # command lines in fresh processes, 6 to 11 s: CI and --all run it
def test_bad_targets_are_refused_in_one_line_naming_them(tmp_path):
    db = _sample_db(tmp_path)
    two = tmp_path / "two.h5"
    m = sample_motions()[0]
    big = replace(m, skeleton=replace(m.skeleton, offsets=m.skeleton.offsets * 3,
                                      end_site_offsets=m.skeleton.end_site_offsets * 3), name="big")
    with MotionDatabase.create(two) as w:
        w.append(m, spec=load_spec("sample"))
        w.append(big, spec=load_spec("sample"))
    bad_bvh = tmp_path / "broken.bvh"
    bad_bvh.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    cases = {"walk.fbx": "not a retargeting target", str(tmp_path / "none.h5"): "no such database",
             str(two): "holds 2 skeletons; name one as", f"{two}:5": "has no skeleton 5",
             str(bad_bvh): "broken.bvh", str(tmp_path / "none.bvh"): "no such BVH file"}
    for target, words in cases.items():
        out = tmp_path / "out.h5"
        r = _cli("retarget", db, "--all", "--to", target, "-o", out, cwd=tmp_path)
        assert r.returncode == 2 and words in r.stderr and len(r.stderr.strip().splitlines()) == 1, (target, r.stderr)
        assert "Traceback" not in r.stderr and not out.exists()
    assert resolve_target(f"{two}:1").skeleton.matches(big.skeleton)
    # the command line points at its info command, the library at the method
    assert "(torchsplice info lists them)" in _cli("retarget", db, "--all", "--to", two, "-o", tmp_path / "o.h5", cwd=tmp_path).stderr
    with pytest.raises(TorchspliceError, match=r"\(MotionDatabase\.summary\(\) lists them\)$"):
        resolve_target(str(two))


def test_a_skeleton_that_is_not_a_humanoid_is_refused_naming_what_it_lacks(tmp_path):
    """An armless rig as the source and as the target: one line each, naming the missing joints."""
    stump = armless_sample()
    rig = tmp_path / "stump.bvh"
    write_bvh(stump, rig)
    db = _sample_db(tmp_path)
    r = _cli("retarget", db, "wave", "--to", rig, "-o", tmp_path / "o.h5", cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
    assert "stump.bvh" in r.stderr and "elbow" in r.stderr, r.stderr
    stumps = tmp_path / "stumps.h5"
    with MotionDatabase.create(stumps) as w:  # stored without a spec: its roles are guessed when read
        w.append(stump)
    r = _cli("retarget", stumps, "--all", "--to", "smpl22", "-o", tmp_path / "o.h5", cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
    assert "stumps.h5" in r.stderr and "elbow" in r.stderr, r.stderr
    assert not (tmp_path / "o.h5").exists()


def test_a_failure_midway_leaves_no_output_and_an_existing_one_untouched(tmp_path, monkeypatch):
    import torchsplice.retarget.clips as rc

    db = _sample_db(tmp_path)
    out = tmp_path / "out.h5"
    retarget_clips(db, ["wave"], to="smpl22", out=out)
    before = out.read_bytes()
    calls = []

    def failing(motions, *a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return [retarget_motion(m, *a, **k) for m in motions]

    monkeypatch.setattr(rc, "retarget_motions", failing)
    monkeypatch.setattr(rc, "CHUNK_CLIPS", 2)
    with pytest.raises(OSError):
        retarget_clips(db, to="smpl22", out=out, overwrite=True)
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.h5", "sample.h5"]
    with pytest.raises(TorchspliceError, match="already exists"):
        retarget_clips(db, to="smpl22", out=out)


@pytest.mark.slow  # command lines in fresh processes, 6 to 11 s: CI and --all run it
def test_the_command_names_the_clips_or_all_and_says_what_it_wrote(tmp_path):
    db = _sample_db(tmp_path)
    r = _cli("retarget", db, "--to", "smpl22", "-o", tmp_path / "o.h5", cwd=tmp_path)
    assert r.returncode == 2 and "name the clips to retarget" in r.stderr
    r = _cli("retarget", db, "nope", "--to", "smpl22", "-o", tmp_path / "o.h5", cwd=tmp_path)
    assert r.returncode == 2 and "nope" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = _cli("retarget", db, "wave", "walk_curve", "--to", "smpl22", "-o", tmp_path / "o.h5", "--no-fix-feet",
             cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "2 clips" in r.stdout and "smpl22" in r.stdout
    with MotionDatabase.open(tmp_path / "o.h5") as got:
        assert got.names == ["wave", "walk_curve"]
    # without feet fixed: the analytic retargeting alone
    with MotionDatabase.open(db) as a:
        m = a.read("wave", dtype=torch.float64)
        spec = a.spec(0)
    t = resolve_target("smpl22")
    want = retarget_motion(m, retarget_map(m.skeleton, spec.bind(m.skeleton), t.skeleton, t.spec.bind(t.skeleton)),
                           fix_feet=False)
    with MotionDatabase.open(tmp_path / "o.h5") as got:
        assert float((got.read("wave", dtype=torch.float64).global_positions() - want.global_positions()).abs().max()) < 1e-5


def test_a_quadruped_or_a_file_that_is_not_a_skeleton_as_target_is_refused_in_one_line(tmp_path):
    """A four-legged rig (no arms: its front legs are not shoulders, elbows and wrists) and a
    Markdown file named .bvh: one line each, naming the file, and no output."""
    from torchsplice.core.motion import Motion
    from torchsplice.core.skeleton import Skeleton

    names = ["Pelvis", "Spine", "Chest", "Neck", "Head"]
    parents = [-1, 0, 1, 2, 3]
    offsets = [[0, 60, 0], [0, 0, 20], [0, 0, 20], [0, 5, 15], [0, 0, 10]]
    for end, at in (("Front", 2), ("Hind", 0)):
        for side, x in (("Left", 8), ("Right", -8)):
            base = len(names)
            names += [f"{end}{side}UpperLeg", f"{end}{side}LowerLeg", f"{end}{side}Paw"]
            parents += [at, base, base + 1]
            offsets += [[x, -5, 0], [0, -25, 0], [0, -25, 0]]
    sk = Skeleton(names=tuple(names), parents=tuple(parents), offsets=torch.tensor(offsets, dtype=torch.float64),
                  channels=tuple(("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation") if p < 0
                                 else ("Zrotation", "Yrotation", "Xrotation") for p in parents))
    dog = Motion(skeleton=sk, rotations=torch.tensor([1.0, 0, 0, 0]).expand(10, len(names), 4).clone(),
                 root_translation=torch.zeros(10, 3), fps=30.0, name="dog")
    write_bvh(dog, tmp_path / "dog.bvh")
    (tmp_path / "notes.bvh").write_text("# My notes\n\nnot a skeleton\n")
    db = _sample_db(tmp_path)
    for target in ("dog.bvh", "notes.bvh"):
        r = _cli("retarget", db, "wave", "--to", tmp_path / target, "-o", tmp_path / "o.h5", cwd=tmp_path)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
        assert target in r.stderr and not (tmp_path / "o.h5").exists(), r.stderr


def test_a_stored_spec_naming_joints_the_skeleton_lacks_is_refused_naming_the_database(tmp_path):
    """A database whose spec's roles name absent joints (LeftPalm), as the source and as the
    target: one line naming the database, its skeleton and the joint."""
    import json

    from torchsplice.specs import DatasetSpec

    d = json.loads(load_spec("sample").to_json())
    d["joints"]["hands"] = ["LeftPalm", "RightPalm"]
    bad = tmp_path / "badmap.h5"
    with MotionDatabase.create(bad) as w:
        for m in sample_motions()[:2]:
            w.append(m, spec=DatasetSpec.from_json(json.dumps(d)))
    db = _sample_db(tmp_path)
    for args in (("retarget", bad, "--all", "--to", "smpl22"), ("retarget", db, "wave", "--to", bad)):
        r = _cli(*args, "-o", tmp_path / "o.h5", cwd=tmp_path)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
        assert "badmap.h5: skeleton 0" in r.stderr and "'LeftPalm'" in r.stderr, r.stderr
        assert not (tmp_path / "o.h5").exists()
