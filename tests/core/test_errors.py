"""Structured errors: the library's errors carry a hint key and the options they name, never
command-line flags; the command line says them with its flags (``torchsplice.cli.cli_message``)."""

from __future__ import annotations

import ast
import pickle
import re
from pathlib import Path

import pytest
import torch

from torchsplice.cli import cli_message, main
from torchsplice.formats.sample_database import write_sample
from torchsplice.core.errors import (HINTS, DatabaseError, MotionError, NotLocomotingError, OutputExistsError,
                                     TorchspliceError, UnfinishedJobError)
from torchsplice.store.database import MotionDatabase
from torchsplice.job.config import JobConfig, parse_shard
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec
from torchsplice.splice import SpliceOptions, splice

PACKAGE = Path(__file__).resolve().parents[2] / "torchsplice"
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z-]+")


def test_no_library_error_message_names_a_flag():
    """Every string in a ``raise`` outside the command line (torchsplice/cli/) is free of ``--flags``
    (a Ray shell command aside)."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.relative_to(PACKAGE).parts[0] == "cli":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Raise) and node.exc is not None:
                for sub in ast.walk(node.exc):
                    if isinstance(sub, ast.Constant) and isinstance(sub.value, str):
                        text = sub.value.replace("`ray start --head`", "")
                        if FLAG.search(text):
                            found.append(f"{path.relative_to(PACKAGE)}:{sub.lineno}: {sub.value}")
    assert found == []


def test_output_exists_is_structured(tmp_path, capsys):
    out = tmp_path / "db.h5"
    write_sample(out)
    with pytest.raises(OutputExistsError) as e:
        MotionDatabase.create(out)
    exc = e.value
    assert isinstance(exc, DatabaseError) and exc.hint == "overwrite"
    assert str(exc) == f"{out}: already exists ({HINTS['overwrite']})" and "--" not in str(exc)
    assert cli_message(exc) == f"{out}: already exists (use --force to overwrite)"
    assert main(["sample", "-o", str(out)]) == 2
    assert capsys.readouterr().err == f"torchsplice: error: {out}: already exists (use --force to overwrite)\n"


def test_not_locomoting_is_structured():
    clips = {m.name: m for m in sample_motions()}
    walk, box = clips["walk_straight"], clips["carry_box"]
    still = walk.__class__(skeleton=walk.skeleton, rotations=walk.rotations[:1].expand_as(walk.rotations).clone(),
                           root_translation=walk.root_translation[:1].expand_as(walk.root_translation).clone(),
                           fps=walk.fps, name="still")
    with pytest.raises(NotLocomotingError) as e:
        splice(still, box, load_spec("sample"))
    exc = e.value
    assert isinstance(exc, MotionError) and exc.hint == "force_locomotion"
    assert str(exc).startswith("clip 'still' does not locomote") and "force=True" in str(exc) and "--" not in str(exc)
    assert cli_message(exc).endswith("(--force-locomotion splices it anyway)") and "force=True" not in cli_message(exc)
    # and the hint is right: forcing it splices it
    r = splice(still, box, load_spec("sample"), options=SpliceOptions(force=True))
    assert r.motion.num_frames > 0 and torch.isfinite(r.motion.rotations).all()


@pytest.mark.parametrize("kwargs, library, cli", [
    ({"max_length_ratio": 0.5}, "max_length_ratio must be at least 1, got 0.5", "--max-length-ratio must be at least 1, got 0.5"),
    ({"workers": 0}, "workers must be at least 1, got 0", "--workers must be at least 1, got 0"),
    ({"copy_sources": True, "layout": "virtual"}, "copy_sources needs layout copy", "--copy-sources needs --layout copy"),
])
def test_options_are_named_as_the_library_and_as_flags(tmp_path, kwargs, library, cli):
    with pytest.raises(TorchspliceError) as e:
        JobConfig(database=tmp_path / "in.h5", output=tmp_path / "out.h5", **kwargs).checked()
    assert str(e.value).startswith(library) and cli_message(e.value).startswith(cli)
    with pytest.raises(TorchspliceError) as e:
        parse_shard("3")
    assert str(e.value) == "shard must look like K/N (e.g. 2/8), got '3'"
    assert cli_message(e.value) == "--shard must look like K/N (e.g. 2/8), got '3'"


def test_errors_keep_their_structure_across_processes():
    for exc in (UnfinishedJobError("the job is in the way"), OutputExistsError("x.h5: already exists"),
                TorchspliceError("{workers} must be at least 1", options=("workers",))):
        back = pickle.loads(pickle.dumps(exc))
        assert type(back) is type(exc) and str(back) == str(exc) and cli_message(back) == cli_message(exc)
        assert back.hint == exc.hint and back.options == exc.options
    assert cli_message(UnfinishedJobError("the job is in the way")) == "the job is in the way (pass --restart to discard it)"
    assert cli_message(ValueError("plain")) == "plain"


def test_progress_in_a_log_is_a_line_every_so_often_and_one_at_the_end():
    """Not on a terminal, progress is lines (a bar would be hidden): every ``every`` seconds and
    at the end, with the count, the share, the rate and the time left; short work prints none."""
    import io

    from torchsplice.core.progress import LogProgress

    out = io.StringIO()
    bar = LogProgress(range(4), total=4, desc="export bvh", unit="file", file=out, every=0.0)
    assert list(bar) == [0, 1, 2, 3]
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("export bvh: 1/4 files (25%)") and "left" in lines[0]
    assert lines[-1].startswith("export bvh: 4/4 files (100%)") and "done in" in lines[-1] and len(lines) == 5
    quiet = io.StringIO()
    short = LogProgress(total=3, desc="import", file=quiet, every=3600.0)
    short.update(3)
    short.close()
    assert quiet.getvalue() == ""
