"""Standing actions: which action frames play, and the compiled splicer against torch.

The specification of :mod:`torchsplice.splice.standing`'s choices, each against brute force or
a known answer: the main motion (the central 95% of the acting hands' path), the best window
(the largest spread of the acting hands), loop points (the closest windows with the main motion
inside the loop). Then the action always shows on real standing takes: onto a shorter
locomotion the result keeps at least 80% of the acting wrist's range in the action's best
window of that length, onto a longer one at least 80% of its whole range. Last, the compiled
standing splicer (:mod:`torchsplice.cpu.standing`) gives torch's results, the same frames and
rotations to float32 rounding, on the sample and on real takes, whatever the batch and threads.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from realdata import BANDAI
from torchsplice.cpu import get_threads, set_threads
from torchsplice.cpu.bank import ClipBank, standing_bank
from torchsplice.formats.bvh import read_bvh
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.splice import SpliceOptions, splice_standing
from torchsplice.splice.clips import clips_to_tensors
from torchsplice.splice.standing import (CORE_SHARE, LIMBS, acting_limbs, acting_mask, action_times, best_windows,
                                         hands_in_chest, loop_points, motion_core, standing_tables)

STANDING = ["dataset-2_raise-up-left-hand_normal_001", "dataset-2_raise-up-both-hands_normal_001",
            "dataset-2_wave-right-hand_normal_001", "dataset-2_wave-both-hands_normal_001",
            "dataset-2_wave-left-hand_normal_001", "dataset-1_bow_normal_001", "dataset-1_punch_normal_002"]
LOCOS = ["dataset-2_walk-turn-left_normal_025", "dataset-1_walk_normal_001", "dataset-1_run_normal_001",
         "dataset-2_walk_normal_008", "dataset-1_dash_normal_001"]


def wrist_range(x: torch.Tensor) -> float:
    """The extent of a ``(T, 3)`` path between its 5th and 95th percentile positions, per axis."""
    q = torch.quantile(x.double(), torch.tensor([0.05, 0.95], dtype=torch.float64), dim=0)
    return float((q[1] - q[0]).norm())


def acting_range(rel: torch.Tensor, limbs) -> float:
    """Mean :func:`wrist_range` of the acting hands of ``rel`` ``(T, 2, 3)`` (both when none act)."""
    sides = [k for k, n in enumerate(LIMBS) if n in limbs] or [0, 1]
    return sum(wrist_range(rel[:, k]) for k in sides) / len(sides)


@pytest.fixture(scope="module")
def real(mocap_dir):
    spec = load_spec("bandai_namco")
    acts = [read_bvh(mocap_dir / BANDAI / f"{n}.bvh") for n in STANDING]
    locos = [read_bvh(mocap_dir / BANDAI / f"{n}.bvh") for n in LOCOS]
    sk = acts[0].skeleton
    roles = spec.bind(sk)
    A = clips_to_tensors(acts, sk, dtype=torch.float64)
    limbs = [found for found, _ in acting_limbs(A, roles, sk)]
    return spec, roles, sk, acts, locos, A, limbs


# ------------------------------------------------------------------------------ the frames chosen
def test_motion_core_holds_the_central_share_of_the_path():
    # a hand still for 20 frames, then moving 2 units a frame for 30, then still for 30
    x = torch.cat([torch.zeros(20), 2 * torch.arange(1, 31, dtype=torch.float64), torch.full((30,), 60.0)])
    rel = torch.zeros(1, 80, 2, 3, dtype=torch.float64)
    rel[0, :, 0, 2] = x
    first, last = motion_core(rel, torch.tensor([80]), torch.tensor([[1.0, 0.0]], dtype=torch.float64))
    # path[t] = 2 (t - 19) from frame 19 to 49: 2.5% of 60 = 1.5 lies after frame 19, 97.5% = 58.5 at frame 49
    assert (int(first), int(last)) == (19, 49)
    assert 0 < CORE_SHARE < 1
    # the other hand is not weighed: a still clip is its whole length
    first, last = motion_core(rel, torch.tensor([80]), torch.tensor([[0.0, 1.0]], dtype=torch.float64))
    assert (int(first), int(last)) == (0, 79)
    # frames past a clip's length are padding, not the clip: path 0, 2, ..., 20 over frames 19..29
    first, last = motion_core(rel, torch.tensor([30]), torch.tensor([[1.0, 0.0]], dtype=torch.float64))
    assert (int(first), int(last)) == (19, 29)


def test_best_windows_equal_brute_force():
    g = torch.Generator().manual_seed(3)
    B, T = 6, 50
    rel = torch.randn(B, T, 2, 3, generator=g, dtype=torch.float64).cumsum(1)
    lengths = torch.tensor([50, 41, 30, 12, 50, 7])
    n = torch.tensor([10, 41, 3, 12, 1, 5])
    mask = torch.tensor([[1, 0], [0, 1], [1, 1], [1, 0], [1, 1], [0, 1]], dtype=torch.float64)
    got = best_windows(rel, lengths, mask, n)
    for b in range(B):
        scores = [float((rel[b, w:w + n[b]].var(0, unbiased=False) * mask[b, :, None]).sum())
                  for w in range(int(lengths[b] - n[b]) + 1)]
        best = max(scores)
        assert scores[int(got[b])] >= best - 1e-9, b
        assert int(got[b]) == next(w for w, v in enumerate(scores) if v >= best - 1e-9), b  # the first of ties
    assert int(got[4]) == 0  # one-frame windows all have no spread: the first wins


def test_loop_points_are_the_closest_windows_around_the_main_motion(real):
    spec, roles, sk, acts, locos, A, limbs = real
    start, end = loop_points(A, roles, sk, 30.0, limbs)
    first, last = motion_core(hands_in_chest(A, roles, sk), A.lengths, acting_mask(limbs, len(acts)))
    chest = standing_tables(roles, sk, 30.0)
    W = chest.window
    for b in range(len(acts)):
        s, e, n = int(start[b]), int(end[b]), int(A.lengths[b])
        assert s <= int(first[b]) and e >= int(last[b]) and e + W <= n and s < e, (STANDING[b], s, e)
        # brute force: no admissible pair of windows is closer
        pos, grot = A.positions[b, :n].double(), A.global_rotations[b, :n].double()
        from torchsplice.core.rotations import quat_apply, quat_conj

        feat = quat_apply(quat_conj(grot[:, chest.chest:chest.chest + 1]),
                          pos[:, chest.feat_joints] - pos[:, chest.chest:chest.chest + 1]).reshape(n, -1)
        win = lambda t: feat[t:t + W].reshape(-1)  # noqa: E731
        best = min(float((win(ee) - win(ss)).norm()) for ee in range(int(last[b]), n - W + 1)
                   for ss in range(0, min(int(first[b]), ee - 1) + 1))
        assert float((win(e) - win(s)).norm()) <= best * (1 + 1e-9), STANDING[b]


def test_a_shorter_locomotion_plays_the_best_window_and_a_longer_one_loops_from_the_start():
    loco, act = torch.tensor([30, 100, 30, 100]), torch.tensor([60, 60, 60, 60])
    window = torch.tensor([17, 0, 17, 0])
    t, _, _ = action_times(loco, act, "loop", 30.0, loop=(torch.tensor([5] * 4), torch.tensor([50] * 4)), window=window)
    assert torch.equal(t[0, :30], torch.arange(17, 47, dtype=torch.float64))
    assert torch.equal(t[1, :50], torch.arange(50, dtype=torch.float64)) and float(t[1, 50]) == 5
    t, _, _ = action_times(loco, act, "hold", 30.0, window=window)
    assert torch.equal(t[2, :30], torch.arange(17, 47, dtype=torch.float64))
    assert float(t[3, 99]) == 59 and float(t[3, 40]) == 40
    t, _, _ = action_times(loco, act, "fit", 30.0, window=window)  # fit plays the whole action, faster
    assert float(t[0, 0]) == 0 and abs(float(t[0, 29]) - 59) < 1e-9


# ------------------------------------------------------------------------------ the action shows
@pytest.mark.parametrize("method", ["splice", "naive"])
def test_the_action_always_shows_on_real_standing_takes(real, method):
    spec, roles, sk, acts, locos, A, limbs = real
    pairs = [(lo, ac) for lo in locos for ac in acts]
    acting = [limbs[k % len(acts)] for k in range(len(pairs))]
    results = splice_standing(pairs, spec, method=method, options=SpliceOptions(dtype=torch.float64, force=True),
                               acting=acting)  # force: the short runs and dashes (20-31 frames) take no full step
    action_rel = hands_in_chest(A, roles, sk)
    shorter = longer = 0
    for (lo, ac), r, limbs_b in zip(pairs, results, acting):
        b = acts.index(ac)
        rel = action_rel[b, :ac.num_frames]
        R = clips_to_tensors([r.motion], sk, dtype=torch.float64)
        got = acting_range(hands_in_chest(R, roles, sk)[0], limbs_b)
        n = r.motion.num_frames
        if n < ac.num_frames:  # the best window of the result's length, by brute force
            shorter += 1
            want = max(acting_range(rel[w:w + n], limbs_b) for w in range(ac.num_frames - n + 1))
        else:
            longer += 1
            want = acting_range(rel, limbs_b)
        assert got >= 0.8 * want, (lo.name, ac.name, got, want)
    assert shorter >= 8 and longer >= 8  # both cases are covered


# ------------------------------------------------------------------------------ compiled = torch
def _both(pairs, spec, method, timing, acting=None):
    out = {}
    for backend in ("torch", "compiled"):
        opts = SpliceOptions(backend=backend, timing=timing, force=True)
        out[backend] = splice_standing(pairs, spec, method=method, options=opts, acting=acting)
    return out["torch"], out["compiled"]


def _assert_same(torch_results, compiled_results):
    for a, b in zip(torch_results, compiled_results):
        assert a.motion.num_frames == b.motion.num_frames
        assert torch.equal(a.curve, b.curve), a.motion.name  # the same frames: window, loop points, fades
        ra, rb = a.motion.rotations, b.motion.rotations
        assert (ra - rb).abs().max() <= 1e-6, a.motion.name  # float32 rounding
        assert torch.allclose(a.motion.local_translations(), b.motion.local_translations(), atol=1e-4)


@pytest.mark.parametrize("timing", ["loop", "hold", "fit"])
@pytest.mark.parametrize("method", ["splice", "naive", "cpmc"])
def test_compiled_standing_equals_torch_on_the_sample(method, timing):
    clips = {m.name: m for m in sample_motions()}
    spec = load_spec("sample")
    names = list(clips)
    pairs = [(clips[a], clips[b]) for a in names for b in names if a != b]
    acting = [(), ("left_arm",), ("right_arm",), ("left_arm", "right_arm")] * len(pairs)
    _assert_same(*_both(pairs, spec, method, timing, acting[:len(pairs)]))


@pytest.mark.parametrize("timing", ["loop", "hold", "fit"])
@pytest.mark.parametrize("method", ["splice", "naive", "cpmc"])
def test_compiled_standing_equals_torch_on_real_takes(real, method, timing):
    spec, roles, sk, acts, locos, A, limbs = real
    pairs = [(lo, ac) for lo in locos for ac in acts]
    torch_r, compiled_r = _both(pairs, spec, method, timing)
    assert [r.acting for r in torch_r] == [r.acting for r in compiled_r]
    _assert_same(torch_r, compiled_r)


def test_compiled_standing_is_bit_identical_in_any_batch_and_on_any_thread_count(real):
    spec, roles, sk, acts, locos, A, limbs = real
    bank = ClipBank.from_motions(locos + acts, sk, roles)
    tables = standing_tables(roles, sk, 30.0)
    lo = np.array([k % len(locos) for k in range(20)])
    ac = np.array([len(locos) + k % len(acts) for k in range(20)])
    acting = np.array([[n in limbs[a - len(locos)] for n in LIMBS] for a in ac])

    def run(order, fresh=True):
        b = ClipBank.from_motions(locos + acts, sk, roles) if fresh else bank  # loop points computed anew or kept
        out = standing_bank(b, lo[order], ac[order], acting[order], tables, "splice", "loop")
        return {k: out.rotations[out.start[i]:out.start[i] + out.frames[i]].copy() for i, k in enumerate(order)}

    before = get_threads()
    try:
        set_threads(2)
        batch = run(np.arange(20))
        shuffled = run(np.array([7, 3, 19, 0, 11, 5, 1, 18, 2, 9, 4, 17, 6, 12, 8, 16, 10, 15, 13, 14]))
        alone = {k: run(np.array([k]), fresh=False)[k] for k in range(20)}
        set_threads(1)
        single = run(np.arange(20))
    finally:
        set_threads(before)
    for k in range(20):
        for other in (shuffled, alone, single):
            assert np.array_equal(batch[k], other[k]), k
