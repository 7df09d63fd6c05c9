"""The ``hands`` section of scripts/benchmark.py: hands kept out of the body (issue targets in
brackets), on real Bandai Namco clips.

Two jobs, each run as a user runs it (``torchsplice splice-all`` in a fresh process), with the
correction (the default) and without it (``--no-keep-hands-out``), alternating, best of two:
- ``hands``: runs, dashes and turning walks x raised hands, waves and calls (the pairs where an
  idle arm swings into a turned torso);
- ``default``: the default job (normal-style locomotions x every action).

For each it prints:
- clips with a hand inside the body where neither source has one, before and after  [<= 3%]
- results flagged ``self_penetration``, and the clips and frames corrected
- the feet: the largest change of any joint but the shoulders and elbows, and of the root [0]
- the acting arm's range in the chest's frame against the action's (5th percentile and
  worst), and the corrected clips' against the uncorrected                     [>= 0.8x]
- the idle arm's swing (its wrist's range in the chest's frame) against the locomotion's,
  on standing actions with one acting arm (5th percentile)                   [>= 0.5x]
- the cost: the job's pairs/s with the correction against without, and the figures (the body
  test, foot skate, floor, jerk) and the correction timed alone on the results (one core), as
  a share of the job's time                                                          [<= 10%]
"""

from __future__ import annotations

import json
import random
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from torchsplice.core.fk import forward_kinematics  # noqa: E402
from torchsplice.core.rotations import quat_apply, quat_conj  # noqa: E402
from torchsplice.ops.body import body_of  # noqa: E402
from torchsplice.ops.hands import arms_of  # noqa: E402
from torchsplice.job.source_figures import scales  # noqa: E402
from torchsplice.job.defaults import usable_cores  # noqa: E402
from torchsplice.job.task import SELF_PENETRATION, changed_arms  # noqa: E402
from torchsplice.ops.plausibility import figure_joints, penetration_of_frames  # noqa: E402
from torchsplice.ops.units import centimetres  # noqa: E402
from torchsplice.store.database import MotionDatabase  # noqa: E402

HANDS_JOB = ["--locomotions", "*run*,*dash*,*turn*", "--actions", "*wave*,*raise*,*bye*,*call*,*guide*"]
JOBS = {"hands": HANDS_JOB, "default": []}
LIMBS = ("left_arm", "right_arm")


# Held-back pairs: takes of the whole dataset that ../shared/mocap does not hold, so that nothing
# tuned on the shipped clips is measured on them.
HELD_LOCOMOTIONS = ("run", "dash", "walk-turn-left", "walk-turn-right")
HELD_ACTIONS = ("wave-", "raise-up-", "bye", "byebye", "guide")
HELD_SAMPLE = 40  # locomotions and actions each, drawn with a fixed seed: 1,600 pairs
GT_TAKES = 3  # the lowest-numbered held-back takes of each content and style in the ground-truth job
_TAKE = re.compile(r"^dataset-(\d+)_(.+?)_([^_]+)_(\d+)$")


def held_back(whole: Path, mocap: Path) -> list[Path]:
    """The Bandai Namco takes under ``whole`` (the whole dataset's BVH files) that are not among
    ``mocap``'s, by file name."""
    shipped = {p.name for p in mocap.rglob("*.bvh")} if mocap.is_dir() else set()
    return sorted(p for p in whole.rglob("*.bvh") if p.name not in shipped and _TAKE.match(p.stem))


def _content(p: Path) -> str:
    return _TAKE.match(p.stem)[2]


def hands_sample(files: list[Path], k: int = HELD_SAMPLE, seed: int = 0) -> list[Path]:
    """``k`` runs, dashes and turning walks and ``k`` standing arm actions (waves, raised hands,
    byes, guides) drawn from ``files`` with a fixed seed."""
    rng = random.Random(seed)
    locos = [p for p in files if _content(p) in HELD_LOCOMOTIONS]
    acts = [p for p in files if _content(p).startswith(HELD_ACTIONS)]
    return sorted(rng.sample(locos, min(k, len(locos))) + rng.sample(acts, min(k, len(acts))))


def ground_truth_sample(files: list[Path], takes: int = GT_TAKES) -> list[Path]:
    """The ground-truth sets among ``files``: per dataset, content (straight walks and the
    locomotions) and style, the ``takes`` lowest-numbered takes."""
    groups: dict[tuple, list[Path]] = {}
    for p in files:
        m = _TAKE.match(p.stem)
        if m[2] == "walk" or m[2] in HELD_LOCOMOTIONS or m[2].startswith("walk-"):
            groups.setdefault(m.groups()[:3], []).append(p)
    return sorted(p for g in groups.values() for p in sorted(g, key=lambda p: int(_TAKE.match(p.stem)[4]))[:takes])


def _job(db: Path, out: Path, args, correct: bool) -> float:
    cmd = [sys.executable, "-m", "torchsplice", "splice-all", str(db), "-o", str(out), "--force", "--restart", "-q",
           *args, *([] if correct else ["--no-keep-hands-out"])]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
    if r.returncode != 0:
        raise SystemExit(f"job failed: {r.stderr[-2000:]}")
    return time.perf_counter() - t0


def _wrist_ranges(clip, arms) -> torch.Tensor:
    """``(2,)`` each wrist's range in the chest's frame (the diagonal of its box)."""
    t = clip.local_translations()
    pos, grot = forward_kinematics(clip.rotations, t[:, 0], clip.skeleton.offsets, clip.skeleton.parents, t)
    rel = quat_apply(quat_conj(grot[:, arms.chest, None]).expand(-1, 2, 4), pos[:, list(arms.wrist)] - pos[:, arms.chest, None])
    return (rel.amax(0) - rel.amin(0)).norm(dim=-1)


def _figures(db: Path, raw: Path, out: Path, t_raw: float, t_out: float, cost: bool = True) -> None:
    with MotionDatabase.open(raw) as r, MotionDatabase.open(out) as o, MotionDatabase.open(db) as src:
        e0, e1 = r.clip_table().extra, o.clip_table().extra
        names = list(o.names)
        n = len(names)
        neither = (np.asarray(e1["penetration_locomotion"]) == 0) & (np.asarray(e1["penetration_action"]) == 0)
        before = ((np.asarray(e0["penetration"]) > 0) & neither).mean()
        after = ((np.asarray(e1["penetration"]) > 0) & neither).mean()
        flags = [sum("self_penetration" in f for f in e["flags"]) for e in (e0, e1)]
        corrected = np.asarray(e1["corrected_frames"])
        print(f"hands   {n} results: a hand inside where neither source has one {100 * before:.1f}% -> "
              f"{100 * after:.1f}%  [<= 3%]; flagged self_penetration {flags[0]} -> {flags[1]}; "
              f"{int((corrected > 0).sum())} clips corrected, {int(corrected.sum())} frames")
        sk = o.skeletons[0]
        roles = o.spec(0).bind(sk)
        body = body_of(sk, roles)
        arms = arms_of(sk, roles, body)
        others = [j for j in range(sk.num_joints) if j not in arms.moved]
        feet, kept, acting, idle, ranges = 0.0, [], [], [], {}

        def source_range(name):
            if name not in ranges:
                ranges[name] = _wrist_ranges(src.read(name), arms)
            return ranges[name]

        for b, name in enumerate(names):
            a, c = r.read(name), o.read(name)
            feet = max(feet, float((a.rotations[:, others] - c.rotations[:, others]).abs().max()),
                       float((a.root_translation - c.root_translation).abs().max()))
            got = _wrist_ranges(c, arms)
            if corrected[b]:
                kept.append(float((got / _wrist_ranges(a, arms).clamp_min(1e-9)).min()))
            act = [i for i, limb in enumerate(LIMBS) if limb in str(e1["acting"][b]).split(",")]
            if str(e1["timing"][b]) == "timewarp":
                act = [0, 1]
            if len(act) < 2 and act:
                i = 1 - act[0]
                idle.append(float(got[i] / source_range(str(e1["locomotion"][b]))[i].clamp_min(1e-9)))
            for i in act:
                acting.append(float(got[i] / source_range(str(e1["action"][b]))[i].clamp_min(1e-9)))
        print(f"hands   feet and lower body: largest change {feet:.3g}  [0]")
        _jerk(np.asarray(e0["jerk"]), np.asarray(e1["jerk"]), corrected > 0)
        if kept:
            print(f"hands   corrected clips' arm range against uncorrected: worst {min(kept):.2f}x, "
                  f"5th percentile {np.percentile(kept, 5):.2f}x  [>= 0.8x]")
        if acting:
            print(f"hands   acting arm's range against the action's: 5th percentile {np.percentile(acting, 5):.2f}x, "
                  f"median {np.median(acting):.2f}x, {100 * np.mean(np.array(acting) >= 0.8):.0f}% at >= 0.8x  [>= 0.8x]")
        if idle:
            print(f"hands   idle arm's swing against the locomotion's: 5th percentile {np.percentile(idle, 5):.2f}x, "
                  f"median {np.median(idle):.2f}x, {100 * np.mean(np.array(idle) >= 0.5):.0f}% at >= 0.5x  [>= 0.5x]")
        if cost:
            _cost(r, e0, names, body, arms, sk, t_raw, t_out)


def _cost(r, e0, names, body, arms, sk, t_raw: float, t_out: float) -> None:
    """The figures and the correction timed alone on the uncorrected results, as the job runs them
    (the compiled kernels on one thread, as in each of the job's workers)."""
    best, _ = _alone(r, e0, names, body, arms, sk)
    workers = usable_cores()  # the job's default: a worker per usable core, each computing its tasks' figures
    print(f"hands   cost: the job with the correction {len(names) / t_out:,.0f} pairs/s against {len(names) / t_raw:,.0f} "
          f"without ({100 * (t_out / t_raw - 1):+.1f}% time, whole process); the figures and the correction alone "
          f"{best:.3f} s on one core, over the job's {workers} workers {100 * best / workers / t_out:.1f}% of its "
          f"{t_out:.2f} s ({100 * best / t_out:.1f}% were they on one)  [<= 10%]")


WHOLE_SAMPLE = 5000
"""Results of the whole dataset's job whose figures and correction are timed alone (drawn with seed 0)."""


def _whole_cost(raw: Path, t_out: float) -> None:
    """The figures and the correction timed alone on :data:`WHOLE_SAMPLE` of the whole dataset's
    job's uncorrected results, scaled to all its frames, against the job's time."""
    with MotionDatabase.open(raw) as r:
        table = r.clip_table()
        pick = np.sort(np.random.default_rng(0).choice(len(r.names), min(WHOLE_SAMPLE, len(r.names)), replace=False))
        e0 = {c: np.asarray(table.extra[c])[pick] for c in ("penetration", "penetration_depth", "penetration_locomotion",
                                                           "penetration_action", "penetration_depth_locomotion",
                                                           "penetration_depth_action")}
        total = int(np.asarray(table.length).sum())
        sk = r.skeletons[0]
        roles = r.spec(0).bind(sk)
        body = body_of(sk, roles)
        best, frames = _alone(r, e0, [r.names[i] for i in pick], body, arms_of(sk, roles, body), sk)
    workers = usable_cores()
    scaled = best * total / frames
    print(f"hands   cost: the figures and the correction alone on {len(pick):,} of its results drawn at random "
          f"({frames:,} frames) {best:.2f} s on one core; at that rate its {total:,} frames take {scaled:.0f} s, over "
          f"its {workers} workers {100 * scaled / workers / t_out:.0f}% of its {t_out:.0f} s  [<= 10%]")


def _alone(r, e0, names, body, arms, sk) -> tuple[float, int]:
    """``(seconds, frames)``: the best of three of the figures and the correction, as the job runs
    them (torchsplice/job/task.py), on the results ``names`` of ``r`` (uncorrected; ``e0`` their
    columns), the compiled kernels on one thread."""
    from torchsplice.core.ranges import lengths_to_starts, ranges_to_rows
    from torchsplice.cpu import get_threads, set_threads
    from torchsplice.splice.backends import get_backend

    threads = get_threads()
    set_threads(1)

    clips = [r.read(n) for n in names]
    rot = np.concatenate([c.rotations.numpy() for c in clips])
    trans = np.concatenate([c.local_translations().numpy() for c in clips])
    lengths = np.array([c.num_frames for c in clips])
    backend = get_backend("compiled")
    share, depth = np.asarray(e0["penetration"]), np.asarray(e0["penetration_depth"])
    allowed = np.maximum(np.asarray(e0["penetration_depth_locomotion"]), np.asarray(e0["penetration_depth_action"]))
    often = np.maximum(np.asarray(e0["penetration_locomotion"]), np.asarray(e0["penetration_action"]))
    allowed[share > often + SELF_PENETRATION] = 0.0  # as the job: what the flag would report may keep nothing
    todo = np.flatnonzero((share > 0) & (depth > allowed))
    starts = lengths_to_starts(lengths)
    rows = ranges_to_rows(starts[todo], lengths[todo])
    per_cm = centimetres(r.spec(0).units)

    joints = figure_joints(sk, r.spec(0).bind(sk))
    up, per_metre, _ = scales(r.spec_json(0))

    out = rot.copy()  # corrected in place as the job does; set back to `rot` between repeats, untimed
    changed = np.zeros(len(rot), np.uint8)

    def once():  # as the job: corrected where they lie, the joints changed read back, those frames measured again
        _, _, deepest = backend.inside_body(out, trans, lengths, sk, body, per_frame=True)
        backend.figures(out, trans, lengths, float(clips[0].fps), sk, joints, up, per_metre)
        if len(todo):
            backend.keep_hands_out(out, trans, lengths[todo], float(clips[0].fps), sk, body, arms, allowed[todo] / per_cm,
                                   deepest=deepest, starts=starts[todo], out=out, changed=changed)
            again, _ = changed_arms(out, changed, arms.moved)  # and the arms the store keeps
            deepest[again] = backend.inside_body(out[again], trans[again], [len(again)], sk, body, per_frame=True)[2]
            penetration_of_frames(torch.from_numpy(deepest[rows]), lengths[todo], body.margin)
            out[again] = rot[again]
            changed[again] = 0

    times = []
    for _ in range(4):  # the first loads the kernels
        times.append(_timed(once))
    best = min(times[1:])
    set_threads(threads)
    return best, int(lengths.sum())


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _import(files: list[Path], db: Path) -> Path:
    folder = db.with_suffix("")
    folder.mkdir()
    for f in files:
        (folder / f.name).symlink_to(f.resolve())
    subprocess.run([sys.executable, "-m", "torchsplice", "import", str(folder), "-o", str(db), "--spec", "bandai_namco",
                    "-q"], check=True, cwd=REPO)
    return db


def _runs(db: Path, tmp: Path, label: str, args, repeats: int) -> tuple[Path, Path, float, float]:
    raw, out = tmp / f"{label}_raw.h5", tmp / f"{label}.h5"
    times = {True: [], False: []}
    for _ in range(repeats):
        for correct in (False, True):
            times[correct].append(_job(db, out if correct else raw, args, correct))
    return raw, out, min(times[False]), min(times[True])


GT_JOB = ["--method", "splice", "--force-locomotion", "--locomotions", "label:style=normal",
          "--locomotions", "label:content=walk-*,label:content=run,label:content=dash", "--actions", "label:content=walk"]


def _ground_truth(files: list[Path], tmp: Path) -> None:
    """The ground-truth error on held-back takes (a style's straight walk spliced onto a
    normal-style turn or run, against the style captured turning or running), with the
    correction and without."""
    db = _import(ground_truth_sample(files), tmp / "gt_sources.h5")
    raw, out, _, _ = _runs(db, tmp, "gt", GT_JOB, 1)
    got = {}
    for label, path in (("without", raw), ("with", out)):
        report = tmp / f"gt_{label}.json"
        subprocess.run([sys.executable, "-m", "torchsplice", "evaluate", str(path), "-o", str(tmp / f"gt_{label}.md"),
                        "--no-pictures", "--json", str(report), "-q", "--force"], check=True, cwd=REPO)
        doc = json.loads(report.read_text())
        got[label] = ({c["name"]: c["gt_error"] for c in doc["clips"] if c["gt_error"] is not None},
                      doc["aggregates"]["splice"]["gt_by_type"], doc["units"])
    (before, types, units), (after, types_after, _) = got["without"], got["with"]
    with MotionDatabase.open(out) as o:
        e = o.clip_table().extra
        moved = {str(n) for n, k in zip(o.names, np.asarray(e["corrected_frames"])) if k > 0}
    changed = sorted(n for n in after if n in moved)
    worse = [after[n] - before[n] for n in changed]
    by_type = ", ".join(f"{t} {types[t]['mean']:.2f} -> {types_after[t]['mean']:.2f}" for t in sorted(types) if t != "all")
    print(f"hands   held-back ground truth: {len(after)} triples; error {np.mean(list(before.values())):.2f} -> "
          f"{np.mean(list(after.values())):.2f} {units} with the correction [no worse] ({by_type}); "
          f"{len(changed)} triples corrected"
          + (f", their error changed by {np.mean(worse):+.2f} on average, {max(worse):+.2f} at worst" if changed else ""))


WHOLE_JOB = ["--locomotions", "label:style=normal", "--actions", "role:action", "--store", "alignment"]


def _jerk(before: np.ndarray, after: np.ndarray, moved: np.ndarray) -> None:
    """The corrected clips' jerk (the ``jerk`` column) against the same clips uncorrected: a pop
    where a correction starts or ends, or an elbow snapping straight, shows as jerk."""
    if moved.any():
        ratio = after[moved] / np.maximum(before[moved], 1e-12)
        print(f"hands   corrected clips' jerk against uncorrected: median {np.median(ratio):.2f}x, 90th percentile "
              f"{np.percentile(ratio, 90):.2f}x, 99th {np.percentile(ratio, 99):.2f}x, worst {ratio.max():.1f}x")


def _columns(raw: Path, out: Path, t_raw: float, t_out: float) -> None:
    """The figures before and after from the output columns alone (for jobs too large to read
    every clip back): a hand inside where neither source has one, flags, the clips corrected,
    the feet's figures (the same bits: only the arms move), and the corrected clips' jerk
    against uncorrected (a pop shows as jerk)."""
    cols = ("penetration", "penetration_locomotion", "penetration_action", "corrected_frames", "foot_skate",
            "foot_slide", "floor", "jerk", "flags")
    e = []
    for path in (raw, out):
        with MotionDatabase.open(path) as d:
            extra = d.clip_table().extra
            e.append({c: np.asarray(extra[c]) for c in cols})
    e0, e1 = e
    neither = (e1["penetration_locomotion"] == 0) & (e1["penetration_action"] == 0)
    inside = [100 * ((x["penetration"] > 0) & neither).mean() for x in e]
    flags = [sum("self_penetration" in str(f) for f in x["flags"]) for x in e]
    corrected = e1["corrected_frames"]
    moved = corrected > 0
    feet = max(float(np.nanmax(np.abs(e1[c] - e0[c]), initial=0.0)) for c in ("foot_skate", "foot_slide", "floor"))
    n = len(corrected)
    print(f"hands   {n:,} results: a hand inside where neither source has one {inside[0]:.2f}% -> {inside[1]:.2f}%  "
          f"[<= 3%]; flagged self_penetration {flags[0]:,} -> {flags[1]:,}; {int(moved.sum()):,} clips corrected, "
          f"{int(corrected.sum()):,} frames; feet figures' largest change {feet:.3g}  [0]")
    _jerk(e0["jerk"], e1["jerk"], moved)
    print(f"hands   the job with the correction {n / t_out:,.0f} pairs/s against {n / t_raw:,.0f} without "
          f"({100 * (t_out / t_raw - 1):+.1f}% time, whole process, one run each)")


def bench_hands(mocap: Path, db: Path | None = None, whole: Path | None = None, whole_db: Path | None = None) -> None:
    """The two jobs on ``mocap``'s Bandai Namco clips; with ``whole`` (a folder of the whole
    dataset's BVH files), also the held-back pairs and the held-back ground truth."""
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if db is None:
            folder = mocap / "bandai_namco_research_motiondataset"
            if not folder.is_dir():
                print(f"hands   skipped: no Bandai Namco clips at {folder}")
                return
            db = tmp / "bn.h5"
            subprocess.run([sys.executable, "-m", "torchsplice", "import", str(folder), "-o", str(db), "--spec",
                            "bandai_namco", "-q"], check=True, cwd=REPO)
        for label, args in JOBS.items():
            raw, out, t_raw, t_out = _runs(db, tmp, label, args, 2)
            print(f"hands   job '{label}' ({' '.join(args) or 'the default selections'}):")
            _figures(db, raw, out, t_raw, t_out)
        if whole_db is not None:
            raw, out, t_raw, t_out = _runs(whole_db, tmp, "whole", WHOLE_JOB, 1)
            print(f"hands   {whole_db.name}: {' '.join(WHOLE_JOB)}:")
            _columns(raw, out, t_raw, t_out)
            _whole_cost(raw, t_out)
        if whole is None:
            return
        files = held_back(whole, mocap)
        print(f"hands   held back: {len(files)} takes of {whole} not in {mocap}")
        sample = _import(hands_sample(files), tmp / "held_sources.h5")
        raw, out, t_raw, t_out = _runs(sample, tmp, "held", HANDS_JOB, 1)
        print(f"hands   held-back pairs: {HELD_SAMPLE} runs, dashes and turns x {HELD_SAMPLE} raised hands, waves, "
              "byes and guides, drawn with seed 0:")
        _figures(sample, raw, out, t_raw, t_out, cost=False)
        _ground_truth(files, tmp)


if __name__ == "__main__":
    import argparse

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mocap", type=Path, nargs="?", default=REPO.parent / "shared" / "mocap")
    p.add_argument("--db", type=Path, default=None, help="the Bandai Namco clips of mocap, already imported")
    p.add_argument("--held-back", type=Path, default=None, help="the whole Bandai Namco dataset's BVH folder")
    p.add_argument("--whole-db", type=Path, default=None,
                   help="the whole dataset imported: also its 300k-pair job (normal-style locomotions x every action)")
    p.add_argument("--skip-jobs", action="store_true", help="only the held-back and whole-dataset measures")
    a = p.parse_args()
    if a.skip_jobs:
        JOBS.clear()  # the held-back measures alone
    bench_hands(a.mocap, a.db, a.held_back, a.whole_db)
