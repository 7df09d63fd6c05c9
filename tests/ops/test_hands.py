"""Keeping hands out of the body (:mod:`torchsplice.ops.hands`), and the job's correction.

Known answers: two-bone IK points the arm at its target with the bones' lengths kept, meets a
target at the arm's own reach, gives back the arm for its own wrist, moves the reach towards the
target's and never past it or snapped straight; an elbow's hinge is recovered from a clip
whose arm bends about a fixed axis, and the IK moves the elbow as smoothly through a straight
arm as elsewhere; the spread in
time of a lone push is the dilated Hann window worked by hand, and stays within its clip; an arm
swung through the chest comes out of it, smoothly, with nothing else changed and frames beyond
the correction's reach bit for bit; a clean clip, and a clip allowed as deep, come back as they
were. On a real job (Bandai Namco runs, dashes and turns x raised hands and waves), the
correction takes every hand out where neither source has one inside, leaves the feet and
lower body exactly, keeps the arms' range, and an alignment store assembles the same frames.
"""

from __future__ import annotations

import json

import math

import numpy as np
import pytest
import torch

from torchsplice.core.fk import forward_kinematics
from torchsplice.core.rotations import quat_angle, quat_apply, quat_between, quat_conj, quat_mul, quat_slerp
from torchsplice.ops.body import body_of, capsule_ends
from torchsplice.ops.hands import (ITERATIONS, RAMP, arm_ik, arms_of, chest_hinge, elbow_hinges, hinge_axes,
                                   keep_hands_out, spread_in_time)
from torchsplice.ops.plausibility import penetration_packed
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.store.database import MotionDatabase


def test_arm_ik_points_at_the_target_keeps_the_bones_and_changes_the_reach_smoothly():
    g = torch.Generator().manual_seed(5)
    n = 400
    S = torch.randn(n, 3, generator=g, dtype=torch.float64)
    E = S + torch.randn(n, 3, generator=g, dtype=torch.float64) * 0.3
    W = E + torch.randn(n, 3, generator=g, dtype=torch.float64) * 0.3
    l1, l2 = (E - S).norm(dim=-1), (W - E).norm(dim=-1)
    d0 = (W - S).norm(dim=-1)
    flexion = torch.pi - torch.acos(((S - E) * (W - E)).sum(-1) / (l1 * l2))
    direction = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=torch.float64), dim=-1)
    share = torch.rand(n, generator=g, dtype=torch.float64)
    reach = (l1 - l2).abs() + (0.05 + 0.9 * share) * (l1 + l2 - (l1 - l2).abs())
    T = S + direction * reach[:, None]
    plane = torch.linalg.cross(S - E, W - E, dim=-1)  # the arm's own hinge: its forearm turns in its plane
    q1, q2, E2, W2 = arm_ik(S, E, W, T, plane)
    assert torch.allclose(torch.nn.functional.normalize(W2 - S, dim=-1), direction, atol=1e-9)
    assert torch.allclose((E2 - S).norm(dim=-1), l1, atol=1e-12) and torch.allclose((W2 - E2).norm(dim=-1), l2, atol=1e-12)
    # the turns are what moves the bones: the elbow's about itself, then all about the shoulder
    assert torch.allclose(E2, S + quat_apply(q2, E - S), atol=1e-12)
    assert torch.allclose(W2, S + quat_apply(q2, E - S + quat_apply(q1, W - E)), atol=1e-12)
    # the reach moves towards the target's, never past it, and stays short of straight and folded
    got, change = (W2 - S).norm(dim=-1), reach - d0
    assert bool(((got - d0) * change >= 0).all()) and bool(((got - d0).abs() <= change.abs() + 1e-12).all())
    assert bool((got < l1 + l2).all()) and bool((got > (l1 - l2).abs()).all())
    # a bent arm follows a small change of reach to first order; a target at the arm's own reach
    # (moved across the shoulder's sphere) is met; the arm's own wrist gives back the arm
    bent = flexion > 1.0
    small = S + direction * (d0 + 1e-4)[:, None]
    _, _, _, W4 = arm_ik(S, E, W, small, plane)
    assert torch.allclose((W4 - S).norm(dim=-1)[bent], d0[bent] + 1e-4, atol=3e-6)
    sphere = S + direction * d0[:, None]
    _, _, _, W5 = arm_ik(S, E, W, sphere, plane)
    assert torch.allclose(W5, sphere, atol=1e-9)
    _, _, E6, W6 = arm_ik(S, E, W, W, plane)
    assert torch.allclose(E6, E, atol=1e-12) and torch.allclose(W6, W, atol=1e-12)
    # a straight arm (no plane of its own), along the chest's X axis or not, swings onto the
    # target's direction and stays straight: bending it would jolt the elbow
    chest = torch.tensor([1.0, 0, 0, 0], dtype=torch.float64)
    for along in ([1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.6, -0.8, 0.0]):
        u = torch.tensor(along, dtype=torch.float64)
        S1, E1, W1 = torch.zeros(3, dtype=torch.float64), 0.3 * u, 0.55 * u
        aim = torch.nn.functional.normalize(u + torch.tensor([0.0, 0.0, 0.5], dtype=torch.float64), dim=0)
        _, _, E2s, W2s = arm_ik(S1, E1, W1, S1 + 0.4 * aim, chest_hinge(E1 - S1, chest))
        assert torch.allclose(W2s, 0.55 * aim, atol=1e-9) and torch.allclose(E2s, 0.3 * aim, atol=1e-9), along
    # far out of reach: the arm points at the target, stretched towards straight
    far = S + direction * (l1 + l2 + 1.0)[:, None]
    _, _, E3, W3 = arm_ik(S, E, W, far, plane)
    assert torch.allclose(torch.nn.functional.normalize(W3 - S, dim=-1), direction, atol=1e-9)
    stretched = (W3 - S).norm(dim=-1)
    assert bool((stretched >= d0 - 1e-12).all()) and bool((stretched <= l1 + l2 + 1e-12).all())


def _bending_arm(flexion: torch.Tensor, seed: int = 3):
    """An arm whose upper arm turns at random and whose elbow bends by ``flexion`` (radians,
    ``(N,)``; 0 straight, below 0 overstretched) about the upper arm's local Z axis: ``(S, E, W,
    upper_rot)``."""
    g = torch.Generator().manual_seed(seed)
    N = len(flexion)
    upper_rot = quat_slerp(torch.tensor([1.0, 0, 0, 0], dtype=torch.float64).expand(N, 4),
                           torch.nn.functional.normalize(torch.randn(4, generator=g, dtype=torch.float64), dim=0).expand(N, 4),
                           torch.linspace(0, 1, N, dtype=torch.float64))
    x = torch.tensor([1.0, 0, 0], dtype=torch.float64)
    z = torch.tensor([0.0, 0, 1], dtype=torch.float64)
    bend = torch.cat([torch.cos(flexion / 2)[:, None], (z * torch.sin(flexion / 2)[:, None])], -1)
    S = torch.zeros(N, 3, dtype=torch.float64)
    E = S + quat_apply(upper_rot, 0.3 * x.expand(N, 3))
    W = E + quat_apply(quat_mul(upper_rot, bend), 0.25 * x.expand(N, 3))
    return S, E, W, upper_rot


def test_the_clips_elbow_hinge_is_recovered_and_the_ik_bends_about_it_smoothly_through_straight():
    # known answer: an elbow bending about the upper arm's local Z has that hinge, whatever the
    # upper arm does; the plane normal -upper x lower points along -Z for flexion about +Z
    flexion = 0.55 + 0.65 * torch.cos(torch.linspace(0, 2 * torch.pi, 71, dtype=torch.float64))  # -0.1 to 1.2, smooth
    S, E, W, upper_rot = _bending_arm(flexion)
    h = elbow_hinges((E - S)[:, None], (W - E)[:, None], upper_rot[:, None], torch.tensor([len(flexion)]))
    assert torch.allclose(torch.nn.functional.normalize(h[0, 0], dim=0), torch.tensor([0.0, 0, -1], dtype=torch.float64),
                          atol=1e-12)
    straight = elbow_hinges((E - S)[:, None], (E - S)[:, None], upper_rot[:, None], torch.tensor([len(flexion)]))
    assert float(straight.abs().max()) == 0.0  # an arm straight on every frame has none: the chest's is used
    chest = torch.tensor([1.0, 0, 0, 0], dtype=torch.float64).expand(len(flexion), 4)
    axes = hinge_axes(h[0, 0].expand(len(flexion), 3), upper_rot, E - S, chest)
    # the wrist held 10 cm out to the side of where it is: a smooth target through the straight frames
    T = W + torch.tensor([0.0, 0.1, 0.0], dtype=torch.float64)
    q1, q2, E2, W2 = arm_ik(S, E, W, T, axes)
    assert torch.allclose(torch.nn.functional.normalize(W2 - S, dim=-1), torch.nn.functional.normalize(T - S, dim=-1),
                          atol=1e-9)
    step = (E2[1:] - E2[:-1]).norm(dim=-1)
    assert float(step.max()) < 3 * float((E[1:] - E[:-1]).norm(dim=-1).max()) + 0.01  # no flip of the elbow
    # the elbow stays on its hinge: it bends, it does not twist out of the hinge's plane
    twist = quat_apply(quat_conj(quat_mul(q2, upper_rot)), torch.linalg.cross(E2 - S, W2 - E2, dim=-1))
    assert float(twist[:, :2].abs().max()) < 1e-9
    # through the straight frames the elbow moves as smoothly as elsewhere: no kink where it straightens
    bend2 = (E2[2:] - 2 * E2[1:-1] + E2[:-2]).norm(dim=-1)
    straight_frames = (flexion.abs() < 0.1)[1:-1]
    assert float(bend2[straight_frames].max()) <= 1.5 * float(bend2[~straight_frames].max())


def _hann(N: int, w: int, pushed: range, lo: int = 0, hi: int | None = None) -> torch.Tensor:
    """The spread worked by hand: 1 on the frames within ``w`` of a pushed one, then a Hann window of
    half-width ``w`` over the clip's frames ``lo:hi``."""
    hi = N if hi is None else hi
    dilated = [1.0 if any(abs(f - p) <= w for p in pushed) and lo <= f < hi else 0.0 for f in range(N)]
    out = []
    for f in range(N):
        num = den = 0.0
        for d in range(-w, w + 1):
            if lo <= f + d < hi:
                weight = 1 + math.cos(math.pi * d / (w + 1))
                num += weight * dilated[f + d]
                den += weight
        out.append(num / den if lo <= f < hi else 0.0)
    return torch.tensor(out, dtype=torch.float64)


def test_a_lone_push_spreads_into_the_worked_hann_window_within_its_clip():
    fps = 20.0
    w = round(RAMP * fps)
    assert w == 3
    N = 41
    push = torch.zeros(N, 1, 3, dtype=torch.float64)
    push[20, 0] = torch.tensor([0.0, 2.0, 0.0])
    got = spread_in_time(push, torch.tensor([N]), torch.tensor([fps]))
    want = _hann(N, w, range(20, 21))
    assert torch.allclose(got[:, 0, 1], 2 * want, atol=1e-12) and float(got[:, 0, [0, 2]].abs().max()) == 0.0
    assert float(got[20, 0, 1]) == 2.0 and bool((got[:20 - 2 * w, 0].abs() == 0).all())
    assert bool((got[20 + 2 * w + 1:, 0] == 0).all())
    # two clips packed: a push at the first's last frame stays in it, at full size there
    push = torch.zeros(30, 1, 3, dtype=torch.float64)
    push[14, 0, 0] = 1.0
    got = spread_in_time(push, torch.tensor([15, 15]), torch.tensor([fps, fps]))
    assert torch.allclose(got[:, 0, 0], _hann(30, w, range(14, 15), 0, 15), atol=1e-12)
    assert float(got[14, 0, 0]) == 1.0 and bool((got[15:] == 0).all())
    # the larger push wins where two are near, per arm
    push = torch.zeros(20, 2, 3, dtype=torch.float64)
    push[8, 0, 0], push[10, 0, 2], push[10, 1, 1] = 1.0, -3.0, 0.5
    got = spread_in_time(push, torch.tensor([20]), torch.tensor([fps]))
    assert float(got[10, 0, 2]) == -3.0 and float(got[10, 0, 0]) == 0.0 and float(got[10, 1, 1]) == 0.5
    assert float(got[9, 0, 0]) > 0.0  # further from the larger, the smaller one shares the average


def _sample_and_its_torso():
    """The sample's first clip (float64), its roles, body and arms, its joints' positions and
    global rotations, and its right torso capsule: ``(a, b, index, midpoint)``."""
    m = sample_motions()[0].to(torch.float64)
    roles = load_spec("sample").bind(m.skeleton)
    body = body_of(m.skeleton, roles)
    arms = arms_of(m.skeleton, roles, body)
    trans = m.local_translations()
    pos, grot = forward_kinematics(m.rotations, trans[:, 0], m.skeleton.offsets, m.skeleton.parents, trans)
    a, b = capsule_ends(pos, body)
    torso = body.names.index("torso_r")
    return m, roles, body, arms, pos, grot, (a, b, torso, (a[:, torso] + b[:, torso]) / 2)


def _swung_through_the_chest():
    """The sample's first clip (float64), and the same clip with its right arm swung smoothly
    towards the torso's axis over frames 30 to 70 (its upper arm pointing at it at frame 50)."""
    m, roles, body, arms, pos, grot, (a, b, torso, mid) = _sample_and_its_torso()
    sh, el = arms.shoulder[1], arms.elbow[1]
    turn = quat_between(torch.nn.functional.normalize(pos[:, el] - pos[:, sh], dim=-1),
                        torch.nn.functional.normalize(mid - pos[:, sh], dim=-1))
    T = m.num_frames
    weight = torch.zeros(T, dtype=torch.float64)
    f = torch.arange(30, 71, dtype=torch.float64)
    weight[30:71] = torch.sin(torch.pi * (f - 30) / 40) ** 2  # smooth in and out
    ident = torch.zeros_like(turn)
    ident[:, 0] = 1.0
    turn = quat_slerp(ident, turn, weight)
    parent = m.skeleton.parents[sh]
    rot = m.rotations.clone()
    rot[:, sh] = quat_mul(quat_conj(grot[:, parent]), quat_mul(turn, grot[:, sh]))
    return m, rot, roles, body, arms


def test_an_arm_swung_through_the_chest_comes_out_smoothly_and_nothing_else_moves():
    m, rot, roles, body, arms = _swung_through_the_chest()
    trans, T = m.local_translations(), m.num_frames
    fk = lambda r: forward_kinematics(r, trans[:, 0], m.skeleton.offsets, m.skeleton.parents, trans)  # noqa: E731
    before, _ = penetration_packed(fk(rot)[0], [T], body)
    assert float(before) > 0.1  # the swing goes inside
    out, corrected = keep_hands_out(rot, trans, [T], m.fps, m.skeleton, body, arms, 0.0)
    pos, grot = fk(out)
    after, depth = penetration_packed(pos, [T], body)
    assert float(after) == 0.0 and float(depth) == 0.0
    changed = (out != rot).any(-1).any(-1)
    assert int(corrected) == int(changed.sum()) > 0
    # only the shoulders and elbows turn; the root, spine, legs and feet are bit for bit
    others = [j for j in range(m.skeleton.num_joints) if j not in arms.moved]
    assert torch.equal(out[:, others], rot[:, others])
    # frames beyond the correction's reach are bit for bit
    w = round(RAMP * m.fps)
    reach = (2 * ITERATIONS + 1) * w + 1
    first, last = int(changed.nonzero().min()), int(changed.nonzero().max())
    assert first >= 30 - reach and last <= 70 + reach
    # smooth: the wrist in the chest's frame accelerates no more than the swing itself did
    def wrist(p, g):
        return quat_apply(quat_conj(g[:, arms.chest]), p[:, arms.wrist[1]] - p[:, arms.chest])

    p0, g0 = fk(rot)
    acc0 = (wrist(p0, g0)[2:] - 2 * wrist(p0, g0)[1:-1] + wrist(p0, g0)[:-2]).norm(dim=-1)
    acc1 = (wrist(pos, grot)[2:] - 2 * wrist(pos, grot)[1:-1] + wrist(pos, grot)[:-2]).norm(dim=-1)
    assert float(acc1.max()) <= 1.5 * float(acc0.max())
    step = quat_angle(out[1:, arms.shoulder[1]], out[:-1, arms.shoulder[1]])
    step0 = quat_angle(rot[1:, arms.shoulder[1]], rot[:-1, arms.shoulder[1]])
    assert float(step.max()) <= 2 * float(step0.max())  # no pop where the correction starts or ends (one is 15x)


def test_a_clean_clip_and_a_clip_allowed_as_deep_come_back_as_they_were():
    m, rot, roles, body, arms = _swung_through_the_chest()
    trans, T = m.local_translations(), m.num_frames
    out, corrected = keep_hands_out(m.rotations, trans, [T], m.fps, m.skeleton, body, arms, 0.0)
    assert torch.equal(out, m.rotations) and int(corrected) == 0
    out, corrected = keep_hands_out(rot, trans, [T], m.fps, m.skeleton, body, arms, float(body.radii.max()) * 3)
    assert torch.equal(out, rot) and int(corrected) == 0
    # packed beside the clean clip, the swung one is corrected as alone and the clean one is not
    both, counts = keep_hands_out(torch.cat([m.rotations, rot]), torch.cat([trans, trans]), [T, T],
                                  torch.tensor([m.fps, m.fps]), m.skeleton, body, arms, torch.tensor([0.0, 0.0]))
    alone, count = keep_hands_out(rot, trans, [T], m.fps, m.skeleton, body, arms, 0.0)
    assert torch.equal(both[:T], m.rotations) and torch.equal(both[T:], alone)
    assert counts.tolist() == [0, int(count)]
    float32, _ = keep_hands_out(rot.float(), trans.float(), [T], m.fps, m.skeleton, body, arms, 0.0)
    assert float32.dtype == torch.float32
    # no clips: nothing to do, by either backend
    from torchsplice.splice.backends import Backend
    from torchsplice.splice.backends.compiled import CompiledBackend

    for run in (CompiledBackend().keep_hands_out, lambda *a: Backend.keep_hands_out(CompiledBackend(), *a)):
        none, counts = run(rot[:0].float().numpy(), trans[:0].float().numpy(), [], m.fps, m.skeleton, body, arms, [])
        assert none.shape == (0, *rot.shape[1:]) and len(counts) == 0
    got = spread_in_time(torch.zeros(5, 2, 3, dtype=torch.float64), torch.tensor([5]), 30.0)  # a scalar rate
    assert got.shape == (5, 2, 3) and bool((got == 0).all())


def _right_arm_aimed(sweep: torch.Tensor, ahead: torch.Tensor, lateral: float = 0.0):
    """The sample's first clip (float64), and the same clip with its right arm aimed at a point
    ``ahead`` ``(T,)`` torso radii in front of the torso's axis at the chest and ``lateral``
    radii to its side (the torso's outside for the right arm at negative values), blended in
    with ``sweep`` ``(T,)`` (fully aimed from a third of it on). ``(m, rot, body, arms)``."""
    m, roles, body, arms, pos, grot, (a, b, torso, mid) = _sample_and_its_torso()
    sh, wr = arms.shoulder[1], arms.wrist[1]
    unit = lambda v: torch.nn.functional.normalize(v, dim=-1)  # noqa: E731
    axis = unit(b[:, torso] - a[:, torso])
    front = unit(torch.linalg.cross(axis, unit(mid - pos[:, sh]), dim=-1))
    side = unit(torch.linalg.cross(front, axis, dim=-1))
    radius = float(body.radii[torso])
    aim = mid + (ahead * radius)[:, None] * front + lateral * radius * side
    turn = quat_between(unit(pos[:, wr] - pos[:, sh]), unit(aim - pos[:, sh]))
    ident = torch.zeros_like(turn)
    ident[:, 0] = 1.0
    turn = quat_slerp(ident, turn, (3 * sweep).clamp(max=1.0))
    rot = m.rotations.clone()
    rot[:, sh] = quat_mul(quat_conj(grot[:, m.skeleton.parents[sh]]), quat_mul(turn, grot[:, sh]))
    return m, rot, body, arms


def _crossing_the_torso(beyond: float):
    """:func:`_right_arm_aimed` over frames 30 to 70 at a point that sweeps from 1.5 torso radii
    in front of the torso's axis to ``beyond`` radii behind it and back (smoothly): its forearm
    enters the torso from the front, crosses the axis and leaves at the front again."""
    T = _sample_and_its_torso()[0].num_frames
    sweep = torch.zeros(T, dtype=torch.float64)
    f = torch.arange(30, 71, dtype=torch.float64)
    sweep[30:71] = torch.sin(torch.pi * (f - 30) / 40) ** 2
    return _right_arm_aimed(sweep, 1.5 - (1.5 + beyond) * sweep)


def test_the_way_out_turns_back_only_on_a_run_that_leaves_where_it_entered():
    """Known answers of ``_turned_back``: one arm and obstacle, the normal along +x or -x."""
    from torchsplice.ops.hands import _turned_back

    def reversed_(signs, follows=None):
        n = len(signs)
        away = torch.zeros(n, 2, 1, 3, dtype=torch.float64)
        away[:, 0, 0, 0] = torch.tensor([float(x or 1) for x in signs], dtype=torch.float64)
        inside = torch.zeros(n, 2, 1, dtype=torch.bool)
        inside[:, 0, 0] = torch.tensor([x != 0 for x in signs])
        follows = torch.ones(n, dtype=torch.bool) if follows is None else torch.tensor(follows)
        got = _turned_back(away, inside, follows)
        assert not bool(got[:, 1].any())  # the other arm is inside nothing
        return got[:, 0, 0].tolist()

    # crosses the axis and comes back: the frames on the far side are pushed out of the entry side
    assert reversed_([1, 1, -1, -1, 1]) == [False, False, True, True, False]
    assert reversed_([1, -1, 1, -1, 1]) == [False, True, False, True, False]
    # goes through (turns once, or three times): the normals are kept
    assert reversed_([1, 1, -1, -1]) == [False] * 4
    assert reversed_([1, -1, 1, -1]) == [False] * 4
    # frames outside the obstacle, or of another clip, end a run: each run counts its own turns
    assert reversed_([1, -1, 0, -1, 1, -1]) == [False, False, False, False, True, False]
    assert reversed_([1, -1, 1, -1, 1, -1], follows=[True, True, True, False, True, True]) == \
        [False, True, False, False, True, False]
    assert reversed_([1, -1, -1, 1, 0, 1]) == [False, True, True, False, False, False]


def test_the_way_round_goes_from_the_entry_normal_round_the_side_away_from_the_chest_to_the_exit_normal():
    """Known answers of ``_way_round``: one arm and an obstacle along z of radius 1, a run whose
    offsets from the axis (``away * apart``) go from +x to -x, the chest at y = -1 or +1."""
    from torchsplice.ops.hands import _runs, _turned_back, _way_round

    def way(offsets, chest_y):
        n = len(offsets)
        v = torch.zeros(n, 2, 1, 3, dtype=torch.float64)
        v[:, 0, 0, :2] = torch.tensor(offsets, dtype=torch.float64)
        v[:, 1, 0, 0] = 1.0
        apart = v.norm(dim=-1)
        away = v / apart[..., None]
        inside = torch.zeros(n, 2, 1, dtype=torch.bool)
        inside[:, 0] = True
        runs = _runs(away, inside, torch.ones(n, dtype=torch.bool))
        assert runs[2][:, 0, 0].tolist() == [1] * n  # one turn: it goes through
        assert not bool(_turned_back(away, inside, torch.ones(n, dtype=torch.bool), runs).any())
        oa = torch.zeros(n, 1, 1, 3, dtype=torch.float64)
        ob = oa.clone()
        ob[..., 2] = 1.0
        chest = torch.tensor([0.0, chest_y, 0.5], dtype=torch.float64).expand(n, 1, 1, 3)
        got = _way_round(away, apart, oa, ob, torch.tensor([1.0], dtype=torch.float64), chest, runs)[:, 0, 0]
        assert torch.allclose(got.norm(dim=-1), torch.ones(n, dtype=torch.float64))
        return got, away[:, 0, 0]

    for chest_y in (-1.0, 1.0):
        for y in (0.1, -0.1):  # the side is the obstacle's outside whichever way the forearm passes
            got, normal = way([(0.95, y / 2), (0.3, y), (-0.3, y), (-0.95, y / 2)], chest_y)
            assert bool((got[1:3, 1] * chest_y < -0.8).all())  # across the axis: mostly the side away from the chest
            assert float((got[0] * normal[0]).sum()) > 0.99 and float((got[-1] * normal[-1]).sum()) > 0.99
            assert float(got[:, 2].abs().max()) == 0.0


def test_the_kernels_runs_turn_back_and_go_round_as_the_torch_rules_do():
    """The compiled pass (:func:`torchsplice.cpu.hands._pushes`) against ``_runs``,
    ``_turned_back`` and ``_way_round`` on random runs: the same normals reversed, each pushed
    out ``apart`` further, the same runs through an obstacle of ``round_`` taken round (through
    the others, along the normal); the push of a frame sums its obstacles'."""
    from torchsplice.cpu.hands import _pushes
    from torchsplice.ops.hands import _runs, _turned_back, _way_round

    rng = np.random.default_rng(0)
    n, O = 400, 3
    inside = rng.random((n, 2, O)) < 0.8
    away = rng.normal(size=(n, 2, O, 3))
    away /= np.linalg.norm(away, axis=-1, keepdims=True)
    away[1:] = np.where(rng.random((n - 1, 2, O, 1)) < 0.7, np.abs(away[:-1]) * np.sign(away[1:]), away[1:])
    pushed = np.sort(rng.choice(n, size=300, replace=False)).astype(np.int64)
    inside[np.setdiff1d(np.arange(n), pushed)] = False  # the frames a pass did not test are inside nothing
    apart, lever = rng.random((n, 2, O)), np.full((n, 2, O), 1.0)
    radii, obstacles, target, slack = np.array([5.0, 6.0, 7.0]), np.arange(O, dtype=np.int64), 1.0, 0.25
    ends = rng.normal(size=(n, 2 * O, 3))
    pos = rng.normal(size=(n, 1, 3))  # the chest's place: the way round leaves it
    grot = np.zeros((n, 1, 4))
    grot[..., 0] = 1.0  # the chest's frame is the world's
    pushes = np.zeros((n, 2, 3))
    round_ = np.array([True, False, True])  # the obstacles a run through is taken round (ops.hands.ROUND)
    kept = _pushes(pushed.copy(), len(pushed), inside, away, apart, lever, radii, obstacles, round_, target, slack, pos,
                   grot, 0, ends, np.empty((n, 2, O, 3), np.int64), np.empty((n, 2, O, 2)), pushes)
    follows = np.zeros(n, bool)
    follows[pushed[1:][pushed[1:] == pushed[:-1] + 1]] = True
    t = {name: torch.from_numpy(a) for name, a in dict(away=away, inside=inside, follows=follows, apart=apart).items()}
    runs = _runs(t["away"], t["inside"], t["follows"])
    back = _turned_back(t["away"], t["inside"], t["follows"], runs).numpy()
    through = inside & (runs[2].numpy() % 2 == 1) & round_
    assert back.any() and through.any() and (inside & ~back & ~through & (runs[2].numpy() % 2 == 1)).any()
    oa, ob = torch.from_numpy(ends[:, None, 0::2]), torch.from_numpy(ends[:, None, 1::2])
    way = _way_round(t["away"], t["apart"], oa, ob, torch.from_numpy(radii), torch.from_numpy(pos[:, :, None]), runs)
    way = way.numpy()
    sign = np.where(back, -1.0, 1.0)
    excess = np.where(back, radii + apart - target, radii - apart - target)
    along = (sign * (excess + slack) / lever)[..., None] * away
    round_ = (way * (radii - target + slack)[..., None] - away * apart[..., None]) / lever[..., None]
    want = np.where(inside[..., None], np.where(through[..., None], round_, along), 0.0).sum(2)
    assert kept == int(inside.any(-1).any(-1).sum())
    assert np.allclose(pushes, want, atol=1e-12)


def _kept_out(m, rot, body, arms, inside_before: float):
    """The clip ``rot`` (its right arm inside the body on more than ``inside_before`` of its
    frames) with its hands kept out: ``(out, corrected, before, after, peak)``, the positions
    ``(T, J, 3)`` before and after, and the right wrist's peak acceleration in the chest's frame
    after over before. Asserts that it is out of the body after."""
    trans, T = m.local_translations(), m.num_frames
    fk = lambda r: forward_kinematics(r, trans[:, 0], m.skeleton.offsets, m.skeleton.parents, trans)  # noqa: E731
    assert float(penetration_packed(fk(rot)[0], [T], body)[0]) > inside_before
    out, corrected = keep_hands_out(rot, trans, [T], m.fps, m.skeleton, body, arms, 0.0)
    (p0, g0), (p1, g1) = fk(rot), fk(out)
    assert float(penetration_packed(p1, [T], body)[0]) == 0.0 and int(corrected) > 0

    def peak_acceleration(p, g):
        wrist = quat_apply(quat_conj(g[:, arms.chest]), p[:, arms.wrist[1]] - p[:, arms.chest])
        return float((wrist[2:] - 2 * wrist[1:-1] + wrist[:-2]).norm(dim=-1).max())

    return out, corrected, p0, p1, peak_acceleration(p1, g1) / peak_acceleration(p0, g0)


def test_an_arm_that_crosses_the_torsos_axis_and_back_is_pushed_out_of_one_side_smoothly():
    m, rot, body, arms = _crossing_the_torso(1.0)
    trans, T = m.local_translations(), m.num_frames
    out, corrected, _, _, peak = _kept_out(m, rot, body, arms, 0.1)
    assert peak <= 1.15  # 1.27x where the far side's frames were pushed out of it
    # the compiled kernel gives the same
    from torchsplice.splice.backends.compiled import CompiledBackend

    got, got_n = CompiledBackend().keep_hands_out(rot.numpy(), trans.numpy(), [T], m.fps, m.skeleton, body, arms,
                                                  [0.0])
    assert int(got_n[0]) == int(corrected) and np.allclose(got, out.numpy(), atol=1e-9)


def _through_the_torso(lateral: float):
    """:func:`_right_arm_aimed` over frames 30 to 70 at a point that sweeps from 1.5 torso radii
    in front of the torso's axis to 1.5 radii behind it, ``lateral`` radii to the side, and stays
    there: its forearm goes through the torso, in at the front and out at the back."""
    T = _sample_and_its_torso()[0].num_frames
    sweep = torch.ones(T, dtype=torch.float64)
    sweep[:30] = 0.0
    f = torch.arange(30, 71, dtype=torch.float64)
    sweep[30:71] = torch.sin(torch.pi / 2 * (f - 30) / 40) ** 2
    return _right_arm_aimed(sweep, 1.5 - 3.0 * sweep, lateral)


def test_an_arm_that_goes_through_the_torso_is_taken_round_its_outside_smoothly():
    """In at the front and out at the back: pushed along the normal on each frame, the forearm
    would be pushed out of the front, then of the back, and swing through the body where it
    crosses the axis (the wrist's peak acceleration 2.07x the swing's); taken round the torso's
    outside it comes out with no more acceleration than the swing had (0.85x)."""
    m, rot, body, arms = _through_the_torso(-0.3)
    trans, T = m.local_translations(), m.num_frames
    out, corrected, p0, pos, peak = _kept_out(m, rot, body, arms, 0.05)
    assert peak <= 1.0
    # round the outside: where the forearm crosses the torso's axis, the corrected wrist is further
    # from the chest, across the axis, than the swing's
    _, _, _, _, _, _, (a, b, torso, mid) = _sample_and_its_torso()
    unit = lambda v: torch.nn.functional.normalize(v, dim=-1)  # noqa: E731
    outward = unit(mid - p0[:, arms.chest])
    front = unit(torch.linalg.cross(unit(b[:, torso] - a[:, torso]), unit(mid - p0[:, arms.shoulder[1]]), dim=-1))
    crossing = int(((p0[:, arms.wrist[1]] - mid) * front).sum(-1)[30:71].abs().argmin()) + 30
    before = float(((p0[crossing, arms.wrist[1]] - mid[crossing]) * outward[crossing]).sum())
    after = float(((pos[crossing, arms.wrist[1]] - mid[crossing]) * outward[crossing]).sum())
    assert after > before + 0.5 * float(body.radii[torso])
    from torchsplice.splice.backends.compiled import CompiledBackend

    got, got_n = CompiledBackend().keep_hands_out(rot.numpy(), trans.numpy(), [T], m.fps, m.skeleton, body, arms,
                                                  [0.0])
    assert int(got_n[0]) == int(corrected) and np.allclose(got, out.numpy(), atol=1e-8)


def _wrists_in_chest(clip, arms) -> torch.Tensor:
    trans = clip.local_translations()
    pos, grot = forward_kinematics(clip.rotations, trans[:, 0], clip.skeleton.offsets, clip.skeleton.parents, trans)
    rel = pos[:, list(arms.wrist)] - pos[:, arms.chest, None]
    return quat_apply(quat_conj(grot[:, arms.chest, None]).expand(-1, 2, 4), rel)


@pytest.mark.realdata
def test_the_job_keeps_hands_out_where_neither_source_has_one_in(runs_with_raised_hands):
    db, raw, out = runs_with_raised_hands
    with MotionDatabase.open(raw) as r, MotionDatabase.open(out) as o:
        assert r.run_record()["keep_hands_out"] is False and o.run_record()["keep_hands_out"] is True
        tr, to = r.clip_table(), o.clip_table()
        assert list(tr.name) == list(to.name)
        e0, e1 = tr.extra, to.extra
        neither = (np.asarray(e1["penetration_locomotion"]) == 0) & (np.asarray(e1["penetration_action"]) == 0)
        was = (np.asarray(e0["penetration"]) > 0) & neither
        now = (np.asarray(e1["penetration"]) > 0) & neither
        assert was.mean() > 0.03 and now.mean() <= 0.03  # the target: at most 3% of clips
        assert not any("self_penetration" in f for f in e1["flags"])
        assert (np.asarray(e0["corrected_frames"]) == 0).all()
        corrected = np.asarray(e1["corrected_frames"])
        sk = o.skeletons[0]
        roles = o.spec(0).bind(sk)
        body = body_of(sk, roles)
        arms = arms_of(sk, roles, body)
        lower = [j for j in range(sk.num_joints) if j not in arms.moved]
        ranges = []
        for name, n in zip(to.name, corrected):
            a, b = r.read(name), o.read(name)
            differ = (a.rotations != b.rotations).any(-1).any(-1)
            assert int(differ.sum()) == int(n), name  # the column counts the frames changed
            assert torch.equal(a.rotations[:, lower], b.rotations[:, lower]), name  # feet and lower body exact
            assert torch.equal(a.root_translation, b.root_translation)
            if n:
                w0, w1 = _wrists_in_chest(a, arms), _wrists_in_chest(b, arms)
                ranges.append(((w1.amax(0) - w1.amin(0)).norm(dim=-1) / (w0.amax(0) - w0.amin(0)).norm(dim=-1)))
        assert corrected.sum() > 0
        # the job measures again only the frames it changed: the columns are the whole results' figures
        from torchsplice.splice.backends.compiled import CompiledBackend

        clips = [o.read(n) for n in to.name]
        share, depth = CompiledBackend().inside_body(torch.cat([c.rotations for c in clips]).numpy(),
                                                     torch.cat([c.local_translations() for c in clips]).numpy(),
                                                     [c.num_frames for c in clips], sk, body)
        assert np.array_equal(share, np.asarray(e1["penetration"]))  # Bandai Namco's units are cm, as the columns
        assert np.allclose(depth, np.asarray(e1["penetration_depth"]), rtol=0, atol=1e-9)
        from torchsplice.store.select import select_clips

        picked = select_clips(to, "corrected_frames>0", "clips", str(out))  # the selection language takes the column
        assert picked == np.flatnonzero(corrected > 0).tolist()
        ranges = torch.stack(ranges)
        assert float(ranges.min()) >= 0.8  # each arm's range in the chest's frame is kept


@pytest.mark.realdata
def test_an_alignment_store_assembles_the_corrected_arms(runs_with_raised_hands, tmp_path, monkeypatch):
    from torchsplice.job.run import splice_all

    db, _, out = runs_with_raised_hands
    al = tmp_path / "al.h5"
    splice_all(db, al, locomotions=["*run*,*dash*,*turn*"], actions=["*wave*,*raise*,*bye*,*call*,*guide*"],
               workers=1, store="alignment")
    with MotionDatabase.open(out) as o, MotionDatabase.open(al) as a:
        corrected = np.asarray(o.clip_table().extra["corrected_frames"])
        names = list(o.names)
        assert (corrected > 0).any()
        for name in names:
            x, y = o.read(name), a.read(name)
            assert torch.equal(x.rotations, y.rotations) and torch.equal(x.root_translation, y.root_translation), name
        k = 0
        starts = np.asarray(a.clip_table().start)
        lengths = np.asarray(a.clip_table().length)
        on = a._assembly().frames_on(a, k, starts, lengths, "cpu")
        mine = torch.cat([o.read(n).rotations for n in names])
        assert torch.allclose(on["rotations"], mine, atol=1e-6)
    # the store keeps the joints moved and zeros for the others: each kept joint's rotation is the
    # motion store's and not the splice's before the correction; a joint left as zeros is the splice's
    import torchsplice.store.assembly as assembly

    with MotionDatabase.open(al) as a, MotionDatabase.open(out) as o:
        assert np.array_equal(a.clip_table().start, o.clip_table().start)
        arms = a.h5["skeletons/0/assembly_arms"][()]
        joints = json.loads(a.h5["assembly/banks/0"].attrs["tables"])["moved"]
        frames_moved = np.flatnonzero((arms != 0).any(axis=(1, 2)))
        chunk = a.h5["skeletons/0/assembly_arms"].chunks[0]  # only the chunks that hold moved frames are stored
        assert a.h5["skeletons/0/assembly_arms"].id.get_num_chunks() == len(np.unique(frames_moved // chunk))
        kept = (arms[frames_moved] != 0).any(axis=2)  # (M, 4)
        assert kept.any(axis=1).all() and not kept.all()  # some frames move one arm only
        final = o.packed(0)["rotations"][frames_moved][:, joints]
        t = a.clip_table()
        monkeypatch.setattr(assembly.Assembly, "moved_arms", lambda *args: None)
        a._assembly_cache = None
        before = a.assembled(0, t.start, t.length, names=("rotations",))["rotations"][frames_moved][:, joints]
        monkeypatch.undo()
        assert np.array_equal(arms[frames_moved][kept], final[kept])
        assert (arms[frames_moved][kept] != before[kept]).any(axis=1).all()
        assert np.array_equal(final[~kept], before[~kept])
    # the moved arms held in memory (the default) or read clip by clip: the same frames
    shuffled = np.random.default_rng(0).permutation(len(names))[:60]

    frames = []
    for budget in (assembly.HELD_PARTS_BYTES, 0):
        monkeypatch.setattr(assembly, "HELD_PARTS_BYTES", budget)
        with MotionDatabase.open(al) as a:
            t = a.clip_table()
            for _ in range(assembly.HOLD_AFTER_READS):
                made = a.assembled(0, t.start[shuffled] + 1, t.length[shuffled] - 2, names=("rotations",))
            assert list(made) == ["rotations"]
            held = a._assembly().held
            assert (held[(0, "assembly_arms")] is None) == (budget == 0) and (0, "assembly_arms") in held
            frames.append(made["rotations"])
    assert np.array_equal(frames[0], frames[1])


@pytest.mark.realdata
def test_the_compiled_correction_gives_the_torch_one(runs_with_raised_hands):
    """The compiled splicer's kernel (:mod:`torchsplice.cpu.hands`) against the backends' torch
    default, on the real job's results that put a hand inside the body."""
    from torchsplice.splice.backends import Backend
    from torchsplice.splice.backends.compiled import CompiledBackend

    _, raw, _ = runs_with_raised_hands
    with MotionDatabase.open(raw) as r:
        e = r.clip_table().extra
        allowed = np.maximum(np.asarray(e["penetration_depth_locomotion"]), np.asarray(e["penetration_depth_action"]))
        todo = np.flatnonzero((np.asarray(e["penetration"]) > 0) & (np.asarray(e["penetration_depth"]) > allowed))
        clips = [r.read(r.names[b]) for b in todo]
        sk = r.skeletons[0]
        roles = r.spec(0).bind(sk)
    body = body_of(sk, roles)
    arms = arms_of(sk, roles, body)
    rot = torch.cat([c.rotations for c in clips]).numpy()
    trans = torch.cat([c.local_translations() for c in clips]).numpy()
    lengths = [c.num_frames for c in clips]
    args = (rot, trans, lengths, clips[0].fps, sk, body, arms, allowed[todo])  # Bandai Namco's units are cm, as the columns
    want_bits, got_bits = np.zeros(len(rot), np.uint8), np.zeros(len(rot), np.uint8)
    want, want_n = Backend.keep_hands_out(CompiledBackend(), *args, changed=want_bits)
    got, got_n = CompiledBackend().keep_hands_out(*args, changed=got_bits)
    assert len(todo) >= 10 and want_n.sum() > 0
    assert np.array_equal(got_n, want_n) and np.allclose(got, want, atol=1e-6)
    assert np.array_equal(got != rot, want != rot)
    # per frame a bit per moved joint whose value changed; every other joint keeps its bits
    moved = list(arms.moved)
    for out, bits in ((got, got_bits), (want, want_bits)):
        differs = (out[:, moved] != rot[:, moved]).any(-1)
        assert np.array_equal((bits[:, None] >> np.arange(4)) & 1, differs.astype(np.uint8)) and differs.any()
        kept = np.ones(rot.shape[:2], bool)
        kept[:, moved] = ~differs
        assert np.array_equal(out.view(np.uint32)[kept], rot.view(np.uint32)[kept])
    assert np.array_equal(got_bits, want_bits)
    # given an `out` that holds the correction already, each backend writes each joint's own value
    # back: no bit is set, and `out` keeps its bits
    for run, done in ((CompiledBackend().keep_hands_out, got),
                      (lambda *a, **k: Backend.keep_hands_out(CompiledBackend(), *a, **k), want)):
        again, bits = done.copy(), np.zeros(len(rot), np.uint8)
        _, counts = run(*args, out=again, changed=bits)
        assert np.array_equal(counts, got_n) and not bits.any()
        assert np.array_equal(again.view(np.uint32), done.view(np.uint32))
    # told each frame's depth from the body test, the kernel tests only the frames deeper than a
    # target in its first pass: the same output bit for bit, on the targets the job uses and on deeper ones
    deepest = CompiledBackend().inside_body(rot, trans, lengths, sk, body, per_frame=True)[2]
    assert (deepest > body.margin).sum() < len(deepest) / 2  # most frames are out: the skip is real
    for allowed_here in (allowed[todo], allowed[todo] + 0.5 * body.margin):
        args = (rot, trans, lengths, clips[0].fps, sk, body, arms, allowed_here)
        plain, plain_n = CompiledBackend().keep_hands_out(*args)
        told, told_n = CompiledBackend().keep_hands_out(*args, deepest=deepest)
        assert np.array_equal(told, plain) and np.array_equal(told_n, plain_n)


@pytest.mark.realdata
def test_evaluate_says_how_many_arms_were_moved(runs_with_raised_hands, tmp_path):
    from torchsplice.evaluation.report import evaluate_database

    _, _, out = runs_with_raised_hands
    report = tmp_path / "report.md"
    evaluate_database(out, report, pictures=False)
    section = report.read_text().split("## Plausibility: a hand inside the body")[1]
    row = next(ln for ln in section.splitlines() if ln.startswith("| splice |"))
    with MotionDatabase.open(out) as o:
        corrected = np.asarray(o.clip_table().extra["corrected_frames"])
    assert row.rstrip(" |").endswith(f"{int((corrected > 0).sum())}, {int(corrected.sum())}")


@pytest.mark.realdata
def test_hands_are_kept_out_on_a_database_whose_units_are_unknown(runs_with_raised_hands, tmp_path):
    """The correction works in the skeleton's units: unknown units (a guessed spec's) leave the
    centimetre columns NaN, not the arms inside."""
    import json
    import shutil

    import h5py

    from torchsplice.job.run import splice_all

    db, _, out = runs_with_raised_hands
    unknown = tmp_path / "unknown.h5"
    shutil.copy(db, unknown)
    with h5py.File(unknown, "r+") as f:
        for k in f["skeletons"]:
            g = f["skeletons"][k]
            spec = json.loads(g.attrs["spec"])
            spec["dataset"]["units"] = "unknown"
            g.attrs["spec"], g.attrs["units"] = json.dumps(spec), "unknown"
    got = tmp_path / "out.h5"
    splice_all(unknown, got, locomotions=["*run*,*dash*,*turn*"], actions=["*wave*,*raise*,*bye*,*call*,*guide*"],
               workers=1)
    with MotionDatabase.open(got) as g, MotionDatabase.open(out) as o:
        e, want = g.clip_table().extra, o.clip_table().extra
        assert g.spec(0).units == "unknown"
        assert np.array_equal(np.asarray(e["corrected_frames"]), np.asarray(want["corrected_frames"]))
        assert np.asarray(e["corrected_frames"]).sum() > 0
        assert np.array_equal(np.asarray(e["penetration"]), np.asarray(want["penetration"]))
        assert np.isnan(np.asarray(e["penetration_depth"])).all() and np.isnan(np.asarray(e["jerk"])).all()


@pytest.mark.realdata
def test_one_pair_spliced_alone_has_its_arms_moved_out_as_the_job_moves_them(runs_with_raised_hands):
    """``splice_pair`` (the ``splice`` command) corrects a result as ``splice_all`` does: the
    same frames changed, the same rotations (torch against the compiled kernel, float32 stores),
    and a note saying how many frames; ``keep_hands_out=False`` gives the splice as it came."""
    from torchsplice.job.pair import splice_pair

    db, raw, out = runs_with_raised_hands
    with MotionDatabase.open(out) as o, MotionDatabase.open(raw) as r:
        e = o.clip_table().extra
        corrected = np.asarray(e["corrected_frames"])
        b = int(np.flatnonzero(corrected > 0)[0])
        name, loco, action = o.names[b], str(e["locomotion"][b]), str(e["action"][b])
        job_out, job_raw = o.read(name), r.read(name)
    fixed = splice_pair(db, loco, action)
    as_came = splice_pair(db, loco, action, keep_hands_out=False)
    assert torch.allclose(as_came.motion.rotations.float(), job_raw.rotations, atol=1e-5)
    assert torch.allclose(fixed.motion.rotations.float(), job_out.rotations, atol=1e-4)
    changed = (fixed.motion.rotations != as_came.motion.rotations).any(-1).any(-1)
    assert int(changed.sum()) == int(corrected[b])
    assert any(f"moved out on {int(corrected[b])} frames" in n for n in fixed.notes)
    assert not any("moved out" in n for n in as_came.notes)
    # a pair the job leaves alone is left alone
    clean = int(np.flatnonzero(corrected == 0)[0])
    alone = splice_pair(db, str(e["locomotion"][clean]), str(e["action"][clean]))
    assert not any("moved out" in n for n in alone.notes)
