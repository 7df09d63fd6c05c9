"""A job's disk is its output: the merge as tasks finish, resumes that merge nothing twice, the
size estimate and the refusal of a job that cannot fit, the dry run, and the closing summary.

Real Bandai Namco clips from ``../shared/mocap`` where a test needs standing actions and many
tasks; the built-in sample elsewhere.
"""

from __future__ import annotations

import json
import os
import re
import signal
import time
from pathlib import Path

import pytest

from torchsplice.core.errors import TorchspliceError
from torchsplice.store.database import MotionDatabase
from torchsplice.job import splice_all
from torchsplice.job.summary import REASONS_SHOWN, reason_lines
from torchsplice.job.size import TABLE_BYTES_PER_CLIP, frame_bytes
from writers import reaped, splice_all_process, summary_of

REPO = Path(__file__).resolve().parents[2]
JOB = {"locomotions": "label:style=normal", "actions": "role:action,role:both"}


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# ------------------------------------------------------------------------------ size and room
def test_dry_run_says_what_the_job_would_do_and_writes_nothing(sample_db, tmp_path):
    out = tmp_path / "out.h5"
    before = listing(tmp_path)
    summary = splice_all(sample_db, out, methods="splice,naive", dry_run=True)
    assert summary.dry_run and summary.pairs == 50
    first = summary.lines()[0]
    m = re.search(r"would write .*out\.h5: 50 spliced clips in (\d+) tasks; expected output about ([\d.]+) (MB|kB) "
                  r"\(([\d,]+) frames\); ([\d.,]+) (GB|MB|TB) free in ", first)
    assert m, first
    assert listing(tmp_path) == before  # no output, no work folder, no lock
    # a time-aligned result is at most as long as the shorter clip of its pair (the sample's fps are one)
    with MotionDatabase.open(sample_db) as db:
        t = db.table()
    n = {str(a): int(b) for a, b in zip(t["name"], t["length"])}
    want = 2 * sum(min(n[lo], n[ac]) for lo in ("walk_straight", "walk_curve", "turn_sharp", "sidestep", "jog")
                   for ac in ("carry_box", "carry_cup", "wave", "punch", "arms_out"))
    assert int(m.group(4).replace(",", "")) == want


def test_the_estimate_is_close_to_what_the_job_writes(sample_db, bandai_namco_db, tmp_path, capsys):
    for db, extra in ((sample_db, {"methods": "splice,naive"}),
                      (bandai_namco_db, JOB)):
        for compression in ("auto", "gzip"):
            out = tmp_path / f"{db.stem}_{compression}.h5"
            s = splice_all(db, out, compression=compression, workers=1, **extra)
            assert s.written == out.stat().st_size
            # errs on the large side: a few percent for auto (rotations raw), more for gzip, whose ratio varies most
            low = 0.85 if compression == "auto" else 0.6
            assert low * s.expected.bytes <= s.written <= 1.02 * s.expected.bytes, (db, compression, s.written, s.expected)
            line = next(ln for ln in s.lines() if "on disk" in ln)
            assert re.fullmatch(r"  [\d.]+ (kB|MB|GB) on disk \(expected [\d.]+ (kB|MB|GB)\)", line), line


def test_frame_bytes_follow_the_layout():
    # a 22-joint frame without joint translations, raw: rotations 352 + root 12 + action frame 4
    assert frame_bytes(22, False, None) == 368
    assert frame_bytes(22, True, None) == 368 + 264
    assert frame_bytes(22, True, "auto") < frame_bytes(22, True, None)
    assert 500 <= TABLE_BYTES_PER_CLIP <= 5000


def test_a_job_that_cannot_fit_is_refused_before_it_starts(sample_db, tmp_path, monkeypatch):
    import torchsplice.job.run as run_mod

    out = tmp_path / "out.h5"
    monkeypatch.setattr(run_mod, "_free_bytes", lambda folder: 50_000)
    with pytest.raises(TorchspliceError, match="the job needs about") as caught:
        splice_all(sample_db, out)
    line = str(caught.value)
    assert "\n" not in line and "50.0 kB free" in line and str(out) in line, line
    assert listing(tmp_path) == []  # refused before anything was written: no plan, no work folder
    monkeypatch.setattr(run_mod, "_free_bytes", lambda folder: 10**12)
    assert "(it does not fit)" not in "\n".join(splice_all(sample_db, out, dry_run=True).lines())
    monkeypatch.setattr(run_mod, "_free_bytes", lambda folder: 50_000)
    assert "(it does not fit)" in splice_all(sample_db, out, dry_run=True).lines()[0]


def test_many_clips_of_one_kind_are_summed_up_in_the_summary():
    skipped = {f"clip{k:02d} does not locomote (no alternating steps; {{force_locomotion}} splices it)": 10 + k
               for k in range(REASONS_SHOWN + 4)}
    skipped["a clip is not spliced onto itself"] = 3
    lines = reason_lines(skipped, lambda why: why.replace("{force_locomotion}", "--force-locomotion"))
    assert len(lines) == REASONS_SHOWN + 2
    assert lines[0].startswith(f"  {10 + REASONS_SHOWN + 3} x clip{REASONS_SHOWN + 3:02d} does not locomote")
    rest = sum(10 + k for k in range(4))  # the four least frequent
    assert f"  {rest} x 4 other clips that do not locomote" in lines
    assert "  3 x a clip is not spliced onto itself" in lines


# ------------------------------------------------------------------------------ the disk while it runs
def files_in(folder: Path):
    """``(relative path, stat)`` of every file under ``folder`` (files and folders that vanish
    during the walk skipped)."""
    for root, _, names in os.walk(folder):
        for name in names:
            p = Path(root) / name
            try:
                yield str(p.relative_to(folder)), p.stat()
            except OSError:
                pass


def footprint(folder: Path) -> tuple[int, dict]:
    """Bytes of the job's files (each file once, whatever it was renamed to during the count): its
    parts and shards, staged output, row log and checkpoints, and the output once renamed into
    place (the clips' banks, an input cache, are counted apart); and the bytes by file."""
    seen, parts = set(), {}
    for rel, st in files_in(folder):
        if "bank-" not in rel and st.st_ino not in seen:
            seen.add(st.st_ino)
            parts[rel] = st.st_size
    return sum(parts.values()), parts


def bank_bytes(folder: Path) -> int:
    return sum(st.st_size for rel, st in files_in(folder) if "bank-" in rel)


@pytest.mark.slow
def test_the_peak_disk_of_a_job_is_about_its_output(bandai_namco_db, tmp_path):
    out = tmp_path / "out.h5"
    with reaped(splice_all_process(bandai_namco_db, out, **JOB, workers=2, batch_pairs=4, cwd=REPO)) as proc:
        peak, banks, at_peak = 0, 0, {}
        while proc.poll() is None:
            size, files = footprint(tmp_path)
            if size > peak:
                peak, at_peak = size, files
            banks = max(banks, bank_bytes(tmp_path))
            time.sleep(0.002)
        _, err = proc.communicate()
    assert proc.returncode == 0, err
    final = out.stat().st_size
    assert peak <= 1.3 * final, (peak, final, len(at_peak), sorted(at_peak.items(), key=lambda kv: -kv[1])[:6])
    assert 0 < banks  # the workers mapped the driver's clips
    assert listing(tmp_path) == ["out.h5", "out.h5.index.csv"]


# ------------------------------------------------------------------------------ killed and resumed
def held(work: Path) -> int:
    return (MotionDatabase.checkpoint_note(work / "output.h5") or {}).get("tasks", 0)


@pytest.mark.slow
def test_a_job_killed_three_times_ends_bit_identical_and_merges_no_task_twice(bandai_namco_db, tmp_path):
    from tests.job.test_job import assert_same_file

    reference = tmp_path / "reference.h5"
    splice_all(bandai_namco_db, reference, **JOB, batch_pairs=4, workers=1)
    out = tmp_path / "killed" / "out.h5"
    out.parent.mkdir()
    work = out.with_name(f".{out.name}.parts")
    job = dict(JOB, batch_pairs=4, workers=2, cwd=REPO,
               env=dict(os.environ, TORCHSPLICE_CHECKPOINT_SECONDS="0"))  # a checkpoint after each task
    merged, kills = [], 0
    for share in (0.2, 0.45, 0.7):
        with reaped(splice_all_process(bandai_namco_db, out, **job)) as proc:
            total = None
            deadline = time.monotonic() + 300
            while proc.poll() is None and time.monotonic() < deadline:
                if total is None and (work / "plan.json").exists():
                    try:
                        total = len(json.loads((work / "plan.json").read_text())["tasks"])
                    except ValueError:
                        pass
                if total is not None and held(work) >= share * total:
                    proc.send_signal(signal.SIGKILL)
                    kills += 1
                    break
                time.sleep(0.005)
            proc.communicate()
        merged.append(held(work))
    assert kills == 3 and merged == sorted(merged) and merged[0] > 0
    with reaped(splice_all_process(bandai_namco_db, out, **job)) as done:
        stdout, stderr = done.communicate(timeout=600)
    assert done.returncode == 0, stderr
    summary = summary_of(stdout)
    m = re.search(r"spliced clips \((\d+) pairs from an earlier run\)", " ".join(summary["lines"]))
    assert m and int(m.group(1)) == summary["resumed"] >= 4 * merged[-1], stdout  # what the output held was not spliced again
    assert not work.exists() and sorted(p.name for p in out.parent.iterdir()) == ["out.h5", "out.h5.index.csv"]
    assert_same_file(out, reference)
