"""Shared fixtures of the torchsplice.data tests: the sample clips, and three small databases built
from them (the plain sample, one shaped like the splice job's output, clips on two skeletons),
each made once per session (read only), from the records and clips of ``tests/helpers/dataset_clips.py``."""

from __future__ import annotations

import pytest
import torch

from dataset_clips import SPLICED_COLUMNS, animated_skeleton, chain_skeleton, random_clip, spliced_records
from torchsplice.core.motion import Motion
from torchsplice.sample import sample_motions
from torchsplice.store.database import MotionDatabase

F32 = dict(dtype=torch.float32, fps=24.0, role="locomotion")  # the random clips as these tests store them


@pytest.fixture(scope="session")
def motions() -> list[Motion]:
    return sample_motions()


@pytest.fixture(scope="session")
def plain_db(tmp_path_factory, motions):
    """The ten sample clips; small chunks so that windows straddle chunk boundaries."""
    path = tmp_path_factory.mktemp("plain") / "sample.h5"
    with MotionDatabase.create(path, chunk_frames=64) as db:
        for m in motions:
            db.append(m)
    return path


@pytest.fixture(scope="session")
def spliced_db(tmp_path_factory, motions):
    path = tmp_path_factory.mktemp("spliced") / "spliced.h5"
    with MotionDatabase.create(path, chunk_frames=128, columns=SPLICED_COLUMNS, frame_columns=("action_frame",)) as db:
        for m, extra, frames in spliced_records(motions):
            db.append(m, extra=extra, frame_extra=frames)
    return path


@pytest.fixture(scope="session")
def two_skeleton_db(tmp_path_factory):
    """Clips on two skeletons; skeleton 0 animates a non-root translation."""
    path = tmp_path_factory.mktemp("two") / "two.h5"
    with MotionDatabase.create(path, chunk_frames=16) as db:
        db.append(random_clip(animated_skeleton(), 50, "anim_a", 1, **F32))
        db.append(random_clip(chain_skeleton(), 30, "chain_a", 2, **F32))
        db.append(random_clip(animated_skeleton(), 1, "anim_one_frame", 3, **F32))
        db.append(random_clip(animated_skeleton(), 37, "anim_b", 4, **F32))
    return path
