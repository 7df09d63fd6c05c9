"""Mirror images of clips on any skeleton (``ops.mirror``, ``mirror_clips``, ``torchsplice mirror``):
positions the reflection of the partner joints' (exact for any rest pose whose two sides are
congruent: the sample's, Bandai Namco's with every bone along +X, LAFAN1's), the classic
quaternion reflection on a symmetric rig, mirroring twice the identity, labels swapped, and the
database written with its columns and splits kept together."""

from __future__ import annotations

import csv

import pytest
import torch

from realdata import BANDAI
from torchsplice.core.errors import TorchspliceError
from torchsplice.core.fk import end_site_positions, forward_kinematics
from torchsplice.core.motion import Motion
from torchsplice.core.rotations import quat_angle
from torchsplice.core.skeleton import Skeleton
from torchsplice.formats.bvh import read_bvh
from torchsplice.data.splits import clip_sources, table_splits
from torchsplice.ops.mirror import mirror_labels, mirror_motion, mirror_rest, mirror_rig, mirror_text, side_partners
from torchsplice.retarget.mirror import mirror_clips
from torchsplice.specs import load_spec
from torchsplice.sample import sample_motion, sample_motions
from torchsplice.store.database import MotionDatabase

F64 = torch.float64


def points(m: Motion) -> torch.Tensor:
    """``(T, J + E, 3)`` joints and end sites, float64."""
    sk = m.skeleton
    pos, g = forward_kinematics(m.rotations.to(F64), m.root_translation.to(F64), sk.offsets.to(F64), sk.parents,
                                None if m.translations is None else m.translations.to(F64))
    if not sk.end_site_parents:
        return pos
    return torch.cat([pos, end_site_positions(pos, g, sk.end_site_parents, sk.end_site_offsets.to(F64))], 1)


def reflected_partners(m: Motion) -> torch.Tensor:
    """What the mirror image's points must be: each partner's, X negated (end sites by their joints' partners)."""
    sk = m.skeleton
    sigma = side_partners(sk)
    ends = list(sk.end_site_parents)
    by = {}
    for e, p in enumerate(ends):
        by.setdefault(p, []).append(e)
    order = sigma + [sk.num_joints + by[sigma[p]][by[p].index(e)] for e, p in enumerate(ends)]
    return points(m)[:, order] * torch.tensor([-1.0, 1.0, 1.0], dtype=F64)


def real(mocap_dir, folder, stem, frames=120) -> Motion:
    m = read_bvh(mocap_dir / folder / f"{stem}.bvh")
    return m.slice(0, min(frames, m.num_frames))


def test_the_sample_rig_is_symmetric_so_the_mirror_is_the_classic_quaternion_reflection():
    m = sample_motion("wave", dtype=F64).slice(0, 60)
    sigma = side_partners(m.skeleton)
    assert torch.equal(mirror_rest(m.skeleton, sigma, 0, 1), torch.eye(3, dtype=F64).expand(m.skeleton.num_joints, 3, 3))
    mm = mirror_motion(m)
    classic = m.rotations[:, sigma] * torch.tensor([1.0, 1.0, -1.0, -1.0], dtype=F64)  # reflect X: (w, x, -y, -z)
    assert float(quat_angle(mm.rotations, classic).max()) < 1e-6
    assert torch.allclose(points(mm), reflected_partners(m), atol=1e-9)


def rest_misfit(sk: Skeleton) -> float:
    """How far the rig's two sides are from congruent: per joint, ``|S_k o_c - M o_sigma(c)|`` of its
    rest offset, summed along each chain from the root; the largest. The mirror's points can miss
    the reflection by this much (twice, both ends of a chain), and no more."""
    sigma = side_partners(sk)
    S = mirror_rest(sk, sigma, 0, 1)
    off = sk.offsets.to(F64)
    M = torch.tensor([-1.0, 1.0, 1.0], dtype=F64)
    miss = [0.0] + [float((S[sk.parents[c]] @ off[c] - M * off[sigma[c]]).norm()) for c in range(1, sk.num_joints)]
    total = []
    for j in range(sk.num_joints):
        s, k = 0.0, j
        while k >= 0:
            s, k = s + miss[k], sk.parents[k]
        total.append(s)
    return max(total)


@pytest.mark.parametrize("folder,stem,congruent", [
    (BANDAI, "dataset-2_wave-right-hand_normal_001", True),
    (BANDAI, "dataset-1_bye_normal_001", True),
    ("lafan1_via_pypi_bvhtools", "test", True),
    ("cmu_graphics_lab", "cmu_12_01_walk", False),
])
def test_any_rest_pose_mirrors_to_within_its_sides_difference_and_twice_is_the_clip(mocap_dir, folder, stem, congruent):
    """Bandai Namco (every bone along its parent's +X: the rest is conjugated, not the identity)
    and LAFAN1 have congruent sides up to the files' rounding, so the mirror is exact to that;
    CMU's differ by a few millimetres, and the mirror misses by no more."""
    m = real(mocap_dir, folder, stem)
    m = Motion(m.skeleton, m.rotations.to(F64), m.root_translation.to(F64), m.fps,
               None if m.translations is None else m.translations.to(F64), name=m.name, labels=dict(m.labels))
    size = m.skeleton.size()
    misfit = rest_misfit(m.skeleton)
    assert (misfit < 1e-5 * size) == congruent, misfit / size
    mm = mirror_motion(m)
    J = m.skeleton.num_joints
    err = float((points(mm) - reflected_partners(m))[:, :J].norm(dim=-1).max())
    assert err <= 2 * misfit + 1e-9 * size, (err, misfit)
    back = mirror_motion(mm)  # twice: the clip, but for the sides' difference once more
    assert float((points(back) - points(m))[:, :J].norm(dim=-1).max()) <= 4 * misfit + 1e-9 * size
    if congruent:
        assert float(quat_angle(back.rotations, m.rotations).max()) < 1e-3
    if folder.startswith("bandai"):
        S = mirror_rest(m.skeleton, side_partners(m.skeleton), 0, 1)
        assert (S - torch.eye(3, dtype=F64)).abs().amax(dim=(1, 2)).max() > 1.0


def test_joints_pair_by_name_or_the_skeleton_is_refused_in_one_line():
    names = ["Hips", "LeftUpLeg", "RightUpLeg", "l_hand", "r_hand", "RToe", "LToe", "Spine"]
    parents = [-1, 0, 0, 0, 0, 2, 1, 0]
    sk = Skeleton(names, parents, torch.zeros(len(names), 3, dtype=F64), [[] for _ in names])
    assert side_partners(sk) == [0, 2, 1, 4, 3, 6, 5, 7]
    lopsided = Skeleton(["Hips", "LeftHand", "Spine"], [-1, 0, 0], torch.zeros(3, 3, dtype=F64), [[], [], []])
    with pytest.raises(TorchspliceError, match="'LeftHand' has no partner 'RightHand'"):
        side_partners(lopsided, "x.h5: skeleton 0")
    crossed = Skeleton(["Hips", "Spine", "LeftArm", "RightArm"], [-1, 0, 1, 0], torch.zeros(4, 3, dtype=F64), [[]] * 4)
    with pytest.raises(TorchspliceError, match="pair by name but not in the hierarchy"):
        side_partners(crossed)


def test_labels_swap_left_and_right_as_words_and_parts_of_words():
    assert mirror_text("wave-right-hand") == "wave-left-hand"
    assert mirror_text("LEFT_ARM turns Clockwise, handLeft") == "RIGHT_ARM turns Counterclockwise, handRight"
    assert mirror_text("leftover bright") == "leftover bright"
    assert mirror_text(mirror_text("walk-turn-left counterclockwise")) == "walk-turn-left counterclockwise"


def test_mirror_clips_writes_originals_and_mirrors_with_columns_and_splits_together(sample_db, tmp_path):
    """(The ``mirror`` command's one line for the refusal: tests/cli/test_command_words.py.)"""
    from torchsplice import export_clips, splice_all

    spliced = tmp_path / "sp.h5"
    splice_all(sample_db, spliced, workers=1)
    out = tmp_path / "m.h5"
    text = mirror_clips(spliced, select="role:spliced", out=out).summary()
    with MotionDatabase.open(spliced) as d:
        src = d.clip_table()
        names = [n for n, r in zip(src.names, src.role) if r == "spliced"]
        cost = {n: float(c) for n, c in zip(src.names, src.extra["cost"])}
    with MotionDatabase.open(out) as d:
        t = d.clip_table()
        assert list(t.names) == [x for n in names for x in (n, n + ".mirror")]
        assert all(float(c) == cost[n.removesuffix(".mirror")] for n, c in zip(t.names, t.extra["cost"]))
        assert all(t.labels[i].get("mirror_of") == t.names[i - 1] for i in range(1, len(t.names), 2))
        m, mm = d.read(names[0]), d.read(names[0] + ".mirror")
    assert torch.allclose(points(mm), reflected_partners(m), atol=1e-3)  # float32 storage
    assert f"{2 * len(names)} clips" in text and f"{len(names)} of them mirror images" in text
    export_clips(out, out=tmp_path / "bvh")
    split = {r["clip"]: r["split"] for r in csv.DictReader(open(tmp_path / "bvh" / "index.csv"))}
    assert all(split[n + ".mirror"] == split[n] for n in names) and set(split.values()) - {""}
    with pytest.raises(TorchspliceError, match="exists already") as exc:
        mirror_clips(out, out=tmp_path / "again.h5")
    assert ".mirror.mirror' exists" not in str(exc.value) and "\n" not in str(exc.value)
    assert not (tmp_path / "again.h5").exists()


def test_letters_alone_pair_only_with_a_partner_and_words_only_as_words():
    """``ROOT`` is not the partner of a ``LOOT`` (the letter rule pairs only where the partner
    exists; else the joint is the centre), ``Bright`` holds no ``right``, and capitals and
    CamelCase parts pair as words."""
    names = ["ROOT", "Bright", "LEFTARM", "RIGHTARM", "handLeft", "handRight", "RHand", "LHand", "R"]
    parents = [-1, 0, 1, 1, 2, 3, 4, 5, 0]
    sk = Skeleton(names, parents, torch.zeros(len(names), 3, dtype=F64), [[] for _ in names])
    assert side_partners(sk) == [0, 1, 3, 2, 5, 4, 7, 6, 8]
    loose = ["Hips", "Leftupleg", "Leftleg", "Rightupleg", "Rightleg", "lhand", "rhand", "HANDLEFT", "HANDRIGHT"]
    sk = Skeleton(loose, [-1, 0, 1, 0, 3, 0, 0, 0, 0], torch.zeros(len(loose), 3, dtype=F64), [[] for _ in loose])
    assert side_partners(sk) == [0, 3, 4, 1, 2, 6, 5, 8, 7]  # sides inside words pair where the partner exists
    sideless = Skeleton(["Hips", "Spine", "Head"], [-1, 0, 1], torch.zeros(3, 3, dtype=F64), [[]] * 3)
    with pytest.raises(TorchspliceError, match="x.h5: cannot mirror: no joint's name says its side"):
        side_partners(sideless, "x.h5")
    worded = Skeleton(["ROOT", "Bright", "LEFTARM"], [-1, 0, 1], torch.zeros(3, 3, dtype=F64), [[]] * 3)
    with pytest.raises(TorchspliceError, match="'LEFTARM' has no partner 'RIGHTARM'"):  # a word must pair
        side_partners(worded)


def test_mirrored_rotations_are_canonical_over_time(mocap_dir):
    """The first frame's w >= 0 and no sign flip between frames, on a real clip turning through
    half turns (the matrix-to-quaternion step alone flips signs)."""
    m = real(mocap_dir, BANDAI, "dataset-2_walk-turn-left_active_025", 400)
    mm = mirror_motion(m)
    q = mm.rotations.to(F64)
    assert float(q[0, :, 0].min()) >= 0
    assert float((q[1:] * q[:-1]).sum(-1).min()) > 0
    sigma = side_partners(m.skeleton)  # the same motion: each step turns as far as the partner's does
    step = quat_angle(m.rotations[1:], m.rotations[:-1])[:, sigma]
    assert torch.allclose(quat_angle(mm.rotations[1:], mm.rotations[:-1]), step, atol=1e-3)


def test_labels_that_name_clips_or_files_are_not_swapped():
    labels = {"content": "wave-right-hand", "split_from": "take-left", "split_frame": "12", "split": "test",
              "path": "/data/right/x.bvh", "retargeted_from": "right.h5", "action.split_from": "wave-right",
              "action.content": "wave-right-hand", "action.mirror_of": "wave-left", "locomotion": "walk-turn-left",
              "action": "wave-right-hand", "method": "splice"}
    out = mirror_labels(labels, "walk-turn-left+wave-right-hand")
    assert out["content"] == out["action.content"] == "wave-left-hand"
    for k in ("split_from", "split_frame", "split", "path", "retargeted_from", "action.split_from",
              "action.mirror_of", "locomotion", "action"):
        assert out[k] == labels[k], k
    assert out["mirror_of"] == "take-left"  # a window's take
    assert mirror_labels({"locomotion": "turn-left"}, "x")["locomotion"] == "turn-right"  # a label, not a source


def test_a_mirrored_window_and_a_window_of_a_mirror_split_with_their_take(tmp_path):
    """Windows of one take are one source; so are their mirror images and the windows of the
    take's mirror image: every split puts them all in one split."""
    spec = load_spec("sample")
    clips = [c.slice(0, 90) for c in sample_motions()]
    db, out = tmp_path / "db.h5", tmp_path / "mirrored.h5"
    with MotionDatabase.create(db) as w:
        for c in clips:
            w.append(c, spec=spec)
            for win in c.windows(1.0):  # 3 windows of each take
                w.append(win, spec=spec)
            for win in mirror_motion(c, name=c.name + ".flip").windows(1.0):
                w.append(win, spec=spec)
    mirror_clips(db, out=out, select="label:split_from=*")  # the windows, each with its mirror image
    with MotionDatabase.open(out) as d:
        table = d.clip_table()
    assert len(table.names) == 2 * 6 * len(clips)
    keys = {n: clip_sources(n, str(r), {"labels": table.labels[i]}) for i, (n, r) in enumerate(zip(table.names, table.role))}
    for c in clips:
        mine = [n for n in table.names if n.startswith(c.name + "#") or n.startswith(c.name + ".flip#")]
        assert len(mine) == 12 and {k for n in mine for k, _ in sum(keys[n], [])} == {c.name}, mine
    for seed in range(5):
        split = dict(zip(table.names, table_splits(table, (0.4, 0.3, 0.3), seed)))
        for c in clips:
            assert len({split[n] for n in table.names if n.split("#")[0].split(".")[0] == c.name}) == 1


def test_mirroring_many_clips_computes_the_rig_once_and_the_mirrors_alone_may_be_mirrored_again(sample_db, tmp_path,
                                                                                                monkeypatch):
    m = sample_motion("wave", dtype=F64).slice(0, 30)
    given = mirror_motion(m, rig=mirror_rig(m.skeleton, "y"))
    assert torch.equal(given.rotations, mirror_motion(m).rotations)
    import torchsplice.retarget.mirror as retarget_mirror

    calls = []
    monkeypatch.setattr(retarget_mirror, "mirror_rig", lambda *a, **k: calls.append(a[0]) or mirror_rig(*a, **k))
    mirror_clips(sample_db, out=tmp_path / "counted.h5")
    with MotionDatabase.open(sample_db) as d:
        assert len(calls) == len(d.skeletons) < len(d)  # once per skeleton, not per clip
    both = tmp_path / "both.h5"
    mirror_clips(sample_db, out=both)
    with pytest.raises(TorchspliceError, match="exists already"):
        mirror_clips(both, out=tmp_path / "again.h5")
    report = mirror_clips(both, out=tmp_path / "again.h5", originals=False)  # X.mirror.mirror: new names
    with MotionDatabase.open(both) as a, MotionDatabase.open(tmp_path / "again.h5") as b:
        assert report.clips == len(b) == len(a) and all(n + ".mirror" in b.names for n in a.names)
        assert b.clip_table().labels[b.index("wave.mirror.mirror")]["mirror_of"] == "wave"
