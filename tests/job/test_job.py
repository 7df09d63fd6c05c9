"""The n x m database job (:mod:`torchsplice.job.run`): ``splice_all`` and ``torchsplice splice-all``.

Counts and provenance on the built-in sample and on real Bandai Namco clips, several methods,
resuming after SIGKILL and after an interrupt (bit-identical to an uninterrupted run), refusing
to mix runs with other arguments, determinism, bounded memory and bad input.

The job's properties are tested through the Python API (:func:`torchsplice.job.splice_all`,
``import_bvh``, ``export_clips``; in a process of its own where a test kills it or sets its
environment); the command line (``main([...])``) where its words, flags or exit codes are the subject.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from torchsplice import __version__
from torchsplice.cli import main
from torchsplice.core.errors import UnfinishedJobError
from torchsplice.core.motion import Motion
from torchsplice.formats.exporters import export_clips
from torchsplice.formats.importer import import_bvh
from torchsplice.store.database import MotionDatabase
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.core.rotations import quat_angle
from torchsplice.job import JobConfig, SpliceJob, splice_all
from cli_helpers import run
from realdata import BANDAI, BANDAI_FEW
from writers import _digest, cli, killed_when, nan_copy, reaped, splice_all_process, summary_of

REPO = Path(__file__).resolve().parents[2]
WAVE = "dataset-2_wave-left-hand_normal_001"
SAMPLE_LOCOS = ["walk_straight", "walk_curve", "turn_sharp", "sidestep", "jog"]
SAMPLE_ACTIONS = ["carry_box", "carry_cup", "wave", "punch", "arms_out"]
VOLATILE_RUN_KEYS = ("started", "command", "engine")  # the only parts of the run record that may differ between runs


def env():
    e = dict(os.environ)
    e.setdefault("OMP_NUM_THREADS", "1")
    return e


def work_folder(out: Path) -> Path:
    return out.with_name(f".{out.name}.parts")


def table(path) -> dict:
    with MotionDatabase.open(path) as db:
        t = db.table()
    return {k: [v.item() if hasattr(v, "item") else v for v in col] for k, col in t.items()}


def clips(path) -> list[dict]:
    with MotionDatabase.open(path) as db:
        return db.summary()["clips"]


def run_record(path) -> dict:
    with h5py.File(path, "r") as f:
        return json.loads(f.attrs["run"])


def h5_dump(path) -> dict:
    """Every group and dataset of a file: dtype, shape, raw values and attributes (run record less its volatile keys)."""
    out = {}

    def attrs(obj):
        a = {}
        for k, v in obj.attrs.items():
            v = v.decode() if isinstance(v, bytes) else v.tolist() if hasattr(v, "tolist") else v
            if k == "run":
                v = {kk: vv for kk, vv in json.loads(v).items() if kk not in VOLATILE_RUN_KEYS}
            a[k] = v
        return a

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            values = obj[()]
            raw = values.tolist() if values.dtype == object else values.tobytes()
            out[name] = (str(obj.dtype), values.shape, raw, attrs(obj))
        else:
            out[name] = ("group", attrs(obj))

    with h5py.File(path, "r") as f:
        visit("/", f)
        f.visititems(visit)
    return out


def assert_same_file(a, b):
    da, db = h5_dump(a), h5_dump(b)
    assert sorted(da) == sorted(db)
    for name in da:
        assert da[name] == db[name], f"{name} differs between {a} and {b}"


def write_db(path, motions, spec_name="sample"):
    spec = load_spec(spec_name)
    with MotionDatabase.create(path) as db:
        for m in motions:
            db.append(m, spec=spec)
    return path


def sample_copies(copies: int, frames: int | None = None):
    """The sample clips, ``copies`` times under new names (``walk_straight_3``), optionally cut to ``frames``."""
    out = []
    for c in range(copies):
        for m in sample_motions():
            m = m.slice(0, frames or m.num_frames)
            m.name = f"{m.name}_{c}"
            out.append(m)
    return out


# --------------------------------------------------------------------------------------------
# fixtures
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def default_out(sample_db, tmp_path_factory):
    out = tmp_path_factory.mktemp("default") / "out.h5"
    splice_all(sample_db, out)
    return out


@pytest.fixture(scope="module")
def multi_out(sample_db, tmp_path_factory):
    out = tmp_path_factory.mktemp("multi") / "out.h5"
    splice_all(sample_db, out, methods="splice,naive,cpmc", copy_sources=True)
    return out


@pytest.fixture(scope="module")
def batch2_out(sample_db, tmp_path_factory):
    """An uninterrupted run with ``batch_pairs=2`` (13 batches), the reference for resumed runs."""
    out = tmp_path_factory.mktemp("batch2") / "out.h5"
    splice_all(sample_db, out, batch_pairs=2)
    return out


# --------------------------------------------------------------------------------------------
# 1. the sample job: counts, provenance, per-frame column, quality figures, run record
# --------------------------------------------------------------------------------------------
def test_sample_job_counts_and_provenance(sample_db, default_out):
    src = table(sample_db)
    assert sorted(n for n, r in zip(src["name"], src["role"]) if r == "locomotion") == sorted(SAMPLE_LOCOS)
    assert sorted(n for n, r in zip(src["name"], src["role"]) if r == "action") == sorted(SAMPLE_ACTIONS)
    with MotionDatabase.open(default_out) as db:
        info = json.loads(json.dumps(db.summary()))  # what `torchsplice info --json` prints
    cs = info["clips"]
    assert info["num_clips"] == len(cs) == 25
    assert {c["role"] for c in cs} == {"spliced"}
    assert len({c["name"] for c in cs}) == 25
    assert {(c["locomotion"], c["action"]) for c in cs} == {(l, a) for l in SAMPLE_LOCOS for a in SAMPLE_ACTIONS}
    for c in cs:
        assert c["name"] == f"{c['locomotion']}+{c['action']}"
        assert src["name"][c["locomotion_id"]] == c["locomotion"] and src["role"][c["locomotion_id"]] == "locomotion"
        assert src["name"][c["action_id"]] == c["action"] and src["role"][c["action_id"]] == "action"
        assert c["method"] == "splice" and c["reference"] == "" and c["flags"] == ""
        own = {"method": "splice", "locomotion": c["locomotion"], "action": c["action"]}
        from_sources = {f"{tag}.{k}": v for tag in ("locomotion", "action")
                        for k, v in json.loads(src["labels"][c[f"{tag}_id"]] or "{}").items()}
        assert from_sources and c["labels"] == {**own, **from_sources}  # the sources' labels are kept
        assert c["fps"] == 30.0 and c["skeleton"] == 0
        params = json.loads(c["params"])
        assert params["max_run"] == 3 and params["posture"] is True and params["force_locomotion"] is False
        loco_frames, act_frames = src["length"][c["locomotion_id"]], src["length"][c["action_id"]]
        # quality figures
        assert np.isfinite(c["cost"]) and c["cost"] >= 0
        assert 0 <= c["crop"] < act_frames
        assert 0 < c["coverage"] <= 1 and c["coverage"] == pytest.approx(c["frames"] / loco_frames)
        assert 0 <= c["posture_deg"] < 90 and 0 <= c["pelvis_correction_deg"] < 90
    with MotionDatabase.open(default_out) as db:
        assert db.frame_columns == ("action_frame",)
        for c in cs:
            f = db.read_frame_column(c["name"], "action_frame")
            act_frames = src["length"][c["action_id"]]
            assert f.shape == (c["frames"],) and np.isfinite(f).all()
            assert (np.diff(f) > 0).all(), c["name"]  # strictly increasing
            assert f[0] >= c["crop"] - 1e-3 and f[-1] <= act_frames - 1 + 1e-3
            assert db.read(c["name"]).num_frames == c["frames"]
    rec = run_record(default_out)
    assert rec["tool"] == f"torchsplice {__version__}"
    assert rec["database"]["path"] == str(sample_db.resolve()) and rec["actions_db"] is None
    assert rec["locomotions"] == ["role:locomotion,role:both"] and rec["actions"] == ["role:action,role:both"]
    assert rec["methods"] == ["splice"] and rec["max_run"] == 3 and rec["posture"] is True
    assert rec["force_locomotion"] is False and rec["copy_sources"] is False
    assert rec["pairs"] == rec["pairs_spliced"] == 25
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[+-]\d{4}", rec["started"])


def test_run_record_command_is_the_command_that_ran(sample_db, tmp_path):
    """Called as ``main([...])`` (e.g. from a notebook), the record holds those arguments, not the host's argv."""
    out = tmp_path / "rec.h5"
    assert main(["splice-all", str(sample_db), "-o", str(out), "--locomotions", "jog", "-q"]) == 0
    command = run_record(out)["command"]
    assert "splice-all" in command and str(out) in command and "jog" in command, command


# --------------------------------------------------------------------------------------------
# 2. several methods, copied sources
# --------------------------------------------------------------------------------------------
def test_several_methods_and_copied_sources(sample_db, multi_out):
    src = table(sample_db)
    cs = clips(multi_out)
    spliced = [c for c in cs if c["role"] == "spliced"]
    assert len(spliced) == 75 and len(cs) == 85
    assert len({c["name"] for c in cs}) == 85
    for method, suffix in (("splice", ""), ("naive", ".naive"), ("cpmc", ".cpmc")):
        rows = [c for c in spliced if c["method"] == method]
        assert {(c["locomotion"], c["action"]) for c in rows} == {(l, a) for l in SAMPLE_LOCOS for a in SAMPLE_ACTIONS}
        for c in rows:
            assert c["name"] == f"{c['locomotion']}+{c['action']}{suffix}"
            assert c["labels"]["method"] == method and c["source"] == f"splice:{method}"
            assert src["name"][c["locomotion_id"]] == c["locomotion"] and src["name"][c["action_id"]] == c["action"]
            # the sample spec's reference rule: content={gait} (walk), path=straight
            assert c["reference"] == ("walk_straight" if method == "cpmc" else "")
            if method == "naive":
                assert c["cost"] is None and c["crop"] == 0
            else:
                assert np.isfinite(c["cost"]) and c["cost"] >= 0
    # the ten selected source clips, with their own roles, labels and frames
    copied = [c for c in cs if c["role"] != "spliced"]
    assert sorted(c["name"] for c in copied) == sorted(src["name"])
    with MotionDatabase.open(sample_db) as a, MotionDatabase.open(multi_out) as b:
        for c in copied:
            i = src["name"].index(c["name"])
            assert c["role"] == src["role"][i] and c["labels"] == json.loads(src["labels"][i])
            assert c["method"] == "" and c["locomotion_id"] == -1 and c["cost"] is None
            m, n = a.read(c["name"]), b.read(c["name"])
            assert np.array_equal(m.rotations.numpy(), n.rotations.numpy())
            assert np.array_equal(m.root_translation.numpy(), n.root_translation.numpy())
            assert np.isnan(b.read_frame_column(c["name"], "action_frame")).all()


def test_splice_rows_do_not_depend_on_the_other_methods(default_out, multi_out):
    """The ``splice`` rows of the three-method run are those of the splice-only run."""
    with MotionDatabase.open(default_out) as a, MotionDatabase.open(multi_out) as b:
        assert a.names == b.names[:25]
        for name in a.names:
            x, y = a.read(name), b.read(name)
            assert x.num_frames == y.num_frames, name
            assert np.allclose(x.rotations.numpy(), y.rotations.numpy(), atol=1e-5), name
            assert np.allclose(a.read_frame_column(name, "action_frame"), b.read_frame_column(name, "action_frame"),
                               atol=1e-4), name


# --------------------------------------------------------------------------------------------
# 3. real data
# --------------------------------------------------------------------------------------------
def test_real_clips_selected_by_labels(bandai_few_db, tmp_path):
    out = tmp_path / "real.h5"
    summary = splice_all(bandai_few_db, out, locomotions=["label:style=normal", "label:content=walk-turn-*"],
                         actions=["label:dataset=2", "label:content=walk*"])
    text = "\n".join(summary.lines())
    src = table(bandai_few_db)
    locos = ["dataset-2_walk-turn-left_normal_025", "dataset-2_walk-turn-right_normal_031"]
    acts = [n for n in BANDAI_FEW if n != WAVE]  # every walk* clip, whatever its role
    # n x m minus the two locomotions paired with themselves
    want = {(l, a) for l in locos for a in acts if l != a}
    assert len(want) == 2 * 5 - 2
    cs = clips(out)
    assert len(cs) == len(want) and {(c["locomotion"], c["action"]) for c in cs} == want
    for c in cs:
        assert c["name"] == f"{c['locomotion']}+{c['action']}" and c["role"] == "spliced"
        assert src["name"][c["locomotion_id"]] == c["locomotion"] and src["name"][c["action_id"]] == c["action"]
        assert np.isfinite(c["cost"]) and 0 < c["coverage"] <= 1 and c["fps"] == 30.0
    assert summary.spliced == summary.pairs == len(want)
    assert summary.skipped == {"a clip is not spliced onto itself": 2}
    assert "wrote" in text and f"{len(want)} spliced clips" in text
    assert "skipped 2 pairs:" in text and "2 x a clip is not spliced onto itself" in text
    rec = run_record(out)
    assert rec["locomotions"] == ["label:style=normal", "label:content=walk-turn-*"]
    assert rec["actions"] == ["label:dataset=2", "label:content=walk*"]
    with MotionDatabase.open(out) as db:
        assert len(db.skeletons) == 1 and json.loads(db.spec_json(0))["name"] == "bandai_namco"
        m = db.read(cs[0]["name"])
        assert m.translations is not None  # Bandai Namco animates joint translations; they are kept


def test_standing_action_is_spliced_by_default_over_the_whole_locomotion(bandai_few_db, tmp_path):
    out = tmp_path / "wave.h5"
    summary = splice_all(bandai_few_db, out, locomotions="role:locomotion")
    text = "\n".join(summary.lines())
    cs = clips(out)
    # 3 locomotions x (2 'both' clips + the standing wave): nothing skipped
    assert len(cs) == 9 and summary.skipped == {} and "skipped" not in text
    assert summary.timings == {"timewarp": 6, "loop": 3}
    assert "6 time-aligned (timewarp), 3 standing actions (loop)" in text
    for c in cs:
        standing = c["action"] == WAVE
        assert c["timing"] == ("loop" if standing else "timewarp")
        assert (c["acting"] == "left_arm") if standing else c["acting"] == ""
        if standing:
            assert c["coverage"] == 1.0 and "does not locomote" not in c["flags"]
    for timing in ("hold", "fit"):
        summary = splice_all(bandai_few_db, tmp_path / f"{timing}.h5", locomotions="role:locomotion", actions=WAVE,
                             timing=timing, acting_limbs="none")
        assert summary.timings == {timing: 3} and f"3 standing actions ({timing})" in "\n".join(summary.lines())
        assert {(c["timing"], c["acting"], c["coverage"]) for c in clips(tmp_path / f"{timing}.h5")} == {(timing, "", 1.0)}


def test_force_locomotion_splices_in_place_action_with_a_flag(bandai_few_db, tmp_path):
    out = tmp_path / "forced.h5"
    summary = splice_all(bandai_few_db, out, locomotions="role:locomotion", force_locomotion=True)
    text = "\n".join(summary.lines())
    cs = clips(out)
    assert len(cs) == 9
    waves = [c for c in cs if c["action"] == WAVE]
    assert len(waves) == 3
    for c in cs:
        # flags are codes (the figures in columns of their own), flag_details says them in words
        assert ("action_not_locomoting" in c["flags"].split(",")) == (c["action"] == WAVE), c["name"]
        assert (f"{WAVE} does not locomote" in c["flag_details"]) == (c["action"] == WAVE), c["name"]
        assert set(c["flags"].split(",")) - {""} <= {"action_not_locomoting", "poor_alignment"}, c["flags"]
        assert ("poor_alignment" in c["flags"]) == (c["alignment_distance"] > 0.10), c["name"]
        assert json.loads(c["params"])["force_locomotion"] is True
    assert summary.skipped == {} and "skipped" not in text
    # the summary counts flagged clips: one line "flagged N clips", N = clips with a non-empty flags column,
    # then one line per code with what it means
    flagged = sum(1 for c in cs if c["flags"])
    assert summary.flagged_clips == flagged and summary.flagged["action_not_locomoting"] == 3
    m = re.search(r"flagged (\d+) clips", text)
    assert m and int(m.group(1)) == flagged, text
    assert re.search(r"  3 x action_not_locomoting: the action does not locomote", text), text


STANDING_LOCOS = ["dataset-2_walk-turn-left_normal_025", "dataset-2_walk-turn-right_normal_031", "dataset-2_walk_normal_008"]
STANDING_ACTIONS = ["dataset-2_raise-up-both-hands_normal_001", "dataset-2_raise-up-left-hand_normal_001",
                    "dataset-2_raise-up-right-hand_normal_001", "dataset-2_wave-both-hands_normal_001",
                    "dataset-2_wave-left-hand_normal_001", "dataset-2_wave-right-hand_normal_001"]


@pytest.fixture(scope="module")
def standing_out(mocap_dir, tmp_path_factory):
    """3 normal-style walks and turns x 6 standing raises and waves (18 standing pairs, some
    locomotions shorter than the action, some longer), in this process, one task per pair."""
    folder = tmp_path_factory.mktemp("standing")
    db = folder / "db.h5"
    import_bvh([mocap_dir / BANDAI / f"{n}.bvh" for n in STANDING_LOCOS + STANDING_ACTIONS], db, spec="bandai_namco")
    out = folder / "out.h5"
    splice_all(db, out, locomotions="role:locomotion", actions="role:action", workers=1, batch_pairs=1)
    return db, out


def test_standing_pairs_do_not_depend_on_batch_size_or_workers(standing_out, tmp_path):
    """Standing pairs run in the compiled splicer one pair per thread, like time-aligned ones:
    the same bits in any task size on any number of workers."""
    db, want = standing_out
    assert {c["timing"] for c in clips(want)} == {"loop"} and len(clips(want)) == 18
    for batch, workers in (("4", "2"), ("7", "3"), ("18", "1")):
        out = tmp_path / f"b{batch}_w{workers}.h5"
        splice_all(db, out, locomotions="role:locomotion", actions="role:action", batch_pairs=int(batch),
                   workers=int(workers))
        assert datasets(out) == datasets(want), (batch, workers)


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=pytest.mark.gpu)])
def test_standing_pairs_on_the_torch_path_equal_the_compiled_ones(standing_out, tmp_path, monkeypatch, device):
    """The torch splicer (CUDA's; on the CPU with numba hidden) plays the same action frames (the
    same windows and loop points, bit for bit) and gives the same rotations within 1e-3 degrees."""
    import torchsplice.cpu

    db, want = standing_out
    monkeypatch.setattr(torchsplice.cpu, "_AVAILABLE", False)
    out = tmp_path / "torch.h5"
    splice_all(db, out, locomotions="role:locomotion", actions="role:action", device=device)
    a, b = table(out), table(want)
    for col in ("name", "length", "timing", "acting", "locomotion", "action"):
        assert a[col] == b[col], col
    with h5py.File(out, "r") as fa, h5py.File(want, "r") as fb:
        qa, qb = (torch.from_numpy(f["skeletons/0/rotations"][()]).double() for f in (fa, fb))
        assert float(torch.rad2deg(quat_angle(qa, qb)).max()) < 1e-3
        assert np.array_equal(fa["skeletons/0/action_frame"][()], fb["skeletons/0/action_frame"][()])


# --------------------------------------------------------------------------------------------
# 4. resume after SIGKILL
# --------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_resume_after_sigkill_is_bit_identical(sample_db, batch2_out, tmp_path):
    out = tmp_path / "killed" / "out.h5"
    out.parent.mkdir()
    work = work_folder(out)
    held = lambda: (MotionDatabase.checkpoint_note(work / "output.h5") or {}).get("tasks", 0)  # noqa: E731
    every_task = dict(env(), TORCHSPLICE_CHECKPOINT_SECONDS="0")  # a checkpoint after each task, to kill between two
    proc = splice_all_process(sample_db, out, batch_pairs=2, env=every_task, cwd=REPO)
    with reaped(proc):
        killed_when(proc, lambda: held() >= 2)
    assert not out.exists()  # the output appears only once complete
    k = held()
    assert 2 <= k < 13 and (work / "plan.json").is_file()
    kept_pairs = 2 * k  # 12 tasks of 2 pairs, then 1
    waiting = sorted(int(p.name.split(".")[0][5:]) for p in work.glob("part-*"))
    # no part of a task the output holds is left but those whose deletion (in the background, right
    # after their append) the kill cut short; the rerun removes those
    assert sum(t < k for t in waiting) <= 2, (k, waiting)

    again = splice_all_process(sample_db, out, batch_pairs=2, env=env(), cwd=REPO)
    stdout, stderr = again.communicate(timeout=300)
    assert again.returncode == 0, stderr
    summary = summary_of(stdout)
    m = re.search(r"25 spliced clips \((\d+) pairs from an earlier run\)", summary["lines"][0])
    assert m and summary["spliced"] == 25 and summary["resumed"] == int(m.group(1)), summary
    assert kept_pairs <= summary["resumed"] <= 25  # what the output held, and the shards finished since
    assert not work.exists()
    assert sorted(p.name for p in out.parent.iterdir()) == ["out.h5", "out.h5.index.csv"]  # nothing else left behind
    names = [c["name"] for c in clips(out)]
    assert len(names) == len(set(names)) == 25
    assert_same_file(out, batch2_out)


# --------------------------------------------------------------------------------------------
# 5. interrupted in-process, resumed by a new SpliceJob
# --------------------------------------------------------------------------------------------
def test_interrupt_then_resume_in_process(sample_db, batch2_out, tmp_path, monkeypatch):
    import torchsplice.job.engines.inline as executors  # the engine of this process (workers=1)

    out = tmp_path / "out.h5"
    config = JobConfig(database=sample_db, output=out, batch_pairs=2, workers=1)
    real = executors.run_task
    calls = []

    def interrupted(plan, task, *args, **kw):
        calls.append(task.size)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(plan, task, *args, **kw)

    monkeypatch.setattr(executors, "run_task", interrupted)
    job = SpliceJob(config, progress=False)
    with pytest.raises(KeyboardInterrupt):
        job.run()
    work = work_folder(out)
    assert job.work == work and not out.exists()
    # the two finished tasks are in the staged output, checkpointed; their shards are gone
    assert not list(work.glob("part-*.h5"))
    assert MotionDatabase.checkpoint_note(work / "output.h5")["tasks"] == 2
    leftovers = [p.name for p in out.parent.glob(f".{out.name}.*") if p != work]
    assert not list(work.glob(".part-*")) and not leftovers  # no temporary file, no lock

    calls.clear()
    monkeypatch.setattr(executors, "run_task", lambda plan, task, *a, **kw: calls.append(task.size) or real(plan, task, *a, **kw))
    summary = SpliceJob(config, progress=False).run()
    assert summary.resumed == 4 and summary.spliced == 25 and summary.pairs == 25
    assert len(calls) == 11 and sum(calls) == 21  # only the unfinished tasks are spliced
    assert summary.merged_shards == 11  # and only their shards merged: the first two are not copied again
    assert "(4 pairs from an earlier run)" in summary.lines()[0]
    assert not work.exists()
    assert_same_file(out, batch2_out)


# --------------------------------------------------------------------------------------------
# 6. other arguments while an unfinished work folder exists
# --------------------------------------------------------------------------------------------
def test_other_arguments_refuse_to_mix_until_restart(sample_db, tmp_path, capsys, monkeypatch):
    import torchsplice.job.engines.inline as executors  # the engine of this process (workers=1)

    out = tmp_path / "out.h5"
    work = work_folder(out)
    real = executors.run_task
    calls = []

    def interrupted(plan, task, *args, **kw):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(plan, task, *args, **kw)

    monkeypatch.setattr(executors, "run_task", interrupted)
    # the command line, interrupted, says where the finished tasks are and how to resume
    cli_base = ["splice-all", sample_db, "-o", out, "--batch-size", "2", "--workers", "1", "-q"]
    code, _, err = run(capsys, *cli_base)
    assert code == 130 and str(work) in err and "resume" in err
    monkeypatch.setattr(executors, "run_task", real)
    state = lambda: (sorted(p.name for p in work.iterdir()), MotionDatabase.checkpoint_note(work / "output.h5"))  # noqa: E731
    plan = (work / "plan.json").read_text()
    before = state()
    assert before[1]["tasks"] == 2  # two tasks finished, in the staged output

    base = dict(batch_pairs=2, workers=1)  # the same job, from Python
    for other in (dict(methods="naive"), dict(actions="carry_box"), dict(batch_pairs=3), dict(posture=False)):
        with pytest.raises(UnfinishedJobError, match="holds an unfinished job with other arguments") as exc:
            splice_all(sample_db, out, **{**base, **other})
        said = str(exc.value)
        assert "\n" not in said and str(work) in said and "restart=True" in said, (other, said)
        assert not out.exists()
        assert state() == before and (work / "plan.json").read_text() == plan
    # the command line's refusal: one line, naming its flag
    code, _, err = run(capsys, *cli_base, "--method", "naive")
    assert code == 2
    assert err.count("\n") == 1 and str(work) in err and "--restart" in err and "Traceback" not in err, err
    assert not out.exists()
    assert state() == before and (work / "plan.json").read_text() == plan

    splice_all(sample_db, out, **base, methods="naive", restart=True)
    cs = clips(out)
    assert len(cs) == 25 and {c["method"] for c in cs} == {"naive"}
    assert not work.exists()


# --------------------------------------------------------------------------------------------
# 7. determinism
# --------------------------------------------------------------------------------------------
def test_two_separate_runs_are_bit_identical(sample_db, default_out, tmp_path):
    """The same job in another process (another interpreter, its own hash seed) writes the same file."""
    out = tmp_path / "again.h5"
    p = splice_all_process(sample_db, out, cwd=tmp_path, env=env())
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    assert_same_file(out, default_out)


def datasets(path) -> dict:
    """Every dataset of a file (clip data and columns), raw; the run record is left out."""
    return {k: v for k, v in h5_dump(path).items() if v[0] != "group"}


def test_output_does_not_depend_on_batch_size_or_workers(sample_db, default_out, tmp_path):
    """Each pair is computed alone by one thread: other task sizes and worker counts (this
    process, or 2 or 3 worker processes) give the same bits, clip data and columns alike."""
    for batch, threads in (("3", "1"), ("7", "2"), ("4", "3")):
        out = tmp_path / f"b{batch}_t{threads}.h5"
        splice_all(sample_db, out, batch_pairs=int(batch), workers=int(threads))
        assert datasets(out) == datasets(default_out), (batch, threads)
        assert run_record(out)["batch_pairs"] == int(batch)


def test_compression_choices_hold_the_same_clips(sample_db, default_out, tmp_path):
    want = datasets(default_out)
    for comp in ("none", "lzf", "gzip"):
        out = tmp_path / f"{comp}.h5"
        splice_all(sample_db, out, compression=comp)
        assert datasets(out) == want
        with h5py.File(out, "r") as f:
            ds = f["skeletons/0/rotations"]
            assert ds.compression == (None if comp == "none" else comp)
            assert f.attrs["compression"] == ("" if comp == "none" else comp)
    with h5py.File(default_out, "r") as f:  # auto: LZF everywhere but the rotations
        assert f["skeletons/0/rotations"].compression is None
        assert f["skeletons/0/root_translation"].compression == "lzf"
        assert f["skeletons/0/action_frame"].compression == "lzf"


def test_torch_path_writes_the_same_clips(sample_db, default_out, tmp_path, monkeypatch):
    """Without the compiled splicer (as on CUDA) the job runs the torch splicer: the same clips
    to float32 rounding, the same alignment choices."""
    import torchsplice.cpu

    monkeypatch.setattr(torchsplice.cpu, "_AVAILABLE", False)
    out = tmp_path / "torch.h5"
    splice_all(sample_db, out)
    a, b = table(out), table(default_out)
    for col in ("name", "length", "crop", "locomotion", "action", "flags"):
        assert a[col] == b[col], col
    assert np.allclose(a["cost"], b["cost"], rtol=1e-4)
    assert np.allclose(a["pelvis_correction_deg"], b["pelvis_correction_deg"], atol=1e-3)
    with h5py.File(out, "r") as fa, h5py.File(default_out, "r") as fb:
        qa, qb = (torch.from_numpy(f["skeletons/0/rotations"][()]).double() for f in (fa, fb))
        assert float(torch.rad2deg(quat_angle(qa, qb)).max()) < 1e-3
        assert np.allclose(fa["skeletons/0/action_frame"][()], fb["skeletons/0/action_frame"][()], atol=1e-3)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_pair_that_cannot_be_aligned_is_skipped_and_the_rest_land(tmp_path, monkeypatch, compiled):
    """An action that is its locomotion's first pose held still, with runs as long as the action:
    the cheapest path stays on the locomotion's first frame, so the alignment does not advance.
    That pair is skipped with its reason; the other pair of the batch still lands."""
    import torchsplice.cpu

    if not compiled:
        monkeypatch.setattr(torchsplice.cpu, "_AVAILABLE", False)
    walk = {m.name: m for m in sample_motions()}["walk_straight"]
    pose = walk.slice(0, 1)
    pose = Motion(walk.skeleton, pose.rotations.expand(16, -1, -1).clone(), pose.root_translation.expand(16, -1).clone(),
                  walk.fps, None if pose.translations is None else pose.translations.expand(16, -1, -1).clone(),
                  name="held_pose", role="action")
    box = {m.name: m for m in sample_motions()}["carry_box"]
    walk.role = "locomotion"
    db = write_db(tmp_path / "in.h5", [walk, pose, box])
    out = tmp_path / "out.h5"
    summary = splice_all(db, out, force_locomotion=True, max_run=15)
    assert summary.spliced == 1 and sum(summary.skipped.values()) == 1, summary.skipped
    stdout = "\n".join(summary.lines())
    assert "1 x the alignment failed (the alignment does not advance in both clips)" in stdout.replace("pair 0: ", "")
    assert [c["name"] for c in clips(out)] == ["walk_straight+carry_box"]


# --------------------------------------------------------------------------------------------
# 8. bounded memory
# --------------------------------------------------------------------------------------------
DRIVER = """
import json, resource, sys
import torch, torchsplice.job
from torchsplice.job import splice_all


def peak_kb():
    # the peak RSS of this process image: ru_maxrss would also count the parent's pages from
    # before execve (Linux keeps the high-water mark across exec), VmHWM does not
    try:
        with open("/proc/self/status") as f:
            return int(next(l for l in f if l.startswith("VmHWM:")).split()[1])
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


before = peak_kb()
# one worker, in this process: the process measured is the one that holds the results
summary = splice_all(sys.argv[1], sys.argv[2], methods="naive", batch_pairs=64, memory_budget_mb=64, workers=1)
print(json.dumps({"spliced": summary.spliced, "before_kb": before, "after_kb": peak_kb()}))
"""


@pytest.mark.slow
def test_peak_memory_does_not_grow_with_the_number_of_pairs(tmp_path):
    """5 x 5 pairs against 40 x 40 (64 times as many), same skeleton, 60-frame clips, same batch size.

    Measured: what the job adds to the peak RSS of a process that has already imported
    everything (about 26 MB small, 115 MB big here). The fixed margin covers the database
    writer's buffer (it flushes every 65,536 frames, which only the big job reaches); a job that
    kept every spliced result in memory adds about 190 MB on the big input and fails.
    """
    small = write_db(tmp_path / "small.h5", sample_copies(1, 60))
    big = write_db(tmp_path / "big.h5", sample_copies(8, 60))
    script = tmp_path / "driver.py"
    script.write_text(DRIVER)
    procs = [subprocess.Popen([sys.executable, str(script), str(db), str(tmp_path / f"out_{db.stem}.h5")],
                              env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for db in (small, big)]
    res = []
    for p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        res.append(json.loads(out.strip().splitlines()[-1]))
    assert [r["spliced"] for r in res] == [25, 1600]
    assert len(clips(tmp_path / "out_small.h5")) == 25 and len(clips(tmp_path / "out_big.h5")) == 1600
    grow_small, grow_big = ((r["after_kb"] - r["before_kb"]) / 1024 for r in res)
    assert grow_big < 1.5 * grow_small + 112, (grow_small, grow_big)


# --------------------------------------------------------------------------------------------
# 9. bad input
# --------------------------------------------------------------------------------------------
def assert_left_nothing(folder: Path, *keep: str):
    assert sorted(p.name for p in folder.iterdir()) == sorted(keep)


def test_selector_matching_nothing(sample_db, tmp_path, capsys):
    out = tmp_path / "out.h5"
    code, text, err = run(capsys, "splice-all", sample_db, "-o", out, "--locomotions", "role:locomotion",
                          "--locomotions", "label:path=zigzag")
    assert code == 2 and err.count("\n") == 1 and err.startswith("torchsplice: error:")
    assert "'label:path=zigzag'" in err and "--locomotions" in err and str(sample_db) in err
    assert text == ""
    assert_left_nothing(tmp_path)
    code, _, err = run(capsys, "splice-all", sample_db, "-o", out, "--actions", "no_such_clip*")
    assert code == 2 and "'no_such_clip*'" in err and "--actions" in err
    assert_left_nothing(tmp_path)
    code, _, err = run(capsys, "splice-all", sample_db, "-o", out, "--actions", "label:content")
    assert code == 2 and err.count("\n") == 1 and "'label:content'" in err and "label:KEY=VALUE" in err
    assert_left_nothing(tmp_path)


def test_actions_db_with_another_skeleton(bandai_few_db, mocap_dir, tmp_path, capsys):
    lafan = tmp_path / "lafan.h5"
    import_bvh([mocap_dir / "lafan1_via_pypi_bvhtools" / "test2.bvh"], lafan)
    out_dir = tmp_path / "o"
    out_dir.mkdir()
    # without retargeting: refused in one line naming both databases
    code, _, err = run(capsys, "splice-all", bandai_few_db, "--actions-db", lafan, "--actions", "*",
                       "-o", out_dir / "x.h5", "--no-retarget")
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert str(bandai_few_db) in err and str(lafan) in err and "skeleton" in err and "--retarget is off" in err
    assert_left_nothing(out_dir)
    # by default the action is retargeted onto the locomotions' skeleton
    summary = splice_all(bandai_few_db, out_dir / "x.h5", actions_db=lafan, actions="*")
    with MotionDatabase.open(out_dir / "x.h5") as db:
        spliced = [i for i, r in enumerate(db.clip_table().role) if r == "spliced"]
        assert spliced and summary.retargeted == len(spliced)
        assert f"{len(spliced)} had the action retargeted" in "\n".join(summary.lines())
        for i in spliced:
            m = db.read(i)
            assert m.skeleton.num_joints == 22 and m.labels["action.retargeted_from"] == "lafan.h5:0 (lafan1)"


def test_unknown_method(sample_db, tmp_path, capsys):
    code, _, err = run(capsys, "splice-all", sample_db, "-o", tmp_path / "o.h5", "--method", "splice,bogus")
    assert code == 2 and err.count("\n") == 1 and "'bogus'" in err and "cpmc" in err
    assert_left_nothing(tmp_path)


def test_existing_output_needs_force(sample_db, tmp_path, capsys):
    out = tmp_path / "o.h5"
    out.write_bytes(b"precious")
    code, _, err = run(capsys, "splice-all", sample_db, "-o", out, "--locomotions", "jog", "-q")
    assert code == 2 and err.count("\n") == 1 and "already exists" in err and "--force" in err
    assert out.read_bytes() == b"precious"
    assert_left_nothing(tmp_path, "o.h5")
    code, _, err = run(capsys, "splice-all", sample_db, "-o", out, "--locomotions", "jog", "-q", "--force")
    assert code == 0, err
    assert len(clips(out)) == 5
    assert_left_nothing(tmp_path, "o.h5", "o.h5.index.csv")


def test_missing_output_folder(sample_db, tmp_path, capsys):
    out = tmp_path / "no" / "such" / "o.h5"
    code, _, err = run(capsys, "splice-all", sample_db, "-o", out)
    assert code == 2 and err.count("\n") == 1 and str(out.parent) in err
    assert not (tmp_path / "no").exists()


def test_missing_database(tmp_path, capsys):
    code, _, err = run(capsys, "splice-all", tmp_path / "nothing.h5", "-o", tmp_path / "o.h5")
    assert code == 2 and err.count("\n") == 1 and "nothing.h5" in err
    assert_left_nothing(tmp_path)


def test_too_short_clip_is_skipped_not_fatal(tmp_path):
    """A clip too short to align (10 frames at 30 fps; 15 needed) costs its pairs, not the whole job, forced or not."""
    motions = sample_motions()
    short = motions[5].slice(0, 10)
    short.name = "carry_box_short"
    db = write_db(tmp_path / "db.h5", motions + [short])
    for force in (False, True):
        out = tmp_path / f"out{int(force)}.h5"
        summary = splice_all(db, out, force_locomotion=force)
        text = "\n".join(summary.lines())
        cs = clips(out)
        assert len(cs) == 25 and "carry_box_short" not in {c["action"] for c in cs}
        assert sum(summary.skipped.values()) == 5 and all("carry_box_short" in why for why in summary.skipped)
        assert "skipped 5 pairs:" in text and "carry_box_short" in text
        assert not work_folder(out).exists()


# --------------------------------------------------------------------------------------------
# 10. the script
# --------------------------------------------------------------------------------------------
def test_script_help():
    done = subprocess.run([sys.executable, "scripts/splice_all.py", "--help"], cwd=REPO, env=env(),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "usage:" in done.stdout and "splice-all" in done.stdout
    for option in ("--locomotions", "--actions", "--method", "--batch-size", "--restart", "--copy-sources"):
        assert option in done.stdout


def test_a_nan_locomotion_is_skipped_for_its_real_reason(sample_db, tmp_path):
    db = nan_copy(sample_db, tmp_path, "walk_straight")
    summary = splice_all(db, tmp_path / "o.h5", workers=1, force_locomotion=True)
    out = "\n".join(summary.lines())
    assert any("walk_straight has non-finite values (NaN or infinity) from frame 5" in why for why in summary.skipped)
    assert "walk_straight has non-finite values (NaN or infinity) from frame 5" in out
    assert "walk_straight does not locomote" not in out
    with MotionDatabase.open(tmp_path / "o.h5") as o:
        assert not any(n.startswith("walk_straight") for n in o.names)


@pytest.mark.slow
def test_sigterm_stops_a_job_like_ctrl_c_and_the_rerun_resumes(sample_db, tmp_path):
    out = tmp_path / "o.h5"
    p = cli("splice-all", sample_db, "-o", out, "--workers", "1", "--batch-size", "2",
            env=dict(os.environ, TORCHSPLICE_CHECKPOINT_SECONDS="0"))  # a checkpoint after each task
    parts = tmp_path / ".o.h5.parts"
    deadline = time.time() + 120
    held = lambda: (MotionDatabase.checkpoint_note(parts / "output.h5") or {}).get("tasks", 0)  # noqa: E731
    while time.time() < deadline and not held() and p.poll() is None:  # a task in the staged output
        time.sleep(0.05)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    if p.returncode == 0:
        pytest.skip("the job finished before it could be stopped")
    assert p.returncode == 143 and "Traceback" not in err
    assert "terminated" in err and "run the same command again to resume" in err
    q = cli("splice-all", sample_db, "-o", out, "--workers", "1", "--batch-size", "2")
    sout, err = q.communicate(timeout=300)
    assert q.returncode == 0, err
    assert "from an earlier run" in sout


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_splice_all_gives_the_same_bits_with_any_workers_and_threads(backend, sample_db, tmp_path, monkeypatch):
    """Each run in a process of its own, with 1 or 2 threads (OMP_NUM_THREADS) and 1 to 3 workers."""
    if backend == "torch":
        monkeypatch.setenv("TORCHSPLICE_BACKEND", "torch")
    runs = [dict(workers=1), dict(workers=2), dict(workers=3)]
    if backend == "compiled":  # each pair is spliced on its own: the batching does not matter either
        runs = [dict(r, batch_pairs=b) for r, b in zip(runs, (8, 3, 5))]
    digests = set()
    for n, extra in enumerate(runs):
        p = splice_all_process(sample_db, tmp_path / f"o{n}.h5", methods="splice,naive,cpmc", **extra,
                               env=dict(os.environ, OMP_NUM_THREADS=str(1 + n % 2)))
        _, err = p.communicate(timeout=600)
        assert p.returncode == 0, err
        digests.add(_digest(tmp_path / f"o{n}.h5"))
    assert len(digests) == 1


def test_a_ctrl_c_that_a_library_swallows_still_stops_the_job_as_an_interrupt():
    """Ctrl-C raised inside a weak reference's callback is printed and lost by Python (the Ray
    driver met it so); the handler records it, and the job's check between tasks raises it."""
    from torchsplice.cli.common import on_sigint, on_sigterm, stop_code, stopped
    from torchsplice.core.stop import Terminated, check_stop, clear_stop

    for handler, exc_type, code, word in ((on_sigint, KeyboardInterrupt, 130, "interrupted"),
                                          (on_sigterm, Terminated, 143, "terminated")):
        clear_stop()
        with pytest.raises(exc_type):
            handler(None, None)
        with pytest.raises(exc_type) as got:  # what was swallowed comes back here
            check_stop()
        assert (got.type is Terminated) == (exc_type is Terminated)
        assert stop_code(got.value) == code and stopped(got.value) == word
    clear_stop()
    check_stop()  # nothing asked: nothing raised


def test_7_windows_of_one_take_are_not_spliced_onto_each_other(sample_db, tmp_path):
    bvh = tmp_path / "bvh"
    export_clips(sample_db, ["walk_straight", "jog"], out=bvh)
    db = tmp_path / "win.h5"
    import_bvh([bvh], db, window=2, window_overlap=0.5)
    out = tmp_path / "sp.h5"
    summary = splice_all(db, out, locomotions="walk_straight*", actions="walk_straight*,jog*")
    assert any("windows of one take are not spliced onto each other" in why for why in summary.skipped)
    assert "windows of one take are not spliced onto each other" in "\n".join(summary.lines())
    with MotionDatabase.open(out) as d:
        table = d.clip_table()
        pairs = [(lab["locomotion.split_from"], lab["action.split_from"]) for lab in table.labels]
    assert pairs and all(a != b for a, b in pairs)
    assert {b for _, b in pairs} == {"jog"}  # every walk window onto every jog window, none onto a walk window
