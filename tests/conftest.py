"""Shared fixtures: where the real motion capture lives, and helpers to find its clips.

Real clips are read from ``../shared/mocap`` beside the checkout, or from the folder named
by the ``TORCHSPLICE_MOCAP`` environment variable. Where it is absent, tests that need it are
skipped with the reason; under CI (``CI=true``) its absence is an error instead, so that CI
never passes by skipping.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
MOCAP = Path(os.environ.get("TORCHSPLICE_MOCAP", REPO.parent / "shared" / "mocap"))


def _require_mocap() -> Path:
    if MOCAP.is_dir() and any(MOCAP.rglob("*.bvh")):
        return MOCAP
    reason = f"real motion capture not found at {MOCAP} (set TORCHSPLICE_MOCAP to its folder)"
    if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
        pytest.fail(reason + "; CI must run the real-data tests", pytrace=False)
    pytest.skip(reason)


@pytest.fixture(scope="session")
def mocap_dir() -> Path:
    """The folder of real BVH files (one subfolder per source)."""
    return _require_mocap()


def real_bvh_files() -> list[Path]:
    """Every real BVH file, sorted; empty when the data is absent (tests then skip via mocap_dir)."""
    return sorted(MOCAP.rglob("*.bvh")) if MOCAP.is_dir() else []


#: real files per folder that the quick suite checks; the others are marked ``slow``
QUICK_FILES_PER_FOLDER = 2


def bvh_params():
    """pytest parameters over every real BVH file, with short ids; one skipping placeholder if none.

    The first :data:`QUICK_FILES_PER_FOLDER` files of each folder run in the quick suite; the
    rest are marked ``slow`` (``scripts/test.sh --all`` and CI run them too).
    """
    files = real_bvh_files()
    if not files:
        return [pytest.param(None, id="no-real-data")]
    seen: dict[Path, int] = {}
    params = []
    for f in files:
        seen[f.parent] = seen.get(f.parent, 0) + 1
        marks = [pytest.mark.slow] if seen[f.parent] > QUICK_FILES_PER_FOLDER else []
        params.append(pytest.param(f, id=f"{f.parent.name[:6]}/{f.stem}", marks=marks))
    return params


@pytest.fixture(scope="session")
def sample_db(tmp_path_factory):
    """The built-in sample as a database (``torchsplice sample``), made once per session; a test
    module may define its own."""
    from torchsplice.cli import main

    db = tmp_path_factory.mktemp("sample") / "sample.h5"
    assert main(["sample", "-o", str(db), "-q"]) == 0
    return db


@pytest.fixture(scope="session")
def runs_with_raised_hands(tmp_path_factory):
    """Bandai Namco runs, dashes and turning walks x raised hands, waves and calls, spliced as
    they come (``raw``, ``keep_hands_out=False``) and with the arms kept out of the body
    (``out``, the default), both motion stores: ``(database, raw, out)``."""
    from torchsplice.formats.importer import import_bvh
    from torchsplice.job.run import splice_all

    _require_mocap()
    folder = tmp_path_factory.mktemp("hands")
    db = folder / "bn.h5"
    import_bvh([MOCAP / "bandai_namco_research_motiondataset"], db, spec="bandai_namco")
    select = dict(locomotions=["*run*,*dash*,*turn*"], actions=["*wave*,*raise*,*bye*,*call*,*guide*"], workers=1)
    splice_all(db, folder / "raw.h5", keep_hands_out=False, **select)
    splice_all(db, folder / "out.h5", **select)
    return db, folder / "raw.h5", folder / "out.h5"


def pytest_collection_modifyitems(config, items):
    """Tests marked ``gpu`` skip, saying so, where torch sees no CUDA device."""
    gpu = [item for item in items if item.get_closest_marker("gpu")]
    if not gpu:
        return
    import torch

    if not torch.cuda.is_available():
        for item in gpu:
            item.add_marker(pytest.mark.skip(reason="gpu: no CUDA device on this machine"))
