"""``--store alignment`` with a splicer that gives no alignments to store (the torch splicer) is
refused by the job's configuration check, before any plan or work folder exists, in a dry run as
in a run; the command the refusal suggests then runs. A refusal that comes later (a plug-in
backend whose bank gives nothing) leaves no plan that would tie the next run to its arguments."""

from __future__ import annotations

import pytest

from cli_helpers import error_line, run
from torchsplice.core.errors import TorchspliceError
from torchsplice.job import splice_all
from torchsplice.job.config import job_config

PAIRS = dict(locomotions="walk_straight,jog", actions="wave,punch", methods="splice", index=False)


def _left(folder, keep) -> list[str]:
    """What the folder holds besides ``keep`` (the job's input)."""
    return sorted(p.name for p in folder.iterdir() if p.name not in keep)


def test_the_refusal_is_one_line_before_any_work_and_its_suggestion_runs(sample_db, tmp_path, capsys):
    out = tmp_path / "tb.h5"
    argv = ["splice-all", sample_db, "-o", out, "--backend", "torch", "-q", "--no-index",
            "--locomotions", "walk_straight,jog", "--actions", "wave,punch"]
    want = f"torchsplice: error: {out}: the torch splicer gives no alignments to store; write --store motion"
    for dry in ([], ["--dry-run"]):
        rc, stdout, err = run(capsys, *argv, "--store", "alignment", *dry)
        assert rc == 2 and error_line(err) == want and stdout == "", dry
        assert _left(tmp_path, ()) == [], dry  # no .tb.h5.parts, no output, no temporary
    # doing what it says works at once (no "unfinished job with other arguments")
    rc, _, err = run(capsys, *argv, "--store", "motion")
    assert rc == 0, err
    assert _left(tmp_path, ()) == ["tb.h5"]


def test_the_api_refuses_in_the_configuration_check(sample_db, tmp_path):
    out = tmp_path / "tb.h5"
    for call in (lambda: job_config(sample_db, out, backend="torch", store="alignment"),
                 lambda: splice_all(sample_db, out, backend="torch", store="alignment", **PAIRS),
                 lambda: splice_all(sample_db, out, backend="torch", store="alignment", dry_run=True, **PAIRS)):
        with pytest.raises(TorchspliceError) as caught:
            call()
        assert str(caught.value) == f"{out}: the torch splicer gives no alignments to store; write store motion"
        assert _left(tmp_path, ()) == []
    # the compiled splicer's alignments are stored; the torch splicer's motions are
    assert job_config(sample_db, out, backend="compiled", store="alignment").store == "alignment"
    assert job_config(sample_db, out, backend="torch", store="motion").store == "motion"


def test_a_later_refusal_leaves_no_plan_behind(sample_db, tmp_path, monkeypatch):
    """A backend that says it stores alignments (it implements ``assembly_bank``) and then gives
    none is refused when the output is opened, after the plan was saved: that plan goes again, so
    the next run, with other arguments, is not refused as an unfinished job."""
    from torchsplice.splice.backends.compiled import CompiledBackend

    out = tmp_path / "late.h5"
    monkeypatch.setattr(CompiledBackend, "assembly_bank", lambda self, prepared: None)
    with pytest.raises(TorchspliceError, match=r"the compiled splicer gives no alignments to store; write store motion$"):
        splice_all(sample_db, out, store="alignment", workers=1, **PAIRS)
    assert not (tmp_path / ".late.h5.parts" / "plan.json").exists() and not out.exists()
    monkeypatch.undo()
    summary = splice_all(sample_db, out, store="motion", workers=1, **PAIRS)
    assert summary.spliced == 4 and out.exists() and not (tmp_path / ".late.h5.parts").exists()
