"""Every real BVH file of ../shared/mocap, one test each: the file is read twice (as the reader
gives it by default, and in float64) and checked once for everything its reading promises.

- the README's table: joints, frames, fps, channels, unit quaternions (``test_bvh``);
- a float64 round trip through ``write_bvh`` moves no joint (``test_bvh``);
- forward kinematics against the per-joint reference (``test_fk``);
- the dataset's spec binds its skeleton, the guess agrees with the hand-written spec, and
  detection picks the family (``test_spec``).

The checks live beside their subjects as ``check_*`` functions. The first
``QUICK_FILES_PER_FOLDER`` files of each folder run in the quick suite; the rest are marked
``slow`` (``scripts/test.sh --all`` and CI run them too).
"""

from __future__ import annotations

import pytest
import torch

from realdata import bvh_params
from tests.core.test_fk import check_every_real_clip_matches_per_joint_reference
from tests.formats.test_bvh import check_real_file_matches_readme, check_real_file_round_trip
from tests.specs.test_spec import (
    check_detect_spec_picks_the_family, check_guess_agrees_with_hand_written_spec, check_spec_binds_real_skeleton,
)
from torchsplice.formats.bvh import read_bvh


@pytest.mark.realdata
@pytest.mark.parametrize("path", bvh_params())
def test_real_file(path, mocap_dir, tmp_path):
    m = read_bvh(path)
    check_real_file_matches_readme(path, m)
    check_spec_binds_real_skeleton(path, m.skeleton)
    check_guess_agrees_with_hand_written_spec(path, m.skeleton)
    check_detect_spec_picks_the_family(path, m.skeleton)
    m64 = read_bvh(path, dtype=torch.float64)
    check_every_real_clip_matches_per_joint_reference(m64)
    check_real_file_round_trip(path, m64, tmp_path)
