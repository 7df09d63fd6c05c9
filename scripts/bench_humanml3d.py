"""The ``humanml3d`` section of scripts/benchmark.py: the HumanML3D export and import.

Prints, with the issue's targets in brackets:
- export speed: clips/s of ``export --format humanml3d`` (statistics, captions, splits and
  index included, files written) of 200-frame clips already on the SMPL body at 20 fps, and
  of the same computation without the files (what the features cost), and per second of
  writing the same files alone with NumPy (what the disk costs)                [>= 2,000 clips/s]
- export of real clips (every Bandai Namco, CMU and LAFAN1 clip of ../shared/mocap, retargeted
  onto the SMPL body, windows of 9.8 s): clips/s, and the format's properties on them:
  positions from the features against new_joints [1e-5 m], bone lengths [1e-6 m], the lowest
  joint's 5th percentile [within 1 cm of 0], features derived again from new_joints [5e-3, away
  from the clip's end; at 20, 40 and 60 frames], contacts agreeing [99%]
- round trip: a HumanML3D import of that export against its positions                [1e-4 m]
- import: motions/s of ``import`` of that export (a database written), beside reading the
  motions one at a time; then the real clips' export again with ``--mirror``: motions/s
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from torchsplice.formats.exporters import export_clips  # noqa: E402
from torchsplice.formats.humanml3d_exporter import HumanML3DExporter  # noqa: E402
from torchsplice.evaluation.humanml3d import folder_properties  # noqa: E402
from torchsplice.formats.humanml3d_import import read_humanml3d_motion, read_humanml3d_motions  # noqa: E402
from torchsplice.specs import load_spec  # noqa: E402
from torchsplice.store.database import MotionDatabase  # noqa: E402


def _smpl_database(tmp: Path, clips: int, frames: int = 201) -> Path:
    """``clips`` clips of ``frames`` frames at 20 fps on the SMPL body: the sample retargeted,
    each tiled to length."""
    from torchsplice.ops.retarget import retarget_map, retarget_motions
    from torchsplice.sample import sample_motions
    from torchsplice.specs.smpl import smpl22_skeleton
    from torchsplice.align.curve import resample_motion

    ms = [m.to(torch.float64) for m in sample_motions()]
    sk = smpl22_skeleton()
    rmap = retarget_map(ms[0].skeleton, load_spec("sample").bind(ms[0].skeleton), sk, load_spec("smpl22").bind(sk))
    base = []
    for m in retarget_motions(ms, rmap):
        m = resample_motion(m, 20.0)
        k = -(-frames // m.num_frames)
        base.append(replace(m, rotations=m.rotations.repeat(k, 1, 1)[:frames],
                            root_translation=m.root_translation.repeat(k, 1)[:frames]))
    db = tmp / "smpl.h5"
    spec = load_spec("smpl22")
    with MotionDatabase.create(db) as w:
        for i in range(clips):
            m = base[i % len(base)]
            w.append(replace(m, name=f"clip{i:05d}", labels=dict(m.labels)), spec=spec)
    return db


def bench_humanml3d(files: list[Path], clips: int = 2000) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        db = _smpl_database(tmp, clips)
        runs = []
        for k in range(2):
            out = tmp / f"out{k}"
            t = time.perf_counter()
            export_clips(db, out=out, format="humanml3d")
            runs.append(time.perf_counter() - t)
            shutil.rmtree(out)
        whole = clips / min(runs)
        exporter = HumanML3DExporter(db, None)
        exporter.check()
        t = time.perf_counter()
        for _ in exporter._clips():
            pass
        compute = clips / (time.perf_counter() - t)
        vecs, joints = np.zeros((200, 263), np.float32), np.zeros((200, 22, 3), np.float32)
        (tmp / "io").mkdir()
        t = time.perf_counter()
        for i in range(clips):
            for a, s in ((vecs, "v"), (joints, "j")):
                with open(tmp / "io" / f"{i}{s}.npy", "wb") as f:
                    np.save(f, a)
            (tmp / "io" / f"{i}.txt").write_text("a person walks#a/DET person/NOUN walk/VERB#0.0#0.0\n")
        disk = clips / (time.perf_counter() - t)
        print(f"humanml3d export of {clips} clips of 200 frames on the SMPL body: {whole:,.0f} clips/s with the files "
              f"[>= 2,000]; the features alone {compute:,.0f} clips/s, the files alone (NumPy, no features) "
              f"{disk:,.0f} clips/s")
        if not files:
            print("humanml3d real clips: no real data; skipped")
            return
        real = tmp / "real.h5"
        from torchsplice.formats.importer import import_bvh

        import_bvh(files, real)
        with MotionDatabase.open(real) as d:
            n = len(d)
            frames = int(d.clip_table().length.sum())
        out = tmp / "real"
        t = time.perf_counter()
        result = export_clips(real, out=out, format="humanml3d", window=9.8)
        dt = time.perf_counter() - t
        w = folder_properties(out)
        print(f"humanml3d export of {n} real clips ({frames:,} frames; retargeted, windows of 9.8 s): {n / dt:,.1f} clips/s; "
              f"{result.summary}")
        print(f"humanml3d properties: positions from features vs new_joints {w['recover']:.1e} m [1e-5]; bones "
              f"{w['bones']:.1e} m [1e-6]; lowest joint's 5th percentile {w['floor_p5'] * 100:+.2f} cm [within 1]; "
              f"features derived again {w['derived20']:.1e} / {w['derived40']:.1e} / {w['derived60']:.1e} at 20 / 40 / 60 "
              f"frames from the end [5e-3]; contacts {w['contacts'] * 100:.1f}% [99%]")
        worst = 0.0
        ids = sorted(f.stem for f in (out / "new_joint_vecs").glob("*.npy"))
        for i in ids:
            m = read_humanml3d_motion(out, i)
            joints = torch.from_numpy(np.load(out / "new_joints" / f"{i}.npy")).double()
            worst = max(worst, float((m.global_positions() - joints).abs().max()))
        print(f"humanml3d round trip: import of the export against its positions {worst:.1e} m [1e-4]")
        t = time.perf_counter()
        for i in ids:  # one at a time (as import read them before): the peer of its batches
            read_humanml3d_motion(out, i)
        alone = time.perf_counter() - t
        t = time.perf_counter()
        read_humanml3d_motions([(out, i, None) for i in ids])
        together = time.perf_counter() - t
        t = time.perf_counter()
        import_bvh([out], tmp / "back.h5", format="humanml3d")
        rate = len(ids) / (time.perf_counter() - t)
        print(f"humanml3d import of {len(ids)} motions (the real clips' export, database written): {rate:,.0f} motions/s, "
              f"{1e3 / rate:.1f} ms a motion; reading them in batches {len(ids) / together:,.0f} motions/s against "
              f"{len(ids) / alone:,.0f} one at a time = {alone / together:.1f}x")
        shutil.rmtree(out)
        t = time.perf_counter()
        result = export_clips(real, out=out, format="humanml3d", window=9.8, mirror=True)
        dt = time.perf_counter() - t
        written = len(list((out / "new_joint_vecs").glob("*.npy")))
        print(f"humanml3d export --mirror of the {n} real clips: {written / dt:,.1f} motions/s written "
              f"({n / dt:,.1f} source clips/s); {result.summary}")


def bench_packed_memory(sizes=(1000, 4000, 10000)) -> None:
    """Peak memory of `torchsplice export --all --packed` against the number of clips (fresh
    processes; 200-frame clips on the SMPL body), and the file's size: flat, as the packed file
    is streamed member by member."""
    import subprocess

    probe = ("import resource, sys; from torchsplice.cli import main; rc = main(sys.argv[1:]); "
             "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for n in sizes:
            sub = tmp / str(n)
            sub.mkdir()
            db = _smpl_database(sub, n)
            out = sub / "all.npz"
            p = subprocess.run([sys.executable, "-c", probe, "export", str(db), "--all", "--packed", "-o", str(out), "-q"],
                               capture_output=True, text=True)
            if p.returncode != 0:
                print(f"packed  export of {n} clips failed: {p.stderr.strip()[-300:]}")
                return
            rows.append((n, int(p.stdout.split()[-1]), out.stat().st_size / 2**20))
            shutil.rmtree(sub)
    text = "; ".join(f"{n:,} clips: {mb:,} MB peak for a {size:,.0f} MB file" for n, mb, size in rows)
    print(f"packed  npz export, peak memory of the process against the clips [flat]: {text}")
