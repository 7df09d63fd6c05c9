"""The README's Python snippets run as written, on real Bandai Namco clips.

The training snippet ("Reading the output for training") filters a spliced database by the
action's style label and reads the character's trajectory; the h5py snippet reads the layout
with plain h5py. Both are taken from README.md itself, so the README cannot drift from the code.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest
import torch

from torchsplice.cli import main

README = Path(__file__).resolve().parents[1] / "README.md"
BANDAI = ["dataset-1_walk_normal_001", "dataset-2_walk-turn-left_normal_025",
          "dataset-1_walk_old_001", "dataset-1_walk_proud_001", "dataset-1_walk_sad_001"]


def snippet(after_heading: str) -> str:
    """The first ```python block after the heading ``after_heading``."""
    text = README.read_text()
    start = text.index(after_heading)
    m = re.search(r"```python\n(.*?)```", text[start:], re.S)
    assert m, f"no python block after {after_heading!r}"
    return m.group(1)


@pytest.fixture(scope="module")
def spliced(mocap_dir, tmp_path_factory) -> Path:
    """``out/spliced.h5``: the Bandai Namco styled walks spliced onto two normal-style locomotions."""
    root = tmp_path_factory.mktemp("readme")
    folder = root / "bvh"
    folder.mkdir()
    for stem in BANDAI:
        shutil.copy(mocap_dir / "bandai_namco_research_motiondataset" / f"{stem}.bvh", folder)
    (root / "out").mkdir()
    assert main(["import", str(folder), "-o", str(root / "bandai.h5"), "-q"]) == 0
    assert main(["splice-all", str(root / "bandai.h5"), "-o", str(root / "out" / "spliced.h5"), "-q",
                 "--locomotions", "role:locomotion", "--actions", "role:both", "--workers", "1"]) == 0
    return root


def test_the_training_snippet_runs_and_selects_by_the_actions_style(spliced, monkeypatch):
    code = snippet("## Reading the output for training")
    assert '"labels.action.style"' in code and '"trajectory"' in code
    monkeypatch.chdir(spliced)
    scope: dict = {}
    exec(compile(code.replace("...", "pass"), "README.md", "exec"), scope)
    ds, batch = scope["ds"], scope["batch"]
    styles = {ds.table["labels"][i] for i in range(ds.num_clips)}
    assert ds.num_clips == 4  # old and proud, each onto two locomotions; sad is filtered out
    assert all('"action.style": "old"' in s or '"action.style": "proud"' in s for s in styles)
    assert all('"locomotion.style": "normal"' in s for s in styles)
    traj = batch["trajectory"]
    assert traj.shape[-1] == 3 and traj.shape[:2] == batch["rotations"].shape[:2]


def test_the_trajectory_is_the_characters_world_position_where_root_translation_stands_still(spliced):
    from torchsplice.data import MotionDataset
    from torchsplice.kinematics import forward_kinematics  # noqa: F401 (the public FK, as users call it)

    ds = MotionDataset(spliced / "out" / "spliced.h5", features=("root_translation", "trajectory", "positions"))
    item = ds[0]
    assert torch.count_nonzero(item["root_translation"]) == 0  # Bandai's joint_Root stays at the origin
    hips = ds.skeletons[0].names.index("Hips")
    assert torch.equal(item["trajectory"], item["positions"][:, hips])
    travel = (item["trajectory"][-1] - item["trajectory"][0])[[0, 2]].norm()
    assert travel > 100  # centimetres: the character walks, it does not walk in place


def test_the_h5py_snippet_runs_and_names_the_trajectory_joint(spliced, monkeypatch):
    code = snippet("### Reading a database without torchsplice")
    monkeypatch.chdir(spliced)
    shutil.copy(spliced / "bandai.h5", spliced / "clips.h5")
    code = code.replace('names.index("walk")', 'names.index("dataset-1_walk_old_001")')
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)
    assert scope["trajectory_joint"] == "Hips"
    assert scope["rotations"].shape[1:] == (22, 4) and scope["labels"]["style"] == "old"
    os.remove(spliced / "clips.h5")


def test_a_single_splice_keeps_its_sources_labels_too(spliced):
    from torchsplice.io.database import MotionDatabase
    from torchsplice.specs import DatasetSpec
    from torchsplice.splice import splice

    with MotionDatabase.open(spliced / "bandai.h5") as db:
        loco, act = db.read("dataset-1_walk_normal_001"), db.read("dataset-1_walk_old_001")
        spec = DatasetSpec.from_json(db.spec_json(db.clip_info(loco.name)["skeleton"]))
    for method in ("splice", "naive"):
        labels = splice(loco, act, spec, method=method).motion.labels
        assert labels["action.style"] == "old" and labels["locomotion.style"] == "normal"
        assert labels["method"] == method and labels["action"] == act.name
