"""The clip bank the compiled splicer reads (:mod:`torchsplice.cpu.bank`): its joint tables
named, and a bank saved and loaded (as the job shares it with its workers) splices the same
bits as the bank it was saved from."""

from __future__ import annotations

import pickle

import numpy as np

from torchsplice.cpu.bank import ClipBank, JointTables, splice_bank
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec


def _bank() -> ClipBank:
    clips = {c.name: c for c in sample_motions()}
    names = ["walk_straight", "walk_curve", "turn_sharp", "carry_box", "wave"]
    motions = [clips[n] for n in names]
    sk = motions[0].skeleton
    return ClipBank.from_motions(motions, sk, load_spec("sample").bind(sk))


def test_the_joint_tables_are_named_and_the_kernels_tuple_in_their_order():
    bank = _bank()
    j = bank.joints
    assert isinstance(j, JointTables) and tuple(j) == (j.parents, j.upper, j.fk_joints, j.act_joints, j.landmarks,
                                                       j.hips, j.shoulders, j.pcloud, j.pelvis, j.pelvis_parent, j.up)
    assert j.upper.dtype == np.bool_ and j.parents.dtype == np.int64 and j.parents[j.pelvis] == j.pelvis_parent
    assert set(j.fk_joints.tolist()) <= set(j.act_joints.tolist()) and j.upper[j.act_joints].any()
    assert pickle.loads(pickle.dumps(j))._fields == JointTables._fields


def test_a_saved_bank_loads_with_the_same_tables_and_splices_the_same_bits(tmp_path):
    bank = _bank()
    bank.save(tmp_path / "bank")
    back = ClipBank.load(tmp_path / "bank")
    for a, b in zip(bank.joints, back.joints):
        assert type(a) is type(b) and np.array_equal(a, b) and np.asarray(a).dtype == np.asarray(b).dtype
    loco, act = np.array([0, 1, 2, 0]), np.array([3, 3, 4, 4])
    x, y = splice_bank(bank, loco, act), splice_bank(back, loco, act)
    assert np.array_equal(x.frames, y.frames) and np.array_equal(x.rotations, y.rotations)
    assert np.array_equal(x.translations, y.translations)
