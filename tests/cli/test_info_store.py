"""``torchsplice info`` says which kind of store a file is: its text's ``store:`` line and its
``--json`` key ``store`` (``motion`` or ``alignment``, as ``MotionDatabase.store`` reads it)."""

from __future__ import annotations

import json

import pytest

from cli_helpers import run
from torchsplice.job import splice_all
from torchsplice.store.database import MotionDatabase


@pytest.fixture(scope="module")
def stores(sample_db, tmp_path_factory):
    folder = tmp_path_factory.mktemp("info_store")
    out = {"motion": sample_db}
    for kind in ("motion", "alignment"):
        out[f"spliced {kind}"] = splice_all(sample_db, folder / f"{kind}.h5", store=kind, locomotions="walk_straight",
                                            actions="wave,punch", index=False, workers=1).output
    return out


@pytest.mark.parametrize("name, kind", [("motion", "motion"), ("spliced motion", "motion"),
                                        ("spliced alignment", "alignment")])
def test_info_says_the_kind_of_store(stores, capsys, name, kind):
    path = stores[name]
    with MotionDatabase.open(path) as db:
        assert db.store == kind
    rc, out, _ = run(capsys, "info", path, "--json")
    assert rc == 0 and json.loads(out)["store"] == kind
    rc, out, _ = run(capsys, "info", path, "--limit", "0")
    lines = [ln for ln in out.splitlines() if ln.startswith("store: ")]
    assert rc == 0 and len(lines) == 1 and lines[0].startswith(f"store: {kind} (")
    if kind == "alignment":
        assert "torchsplice materialize" in lines[0]
