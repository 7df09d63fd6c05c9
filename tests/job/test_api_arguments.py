"""The job's Python API (``torchsplice.job.splice_all``) given arguments of the wrong type or
range: one :class:`TorchspliceError` naming the option, raised before any work, never a
``TypeError`` from deep inside the job."""

from __future__ import annotations

import pytest

from torchsplice.cli import cli_message, main
from torchsplice.core.errors import TorchspliceError
from torchsplice.job import job_config, splice_all


BAD = [
    ({"workers": "2"}, "workers"), ({"workers": 1.5}, "workers"), ({"workers": True}, "workers"),
    ({"max_length_ratio": "3"}, "max_length_ratio"), ({"methods": None}, "methods"), ({"methods": 5}, "methods"),
    ({"methods": ["splice", 3]}, "methods"), ({"locomotions": 5}, "locomotions"), ({"actions": [None]}, "actions"),
    ({"memory_budget_mb": "big"}, "memory_budget_mb"), ({"memory_budget_mb": -5}, "memory_budget_mb"),
    ({"batch_pairs": 0}, "batch_pairs"), ({"max_run": -1}, "max_run"), ({"max_run": "3"}, "max_run"),
    ({"copy_sources": "yes"}, "copy_sources"), ({"force_locomotion": 1}, "force_locomotion"),
    ({"posture": "no"}, "posture"), ({"acting_limbs": 5}, "acting_limbs"), ({"ray_address": 6379}, "ray_address"),
    ({"device": 0}, "device"), ({"actions_db": 3}, "actions_db"),
]


@pytest.mark.parametrize("options, name", BAD, ids=[f"{n}={o[n]!r}" for o, n in BAD])
def test_bad_option_types_are_one_line_naming_the_option(sample_db, tmp_path, options, name):
    with pytest.raises(TorchspliceError) as e:
        splice_all(sample_db, tmp_path / "out.h5", **{"workers": 1, **options})
    assert name in str(e.value) and "\n" not in str(e.value)
    assert "--" + name.replace("_", "-") in cli_message(e.value) or name in ("methods",)  # flags on the command line
    assert not (tmp_path / "out.h5").exists() and not (tmp_path / ".out.h5.parts").exists()


@pytest.mark.parametrize("database, output", [(123, "o.h5"), ("sample.h5", None)])
def test_paths_of_the_wrong_type_are_one_line(tmp_path, monkeypatch, database, output):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(TorchspliceError, match="must be a path"):
        splice_all(database, output, workers=1)


@pytest.mark.parametrize("shard", [(5, 2), (0, 3), ("1", 2), (1, 2, 3), 7])
def test_bad_shards_are_refused(sample_db, tmp_path, shard):
    with pytest.raises(TorchspliceError, match="shard"):
        splice_all(sample_db, tmp_path / "out.h5", workers=1, shard=shard)
    assert not (tmp_path / ".out.h5.parts").exists()


def test_the_command_line_still_builds_its_configuration(sample_db, tmp_path):
    c = job_config(sample_db, tmp_path / "o.h5", methods="splice,naive", workers=2, max_length_ratio=3,
                   memory_budget_mb=512, batch_pairs=4, max_run=2, copy_sources=True)
    assert c.methods == ("splice", "naive") and c.max_length_ratio == 3 and c.workers == 2


def test_skip_reasons_name_options_as_the_caller_does(sample_db, tmp_path, capsys):
    summary = splice_all(sample_db, tmp_path / "api.h5", workers=1, locomotions="walk_curve,jog",
                         actions="carry_box", max_length_ratio=1.1)
    text = "\n".join(summary.lines())
    assert "more than max_length_ratio 1.1" in text and "--" not in text
    assert main(["splice-all", str(sample_db), "-o", str(tmp_path / "cli.h5"), "--workers", "1",
                 "--locomotions", "walk_curve,jog", "--actions", "carry_box", "--max-length-ratio", "1.1"]) == 0
    assert "more than --max-length-ratio 1.1" in capsys.readouterr().out


def test_viewer_notes_name_options_as_the_caller_does(sample_db, tmp_path, capsys):
    from torchsplice.viz.viewer import write_viewer

    write_viewer(sample_db, tmp_path / "a.html", max_clips=2)
    err = capsys.readouterr().err
    assert "(max_clips 2)" in err and "--" not in err
    assert main(["view", str(sample_db), "-o", str(tmp_path / "b.html"), "--max-clips", "2"]) == 0
    assert "(--max-clips 2)" in capsys.readouterr().err
