"""Where the real motion capture lives, and helpers to find its clips (see ``tests/conftest.py``).

Real clips are read from ``../shared/mocap`` beside the checkout, or from the folder named by the
``TORCHSPLICE_MOCAP`` environment variable.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Iterable

import pytest

REPO = Path(__file__).resolve().parents[2]
MOCAP = Path(os.environ.get("TORCHSPLICE_MOCAP", REPO.parent / "shared" / "mocap"))
BANDAI = "bandai_namco_research_motiondataset"
"""The Bandai Namco folder of :data:`MOCAP` (``MOCAP / BANDAI / f"{name}.bvh"``)."""

BANDAI_FEW = [
    "dataset-2_walk-turn-left_normal_025",  # locomotion
    "dataset-2_walk-turn-right_normal_031",  # locomotion
    "dataset-2_walk_normal_008",  # locomotion
    "dataset-2_walk_active_032",  # both
    "dataset-2_walk-turn-left_elderly_003",  # both
    "dataset-2_wave-left-hand_normal_001",  # action, standing in place
]
"""The clips of the ``bandai_few_db`` fixture: three locomotions, two clips of both roles and a
wave performed standing in place."""

BANDAI_FOLDER = ["dataset-2_walk_normal_008", "dataset-2_walk-turn-left_elderly_003",
                 "dataset-2_wave-left-hand_normal_001", "dataset-1_walk-back_musical_001"]
"""The clips the ``bandai_folder`` fixture copies: a locomotion, a clip of both roles, an action
and a walk of the other session."""


def _require_mocap() -> Path:
    if MOCAP.is_dir() and any(MOCAP.rglob("*.bvh")):
        return MOCAP
    reason = f"real motion capture not found at {MOCAP} (set TORCHSPLICE_MOCAP to its folder)"
    if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
        pytest.fail(reason + "; CI must run the real-data tests", pytrace=False)
    pytest.skip(reason)


def copy_bandai(names: Iterable[str], folder: Path) -> Path:
    """``folder`` (made if missing) holding copies of the Bandai Namco clips ``names`` (stems):
    a folder a test may write into, never the shared one."""
    source = _require_mocap() / BANDAI
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        shutil.copy(source / f"{name}.bvh", folder)
    return folder


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
