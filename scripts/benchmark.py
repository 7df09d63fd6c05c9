#!/usr/bin/env python
"""Print torchsplice's speed figures; targets in brackets are for a 2-core CPU machine.

    python scripts/benchmark.py                   # every section, real data from ../shared/mocap
    python scripts/benchmark.py --only stages,job # some sections
    python scripts/benchmark.py --device cuda     # the torch path on a GPU (stages, job, the store's assembly)

Sections:
  parse   BVH parse speed on every real file: MB/s and frames/s                  [>= 30 MB/s]
  stages  per-stage throughput of the compiled CPU splicer on one core: grid cells/s, DP
          cells/s, Horn frames/s, FK joint-frames/s (beside torch's), database write MB/s
  splice  splices/s of the compiled splicer on real pairs, beside a careful per-pair NumPy
          splicer of the same method (scripts/numpy_reference.py) timed in the same run, and
          their agreement                                                      [>= 50x the peer]
  job     `torchsplice splice-all` as a user runs it, on n x n real walks and turns: whole-process
          splices/s (interpreter start included) for a small and a big job, the marginal rate
          (extra splices over extra seconds), peak memory of both; the share of the big job's time
          its test of a hand inside the body takes (run again on its results); then the big job
          again while one other CPU-bound process runs, started here for a bounded time
          [>= 1,000/s marginal, >= 800/s whole on 60 x 60, body test and correction <= 10%,
          >= 40% of quiet when busy]
  engines local workers on one core and on all, and Ray                     [>= 1.8x, Ray < 10%]
  mix     the real workload: normal-style locomotions x every action clip (nearly all standing):
          standing against time-aligned output frames/s on the same locomotions, the whole job's
          pairs/s, peak disk and memory, and a job killed three times and resumed (its total time
          and its output against the uninterrupted run's); --mix-db runs it on a whole dataset
          [>= 0.8, >= 1,300 pairs/s, <= 1.2x disk, <= 1.15x time when killed thrice]
  retarget  between the shipped rigs on every real clip (scripts/bench_retarget.py): round trips,
          bone directions, feet, cross-dataset splices, joint-frames/s, and splice-all with
          actions on another skeleton against the same actions on the locomotions' own
          [<= 1% (worst < 2%), <= 3 deg, skate <= +1 cm/s, >= 1M/s, >= 0.8]
  humanml3d the HumanML3D export and import (scripts/bench_humanml3d.py): export clips/s with the
          files, the features alone and the files alone; on every real clip, the format's
          properties and the import's round trip        [>= 2,000 clips/s, 1e-5 m, 1e-6 m, 1e-4 m]
  hands   hands kept out of the body (scripts/bench_hands.py), on Bandai Namco runs, dashes and turns
          x raised hands and waves, and on the default job: a hand inside where neither source has
          one, before and after; flags; the feet (unchanged); the acting arm's range and the idle
          arm's swing; the job's pairs/s with the correction against without, and the figures and
          the correction alone as a share of the job's time; --held-back adds the same on 1,600 pairs
          of takes that --mocap does not hold, and the ground-truth error there with and without
          the correction; --mix-db adds the whole dataset's 300k-pair job, before and after
          (from its columns)       [<= 3%, 0, >= 0.8x, >= 0.5x, <= 10%, no worse]
  packed  peak memory of a packed .npz export of 1,000, 4,000 and 10,000 clips   [flat]
  store   alignment stores against motion stores (scripts/bench_store.py): size, job time, reads bit
          for bit, assembly clips/s per core, MotionDataset frames/s, SIGKILL and resume, streaming
          HumanML3D features against the export and a T2M-GPT-style loader; --big-db: the default job
          on a whole dataset                    [>= 10x smaller, <= 1.0x time, >= 1x reads, <= 30 min, <= 12 GB]
  startup each command's wall time on a small database (the sample), best of five, beside the
          interpreter alone and the interpreter importing torch: what a command adds of its own
          [--help <= 0.5 s; a command reading clips <= torch's import + 0.8 s]

Without real data (no ../shared/mocap and no TORCHSPLICE_MOCAP), the built-in synthetic
sample stands in and the figures say so. Timings are the best of several repeats; the machine
is shared, so compare ratios measured in one run rather than figures from different runs.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))

from bench_record import WHOLE, Recorder  # noqa: E402
from torchsplice.formats.bvh import format_bvh, read_bvh  # noqa: E402


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
    from torchsplice.sample import sample_motions

    paths = []
    for m in sample_motions():
        p = tmp / f"{m.name}.bvh"
        p.write_text(format_bvh(m))
        paths.append(p)
    return paths


def walks_and_turns(files: list[Path], n: int) -> list[Path]:
    """Up to ``n`` Bandai Namco walks and turns (longest first), or any clips without them."""
    walks = [f for f in files if re.match(r"dataset-\d_walk", f.stem)]
    if not walks:
        return files[:n]
    return sorted(walks, key=lambda f: -f.stat().st_size)[:n]


# ----------------------------------------------------------------------------------- sections
def bench_parse(files: list[Path]) -> None:
    size = sum(f.stat().st_size for f in files)
    frames = 0

    def run():
        nonlocal frames
        frames = sum(read_bvh(f).num_frames for f in files)

    dt = best_of(run, repeats=3)
    print(f"parse   {len(files)} files, {size / 1e6:.1f} MB: {size / 1e6 / dt:.1f} MB/s, {frames / dt:,.0f} frames/s  [>= 30 MB/s]")


def _bank(files: list[Path]):
    from torchsplice.cpu.bank import ClipBank
    from torchsplice.specs import detect_spec

    clips = [read_bvh(f) for f in files]
    spec = detect_spec(clips[0].skeleton, files[0].name)
    roles = spec.bind(clips[0].skeleton)
    return clips, spec, roles, ClipBank.from_motions(clips, clips[0].skeleton, roles)


def bench_stages(files: list[Path], device: str) -> None:
    from numba import njit

    from torchsplice.align.distance import distance_grid
    from torchsplice.align.horn import horn_rotation
    from torchsplice.align.timewarp import timewarp
    from torchsplice.cpu import get_threads, set_threads
    from torchsplice.cpu.fk import fk_clips
    from torchsplice.cpu.grid import distance_row_block
    from torchsplice.cpu.horn import horn_batch
    from torchsplice.cpu.timewarp import dp_pair
    from torchsplice.store.database import MotionDatabase
    from torchsplice.core.fk import forward_kinematics

    clips, spec, roles, bank = _bank(walks_and_turns(files, 16))
    n = len(clips)
    pairs = [(a, b) for a in range(n) for b in range(n) if a != b][:64]
    li, ai = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    cells = float((bank.lengths[li] * bank.lengths[ai]).sum())
    threads = get_threads()
    set_threads(1)
    try:
        if device == "cpu":
            @njit(cache=False, nogil=True)
            def grids(feat, starts, lengths, li, ai):
                s = 0.0
                for b in range(li.shape[0]):
                    na, nb = lengths[li[b]], lengths[ai[b]]
                    g = np.empty((na, nb))
                    distance_row_block(feat, starts[li[b]], na, starts[ai[b]], nb, 1.0, g)
                    s += g[0, 0]
                return s

            @njit(cache=False, nogil=True)
            def dps(starts, lengths, li, ai, grid):
                s = 0.0
                for b in range(li.shape[0]):
                    na, nb = lengths[li[b]], lengths[ai[b]]
                    cells_ = np.empty((na + nb, 2), np.int64)
                    s += dp_pair(grid, 0, na, nb, 3, cells_)[1]
                return s

            dt = best_of(lambda: grids(bank.feat, bank.starts, bank.lengths, li, ai), 3)
            print(f"stages  distance grid, compiled: {cells / dt / 1e6:,.0f} million cells/s per core")
            T = int(bank.lengths.max())
            rng = np.random.default_rng(0)
            grid = rng.random((T, T))
            dt = best_of(lambda: dps(bank.starts, bank.lengths, li, ai, grid), 3)
            print(f"stages  DP timewarp (7 states), compiled: {cells / dt / 1e6:,.0f} million cells/s per core  [aim >= 60]")
            N = 200_000
            src, tgt = rng.standard_normal((N, 4, 3)), rng.standard_normal((N, 4, 3))
            out = np.empty((N, 4))
            w = np.full(4, 0.25)
            dt = best_of(lambda: horn_batch(src, tgt, w, out), 3)
            print(f"stages  Horn rotation (4 points, closed form), compiled: {N / dt / 1e6:.1f} million frames/s per core")
            pos, grot = np.empty_like(bank.trans), np.empty_like(bank.rot)
            dt = best_of(lambda: fk_clips(bank.rot, bank.trans, bank.joints.parents, bank.starts, bank.lengths, pos, grot), 3)
            print(f"stages  forward kinematics, compiled: {bank.rot.shape[0] * bank.rot.shape[1] / dt / 1e6:.1f} million joint-frames/s per core")
        torch.set_num_threads(1)
        # the torch implementations, on the same machine (and the GPU with --device cuda)
        sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)
        B, T = 64, 250
        g = torch.Generator().manual_seed(0)
        a, b = torch.randn(B, T, 3, 3, generator=g).to(device), torch.randn(B, T, 3, 3, generator=g).to(device)
        ha, hb = torch.rand(B, T, generator=g).to(device), torch.rand(B, T, generator=g).to(device)
        dt = best_of(lambda: (distance_grid(a, b, heading_a=ha, heading_b=hb, max_heading_deviation=1.0), sync()), 3)
        print(f"stages  distance grid, torch on {device}: {B * T * T / dt / 1e6:,.0f} million cells/s")
        grid_t = distance_grid(a, b, heading_a=ha, heading_b=hb, max_heading_deviation=1.0)
        dt = best_of(lambda: (timewarp(grid_t, max_run=3, backend="torch"), sync()), 2)
        print(f"stages  DP timewarp, torch on {device}: {B * T * T / dt / 1e6:,.1f} million cells/s")
        src_t, tgt_t = torch.randn(B * T, 4, 3, generator=g).to(device), torch.randn(B * T, 4, 3, generator=g).to(device)
        dt = best_of(lambda: (horn_rotation(src_t, tgt_t), sync()), 3)
        print(f"stages  Horn rotation (SVD), torch on {device}: {B * T / dt / 1e6:.2f} million frames/s")
        rot = torch.from_numpy(bank.rot).float().to(device)
        tr = torch.from_numpy(bank.trans).float().to(device)
        off = clips[0].skeleton.offsets.float().to(device)
        dt = best_of(lambda: (forward_kinematics(rot, tr[:, 0], off, clips[0].skeleton.parents, tr), sync()), 3)
        print(f"stages  forward kinematics, torch on {device} (1 thread on cpu): {rot.shape[0] * rot.shape[1] / dt / 1e6:.1f} million joint-frames/s")
    finally:
        set_threads(threads)
        torch.set_num_threads(os.cpu_count() or 1)
    # database write rate, as the job writes: packed clips, raw and with the default compression
    N = bank.rot.shape[0]
    rot32, tr32 = bank.rot.astype(np.float32), bank.trans.astype(np.float32)
    mb = (rot32.nbytes + tr32.nbytes) / 1e6
    with tempfile.TemporaryDirectory() as tmp:
        for comp in (None, "auto", "gzip"):
            def write():
                with MotionDatabase.create(Path(tmp) / "w.h5", overwrite=True, compression=comp, chunk_frames=256) as db:
                    db.append_packed(clips[0].skeleton, rot32, tr32[:, 0], tr32, bank.lengths, [f"c{i}" for i in range(n)], 30.0)
            dt = best_of(write, 3)
            size = (Path(tmp) / "w.h5").stat().st_size / 1e6
            print(f"stages  database write, compression {comp or 'none'}: {mb / dt:,.0f} MB/s of frames ({N:,} frames, file {size:.1f} MB)")


def bench_splice(files: list[Path], device: str) -> None:
    import numpy_reference as ref

    from torchsplice.core.rotations import quat_angle
    from torchsplice.cpu import get_threads
    from torchsplice.cpu.bank import splice_bank
    from torchsplice.splice import SpliceOptions, splice_pairs
    from torchsplice.splice.options import align_kwargs
    from torchsplice.splice.options import AlignOptions

    chosen = walks_and_turns(files, 60)
    clips, spec, roles, bank = _bank(chosen)
    n = len(clips)
    pairs = [(a, b) for a in range(n) for b in range(n) if a != b]
    li, ai = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    mean = float((bank.lengths[li] + bank.lengths[ai]).mean() / 2)
    print(f"splice  {n} clips, {len(pairs)} pairs of about {mean:.0f} frames (spec {spec.name})")
    kw = align_kwargs(AlignOptions(), clips[0].fps)
    if device == "cpu":
        dt = best_of(lambda: splice_bank(bank, li, ai, **kw), 2)
        ours = len(pairs) / dt
        print(f"splice  compiled splicer, {get_threads()} threads: {ours:,.0f} splices/s ({dt / len(pairs) * 1e3 * get_threads():.2f} ms per pair per core)")
    else:
        batch = [(clips[a], clips[b]) for a, b in pairs[:512]]
        opt = SpliceOptions(force=True, check_locomotion=False, device=device)
        dt = best_of(lambda: (splice_pairs(batch, spec, options=opt), torch.cuda.synchronize()), 2)
        ours = len(batch) / dt
        print(f"splice  torch splicer on {device}, batch of {len(batch)}: {ours:,.0f} splices/s")
    # the careful NumPy peer, one pair at a time, in one process, on a random sample of the pairs
    rng = np.random.default_rng(0)
    sample = [pairs[k] for k in rng.choice(len(pairs), size=min(16, len(pairs)), replace=False)]

    def arrays(m):
        return {"rot": m.rotations.double().numpy(), "trans": m.local_translations().double().numpy()}

    outs = []
    t0 = time.perf_counter()
    for a, b in sample:
        outs.append(ref.splice_pair(arrays(clips[a]), arrays(clips[b]), roles, clips[a].skeleton.parents, clips[a].fps))
    peer_all = len(sample) / (time.perf_counter() - t0)
    print(f"splice  careful NumPy per-pair peer (scripts/numpy_reference.py), one process: {peer_all:.1f} splices/s "
          f"on {len(sample)} random pairs of the set")
    print(f"splice  compiled splicer = {ours / peer_all:,.0f}x the peer  [>= 50x]")
    got = splice_bank(bank, [p[0] for p in sample], [p[1] for p in sample], dtype=np.float64, **kw)
    rot_err = max(float(quat_angle(torch.from_numpy(got.rotations[s:s + f]), torch.from_numpy(o[0])).max())
                  for s, f, o in zip(got.start, got.frames, outs) if f == len(o[0]))
    curve_err = max(float(np.abs(got.curve[s:s + f] - o[2]).max()) for s, f, o in zip(got.start, got.frames, outs) if f == len(o[0]))
    same = sum(f == len(o[0]) for f, o in zip(got.frames, outs))
    print(f"splice  agreement with the peer: {same}/{len(sample)} same lengths, rotations within {np.degrees(rot_err):.1g} deg, "
          f"curves within {curve_err:.1g} frames")
    globals()["_PEER_RATE"] = peer_all


def _tree_rss_mb(root: int, largest: bool = False) -> float:
    """Resident memory of a process and all its descendants, MB (from /proc); ``largest``: of
    the largest of them alone. Pages shared between them (a mapped clip bank) count in each."""
    kids: dict[int, list[int]] = {}
    rss: dict[int, int] = {}
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                stat = (p / "stat").read_text().rsplit(")", 1)[1].split()
                kids.setdefault(int(stat[1]), []).append(int(p.name))
                rss[int(p.name)] = int(stat[21]) * os.sysconf("SC_PAGE_SIZE")
            except (OSError, IndexError, ValueError):
                pass
    total, most, todo = 0, 0, [root]
    while todo:
        pid = todo.pop()
        total += rss.get(pid, 0)
        most = max(most, rss.get(pid, 0))
        todo += kids.get(pid, [])
    return (most if largest else total) / 2**20


def _run_job(db: Path, out: Path, clips: list[str], device: str, extra=(), cores=None, prefix=()) -> tuple[float, int, float]:
    """One ``torchsplice splice-all`` in a fresh process: (wall seconds, splices, peak MB of the
    process and its workers, sampled every 20 ms). ``cores`` pins it (and its workers) to those
    cores; ``prefix`` runs it under another command (``unshare --net ...``)."""
    sel = ",".join(clips)
    cmd = [sys.executable, "-m", "torchsplice", "splice-all", str(db), "-o", str(out), "--locomotions", sel,
           "--actions", sel, "--force", "--restart", "-q", *extra] + (["--device", device] if device != "cpu" else [])
    if prefix:
        cmd = [*prefix, " ".join(map(shlex.quote, cmd))]
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
                         preexec_fn=(lambda: os.sched_setaffinity(0, cores)) if cores else None)
    peak = 0.0
    while p.poll() is None:
        peak = max(peak, _tree_rss_mb(p.pid))
        time.sleep(0.02)
    dt = time.perf_counter() - t0
    _, err = p.communicate()
    if p.returncode != 0:
        raise SystemExit(f"job failed: {err[-2000:]}")
    import h5py

    with h5py.File(out, "r") as f:
        spliced = f["clips/name"].shape[0]
    return dt, spliced, peak


def _body_test_share(output: Path, job_seconds: float) -> None:
    """The share of a job's time its test of a hand inside the body takes: the compiled test run
    again on every result of ``output`` (the job's own frames, on every core as the job's
    workers are), against the job's whole time."""
    from torchsplice.ops.body import body_of
    from torchsplice.splice.backends import get_backend
    from torchsplice.store.database import MotionDatabase

    from torchsplice.job.source_figures import scales
    from torchsplice.ops.plausibility import figure_joints

    with MotionDatabase.open(output) as o:
        clips = [o.read(n) for n in o.names]
        sk = o.skeletons[0]
        roles = o.spec(0).bind(sk)
        body = body_of(sk, roles)
        spec = o.spec_json(0)
    rot = np.concatenate([c.rotations.numpy() for c in clips])
    trans = np.concatenate([c.local_translations().numpy() for c in clips])
    backend = get_backend("compiled")
    lengths = [c.num_frames for c in clips]
    joints = figure_joints(sk, roles)
    up, per_metre, _ = scales(spec)

    def figures():
        backend.inside_body(rot, trans, lengths, sk, body, per_frame=True)  # as the job: each frame's depth kept
        backend.figures(rot, trans, lengths, float(clips[0].fps), sk, joints, up, per_metre)

    best = best_of(figures, repeats=3)
    print(f"job     the figures of its {len(clips):,} results (hand in the body, foot skate, floor, jerk): {best:.3f} s = "
          f"{100 * best / job_seconds:.1f}% of the job's {job_seconds:.2f} s  [figures and correction <= 10%; the "
          "correction: see hands]")


def bench_job(files: list[Path], device: str) -> None:
    from torchsplice.cli import main as cli

    chosen = walks_and_turns(files, 60)
    names = [f.stem for f in chosen]
    small = names[:: max(1, len(names) // 20)][:20]  # above one batch, so memory is comparable
    with tempfile.TemporaryDirectory() as tmp:
        db, out = Path(tmp) / "in.h5", Path(tmp) / "out.h5"
        cli(["import", *map(str, chosen), "-o", str(db), "-q"])
        frames = sum(read_bvh(f).num_frames for f in chosen) / len(chosen)
        print(f"job     {len(names)} clips of {frames:.0f} frames on average; torchsplice splice-all in a fresh process each run")
        runs = {}
        for label, sel in (("small", small), ("big", names)):
            best = min((_run_job(db, out, sel, device) for _ in range(2)), key=lambda r: r[0])
            runs[label] = best
            dt, n, peak = best
            print(f"job     {len(sel)} x {len(sel)}: {n} splices in {dt:.2f} s = {n / dt:,.0f} splices/s whole process, "
                  f"peak memory {peak:.0f} MB" + ("  [>= 800/s on 60 x 60]" if label == "big" else ""))
        (t_s, n_s, p_s), (t_b, n_b, p_b) = runs["small"], runs["big"]
        marginal = (n_b - n_s) / max(t_b - t_s, 1e-9)
        print(f"job     marginal: {marginal:,.0f} splices/s ({n_b - n_s} extra splices in {t_b - t_s:.2f} extra seconds)  [>= 1,000/s]")
        print(f"job     peak memory {p_s:.0f} MB for {n_s} splices, {p_b:.0f} MB for {n_b}")
        _body_test_share(out, t_b)
        peer = globals().get("_PEER_RATE")
        if peer:
            print(f"job     against the careful NumPy peer ({peer:.1f}/s): {marginal / peer:,.0f}x marginal, "
                  f"{n_b / t_b / peer:,.0f}x whole process  [>= 50x]")
        # the same big job while one other CPU-bound process runs (bounded: killed when done, 120 s at most)
        busy = subprocess.Popen([sys.executable, "-c", "import time\nt = time.time()\nwhile time.time() - t < 120: pass"])
        try:
            time.sleep(0.5)
            t_busy, n_busy, _ = _run_job(db, out, names, device)
        finally:
            busy.kill()
            busy.wait()
        ratio = (n_busy / t_busy) / (n_b / t_b)
        print(f"job     with one other CPU-bound process: {n_busy / t_busy:,.0f} splices/s whole process = "
              f"{100 * ratio:.0f}% of quiet  [>= 40%]")


def bench_engines(files: list[Path]) -> None:
    """Local workers on one core and on every core, and Ray, each on a 20 x 20 and a 60 x 60 job:
    marginal seconds per extra splice, so that start-up costs cancel out."""
    from torchsplice.cli import main as cli

    chosen = walks_and_turns(files, 60)
    names = [f.stem for f in chosen]
    small = names[:: max(1, len(names) // 20)][:20]
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    n = len(cores)
    ray_ok = importlib.util.find_spec("ray") is not None and shutil.which("unshare") is not None and os.geteuid() == 0
    with tempfile.TemporaryDirectory() as tmp:
        db, out = Path(tmp) / "in.h5", Path(tmp) / "out.h5"
        cli(["import", *map(str, chosen), "-o", str(db), "-q"])

        def marginal(**kw):
            runs = {}
            for label, sel in (("small", small), ("big", names)):
                runs[label] = min((_run_job(db, out, sel, "cpu", **kw) for _ in range(2)), key=lambda r: r[0])
            (ts, ns, _), (tb, nb, peak) = runs["small"], runs["big"]
            return (nb - ns) / max(tb - ts, 1e-9), nb / tb, peak

        one = marginal(extra=["--workers", "1"], cores={cores[0]})
        print(f"engines local, 1 worker on 1 core: {one[0]:,.0f} splices/s marginal, {one[1]:,.0f} whole process")
        many = marginal(extra=["--workers", str(n)])
        print(f"engines local, {n} workers on {n} cores: {many[0]:,.0f} splices/s marginal, {many[1]:,.0f} whole process, "
              f"peak memory {many[2]:.0f} MB with its workers = {many[0] / one[0]:.2f}x one worker  [>= 1.8x on 2 cores]")
        if ray_ok:
            ray = _ray_marginal(db, out, small, names)
            print(f"engines Ray, a local instance ({n} CPUs, in a private network namespace): {ray[0]:,.0f} splices/s "
                  f"marginal, {ray[1]:,.0f} whole process (its start included) = {100 * (many[0] / ray[0] - 1):+.0f}% "
                  "time against the local engine  [overhead < 10%]")
        else:
            print("engines Ray: skipped (needs ray, unshare and root for a private network namespace)")


def _ray_marginal(db: Path, out: Path, small: list[str], names: list[str]) -> tuple[float, float]:
    runs = {}
    for label, sel in (("small", small), ("big", names)):
        s = ",".join(sel)
        cmd = (f"ip link set lo up && RAY_USAGE_STATS_ENABLED=0 RAY_AUTH_MODE=disabled {shlex.quote(sys.executable)} -m torchsplice splice-all "
               f"{db} -o {out} --locomotions {shlex.quote(s)} --actions {shlex.quote(s)} --force --restart -q --engine ray")
        best = None
        for _ in range(2):
            t0 = time.perf_counter()
            p = subprocess.run(["unshare", "--net", "bash", "-c", cmd], capture_output=True, text=True, cwd=REPO)
            dt = time.perf_counter() - t0
            if p.returncode != 0:
                raise SystemExit(f"Ray job failed: {p.stderr[-2000:]}")
            best = dt if best is None else min(best, dt)
        import h5py

        with h5py.File(out, "r") as f:
            runs[label] = (best, f["clips/name"].shape[0])
    (ts, ns), (tb, nb) = runs["small"], runs["big"]
    return (nb - ns) / max(tb - ts, 1e-9), nb / tb


# ----------------------------------------------------------------------------------- the real mix
MIX_LOCOMOTIONS = "label:style=normal"


def _folder_bytes(folder: Path, skip: Path) -> int:
    """Bytes of the files under ``folder`` but ``skip``, each file once (a file renamed during the
    count is not counted twice)."""
    seen, total = set(), 0
    for root, _, names in os.walk(folder):
        for name in names:
            p = Path(root) / name
            try:
                st = p.stat()
            except OSError:
                continue
            if p != skip and st.st_ino not in seen:
                seen.add(st.st_ino)
                total += st.st_size
    return total


def _mix_job(db: Path, out: Path, actions: str, extra=(), kill_at=None, env=None, locomotions: str | None = None) -> dict:
    """``splice-all`` of the normal-style locomotions (or ``locomotions``) x ``actions`` in a
    fresh process: :func:`_watched_job`'s figures."""
    args = ("--locomotions", locomotions or MIX_LOCOMOTIONS, "--actions", actions, *extra)
    return _watched_job(db, out, args, kill_at, env)


def _watched_job(db: Path, out: Path, args=(), kill_at=None, env=None) -> dict:
    """``splice-all DB -o OUT ARGS`` in a fresh process: wall seconds, the job's own splicing
    seconds (``compute``: from its summary, start-up and planning left out), peak memory of the
    process and its workers (MB) and of its largest process, peak bytes of the output folder (the
    input database left out) and of the clip banks in it, sampled every 20 ms, and what it said;
    killed once the output holds ``kill_at`` of the plan's tasks (then ``killed`` is true)."""
    from torchsplice.store.database import MotionDatabase

    cmd = [sys.executable, "-m", "torchsplice", "splice-all", str(db), "-o", str(out), *args]
    work = out.with_name(f".{out.name}.parts")
    t0 = time.perf_counter()
    said_to = tempfile.TemporaryFile("w+")  # files, not pipes: a long job's progress cannot fill them and stall it
    p = subprocess.Popen(cmd, stdout=said_to, stderr=subprocess.STDOUT, text=True, cwd=REPO, env=env)
    peak_mb = peak_one = peak_disk = peak_bank = 0.0
    total, killed = None, False
    while p.poll() is None:
        peak_mb = max(peak_mb, _tree_rss_mb(p.pid))
        peak_one = max(peak_one, _tree_rss_mb(p.pid, largest=True))
        peak_disk = max(peak_disk, _folder_bytes(out.parent, db))
        peak_bank = max(peak_bank, sum(_folder_bytes(b, db) for b in work.glob("bank-*")))
        if kill_at is not None:
            if total is None and (work / "plan.json").exists():
                try:
                    total = len(json.loads((work / "plan.json").read_text())["tasks"])
                except ValueError:
                    pass
            held = (MotionDatabase.checkpoint_note(work / "output.h5") or {}).get("tasks", 0)
            if total and held >= kill_at * total:
                p.send_signal(signal.SIGKILL)
                killed = True
        time.sleep(0.02)
    dt = time.perf_counter() - t0
    p.wait()
    said_to.seek(0)
    said = said_to.read()
    if p.returncode != 0 and not killed:
        raise SystemExit(f"job failed: {said[-2000:]}")
    compute = re.search(r"spliced clips.* in ([0-9.]+) s \(", said)
    on_disk = re.search(r"^\s*(\S+ \S+ on disk \(expected [^)]*\))", said, re.M)
    return {"on_disk": on_disk.group(1) if on_disk else "", "seconds": dt, "peak_mb": peak_mb, "peak_one": peak_one,
            "peak_disk": peak_disk, "peak_bank": peak_bank, "killed": killed, "said": said,
            "compute": float(compute.group(1)) if compute else float("nan")}


def _task_rates(db: Path, actions: str):
    """The job's own tasks of normal-style locomotions x ``actions``, run in this process as its
    workers run them (:func:`torchsplice.job.task.run_task`, compiled splicer on every thread),
    the clips and banks ready: (output frames/s, pairs/s, pairs, the plan), best of 2 runs."""
    from torchsplice.job.config import job_config
    from torchsplice.job.plan import make_plan
    from torchsplice.job.sources import Sources
    from torchsplice.job.task import run_task

    config = job_config(db, db.with_name("unused.h5"), locomotions=(MIX_LOCOMOTIONS,), actions=(actions,))
    sources = Sources(config.database, config.actions_db)
    plan = make_plan(config, sources)
    sources.share_banks(plan.groups)
    best = None
    for _ in range(3):  # the first run builds the banks
        t0 = time.perf_counter()
        frames = sum(int(run_task(plan, t, sources, config).lengths.sum()) for t in plan.tasks)
        dt = time.perf_counter() - t0
        best = dt if best is None or _ == 0 else min(best, dt)
    return frames / best, len(plan.pairs) / best, len(plan.pairs), plan


def _clips_mb(db: Path, plan) -> float:
    """MB of the clips ``plan`` selects, as float32 rotations and translations."""
    from torchsplice.store.database import MotionDatabase

    with MotionDatabase.open(db) as d:
        lengths = d.table()["length"]
        frames = sum(int(lengths[int(c.split(":")[1])]) for g in plan.groups for c in g.clips)
        skeletons = d.skeletons.values() if isinstance(d.skeletons, dict) else d.skeletons
        joints = max(len(s.names) for s in skeletons)
    return frames * joints * 7 * 4 / 2**20


def _frames_and_clips(path: Path) -> tuple[int, int]:
    import h5py

    with h5py.File(path, "r") as f:
        return (sum(f[f"skeletons/{k}/rotations"].shape[0] for k in f["skeletons"]), f["clips/name"].shape[0])


def _same_content(a: Path, b: Path, rows: int = 1 << 20) -> bool:
    """Whether two outputs hold the same datasets, bit for bit (the run record aside), compared
    ``rows`` rows at a time (an output may be larger than memory)."""
    import h5py

    def names(f):
        out = []
        f.visititems(lambda name, obj: out.append(name) if isinstance(obj, h5py.Dataset) else None)
        return sorted(out)

    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        if names(fa) != names(fb):
            return False
        for name in names(fa):
            da, db = fa[name], fb[name]
            if da.shape != db.shape or da.dtype != db.dtype:
                return False
            if da.shape == ():
                if da[()] != db[()]:
                    return False
                continue
            for k in range(0, da.shape[0], rows):
                x, y = da[k:k + rows], db[k:k + rows]
                if (x.tobytes() if x.dtype != object else repr(x.tolist())) != \
                        (y.tobytes() if y.dtype != object else repr(y.tolist())):
                    return False
    return True


def bench_mix(files: list[Path], device: str, mix_db: Path | None) -> None:
    """The real workload: normal-style Bandai Namco locomotions x every action clip (nearly all of
    them standing actions), as a user runs it (see docs/reference/speed.md)."""
    from torchsplice.cli import main as cli
    from torchsplice.store.database import MotionDatabase
    from torchsplice.job.size import format_bytes

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        db = mix_db
        if db is None:
            bandai = [f for f in files if re.match(r"dataset-\d_", f.stem)]
            if not bandai:
                print("mix     skipped: needs Bandai Namco clips (../shared/mocap) or --mix-db")
                return
            db = tmp / "bandai.h5"
            cli(["import", *map(str, bandai), "-o", str(db), "-q"])
        with MotionDatabase.open(db) as d:
            n_clips = len(d)
        print(f"mix     {db.name}: {n_clips} clips; locomotions {MIX_LOCOMOTIONS!r}; each job in a fresh process"
              + ("" if mix_db else " (the shipped subset: the targets are for the whole dataset, --mix-db)"))
        outs = tmp / "out"
        outs.mkdir()
        extra = ["--device", device] if device != "cpu" else []
        # 1. standing actions against time-aligned ones, onto the same locomotions: the job's tasks
        rates = {label: _task_rates(db, actions) for label, actions in
                 (("standing (role:action)", "role:action"), ("time-aligned (role:both)", "role:both"))}
        for label, (fps_, pps, n, _) in rates.items():
            print(f"mix     {label}: {n:,} pairs, {fps_:,.0f} output frames/s, {pps:,.0f} pairs/s (the job's tasks, "
                  "in one process)")
        a, b = rates["standing (role:action)"][0], rates["time-aligned (role:both)"][0]
        print(f"mix     standing / time-aligned output frames/s: {a / b:.2f}  [>= 0.8]")
        # 2. the real mix: every action clip, the disk and memory it takes
        out = outs / "mix.h5"
        r = _mix_job(db, out, "role:action", extra)
        frames, clips = _frames_and_clips(out)
        size = out.stat().st_size
        print(f"mix     real mix: {clips:,} pairs in {r['seconds']:.1f} s = {clips / r['seconds']:,.0f} pairs/s whole process "
              f"[>= 1,300 on the whole dataset]; output {format_bytes(size)} ({r['on_disk']}), peak disk {format_bytes(r['peak_disk'])} = "
              f"{r['peak_disk'] / size:.2f}x the output [<= 1.2x] (the clip bank {format_bytes(r['peak_bank'])} of it, "
              f"a fixed cost); peak memory of the job and its workers "
              f"{r['peak_mb']:,.0f} MB, of the largest process {r['peak_one']:,.0f} MB [<= --memory-budget 1,024 MB + the "
              f"selected clips as the splicer holds them, the bank, {r['peak_bank'] / 2**20:,.0f} MB, mapped by every "
              f"process; the clips' raw frames are {_clips_mb(db, rates['standing (role:action)'][3]):,.0f} MB]")
        if device != "cpu":
            return
        # 3. killed three times, then resumed: the same output, and the time it costs
        killed = outs / "killed.h5"
        spent = 0.0
        for share in (0.25, 0.5, 0.75):
            spent += _mix_job(db, killed, "role:action", kill_at=share)["seconds"]
        spent += _mix_job(db, killed, "role:action")["seconds"]
        print(f"mix     killed at 25%, 50% and 75% and resumed: {spent:.1f} s in all = {spent / r['seconds']:.2f}x the "
              f"uninterrupted run [<= 1.15x]; output {'bit-identical' if _same_content(killed, out) else 'DIFFERENT'}")


def bench_startup() -> None:
    """Each command's wall time as a user runs it, beside ``python -c pass`` and ``import torch``."""
    print("\n== startup: commands on the built-in sample, best of 5 (wall s)")
    py = [sys.executable]

    def wall(argv, cwd) -> float:
        def once():
            out = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=300)
            if out.returncode != 0:
                raise RuntimeError(f"{' '.join(argv)}: {out.stderr.strip()[-300:]}")
        return best_of(once, repeats=5)

    with tempfile.TemporaryDirectory() as tmp:
        ts = py + ["-m", "torchsplice"]
        subprocess.run(ts + ["sample", "-o", "s.h5", "-q"], cwd=tmp, check=True)
        base, torch_import = wall(py + ["-c", "pass"], tmp), wall(py + ["-c", "import torch"], tmp)
        print(f"  python alone {base:.2f} s; python importing torch {torch_import:.2f} s")
        rows = [("--help", ts + ["--help"], False), ("info", ts + ["info", "s.h5"], True),
                ("info --json", ts + ["info", "s.h5", "--json"], True),
                ("export one clip (BVH)", ts + ["export", "s.h5", "walk_curve", "-o", "w.bvh", "-f", "-q"], True),
                ("splice one pair (BVH)", ts + ["splice", "s.h5", "--locomotion", "walk_curve", "--action", "wave",
                                                "-o", "p.bvh", "-f", "-q"], True)]
        for label, argv, clips in rows:
            s = wall(argv, tmp)
            ours = s - (torch_import if clips else base)
            target = 0.8 if clips else 0.5
            print(f"  {label:24s} {s:.2f} s: {ours:.2f} s beyond {'torch' if clips else 'python'} "
                  f"[{'<=' if clips else '<='} {target}{' + torch' if clips else ''}]"
                  f"{'' if (ours if clips else s) <= target else '  NOT MET'}")


def _shown(path: Path) -> str:
    """``path`` as the records show it: relative to the repository where it is beside it."""
    try:
        return os.path.relpath(path.resolve(), REPO)
    except ValueError:
        return str(path)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--mocap", type=Path, default=Path(os.environ.get("TORCHSPLICE_MOCAP", REPO.parent / "shared" / "mocap")),
                   help="folder of real BVH files (default ../shared/mocap or $TORCHSPLICE_MOCAP)")
    p.add_argument("--only", default="parse,stages,splice,job,engines,mix,retarget,humanml3d,hands,packed,store,startup",
                   help="comma-separated sections: parse, stages, splice, job, engines, mix, retarget, humanml3d, "
                        "hands, packed, store, startup")
    p.add_argument("--big-db", type=Path, default=None,
                   help="store: also run the default job with --store alignment on this database (e.g. the whole "
                        "Bandai Namco dataset imported)")
    p.add_argument("--mix-db", type=Path, default=None,
                   help="the real mix on this database (e.g. the whole Bandai Namco dataset imported) instead of "
                        "the Bandai Namco clips of --mocap; hands: also that job with and without the correction")
    p.add_argument("--held-back", type=Path, default=None,
                   help="hands: also the held-back pairs and ground truth, from this folder of the whole Bandai Namco "
                        "dataset's BVH files (the takes that --mocap does not hold)")
    p.add_argument("--device", default="cpu", help="cpu (the compiled splicer) or a torch device such as cuda")
    p.add_argument("--json", type=Path, default=None,
                   help="also keep what each section printed, with the date and machine, in this file (its other "
                        "sections kept): docs/reference/benchmark-runs.json is what the docs' Speed page shows")
    args = p.parse_args()
    sections = set(args.only.split(","))
    from torchsplice.cpu import get_threads

    print(f"torch {torch.__version__}, {os.cpu_count()} cores, compiled splicer threads {get_threads()}, device {args.device}")
    with tempfile.TemporaryDirectory() as tmp:
        files = real_files(args.mocap)
        if files:
            data = f"{len(files)} real BVH files from {_shown(args.mocap)}"
        else:
            files = sample_files(Path(tmp))
            data = f"no real data at {args.mocap}; the built-in synthetic sample ({len(files)} clips)"
        from bench_hands import bench_hands
        from bench_humanml3d import bench_humanml3d, bench_packed_memory
        from bench_retarget import bench_retarget
        from bench_store import bench_store

        runs = {  # in the order they run
            "parse": lambda: bench_parse(files),
            "stages": lambda: bench_stages(files, args.device),
            "splice": lambda: bench_splice(files, args.device),
            "job": lambda: bench_job(files, args.device),
            "engines": lambda: bench_engines(files) if args.device == "cpu" else None,
            "mix": lambda: bench_mix(files, args.device, args.mix_db),
            "retarget": lambda: bench_retarget(files, args.mocap),
            "humanml3d": lambda: bench_humanml3d(real_files(args.mocap)),
            "hands": lambda: bench_hands(args.mocap, whole=args.held_back, whole_db=args.mix_db),
            "packed": bench_packed_memory,
            "store": lambda: bench_store(real_files(args.mocap), args.big_db, args.device),
            "startup": bench_startup,
        }
        unknown = sections - set(runs)
        if unknown:
            p.error(f"--only: no section named {', '.join(sorted(unknown))} (sections: {', '.join(runs)})")
        recorder = Recorder(args.json)
        # a section run on the whole dataset is recorded apart from its run on --mocap's files
        whole = {"mix": args.mix_db, "hands": args.mix_db or args.held_back, "store": args.big_db}
        try:
            for name, run in runs.items():
                if name in sections:
                    with recorder.section(name + WHOLE if whole.get(name) else name):
                        print(f"data: {data}")
                        run()
        finally:
            recorder.save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
