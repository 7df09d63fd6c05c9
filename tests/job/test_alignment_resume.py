"""Resume after SIGKILL holds for an alignment store (issue 31) as it does for a motion store
(tests/job/test_job.py, tests/job/test_job_disk.py): a ``splice_all(..., store="alignment")``
killed with SIGKILL between two checkpoints, twice, then run again, ends bit-identical to an
uninterrupted run (every dataset and attribute, the source banks included; the run record but
its start time, command and engine), and splices again no task the output held."""

from __future__ import annotations

import json
import re

import pytest

from tests.job.test_job import REPO, assert_same_file, env, work_folder
from tests.store.test_alignment_store import READ
from torchsplice.job import splice_all
from torchsplice.store.database import MotionDatabase
from writers import killed_when, reaped, splice_all_process, summary_of

JOB = dict(store="alignment", methods="splice,naive,cpmc", batch_pairs=6, workers=1, index=False)  # 75 pairs, 15 tasks


def held(work) -> int:
    return (MotionDatabase.checkpoint_note(work / "output.h5") or {}).get("tasks", 0)


@pytest.mark.slow
def test_an_alignment_store_killed_twice_resumes_bit_identical(sample_db, tmp_path):
    reference = tmp_path / "reference.h5"
    splice_all(sample_db, reference, **JOB)
    out = tmp_path / "killed" / "out.h5"
    out.parent.mkdir()
    work = work_folder(out)
    every_task = dict(env(), TORCHSPLICE_CHECKPOINT_SECONDS="0")  # a checkpoint after each task, to kill between two
    merged = []
    for tasks in (1, 6):  # killed after the first task (the banks written), then midway
        with reaped(splice_all_process(sample_db, out, env=every_task, cwd=REPO, **JOB)) as proc:
            killed_when(proc, lambda: held(work) >= tasks)
        assert not out.exists()  # the output appears only once complete
        merged.append(held(work))
    tasks = json.loads((work / "plan.json").read_text())["tasks"]  # 5 tasks a method
    assert 1 <= merged[0] < merged[1] < len(tasks) == 15, merged
    kept = sum(t["stop"] - t["start"] for t in tasks[: merged[1]])  # pairs the output held (tasks merge in order)

    with reaped(splice_all_process(sample_db, out, env=env(), cwd=REPO, **JOB)) as again:
        stdout, stderr = again.communicate(timeout=300)
    assert again.returncode == 0, stderr
    summary = summary_of(stdout)
    m = re.search(r"75 spliced clips \((\d+) pairs from an earlier run\)", summary["lines"][0])
    assert m and summary["spliced"] == 75 and summary["resumed"] == int(m.group(1)), summary
    assert kept <= summary["resumed"] < 75  # what the output held was not spliced again
    assert not work.exists() and sorted(p.name for p in out.parent.iterdir()) == ["out.h5"]  # nothing left behind
    assert_same_file(out, reference)
    with MotionDatabase.open(out) as db, MotionDatabase.open(reference) as ref:
        assert db.store == "alignment" and len(db) == 75
        for x, y in zip(db.read_many(range(len(db))), ref.read_many(range(len(ref)))):  # every clip assembles
            assert all(getattr(x, k) is None or getattr(x, k).numpy().tobytes() == getattr(y, k).numpy().tobytes()
                       for k in READ), x.name
