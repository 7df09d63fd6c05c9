"""The ``store`` section of scripts/benchmark.py: alignment stores against motion stores.

    python scripts/benchmark.py --only store
    python scripts/benchmark.py --only store --big-db bandai_full.h5   # and the default job on it

On 60 Bandai Namco walks and turns plus every standing action of ../shared/mocap (locomotions:
the walks; actions: the walks and the standing actions), as a user runs it:

- sizes: the alignment store (its banks of source clips included) against the motion store
  of the same job                                                                  [>= 10x smaller]
- the job's whole-process time, alignment against motion                          [<= 1.0x]
- every clip read back bit for bit against the motion store (a check, printed)
- assembly: clips/s and frames/s on one core (``MotionDatabase.assembled``, every clip); the
  torch assembly (``MotionDatabase.assembled_on``, what ``MotionDataset(assemble_on=...)`` runs)
  on the CPU's threads, and with ``--device cuda`` on the GPU, clips/s (the frames left there)
- ``MotionDataset`` frames/s over each store, page cache warm, the same shuffled reads [>= 1x]
- the alignment job killed (SIGKILL) at half its tasks and resumed: its time against the
  uninterrupted run's and its output bit for bit the uninterrupted one's
- streaming HumanML3D features (``HumanML3DStream``, 2 workers) clips/s, against the
  ``humanml3d`` export's own clips/s and a T2M-GPT/MoMask-style loader (every ``.npy`` of the
  exported folder loaded at start, then cropped per item)
- with ``--big-db``: the default job (``splice-all DB -o OUT --store alignment``) on it, its time,
  output size and peak memory                                         [<= 30 min, <= 12 GB]
"""

from __future__ import annotations

import os
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _job(db: Path, out: Path, store: str, locos: str, actions: str, kill_at=None, extra=()) -> dict:
    """``splice-all`` in a fresh process (:func:`benchmark._mix_job`: wall seconds, peak memory,
    killed with SIGKILL once its staged output holds ``kill_at`` of its tasks)."""
    from benchmark import _mix_job

    return _mix_job(db, out, actions, extra=("--store", store, "-q", "--no-index", "--force", *extra), kill_at=kill_at,
                    locomotions=locos)


def _same_reads(a: Path, b: Path) -> tuple[int, int]:
    """``(clips, clips that differ)`` between two outputs, read through torchsplice."""
    from torchsplice.store.database import MotionDatabase

    bad = 0
    with MotionDatabase.open(a) as x, MotionDatabase.open(b) as y:
        assert x.names == y.names
        for s in range(0, len(x), 2000):
            rows = list(range(s, min(s + 2000, len(x))))
            for m1, m2 in zip(x.read_many(rows), y.read_many(rows)):
                for k in ("rotations", "root_translation", "translations"):
                    p, q = getattr(m1, k), getattr(m2, k)
                    if (p is None) != (q is None) or (p is not None and p.numpy().tobytes() != q.numpy().tobytes()):
                        bad += 1
                        break
        return len(x), bad


def _dataset_rates(runs: list[tuple[Path, int]], passes: int = 7) -> list[float]:
    """Frames/s of ``MotionDataset`` over each ``(path, threads)`` of ``runs`` (``threads``: this
    process's torch threads, which an alignment store's assembly shares its clips over), reading
    every clip in a shuffled order, batches of 64, in this process: the best of ``passes``, the
    runs' passes taken in turn so that a busy moment of a shared machine falls on each alike (a
    first pass warms the page cache)."""
    import torch

    from torchsplice.data import MotionDataset

    sets = [MotionDataset(p, features=("rotations", "root_translation")) for p, _ in runs]
    order = np.random.default_rng(0).permutation(len(sets[0])).tolist()
    best = [float("inf")] * len(sets)
    frames = [0] * len(sets)
    was = torch.get_num_threads()
    try:
        for _ in range(passes + 1):
            for i, (ds, (_, threads)) in enumerate(zip(sets, runs)):
                torch.set_num_threads(threads)
                t0 = time.perf_counter()
                frames[i] = 0
                for s in range(0, len(order), 64):
                    frames[i] += sum(int(item["length"]) for item in ds.__getitems__(order[s:s + 64]))
                best[i] = min(best[i], time.perf_counter() - t0)
    finally:
        torch.set_num_threads(was)
    return [f / b for f, b in zip(frames, best)]


def _every_clip_rate(path: Path, assemble, sync=lambda: None) -> tuple[float, float]:
    """(clips/s, frames/s) of ``assemble(db, k, starts, lengths)`` over every clip of an
    alignment store, 512 clips a call, best of 3 (after one call that loads the banks and warms
    up; ``sync`` waits for a device)."""
    from torchsplice.store.database import MotionDatabase

    with MotionDatabase.open(path) as db:
        t = db.clip_table()
        assemble(db, 0, t.start[:1], t.length[:1])
        sync()
        best = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            for k in sorted(set(t.skeleton.tolist())):
                rows = np.flatnonzero(t.skeleton == k)
                for s in range(0, len(rows), 512):
                    r = rows[s:s + 512]
                    assemble(db, k, t.start[r], t.length[r])
            sync()
            best = min(best, time.perf_counter() - t0)
        return len(t) / best, int(t.length.sum()) / best


def _assembly_rate(path: Path) -> tuple[float, float]:
    """(clips/s, frames/s) of assembling every clip of an alignment store on one core
    (``MotionDatabase.assembled``, the compiled kernels)."""
    return _every_clip_rate(path, lambda db, k, starts, lengths: db.assembled(k, starts, lengths))


def _assembly_rate_on(path: Path, device: str) -> float:
    """Clips/s of the torch assembly of every clip of an alignment store on ``device``
    (``MotionDatabase.assembled_on``; the frames stay on the device)."""
    import torch

    sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)
    return _every_clip_rate(path, lambda db, k, starts, lengths: db.assembled_on(k, starts, lengths, device), sync)[0]


def _t2m_loader_rate(folder: Path) -> float:
    """Clips/s of a T2M-GPT/MoMask-style loader over an exported HumanML3D folder: every
    ``new_joint_vecs`` file and caption file loaded at start (as their Text2MotionDataset does),
    then one epoch of normalised, cropped items in batches of 32."""
    t0 = time.perf_counter()
    mean, std = np.load(folder / "Mean.npy"), np.load(folder / "Std.npy")
    ids = (folder / "all.txt").read_text().split()
    data = {i: (np.load(folder / "new_joint_vecs" / f"{i}.npy"), (folder / "texts" / f"{i}.txt").read_text().splitlines())
            for i in ids}
    rng = np.random.default_rng(0)
    order = rng.permutation(len(ids))
    for s in range(0, len(order), 32):
        batch = []
        for j in order[s:s + 32]:
            motion, texts = data[ids[j]]
            n = len(motion) - len(motion) % 4
            start = rng.integers(0, len(motion) - n + 1)
            batch.append(((motion[start:start + n] - mean) / std, texts[rng.integers(len(texts))]))
    return len(ids) / (time.perf_counter() - t0)


def bench_store(files: list[Path], big_db: Path | None = None, device: str = "cpu") -> None:
    from benchmark import walks_and_turns
    from torchsplice.cli import main as cli

    walks = walks_and_turns(files, 60)
    standing = [f for f in files if re.match(r"dataset-\d_(bow|bye|byebye|call|guide|kick|punch|respond|raise|wave)", f.stem)]
    if not walks:
        print("store   no real data: section skipped")
        return
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        db = tmp / "in.h5"
        cli(["import", *map(str, walks + standing), "--spec", "bandai_namco", "-o", str(db), "-q"])
        locos = ",".join(f.stem for f in walks)
        actions = ",".join(f.stem for f in walks + standing)
        print(f"store   {len(walks)} walks and turns x {len(walks)} walks and {len(standing)} standing actions of "
              "Bandai Namco; splice-all in a fresh process each run")
        runs = {}
        for store in ("motion", "alignment"):
            out = tmp / f"{store}.h5"
            runs[store] = min((_job(db, out, store, locos, actions) for _ in range(2)), key=lambda r: r["seconds"])
            runs[store]["bytes"] = out.stat().st_size
        m, a = runs["motion"], runs["alignment"]
        from torchsplice.store.database import MotionDatabase

        with MotionDatabase.open(tmp / "alignment.h5") as d:
            clips = len(d)
            banks = sum(d.h5[f"assembly/banks/{b}/{n}"].id.get_storage_size() for b in d.h5["assembly/banks"]
                        for n in ("rotations", "translations"))
        print(f"store   {clips:,} clips: motion store {m['bytes'] / 1e6:,.1f} MB, alignment store {a['bytes'] / 1e6:,.1f} MB "
              f"(its source clips {banks / 1e6:,.1f} MB): {m['bytes'] / a['bytes']:.1f}x smaller  [>= 10x]")
        print(f"store   the job: motion {m['seconds']:.1f} s, alignment {a['seconds']:.1f} s: {a['seconds'] / m['seconds']:.2f}x "
              f"the time  [<= 1.0x]; peak memory {m['peak_mb']:,.0f} / {a['peak_mb']:,.0f} MB")
        n, bad = _same_reads(tmp / "alignment.h5", tmp / "motion.h5")
        print(f"store   read back: {n - bad:,} of {n:,} clips bit for bit the motion store's")
        cps, fps_ = _assembly_rate(tmp / "alignment.h5")
        print(f"store   assembly on one core: {cps:,.0f} clips/s, {fps_ / 1e6:,.2f} million frames/s")
        import torch

        for dev in ["cpu"] + ([device] if device != "cpu" else []):
            on = _assembly_rate_on(tmp / "alignment.h5", dev)
            threads = f", {torch.get_num_threads()} threads" if dev == "cpu" else ""
            print(f"store   assembly by torch on {dev}{threads}: {on:,.0f} clips/s  (MotionDataset(assemble_on=...))")
        from torchsplice.job.defaults import usable_cores

        cores = usable_cores()
        rm, ra, ra1 = _dataset_rates([(tmp / "motion.h5", cores), (tmp / "alignment.h5", cores),
                                      (tmp / "alignment.h5", 1)])
        print(f"store   MotionDataset, shuffled whole clips, warm cache: motion {rm / 1e6:,.2f}, alignment {ra / 1e6:,.2f} "
              f"million frames/s: {ra / rm:.2f}x  [>= 1x]  (the assembly on {cores} threads, as a reader in the "
              f"main process; on 1, as in a DataLoader worker: {ra1 / rm:.2f}x)")
        # killed with SIGKILL at half its tasks, resumed
        out = tmp / "killed.h5"
        first = _job(db, out, "alignment", locos, actions, kill_at=0.5, extra=("--batch-size", "200"))
        rest = _job(db, out, "alignment", locos, actions, extra=("--batch-size", "200"))
        whole = _job(db, tmp / "whole.h5", "alignment", locos, actions, extra=("--batch-size", "200"))
        from benchmark import _same_content

        same = _same_content(out, tmp / "whole.h5")
        print(f"store   killed at half its tasks (SIGKILL: {first['killed']}) and resumed: "
              f"{(first['seconds'] + rest['seconds']) / whole['seconds']:.2f}x the uninterrupted run's time; "
              f"output {'bit-identical' if same else 'DIFFERENT'} to it  [bit-identical]")
        _bench_streaming(tmp / "alignment.h5", tmp)
    if big_db is not None:
        _bench_default_job(big_db)


def _bench_streaming(store: Path, tmp: Path) -> None:
    from torch.utils.data import DataLoader

    from torchsplice.formats.exporters import export_clips
    from torchsplice.formats.humanml3d_stream import HumanML3DStream
    from torchsplice.store.database import MotionDatabase

    with MotionDatabase.open(store) as db:
        some = db.names[:: max(1, len(db) // 800)][:800]  # 800 clips spread over the store
    folder = tmp / "HumanML3D"
    t0 = time.perf_counter()
    export_clips(store, some, out=folder, format="humanml3d")
    export_rate = len(some) / (time.perf_counter() - t0)
    stream = HumanML3DStream(store, batch_size=32, clips=some)
    t0 = time.perf_counter()
    n = sum(len(b["id"]) for b in DataLoader(stream, batch_size=None, num_workers=2))
    stream_rate = n / (time.perf_counter() - t0)
    loader = max(_t2m_loader_rate(folder) for _ in range(2))
    print(f"store   HumanML3D features streamed (2 workers): {stream_rate:,.0f} clips/s; the export writing its "
          f"folder {export_rate:,.0f} clips/s; a T2M-GPT-style loader over that folder (load all, one epoch) "
          f"{loader:,.0f} clips/s")


def _bench_default_job(db: Path) -> None:
    """The default job on a whole dataset, alignment store."""
    from benchmark import _watched_job

    with tempfile.TemporaryDirectory(dir=db.parent) as tmp:
        out = Path(tmp) / "default.h5"
        r = _watched_job(db, out, ("--store", "alignment"))
        said, dt, peak, peak_one, bank = r["said"], r["seconds"], r["peak_mb"], r["peak_one"], r["peak_bank"] / 2**20
        size = sum(f.stat().st_size for f in Path(tmp).iterdir())
        wrote = re.search(r"^wrote .*$", said, re.M)  # the job's summary, after its progress lines
        print(f"store   the default job on {db}: {wrote.group(0) if wrote else said.strip()[-300:]}")
        print(f"store   {dt / 60:.1f} min, output {out.stat().st_size / 1e9:.2f} GB ({size / 1e9:.2f} GB with its "
              f"index), peak memory {peak:,.0f} MB (largest process {peak_one:,.0f} MB, against the 1,024 MB budget "
              f"plus the clip bank, {bank:,.0f} MB, which every process maps)  [<= 30 min, <= 12 GB; budget plus bank]")


if __name__ == "__main__":
    sys.path.insert(0, str(REPO / "scripts"))
    sys.path.insert(0, str(REPO))
    mocap = Path(os.environ.get("TORCHSPLICE_MOCAP", REPO.parent / "shared" / "mocap"))
    bench_store(sorted(mocap.rglob("*.bvh")), Path(sys.argv[1]) if len(sys.argv) > 1 else None)
