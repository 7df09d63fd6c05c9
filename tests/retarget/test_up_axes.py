"""Up axes: a clip that changes skeleton is turned onto the target's up axis, wherever it does.

Every shipped rig (the built-in sample, SMPL-22, and CMU, LAFAN1 and Bandai Namco from their
BVH files) is turned onto each of Y, Z and X up (:func:`rigs.turned`: its rest offsets and its
motion, as a rig exported that way holds them), as a source and as a target. Known answer:
retargeting is equivariant, so the result on a target standing along ``v`` is the Y-up result
turned onto ``v`` (:func:`~torchsplice.core.rotations.up_axis_turn`), whatever the source's up
axis, and it stands along ``v``. Then each place a clip changes skeleton: ``retarget_clips``
(onto SMPL-22 and onto a Z-up database, labelled as it is), the HumanML3D export (a Z-up
database exports what its Y-up twin does), and ``splice_all`` with actions on a Z-up rig
(retarget on: spliced as the Y-up twin's; off: refused, saying why).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from realdata import MOCAP, _require_mocap
from rigs import turned
from torchsplice.core.errors import TorchspliceError
from torchsplice.core.rotations import quat_apply, up_axis_turn
from torchsplice.formats.exporters import export_clips
from torchsplice.formats.importer import import_bvh
from torchsplice.job.run import splice_all
from torchsplice.ops.retarget import retarget_map, retarget_motions
from torchsplice.retarget import retarget_clips
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.specs.canonical import canonical_joints
from torchsplice.specs.smpl import smpl22_skeleton
from torchsplice.specs.vocabulary import AXES
from torchsplice.store.database import MotionDatabase

FRAMES = 90
"""Frames of each real clip used (the retargeting is per frame but for the feet)."""
REAL = {"cmu": ("cmu_graphics_lab", "cmu_12_01_walk.bvh", "auto"),
        "lafan1": ("lafan1_via_pypi_bvhtools", "test.bvh", "auto"),
        "bandai_namco": ("bandai_namco_research_motiondataset", "dataset-1_walk_normal_001.bvh", "bandai_namco")}
RIGS = ("sample", "smpl22", *REAL)


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> dict:
    """Rig name -> (a clip on it, Y up, float64; its spec)."""
    sample, sample_spec = sample_motions()[0].to(torch.float64), load_spec("sample")
    smpl_spec = load_spec("smpl22")
    smpl_map = retarget_map(sample.skeleton, sample_spec.bind(sample.skeleton), smpl22_skeleton(),
                            smpl_spec.bind(smpl22_skeleton()))
    out = {"sample": (sample, sample_spec), "smpl22": (retarget_motions([sample], smpl_map)[0], smpl_spec)}
    _require_mocap()
    folder = tmp_path_factory.mktemp("up")
    for rig, (source, name, spec) in REAL.items():
        db = folder / f"{rig}.h5"
        import_bvh([MOCAP / source / name], db, spec=spec)
        with MotionDatabase.open(db) as d:
            m = d.read(d.names[0], dtype=torch.float64)
            out[rig] = (replace(m, rotations=m.rotations[:FRAMES], root_translation=m.root_translation[:FRAMES],
                                translations=None if m.translations is None else m.translations[:FRAMES]),
                        d.spec(d.clip_info(d.names[0])["skeleton"]))
    return out


def _played(clip, spec, u: str, target, target_spec, v: str) -> torch.Tensor:
    """World positions of ``clip`` turned onto ``u`` retargeted onto ``target`` turned onto ``v``."""
    src, tgt = turned(clip, u), turned(target, v)
    rmap = retarget_map(src.skeleton, replace(spec, up_axis=u).bind(src.skeleton), tgt.skeleton,
                        replace(target_spec, up_axis=v).bind(tgt.skeleton))
    return retarget_motions([src], rmap, True)[0].global_positions().double()


def _turn(pos: torch.Tensor, v: str) -> torch.Tensor:
    return quat_apply(up_axis_turn(1, AXES[v]).expand(*pos.shape[:-1], 4), pos)


def _standing(pos: torch.Tensor, spec, skeleton, v: str) -> float:
    """How far the head stands above the pelvis along up axis ``v``, over their distance (1: upright)."""
    j = canonical_joints(spec.bind(skeleton), skeleton)
    d = pos[:, j.get("head", j["spine"][-1])] - pos[:, j["pelvis"]]
    return float((d[:, AXES[v]] / d.norm(dim=-1)).mean())


@pytest.mark.realdata
@pytest.mark.parametrize("role", ["source", "target"])
@pytest.mark.parametrize("rig", RIGS)
def test_each_rig_in_each_up_axis_retargets_as_its_y_up_self_turned(clips, rig, role):
    """The rig in each of Y, Z and X up, as the source (onto SMPL-22; the sample for SMPL-22
    itself) and as the target (of the sample; of CMU for the sample itself), onto or from each
    of Y, Z and X up: the result is the Y-up result turned onto the target's up axis (1e-9 of
    the positions' scale), and it stands along that axis."""
    partner = "smpl22" if rig != "smpl22" else "sample"
    if role == "target":
        partner = "sample" if rig != "sample" else "cmu"
    (clip, spec), (target, target_spec) = ((clips[rig], clips[partner]) if role == "source"
                                           else (clips[partner], clips[rig]))
    target = replace(target, rotations=target.rotations[:1], root_translation=target.root_translation[:1],
                     translations=None if target.translations is None else target.translations[:1])
    y_up = _played(clip, spec, "y", target, target_spec, "y")
    scale = float(y_up.abs().max())
    assert _standing(y_up, target_spec, target.skeleton, "y") > 0.8
    for u in "xyz":
        for v in "xyz":
            got = _played(clip, spec, u, target, target_spec, v)
            err = float((got - _turn(y_up, v)).abs().max()) / scale
            assert err < 1e-9, (rig, role, u, v, err)
            assert _standing(got, target_spec, target.skeleton, v) > 0.8, (rig, role, u, v)


def _database(path, motions, spec):
    with MotionDatabase.create(path) as db:
        for m in motions:
            db.append(m, spec=spec)
    return path


@pytest.fixture(scope="module")
def twins(tmp_path_factory) -> tuple:
    """The sample's clips in a Y-up database and turned in a Z-up one (its spec says ``z``)."""
    folder = tmp_path_factory.mktemp("twins")
    spec = load_spec("sample")
    motions = sample_motions()
    return (_database(folder / "y.h5", motions, spec),
            _database(folder / "z.h5", [turned(m, "z") for m in motions], replace(spec, up_axis="z")))


def _read_all(path) -> dict[str, torch.Tensor]:
    with MotionDatabase.open(path) as db:
        return {n: db.read(n, dtype=torch.float64).global_positions().double() for n in db.names}


def test_retarget_clips_turns_a_z_up_database_onto_the_targets_up_axis_and_labels_it(twins, tmp_path):
    y, z = twins
    onto_y = retarget_clips(y, to="smpl22", out=tmp_path / "y_on_smpl.h5").output
    onto_smpl = retarget_clips(z, to="smpl22", out=tmp_path / "z_on_smpl.h5").output
    with MotionDatabase.open(onto_smpl) as db:
        assert db.skeleton_info(0).up_axis == "y"
    want, got = _read_all(onto_y), _read_all(onto_smpl)
    assert got.keys() == want.keys()
    for name in want:  # turned to Z and back: the Y-up database's result
        assert float((got[name] - want[name]).abs().max()) < 1e-4, name
    # onto a Z-up database's skeleton: labelled z, and the Y-up result turned onto Z
    onto_z = retarget_clips(y, to=str(z), out=tmp_path / "y_on_z.h5").output
    itself = retarget_clips(y, to=str(y), out=tmp_path / "y_on_y.h5").output
    with MotionDatabase.open(onto_z) as db:
        assert db.skeleton_info(0).up_axis == "z" and db.attrs["up_axis"] == "z"
    want, got = _read_all(itself), _read_all(onto_z)
    for name in want:
        assert float((got[name] - _turn(want[name], "z")).abs().max()) < 1e-4, name
        assert _standing(got[name], load_spec("sample"), turned(sample_motions()[0], "z").skeleton, "z") > 0.8


def test_a_z_up_database_exports_to_humanml3d_as_its_y_up_twin(twins, tmp_path):
    y, z = twins
    names = sample_motions()[0].name, sample_motions()[1].name
    for path, out in ((y, tmp_path / "y"), (z, tmp_path / "z")):
        export_clips(path, list(names), out=out, format="humanml3d")
    for f in sorted((tmp_path / "y" / "new_joints").glob("*.npy")):
        want, got = np.load(f), np.load(tmp_path / "z" / "new_joints" / f.name)
        assert got.shape == want.shape
        assert float(np.abs(got - want).max()) < 1e-4, f.name  # Y up, feet on the floor, as the twin's


def test_splice_all_retargets_actions_on_another_up_axis_or_says_why_not(twins, tmp_path):
    y, z = twins
    want = splice_all(y, tmp_path / "yy.h5", actions_db=y, methods="splice")
    got = splice_all(y, tmp_path / "yz.h5", actions_db=z, methods="splice")
    assert got.spliced == want.spliced > 0
    a, b = _read_all(tmp_path / "yy.h5"), _read_all(tmp_path / "yz.h5")
    assert a.keys() == b.keys()
    for name in a:  # the Z-up actions turned back onto Y: the same upper bodies, to within the feet's fix
        assert float((a[name] - b[name]).norm(dim=-1).max()) < 0.02 * float(a[name][..., 1].max()), name
    with pytest.raises(TorchspliceError, match=r"z.h5: up axis 'z' differs from .*y.h5's 'y'.*retarget is off"):
        splice_all(y, tmp_path / "off.h5", actions_db=z, methods="splice", retarget=False)
    assert not (tmp_path / "off.h5").exists()
