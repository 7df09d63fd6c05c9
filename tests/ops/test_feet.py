"""Feet fixed after retargeting (:mod:`torchsplice.ops.feet`).

Known answers: two-bone IK reaches every reachable target exactly, keeps bone lengths and the
foot's world rotation, and straightens toward one out of reach; the pin's blend weights; a clip
on its own skeleton is left as it is. Real rigs: retargeted between Bandai Namco, CMU (both
namings), LAFAN1 and the sample, the feet slide no more than the source's plus 1 cm/s, go no
lower below the floor than the source's by more than 1 cm, and the upper body is untouched.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch

from tests.ops.test_retarget import real_clips, roles_of
from torchsplice.core.rotations import quat_angle, quat_apply, quat_normalize
from torchsplice.core.fk import forward_kinematics
from torchsplice.evaluation.retargeting import centimetres, feet_figures
from torchsplice.ops.feet import _blend_weight, _pins, rig_heights, two_bone_ik
from torchsplice.ops.retarget import retarget_map, retarget_motion
from torchsplice.sample import sample_motions
from torchsplice.specs import detect_spec
from torchsplice.specs.canonical import canonical_joints, canonical_legs


def _chain(n: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    hip = torch.randn(n, 3, generator=g, dtype=torch.float64)
    g_hip = quat_normalize(torch.randn(n, 4, generator=g, dtype=torch.float64))
    g_knee = quat_normalize(torch.randn(n, 4, generator=g, dtype=torch.float64))
    thigh, shin = torch.tensor([0.0, -0.45, 0.0], dtype=torch.float64), torch.tensor([0.0, -0.4, 0.02], dtype=torch.float64)
    knee = hip + quat_apply(g_hip, thigh.expand(n, 3))
    ankle = knee + quat_apply(g_knee, shin.expand(n, 3))
    return hip, knee, ankle, g_hip, g_knee, thigh, shin, g


def test_two_bone_ik_reaches_every_reachable_target_and_keeps_bone_lengths():
    hip, knee, ankle, g_hip, g_knee, thigh, shin, g = _chain(2000)
    a, b = thigh.norm(), shin.norm()
    # targets at random directions and reachable distances from the hip
    direction = torch.randn(2000, 3, generator=g, dtype=torch.float64)
    direction = direction / direction.norm(dim=-1, keepdim=True)
    dist = (a - b).abs() + 0.01 + torch.rand(2000, 1, generator=g, dtype=torch.float64) * ((a + b) * 0.99 - (a - b).abs() - 0.01)
    target = hip + direction * dist
    q_hip, q_knee = two_bone_ik(hip, knee, ankle, target, g_hip, g_knee)
    new_knee = hip + quat_apply(q_hip, thigh.expand(2000, 3))
    new_ankle = new_knee + quat_apply(q_knee, shin.expand(2000, 3))
    assert float((new_ankle - target).norm(dim=-1).max()) < 1e-9
    # the knee bends to the side it bent to: its offset from the hip-target line keeps its side
    u = (target - hip) / dist

    def side(k):
        off = (k - hip) - ((k - hip) * u).sum(-1, keepdim=True) * u
        return off

    bent = side(knee).norm(dim=-1) > 1e-3 * float(a)  # a straight leg has no side to keep
    assert bool(((side(knee) * side(new_knee)).sum(-1) > 0)[bent].all()) and int(bent.sum()) > 1900


def test_two_bone_ik_straightens_toward_a_target_out_of_reach_and_leaves_a_reached_one():
    hip, knee, ankle, g_hip, g_knee, thigh, shin, g = _chain(200, seed=1)
    far = hip + (ankle - hip) / (ankle - hip).norm(dim=-1, keepdim=True) * 5.0
    q_hip, q_knee = two_bone_ik(hip, knee, ankle, far, g_hip, g_knee)
    new_ankle = hip + quat_apply(q_hip, thigh.expand(200, 3)) + quat_apply(q_knee, shin.expand(200, 3))
    along = (new_ankle - hip) / (new_ankle - hip).norm(dim=-1, keepdim=True)
    aim = (far - hip) / (far - hip).norm(dim=-1, keepdim=True)
    assert float((along - aim).norm(dim=-1).max()) < 1e-6  # on the line to the target, as far as it goes
    assert float((new_ankle - hip).norm(dim=-1).min()) > 0.99 * float(thigh.norm() + shin.norm())
    # a target where the ankle already is: the leg as it was
    q_hip, q_knee = two_bone_ik(hip, knee, ankle, ankle, g_hip, g_knee)
    assert float(quat_angle(q_hip, g_hip).max()) < 1e-6 and float(quat_angle(q_knee, g_knee).max()) < 1e-6


def test_a_pin_blends_in_and_out_linearly_over_its_frames():
    held = np.zeros(20, dtype=bool)
    held[8:11] = True
    w = _blend_weight(held, np.zeros(20, dtype=np.int64), np.full(20, 3))
    expected = [0, 0, 0, 0, 0, 0.25, 0.5, 0.75, 1, 1, 1, 0.75, 0.5, 0.25, 0, 0, 0, 0, 0, 0]
    assert np.allclose(w, expected)
    assert float(np.abs(_blend_weight(np.zeros(5, dtype=bool), np.zeros(5, dtype=np.int64), np.full(5, 3))).max()) == 0.0
    # two clips back to back: a pin at the end of the first does not blend into the second
    clip = np.repeat([0, 1], 10)
    held = np.zeros(20, dtype=bool)
    held[8:10] = True
    w = _blend_weight(held, clip, np.full(20, 3))
    assert np.allclose(w[:10], [0, 0, 0, 0, 0, 0.25, 0.5, 0.75, 1, 1]) and np.all(w[10:] == 0)


def test_pins_hold_each_run_and_hand_over_from_heel_to_toe_without_a_jump():
    """A known answer: an ankle run then a toe run; the ankle is held at its run's mean offset
    from the source's path, and the toe then stays where the foot left it."""
    N = 12
    pos = np.zeros((N, 2, 3))
    pos[:, 0, 0] = np.arange(N) * 0.1  # the target's ankle drifts along x
    pos[:, 1] = pos[:, 0] + [0.0, 0.0, 0.2]  # its toe, 0.2 ahead
    guide = np.zeros((N, 2, 3))  # the source's ankle and toe stand still at 0 and (0, 0, 0.2)
    guide[:, 1, 2] = 0.2
    ankle = np.zeros(N, dtype=bool)
    ankle[2:6] = True
    toe = np.zeros(N, dtype=bool)
    toe[2:9] = True
    first = np.zeros(N, dtype=bool)
    first[0] = True
    pinned, held = _pins(pos, guide, 0, 1, 0, 1, ankle, toe, first)
    # each contact widened by a frame on both sides (speeds by central differences read them)
    assert held.tolist() == [False] + [True] * 9 + [False] * 2
    assert np.allclose(pinned[1:7, 0], 0.35)  # the ankle run's mean x: (0.1 + ... + 0.6) / 6
    toe_at = pinned[7:10] + (pos[7:10, 1] - pos[7:10, 0])
    assert np.allclose(toe_at[:, 0], 0.35) and np.allclose(toe_at[:, 2], 0.2)  # where the foot left it
    assert np.allclose(pinned[:1], pos[:1, 0]) and np.allclose(pinned[10:], pos[10:, 0])  # free frames as they are


def _cm(skeleton) -> float:
    return centimetres(detect_spec(skeleton))


RIGS = ("bandai_namco", "cmu", "cmu_max", "lafan1", "sample")


def _clip(rig):
    return sample_motions()[0].to(torch.float64) if rig == "sample" else real_clips()[rig]


@pytest.mark.parametrize("source,target", [p for p in itertools.permutations(RIGS, 2)])
def test_fixed_feet_slide_no_more_than_the_source_and_stay_above_its_floor(source, target):
    """As the command and the job run it (the target rig's own resting foot heights, measured on
    its clip): foot skate (the evaluation's measure, in cm/s of each rig) at most the source's,
    scaled like the trajectory, plus 1 cm/s; no ankle or toe sinks further below its resting
    height than the source's, by more than 1 cm (:func:`feet_figures`); each foot keeps the world
    rotation the analytic retargeting gave it, and the upper body is the analytic one."""
    a, b = _clip(source), _clip(target)
    ra, rb = roles_of(a.skeleton), roles_of(b.skeleton)
    rmap = retarget_map(a.skeleton, ra, b.skeleton, rb)
    heights = rig_heights([b], list(canonical_legs(canonical_joints(rb, b.skeleton))), rb.up_axis)
    fixed = retarget_motion(a, rmap, target_heights=heights)
    plain = retarget_motion(a, rmap, fix_feet=False)
    f = feet_figures(a, fixed, rmap, ra, rb, _cm(a.skeleton), _cm(b.skeleton), heights)
    assert f["skate"] <= f["skate_source"] + 1.0, f
    assert f["lower"] <= 1.0, f
    _, g_fixed = forward_kinematics(fixed.rotations, fixed.root_translation, b.skeleton.offsets, b.skeleton.parents,
                                    fixed.translations)
    _, g_plain = forward_kinematics(plain.rotations, plain.root_translation, b.skeleton.offsets, b.skeleton.parents,
                                    plain.translations)
    ankles = [leg[2] for leg in rmap.legs]
    assert float(quat_angle(g_fixed[:, ankles], g_plain[:, ankles]).max()) < 1e-6
    # the arms, spine and head are the analytic retargeting's (only legs and the pelvis's height move)
    legs = {j for leg in rmap.legs for j in leg[:3]}
    upper = [j for j in range(b.skeleton.num_joints) if j not in legs and j not in (rmap.pelvis[0],)]
    ancestors = set()
    for j in legs | {rmap.pelvis[0]}:
        while j >= 0:
            ancestors.add(j)
            j = b.skeleton.parents[j]
    upper = [j for j in upper if j not in ancestors]
    assert upper and float(quat_angle(fixed.rotations[:, upper], plain.rotations[:, upper]).max()) < 1e-9
