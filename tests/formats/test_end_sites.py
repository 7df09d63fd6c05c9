"""End Sites are part of a clip's identity: two files that differ only in their End Site offsets
keep their own End Sites through a database (issue 10)."""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from torchsplice.core.skeleton import Skeleton
from torchsplice.formats.bvh import read_bvh, write_bvh
from torchsplice.formats.exporters import export_clips
from torchsplice.formats.importer import import_bvh
from torchsplice.store.database import MotionDatabase

WALK = "cmu_12_01_walk.bvh"
_END_SITE = re.compile(r"(End Site\s*\{\s*OFFSET)([^\n}]*)")


def _cmu_walk(mocap_dir: Path) -> Path:
    hits = sorted(mocap_dir.rglob(WALK)) or sorted(p for p in mocap_dir.rglob("*.bvh") if "walk" in p.stem.lower()
                                                    and "End Site" in p.read_text(errors="replace")[:20000])
    if not hits:
        pytest.skip(f"no CMU walk with End Sites under {mocap_dir}")
    return hits[0]


def _zero_end_sites(text: str) -> str:
    out, n = _END_SITE.subn(r"\1 0.0 0.0 0.0", text)
    assert n > 0
    return out


def _ends(path: Path) -> tuple[tuple[int, ...], torch.Tensor]:
    sk = read_bvh(path, dtype=torch.float64).skeleton
    return sk.end_site_parents, sk.end_site_offsets


def test_end_sites_survive_a_shared_database(mocap_dir, tmp_path):
    from torchsplice.splice import SpliceOptions, splice

    src = _cmu_walk(mocap_dir)
    f1 = tmp_path / src.name
    f1.write_text(src.read_text())
    f2 = tmp_path / f"{src.stem}_flat_ends.bvh"
    f2.write_text(_zero_end_sites(src.read_text()))
    p1, e1 = _ends(f1)
    p2, e2 = _ends(f2)
    assert p1 == p2 and e1.abs().max() > 0.5 and e2.abs().max() == 0  # only the End Sites differ
    db = tmp_path / "db.h5"
    assert import_bvh([f1, f2], db).ok
    for f, ends in ((f1, e1), (f2, e2)):
        out = tmp_path / f"out_{f.stem}.bvh"
        assert export_clips(db, [f.stem], out=out).files == [out]
        parents, offsets = _ends(out)
        assert parents == p1
        torch.testing.assert_close(offsets, ends, rtol=0, atol=1e-4, msg=lambda m: f"{out.name}: End Sites moved: {m}")
    with MotionDatabase.open(db) as d:
        assert len(d.skeletons) == 2  # one skeleton per set of End Sites
        assert {d.clip_info(f1.stem)["skeleton"], d.clip_info(f2.stem)["skeleton"]} == {0, 1}
        # a splice of the two is still fine: the skeletons differ only in their End Sites
        loco, act, spec = d.read(f1.stem), d.read(f2.stem), d.spec(d.clip_info(f1.stem)["skeleton"])
    result = splice(loco, act, spec, method="naive", options=SpliceOptions(force=True))
    out = tmp_path / "spliced.bvh"
    write_bvh(result.motion, out)
    torch.testing.assert_close(_ends(out)[1], e1, rtol=0, atol=1e-4)  # the locomotion's skeleton


def _chain(ends) -> Skeleton:
    ch = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    return Skeleton(["A", "B", "C"], [-1, 0, 1], [[0, 0, 0], [0, 10, 0], [0, 10, 0]], [ch, ch[3:], ch[3:]],
                    end_site_parents=[2], end_site_offsets=ends)


def test_matches_and_mismatch_see_end_sites():
    a, b = _chain([[0, 5, 0]]), _chain([[0, 5, 0]])
    assert a.matches(b) and a.mismatch(b) is None
    assert a.matches(_chain([[0, 5 + 1e-6, 0]]))  # within the tolerance
    c = _chain([[0, 0, 0]])
    assert not a.matches(c) and a.same_topology(c)
    assert "End Site" in a.mismatch(c) and "'C'" in a.mismatch(c)
    d = Skeleton(a.names, a.parents, a.offsets, a.channels)  # no End Sites at all
    assert not a.matches(d) and "End Sites differ" in a.mismatch(d)
    with pytest.raises(ValueError, match="End Site"):
        Skeleton(a.names, a.parents, a.offsets, a.channels, [7], [[0, 1, 0]])


def test_a_database_with_merged_end_sites_still_reads(tmp_path):
    """A file written before the fix (two clips sharing one skeleton, End Sites of the first)
    reads as before, and appending a clip with those End Sites still shares the skeleton."""
    from torchsplice.core.motion import Motion

    a, b = _chain([[0, 5, 0]]), _chain([[0, 0, 0]])
    g = torch.Generator().manual_seed(0)

    def clip(sk, name):
        rot = torch.nn.functional.normalize(torch.randn(7, 3, 4, generator=g, dtype=torch.float64), dim=-1)
        return Motion(sk, rot, torch.randn(7, 3, generator=g, dtype=torch.float64), 30.0, name=name)

    m1, m2 = clip(a, "one"), clip(a, "two")
    p = tmp_path / "old.h5"
    with MotionDatabase.create(p, dtype=np.float64) as db:
        db.append(m1)
        db.append(m2)  # same skeleton object: one stored skeleton, as the old matching made of a and b
    with h5py.File(p, "r") as f:
        assert list(f["skeletons"]) == ["0"]
    with MotionDatabase.open(p) as db:
        assert len(db.skeletons) == 1
        for m in (m1, m2):
            r = db.read(m.name, dtype=torch.float64)
            assert torch.equal(r.rotations, m.rotations) and torch.equal(r.skeleton.end_site_offsets, a.end_site_offsets)
        assert [m.name for m in db.read_many(["two", "one"])] == ["two", "one"]
    with MotionDatabase.open(p, mode="a") as db:
        db.append(clip(_chain([[0, 5, 0]]), "three"))  # same End Sites: shares skeleton 0
        db.append(clip(b, "four"))  # other End Sites: a new skeleton
    with MotionDatabase.open(p) as db:
        assert len(db.skeletons) == 2
        assert [db.clip_info(n)["skeleton"] for n in ("one", "two", "three", "four")] == [0, 0, 0, 1]
        assert torch.equal(db.read("four").skeleton.end_site_offsets, b.end_site_offsets)
