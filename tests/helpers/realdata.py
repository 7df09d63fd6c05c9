"""Where the real motion capture lives, and helpers to find its clips (see ``tests/conftest.py``).

Real clips are read from ``../shared/mocap`` beside the checkout, or from the folder named by the
``TORCHSPLICE_MOCAP`` environment variable.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
MOCAP = Path(os.environ.get("TORCHSPLICE_MOCAP", REPO.parent / "shared" / "mocap"))


def _require_mocap() -> Path:
    if MOCAP.is_dir() and any(MOCAP.rglob("*.bvh")):
        return MOCAP
    reason = f"real motion capture not found at {MOCAP} (set TORCHSPLICE_MOCAP to its folder)"
    if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
        pytest.fail(reason + "; CI must run the real-data tests", pytrace=False)
    pytest.skip(reason)


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
