"""Every reader works on both stores unchanged (issue 31): one job spliced from the built-in
sample twice, into a motion store and into an alignment store, then each reader run on both
gives the same result: ``export`` in every built-in format and a plug-in's, ``info`` (the
summary it prints), ``evaluate`` (the report's numbers), ``retarget`` and ``mirror`` of the
spliced output, and ``splice_all`` whose input is the spliced output. What may differ is said
where it does: the input's file name where an output records it, and the store's kind.

Also here: the source banks of an alignment store carry a Fletcher-32 checksum, so a flipped
byte that still decompresses to finite values is one line naming the file and the bank, not a
motion; a bank written without the checksum (files from before it) still reads."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.job.test_job import VOLATILE_RUN_KEYS, h5_dump
from tests.store.test_alignment_store import READ, _bits, assert_reads_alike
from torchsplice.core.errors import DatabaseError
from torchsplice.evaluation.report import evaluate_database
from torchsplice.formats.exporters import export_clips
from torchsplice.job import splice_all
from torchsplice.retarget import retarget_clips
from torchsplice.retarget.mirror import mirror_clips
from torchsplice.store.database import MotionDatabase

SOME = "jog+*,walk_curve+wave*"  # 18 clips: every method (splice, naive, cpmc), several actions
BANK = "assembly/banks/0"


@pytest.fixture(scope="module")
def stores(sample_db, tmp_path_factory) -> tuple[Path, Path]:
    """``(motion store, alignment store)`` of the sample's job (splice, naive and cpmc)."""
    folder = tmp_path_factory.mktemp("both")
    out = {}
    for store in ("motion", "alignment"):
        out[store] = folder / f"{store}.h5"
        splice_all(sample_db, out[store], store=store, methods="splice,naive,cpmc", workers=1, index=False)
    return out["motion"], out["alignment"]


def test_the_two_stores_hold_the_same_clips(stores):
    """The premise of every test here: the two files are the two stores of one job."""
    motion, alignment = stores
    assert_reads_alike(alignment, motion)


# ------------------------------------------------------------------------------------- export
def _files(folder: Path) -> list[Path]:
    return sorted(p.relative_to(folder) for p in folder.rglob("*") if p.is_file())


def _arrays(path: Path) -> dict:
    if path.suffix == ".npy":
        return {"": np.load(path, allow_pickle=False)}
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _same_file(x: Path, y: Path, names_input: bool, inputs: tuple[Path, Path]) -> None:
    """``x`` (exported from the motion store) and ``y`` (from the alignment store) hold the same
    arrays (.npz, .npy: names, dtypes, shapes, bits) or the same bytes; with ``names_input``,
    the same bytes but for the input database's path."""
    if x.suffix in (".npz", ".npy"):
        a, b = _arrays(x), _arrays(y)
        assert sorted(a) == sorted(b), x.name
        for k in a:
            assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, (x.name, k)
            assert _bits(a[k]) == _bits(b[k]), (x.name, k)
        return
    p, q = x.read_bytes(), y.read_bytes()
    if names_input:
        assert str(inputs[0]).encode() in p and str(inputs[1]).encode() in q, x.name  # what differs, there
        p, q = p.replace(str(inputs[0]).encode(), b"<input>"), q.replace(str(inputs[1]).encode(), b"<input>")
    assert p == q, x.name


EXPORTS = {"npz": ("npz", {}), "npz-packed": ("npz", {"packed": True}), "npz-6d": ("npz", {"features": "6d"}),
           "bvh": ("bvh", {}), "humanml3d": ("humanml3d", {}), "humanml3d-shards": ("humanml3d", {"shards": 2}),
           "toy-plugin": ("toy", {})}


@pytest.mark.parametrize("format, options", EXPORTS.values(), ids=EXPORTS.keys())
def test_every_export_format_writes_the_same_files_from_both_stores(stores, tmp_path, format, options):
    """Every built-in format (npz: a file a clip, packed, 6D features; BVH; HumanML3D: a folder,
    WebDataset shards) and a plug-in's (the toy CSV of tests/helpers/toy_exporter.py) write the
    same files from either store; only the HumanML3D index.csv differs, by the database path it
    records per clip."""
    if format == "toy":
        import toy_exporter  # noqa: F401 (registers the format)
    results = []
    for store, path in zip(("motion", "alignment"), stores):
        out = tmp_path / store / "clips.npz" if options.get("packed") else tmp_path / store
        out.parent.mkdir(exist_ok=True)
        results.append(export_clips(path, None, out=out, format=format, select=SOME, **options))
    m, a = results
    assert m.names == a.names and len(m.names) == 18 and m.frames == a.frames > 0 and m.fps == a.fps
    assert _files(tmp_path / "motion") == _files(tmp_path / "alignment")
    pairs = [(tmp_path / "motion" / f, tmp_path / "alignment" / f) for f in _files(tmp_path / "motion")]
    if options.get("packed") or options.get("shards"):  # a packed file and its index; the shards' tar files
        assert {x.suffix for x, _ in pairs} >= {".npz" if options.get("packed") else ".tar"}
    else:
        assert len(pairs) >= len(m.names)
    for x, y in pairs:
        _same_file(x, y, format == "humanml3d" and x.name == "index.csv", stores)


# --------------------------------------------------------------------------------------- info
def test_info_summarises_both_stores_alike(stores):
    """What ``info`` prints (``MotionDatabase.summary`` and the store's kind): the same clips,
    columns, labels, skeletons, roles and counts. The kind differs, and so does the schema
    version (2 for an alignment store, so that an older torchsplice refuses it:
    docs/alignment-store.md); the run record differs by the store option and what the job's
    plan hash covers."""
    motion, alignment = stores
    for clips, select in ((None, None), (["jog+wave", "jog+wave.cpmc"], None), (None, ["method:naive", "jog*"])):
        with MotionDatabase.open(motion) as m, MotionDatabase.open(alignment) as a:
            sm, sa = m.summary(clips=clips, select=select), a.summary(clips=clips, select=select)
            assert (m.store, a.store) == ("motion", "alignment")
        assert (sm.pop("path"), sa.pop("path")) == (str(motion), str(alignment))
        assert (sm.pop("schema_version"), sa.pop("schema_version")) == (1, 2)
        rm, ra = sm.pop("run"), sa.pop("run")
        assert ra.pop("store") == "alignment" and rm.pop("store", "motion") == "motion"
        for k in (*VOLATILE_RUN_KEYS, "plan_sha256"):
            rm.pop(k, None), ra.pop(k, None)
        assert rm == ra
        assert sm == sa and sm["clips"], (clips, select)


# ----------------------------------------------------------------------------------- evaluate
def test_evaluate_reports_the_same_numbers_on_both_stores(stores, tmp_path):
    """The report's aggregates and every clip's row (JSON, CSV) are equal; its Markdown too,
    but for the database it names."""
    reports = []
    for store, path in zip(("motion", "alignment"), stores):
        agg = evaluate_database(path, tmp_path / f"{store}.md", pictures=False, select=SOME,
                                json=tmp_path / f"{store}.json", csv=tmp_path / f"{store}.csv")
        data = json.loads((tmp_path / f"{store}.json").read_text())
        assert data.pop("database") == str(path)
        text = (tmp_path / f"{store}.md").read_text()
        assert path.name in text
        text = text.replace(str(path), "<input>").replace(path.name, "<input>")
        reports.append((agg, data, (tmp_path / f"{store}.csv").read_text(), text))
    (agg_m, json_m, csv_m, md_m), (agg_a, json_a, csv_a, md_a) = reports
    assert agg_m == agg_a and sorted(agg_m) == ["cpmc", "naive", "splice"]
    assert len(json_m["clips"]) == 18 and json_m == json_a
    assert csv_m == csv_a and md_m == md_a


# --------------------------------------------------- outputs written from a spliced output
def _dump(path: Path, source: Path) -> dict:
    """Every dataset and attribute of ``path`` (:func:`tests.job.test_job.h5_dump`), its input
    ``source`` named as ``<input>`` and the run record less what identifies the input file
    (its path, size and time; the plan's hash, which covers them)."""
    out = {}
    for name, entry in h5_dump(path).items():
        attrs = dict(entry[-1])
        if "run" in attrs:
            attrs["run"] = {k: v for k, v in attrs["run"].items() if k not in ("database", "source", "plan_sha256")}
        out[name] = repr((*entry[:-1], attrs)).replace(str(source), "<input>").replace(source.name, "<input>")
    return out


def _same_output(x: Path, y: Path, inputs: tuple[Path, Path]) -> None:
    """Outputs written from the two stores: every dataset and attribute equal (but where they
    name their input), and every clip read with the same bits."""
    dx, dy = _dump(x, inputs[0]), _dump(y, inputs[1])
    assert sorted(dx) == sorted(dy)
    for name in dx:
        assert dx[name] == dy[name], name
    with MotionDatabase.open(x) as a, MotionDatabase.open(y) as b:
        assert a.store == b.store and a.names == b.names and len(a) > 0
        for p, q in zip(a.read_many(range(len(a))), b.read_many(range(len(b)))):
            for k in READ:
                u, v = getattr(p, k), getattr(q, k)
                assert (u is None) == (v is None) and (u is None or _bits(u) == _bits(v)), (p.name, k)


def _retarget(src, out):
    return retarget_clips(src, select=SOME, to="smpl22", out=out)


def _mirror(src, out):
    return mirror_clips(src, select=SOME, out=out)


def _splice_into(store):
    def run(src, out):  # spliced clips as the locomotions and the actions (a cpmc and a naive one among them)
        return splice_all(src, out, locomotions="walk_straight+carry_box,jog+wave.cpmc",
                          actions="walk_curve+punch.naive,turn_sharp+wave", store=store, workers=1, index=False)
    return run


@pytest.mark.parametrize("write", [_retarget, _mirror, _splice_into("motion"), _splice_into("alignment")],
                         ids=["retarget", "mirror", "splice_all-motion", "splice_all-alignment"])
def test_a_spliced_output_of_either_store_gives_the_same_output(stores, tmp_path, write):
    """``retarget`` (onto smpl22), ``mirror`` and ``splice_all`` (into either store) of the
    spliced output write the same file from either store."""
    outs = [tmp_path / f"from_{store}.h5" for store in ("motion", "alignment")]
    for src, out in zip(stores, outs):
        write(src, out)
    _same_output(*outs, stores)


# ------------------------------------------------------------------ source banks' checksums
def _flip_found(ds: h5py.Dataset, folder: Path) -> int:
    """A byte of ``ds``'s first chunk whose flip, in a copy of the chunk stored without a
    checksum (the same filters otherwise: the same compressed bytes), still decompresses, to
    finite values that differ: the damage only a checksum catches. Returns its place in the chunk."""
    whole = ds[: ds.chunks[0]]
    with h5py.File(folder / "unchecked.h5", "w") as f:
        plain = f.create_dataset("x", data=whole, chunks=ds.chunks, compression="lzf", shuffle=True)
        _, raw = plain.id.read_direct_chunk((0,) * ds.ndim)
        assert ds.id.read_direct_chunk((0,) * ds.ndim)[1][:-4] == raw  # the stored chunk: these bytes and a checksum
        for at in range(len(raw) // 2, len(raw) // 2 + 200):
            flipped = bytearray(raw)
            flipped[at] ^= 0x04
            plain.id.write_direct_chunk((0,) * ds.ndim, bytes(flipped))
            try:
                got = plain[()]
            except OSError:
                continue
            if np.isfinite(got).all() and not np.array_equal(got, whole):
                return at
    raise AssertionError("no byte of the chunk flips silently")


def test_a_flipped_byte_in_a_source_bank_is_one_line_naming_the_file_and_the_bank(stores, tmp_path):
    path = tmp_path / "flipped.h5"
    shutil.copy(stores[1], path)
    with h5py.File(path, "r") as f:
        ds = f[f"{BANK}/rotations"]
        assert ds.fletcher32 and f[f"{BANK}/translations"].fletcher32
        at = _flip_found(ds, tmp_path)
        info, rows = ds.id.get_chunk_info(0), min(ds.chunks[0], len(ds))
    with open(path, "r+b") as raw:
        raw.seek(info.byte_offset + at)
        byte = raw.read(1)[0]
        raw.seek(info.byte_offset + at)
        raw.write(bytes([byte ^ 0x04]))
    with MotionDatabase.open(path) as db:
        with pytest.raises(DatabaseError) as caught:
            db.read(0)
    line = str(caught.value)
    assert "\n" not in line and line.startswith(f"{path}: damaged alignment store: bank 0 ({BANK}) cannot be read from ")
    assert f"(rows 0:{rows} of its rotations: " in line


def test_a_bank_written_without_a_checksum_still_reads(stores, tmp_path):
    """A store whose banks have no checksum (as written before it) reads as the motion store."""
    path = tmp_path / "unchecked.h5"
    shutil.copy(stores[1], path)
    with h5py.File(path, "r+") as f:
        for name in ("rotations", "translations"):
            old = f[f"{BANK}/{name}"]
            data, chunks = old[()], old.chunks
            del f[f"{BANK}/{name}"]
            f[BANK].create_dataset(name, data=data, chunks=chunks, compression="lzf", shuffle=True)
            assert not f[f"{BANK}/{name}"].fletcher32
    assert_reads_alike(path, stores[0])
