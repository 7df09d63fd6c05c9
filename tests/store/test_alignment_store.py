"""Alignment stores (``splice-all --store alignment``): each source clip once and, per spliced
clip, what splicing computed; every read assembles the motion, bit for bit the motion store's.

Known answers: the motion store of the same job (written with the same assembly), on the
built-in sample (splice, naive, cpmc) and on real Bandai Namco clips (standing actions looped,
held and fitted; LAFAN1 actions retargeted onto Bandai Namco's skeleton)."""

from __future__ import annotations

import shutil

import h5py
import numpy as np
import pytest
import torch

from cli_helpers import error_line, run
from realdata import BANDAI
from torchsplice.cli.common import flag
from torchsplice.core.errors import DatabaseError, TorchspliceError
from torchsplice.job import merge_job, splice_all
from torchsplice.job.materialize import materialize
from torchsplice.store.database import MotionDatabase

READ = ("rotations", "root_translation", "translations")


def _job(db, out, store, **options):
    options.setdefault("methods", "splice,naive,cpmc")
    options.setdefault("index", False)
    splice_all(db, out, store=store, overwrite=True, **options)
    return out


def _bits(a) -> bytes:
    return a.numpy().tobytes() if isinstance(a, torch.Tensor) else np.ascontiguousarray(a).tobytes()


def assert_reads_alike(alignment, motion):
    """Every reader of the two files gives the same bits, and the same clip table."""
    with MotionDatabase.open(alignment) as a, MotionDatabase.open(motion) as m:
        assert a.store == "alignment" and m.store == "motion"
        assert a.names == m.names and a.columns == m.columns and a.frame_columns == m.frame_columns
        ta, tm = a.table(), m.table()
        assert set(ta) == set(tm)
        for col in tm:
            x, y = np.asarray(ta[col]), np.asarray(tm[col])
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), col
        for x, y in zip(a.read_many(range(len(a))), m.read_many(range(len(m)))):
            for k in READ:
                p, q = getattr(x, k), getattr(y, k)
                assert (p is None) == (q is None) and (p is None or _bits(p) == _bits(q)), (x.name, k)
        for i in range(0, len(m), max(1, len(m) // 7)):
            assert _bits(a.read(i).rotations) == _bits(m.read(i).rotations)
        for ba, bm in zip(a.batches(batch_size=9), m.batches(batch_size=9)):
            assert ba.names == bm.names
            for k in READ:
                p, q = getattr(ba, k), getattr(bm, k)
                assert (p is None) == (q is None) and (p is None or _bits(p) == _bits(q)), k
        for i in range(len(m)):
            assert _bits(a.read_frame_column(i, "action_frame")) == _bits(m.read_frame_column(i, "action_frame"))
        for k in range(len(m.skeletons)):
            pa, pm = a.packed(k), m.packed(k)
            t = m.clip_table()
            mine = t.skeleton == k
            rows = np.concatenate([np.arange(s, s + n) for s, n in zip(t.start[mine], t.length[mine])])
            for name in pm:
                assert _bits(pa[name][rows]) == _bits(pm[name][rows]), name
            with pytest.MonkeyPatch.context() as mp:  # the clips shared over threads: the same bits
                mp.setattr("torchsplice.store.assembly.SPLIT_FRAMES", 1)
                shared = a.assembled(k, t.start[mine], t.length[mine], threads=3)
            for name in shared:
                assert _bits(shared[name]) == _bits(pm[name][rows]), name
            # windows inside clips, as the training dataset reads them
            starts, lengths = t.start[mine][:5] + 1, np.minimum(t.length[mine][:5] - 1, 17)
            for name in ("rotations", "root_translation"):
                wa = a.frame_array(k, name).gather(starts, lengths)
                wm = m.frame_array(k, name).gather(starts, lengths)
                assert _bits(wa) == _bits(wm), name


@pytest.fixture(scope="module")
def sample_jobs(sample_db, tmp_path_factory):
    """The sample's job (splice, naive, cpmc) as a motion store and as an alignment store."""
    folder = tmp_path_factory.mktemp("stores")
    return (_job(sample_db, folder / "motion.h5", "motion", workers=2),
            _job(sample_db, folder / "alignment.h5", "alignment", workers=2))


def test_an_alignment_store_reads_bit_for_bit_as_the_motion_store(sample_jobs):
    motion, alignment = sample_jobs
    assert_reads_alike(alignment, motion)
    with h5py.File(alignment, "r") as f:  # what plain h5py finds
        assert f.attrs["store"] == "alignment" and "assembly_curve" in f.attrs["store_readme"]
        assert int(f.attrs["schema_version"]) == 2
        kind, method = f["clips/assembly_kind"][()], f["clips/method"].asstr()[()]
        assert set(kind[method == "cpmc"]) == {-1}  # cpmc through the timewarp keeps its frames
        assert set(kind[method != "cpmc"]) == {1}  # splice and naive: a curve and a pelvis rotation
        sk = f["skeletons/0"]
        cpmc = np.concatenate([np.arange(s, s + n) for s, n, m in zip(f["clips/start"][()], f["clips/length"][()], method)
                               if m == "cpmc"])
        assert np.isfinite(sk["rotations"][()][cpmc]).all() and sk["assembly_curve"].dtype == np.float64


def test_parts_held_in_memory_or_read_clip_by_clip_give_the_same_frames(sample_jobs, monkeypatch):
    """An alignment store's per-frame parts are held in memory where small (HELD_PARTS_BYTES),
    else read clip by clip: the reads are the motion store's either way; and a reader that asks
    for some arrays gets those, with the bits of a full read."""
    import torchsplice.store.assembly as assembly

    motion, alignment = sample_jobs
    monkeypatch.setattr(assembly, "HELD_PARTS_BYTES", 0)
    assert_reads_alike(alignment, motion)
    with MotionDatabase.open(alignment) as a:
        for i in range(assembly.HOLD_AFTER_READS):
            a.read(i)
        assert a._assembly().held and not any(v is not None for v in a._assembly().held.values())
    monkeypatch.undo()
    with MotionDatabase.open(alignment) as a:
        t = a.clip_table()
        rows = np.random.default_rng(1).permutation(len(t.start))[:40]
        starts, lengths = t.start[rows] + 2, np.maximum(t.length[rows] - 5, 0)
        full = a.assembled(0, starts, lengths)
        assert (0, "assembly_curve") not in a._assembly().held  # a reader of a few clips reads no more
        for _ in range(assembly.HOLD_AFTER_READS - 1):
            assert all(_bits(x) == _bits(full[n]) for n, x in a.assembled(0, starts, lengths).items())
        assert a._assembly().held[(0, "assembly_curve")] is not None
        for names in (("rotations",), ("rotations", "root_translation"), ("root_translation", "action_frame")):
            some = a.assembled(0, starts, lengths, names=names)
            assert sorted(some) == sorted(n for n in names if n in full)
            for n in some:
                assert _bits(some[n]) == _bits(full[n]), (names, n)


def test_a_read_shared_over_threads_gives_the_one_threads_bits(sample_jobs, monkeypatch):
    """Every thread count assembles the same bits (each thread its own clips and rows), and
    the motion store's frames; a batch under SPLIT_FRAMES a thread stays in the calling thread."""
    import torchsplice.core.threads as threads
    import torchsplice.store.assembly as assembly

    motion, alignment = sample_jobs
    with MotionDatabase.open(alignment) as a, MotionDatabase.open(motion) as m:
        t = a.clip_table()
        rows = np.random.default_rng(2).permutation(len(t.start))
        starts, lengths = t.start[rows] + 1, np.maximum(t.length[rows] - 3, 0)
        one = a.assembled(0, starts, lengths, threads=1)
        want = m.assembled(0, starts, lengths)
        assert all(_bits(one[n]) == _bits(want[n]) for n in want)
        made = []
        pool_of = threads._pool_of
        monkeypatch.setattr(threads, "_pool_of", lambda n: made.append(n) or pool_of(n))
        few = np.cumsum(lengths) < 3 * assembly.SPLIT_FRAMES  # too few frames to share over 3 threads
        a.assembled(0, starts[few], lengths[few], threads=3)
        assert made == []
        a.assembled(0, starts, lengths, threads=1)
        assert made == []
        monkeypatch.setattr(assembly, "SPLIT_FRAMES", 1)
        for n_threads in (2, 3, 7):
            shared = a.assembled(0, starts, lengths, threads=n_threads)
            assert all(_bits(shared[n]) == _bits(one[n]) for n in one), n_threads
        # a chunk a thread: the calling thread's and those of a pool of the rest
        assert sorted(set(made)) == [1, 2, 6] and len(made) == 1 + 2 + 6


def test_a_part_that_is_mostly_zeros_stores_only_its_chunks_with_data(tmp_path):
    from torchsplice.store.assembling import _write_nonzero_chunks

    a = np.zeros((1000, 4, 4), np.float32)
    a[300:310, 2:] = 1.0  # rows 400..409 of the dataset: chunk 6
    a[999, 0, 0] = 2.0  # row 1099: chunk 17
    with h5py.File(tmp_path / "sparse.h5", "w") as f:
        d = f.create_dataset("x", shape=(1100, 4, 4), chunks=(64, 4, 4), dtype=np.float32, compression="lzf",
                             shuffle=True)
        d[:100] = 5.0  # rows another append wrote, sharing chunk 1 with these
        _write_nonzero_chunks(d, 100, a)
        assert np.array_equal(d[100:], a) and (d[:100] == 5.0).all()
        assert d.id.get_num_chunks() == 2 + 2  # chunks 0 and 1 from before, 6 and 17
        _write_nonzero_chunks(d, 100, np.zeros_like(a))  # nothing to write
        assert d.id.get_num_chunks() == 4


def test_the_alignment_store_of_splice_and_naive_is_smaller(sample_db, tmp_path):
    motion = _job(sample_db, tmp_path / "m.h5", "motion", methods="splice,naive")
    alignment = _job(sample_db, tmp_path / "a.h5", "alignment", methods="splice,naive")
    assert alignment.stat().st_size < 0.75 * motion.stat().st_size


def test_the_alignment_store_is_self_contained(sample_db, sample_jobs, tmp_path):
    db = tmp_path / "input.h5"
    shutil.copy(sample_db, db)
    out = _job(db, tmp_path / "alone.h5", "alignment", workers=1)
    db.unlink()  # its input deleted, the output reads the same
    assert_reads_alike(out, sample_jobs[0])


@pytest.mark.parametrize("layout", ["copy", "virtual"])
def test_a_resumed_alignment_store_is_bit_identical(sample_db, sample_jobs, tmp_path, monkeypatch, layout):
    import torchsplice.job.engines.inline as executors

    out = tmp_path / "out.h5"
    real, calls = executors.run_task, []

    def interrupted(plan, task, *args, **kw):
        calls.append(task)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(plan, task, *args, **kw)

    monkeypatch.setattr(executors, "run_task", interrupted)
    with pytest.raises(KeyboardInterrupt):
        splice_all(sample_db, out, store="alignment", methods="splice,naive,cpmc", workers=1, batch_pairs=7, index=False,
                   layout=layout)
    assert not out.exists()
    monkeypatch.setattr(executors, "run_task", real)
    summary = splice_all(sample_db, out, store="alignment", methods="splice,naive,cpmc", workers=1, batch_pairs=7,
                         index=False, layout=layout)
    assert summary.resumed > 0
    assert_reads_alike(out, sample_jobs[0])
    with h5py.File(out, "r") as f, h5py.File(sample_jobs[1], "r") as g:
        assert np.array_equal(f["assembly/banks/0/rotations"][()], g["assembly/banks/0/rotations"][()])
        for col in ("assembly_bank", "assembly_locomotion", "assembly_action", "assembly_crop"):
            assert np.array_equal(f[f"clips/{col}"][()], g[f"clips/{col}"][()]), col


def test_shards_merge_into_the_same_alignment_store(sample_db, sample_jobs, tmp_path):
    out = tmp_path / "sliced.h5"
    for k in (1, 2, 3):
        splice_all(sample_db, out, store="alignment", methods="splice,naive,cpmc", batch_pairs=9, shard=f"{k}/3")
    assert not out.exists()  # slices write no output
    shards = sorted((tmp_path / ".sliced.h5.parts").glob("part-*.shard"))
    assert len(shards) == 9  # a task's parts, not its frames
    broken = shards[4].read_bytes()
    shards[4].write_bytes(broken[:-7])  # a shard cut short: one line naming it
    with pytest.raises(TorchspliceError, match="not a whole part") as exc:
        merge_job(out, progress=False)
    assert str(shards[4]) in str(exc.value) and "\n" not in str(exc.value)
    shards[4].write_bytes(broken)
    merge_job(out, progress=False)
    assert_reads_alike(out, sample_jobs[0])


def test_a_virtual_alignment_store_reads_its_shards_parts_as_the_motion_store(sample_db, sample_jobs, tmp_path):
    """``--layout virtual --store alignment``: the table and banks in the output, each task's
    per-frame parts in its shard under OUT.shards/, read through virtual datasets; whole
    runs, a --shard run merged, and the output moved with its shards read the same bits."""
    out = _job(sample_db, tmp_path / "virtual.h5", "alignment", layout="virtual", batch_pairs=9, workers=2)
    assert_reads_alike(out, sample_jobs[0])
    with MotionDatabase.open(out) as db:
        assert db.store == "alignment" and db.h5["skeletons/0/assembly_curve"].is_virtual
    shards = sorted((tmp_path / "virtual.h5.shards").rglob("part-*.h5"))
    assert len(shards) > 3 and sum(f.stat().st_size for f in shards) < out.stat().st_size * 20
    moved = tmp_path / "moved"
    moved.mkdir()
    shutil.move(out, moved / out.name)
    shutil.move(tmp_path / "virtual.h5.shards", moved / "virtual.h5.shards")
    assert_reads_alike(moved / out.name, sample_jobs[0])
    sliced = tmp_path / "sliced.h5"
    for k in (1, 2):
        splice_all(sample_db, sliced, store="alignment", layout="virtual", methods="splice,naive,cpmc", batch_pairs=9,
                   shard=f"{k}/2")
    merge_job(sliced, progress=False)
    assert_reads_alike(sliced, sample_jobs[0])


def test_copied_sources_keep_their_frames_in_an_alignment_store(sample_db, tmp_path):
    out = _job(sample_db, tmp_path / "copied.h5", "alignment", methods="splice", copy_sources=True)
    with MotionDatabase.open(out) as db, MotionDatabase.open(sample_db) as src:
        t = db.clip_table()
        assert set(t.role) > {"spliced"} and len(db) == 25 + len(src)
        for name in src.names:
            assert _bits(db.read(name).rotations) == _bits(src.read(name).rotations)
        assert set(db.h5["clips/assembly_kind"][()][t.role != "spliced"].tolist()) == {-1}


def test_the_dataset_reads_an_alignment_store_as_a_motion_store(sample_jobs):
    from torchsplice.data import MotionDataset

    motion, alignment = sample_jobs
    feats = ["rotations", "root_translation", "positions", "action_frame"]
    for kw in ({}, {"window": 16, "stride": 9}):
        da, dm = MotionDataset(alignment, features=feats, **kw), MotionDataset(motion, features=feats, **kw)
        assert len(da) == len(dm) > 0
        for i in range(0, len(dm), max(1, len(dm) // 6)):
            x, y = da[i], dm[i]
            for f in feats:
                assert _bits(x[f]) == _bits(y[f]), (i, f)


def _device_batches(path, device, feats, num_workers=0, **kw):
    """``(batch assembled in the collate step on device, the same items collated as usual)``."""
    from torch.utils.data import DataLoader

    from torchsplice.data import MotionDataset, collate_motion

    ds = MotionDataset(path, features=feats, assemble_on=device, **kw)
    plain = MotionDataset(path, features=feats, **kw)
    loader = DataLoader(ds, batch_size=7, collate_fn=ds.collate, num_workers=num_workers)
    for b, batch in enumerate(loader):
        yield batch, collate_motion(plain.__getitems__(range(7 * b, min(7 * b + 7, len(plain)))))


@pytest.mark.parametrize("num_workers", [0, 2])
def test_a_dataset_assembles_whole_batches_in_its_collate_step(sample_jobs, num_workers):
    motion, alignment = sample_jobs
    feats = ["rotations", "positions", "velocities", "action_frame"]
    for path, tol in ((alignment, 1e-5), (motion, 0.0)):   # parts assembled by torch; frames read as they are
        for kw in ({}, {"window": 16, "stride": 9}):
            n = 0
            for got, want in _device_batches(path, "cpu", feats, num_workers, **kw):
                assert got["name"] == want["name"] and torch.equal(got["mask"], want["mask"])
                for f in feats:
                    scale = 1.0 if f == "rotations" else float(want[f].abs().nan_to_num().max()) + 1.0
                    err = (got[f] - want[f]).abs().nan_to_num().max()
                    assert float(err) <= tol * scale * (30 if f == "velocities" else 1), (path.name, f, float(err))
                    assert torch.equal(got[f].isnan(), want[f].isnan())
                n += len(got["name"])
            assert n > 0


def test_a_gpu_collate_in_a_worker_process_is_one_line(sample_jobs, monkeypatch):
    from torchsplice.data import DatasetError, MotionDataset

    ds = MotionDataset(sample_jobs[1], assemble_on="cuda")
    items = ds.__getitems__([0, 1])
    assert all("rotations" not in it for it in items)
    monkeypatch.setattr(torch.utils.data, "get_worker_info", lambda: object())
    with pytest.raises(DatasetError, match="num_workers=0"):
        ds.collate(items)
    with pytest.raises(ValueError, match="choose one"):
        MotionDataset(sample_jobs[1], assemble_on="cpu", preload=True)


DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.gpu)]


@pytest.mark.parametrize("device", DEVICES)
def test_a_dataset_assembles_its_batches_on_the_device(sample_jobs, device):
    """A dataset over an alignment store assembling on ``device``: its batches there, positions
    within 1e-4 of the compiled assembly's (float32 forward kinematics)."""
    n = 0
    for got, want in _device_batches(sample_jobs[1], device, ["rotations", "positions"]):
        assert got["rotations"].device.type == device and got["mask"].device.type == device
        assert float((got["positions"].cpu() - want["positions"]).abs().max()) <= 1e-4
        n += 1
    assert n > 0


def test_materialize_writes_the_motion_store(sample_jobs, tmp_path):
    """(The ``materialize`` command's one line naming ``--store``: tests/cli/test_command_words.py.)"""
    motion, alignment = sample_jobs
    out = tmp_path / "materialized.h5"
    with MotionDatabase.open(motion) as m:
        assert materialize(alignment, out) == len(m)
    assert out.is_file() and (tmp_path / "materialized.h5.index.csv").is_file()
    with MotionDatabase.open(out) as db:
        assert db.store == "motion" and "assembly_curve" not in db.h5["skeletons/0"]
    for x, y in ((out, motion),):
        with MotionDatabase.open(x) as a, MotionDatabase.open(y) as m:
            assert a.names == m.names
            for k in READ[:2]:
                assert _bits(a.packed(0)[k]) == _bits(m.packed(0)[k])
    with pytest.raises(TorchspliceError, match="is a motion store already") as exc:
        materialize(motion, tmp_path / "again.h5")
    assert "\n" not in str(exc.value) and not (tmp_path / "again.h5").exists()


def test_render_and_view_draw_an_alignment_store_as_the_motion_store(sample_jobs, tmp_path):
    from torchsplice.viz.render import render
    from torchsplice.viz.sources import read_clips
    from torchsplice.viz.viewer import write_viewer

    motion, alignment = sample_jobs
    for store, path in (("m", motion), ("a", alignment)):
        clips, spec = read_clips(path, ["jog+carry_box"])
        render(clips, tmp_path / f"{store}.png", titles=[c.name for c in clips], up_axis=spec.up_axis)
        write_viewer(path, tmp_path / f"{store}.html", clips=["jog+carry_box", "jog+wave"], quiet=True)
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "m.png").read_bytes()
    page = (tmp_path / "a.html").read_text().replace(str(alignment), str(motion)).replace(alignment.name, motion.name)
    assert page == (tmp_path / "m.html").read_text()


def test_bad_input_gets_one_line(sample_db, sample_jobs, tmp_path, capsys):
    motion, alignment = sample_jobs
    with pytest.raises(SystemExit) as exit_:
        run(capsys, "splice-all", sample_db, "-o", tmp_path / "x.h5", "--store", "alignmnt")
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "did you mean 'alignment'" in err and "Traceback" not in err
    with pytest.raises(TorchspliceError, match="did you mean 'alignment'"):
        splice_all(sample_db, tmp_path / "x.h5", store="alignmnt")
    # an append of motions to an alignment store
    with pytest.raises(DatabaseError, match="is an alignment store.*materialize"):
        MotionDatabase.open(alignment, "a")
    # damaged source rows, missing banks, parts that point nowhere: one line naming the file
    for damage in ("no banks", "short bank", "bad row"):
        broken = tmp_path / f"{damage.replace(' ', '_')}.h5"
        shutil.copy(alignment, broken)
        with h5py.File(broken, "r+") as f:
            if damage == "no banks":
                del f["assembly/banks"]
            elif damage == "short bank":
                f["assembly/banks/0/lengths"][0] = 10 ** 7
            else:
                f["clips/assembly_action"][3] = 10 ** 6
        with pytest.raises(DatabaseError) as exc:
            MotionDatabase.open(broken).close()
        assert str(broken) in str(exc.value) and "\n" not in str(exc.value), damage
        rc, _, err = run(capsys, "info", broken)
        assert rc != 0 and str(broken) in error_line(err)


def test_dry_run_says_what_the_alignment_store_would_take(sample_db, tmp_path):
    summary = splice_all(sample_db, tmp_path / "x.h5", dry_run=True)
    assert summary.alignment is not None and summary.alignment.bytes > 0
    assert "with store alignment about" in "\n".join(summary.lines()) and not (tmp_path / "x.h5").exists()
    assert "with --store alignment about" in "\n".join(summary.lines(flag))  # the command line names its flag


def _torch_against_kernels(path, device: str = "cpu") -> float:
    """The largest difference between the torch assembly (on ``device``) and the compiled
    kernels'; the per-frame columns, read and moved there, are the same bits."""
    worst = 0.0
    with MotionDatabase.open(path) as db:
        t = db.clip_table()
        for k in sorted(set(t.skeleton.tolist())):
            r = np.flatnonzero(t.skeleton == k)
            for starts, lengths in ((t.start[r], t.length[r]), (t.start[r] + 3, np.minimum(t.length[r] - 3, 20))):
                a = db.assembled(k, starts, lengths)
                b = db.assembled_on(k, starts, lengths, device)
                assert a.keys() == b.keys()
                for name in ("rotations", "root_translation", "translations"):
                    if name in a:
                        assert b[name].device.type == device
                        assert b[name].dtype == torch.float32 and b[name].shape == a[name].shape
                        worst = max(worst, float(np.abs(a[name] - b[name].cpu().numpy()).max()))
                for name in db.frame_columns:
                    assert b[name].device.type == device
                    np.testing.assert_array_equal(b[name].cpu().numpy(), a[name], err_msg=name)
    return worst


@pytest.mark.parametrize("device", DEVICES)
def test_the_torch_assembly_on_a_device_gives_the_kernels_frames(sample_jobs, device):
    """An alignment store's clips (whole, and windows inside them) assembled by torch on
    ``device`` (what a GPU reads with) are the compiled kernels' frames within 1e-5."""
    assert _torch_against_kernels(sample_jobs[1], device) <= 1e-5


@pytest.mark.parametrize("device", DEVICES)
def test_a_batch_asked_for_on_a_device_is_assembled_there(sample_jobs, device):
    """``read_batch(device=...)`` of an alignment store (assembled by torch on a GPU, by the
    kernels on the CPU) gives the motion store's padded batch on that device, within 1e-5."""
    with MotionDatabase.open(sample_jobs[1]) as a, MotionDatabase.open(sample_jobs[0]) as m:
        ba, bm = a.read_batch(list(range(12)), device=device), m.read_batch(list(range(12)))
        assert ba.rotations.device.type == ba.mask.device.type == device
        assert torch.equal(ba.mask.cpu(), bm.mask) and torch.equal(ba.lengths.cpu(), bm.lengths)
        assert float((ba.rotations.cpu() - bm.rotations).abs().max()) <= 1e-5
        assert float((ba.root_translation.cpu() - bm.root_translation).abs().max()) <= 1e-5 * (
            1 + float(bm.root_translation.abs().max()))


def test_the_stores_codes_are_the_kernels():
    from torchsplice.cpu.splice import METHOD_CODES
    from torchsplice.cpu.standing import TIMING_CODES
    from torchsplice.store import assembly

    assert assembly.METHOD_CODES == METHOD_CODES and assembly.TIMING_CODES == TIMING_CODES


def test_the_arc_table_gives_qslerps_bits():
    """Reads look the slerps' angles up (cpu.assemble.arc_table); the result is qslerp's, bit for
    bit, on opposite hemispheres, equal and nearly equal neighbours, and at the curve's ends."""
    from torchsplice.cpu.assemble import arc_table, timewarp_rows

    rng = np.random.default_rng(3)
    N, J = 400, 5   # rows 0..39 the action, every row the locomotion
    rot = rng.normal(size=(N, J, 4))
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    rot[5:9] = rot[4]                       # equal neighbours (theta 0)
    rot[12] = -rot[11]                      # the same rotation, opposite sign (a flip, theta 0)
    rot[20] = rot[19] + 1e-9                # nearly equal (the linear branch)
    rot[20] /= np.linalg.norm(rot[20], axis=-1, keepdims=True)
    rot[25:] *= np.where(rng.random((N - 25, J, 1)) < 0.5, -1.0, 1.0)  # random hemispheres
    n_act = 40
    trans = rng.normal(size=(N, J, 3))
    upper = np.array([False, True, True, False, True])
    T = 300
    curve = np.concatenate([np.linspace(-2.0, n_act + 2.0, T - 3), [0.0, n_act - 1.0, 11.5]])
    prot = rng.normal(size=(T, 4))
    outs = []
    for arc in (np.empty((0, J, 2)), arc_table(rot, upper)):
        orot, otrans = np.empty((T, J, 4)), np.empty((T, J, 3))
        timewarp_rows(rot, trans, arc, 0, 0, n_act, upper, 0, curve, prot, T, orot, otrans)
        outs.append((orot, otrans))
    assert outs[0][0].tobytes() == outs[1][0].tobytes() and outs[0][1].tobytes() == outs[1][1].tobytes()
    assert np.isfinite(outs[1][0]).all()


BN_TAKES = ("dataset-1_walk_normal_001", "dataset-2_walk_normal_008", "dataset-2_walk-turn-left_active_025",
            "dataset-1_bow_normal_001", "dataset-2_wave-left-hand_normal_001",
            "dataset-2_raise-up-both-hands_normal_001")


@pytest.fixture(scope="module")
def real_dbs(mocap_dir, tmp_path_factory):
    """Six Bandai Namco takes (walks, a turn, standing actions) and the LAFAN1 clips, imported."""
    from torchsplice.formats.importer import import_bvh

    folder = tmp_path_factory.mktemp("real")
    src = folder / "bn"
    src.mkdir()
    for name in BN_TAKES:
        (src / f"{name}.bvh").symlink_to(mocap_dir / BANDAI / f"{name}.bvh")
    import_bvh([src], folder / "bn.h5", spec="bandai_namco")
    import_bvh([mocap_dir / "lafan1_via_pypi_bvhtools"], folder / "lafan.h5")
    return folder / "bn.h5", folder / "lafan.h5"


@pytest.mark.realdata
@pytest.mark.parametrize("timing", ["loop", pytest.param("hold", marks=pytest.mark.slow),
                                    pytest.param("fit", marks=pytest.mark.slow)])
def test_standing_actions_on_real_clips_read_bit_for_bit(real_dbs, tmp_path, timing):
    bn, _ = real_dbs
    motion = _job(bn, tmp_path / "m.h5", "motion", timing=timing)
    alignment = _job(bn, tmp_path / "a.h5", "alignment", timing=timing)
    with MotionDatabase.open(alignment) as db:
        kinds = set(db.h5["clips/assembly_kind"][()].tolist())
        assert 2 in kinds and 1 in kinds  # standing and time-aligned clips
    assert_reads_alike(alignment, motion)
    assert _torch_against_kernels(alignment) <= 1e-5  # a loop's inertialized seams too


@pytest.mark.realdata
def test_retargeted_actions_read_bit_for_bit(real_dbs, tmp_path):
    bn, lafan = real_dbs
    options = dict(actions_db=lafan, actions="*", methods="splice,naive")
    motion = _job(bn, tmp_path / "m.h5", "motion", **options)
    alignment = _job(bn, tmp_path / "a.h5", "alignment", **options)
    with MotionDatabase.open(alignment) as db:
        names = [n for b in db.h5["assembly/banks"].values() for n in b["names"].asstr()[()]]
        assert any(n.endswith("(retargeted)") for n in names)  # each action once per target skeleton
    assert_reads_alike(alignment, motion)
