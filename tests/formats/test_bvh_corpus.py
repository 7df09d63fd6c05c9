"""Issue 10, "Nothing lost, no traceback": a corpus of 1,000+ malformed and edge-case BVH files.

The corpus (``bvh_corpus.py``) is made at test time from small real files. Every variant must
either read (and then equal the clean parse: joint names, frame count, fps, values) or be
refused with a ``TorchspliceError`` whose message is one line, under 300 characters, naming
the file; no other exception may escape. At the command line, ``torchsplice import`` over a
folder of them must print no traceback, skip each bad file with one ``skipped FILE: reason``
line, import every good one, and leave no stray file beside the database.
"""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path

import pytest
import torch

from bvh_corpus import Variant, build_corpus
from realdata import MOCAP, _require_mocap
from torchsplice.core.errors import TorchspliceError
from torchsplice.formats.bvh import BVHWarning, parse_bvh, read_bvh

pytestmark = pytest.mark.realdata
MAX_MESSAGE = 300


@pytest.fixture(scope="module")
def corpus():
    _require_mocap()  # skips (or fails under CI) with the reason when the real data is absent
    return build_corpus(MOCAP)


@pytest.fixture(scope="module")
def corpus_files(corpus, tmp_path_factory):
    folder = tmp_path_factory.mktemp("bvhc")
    return list(zip(corpus.variants, corpus.write(folder)))


@pytest.fixture(scope="module")
def refs(corpus):
    return {k: parse_bvh(text, path=f"<{k}>", dtype=torch.float64, name=k) for k, text in corpus.refs.items()}


def _digest(c) -> str:
    h = hashlib.sha256()
    for v in c.variants:
        h.update(v.stem.encode() + b"\0" + v.data + repr((v.parses, v.imports, v.frames, v.warns)).encode())
    return h.hexdigest()


def test_corpus_is_large_varied_and_deterministic(corpus):
    vs = corpus.variants
    assert len(vs) >= 1000
    assert len({v.stem.lower() for v in vs}) == len(vs)  # unique stems: clip names at import
    assert _digest(build_corpus(MOCAP)) == _digest(corpus)
    assert sum(v.parses for v in vs) >= 100 and sum(not v.parses for v in vs) >= 800
    kinds = " ".join(v.stem for v in vs)
    for kind in ("truncated_at", "frames_", "channels_", "nonfinite", "absurd", "bad", "bytes", "chain",
                 "wide", "bom", "crlf", "tabs", "trailing", "brace_missing", "duplicate_name", "empty",
                 "hierarchy_only", "control", "utf16", "huge_token"):
        assert kind in kinds, kind
    for key in corpus.refs:  # every source gives its share
        assert sum(v.stem.startswith(key + "_") for v in vs) >= 300


def _check_error(v: Variant, path: Path, exc: TorchspliceError) -> str | None:
    msg = str(exc)
    if "\n" in msg or "\r" in msg:
        return "message spans several lines"
    if len(msg) >= MAX_MESSAGE:
        return f"message of {len(msg)} characters"
    if str(path) not in msg:
        return "message does not name the file"
    if v.phrase and v.phrase.lower() not in msg.lower():
        return f"message lacks {v.phrase!r}"
    return None


def _check_clip(v: Variant, path: Path, m, ref, caught) -> str | None:
    frames = v.frames or (ref.num_frames if ref is not None else None)
    if frames is not None and m.num_frames != frames:
        return f"{m.num_frames} frames, expected {frames}"
    if m.name != path.stem or m.source != str(path):
        return f"name {m.name!r} / source {m.source!r}"
    if not all(torch.isfinite(t).all() for t in (m.rotations, m.root_translation, m.skeleton.offsets)):
        return "non-finite values in the clip"
    ours = [w for w in caught if issubclass(w.category, BVHWarning)]
    if len(ours) != int(v.warns):
        return f"{len(ours)} BVHWarning(s), expected {int(v.warns)}: {[str(w.message)[:80] for w in ours]}"
    for w in ours:
        text = str(w.message)
        if "\n" in text or len(text) >= MAX_MESSAGE or str(path) not in text or "ignored" not in text:
            return f"warning not one short line naming the file: {text[:120]!r}"
    if ref is None:
        return None
    want_fps = v.fps if v.fps is not None else ref.fps
    if m.fps != want_fps:
        return f"fps {m.fps}, expected {want_fps}"
    if v.same_names and m.skeleton.names != ref.skeleton.names:
        return "joint names differ from the clean parse"
    if m.skeleton.num_joints != ref.skeleton.num_joints or m.skeleton.parents != ref.skeleton.parents:
        return "hierarchy differs from the clean parse"
    if m.skeleton.channels != ref.skeleton.channels:
        return "channels differ from the clean parse"
    T = m.num_frames
    pairs = [(m.skeleton.offsets, ref.skeleton.offsets), (m.rotations, ref.rotations[:T]),
             (m.root_translation, ref.root_translation[:T])]
    if (m.translations is None) != (ref.translations is None):
        return "translations present in one parse only"
    if m.translations is not None:
        pairs.append((m.translations, ref.translations[:T]))
    for a, b in pairs:
        if a.shape != b.shape or not torch.allclose(a, b, rtol=1e-9, atol=1e-9):
            return "values differ from the clean parse"
    return None


def test_every_variant_reads_or_is_refused_in_one_clean_line(corpus_files, refs):
    failures = []
    for v, path in corpus_files:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                m = read_bvh(path, dtype=torch.float64)
            except TorchspliceError as exc:
                why = "valid file refused" if v.parses else _check_error(v, path, exc)
                problem = f"{why}: {str(exc)[:150]!r}" if why else None
                if not problem and any(issubclass(w.category, BVHWarning) for w in caught):
                    problem = "warned about a file it refused"
            except Exception as exc:  # noqa: BLE001 - any other escape is the bug this test is for
                problem = f"{type(exc).__name__} escaped: {str(exc)[:150]!r}"
            else:
                problem = (_check_clip(v, path, m, refs.get(v.ref) if v.ref else None, caught) if v.parses
                           else f"invalid file read ({m.num_frames} frames)")
        if problem:
            failures.append(f"{v.stem} [{v.what}]: {problem}")
    assert not failures, f"{len(failures)} of {len(corpus_files)} variants failed:\n" + "\n".join(failures)


def _cli_subset(corpus) -> list[Variant]:
    """Every valid variant and every third invalid one (a few hundred files, a few seconds)."""
    invalid = [v for v in corpus.variants if not v.parses]
    return [v for v in corpus.variants if v.parses] + invalid[::3]


@pytest.mark.slow
def test_cli_import_of_the_corpus_skips_bad_files_one_line_each(corpus, tmp_path, capsys):
    from torchsplice.cli import main
    from torchsplice.store.database import MotionDatabase

    subset = _cli_subset(corpus)
    assert len(subset) >= 300
    paths = corpus.write(tmp_path / "in", subset)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "corpus.h5"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", BVHWarning)  # printing these is the command line's business
        code = main(["import", str(tmp_path / "in"), "-o", str(out), "--spec", "auto", "-q"])
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "Traceback" not in cap.out
    assert code == 1
    lines = [l for l in cap.err.splitlines() if l.strip()]
    skipped_lines = {}
    for p in paths:
        prefix = f"skipped {p}:"  # "skipped FILE: why" or "skipped FILE:LINE: why"
        mine = [l for l in lines if l.startswith(prefix)]
        if mine:
            skipped_lines[p.stem] = mine
    with MotionDatabase.open(out) as db:
        names = set(db.names)
    failures = []
    for v, p in zip(subset, paths):
        skipped = skipped_lines.get(v.stem, [])
        imported = v.stem in names
        if len(skipped) > 1:
            failures.append(f"{v.stem}: {len(skipped)} skipped lines")
        if imported and skipped:
            failures.append(f"{v.stem}: both imported and skipped")
        if not imported and not skipped:
            failures.append(f"{v.stem}: neither imported nor skipped")
        if v.imports is True and not imported:
            failures.append(f"{v.stem}: not imported: {skipped[0][:200] if skipped else ''}")
        if v.imports is False and imported:
            failures.append(f"{v.stem}: imported, but must be skipped")
        if skipped and not skipped[0].removeprefix(f"skipped {p}:").lstrip("0123456789:").strip():
            failures.append(f"{v.stem}: skipped without a reason")
        if skipped and ("unexpected error" in skipped[0] or "please report" in skipped[0]):
            failures.append(f"{v.stem}: a bug, not a clean refusal: {skipped[0][:200]}")
    assert not failures, f"{len(failures)} of {len(subset)} files failed:\n" + "\n".join(failures)
    assert sorted(q.name for q in out_dir.iterdir()) == ["corpus.h5"]  # no .partial or other stray file
    assert sorted(q.name for q in (tmp_path / "in").iterdir()) == sorted(p.name for p in paths)  # inputs untouched
