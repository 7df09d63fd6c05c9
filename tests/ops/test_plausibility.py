"""Plausibility: a body of capsules around any humanoid skeleton, and what a person would reject
(:mod:`torchsplice.ops.body`, :mod:`torchsplice.ops.plausibility`), measured on every result.

Known answers: the closed-form segment distance against brute force; a clip built with a hand
inside the chest (inside on exactly those frames, as deep as the torso's radius) and the clean
clip (never); a foot sliding at known speeds against GMD's skate rule worked by hand; a seam
of known size in the upper body; the body built on every shipped rig. On a real job (Bandai
Namco runs, dashes and turns x raised hands and waves), every result's columns equal the
figures of its stored frames and of its sources, and the flag says so exactly where the result
exceeds both sources.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from realdata import MOCAP, _require_mocap
from torchsplice.ops.body import CAPSULES, INSIDE_MARGIN, body_of, capsule_ends, inside_depth, segment_distance
from torchsplice.ops.plausibility import GMD_FPS, jerk, penetration, penetration_of_frames, penetration_packed, skate_ratio
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.specs.canonical import canonical_joints
from torchsplice.specs.smpl import smpl22_skeleton
from torchsplice.store.database import MotionDatabase


def test_the_segment_distance_is_the_brute_force_minimum():
    g = torch.Generator().manual_seed(3)
    P = torch.randn(600, 4, 3, generator=g, dtype=torch.float64)
    P[:50, 1] = P[:50, 0]  # a point against a segment
    P[50:100, 3] = P[50:100, 2]  # a segment against a point
    P[100:150, 3] = P[100:150, 2] + 0.6 * (P[100:150, 1] - P[100:150, 0])  # parallel
    P[150:200, 1], P[150:200, 3] = P[150:200, 0], P[150:200, 2]  # two points
    got = segment_distance(P[:, 0], P[:, 1], P[:, 2], P[:, 3])
    s = torch.linspace(0, 1, 801, dtype=torch.float64)
    a = P[:, None, 0] + s[None, :, None] * (P[:, None, 1] - P[:, None, 0])
    b = P[:, None, 2] + s[None, :, None] * (P[:, None, 3] - P[:, None, 2])
    # every pair of grid points, their distances computed directly (not through a matrix product), 100 rows at a time
    brute = torch.cat([torch.cdist(a[i:i + 100], b[i:i + 100], compute_mode="donot_use_mm_for_euclid_dist").flatten(1).amin(1)
                       for i in range(0, len(P), 100)])
    scale = (P[:, 1] - P[:, 0]).norm(dim=-1) + (P[:, 3] - P[:, 2]).norm(dim=-1)
    assert bool((got <= brute + 1e-12).all())  # never above a distance that is reached
    assert bool((brute - got <= 1e-3 * scale + 1e-12).all())  # within the grid's step
    assert float(segment_distance(*torch.tensor([[0, 0, 0], [1, 0, 0], [0.5, -1, 2], [0.5, 1, 2]],
                                                dtype=torch.float64))) == pytest.approx(2.0)


def _sample():
    m = sample_motions()[0].to(torch.float64)
    return m, load_spec("sample").bind(m.skeleton)


def test_the_body_of_smpl22_has_the_stated_sizes():
    sk = smpl22_skeleton()
    body = body_of(sk, load_spec("smpl22").bind(sk))
    legs = (0.3936 + 0.4324 + 0.3902 + 0.4256) / 2  # hip to knee to ankle, both legs (smpl.py's bone table)
    spine = 0.1316 + 0.1432 + 0.0574 + 0.2194 + 0.1030  # pelvis, spine1, spine2, spine3, neck, head
    assert body.height == pytest.approx(legs + spine)
    sizes = body.sizes()
    for name, (*_, share) in CAPSULES.items():
        assert sizes[name] == pytest.approx(share * body.height)
    assert sizes["torso_l"] == pytest.approx(0.100, abs=1e-3) and sizes["forearm_r"] == pytest.approx(0.037, abs=1e-3)
    assert body.margin == pytest.approx(INSIDE_MARGIN * body.height)


def test_a_hand_put_inside_the_chest_is_inside_there_only_and_as_deep_as_the_torso():
    m, roles = _sample()
    body = body_of(m.skeleton, roles)
    clean = m.global_positions()
    T = clean.shape[0]
    share, depth = penetration(clean[None], torch.tensor([T]), body)
    assert float(share) == 0.0 and float(depth) == 0.0  # the clean clip
    j = canonical_joints(roles, m.skeleton)
    a, b = capsule_ends(clean, body)
    torso = list(CAPSULES).index("torso_r")
    mid = (a[:, torso] + b[:, torso]) / 2  # the torso's axis, halfway up
    forward = torch.zeros(T, 3, dtype=torch.float64)
    forward[:, 2] = 1.0  # any direction across the axis: the hand lies on it
    bad = clean.clone()
    frames = torch.arange(40, 52)
    bad[frames, j["wrist_r"]] = mid[frames]
    bad[frames, j["elbow_r"]] = mid[frames] + 0.3 * body.height * forward[frames]
    share, depth = penetration(bad[None], torch.tensor([T]), body)
    assert float(share) == pytest.approx(len(frames) / T)
    assert float(depth) == pytest.approx(float(body.radii[torso]), rel=1e-9)  # the axis crosses the torso's axis
    inside = inside_depth(bad, body).flatten(1).amax(1) > body.margin
    assert inside.nonzero().flatten().tolist() == frames.tolist()
    # packed along frames, with the clean clip beside it: the same figures
    share2, depth2 = penetration_packed(torch.cat([clean, bad]), [T, T], body)
    assert share2.tolist() == [0.0, pytest.approx(len(frames) / T)] and float(depth2[1]) == pytest.approx(float(depth))


@pytest.mark.realdata
def test_the_body_is_built_on_every_shipped_rig_and_clean_captures_seldom_touch_it(tmp_path):
    from torchsplice.formats.importer import import_bvh

    _require_mocap()
    db = tmp_path / "rigs.h5"
    import_bvh([MOCAP / "cmu_graphics_lab", MOCAP / "lafan1_via_pypi_bvhtools",
                MOCAP / "bandai_namco_research_motiondataset" / "dataset-1_walk_normal_001.bvh",
                MOCAP / "bandai_namco_research_motiondataset" / "dataset-1_run_normal_001.bvh"], db)
    m, roles = _sample()
    rigs = {"sample": (m.skeleton, roles), "smpl22": (smpl22_skeleton(), load_spec("smpl22").bind(smpl22_skeleton()))}
    shares = []
    with MotionDatabase.open(db) as d:
        for k, sk in enumerate(d.skeletons):
            rigs[f"{d.skeleton_info(k).spec_name}:{k}"] = (sk, d.spec(k).bind(sk))
        for name in d.names:
            c = d.read(name, dtype=torch.float64)
            k = d.clip_info(name)["skeleton"]
            share, _ = penetration(c.global_positions()[None], torch.tensor([c.num_frames]),
                                   body_of(*rigs[f"{d.skeleton_info(k).spec_name}:{k}"]))
            shares.append(float(share))
    assert {"cmu", "cmu_max", "lafan1", "bandai_namco"} <= {k.split(":")[0] for k in rigs}, rigs.keys()
    for name, (sk, r) in rigs.items():
        body = body_of(sk, r)
        assert body.height > 0 and bool((body.radii > 0).all()), name
    # CMU's 131_* hold hands against the body (a real contact); walks and runs do not
    assert sum(s > 0.05 for s in shares) <= 2, shares


def _feet(T: int, fps: float, speed: float, height: float = 0.0) -> torch.Tensor:
    """A two-joint 'body': a foot sliding along X at ``speed`` m/s, ``height`` m up, and the other
    foot standing still on the floor (y = 0, the clip's lowest point); ``(1, T, 2, 3)``."""
    p = torch.zeros(1, T, 2, 3, dtype=torch.float64)
    p[0, :, 0, 0] = torch.arange(T, dtype=torch.float64) * speed / fps
    p[0, :, 0, 1] = height
    return p


@pytest.mark.parametrize("fps", [20.0, 30.0, 60.0])
def test_gmds_skate_ratio_of_a_foot_sliding_at_known_speeds(fps):
    T = int(3 * fps) + 1  # 3 s: 60 steps at 20 fps
    ratio = lambda p: float(skate_ratio(p, torch.tensor([T]), torch.tensor([fps]), [0, 1], 1, 1.0))  # noqa: E731
    assert ratio(_feet(T, fps, 1.0)) == 1.0  # every step: averaged over 5 steps even at the ends (0.6 m/s there)
    assert ratio(_feet(T, fps, 0.4)) == 0.0  # below 0.5 m/s
    steps = int(3 * GMD_FPS)
    assert ratio(_feet(T, fps, 0.7)) == pytest.approx((steps - 2) / steps)  # the first and last steps average 0.42 m/s
    assert ratio(_feet(T, fps, 1.0, height=0.06)) == 0.0  # 6 cm up: not in contact
    cm = _feet(T, fps, 1.0) * 100  # in centimetres: the same answer
    assert float(skate_ratio(cm, torch.tensor([T]), torch.tensor([fps]), [0, 1], 1, 100.0)) == 1.0


@pytest.mark.parametrize("fps", [20.0, 30.0, 60.0])
def test_foot_slide_and_floor_of_feet_at_known_speeds_and_heights(fps):
    from torchsplice.ops.plausibility import floor_height, foot_slide

    T = int(3 * fps) + 1
    lengths, rate = torch.tensor([T]), torch.tensor([fps])
    # one foot slides at 1 m/s, the other stands: both in contact on every step, a mean of 0.5 m/s
    assert float(foot_slide(_feet(T, fps, 1.0), lengths, rate, [0, 1], 1, 1.0)) == pytest.approx(0.5)
    assert float(foot_slide(_feet(T, fps, 1.0, height=0.06), lengths, rate, [0, 1], 1, 1.0)) == 0.0  # 6 cm up: not in contact
    assert float(foot_slide(_feet(T, fps, 1.0) * 100, lengths, rate, [0, 1], 1, 100.0)) == pytest.approx(50.0)  # cm/s
    lowered = _feet(T, fps, 0.0)
    lowered[..., 1] -= 0.03  # the whole clip 3 cm under the ground
    assert float(floor_height(lowered, lengths, [0, 1], 1)) == pytest.approx(-0.03)
    assert float(floor_height(_feet(T, fps, 0.0, height=0.06), lengths, [0], 1)) == pytest.approx(0.06)


def test_a_seam_of_known_size_shows_in_the_jerk():
    T, fps, s = 60, 30.0, 0.05
    pos = torch.zeros(1, T, 3, 3, dtype=torch.float64)  # a chest (joint 0) and two hands, standing still
    pos[0, :, 1] = torch.tensor([0.3, 0.0, 0.0], dtype=torch.float64)
    pos[0, :, 2] = torch.tensor([-0.3, 0.0, 0.0], dtype=torch.float64)
    rot = torch.zeros(1, T, 4, dtype=torch.float64)
    rot[..., 0] = 1.0
    lengths = torch.tensor([T])
    assert float(jerk(pos, rot, lengths, torch.tensor([fps]), [1, 2], 0)) < 1e-6  # still: rounding only
    pos[0, 30:, 1, 1] += s  # one hand jumps by s at frame 30 (a seam), the other does not
    got = float(jerk(pos, rot, lengths, torch.tensor([fps]), [1, 2], 0))
    # the third differences across a step of s are s, -2s and s: the largest 2s, halved by the still hand
    assert got == pytest.approx(2 * s * fps ** 3 / 2)
    # turning the whole body (chest included) changes nothing: the hands are read in the chest's frame
    turn = torch.tensor([np.cos(0.4), 0.0, np.sin(0.4), 0.0], dtype=torch.float64)
    from torchsplice.core.rotations import quat_apply

    turned = quat_apply(turn.expand(1, T, 3, 4), pos)
    assert float(jerk(turned, turn.expand(1, T, 4).clone(), lengths, torch.tensor([fps]), [1, 2], 0)) == pytest.approx(got)


@pytest.mark.realdata
def test_every_results_columns_are_its_frames_figures_and_its_sources(runs_with_raised_hands):
    db, out, _ = runs_with_raised_hands  # as spliced: the flags have hands inside to find
    with MotionDatabase.open(out) as o, MotionDatabase.open(db) as src:
        t = o.clip_table()
        names = list(t.name)
        k = int(t.skeleton[0])
        sk = o.skeletons[k]
        body = body_of(sk, o.spec(k).bind(sk))
        clips = [o.read(n, dtype=torch.float64) for n in names]
        positions = torch.cat([c.global_positions() for c in clips])
        share, depth = penetration_packed(positions, [c.num_frames for c in clips], body)
        e = t.extra
        assert np.allclose(np.asarray(e["penetration"]), share.numpy(), atol=1.5 / 70)  # float32 frames: a frame at most
        inside = np.asarray(e["penetration"]) > 0
        assert inside.any() and np.allclose(np.asarray(e["penetration_depth"])[inside], depth.numpy()[inside], atol=0.05)
        of = {}
        for name in src.names:
            c = src.read(name, dtype=torch.float64)
            s, d = penetration(c.global_positions()[None], torch.tensor([c.num_frames]), body)
            of[name] = (float(s), float(d))
        loco = np.array([of[n][0] for n in t.extra["locomotion"]])
        act = np.array([of[n][0] for n in t.extra["action"]])
        assert np.allclose(np.asarray(e["penetration_locomotion"]), loco) and np.allclose(np.asarray(e["penetration_action"]), act)
        flagged = np.array(["self_penetration" in f for f in e["flags"]])
        expect = np.asarray(e["penetration"]) > np.maximum(loco, act) + 0.05
        assert flagged.any() and (flagged == expect).all()
        for f, words in zip(e["flags"], e["flag_details"]):
            assert ("self_penetration" in f) == ("a hand inside the body on" in words)


@pytest.mark.realdata
def test_the_compiled_body_test_gives_the_torch_figures(runs_with_raised_hands):
    """The compiled splicer's kernel (:mod:`torchsplice.cpu.body`) against the backends' torch
    default, on every result of the real job (some of them with a hand inside the body)."""
    from torchsplice.splice.backends import Backend
    from torchsplice.splice.backends.compiled import CompiledBackend

    _, out, _ = runs_with_raised_hands
    with MotionDatabase.open(out) as o:
        clips = [o.read(n) for n in o.names]
        sk = o.skeletons[0]
        body = body_of(sk, o.spec(0).bind(sk))
    rot = torch.cat([c.rotations for c in clips]).numpy()
    trans = torch.cat([c.local_translations() for c in clips]).numpy()
    lengths = [c.num_frames for c in clips]
    want = Backend.inside_body(CompiledBackend(), rot, trans, lengths, sk, body, per_frame=True)  # the torch default
    got = CompiledBackend().inside_body(rot, trans, lengths, sk, body, per_frame=True)
    assert (want[0] > 0).sum() >= 10
    assert np.array_equal(got[0], want[0]) and np.allclose(got[1], want[1], atol=1e-9)
    # each frame's deepest: the same where it counts (deeper than the margin), at most the margin elsewhere
    counts = want[2] > body.margin
    assert np.array_equal(got[2] > body.margin, counts) and counts.sum() >= 10
    assert np.allclose(got[2][counts], want[2][counts], atol=1e-9) and (got[2][~counts] <= body.margin).all()
    # ... from which the figures of any frames' clips follow, bit for bit: here every clip's again
    share, depth = penetration_of_frames(torch.from_numpy(got[2]), lengths, body.margin)
    assert np.array_equal(share.numpy(), got[0]) and np.array_equal(depth.numpy(), got[1])


@pytest.mark.realdata
def test_evaluate_reports_the_figures_per_method_against_the_sources(runs_with_raised_hands, tmp_path):
    from torchsplice.evaluation.report import evaluate_database

    _, out, _ = runs_with_raised_hands
    report = tmp_path / "report.md"
    evaluate_database(out, report, pictures=False)
    text = report.read_text()
    with MotionDatabase.open(out) as o:
        e = o.clip_table().extra
        share = np.asarray(e["penetration"])
        beyond = share - np.maximum(np.asarray(e["penetration_locomotion"]), np.asarray(e["penetration_action"]))
    section = text.split("## Plausibility: a hand inside the body")[1]
    row = next(ln for ln in section.splitlines() if ln.startswith("| splice |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[1] == str(len(share))
    assert cells[2] == f"{100 * (share > 0).mean():.1f}%" and cells[3] == f"{100 * (beyond > 0.05).mean():.1f}%"
    worst = np.argmax(beyond)
    with MotionDatabase.open(out) as o:
        assert "Most beyond their sources" in text and o.names[worst] in text.split("Most beyond their sources")[1]


@pytest.mark.realdata
def test_the_figures_columns_are_the_frames_figures_and_the_compiled_ones_the_torch_ones(runs_with_raised_hands):
    """``foot_skate``, ``foot_slide``, ``floor`` and ``jerk`` of every result are those of its
    stored frames (:func:`~torchsplice.ops.plausibility.clip_figures`, torch), ``jerk_action``
    the action's own; the compiled kernel (:mod:`torchsplice.cpu.figures`) gives the torch
    figures."""
    from torchsplice.ops.plausibility import clip_figures, figure_joints
    from torchsplice.splice.backends import Backend
    from torchsplice.splice.backends.compiled import CompiledBackend

    db, _, out = runs_with_raised_hands
    with MotionDatabase.open(out) as o, MotionDatabase.open(db) as src:
        t = o.clip_table()
        sk = o.skeletons[0]
        joints = figure_joints(sk, o.spec(0).bind(sk))
        clips = [o.read(n, dtype=torch.float64) for n in t.name]
        actions = {n: src.read(n, dtype=torch.float64) for n in set(t.extra["action"])}
    e = t.extra
    rot = torch.cat([c.rotations for c in clips]).numpy()
    trans = torch.cat([c.local_translations() for c in clips]).numpy()
    lengths = [c.num_frames for c in clips]
    got = CompiledBackend().figures(rot, trans, lengths, clips[0].fps, sk, joints, 1, 100.0)  # Bandai Namco: cm, Y up
    want = Backend.figures(CompiledBackend(), rot, trans, lengths, clips[0].fps, sk, joints, 1, 100.0)
    for k in ("foot_skate", "foot_slide", "floor", "jerk"):
        assert np.allclose(got[k], want[k], rtol=1e-9, atol=1e-9), k
        assert np.allclose(np.asarray(e[k]), want[k], rtol=1e-4, atol=1e-3), k  # the job's frames, float32
    assert (np.asarray(e["foot_skate"]) > 0).any() and (np.asarray(e["jerk"]) > 0).all()
    a = actions[str(e["action"][0])]
    t0 = a.local_translations()
    from torchsplice.core.fk import forward_kinematics

    pos, grot = forward_kinematics(a.rotations, t0[:, 0], sk.offsets.double(), sk.parents, t0)
    own = clip_figures(pos[None], grot[None], torch.tensor([a.num_frames]), a.fps, joints, 1, 100.0)["jerk"]
    assert float(e["jerk_action"][0]) == pytest.approx(float(own), rel=1e-3)


@pytest.mark.realdata
def test_evaluate_draws_the_results_most_beyond_their_sources_across_the_contact(runs_with_raised_hands, tmp_path):
    from torchsplice.evaluation.plausibility import PICTURED
    from torchsplice.evaluation.report import evaluate_database

    _, raw, _ = runs_with_raised_hands  # as spliced: hands inside to draw
    report = tmp_path / "report.md"
    evaluate_database(raw, report, pictures=True, examples=0)
    text = report.read_text()
    with MotionDatabase.open(raw) as o:
        e = o.clip_table().extra
        beyond = np.asarray(e["penetration"]) - np.maximum(np.asarray(e["penetration_locomotion"]),
                                                           np.asarray(e["penetration_action"]))
        worst = [o.names[i] for i in np.argsort(-beyond)[:PICTURED]]
    drawn = [ln for ln in text.split("## Pictures")[1].splitlines() if "_inside.png" in ln]
    assert len(drawn) == PICTURED
    for name, line in zip(worst, drawn):
        assert name in line and "deepest at" in line
        assert (tmp_path / line.split("(<")[1].split(">)")[0]).stat().st_size > 10_000  # a real picture


def _gmd_by_hand(joints: np.ndarray) -> float:
    """GMD's skate ratio of one HumanML3D ``new_joints`` motion ``(T, 22, 3)`` (20 fps, metres,
    Y up, the floor at 0), step by step as its definition reads: SMPL's feet (joints 10 and 11),
    horizontal speed per step, its mean over the 5 steps centred on it (zeros beyond the clip),
    contact below 5 cm in both frames, skating when in contact and both speeds exceed 0.5 m/s;
    the share of steps in which either foot skates."""
    T = joints.shape[0]
    steps = T - 1
    skating = 0
    for k in range(steps):
        hit = False
        for f in (10, 11):
            def speed(i):
                return float(np.hypot(*(joints[i + 1, f, [0, 2]] - joints[i, f, [0, 2]]))) * 20.0 if 0 <= i < steps else 0.0
            mean = sum(speed(i) for i in range(k - 2, k + 3)) / 5.0
            touch = joints[k, f, 1] < 0.05 and joints[k + 1, f, 1] < 0.05
            hit |= bool(touch and speed(k) > 0.5 and mean > 0.5)
        skating += hit
    return skating / steps


@pytest.mark.realdata
def test_gmds_skate_ratio_on_humanml3d_motions_is_its_definition_worked_step_by_step(tmp_path):
    """On HumanML3D motions (real Bandai Namco runs and walks exported as HumanML3D: SMPL's 22
    joints at 20 fps, the floor at 0, as HumanML3D's own sample is), :func:`skate_ratio` is GMD's
    definition worked by hand, on every motion whose feet are its lowest joints (where the
    clip's lowest foot point, this measure's floor, is HumanML3D's). Checked in development on
    the format's own sample too (``HumanML3D/new_joints/012314.npy`` of EricGuo5513/HumanML3D,
    not in ../shared): 23 of its 169 steps skate, 0.136, by both."""
    from torchsplice.formats.exporters import export_clips
    from torchsplice.formats.importer import import_bvh

    _require_mocap()
    folder = MOCAP / "bandai_namco_research_motiondataset"
    files = sorted(folder.glob("dataset-1_run_*.bvh"))[:4] + sorted(folder.glob("dataset-1_walk_*.bvh"))[:4]
    db = tmp_path / "bn.h5"
    import_bvh(files, db, spec="bandai_namco")
    out = tmp_path / "h3"
    export_clips(db, out=out, format="humanml3d")
    compared = 0
    for f in sorted((out / "new_joints").glob("*.npy")):
        j = np.load(f).astype(np.float64)
        if abs(j[:, [10, 11], 1].min() - j[..., 1].min()) > 1e-9:
            continue  # another joint is lower: HumanML3D's floor is not the feet's
        got = float(skate_ratio(torch.from_numpy(j)[None], torch.tensor([len(j)]), torch.tensor([20.0]), [10, 11], 1, 1.0))
        assert got == pytest.approx(_gmd_by_hand(j), abs=1e-12), f.name
        compared += 1
    assert compared >= 6
