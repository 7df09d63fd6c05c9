#!/usr/bin/env python
"""Print torchsplice's speed figures (targets in brackets are for a 2-core CPU machine).

    python scripts/benchmark.py                   # every section, real data from ../shared/mocap
    python scripts/benchmark.py --only parse,fk   # some sections
    python scripts/benchmark.py --device cuda     # tensor work on a GPU

Sections:
  parse  BVH parse speed on every real file: MB/s and frames/s            [>= 30 MB/s]
  fk     batched forward kinematics on real clips: joint-frames/s        [>= 10 million]
  db     HDF5 database: clips written and read per second, file size

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


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--mocap", type=Path, default=Path(os.environ.get("TORCHSPLICE_MOCAP", REPO.parent / "shared" / "mocap")),
                   help="folder of real BVH files (default ../shared/mocap or $TORCHSPLICE_MOCAP)")
    p.add_argument("--only", default="parse,fk,db", help="comma-separated sections: parse, fk, db")
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
