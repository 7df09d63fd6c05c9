#!/usr/bin/env python
"""Print torchsplice's speed figures (targets in brackets are for a 2-core CPU machine).

    python scripts/benchmark.py                   # every section, real data from ../shared/mocap
    python scripts/benchmark.py --only parse,fk   # some sections
    python scripts/benchmark.py --device cuda     # tensor work on a GPU

Sections:
  parse  BVH parse speed on every real file: MB/s and frames/s            [>= 30 MB/s]
  fk     batched forward kinematics on real clips: joint-frames/s        [>= 10 million]
  db     HDF5 database: clips written and read per second, file size
  splice per-stage throughput (grid cells/s, DP cells/s, Horn frames/s) and splices/s for
         batches of real pairs (Bandai Namco walks, up to 250 frames), beside a per-pair NumPy
         version of the same method (scripts/numpy_reference.py)   [>= 100x it, >= 200 splices/s]
  job    the n x m database job end to end on real clips: splices/s and peak memory

Without real data (no ../shared/mocap and no TORCHSPLICE_MOCAP), the built-in synthetic
sample stands in and the figures say so. Timings are the best of several repeats.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))

from torchsplice.io.bvh import format_bvh, read_bvh  # noqa: E402
from torchsplice.io.database import MotionDatabase  # noqa: E402
from torchsplice.kinematics.fk import forward_kinematics  # noqa: E402


def best_of(fn, repeats: int = 5) -> float:
    """Seconds of the fastest of ``repeats`` calls (after one warm-up call)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def real_files(mocap: Path) -> list[Path]:
    return sorted(mocap.rglob("*.bvh")) if mocap.is_dir() else []


def sample_files(tmp: Path) -> list[Path]:
    """The built-in sample written out as BVH, for machines without the real data."""
    from torchsplice.io.sample import sample_motions

    paths = []
    for m in sample_motions():
        p = tmp / f"{m.name}.bvh"
        p.write_text(format_bvh(m))
        paths.append(p)
    return paths


def bench_parse(files: list[Path]) -> None:
    size = sum(f.stat().st_size for f in files)
    frames = 0

    def run():
        nonlocal frames
        frames = sum(read_bvh(f).num_frames for f in files)

    dt = best_of(run, repeats=3)
    print(f"parse  {len(files)} files, {size / 1e6:.1f} MB: {size / 1e6 / dt:.1f} MB/s, "
          f"{frames / dt:,.0f} frames/s  [target >= 30 MB/s]")
    big = max(files, key=lambda f: f.stat().st_size)
    dt = best_of(lambda: read_bvh(big), repeats=3)
    print(f"parse  largest file {big.name} ({big.stat().st_size / 1e6:.1f} MB): {big.stat().st_size / 1e6 / dt:.1f} MB/s")


def bench_fk(files: list[Path], device: str) -> None:
    motions = [read_bvh(f) for f in files]
    by_skeleton: dict[tuple, list] = {}
    for m in motions:
        by_skeleton.setdefault(m.skeleton.names, []).append(m)
    group = sorted(max(by_skeleton.values(), key=len), key=lambda m: -m.num_frames)[:32]
    T = min(250, min(m.num_frames for m in group))  # the clips' common length, up to 250 frames
    sk = group[0].skeleton
    for dtype in (torch.float32, torch.float64):
        rot = torch.stack([m.rotations[:T] for m in group]).to(device, dtype)
        root = torch.stack([m.root_translation[:T] for m in group]).to(device, dtype)
        trans = None if group[0].translations is None else torch.stack([m.translations[:T] for m in group]).to(device, dtype)
        off = sk.offsets.to(device, dtype)

        def run():
            forward_kinematics(rot, root, off, sk.parents, trans)
            if device.startswith("cuda"):
                torch.cuda.synchronize()

        dt = best_of(run)
        n = rot.shape[0] * rot.shape[1] * rot.shape[2]
        print(f"fk     {str(dtype).removeprefix('torch.')} {tuple(rot.shape[:3])} (clips, frames, joints) on {device}: "
              f"{n / dt / 1e6:.1f} million joint-frames/s  [target >= 10 million]")


def bench_db(files: list[Path]) -> None:
    motions = [read_bvh(f) for f in files]
    frames = sum(m.num_frames for m in motions)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.h5"

        def write():
            with MotionDatabase.create(path, overwrite=True) as db:
                for m in motions:
                    db.append(m)

        dt_w = best_of(write, repeats=2)

        def read():
            with MotionDatabase.open(path) as db:
                for b in db.batches(batch_size=32):
                    pass

        dt_r = best_of(read, repeats=2)
        mb = path.stat().st_size / 1e6
    print(f"db     {len(motions)} clips, {frames:,} frames: write {len(motions) / dt_w:,.0f} clips/s "
          f"({frames / dt_w:,.0f} frames/s), padded batch read {frames / dt_r:,.0f} frames/s, file {mb:.1f} MB")


def bench_splice(files: list[Path], device: str) -> None:
    import numpy as np

    import numpy_reference as ref
    from torchsplice.align.distance import distance_grid
    from torchsplice.align.horn import horn_rotation
    from torchsplice.align.timewarp import timewarp
    from torchsplice.core.rotations import quat_angle
    from torchsplice.io.spec import detect_spec
    from torchsplice.splice import SpliceOptions, splice_pairs

    walks = [f for f in files if "walk" in f.stem and f.stem.startswith("dataset-")] or files
    clips = [read_bvh(f) for f in walks]
    long = [m.slice(0, 250) for m in clips if m.num_frames >= 200]  # pairs of ~250-frame clips
    clips = long if len(long) >= 8 else [m.slice(0, 250) if m.num_frames > 250 else m for m in clips if m.num_frames >= 60]
    spec = detect_spec(clips[0].skeleton, walks[0].name)
    roles = spec.bind(clips[0].skeleton)
    pairs = [(a, b) for a in clips for b in clips][:128]
    mean_frames = sum(a.num_frames + b.num_frames for a, b in pairs) / (2 * len(pairs))
    print(f"splice {len(clips)} clips, {len(pairs)} pairs of about {mean_frames:.0f} frames (spec {spec.name}), on {device}")
    opt = SpliceOptions(force=True, device=device)
    sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)

    # per stage, on one batch of 64 pairs
    B, T = 64, 250
    g = torch.Generator().manual_seed(0)
    a = torch.randn(B, T, 3, 3, generator=g).to(device)
    b = torch.randn(B, T, 3, 3, generator=g).to(device)
    ha, hb = torch.rand(B, T, generator=g).to(device), torch.rand(B, T, generator=g).to(device)
    dt = best_of(lambda: (distance_grid(a, b, heading_a=ha, heading_b=hb, max_heading_deviation=1.0), sync()), 3)
    print(f"splice   distance grid: {B * T * T / dt / 1e6:.1f} million cells/s")
    grid = distance_grid(a, b, heading_a=ha, heading_b=hb, max_heading_deviation=1.0)
    dt = best_of(lambda: (timewarp(grid, max_run=3), sync()), 3)
    print(f"splice   DP timewarp:   {B * T * T / dt / 1e6:.1f} million cells/s")
    src, tgt = torch.randn(B * T, 5, 3, generator=g).to(device), torch.randn(B * T, 5, 3, generator=g).to(device)
    dt = best_of(lambda: (horn_rotation(src, tgt), sync()), 3)
    print(f"splice   Horn by SVD:   {B * T / dt / 1e6:.2f} million frames/s")

    for n in (32, 64, 128):
        batch = pairs[:n]
        dt = best_of(lambda: (splice_pairs(batch, spec, options=opt), sync()), 2)
        print(f"splice   end to end, batch of {n}: {n / dt:,.0f} splices/s  [target >= 200]")
    batched_per_pair = dt / len(batch)

    # the per-pair NumPy reference, on two pairs; it must agree with the batched code
    k = 2
    sample = pairs[1:1 + k]
    t0 = time.perf_counter()
    outs = []
    for lo, ac in sample:
        def arrays(m):
            return {"rot": m.rotations.double().numpy(), "trans": m.local_translations().double().numpy()}
        outs.append(ref.splice_pair(arrays(lo), arrays(ac), roles, lo.skeleton.parents, lo.fps))
    ref_per_pair = (time.perf_counter() - t0) / k
    ours = splice_pairs(sample, spec, options=SpliceOptions(force=True, dtype=torch.float64))
    diff = max(float(quat_angle(r.motion.rotations, torch.from_numpy(o[0])).max()) for r, o in zip(ours, outs))
    curve = max(float(np.abs(r.curve.numpy() - o[2]).max()) for r, o in zip(ours, outs))
    print(f"splice   NumPy per-pair reference: {ref_per_pair:.2f} s per pair; batched: {batched_per_pair * 1e3:.1f} ms "
          f"per pair = {ref_per_pair / batched_per_pair:,.0f}x  [target >= 100x]")
    print(f"splice   agreement with the reference: rotations within {np.degrees(diff):.2g} deg, curves within {curve:.2g} frames")


def _job_child(files: list[str], tmp: str, queue) -> None:
    """Run one splice-all job in a fresh process; report time, pairs and peak RSS."""
    import resource

    from torchsplice.cli import main as cli

    db, out = Path(tmp) / "in.h5", Path(tmp) / "out.h5"
    cli(["import", *files, "-o", str(db), "-q"])
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    from torchsplice.job import JobConfig, SpliceJob

    summary = SpliceJob(JobConfig(database=db, output=out, locomotions=("*",), actions=("*",)), progress=False).run()
    queue.put((time.perf_counter() - t0, summary.spliced, summary.compute_seconds, base,
               resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, out.stat().st_size))


def bench_job(files: list[Path]) -> None:
    import multiprocessing as mp

    walks = [str(f) for f in files if "walk" in f.stem and f.stem.startswith("dataset-2")][:16] or [str(f) for f in files[:16]]
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    with tempfile.TemporaryDirectory() as tmp:
        p = ctx.Process(target=_job_child, args=(walks, tmp, queue))
        p.start()
        seconds, spliced, compute, base, peak, size = queue.get()
        p.join()
    print(f"job    {len(walks)} x {len(walks)} real clips (self-pairs skipped): {spliced} splices in {seconds:.1f} s "
          f"= {spliced / seconds:,.0f} splices/s end to end ({spliced / compute:,.0f}/s in splicing); "
          f"peak memory {peak / 1024:.0f} MB ({(peak - base) / 1024:+.0f} MB over the loaded interpreter); output {size / 1e6:.1f} MB")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--mocap", type=Path, default=Path(os.environ.get("TORCHSPLICE_MOCAP", REPO.parent / "shared" / "mocap")),
                   help="folder of real BVH files (default ../shared/mocap or $TORCHSPLICE_MOCAP)")
    p.add_argument("--only", default="parse,fk,db,splice,job", help="comma-separated sections: parse, fk, db, splice, job")
    p.add_argument("--device", default="cpu", help="device for tensor work (cpu, cuda)")
    args = p.parse_args()
    sections = set(args.only.split(","))
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, device {args.device}")
    with tempfile.TemporaryDirectory() as tmp:
        files = real_files(args.mocap)
        if files:
            print(f"data: {len(files)} real BVH files from {args.mocap}")
        else:
            files = sample_files(Path(tmp))
            print(f"data: no real data at {args.mocap}; using the built-in synthetic sample ({len(files)} clips)")
        if "parse" in sections:
            bench_parse(files)
        if "fk" in sections:
            bench_fk(files, args.device)
        if "db" in sections:
            bench_db(files)
        if "splice" in sections:
            bench_splice(files, args.device)
        if "job" in sections:
            bench_job(files)
    return 0


if __name__ == "__main__":
    sys.exit(main())
