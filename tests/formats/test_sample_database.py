"""The built-in sample as a database (:func:`torchsplice.write_sample`), what ``torchsplice sample``
writes."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from torchsplice import MotionDatabase, write_sample
from torchsplice.cli import main
from torchsplice.core.errors import OutputExistsError
from torchsplice.sample import SAMPLE_CLIPS


def test_every_sample_clip_is_written_with_its_role_and_read_back_as_returned(tmp_path):
    out = tmp_path / "sample.h5"
    motions = write_sample(out)
    assert [m.name for m in motions] == list(SAMPLE_CLIPS)
    with MotionDatabase.open(out) as db:
        assert db.names == [m.name for m in motions]
        roles = {db.clip_info(m.name)["role"] for m in motions}
        assert roles == {"locomotion", "action"}
        for m, back in zip(motions, db.read_many(range(len(db)))):
            assert np.array_equal(back.rotations.numpy(), m.rotations.numpy())


def test_an_existing_file_is_kept_unless_overwrite(tmp_path):
    out = tmp_path / "sample.h5"
    out.write_bytes(b"mine")
    with pytest.raises(OutputExistsError) as caught:
        write_sample(out)
    assert str(out) in str(caught.value) and "\n" not in str(caught.value)
    assert out.read_bytes() == b"mine"
    write_sample(out, overwrite=True)
    with MotionDatabase.open(out) as db:
        assert len(db) == len(SAMPLE_CLIPS)


def test_the_sample_command_writes_the_same_database(tmp_path):
    write_sample(tmp_path / "api.h5")
    assert main(["sample", "-o", str(tmp_path / "cli.h5"), "-q"]) == 0
    with h5py.File(tmp_path / "api.h5") as a, h5py.File(tmp_path / "cli.h5") as b:
        for name in ("clips/name", "clips/role"):
            assert list(a[name][()]) == list(b[name][()])
        for name in ("skeletons/0/rotations", "skeletons/0/root_translation", "skeletons/0/offsets"):
            assert np.array_equal(a[name][()], b[name][()])
