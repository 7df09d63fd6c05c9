"""``import --append`` and ``--units`` under attack: a file whose clip is already in the
database, ``--units unknown``, and a database that mixes units on one skeleton topology
(``--append --units`` into a database of other units), whose pairs across units must not be
spliced."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from torchsplice.cli import main
from torchsplice.core.errors import TorchspliceError
from torchsplice.formats.bvh import write_bvh
from torchsplice.store.database import MotionDatabase
from torchsplice.formats.importer import import_bvh
from torchsplice.ops.units import convert_units
from torchsplice.job import splice_all
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec


@pytest.fixture(scope="module")
def bvh_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("bvh")
    for m in sample_motions()[:3]:
        write_bvh(m, d / f"{m.name}.bvh")
    return d


def test_append_skips_a_clip_already_in_the_database_and_imports_the_others(bvh_dir, tmp_path):
    db = tmp_path / "db.h5"
    first = sorted(bvh_dir.glob("*.bvh"))[0]
    import_bvh([first], db, spec="sample")
    report = import_bvh([bvh_dir], db, spec="sample", append=True)
    assert [why for _, why in report.skipped] == [f"clip name {first.stem!r} is already in the database"]
    assert len(report.imported) == 2 and report.clips == 3


def test_units_unknown_is_refused_as_a_unit_name(bvh_dir, tmp_path, capsys):
    rc = main(["import", str(bvh_dir), "-o", str(tmp_path / "u.h5"), "--units", "unknown"])
    err = capsys.readouterr().err
    assert rc == 2 and "--units" in err and "'unknown'" in err and "cannot be converted to 'unknown'" not in err, err
    with pytest.raises(TorchspliceError, match=r"^units: cannot convert to 'unknown' units; name a length unit"):
        import_bvh([bvh_dir], tmp_path / "u.h5", units="unknown")


def test_pairs_across_units_of_one_topology_are_not_spliced(tmp_path):
    spec = load_spec("sample")
    by = {m.name: m for m in sample_motions()}
    db = tmp_path / "mixed.h5"
    with MotionDatabase.create(db) as out:
        for n in ("walk_curve", "carry_box"):
            out.append(by[n], spec=spec)
            m, s = convert_units(by[n], spec, "m")
            out.append(replace(m, name=n + "_m"), spec=s)
    summary = splice_all(db, tmp_path / "out.h5", locomotions="walk_curve*", actions="carry_box*", workers=1,
                         retarget=False)
    assert summary.spliced == 2  # cm onto cm, m onto m
    differ = {w: n for w, n in summary.skipped.items() if "units differ" in w}
    assert sum(differ.values()) == 2, summary.skipped
    with MotionDatabase.open(tmp_path / "out.h5") as out:
        assert sorted(out.names) == ["walk_curve+carry_box", "walk_curve_m+carry_box_m"]
    # retargeted (the default): the action in centimetres brought onto the skeleton in metres splices as
    # the same action stored in metres does
    summary = splice_all(db, tmp_path / "all.h5", locomotions="walk_curve*", actions="carry_box*", workers=1)
    assert summary.spliced == 4 and summary.retargeted == 2 and not summary.skipped
    with MotionDatabase.open(tmp_path / "all.h5") as out:
        a = out.read("walk_curve_m+carry_box", dtype=torch.float64)
        b = out.read("walk_curve_m+carry_box_m", dtype=torch.float64)
        assert a.labels["action.retargeted_from"].endswith("(sample)") and "action.retargeted_from" not in b.labels
        assert a.num_frames == b.num_frames
        err = (a.global_positions() - b.global_positions()).norm(dim=-1)
        assert float(err.mean()) < 0.01, float(err.mean())  # metres: within a centimetre on average


def test_a_named_pipe_named_like_a_bvh_file_is_one_line_never_read(tmp_path, capsys):
    """A FIFO would block the import forever: given by name or found in a folder, it is
    skipped in one line and the other files land."""
    import os

    from torchsplice.cli import main as cli
    from torchsplice.formats.bvh import write_bvh
    from torchsplice.sample import sample_motions

    folder = tmp_path / "takes"
    folder.mkdir()
    write_bvh(sample_motions()[0], folder / "ok.bvh")
    os.mkfifo(folder / "pipe.bvh")
    assert cli(["import", str(folder), "-o", str(tmp_path / "a.h5"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "pipe.bvh: is a named pipe (FIFO), not a regular file" in err and "Traceback" not in err
    assert cli(["import", str(folder / "pipe.bvh"), "-o", str(tmp_path / "b.h5"), "-q"]) == 2
    assert "pipe.bvh: is a named pipe (FIFO), not a regular file" in capsys.readouterr().err
