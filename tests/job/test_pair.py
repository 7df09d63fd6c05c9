"""``splice_pair``: one pair of a database by name, as the ``splice`` command and the job
splice it (same result as :func:`~torchsplice.splice.splice` on the clips read; a poorly
aligned pair noted; a reference refused where the method takes none). Pairs across skeletons
are in ``test_cross_dataset.py``."""

from __future__ import annotations

import pickle

import pytest
import torch

from torchsplice.core.errors import TorchspliceError
from torchsplice.job import splice_pair
from torchsplice.splice import SpliceOptions, splice
from torchsplice.store.database import MotionDatabase


@pytest.mark.parametrize("method", ["splice", "naive"])
def test_a_pair_by_name_is_the_splice_of_its_clips(sample_db, method):
    """The identity case: on one skeleton, ``splice_pair`` is ``splice`` of the two clips read
    from the database, bit for bit, with the same notes."""
    with MotionDatabase.open(sample_db) as db:
        loco, act = db.read("walk_curve"), db.read("carry_box")
        spec = db.spec(db.clip_info("walk_curve")["skeleton"])
    options = SpliceOptions()
    want = splice(loco, act, spec, method=method, options=options)
    got = splice_pair(sample_db, "walk_curve", "carry_box", method=method, options=options)
    assert (got.locomotion, got.action, got.method) == ("walk_curve", "carry_box", method)
    assert torch.equal(got.motion.rotations, want.motion.rotations)
    assert torch.equal(got.motion.root_translation, want.motion.root_translation)
    assert got.notes == want.notes


def test_a_reference_for_a_method_without_one_is_refused_naming_the_option(sample_db):
    with pytest.raises(TorchspliceError) as info:
        splice_pair(sample_db, "walk_curve", "carry_box", method="naive", reference="walk_straight")
    exc = info.value
    assert exc.options == ("reference",) and str(exc) == ("reference is only used by methods that need a reference "
                                                          "clip (cpmc), not naive")
    assert pickle.loads(pickle.dumps(exc)).options == ("reference",)


def test_an_unknown_clip_is_one_line_naming_it(sample_db):
    with pytest.raises(TorchspliceError, match="carry_bx") as info:
        splice_pair(sample_db, "walk_curve", "carry_bx")
    assert "\n" not in str(info.value)
