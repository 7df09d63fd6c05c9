"""Splicing (Heck, Kovar & Gleicher 2006) and the naive and CPMC baselines: properties that can fail.

Every check measures the output (local rotations, forward kinematics, the alignment curve)
against something computed independently here: the input clips themselves, a clip resampled
at a known time warp, the phase of a real walk, a captured ground truth. Tight tolerances are
claimed only in float64.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from realdata import BANDAI
from torchsplice.align.curve import interpolate_frames, slerp_frames
from torchsplice.core.errors import MotionError, TorchspliceError
from torchsplice.core.motion import Motion
from torchsplice.core.rotations import axis_angle_to_quat, quat_angle, quat_apply, quat_mul
from torchsplice.evaluation.ground_truth import bandai_namco_triples, upper_body_error
from torchsplice.formats.bvh import read_bvh
from torchsplice.specs import detect_spec, load_spec
from torchsplice.kinematics.heading import heading_frame, to_heading_frame
from torchsplice.splice import NotLocomotingError, SpliceOptions, splice, splice_pairs
from torchsplice.splice.clips import clips_to_tensors
from torchsplice.splice.heck import splice_tensors, time_align
from torchsplice.splice.references import find_reference

F64 = torch.float64
OPT = SpliceOptions(dtype=F64)
LOCOMOTION = ("walk_straight", "walk_curve", "turn_sharp", "sidestep", "jog")
ACTIONS = ("carry_box", "carry_cup", "wave", "punch", "arms_out")
TURN_LEFT = "dataset-2_walk-turn-left_normal_025"
ELDERLY = "dataset-2_walk_elderly_006"
WALK2 = "dataset-2_walk_normal_008"


# ------------------------------------------------------------------------------ fixtures, helpers


def angle(a: torch.Tensor, b: torch.Tensor) -> float:
    """Largest geodesic angle (radians) between two rotation tensors."""
    return float(quat_angle(a, b).max())


def at_times(m: Motion, times: torch.Tensor, name: str | None = None) -> Motion:
    """``m`` sampled at fractional frames ``times`` (slerp / linear), same frame rate."""
    t = times.to(F64)[None]
    n = torch.tensor([m.num_frames])
    return replace(
        m,
        rotations=slerp_frames(m.rotations[None], t.to(m.dtype), n)[0],
        root_translation=interpolate_frames(m.root_translation[None], t.to(m.dtype), n)[0],
        translations=None if m.translations is None else interpolate_frames(m.translations[None], t.to(m.dtype), n)[0],
        name=name or m.name,
        labels=dict(m.labels),
    )


def place(m: Motion, deg: float = 73.0, offset=(123.4, 0.0, -56.7), up: int = 1) -> Motion:
    """``m`` turned by ``deg`` about the up axis and moved on the floor: the rigid transform is
    applied to the BVH root joint (joint 0: ``Hips`` on the sample, ``joint_Root`` on Bandai
    Namco, whose ``Hips`` then follows through the hierarchy)."""
    axis = torch.zeros(3, dtype=m.dtype)
    axis[up] = math.radians(deg)
    q = axis_angle_to_quat(axis).expand(m.num_frames, 4)
    rot = m.rotations.clone()
    rot[:, 0] = quat_mul(q, rot[:, 0])
    root = quat_apply(q, m.root_translation) + torch.tensor(offset, dtype=m.dtype)
    trans = None
    if m.translations is not None:
        trans = m.translations.clone()
        trans[:, 0] = root
    return replace(m, rotations=rot, root_translation=root, translations=trans, name=m.name + "_placed",
                   labels=dict(m.labels))


def leans(m: Motion, roles) -> torch.Tensor:
    """``(T,)`` trunk lean in degrees: the pelvis -> shoulder-midpoint vector's angle from the up
    axis in the sagittal plane of the hips' heading frame (positive forward)."""
    p = m.global_positions().to(F64)
    H = heading_frame(p[:, roles.hips[0]], p[:, roles.hips[1]], roles.up_axis)
    mid = p[:, list(roles.shoulders)].mean(1)
    v = to_heading_frame(mid[:, None], p[:, roles.pelvis], H)[:, 0]
    lat = 1 if roles.up_axis == 0 else 0
    fwd = 3 - lat - roles.up_axis
    return torch.rad2deg(torch.atan2(v[:, fwd], v[:, roles.up_axis]))


def check_path(path: torch.Tensor, max_run: int) -> None:
    """A DP path: starts at (0, 0), steps (1,0) (0,1) (1,1), runs of one kind at most ``max_run``."""
    assert path.dim() == 2 and path.shape[1] == 2 and path.shape[0] >= 2
    assert path[0].tolist() == [0, 0]
    steps = torch.diff(path, dim=0).tolist()
    assert all(tuple(s) in ((1, 0), (0, 1), (1, 1)) for s in steps), "path steps must be (1,0), (0,1) or (1,1)"
    for kind in ((1, 0), (0, 1)):
        run = 0
        for s in steps:
            run = run + 1 if tuple(s) == kind else 0
            assert run <= max_run, f"more than {max_run} consecutive {kind} steps"


# ------------------------------------------------------------------------------ 1. self-splice


def assert_returns_itself(m: Motion, spec, options: SpliceOptions = OPT) -> None:
    r = splice(m, m, spec, options=options)
    n = r.motion.num_frames
    assert n == m.num_frames
    assert angle(r.motion.rotations, m.rotations) < 1e-5
    assert torch.equal(r.motion.root_translation, m.root_translation)
    if m.translations is not None:
        assert torch.equal(r.motion.translations, m.translations)
    assert r.crop == 0
    assert torch.allclose(r.curve, torch.arange(n, dtype=F64), atol=1e-6)


@pytest.mark.parametrize("name", LOCOMOTION + ACTIONS)
def test_splicing_a_sample_clip_onto_itself_returns_it(sample_f64, name):
    clips, spec, _ = sample_f64
    assert_returns_itself(clips[name], spec)


@pytest.mark.parametrize("name", [WALK2, TURN_LEFT, "dataset-2_walk-turn-right_normal_031", ELDERLY,
                                  "dataset-1_walk_proud_001", "dataset-2_run_normal_028"])
def test_splicing_a_bandai_namco_walk_onto_itself_returns_it(bandai_f64, name):
    read, spec = bandai_f64
    assert_returns_itself(read(name), spec)


@pytest.mark.parametrize("backend", ["compiled", "torch"])
@pytest.mark.parametrize("name", [WALK2, "dataset-1_walk-left_normal_001", "dataset-1_walk-right_normal_001"])
def test_with_the_locomotions_twist_a_clip_onto_itself_still_returns_it(bandai_f64, name, backend):
    read, spec = bandai_f64  # the side walks twist their shoulders by about 16 degrees: none is added to their own
    assert_returns_itself(read(name), spec, replace(OPT, twist=1.0, force=True, backend=backend))


def test_splicing_the_cmu_walk_onto_itself_returns_it(mocap_dir):
    m = read_bvh(mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh", dtype=F64)
    assert m.fps == 120.0
    spec = detect_spec(m.skeleton, "cmu_12_01_walk.bvh")
    assert spec.name == "cmu"
    assert_returns_itself(m, spec)


# ------------------------------------------------------------------------------ 2. world placement


def assert_same_result(r1, r2, size: float) -> None:
    assert r1.motion.num_frames == r2.motion.num_frames
    assert angle(r1.motion.rotations, r2.motion.rotations) < 1e-5
    assert float((r1.motion.root_translation - r2.motion.root_translation).abs().max()) <= 1e-6 * size
    if r1.motion.translations is not None:
        assert float((r1.motion.translations - r2.motion.translations).abs().max()) <= 1e-6 * size
    assert torch.allclose(r1.curve, r2.curve, atol=1e-6)


@pytest.mark.parametrize("method", ["splice", "naive", "cpmc"])
@pytest.mark.parametrize("loco, act", [("walk_straight", "carry_box"), ("walk_curve", "wave"), ("turn_sharp", "punch")])
def test_placing_the_action_elsewhere_changes_nothing_sample(sample_f64, method, loco, act):
    clips, spec, _ = sample_f64
    L, A = clips[loco], clips[act]
    ref = clips["walk_straight"] if method == "cpmc" else None
    r1 = splice(L, A, spec, method, ref, OPT)
    moved = place(A)
    assert float((moved.global_positions() - A.global_positions()).abs().max()) > 50  # it did move
    r2 = splice(L, moved, spec, method, ref, OPT)
    assert_same_result(r1, r2, L.skeleton.size())
    if method == "cpmc" and loco == "walk_straight":  # the reference's placement does not matter either
        r3 = splice(L, A, spec, method, place(ref, -120.0, (-300.0, 0.0, 40.0)), OPT)
        assert_same_result(r1, r3, L.skeleton.size())


@pytest.mark.parametrize("method", ["splice", "naive", "cpmc"])
def test_placing_the_action_elsewhere_changes_nothing_bandai(bandai_f64, method):
    read, spec = bandai_f64
    L, A = read(TURN_LEFT), read(ELDERLY)
    ref = read(WALK2) if method == "cpmc" else None
    r1 = splice(L, A, spec, method, ref, OPT)
    moved = place(A)
    # joint_Root moved, and Hips (the trajectory joint) with it
    hips = spec.bind(A.skeleton).root
    assert float((moved.global_positions()[:, hips] - A.global_positions()[:, hips]).abs().max()) > 50
    r2 = splice(L, moved, spec, method, ref, OPT)
    assert_same_result(r1, r2, L.skeleton.size())


# ------------------------------------------------------------------------------ 3. determinism


@pytest.mark.parametrize("method", ["splice", "naive", "cpmc"])
def test_same_inputs_give_bit_identical_results(sample_f64, method):
    clips, spec, _ = sample_f64
    clips32 = {n: clips[n].to(torch.float32) for n in ("walk_curve", "carry_box", "jog", "wave", "walk_straight")}
    runs = ((clips, OPT), (clips32, SpliceOptions())) if method == "splice" else ((clips, OPT),)
    for c, opt in runs:
        refs = [c["walk_straight"]] * 2 if method == "cpmc" else None
        pairs = [(c["walk_curve"], c["carry_box"]), (c["jog"], c["wave"])]
        a = splice_pairs(pairs, spec, method, refs, opt)
        b = splice_pairs(pairs, spec, method, refs, opt)
        for x, y in zip(a, b):
            assert torch.equal(x.motion.rotations, y.motion.rotations)
            assert torch.equal(x.motion.root_translation, y.motion.root_translation)
            assert torch.equal(x.curve, y.curve) and torch.equal(x.path, y.path)
            assert torch.equal(x.pelvis_correction, y.pelvis_correction)
            assert x.crop == y.crop and x.posture_deg == y.posture_deg
            assert x.cost == y.cost or (math.isnan(x.cost) and math.isnan(y.cost))


# ------------------------------------------------------------------------------ 4. batched = single


@pytest.mark.parametrize("method", ["splice", "naive", "cpmc"])
def test_batched_pairs_equal_single_pairs(sample_f64, method):
    clips, spec, _ = sample_f64
    names = [("walk_straight", "carry_box"), ("walk_curve", "wave"), ("turn_sharp", "carry_cup"),
             ("jog", "punch"), ("sidestep", "arms_out"), ("walk_straight", "punch")]
    pairs = [(clips[a], clips[b]) for a, b in names]
    assert len({(a.num_frames, b.num_frames) for a, b in pairs}) > 3  # different lengths
    refs = [clips["walk_straight"]] * len(pairs) if method == "cpmc" else None
    batch = splice_pairs(pairs, spec, method, refs, OPT)
    assert [r.action for r in batch] == [b for _, b in names]
    for k, (L, A) in enumerate(pairs):
        one = splice(L, A, spec, method, None if refs is None else refs[k], OPT)
        got = batch[k]
        assert got.motion.num_frames == one.motion.num_frames
        assert angle(got.motion.rotations, one.motion.rotations) < 1e-9
        assert torch.allclose(got.motion.root_translation, one.motion.root_translation, atol=1e-9, rtol=0)
        assert torch.allclose(got.curve, one.curve, atol=1e-9, rtol=0)
        assert torch.equal(got.path, one.path) and got.crop == one.crop
        assert got.posture_deg == pytest.approx(one.posture_deg, abs=1e-9)
        assert torch.allclose(got.pelvis_correction, one.pelvis_correction, atol=1e-7, rtol=0)


@pytest.mark.parametrize("frames", [16, 24])
def test_a_short_clip_in_the_batch_changes_no_other_pair(sample_f64, frames):
    """A pair's result must not depend on what else is in the batch. A short action (here
    ``frames`` frames, forced) beside it must leave its crop, length and poses unchanged."""
    clips, spec, _ = sample_f64
    opt = replace(OPT, force=True)
    short = replace(clips["wave"].slice(40, 40 + frames), name=f"wave{frames}")
    for loco, act in [("walk_curve", "carry_box"), ("sidestep", "arms_out"), ("jog", "wave")]:
        one = splice(clips[loco], clips[act], spec, options=opt)
        two = splice_pairs([(clips[loco], clips[act]), (clips["walk_straight"], short)], spec, options=opt)[0]
        assert (two.crop, two.motion.num_frames) == (one.crop, one.motion.num_frames), (loco, act)
        assert angle(two.motion.rotations, one.motion.rotations) < 1e-9


def test_locomotion_verdict_does_not_depend_on_the_batch(sample_f64):
    """A 29-frame walk is refused alone; it must be refused in a batch beside a longer clip too."""
    clips, spec, _ = sample_f64
    short = replace(clips["walk_straight"].slice(0, 29), name="walk29")
    alone = splice(short, clips["carry_box"], spec, options=replace(OPT, force=True)).checks[0]
    batched = splice_pairs([(clips["walk_straight"], clips["carry_box"]), (short, clips["carry_box"])], spec,
                           options=replace(OPT, force=True))[1].checks[0]
    assert (batched.locomoting, batched.swings) == (alone.locomoting, alone.swings)


# ------------------------------------------------------------------------------ 5. posture


@pytest.mark.parametrize("loco", ["walk_straight", "walk_curve"])
def test_posture_transfer_keeps_the_carry_box_lean(sample_f64, loco):
    clips, spec, roles = sample_f64
    L, A = clips[loco], clips["carry_box"]
    r = splice(L, A, spec, options=OPT)
    want = float(leans(at_times(A, r.curve), roles).mean())
    assert want < -9.0  # the box carrier leans back (sanity of the measure)
    assert abs(float(leans(L, roles).mean()) - want) > 10.0  # ... unlike the walker
    got = float(leans(r.motion, roles).mean())
    assert abs(got - want) < 1.0
    flat = splice(L, A, spec, options=replace(OPT, posture=False))
    assert abs(float(leans(flat.motion, roles).mean()) - want) > 5.0
    assert r.posture_deg > 5.0 and flat.posture_deg == 0.0


def paper_posture_lean(L: Motion, A: Motion, roles, flat) -> tuple[float, torch.Tensor]:
    """Mean lean with the paper's literal posture step: spliced local pelvis ``q_SP * q_G``
    (``q_G`` applied in the pelvis's own frame), from the result without posture transfer."""
    sk = L.skeleton
    out = splice_tensors(clips_to_tensors([L], sk, F64), clips_to_tensors([A], sk, F64), roles, sk, OPT.align, L.fps)
    q_g = out.posture_rotation[0]
    rot = flat.motion.rotations.clone()
    rot[:, roles.pelvis] = quat_mul(rot[:, roles.pelvis], q_g.expand(rot.shape[0], 4))
    return float(leans(replace(flat.motion, rotations=rot), roles).mean()), q_g


@pytest.mark.parametrize("loco, act", [(TURN_LEFT, ELDERLY), (WALK2, ELDERLY),
                                       ("dataset-1_walk-left_normal_001", "dataset-1_walk_old_001")])
def test_posture_transfer_on_real_styled_walk_and_the_literal_paper_formula(bandai_f64, loco, act):
    read, spec = bandai_f64
    L, A = read(loco), read(act)
    roles = spec.bind(L.skeleton)
    r = splice(L, A, spec, options=OPT)
    flat = splice(L, A, spec, options=replace(OPT, posture=False))
    want = float(leans(at_times(A, r.curve), roles).mean())
    ours = abs(float(leans(r.motion, roles).mean()) - want)
    assert ours < 1.5
    assert abs(float(leans(flat.motion, roles).mean()) - want) > 5.0
    paper, q_g = paper_posture_lean(L, A, roles, flat)
    # the q_G the library used is the one it reports
    assert math.degrees(float(quat_angle(q_g, torch.tensor([1.0, 0, 0, 0], dtype=F64)))) == pytest.approx(r.posture_deg, abs=1e-6)
    # Bandai Namco's pelvis axes are not the heading frame's: q_G in the pelvis's local frame tilts
    # the trunk about the wrong axis
    assert abs(paper - want) > ours + 4.0


def test_literal_paper_formula_agrees_on_world_aligned_joint_axes(sample_f64):
    """Where the pelvis's local axes are the world's (the sample), both formulas agree: this
    validates the re-computation of the paper's formula in the test above."""
    clips, spec, roles = sample_f64
    L, A = clips["walk_straight"], clips["carry_box"]
    r = splice(L, A, spec, options=OPT)
    flat = splice(L, A, spec, options=replace(OPT, posture=False))
    paper, _ = paper_posture_lean(L, A, roles, flat)
    assert paper == pytest.approx(float(leans(r.motion, roles).mean()), abs=0.5)


# ------------------------------------------------------------------------------ spatial alignment


def cloud_error(m: Motion, L: Motion, roles) -> torch.Tensor:
    """``(T,)`` summed squared distance between the spine and shoulder joints of ``m`` and of
    the locomotion ``L``, each relative to its own pelvis joint (world axes)."""
    idx = [j for j in roles.spine if j != roles.pelvis] + list(roles.shoulders)
    p, q = m.global_positions(), L.global_positions()[: m.num_frames]
    a = p[:, idx] - p[:, roles.pelvis, None]
    b = q[:, idx] - q[:, roles.pelvis, None]
    return ((a - b) ** 2).sum((-1, -2))


def with_pelvis(m: Motion, roles, rot: torch.Tensor) -> Motion:
    r = m.rotations.clone()
    r[:, roles.pelvis] = rot
    return replace(m, rotations=r)


@pytest.mark.parametrize("where", ["sample", "bandai"])
def test_spatial_alignment_is_the_best_pelvis_rotation(sample_f64, request, where):
    """Without posture transfer the spliced pelvis rotation ``q_LP * q_A`` brings the action's
    spine and shoulders as close as any pelvis rotation can to the locomotion's (Horn's
    least squares): perturbing it, or leaving ``q_LP`` alone, never does better."""
    if where == "sample":
        clips, spec, roles = sample_f64
        L, A = clips["walk_curve"], clips["punch"]
    else:
        read, spec = request.getfixturevalue("bandai_f64")
        L, A = read(TURN_LEFT), read(ELDERLY)
        roles = spec.bind(L.skeleton)
    r = splice(L, A, spec, options=replace(OPT, posture=False))
    n = r.motion.num_frames
    best = cloud_error(r.motion, L, roles)
    q_lp = L.rotations[:n, roles.pelvis]
    plain = cloud_error(with_pelvis(r.motion, roles, q_lp), L, roles)
    assert bool((best <= plain + 1e-9).all()) and float(plain.mean()) > float(best.mean()) + 1e-3
    # the reported correction is the angle between q_LP and the spliced pelvis
    corr = torch.rad2deg(quat_angle(q_lp, r.motion.rotations[:, roles.pelvis]))
    assert torch.allclose(r.pelvis_correction, corr, atol=1e-6)
    assert float(r.pelvis_correction.max()) > 0.5
    g = torch.Generator().manual_seed(7)
    for _ in range(4):
        delta = axis_angle_to_quat(torch.randn(n, 3, dtype=F64, generator=g) * 0.05)
        for rot in (quat_mul(r.motion.rotations[:, roles.pelvis], delta), quat_mul(delta, r.motion.rotations[:, roles.pelvis])):
            worse = cloud_error(with_pelvis(r.motion, roles, rot), L, roles)
            assert bool((best <= worse + 1e-9 * L.skeleton.size() ** 2).all())


# ------------------------------------------------------------------------------ 6. wrong foot


def knee_signal(m: Motion, roles) -> torch.Tensor:
    """``(T,)`` forward distance between the knees in the heading frame (left minus right)."""
    p = m.global_positions().to(F64)
    H = heading_frame(p[:, roles.hips[0]], p[:, roles.hips[1]], roles.up_axis)
    k = to_heading_frame(p[:, list(roles.knees)], p[:, roles.root], H)
    fwd = 3 - (1 if roles.up_axis == 0 else 0) - roles.up_axis
    return k[:, 0, fwd] - k[:, 1, fwd]


def stride_by_autocorrelation(s: torch.Tensor) -> int:
    """Gait cycle (two steps) in frames: first autocorrelation peak after the first negative lobe."""
    s = s - s.mean()
    T = s.shape[0]
    ac = torch.stack([(s[: T - lag] * s[lag:]).mean() for lag in range(T // 2)])
    lag = int((ac < 0).nonzero()[0])
    while lag + 1 < ac.shape[0] and (ac[lag] < 0 or ac[lag + 1] >= ac[lag]):
        lag += 1
    return lag


def gait_phase(x: torch.Tensor, s: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Gait phase (cycles) at fractional frames ``x``: linear between successive zero crossings
    of the knee signal (two per cycle); and where it is defined."""
    a, b = s[:-1], s[1:]
    idx = ((a < 0) != (b < 0)).nonzero()[:, 0]
    cross = idx.to(F64) + a[idx] / (a[idx] - b[idx])
    i = torch.searchsorted(cross, x) - 1
    ok = (i >= 0) & (i < cross.shape[0] - 1)
    i = i.clamp(0, cross.shape[0] - 2)
    return (i + (x - cross[i]) / (cross[i + 1] - cross[i])) / 2, ok


@pytest.mark.parametrize("name", [WALK2, "dataset-1_walk_proud_001"])
def test_never_on_the_wrong_foot(bandai_f64, name):
    """The walk spliced onto itself shifted by k frames: the action frame matched to locomotion
    frame t must be in phase with it (t - k plus whole gait cycles), never half a cycle off.

    Strides of a real walk vary by a few frames, so the phase is measured on the clip itself
    (knee zero crossings) rather than assumed to repeat with one constant stride; the constant-
    stride error is also checked against a quarter stride (half a stride = the wrong foot)."""
    read, spec = bandai_f64
    m = read(name)
    roles = spec.bind(m.skeleton)
    s = knee_signal(m, roles)
    S = stride_by_autocorrelation(s)
    assert 20 <= S <= 70, S  # a human gait cycle at 30 fps
    ks = list(range(1, S + 10, 3))  # more than a stride of shifts
    pairs = [(m, replace(m.slice(k, m.num_frames), name=f"{name}[{k}:]")) for k in ks]
    for k, r in zip(ks, splice_pairs(pairs, spec, options=OPT)):
        t = torch.arange(r.curve.shape[0], dtype=F64)
        late = t >= 15
        const = torch.remainder(r.curve - (t - k) + S / 2, S) - S / 2
        assert float(const[late].abs().max()) < S / 4, (k, float(const[late].abs().max()))
        pt, ok_t = gait_phase(t, s)
        pa, ok_a = gait_phase(r.curve + k, s)
        ok = ok_t & ok_a & late
        assert int(ok.sum()) > 0.5 * r.curve.shape[0]
        err = (torch.remainder(pa - pt + 0.5, 1.0) - 0.5) * S
        assert float(err[ok].abs().max()) < 2.0, (k, float(err[ok].abs().max()))


# ------------------------------------------------------------------------------ 7. known time warp


@pytest.mark.parametrize("loco", ["walk_straight", "walk_curve", "turn_sharp"])
@pytest.mark.parametrize("warp", ["1.2x", "wavy"])
def test_alignment_curve_recovers_a_known_time_warp(sample_f64, loco, warp):
    """The action is the locomotion played at action frame a -> locomotion time g(a); the curve
    must be g's inverse."""
    clips, spec, _ = sample_f64
    W = clips[loco]
    if warp == "1.2x":
        g = lambda a: 1.2 * a  # noqa: E731
    else:
        g = lambda a: 1.1 * a + 4.0 * torch.sin(2 * math.pi * a / 90.0)  # noqa: E731  monotone: 1.1 > 4 * 2pi / 90
    a = torch.arange(0, 2 * W.num_frames, dtype=F64)
    ga = g(a)
    keep = ga <= W.num_frames - 1
    A = at_times(W, ga[keep], name=f"{loco}@{warp}")
    r = splice(W, A, spec, options=OPT)
    assert r.crop == 0
    t = torch.arange(r.curve.shape[0], dtype=F64)
    fine = torch.linspace(0, float(a[keep][-1]), 20001, dtype=F64)
    inverse = torch.from_numpy(np.interp(t.numpy(), g(fine).numpy(), fine.numpy()))
    n = t.shape[0]
    middle = slice(n // 6, n - n // 6)
    assert n >= 0.8 * W.num_frames
    assert float((r.curve - inverse)[middle].abs().max()) < 1.0


# ------------------------------------------------------------------------------ 8. frame rates


def test_action_at_120_fps_onto_locomotion_at_30_fps(sample_f64):
    clips, spec, roles = sample_f64
    L, A = clips["walk_straight"], clips["carry_box"]
    A120 = replace(at_times(A, torch.arange(0, A.num_frames - 1 + 1e-9, 0.25, dtype=F64)), fps=120.0, name="carry_box@120")
    r30, r120 = splice(L, A, spec, options=OPT), splice(L, A120, spec, options=OPT)
    assert r120.motion.fps == 30.0 and r120.motion.num_frames == r30.motion.num_frames
    assert torch.allclose(r120.curve, 4 * r30.curve, atol=1e-6)  # in the action's own 120-fps frames
    assert r120.crop == 4 * r30.crop
    assert angle(r120.motion.rotations, r30.motion.rotations) < 1e-6
    # the upper body is the 120-fps action sampled at the curve
    upper = [j for j in roles.upper_body if j != roles.pelvis]
    want = slerp_frames(A120.rotations[None], r120.curve[None], torch.tensor([A120.num_frames]))[0]
    assert angle(r120.motion.rotations[:, upper], want[:, upper]) < 1e-6


def test_cmu_walk_at_120_fps_onto_itself_at_30_fps(mocap_dir):
    m = read_bvh(mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh", dtype=F64)
    spec = detect_spec(m.skeleton, "cmu_12_01_walk.bvh")
    L = replace(at_times(m, torch.arange(0, m.num_frames, 4, dtype=F64)), fps=30.0, name="cmu_walk@30")
    r = splice(L, m, spec, options=OPT)
    assert r.motion.fps == 30.0 and r.motion.num_frames == L.num_frames
    t = torch.arange(r.curve.shape[0], dtype=F64)
    assert float((r.curve - 4 * t).abs().max()) < 1.0  # 120-fps frames of the action
    assert angle(r.motion.rotations, L.rotations) < 1e-5


# ------------------------------------------------------------------------------ 9. not locomoting


@pytest.mark.parametrize("clip", ["dataset-2_wave-left-hand_normal_001", "dataset-1_bow_normal_001"])
def test_in_place_locomotions_are_refused_unless_forced_and_in_place_actions_stand(bandai_f64, clip):
    read, spec = bandai_f64
    walk, still = read(WALK2), read(clip)
    with pytest.raises(NotLocomotingError) as e:
        splice(still, walk, spec, options=OPT)  # as the locomotion: nothing to walk on
    msg = str(e.value)
    assert clip in msg and "does not locomote" in msg and "no alternating steps" in msg and "\n" not in msg
    with pytest.raises(NotLocomotingError, match=clip):  # within a batch
        splice_pairs([(walk, walk), (still, walk)], spec, options=OPT)
    standing = splice_pairs([(walk, walk), (walk, still)], spec, options=OPT)  # as the action: a standing action
    assert [r.timing for r in standing] == ["timewarp", "loop"]
    assert standing[1].motion.num_frames == walk.num_frames and "standing action" in standing[1].notes[-1]
    r = splice(walk, still, spec, options=replace(OPT, force=True))  # forced through the timewarp
    assert r.motion.num_frames > 0
    assert len(r.notes) == 1 and clip in r.notes[0] and "does not locomote" in r.notes[0]
    assert r.checks[0].locomoting and not r.checks[1].locomoting and r.checks[1].reason


def test_walks_pass_the_locomotion_check(bandai_f64, sample_f64):
    read, spec = bandai_f64
    r = splice(read(TURN_LEFT), read(ELDERLY), spec, options=OPT)
    assert r.checks[0].locomoting and r.checks[1].locomoting and r.notes == ()
    assert min(r.checks[0].swings) >= 1 and r.checks[0].travel >= 1.0
    clips, sspec, _ = sample_f64
    for res in splice_pairs([(clips[n], clips["wave"]) for n in LOCOMOTION], sspec, options=OPT):
        assert all(c.locomoting for c in res.checks) and res.notes == ()


# ------------------------------------------------------------------------------ 10. bad input


@pytest.fixture(scope="module")
def three_skeletons(mocap_dir):
    bn = read_bvh(mocap_dir / BANDAI / f"{WALK2}.bvh")
    lafan = read_bvh(mocap_dir / "lafan1_via_pypi_bvhtools" / "test2.bvh").slice(0, 300)
    cmu = read_bvh(mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh")
    return [bn, lafan, cmu]


@pytest.mark.parametrize("i, j", [(0, 1), (1, 0), (0, 2), (2, 1)])
def test_different_skeletons_are_refused_naming_both_clips(three_skeletons, i, j):
    a, b = three_skeletons[i], three_skeletons[j]
    spec = detect_spec(a.skeleton, a.name + ".bvh")
    for method in ("splice", "naive"):
        with pytest.raises(MotionError) as e:
            splice(a, b, spec, method)
        assert a.name in str(e.value) and b.name in str(e.value)


def test_pairs_of_different_skeletons_in_one_batch_are_refused(three_skeletons, bandai_f64):
    read, spec = bandai_f64
    a = three_skeletons[0]
    laf = three_skeletons[1]
    with pytest.raises(MotionError, match=laf.name):
        splice_pairs([(a, a), (laf, laf)], spec)


def test_short_and_non_finite_clips_are_refused_by_name(sample_f64):
    clips, spec, _ = sample_f64
    L, A = clips["walk_straight"], clips["carry_box"]
    short = replace(A.slice(0, 5), name="tiny_clip")
    for pair in ((L, short), (short, L)):
        with pytest.raises(MotionError, match="tiny_clip") as e:
            splice(*pair, spec)
        assert "5 frames" in str(e.value)
    rot = A.rotations.clone()
    rot[17, 12, 2] = float("nan")
    bad = replace(A, rotations=rot, name="nan_clip")
    for pair in ((L, bad), (bad, L)):
        with pytest.raises(MotionError, match="nan_clip"):
            splice(*pair, spec)
    root = L.root_translation.clone()
    root[3, 0] = float("inf")
    with pytest.raises(MotionError, match="inf_clip"):
        splice(replace(L, root_translation=root, name="inf_clip"), A, spec)
    with pytest.raises(MotionError, match="nan_clip"):  # a bad reference is named too
        splice(L, A, spec, "cpmc", bad)


# ------------------------------------------------------------------------------ 6b. the locomotion's twist


def shoulder_yaw_deg(m: Motion, roles) -> float:
    """Yaw (degrees) of the frame-averaged shoulder line against the hips, in heading frames."""
    from torchsplice.splice.heck import shoulder_yaw

    p = m.global_positions().to(F64)
    H = heading_frame(p[:, roles.hips[0]], p[:, roles.hips[1]], roles.up_axis)
    cloud = to_heading_frame(p[:, list(roles.shoulders)], p[:, roles.pelvis], H).mean(0)
    return math.degrees(float(shoulder_yaw(cloud, roles.up_axis)))


@pytest.mark.parametrize("up", [0, 1, 2])
def test_twist_target_known_answers(up):
    from torchsplice.splice.heck import shoulder_yaw, twist_target

    g = torch.Generator().manual_seed(up)
    act, loco = torch.randn(5, 2, 3, generator=g, dtype=F64), torch.randn(5, 2, 3, generator=g, dtype=F64)
    assert twist_target(act, loco, 0.0, up) is act                      # share 0: the paper's target
    full, half = twist_target(act, loco, 1.0, up), twist_target(act, loco, 0.5, up)
    ya, yl = shoulder_yaw(act, up), shoulder_yaw(loco, up)
    wrap = lambda x: torch.remainder(x + math.pi, 2 * math.pi) - math.pi  # noqa: E731
    assert torch.allclose(wrap(shoulder_yaw(full, up) - yl), torch.zeros(5, dtype=F64), atol=1e-12)
    assert torch.allclose(wrap(shoulder_yaw(half, up) - ya), 0.5 * (yl - ya), atol=1e-12)
    for out in (full, half):                                            # a turn about the up axis only
        assert torch.allclose(out.norm(dim=-1), act.norm(dim=-1), atol=1e-12)
        assert torch.equal(out[..., up], act[..., up])
    square = torch.tensor([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]], dtype=F64)[None][..., [(k - (1 if up == 0 else 0)) % 3 for k in range(3)]]
    assert abs(float(shoulder_yaw(square, up))) < 1e-12                 # square shoulders: yaw 0


def test_the_twist_share_moves_the_shoulders_towards_the_side_walks(bandai_f64):
    read, spec = bandai_f64
    act, roles = read("dataset-1_walk_happy_001"), spec.bind(read(WALK2).skeleton)
    for name, sign in (("dataset-1_walk-left_normal_001", 1), ("dataset-1_walk-right_normal_001", -1)):
        loco = read(name)
        y_loco, y_act = shoulder_yaw_deg(loco, roles), shoulder_yaw_deg(act, roles)
        assert sign * y_loco > 10 and abs(y_act) < 5                    # the side walk twists, the walk does not
        got = {tw: shoulder_yaw_deg(splice(loco, act, spec, options=replace(OPT, twist=tw, force=True)).motion, roles)
               for tw in (0.0, 0.5, 1.0)}
        assert abs(got[0.0] - y_act) < 1.5                              # the paper: the action's posture
        assert abs(got[1.0] - y_loco) < 1.5                             # all of the locomotion's twist
        assert abs(got[0.5] - 0.5 * (got[0.0] + got[1.0])) < 1.0        # half of it
    with pytest.raises(TorchspliceError, match="twist"):
        splice(loco, act, spec, options=replace(OPT, twist=1.5, force=True))


def test_unknown_method_and_missing_reference(sample_f64):
    clips, spec, _ = sample_f64
    L, A = clips["walk_straight"], clips["carry_box"]
    with pytest.raises(TorchspliceError, match="unknown method 'blend'"):
        splice(L, A, spec, "blend")
    with pytest.raises(TorchspliceError, match="reference"):
        splice(L, A, spec, "cpmc")
    with pytest.raises(TorchspliceError, match="reference"):
        splice_pairs([(L, A), (L, A)], spec, "cpmc", [L])  # one reference short


# ------------------------------------------------------------------------------ 11. result structure


def assert_structure(L: Motion, A: Motion, r, roles, max_run: int = 3) -> None:
    n = r.motion.num_frames
    lower = list(roles.lower_body)
    assert roles.root in lower and 0 in lower and roles.pelvis not in lower
    # root and lower body are the locomotion's, frame for frame
    assert torch.equal(r.motion.rotations[:, lower], L.rotations[:n, lower])
    assert torch.equal(r.motion.root_translation, L.root_translation[:n])
    if L.translations is not None:
        assert torch.equal(r.motion.translations[:, lower], L.translations[:n, lower])
        assert torch.equal(r.motion.translations[:, roles.pelvis], L.translations[:n, roles.pelvis])
    # the upper body above the pelvis is the action sampled at the curve
    upper = [j for j in roles.upper_body if j != roles.pelvis]
    lengths = torch.tensor([A.num_frames])
    want = slerp_frames(A.rotations[None], r.curve[None], lengths)[0]
    assert angle(r.motion.rotations[:, upper], want[:, upper]) < 1e-6
    if A.translations is not None:
        wt = interpolate_frames(A.translations[None], r.curve[None], lengths)[0]
        assert torch.allclose(r.motion.translations[:, upper], wt[:, upper], atol=1e-6 * L.skeleton.size(), rtol=0)
    # lengths, curve and path
    assert n <= L.num_frames and r.path.shape[0] >= 2
    check_path(r.path, max_run)
    i_end, j_end = r.path[-1].tolist()
    assert n == i_end + 1
    assert i_end == L.num_frames - 1 or j_end == A.num_frames - r.crop - 1  # ends on an edge of the grid
    assert r.curve.dtype == F64 and r.curve.shape == (n,)
    assert bool((torch.diff(r.curve) > 0).all())
    assert float(r.curve[0]) == pytest.approx(r.crop, abs=1e-9)
    assert float(r.curve[-1]) == pytest.approx(r.crop + j_end, abs=1e-9)
    assert float(r.curve.max()) <= A.num_frames - 1 + 1e-9
    assert r.pelvis_correction.shape == (n,) and bool((r.pelvis_correction >= 0).all())
    assert r.motion.skeleton is L.skeleton and r.motion.fps == L.fps and r.motion.role == "spliced"


@pytest.mark.parametrize("loco, act", [("walk_straight", "carry_box"), ("turn_sharp", "wave"), ("jog", "punch"),
                                       ("sidestep", "carry_cup")])
def test_result_structure_sample(sample_f64, loco, act):
    clips, spec, roles = sample_f64
    L, A = clips[loco], clips[act]
    r = splice(L, A, spec, options=OPT)
    assert r.method == "splice" and r.locomotion == loco and r.action == act and r.reference is None
    assert math.isfinite(r.cost) and r.cost >= 0
    assert_structure(L, A, r, roles)


def test_result_structure_respects_max_run(sample_f64):
    clips, spec, roles = sample_f64
    L, A = clips["walk_curve"], clips["carry_box"]
    for max_run in (1, 2, 5):
        opt = replace(OPT, align=replace(OPT.align, max_run=max_run))
        assert_structure(L, A, splice(L, A, spec, options=opt), roles, max_run)


def test_result_structure_bandai(bandai_f64):
    read, spec = bandai_f64
    L, A = read(TURN_LEFT), read(ELDERLY)
    r = splice(L, A, spec, options=OPT)
    assert L.translations is not None
    assert_structure(L, A, r, spec.bind(L.skeleton))


# ------------------------------------------------------------------------------ 12. naive


@pytest.mark.parametrize("loco, act", [("walk_straight", "carry_box"), ("jog", "wave"), ("walk_curve", "punch")])
def test_naive_copies_the_upper_body_frame_by_frame(sample_f64, loco, act):
    clips, spec, roles = sample_f64
    L, A = clips[loco], clips[act]
    r = splice(L, A, spec, "naive", options=OPT)
    n = min(L.num_frames, A.num_frames)
    assert r.motion.num_frames == n and r.crop == 0 and r.path.shape[0] == 0 and math.isnan(r.cost)
    upper, lower = list(roles.upper_body), list(roles.lower_body)
    assert roles.pelvis in upper
    assert torch.equal(r.motion.rotations[:, upper], A.rotations[:n, upper])
    assert torch.equal(r.motion.rotations[:, lower], L.rotations[:n, lower])
    assert torch.equal(r.motion.root_translation, L.root_translation[:n])
    assert torch.equal(r.curve, torch.arange(n, dtype=F64))
    assert r.posture_deg == 0.0 and bool((r.pelvis_correction == 0).all())


def test_naive_bandai_keeps_locomotion_translations(bandai_f64):
    read, spec = bandai_f64
    L, A = read(TURN_LEFT), read(ELDERLY)
    roles = spec.bind(L.skeleton)
    r = splice(L, A, spec, "naive", options=OPT)
    n = min(L.num_frames, A.num_frames)
    assert r.motion.num_frames == n
    assert torch.equal(r.motion.rotations[:, list(roles.upper_body)], A.rotations[:n, list(roles.upper_body)])
    assert torch.equal(r.motion.translations[:, list(roles.lower_body)], L.translations[:n, list(roles.lower_body)])
    assert torch.equal(r.motion.translations[:, roles.pelvis], L.translations[:n, roles.pelvis])


# ------------------------------------------------------------------------------ 13. cpmc


@pytest.mark.parametrize("act", ["carry_box", "wave", "punch"])
def test_cpmc_with_the_base_as_reference_returns_the_action(sample_f64, act):
    """Reference = locomotion = walk_straight: the difference added back onto its own reference.

    The result is ``W(t) * R(tau)^-1 * A(s)`` with ``s`` = curve(t) the action frame and
    ``tau`` the reference frame the reference-to-action alignment pairs with ``s``; so each
    joint's error against ``A(s)`` is ``angle(W(t), W(tau))``: zero only if the two
    independent alignments invert each other exactly. Phase cropping typically pairs the base
    frame with the reference one gait cycle later, so the error is the walk's cycle-to-cycle
    variation. Beyond that, slerping the difference instead of each factor adds a second-order
    term: at most (w * (L + 1))^2 / 8 for per-frame angular steps w and path slope limit L.
    """
    clips, spec, roles = sample_f64
    W, A = clips["walk_straight"], clips[act]
    r = splice(W, A, spec, "cpmc", W, OPT)
    assert r.reference == "walk_straight"
    n = r.motion.num_frames
    up = list(roles.upper_body)
    a_s = slerp_frames(A.rotations[None], r.curve[None], torch.tensor([A.num_frames]))[0]
    err = quat_angle(r.motion.rotations[:, up], a_s[:, up])  # (n, U)
    # the reference frame paired with each action frame (as cpmc aligns them: reference to action)
    al = time_align(clips_to_tensors([A], W.skeleton, F64), clips_to_tensors([W], W.skeleton, F64), roles, OPT.align, W.fps)
    m = int(al.frames[0])
    tau = interpolate_frames((al.curve[0, :m] + al.crop[0])[None, :, None], r.curve[None], torch.tensor([m]))[0, :, 0]
    w_tau = slerp_frames(W.rotations[None], tau[None], torch.tensor([W.num_frames]))[0]
    drift = quat_angle(W.rotations[:n, up], w_tau[:, up])
    step = float(quat_angle(W.rotations[1:, up], W.rotations[:-1, up]).max())
    second_order = (step * (OPT.align.max_run + 1)) ** 2 / 8
    assert float((err - drift).max()) < second_order
    assert float(err.mean()) < math.radians(2.0)
    # and the lower body and root are the base's
    lower = list(roles.lower_body)
    assert torch.equal(r.motion.rotations[:, lower], W.rotations[:n, lower])
    assert torch.equal(r.motion.root_translation, W.root_translation[:n])
    # far closer to the action's upper body than the base's own upper body is
    base_err = quat_angle(W.rotations[:n, up], a_s[:, up])
    assert float(err.mean()) < 0.5 * float(base_err.mean())


def test_cpmc_result_structure(sample_f64):
    clips, spec, roles = sample_f64
    L, A, R = clips["walk_curve"], clips["carry_box"], clips["walk_straight"]
    r = splice(L, A, spec, "cpmc", R, OPT)
    n = r.motion.num_frames
    lower = list(roles.lower_body)
    assert torch.equal(r.motion.rotations[:, lower], L.rotations[:n, lower])
    assert torch.equal(r.motion.root_translation, L.root_translation[:n])
    check_path(r.path, OPT.align.max_run)
    assert n == int(r.path[-1, 0]) + 1 and bool((torch.diff(r.curve) > 0).all())


def test_find_reference_sample(sample_f64):
    clips, spec, _ = sample_f64
    cands = [(m.name, m.role, m.labels) for m in clips.values()]
    for act in ACTIONS:
        assert find_reference(act, clips[act].labels, cands, spec) == "walk_straight"
    # without a straight walk there is none
    assert find_reference("carry_box", clips["carry_box"].labels, [c for c in cands if c[0] != "walk_straight"], spec) is None


def test_find_reference_bandai(mocap_dir):
    spec = load_spec("bandai_namco")
    names = sorted(p.stem for p in (mocap_dir / BANDAI).glob("*.bvh"))
    cands = [(n, *spec.clip_metadata(n)) for n in names]
    role, labels = spec.clip_metadata(ELDERLY)
    assert role == "both"
    assert find_reference(ELDERLY, labels, cands, spec) == WALK2
    role, labels = spec.clip_metadata("dataset-1_walk-left_proud_001")
    assert find_reference("dataset-1_walk-left_proud_001", labels, cands, spec) == "dataset-1_walk-left_normal_001"


# ------------------------------------------------------------------------------ 14. ground truth


@pytest.mark.slow
def test_splice_beats_naive_on_bandai_namco_ground_truth(mocap_dir, bandai_f64, capsys):
    read, spec = bandai_f64
    names = sorted(p.stem for p in (mocap_dir / BANDAI).glob("*.bvh"))
    triples = bandai_namco_triples(names)
    assert len(triples) >= 40
    pairs = [(read(t.locomotion), read(t.action)) for t in triples]
    captures = [read(t.capture) for t in triples]
    roles = spec.bind(pairs[0][0].skeleton)
    opt = SpliceOptions(force=True)  # a few normal Dataset-1 clips are very short
    errors = {}
    for method in ("splice", "naive"):
        results = splice_pairs(pairs, spec, method, options=opt)
        errors[method] = upper_body_error([r.motion for r in results], captures, roles)
        assert errors[method].shape == (len(triples),) and bool(torch.isfinite(errors[method]).all())
    assert float(errors["splice"].mean()) < float(errors["naive"].mean())
    out, err = capsys.readouterr()
    assert out == "" and err == ""


# ------------------------------------------------------------------------------ 15. CUDA


@pytest.mark.gpu
@pytest.mark.parametrize("method", ["splice", "naive", "cpmc"])
def test_cuda_equals_cpu(sample_f64, method):
    clips, spec, _ = sample_f64
    pairs = [(clips["walk_curve"], clips["carry_box"]), (clips["jog"], clips["wave"])]
    refs = [clips["walk_straight"]] * 2 if method == "cpmc" else None
    cpu = splice_pairs(pairs, spec, method, refs, OPT)
    gpu = splice_pairs(pairs, spec, method, refs, replace(OPT, device="cuda"))
    for c, g in zip(cpu, gpu):
        assert g.motion.rotations.device.type == "cuda"
        assert g.motion.num_frames == c.motion.num_frames
        assert torch.equal(g.path, c.path) and g.crop == c.crop
        assert angle(g.motion.rotations.cpu(), c.motion.rotations) < 1e-6
        assert torch.allclose(g.motion.root_translation.cpu(), c.motion.root_translation, atol=1e-9, rtol=0)
        assert torch.allclose(g.curve, c.curve, atol=1e-6, rtol=0)
