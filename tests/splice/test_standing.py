"""Standing actions onto locomotion, on real Bandai Namco clips.

A standing wave spliced onto a walk and a turn: the result is as long as the locomotion, the
waving wrist keeps its motion relative to the chest, the idle wrist swings with the walk in
phase with the opposite leg, loop seams are as smooth as the capture, and the lower body and
root are the locomotion's. Also: the timing functions, the acting-limb detection, the
baselines on standing actions, and the default n x m job skipping no standing action.
"""

from __future__ import annotations

import re

import pytest
import torch

from realdata import copy_bandai
from torchsplice import import_bvh, splice_all
from torchsplice.evaluation.report import evaluate_database
from torchsplice.core.rotations import quat_angle, quat_apply, quat_conj
from torchsplice.core.fk import forward_kinematics
from torchsplice.splice import SpliceOptions, splice, splice_standing
from torchsplice.splice.standing import (ACTING_THRESHOLD, LOOP_BLEND_SECONDS, action_times, arm_chains,
                                         parse_limbs)

WAVE_R = "dataset-2_wave-right-hand_normal_001"
WAVE_L = "dataset-2_wave-left-hand_normal_001"
RAISE_BOTH = "dataset-2_raise-up-both-hands_normal_001"
RAISE_LEFT = "dataset-2_raise-up-left-hand_normal_001"
WALK = "dataset-1_walk_normal_001"
WALK_OLD = "dataset-1_walk_old_001"
TURN = "dataset-2_walk-turn-left_normal_025"


def fk(m):
    sk = m.skeleton
    return forward_kinematics(m.rotations, m.root_translation, sk.offsets.to(m.rotations), sk.parents, m.translations)[:2]


def in_chest(m, roles, joint: int, chest: int) -> torch.Tensor:
    """``(T, 3)`` position of ``joint`` in the chest's frame."""
    pos, grot = fk(m)
    return quat_apply(quat_conj(grot[:, chest]), pos[:, joint] - pos[:, chest])


def extent(x: torch.Tensor) -> float:
    """Size of a path: the diagonal of its bounding box."""
    return float((x.max(0).values - x.min(0).values).norm())


def forward_swing(m, roles, joint: int) -> torch.Tensor:
    """``(T,)`` the joint's position relative to the pelvis along the walking direction of each
    frame (the root's horizontal velocity over half a second, so that turns count too)."""
    pos, _ = fk(m)
    root = pos[:, roles.root].clone()
    root[:, roles.up_axis] = 0
    k = int(m.fps // 4)
    ahead = torch.cat([root[k:], root[-1:].expand(k, 3)]) - torch.cat([root[:1].expand(k, 3), root[:-k]])
    d = ahead / ahead.norm(dim=-1, keepdim=True).clamp(min=1e-9)
    return ((pos[:, joint] - pos[:, roles.pelvis]) * d).sum(-1)


def phase(m, roles, hand: int, foot: int) -> float:
    """Correlation of a wrist's forward swing with a foot's (1: in phase)."""
    a, b = forward_swing(m, roles, hand), forward_swing(m, roles, foot)
    return float(torch.corrcoef(torch.stack([a - a.mean(), b - b.mean()]))[0, 1])


@pytest.mark.parametrize("loco_name", [WALK, TURN])
def test_a_standing_wave_on_a_walk_and_a_turn(bandai_f64, loco_name):
    read, spec = bandai_f64
    loco, wave = read(loco_name), read(WAVE_R)
    roles = spec.bind(loco.skeleton)
    r = splice(loco, wave, spec, options=SpliceOptions(dtype=torch.float64))
    m = r.motion
    assert r.timing == "loop" and r.acting == ("right_arm",)
    assert m.num_frames == loco.num_frames  # as long as the locomotion
    lower = list(roles.lower_body)
    assert torch.equal(m.rotations[:, lower], loco.rotations[:, lower])
    assert torch.equal(m.root_translation, loco.root_translation)
    assert torch.equal(m.local_translations(), loco.local_translations())
    chest = arm_chains(roles, loco.skeleton)["right_arm"][0]
    # the waving wrist moves relative to the chest as in the action (within 20%)
    w_out, w_act = extent(in_chest(m, roles, roles.hands[1], chest)), extent(in_chest(wave, roles, roles.hands[1], chest))
    assert abs(w_out - w_act) <= 0.2 * w_act, (w_out, w_act)
    # the idle (left) wrist swings with at least half the locomotion's own amplitude ...
    i_out, i_loco = extent(in_chest(m, roles, roles.hands[0], chest)), extent(in_chest(loco, roles, roles.hands[0], chest))
    assert i_out >= 0.5 * i_loco, (i_out, i_loco)
    # ... in phase with the opposite (right) leg
    own = phase(loco, roles, roles.hands[0], roles.feet[1])
    assert own > 0.5  # the captured walk swings its left arm with its right leg ...
    assert phase(m, roles, roles.hands[0], roles.feet[1]) > 0.5  # ... and so does the result


@pytest.mark.parametrize("action", [WAVE_L, RAISE_LEFT])
def test_loop_seams_are_continuous(bandai_f64, action):
    read, spec = bandai_f64
    loco, wave = read(WALK_OLD), read(action)
    assert loco.num_frames > wave.num_frames  # one seam at least
    roles = spec.bind(loco.skeleton)
    r = splice(loco, wave, spec, options=SpliceOptions(dtype=torch.float64))
    m = r.motion
    chest = arm_chains(roles, loco.skeleton)["left_arm"][0]

    def jumps(x: torch.Tensor) -> torch.Tensor:  # |v(t) - v(t-1)| of a (T, 3) path, per frame t
        v = x[1:] - x[:-1]
        return (v[1:] - v[:-1]).norm(dim=-1)

    captured = jumps(in_chest(wave, roles, roles.hands[0], chest))
    out = jumps(in_chest(m, roles, roles.hands[0], chest))
    curve = r.curve
    seams = [t for t in range(1, len(curve)) if curve[t] < curve[t - 1]]  # where the action jumps back
    assert seams and all(t - 2 >= 0 for t in seams)
    worst = max(float(out[t - 2:t + 1].max()) for t in seams)  # the jumps of the frames around each seam
    # the loop holds the whole gesture, so its seam joins the end of the lowering to the clip's first
    # frame; both takes start already raising the arm (the wave at 1.9 cm a frame), so the seam carries
    # the capture's own start-up acceleration: within 1.25 times the capture's largest jump for the
    # wave, twice for the short raise-hand gesture, which also ends moving the other way
    bound = (1.25 if action == WAVE_L else 2.0) * float(captured.max())
    assert worst <= bound, (worst, bound)
    # the pose is continuous at every seam: no frame-to-frame step larger than the capture's largest
    steps = (in_chest(m, roles, roles.hands[0], chest).diff(dim=0)).norm(dim=-1)
    cap_steps = (in_chest(wave, roles, roles.hands[0], chest).diff(dim=0)).norm(dim=-1)
    assert max(float(steps[t - 1]) for t in seams) <= float(cap_steps.max())


def test_timings_fill_the_locomotion():
    loco, act = torch.tensor([100, 30]), torch.tensor([40, 60])
    t, frm, w = action_times(loco, act, "hold", 30.0)
    assert t.shape == (2, 100) and float(t[0, 99]) == 39 and float(t[0, 10]) == 10 and torch.all(w == 1)
    t, frm, w = action_times(loco, act, "fit", 30.0)
    assert float(t[0, 0]) == 0 and abs(float(t[0, 99]) - 39) < 1e-9 and abs(float(t[1, 29]) - 59) < 1e-9
    t, frm, ph = action_times(loco, act, "loop", 30.0, loop=(torch.tensor([5, 0]), torch.tensor([35, 50])))
    blend = min(round(LOOP_BLEND_SECONDS * 30), 40 // 3)
    assert torch.equal(t[0, :35], torch.arange(35, dtype=torch.float64))  # the first pass up to the loop's end
    assert float(t[0, 35]) == 5 and float(frm[0, 35]) == 35 and float(ph[0, 35]) == 0  # back to its start
    assert float(t[0, 35 + 30]) == 5  # period 30 frames
    assert 0 < float(ph[0, 35 + blend - 1]) < 1 and float(ph[0, 35 + blend]) == 1
    assert torch.all(ph[0, :35] == 1) and torch.all(t[0] < 40)
    with pytest.raises(ValueError, match="timing"):
        action_times(loco, act, "bounce", 30.0)


def test_acting_limbs_are_found_from_the_data(bandai_f64):
    read, spec = bandai_f64
    found = {}
    for name in (WAVE_R, WAVE_L, RAISE_BOTH):
        r = splice(read(WALK), read(name), spec)
        found[name] = r.acting
    assert found == {WAVE_R: ("right_arm",), WAVE_L: ("left_arm",), RAISE_BOTH: ("left_arm", "right_arm")}
    assert 0 < ACTING_THRESHOLD < 1
    forced = splice(read(WALK), read(WAVE_R), spec, options=SpliceOptions(acting_limbs=("left_arm", "right_arm")))
    assert forced.acting == ("left_arm", "right_arm")
    assert parse_limbs("auto") is None and parse_limbs("none") == () and parse_limbs("both") == ("left_arm", "right_arm")
    with pytest.raises(ValueError, match="unknown limb"):
        parse_limbs("tail")


@pytest.mark.parametrize("method", ["naive", "cpmc"])
def test_the_baselines_handle_standing_actions(bandai_f64, method):
    read, spec = bandai_f64
    loco, wave = read(WALK), read(WAVE_R)
    roles = spec.bind(loco.skeleton)
    r = splice(loco, wave, spec, method=method, options=SpliceOptions(dtype=torch.float64))
    assert r.timing == "loop" and r.motion.num_frames == loco.num_frames and r.reference is None
    lower = list(roles.lower_body)
    assert torch.equal(r.motion.rotations[:, lower], loco.rotations[:, lower])
    upper = list(roles.upper_body)
    if method == "naive":  # the action's upper body as it is, frame by frame for the first pass
        n = next(t for t in range(1, len(r.curve)) if r.curve[t] < r.curve[t - 1])
        assert n > wave.num_frames * 2 // 3
        assert torch.allclose(r.motion.rotations[:n, upper], wave.rotations[:n, upper], atol=1e-12)
    else:  # the walk plus the action's motion since its first frame: frame 0 is the walk's
        assert torch.allclose(r.motion.rotations[0, upper].abs(), loco.rotations[0, upper].abs(), atol=1e-9)


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=pytest.mark.gpu)])
def test_standing_actions_on_a_device_equal_the_compiled_splicer(bandai_f64, device):
    """Standing actions spliced by the torch splicer on ``device`` (CUDA, or the CPU) against the
    compiled splicer on the CPU, every method and timing: the same lengths, acting arms and
    action frames (within 1e-9 frames), the lower body and root the locomotion's bit for bit,
    rotations within 1e-3 degrees."""
    read, spec = bandai_f64
    pairs = [(read(WALK), read(WAVE_R)), (read(TURN), read(RAISE_BOTH)), (read(WALK_OLD), read(RAISE_LEFT))]
    lower = list(spec.bind(read(WALK).skeleton).lower_body)
    for method in ("splice", "naive", "cpmc"):
        for timing in ("loop", "hold", "fit"):
            want = splice_standing(pairs, spec, method, SpliceOptions(timing=timing))
            got = splice_standing(pairs, spec, method, SpliceOptions(timing=timing, device=device, backend="torch"))
            for (loco, _), g, w in zip(pairs, got, want):
                where = (method, timing, g.action)
                assert g.motion.rotations.device.type == device, where
                assert g.timing == w.timing == timing and g.acting == w.acting, where
                assert g.motion.num_frames == w.motion.num_frames == loco.num_frames, where
                assert float((g.curve.cpu() - w.curve).abs().max()) <= 1e-9, where
                rot = g.motion.rotations.cpu().double()
                assert torch.equal(rot[:, lower], loco.rotations[:, lower].float().double()), where
                assert torch.equal(g.motion.root_translation.cpu(), loco.root_translation.float()), where
                angle = torch.rad2deg(quat_angle(rot, w.motion.rotations.double()))
                assert float(angle.max()) < 1e-3, where

@pytest.mark.slow
def test_the_default_job_on_bandai_skips_no_standing_action(bandai_namco_db, tmp_path):
    db = bandai_namco_db  # ../shared/mocap's Bandai Namco clips as `torchsplice import FOLDER` makes them
    summary = splice_all(db, tmp_path / "out.h5", locomotions="role:locomotion", actions="role:action",
                         methods="splice,naive,cpmc")
    text = "\n".join(summary.lines())
    from torchsplice.store.database import MotionDatabase

    with MotionDatabase.open(db) as src:
        t = src.table()
        actions = {str(n) for n, r in zip(t["name"], t["role"]) if r == "action"}
    not_locomoting = {m.group(1) for why in summary.skipped for m in [re.match(r"(\S+) does not locomote", why)] if m}
    assert not_locomoting and not (not_locomoting & actions), summary.skipped  # only short locomotions are skipped so
    assert not_locomoting == set(re.findall(r"x (\S+) does not locomote", text)), text
    m = re.search(r"(\d+) time-aligned \(timewarp\), (\d+) standing actions \(loop\)", text)
    assert m and int(m.group(2)) == summary.timings["loop"] > 0, text
    with MotionDatabase.open(tmp_path / "out.h5") as out:
        t = out.table()
        actions = {str(a) for a in t["action"]}
        waves = [a for a in actions if "wave" in a or "raise" in a or "bow" in a]
        assert len(waves) >= 7  # every standing wave, raise-hand and bow of the folder is spliced
        standing = t["timing"] == "loop"
        assert (t["coverage"][standing] == 1.0).all()


@pytest.mark.slow
def test_evaluate_reports_standing_actions_with_two_filmstrips(mocap_dir, tmp_path):
    folder = copy_bandai((WALK, WALK_OLD, TURN, WAVE_L, WAVE_R, RAISE_LEFT), tmp_path / "bvh")
    db, out, report = tmp_path / "b.h5", tmp_path / "o.h5", tmp_path / "r.md"
    assert import_bvh([folder], db).ok
    splice_all(db, out, locomotions="role:locomotion,role:both", actions="role:action", methods="splice,naive,cpmc",
               workers=1)
    evaluate_database(out, report)
    text = report.read_text()
    start = text.index("## Standing actions")
    section = text[start:text.index("\n## ", start)]  # up to the next section
    rows = {ln.split("|")[1].strip(): [x.strip() for x in ln.split("|")[2:-1]]
            for ln in section.splitlines() if ln.startswith("| ") and not ln.startswith("| method")}
    assert set(rows) == {"splice", "naive", "cpmc"} and all(r[0] == "9" for r in rows.values())
    # the action shows: the acting wrist's range against the whole action's and against its best window
    assert float(rows["splice"][1]) >= 0.8 and float(rows["splice"][3]) >= 0.9 and float(rows["splice"][4]) >= 0.8
    assert "Worst pairs (action kept against the best window):" in section
    error = {m: float(r[5]) for m, r in rows.items()}
    assert error["splice"] < 1.0 < error["cpmc"]  # the acting wrist moves as in the frames played (cm)
    assert float(rows["splice"][8]) <= 1.5  # the worst seam: about as smooth as the capture
    in_range = {m: int(r[6].split("%")[0]) for m, r in rows.items()}
    assert in_range["splice"] > in_range["naive"]  # the idle arm swings with the walk, not held still
    assert len(re.findall(r"^\*\*\S+ \(standing action, loop;", text, re.M)) == 2
    assert len(list((tmp_path / "r_files").glob("*_filmstrip.png"))) >= 2
