"""The ``retarget`` section of scripts/benchmark.py: retargeting between the shipped rigs, on
every real clip of ../shared/mocap (Bandai Namco, CMU in both namings, LAFAN1) and the sample.

Prints, with the issue's targets in brackets:
- round trips onto each other rig and back: mean joint error over the character's height, the
  mean over clips and the worst clip, analytic [<= 1%, worst < 2%], and with the feet fixed
  both ways (no target: each rig's feet stand at its own heights, so the legs bend twice)
- bone directions (analytic, the feet not fixed): bones whose mean angle from the source's
  exceeds 3 degrees, with figures                                                 [<= 3 deg]
- feet (fixed): clips whose foot skate exceeds the source's (scaled) + 1 cm/s, and how much
  further below its resting height a foot goes than the source's         [0 clips, <= 1 cm]
- cross-dataset splices (the job, three methods): the acting wrist's range of motion in the
  chest frame over arm length against the action's, and foot skate against the locomotion's
  [within 20%, skate within 1 cm/s]
- speed: joint-frames/s of retargeting on one core (feet fixed), and splice-all with actions
  that must be retargeted against the same actions already on the locomotions' skeleton
  (output frames/s, fresh processes)                                       [>= 1M/s, >= 0.8]
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from torchsplice.evaluation.metrics import foot_skate_stats  # noqa: E402
from torchsplice.evaluation.retargeting import (bone_angles, centimetres, feet_figures, round_trip_errors,  # noqa: E402
                                                wrist_spread)
from torchsplice.formats.bvh import read_bvh  # noqa: E402
from torchsplice.ops.feet import rig_heights  # noqa: E402
from torchsplice.ops.retarget import retarget_map, retarget_motions  # noqa: E402
from torchsplice.specs import detect_spec, load_spec  # noqa: E402
from torchsplice.specs.canonical import canonical_joints, canonical_legs  # noqa: E402

BANDAI = "bandai_namco_research_motiondataset"


class Rig:
    """The clips of one skeleton (one spec, one joint layout), with its roles and foot heights."""

    def __init__(self, name: str, motions: list, spec):
        self.name, self.motions, self.spec = name, motions, spec
        self.skeleton = motions[0].skeleton
        self.roles = spec.bind(self.skeleton)
        legs = list(canonical_legs(canonical_joints(self.roles, self.skeleton)))
        self.heights = rig_heights([m for m in motions if m.num_frames >= 3][:16], legs, int(self.roles.up_axis))
        self.cm = centimetres(spec)


def rigs_of(files: list[Path]) -> dict[str, Rig]:
    """Every real clip by rig (skeletons that match share one), and the sample."""
    from torchsplice.sample import sample_motions

    groups: dict[str, tuple[list, object]] = {}
    for f in files:
        m = read_bvh(f, dtype=torch.float64)
        spec = detect_spec(m.skeleton, f.name)
        for ms, _ in groups.values():
            if ms[0].skeleton.matches(m.skeleton):
                ms.append(m)
                break
        else:
            n = sum(k.split("#")[0] == spec.name for k in groups)
            groups[f"{spec.name}#{n}" if n else spec.name] = ([m], spec)
    out = {k: Rig(k, ms, spec) for k, (ms, spec) in groups.items()}
    out["sample"] = Rig("sample", [m.to(torch.float64) for m in sample_motions()], load_spec("sample"))
    return out


def _map(a: Rig, b: Rig):
    return retarget_map(a.skeleton, a.roles, b.skeleton, b.roles, a.name, b.name)


def round_trips(rigs: dict[str, Rig]) -> None:
    worst_all, worst_fixed, worst_mean = (0.0, ""), (0.0, ""), 0.0
    for a in rigs.values():
        for b in rigs.values():
            if a is b or a.spec.name == b.spec.name:
                continue
            there, back = _map(a, b), _map(b, a)
            plain = round_trip_errors(a.motions, there, back, a.roles)
            fixed = round_trip_errors(a.motions, there, back, a.roles, True, b.heights, a.heights)
            mean = lambda x: 100 * sum(x) / len(x)  # noqa: E731
            print(f"retarget round trip {a.name} ({len(a.motions)} clips) -> {b.name} -> back: {mean(plain):.2f}% of "
                  f"height (worst clip {100 * max(plain):.2f}%); feet fixed {mean(fixed):.2f}% "
                  f"(worst {100 * max(fixed):.2f}%)")
            worst_all = max(worst_all, (max(plain), f"{a.name} -> {b.name}"))
            worst_fixed = max(worst_fixed, (max(fixed), f"{a.name} -> {b.name}"))
            worst_mean = max(worst_mean, mean(plain))
    print(f"retarget round trips: the worst pair of rigs {worst_mean:.2f}% on average, the worst clip "
          f"{100 * worst_all[0]:.2f}% ({worst_all[1]})  [mean <= 1%, worst < 2%]; with the feet fixed both ways the "
          f"worst clip {100 * worst_fixed[0]:.2f}% ({worst_fixed[1]})")


def bones_and_feet(rigs: dict[str, Rig]) -> None:
    over, worst_limb, skate_over, lower, clips, extra = [], 0.0, [], 0.0, 0, []
    for a in rigs.values():
        for b in rigs.values():
            if a is b or a.spec.name == b.spec.name:
                continue
            rmap = _map(a, b)
            plain = retarget_motions(a.motions, rmap, False)
            fixed = retarget_motions(a.motions, rmap, True, b.heights)
            sums: dict[str, float] = {}
            for m, r in zip(a.motions, plain):
                for bone, deg in bone_angles(m, r, rmap, b.roles).items():
                    sums[bone] = sums.get(bone, 0.0) + deg / len(a.motions)
            spine = set(canonical_joints(b.roles, b.skeleton)["spine"])
            for bone, deg in sums.items():
                first = b.skeleton.names.index(bone.split("->")[0])
                if first not in spine:
                    worst_limb = max(worst_limb, deg)
                if deg > 3.0:
                    over.append(f"{a.name}->{b.name} {bone} {deg:.1f}")
            for m, r in zip(a.motions, fixed):
                f = feet_figures(m, r, rmap, a.roles, b.roles, a.cm, b.cm, b.heights)
                clips += 1
                lower = max(lower, f["lower"])
                extra.append(f["skate"] - f["skate_source"])
                if f["skate"] > f["skate_source"] + 1.0:
                    skate_over.append(f"{a.name}->{b.name} {m.name}: {f['skate_source']:.2f} -> {f['skate']:.2f} cm/s")
    print(f"retarget bones (analytic): every limb bone within {worst_limb:.1f} deg of the source's on average  "
          f"[<= 3 deg]; bones over 3 deg (spines of other joint counts bend otherwise): {len(over)}")
    for line in over[:12]:
        print(f"  {line}")
    if len(over) > 12:
        print(f"  ... {len(over) - 12} more")
    print(f"retarget feet fixed: foot skate {sum(extra) / len(extra):+.2f} cm/s against the source's on average over "
          f"{clips} clips, {len(skate_over)} clips more than + 1 cm/s; a foot sinks at most {max(lower, 0.0):.2f} cm "
          "further below its resting height than the source's  [0 clips, <= 1 cm]")
    for line in skate_over[:8]:
        print(f"  {line}")


def _job(args: list[str]) -> tuple[float, int]:
    """``torchsplice splice-all ARGS`` in a fresh process: (seconds, output frames)."""
    import h5py

    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "torchsplice", "splice-all", *args, "-q", "--force", "--restart"],
                       cwd=REPO, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"job failed: {r.stderr[-2000:]}")
    out = Path(args[args.index("-o") + 1])
    with h5py.File(out, "r") as f:
        return dt, int(f["clips/length"][:].sum())


def cross_dataset(mocap: Path, tmp: Path) -> None:
    from torchsplice.formats.importer import import_bvh
    from torchsplice.store.database import MotionDatabase

    bn, cmu, lafan = tmp / "bn.h5", tmp / "cmu.h5", tmp / "lafan.h5"
    import_bvh([mocap / BANDAI / f"dataset-2_{n}.bvh" for n in ("wave-right-hand_normal_001", "walk_normal_008",
                                                                 "walk-turn-left_normal_025")], bn)
    import_bvh([mocap / "cmu_graphics_lab" / "cmu_12_01_walk.bvh"], cmu)
    import_bvh([mocap / "lafan1_via_pypi_bvhtools"], lafan)
    cases = [("a Bandai Namco wave onto a CMU walk", cmu, "cmu_12_01_walk", bn, "dataset-2_wave-right-hand_normal_001"),
             ("a Bandai Namco wave onto a LAFAN1 locomotion", lafan, "test2", bn, "dataset-2_wave-right-hand_normal_001"),
             ("a LAFAN1 action onto a Bandai Namco turn", bn, "dataset-2_walk-turn-left_normal_025", lafan, "test")]
    for n, (what, ldb, loco, adb, action) in enumerate(cases):
        out = tmp / f"cross{n}.h5"
        _job([str(ldb), "--actions-db", str(adb), "--locomotions", loco, "--actions", action, "-o", str(out),
              "--method", "splice,naive,cpmc"])
        with MotionDatabase.open(ldb) as d:
            lm = d.read(loco, dtype=torch.float64)
            lroles = d.spec(d.clip_info(loco)["skeleton"]).bind(lm.skeleton)
            lcm = centimetres(d.spec(d.clip_info(loco)["skeleton"]))
        with MotionDatabase.open(adb) as d:
            am = d.read(action, dtype=torch.float64)
            aroles = d.spec(d.clip_info(action)["skeleton"]).bind(am.skeleton)
        side = max((0, 1), key=lambda s: wrist_spread(am, aroles, s))
        loco_skate = float(foot_skate_stats([lm], lroles).speed[0]) * lcm
        with MotionDatabase.open(out) as d:
            t = d.table()
            parts = []
            for i, method in enumerate(t["method"]):
                r = d.read(i, dtype=torch.float64)
                got = wrist_spread(r, lroles, side)
                # against the action over the frames the result plays (its action_frame column)
                used = d.read_frame_column(i, "action_frame").round().clip(0, am.num_frames - 1).astype(int)
                want = wrist_spread(am, aroles, side, used)
                skate = float(foot_skate_stats([r], lroles).speed[0]) * lcm
                parts.append(f"{method}: wrist range {got / want:.2f} of the action's, skate {skate:.2f} cm/s")
        print(f"retarget splice {what} (skate of the locomotion {loco_skate:.2f} cm/s): " + "; ".join(parts)
              + "  [0.8 to 1.2, skate within 1 cm/s]")


def speed(rigs: dict[str, Rig], mocap: Path, tmp: Path) -> None:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    src = max((r for r in rigs.values() if r.spec.name == "bandai_namco"), key=lambda r: len(r.motions))
    to = next(r for r in rigs.values() if r.spec.name == "lafan1")
    rmap = _map(src, to)
    chunk = src.motions[:64]
    retarget_motions(chunk[:2], rmap, True, to.heights)
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        retarget_motions(chunk, rmap, True, to.heights)
        best = min(best, time.perf_counter() - t0)
    jf = sum(m.num_frames for m in chunk) * to.skeleton.num_joints
    print(f"retarget speed: {len(chunk)} Bandai Namco clips onto LAFAN1, feet fixed, one core: {jf / best / 1e6:.2f}M "
          "joint-frames/s  [>= 1M]")
    torch.set_num_threads(threads)
    # splice-all: actions stored on another skeleton (retargeted there once) against the same actions
    # on the locomotions' own skeleton: the job must bring them back, once per action
    from torchsplice.formats.importer import import_bvh
    from torchsplice.retarget import retarget_clips

    bn, moved = tmp / "bn_all.h5", tmp / "moved.h5"
    import_bvh(sorted((mocap / BANDAI).glob("dataset-2_*.bvh")), bn)
    retarget_clips(bn, to="smpl22", out=moved, select="role:action")
    common = ["--locomotions", "role:locomotion,role:both", "--workers", "2"]
    same = min(_job([str(bn), "-o", str(tmp / "same.h5"), *common, "--actions", "role:action"]) for _ in range(2))
    cross = min(_job([str(bn), "--actions-db", str(moved), "-o", str(tmp / "cross.h5"), *common, "--actions", "*"])
                for _ in range(2))
    rate_same, rate_cross = same[1] / same[0], cross[1] / cross[0]
    print(f"retarget splice-all: actions on another skeleton (SMPL) {rate_cross:,.0f} output frames/s against "
          f"{rate_same:,.0f} on the locomotions' own = {rate_cross / rate_same:.2f}  [>= 0.8]")


def bench_retarget(files: list[Path], mocap: Path) -> None:
    if not any(BANDAI in str(f) for f in files):
        print("retarget: needs the real clips of ../shared/mocap (Bandai Namco, CMU, LAFAN1); skipped")
        return
    rigs = rigs_of(files)
    print("retarget rigs: " + ", ".join(f"{k} ({len(r.motions)} clips, {r.skeleton.num_joints} joints)"
                                         for k, r in rigs.items()))
    round_trips(rigs)
    bones_and_feet(rigs)
    with tempfile.TemporaryDirectory() as tmp:
        cross_dataset(mocap, Path(tmp))
        speed(rigs, mocap, Path(tmp))
