"""torchsplice.data: MotionDataset's derived features: positions and global rotations (forward
kinematics), animated and unanimated translations, velocities (finite differences, windows
included) and per-frame columns."""

from __future__ import annotations

import torch

from torchsplice.core.fk import forward_kinematics
from torchsplice.data import MotionDataset
from torchsplice.store.database import MotionDatabase


def velocities_of(pos: torch.Tensor, fps: float) -> torch.Tensor:
    """Reference finite differences, written out frame by frame."""
    v = torch.zeros_like(pos)
    for t in range(1, pos.shape[0]):
        v[t] = (pos[t] - pos[t - 1]) * fps
    if pos.shape[0] > 1:
        v[0] = v[1]
    return v


def test_positions_and_global_rotations_are_forward_kinematics(plain_db, motions):
    ds = MotionDataset(plain_db, window=45, stride=40, features=("positions", "global_rotations"))
    with MotionDatabase.open(plain_db) as db:
        full = {}
        for m in motions:
            r = db.read(m.name)
            full[m.name] = (r.global_positions(), forward_kinematics(r.rotations, r.root_translation,
                                                                      r.skeleton.offsets.float(), r.skeleton.parents)[1])
    for i in range(0, len(ds), 3):
        item = ds[i]
        s = item["start"]
        pos, grot = full[item["name"]]
        assert item["positions"].shape == (45, 22, 3) and item["global_rotations"].shape == (45, 22, 4)
        torch.testing.assert_close(item["positions"], pos[s:s + 45], rtol=0, atol=1e-4)
        torch.testing.assert_close(item["global_rotations"], grot[s:s + 45], rtol=0, atol=1e-6)
    assert "rotations" not in ds[0]


def test_features_with_animated_translations(two_skeleton_db):
    ds = MotionDataset(two_skeleton_db, where={"skeleton": 0}, features=("translations", "positions", "velocities"))
    assert ds.names == ["anim_a", "anim_one_frame", "anim_b"]
    with MotionDatabase.open(two_skeleton_db) as db:
        for i in range(len(ds)):
            item = ds[i]
            ref = db.read(item["name"])
            assert ref.translations is not None
            assert torch.equal(item["translations"], ref.local_translations())
            assert not torch.equal(item["translations"][:, 1], ref.skeleton.offsets[1].float().expand(item["length"], 3))
            torch.testing.assert_close(item["positions"], ref.global_positions(), rtol=0, atol=1e-5)
            torch.testing.assert_close(item["velocities"], velocities_of(ref.global_positions(), 24.0), rtol=0, atol=1e-3)
    assert torch.equal(ds[1]["velocities"], torch.zeros(1, 5, 3))  # one frame: no motion to measure


def test_translations_are_offsets_where_not_animated(plain_db):
    item = MotionDataset(plain_db, clips=["wave"], features=("translations", "root_translation"))[0]
    sk = MotionDataset(plain_db, clips=["wave"]).skeleton
    assert torch.equal(item["translations"][:, 0], item["root_translation"])
    assert torch.equal(item["translations"][:, 1:], sk.offsets[1:].float().expand(item["length"], -1, -1))


def test_velocities_are_finite_differences(plain_db, motions):
    whole = MotionDataset(plain_db, features=("velocities", "positions"))
    windows = MotionDataset(plain_db, window=30, stride=25, features=("velocities",))
    clip_vel = {}
    for i in range(len(whole)):
        item = whole[i]
        v, p = item["velocities"], item["positions"].double()
        ref = velocities_of(p, item["fps"])
        torch.testing.assert_close(v.double(), ref, rtol=1e-5, atol=1e-3)
        assert torch.equal(v[0], v[1])
        clip_vel[item["name"]] = v
    for i in range(len(windows)):
        item = windows[i]
        s = item["start"]
        # a window inside a clip uses the frame before it: its velocities are the clip's
        torch.testing.assert_close(item["velocities"], clip_vel[item["name"]][s:s + 30], rtol=0, atol=1e-4)


def test_per_frame_column_feature(spliced_db):
    ds = MotionDataset(spliced_db, where={"role": "spliced"}, window=32, stride=50, features=("action_frame", "rotations"))
    with MotionDatabase.open(spliced_db) as db:
        for i in range(len(ds)):
            item = ds[i]
            s = item["start"]
            col = torch.from_numpy(db.read_frame_column(item["name"], "action_frame"))
            assert item["action_frame"].shape == (32,)
            assert torch.equal(item["action_frame"], col[s:s + 32])
            assert torch.equal(item["action_frame"], torch.arange(s, s + 32) * 0.5 + item["action_frame"][0] - s * 0.5)
    inputs = MotionDataset(spliced_db, where={"role": "locomotion"}, features=("action_frame",))
    assert torch.isnan(inputs[0]["action_frame"]).all()  # not given for input clips
