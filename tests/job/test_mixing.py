"""Datasets mixed in one database: which clips splice together, and the job's account of the
pairs it does not form.

Pairs need one skeleton topology (the same joint names and parents, see
``torchsplice.job.plan``). On the shipped data: Bandai Namco's two capture sessions share one
(their bone lengths differ), the built-in sample shares LAFAN1's, and CMU's two releases (the
MotionBuilder and 3ds Max namings) share none with each other or with the rest.
"""

from __future__ import annotations

import re

import pytest

from realdata import BANDAI
from torchsplice import import_bvh, splice_all
from torchsplice.cli.common import flag
from torchsplice.formats.bvh import read_bvh
from torchsplice.store.database import MotionDatabase
from torchsplice.sample import sample_motions
from torchsplice.specs import load_spec

LOCOS = ["dataset-2_walk_normal_008", "dataset-1_walk_proud_001", "cmu_12_01_walk", "walk_curve", "test#001"]
ACTIONS = ["dataset-2_wave-left-hand_normal_001", "dataset-1_bye_normal_001", "131_02", "carry_box", "test2#002"]


@pytest.fixture(scope="module")
def mixed_db(mocap_dir, tmp_path_factory):
    """Bandai Namco, CMU (both namings), LAFAN1 (cut into 4 s windows) and the sample, in centimetres."""
    out = tmp_path_factory.mktemp("mixing") / "mixed.h5"
    bandai = [mocap_dir / BANDAI / f"{n}.bvh" for n in (*LOCOS[:2], *ACTIONS[:2])]
    assert import_bvh([*bandai, mocap_dir / "cmu_graphics_lab"], out, units="cm").ok
    assert import_bvh([mocap_dir / "lafan1_via_pypi_bvhtools"], out, append=True, units="cm", window=4).ok
    with MotionDatabase.open(out, mode="a") as db:
        spec = load_spec("sample")
        for m in sample_motions():
            db.append(m, spec=spec)
    return out


def topology_classes(mocap_dir) -> dict[str, str]:
    """Each shipped dataset (and the sample) -> the first dataset with its topology."""
    files = {"bandai_namco session 1": mocap_dir / BANDAI / "dataset-1_walk_proud_001.bvh",
             "bandai_namco session 2": mocap_dir / BANDAI / "dataset-2_walk_normal_008.bvh",
             "cmu": mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh",
             "cmu_max": mocap_dir / "cmu_graphics_lab" / "131_01.bvh",
             "lafan1": mocap_dir / "lafan1_via_pypi_bvhtools" / "test.bvh"}
    sk = {k: read_bvh(f).skeleton for k, f in files.items()}
    sk["sample"] = sample_motions()[0].skeleton
    return {k: next(o for o in sk if sk[o].same_topology(s)) for k, s in sk.items()}


def test_which_shipped_datasets_share_a_topology(mocap_dir):
    """The table in docs/mixing.md."""
    assert topology_classes(mocap_dir) == {
        "bandai_namco session 1": "bandai_namco session 1", "bandai_namco session 2": "bandai_namco session 1",
        "cmu": "cmu", "cmu_max": "cmu_max", "lafan1": "lafan1", "sample": "lafan1"}


def test_splice_all_on_a_mixed_database_counts_the_pairs_not_formed_by_skeleton(mixed_db, tmp_path):
    out = tmp_path / "out.h5"
    summary = splice_all(mixed_db, out, workers=1, retarget=False, locomotions=",".join(LOCOS), actions=",".join(ACTIONS))
    text = "\n".join(summary.lines())
    assert "(--retarget is off)" in "\n".join(summary.lines(flag))  # the command names its flag
    with MotionDatabase.open(mixed_db) as db:
        sk = db.skeletons
        kind = {n: db.clip_info(n)["skeleton"] for n in LOCOS + ACTIONS}
        specs = {k: db.summary()["skeletons"][k]["spec"] for k in range(len(sk))}
    # brute force: every locomotion x action pair whose skeletons differ in topology, by skeleton pair
    want: dict[tuple[int, int], int] = {}
    formed = 0
    for a in LOCOS:
        for b in ACTIONS:
            ka, kb = kind[a], kind[b]
            if sk[ka].same_topology(sk[kb]):
                formed += 1
            else:
                want[(ka, kb)] = want.get((ka, kb), 0) + 1
    assert formed == 8 and sum(want.values()) == 17
    got = {}
    pattern = re.compile(r"^  (\d+) x locomotions on skeleton (\d+) \((\w+), (\d+) joints\) x actions on skeleton (\d+) "
                         r"\((\w+), (\d+) joints\) \(retarget is off\)$")
    for line in text.splitlines():
        hit = pattern.match(line)
        if hit:
            n, ka, spec_a, ja, kb, spec_b, jb = hit.groups()
            ka, kb = int(ka), int(kb)
            assert (spec_a, spec_b) == (specs[ka], specs[kb])
            assert (int(ja), int(jb)) == (sk[ka].num_joints, sk[kb].num_joints)
            got[(ka, kb)] = int(n)
    assert got == want, text
    assert "not formed: 17 pairs whose clips are on skeletons of different joints" in text
    # the formed pairs were all spliced or skipped with a reason: none across datasets of other topologies
    with MotionDatabase.open(out) as res:
        t = res.table()
        pairs = {(str(lo), str(ac)) for lo, ac in zip(t["locomotion"], t["action"])}
    section = re.search(r"^skipped (\d+) pairs:$", text, re.M)
    skipped = int(section.group(1)) if section else 0
    assert len(pairs) + skipped == formed
    assert all(sk[kind[lo]].same_topology(sk[kind[ac]]) for lo, ac in pairs)
    # Bandai Namco's two sessions splice together, and so do the sample and LAFAN1
    assert any(kind[lo] != kind[ac] and specs[kind[lo]] == specs[kind[ac]] == "bandai_namco" for lo, ac in pairs)
    assert any({specs[kind[lo]], specs[kind[ac]]} == {"sample", "lafan1"} for lo, ac in pairs), pairs


def test_splice_all_on_a_mixed_database_retargets_the_pairs_across_skeletons(mixed_db, tmp_path):
    """By default every humanoid pair is formed: the 17 pairs across topologies with the action
    retargeted onto the locomotion's skeleton (once per action and skeleton), the others as they are."""
    out = tmp_path / "out.h5"
    summary = splice_all(mixed_db, out, workers=1, locomotions=",".join(LOCOS), actions=",".join(ACTIONS))
    text = "\n".join(summary.lines())
    assert summary.retargeted == 17
    assert "not formed" not in text and "17 had the action retargeted onto the locomotion's skeleton" in text, text
    with MotionDatabase.open(mixed_db) as db:
        sk = db.skeletons
        kind = {n: db.clip_info(n)["skeleton"] for n in LOCOS + ACTIONS}
    with MotionDatabase.open(out) as res:
        t = res.table()
        section = re.search(r"^skipped (\d+) pairs:$", text, re.M)
        assert len(t["locomotion"]) + (int(section.group(1)) if section else 0) == 25
        for i, (lo, ac) in enumerate(zip(t["locomotion"], t["action"])):
            m = res.read(i)
            lo, ac = str(lo), str(ac)
            assert m.skeleton.same_topology(sk[kind[lo]])  # on the locomotion's skeleton
            moved = "action.retargeted_from" in m.labels
            assert moved == (not sk[kind[lo]].same_topology(sk[kind[ac]])), (lo, ac, m.labels)
