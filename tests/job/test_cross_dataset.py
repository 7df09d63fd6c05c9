"""Splicing across datasets: the actions of one dataset on the locomotions of another, through
``splice-all`` with every method that has what it needs (cpmc a reference) (the pairs formed by retargeting the action onto
the locomotion's skeleton).

Known answers for the measure first (:func:`~torchsplice.evaluation.retargeting.wrist_spread`
does not change when the whole clip turns or the rig grows), then the real pairs of the issue:
a Bandai Namco wave onto a CMU walk and onto a LAFAN1 locomotion, and a LAFAN1 action onto a
Bandai Namco turn. The acting wrist's range of motion in the chest frame, over arm length, stays
within 20% of the action's over the frames the result plays; the feet are the locomotion's
(foot skate equal to it).
"""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from realdata import BANDAI, MOCAP, _require_mocap
from torchsplice.core.rotations import axis_angle_to_quat, quat_mul
from torchsplice.evaluation.metrics import foot_skate_stats
from torchsplice.evaluation.retargeting import centimetres, wrist_spread
from torchsplice.formats.importer import import_bvh
from torchsplice.job import splice_all
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.store.database import MotionDatabase

WAVE = "dataset-2_wave-right-hand_normal_001"


def test_the_wrist_spread_does_not_change_when_the_clip_turns_or_the_rig_grows():
    m = next(x for x in sample_motions() if x.name == "wave").to(torch.float64)
    roles = load_spec("sample").bind(m.skeleton)
    base = [wrist_spread(m, roles, s) for s in (0, 1)]
    turn = axis_angle_to_quat(torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64) * 1.1)
    turned = replace(m, rotations=m.rotations.clone(), root_translation=m.root_translation @ torch.tensor(
        [[0.4536, 0, -0.8912], [0, 1, 0], [0.8912, 0, 0.4536]], dtype=torch.float64))
    turned.rotations[:, 0] = quat_mul(turn.expand(m.num_frames, 4), m.rotations[:, 0])
    big = replace(m, skeleton=replace(m.skeleton, offsets=m.skeleton.offsets * 2.5), root_translation=m.root_translation * 2.5)
    for s in (0, 1):
        assert wrist_spread(turned, roles, s) == pytest.approx(base[s], rel=1e-6)  # the sample is float32
        assert wrist_spread(big, roles, s) == pytest.approx(base[s], rel=1e-6)  # the sample is float32
    assert max(base) > 2 * min(base)  # one hand waves


@pytest.fixture(scope="module")
def dbs(tmp_path_factory):
    _require_mocap()  # skips without the data, fails under CI
    root = tmp_path_factory.mktemp("cross")
    bn, cmu, lafan = root / "bn.h5", root / "cmu.h5", root / "lafan.h5"
    import_bvh([MOCAP / BANDAI / f"dataset-2_{n}.bvh" for n in ("wave-right-hand_normal_001", "walk_normal_008",
                                                                 "walk-turn-left_normal_025")], bn)
    import_bvh([MOCAP / "cmu_graphics_lab" / "cmu_12_01_walk.bvh"], cmu)
    import_bvh([MOCAP / "lafan1_via_pypi_bvhtools"], lafan)
    return {"bn": bn, "cmu": cmu, "lafan": lafan, "root": root}


CASES = [("cmu", "cmu_12_01_walk", "bn", WAVE, "splice,naive,cpmc"),
         ("lafan", "test2", "bn", WAVE, "splice,naive,cpmc"),
         ("bn", "dataset-2_walk-turn-left_normal_025", "lafan", "test", "splice,naive")]


@pytest.mark.parametrize("loco_db,loco,action_db,action,methods", CASES, ids=["wave-on-cmu", "wave-on-lafan1",
                                                                                "lafan1-on-turn"])
def test_an_action_of_one_dataset_on_a_locomotion_of_another(dbs, loco_db, loco, action_db, action, methods):
    out = dbs["root"] / f"{loco}+{action}.h5"
    summary = splice_all(dbs[loco_db], out, actions_db=dbs[action_db], locomotions=loco, actions=action,
                         methods=methods, workers=1)
    assert summary.spliced == len(methods.split(",")) and summary.retargeted == summary.spliced
    with MotionDatabase.open(dbs[loco_db]) as d:
        lm = d.read(loco, dtype=torch.float64)
        spec = d.spec(d.clip_info(loco)["skeleton"])
        lroles = spec.bind(lm.skeleton)
    with MotionDatabase.open(dbs[action_db]) as d:
        am = d.read(action, dtype=torch.float64)
        aroles = d.spec(d.clip_info(action)["skeleton"]).bind(am.skeleton)
    side = max((0, 1), key=lambda s: wrist_spread(am, aroles, s))
    cm = centimetres(spec)
    loco_skate = float(foot_skate_stats([lm], lroles).speed[0]) * cm
    with MotionDatabase.open(out) as d:
        t = d.table()
        assert sorted(map(str, t["method"])) == sorted(methods.split(","))
        for i in range(len(t["method"])):
            r = d.read(i, dtype=torch.float64)
            assert r.skeleton.same_topology(lm.skeleton) and r.labels["action.retargeted_to"].startswith(dbs[loco_db].name)
            used = d.read_frame_column(i, "action_frame").round().clip(0, am.num_frames - 1).astype(int)
            ratio = wrist_spread(r, lroles, side) / wrist_spread(am, aroles, side, used)
            assert 0.8 <= ratio <= 1.2, (t["method"][i], ratio)
            skate = float(foot_skate_stats([r], lroles).speed[0]) * cm
            assert abs(skate - loco_skate) <= 1.0, (t["method"][i], skate, loco_skate)


def test_splice_pair_plot_alignment_and_evaluate_take_pairs_across_skeletons(dbs, tmp_path):
    """One database holding both datasets: ``splice_pair`` (what the ``splice`` command runs)
    retargets the action as ``splice-all`` does (the result is on the locomotion's skeleton, and
    its upper body is the job's result's; ``splice()`` on two clips does not retarget; the
    ``plot-alignment`` command's own retargeting: tests/cli/test_command_words.py), and
    ``evaluate_database`` measures a retargeted output against the action as spliced."""
    from torchsplice.evaluation.report import evaluate_database
    from torchsplice.job import splice_pair

    mixed = tmp_path / "mixed.h5"
    import_bvh([MOCAP / BANDAI / "dataset-2_walk-turn-left_normal_025.bvh", MOCAP / "lafan1_via_pypi_bvhtools" / "test.bvh"],
               mixed)
    loco = "dataset-2_walk-turn-left_normal_025"
    one = splice_pair(mixed, loco, "test").motion
    out = tmp_path / "job.h5"
    splice_all(mixed, out, locomotions=loco, actions="test", workers=1)
    with MotionDatabase.open(out) as d:
        job = d.read(f"{loco}+test")
    with MotionDatabase.open(mixed) as d:
        skeleton = d.read(loco).skeleton
    assert one.skeleton.same_topology(skeleton) and job.skeleton.same_topology(skeleton)
    assert one.num_frames == job.num_frames
    assert torch.equal(one.rotations, job.rotations) and torch.equal(one.root_translation, job.root_translation)
    evaluate_database(out, tmp_path / "report.md", pictures=False)
    text = (tmp_path / "report.md").read_text()
    assert "| splice |" in text and "## Retargeted pairs" in text, text
    section = text.split("## Retargeted pairs", 1)[1]
    row = next(line for line in section.splitlines() if line.startswith("| splice | 1 | "))
    ratio = float(row.split("|")[3].split()[0])
    assert 0.8 <= ratio <= 1.2, row  # the acting wrist's range, as the benchmark measures it


def test_target_brings_every_clip_onto_one_skeleton_once(dbs, tmp_path):
    """``--target smpl22``: the Bandai Namco locomotions and the LAFAN1 actions both on SMPL's
    skeleton; the retargeted inputs sit beside the output and a rerun reuses them; a dry run
    leaves nothing."""
    from torchsplice.specs.smpl import SMPL22_NAMES

    out = tmp_path / "o.h5"
    kw = dict(actions_db=dbs["lafan"], locomotions="dataset-2_walk*", actions="test", workers=1, target="smpl22")
    dry = splice_all(dbs["bn"], out, dry_run=True, **kw)
    assert dry.pairs == 2 and "smpl22" in dry.target and sorted(p.name for p in tmp_path.iterdir()) == []
    summary = splice_all(dbs["bn"], out, **kw)
    assert summary.spliced == 2 and summary.retargeted == 0 and "smpl22" in summary.target
    made = [tmp_path / "o.h5.target-locomotions.h5", tmp_path / "o.h5.target-actions.h5"]
    assert all(p.exists() and p.with_name(p.name + ".json").exists() for p in made)
    with MotionDatabase.open(out) as d:
        assert [sk.names for sk in d.skeletons] == [SMPL22_NAMES]
        m = d.read(0)
        assert m.labels["action.retargeted_to"] == "smpl22" and m.labels["locomotion.retargeted_to"] == "smpl22"
    stamps = [p.stat().st_mtime_ns for p in made]
    again = splice_all(dbs["bn"], out, overwrite=True, **kw)
    assert again.spliced == 2 and [p.stat().st_mtime_ns for p in made] == stamps  # reused, not made again


def test_pairs_across_skeletons_give_the_same_bits_in_one_run_in_slices_and_in_one_process(dbs, tmp_path):
    """The actions retargeted in the driver (banks saved for two worker processes), in each
    slice's own process, or in this process with one worker: the same output, dataset for dataset."""
    from torchsplice.job import merge_job

    kw = dict(actions_db=dbs["lafan"], locomotions="dataset-2_walk*", actions="*", methods=("splice", "naive"),
              batch_pairs=1)

    from tests.job.test_job import datasets as data  # every dataset, raw; the run record left out

    whole = tmp_path / "whole.h5"
    s = splice_all(dbs["bn"], whole, workers=2, **kw)
    assert s.spliced == 8 and s.retargeted == 8
    inline = tmp_path / "inline.h5"
    splice_all(dbs["bn"], inline, workers=1, **kw)  # one worker: this process runs the tasks
    sliced = tmp_path / "sliced.h5"
    for k in (1, 2):
        splice_all(dbs["bn"], sliced, workers=1, shard=f"{k}/2", **kw)
    assert merge_job(sliced, progress=False).spliced == 8
    assert data(whole) == data(inline) == data(sliced)
