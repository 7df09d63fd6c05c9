"""Units under attack: clips of one dataset in metres and in centimetres in one database (they
are two skeletons, whose pairs are not spliced), on every shipped dataset, and a metre BVH read
back as centimetres (a warning that the skeleton is not a human's size). Through the Python API
(:func:`import_bvh`, :func:`splice_all`, :func:`export_clips`)."""

from __future__ import annotations

import json

import pytest

from realdata import BANDAI
from torchsplice import export_clips, import_bvh, splice_all
from torchsplice.formats.bvh import read_bvh
from torchsplice.store.database import MotionDatabase
from torchsplice.ops.units import convert_units, implausible_size
from torchsplice.specs import detect_spec

SHIPPED = {  # one real file per shipped dataset spec with data in ../shared/mocap
    "bandai_namco": f"{BANDAI}/dataset-2_walk_normal_008.bvh",
    "cmu": "cmu_graphics_lab/cmu_12_01_walk.bvh",
    "lafan1": "lafan1_via_pypi_bvhtools/test2.bvh",
}


@pytest.mark.parametrize("dataset", list(SHIPPED))
def test_a_skeleton_in_other_units_is_another_skeleton_on_every_dataset(mocap_dir, dataset):
    path = mocap_dir / SHIPPED[dataset]
    clip = read_bvh(path)
    spec = detect_spec(clip.skeleton, path.name).resolve(clip.skeleton)
    assert implausible_size(clip.skeleton, spec.units) is None  # a human, in its spec's units
    for target in ("m", "mm"):
        other, _ = convert_units(clip, spec, target)
        assert not clip.skeleton.matches(other.skeleton) and not other.skeleton.matches(clip.skeleton)
        assert clip.skeleton.mismatch(other.skeleton).startswith("sizes differ"), target
        assert implausible_size(other.skeleton, spec.units) is not None  # read as the spec's units: not a human
    assert clip.skeleton.matches(read_bvh(path).skeleton)


def test_bandai_sessions_of_one_unit_still_share_their_skeletons(mocap_dir):
    """Every joint of Bandai Namco is animated: only the scale tells units apart, and the two
    sessions' skeletons (their Hips offsets differ a little) are not told apart by it."""
    a = read_bvh(mocap_dir / BANDAI / "dataset-2_walk_normal_008.bvh").skeleton
    b = read_bvh(mocap_dir / BANDAI / "dataset-2_wave-left-hand_normal_001.bvh").skeleton
    c = read_bvh(mocap_dir / BANDAI / "dataset-1_walk_normal_001.bvh").skeleton
    assert a.matches(b)
    assert a._same_scale(c)


def test_clips_appended_in_other_units_are_not_spliced_with_the_others(mocap_dir, tmp_path):
    files = [mocap_dir / BANDAI / f"dataset-2_{n}.bvh" for n in
             ("walk_normal_008", "walk-turn-left_normal_025", "walk_active_032", "walk-turn-left_elderly_003")]
    db = tmp_path / "mix.h5"
    assert not import_bvh(files[:2], db, units="m").skipped
    assert not import_bvh(files[2:], db, append=True).skipped
    with MotionDatabase.open(db) as d:
        assert len(d.skeletons) == 2
        units = {json.loads(d.spec_json(k))["dataset"]["units"] for k in range(len(d.skeletons))}
    assert units == {"m", "cm"}
    summary = splice_all(db, tmp_path / "out.h5", locomotions="*", actions="*", retarget=False)
    text = "\n".join(summary.lines())
    assert "units differ" in text, text
    with MotionDatabase.open(tmp_path / "out.h5") as out:
        assert len(out) == 4  # m onto m, cm onto cm: 2 + 2
    # retargeting (the default) brings each action onto the other units' skeleton: every pair is formed
    summary = splice_all(db, tmp_path / "all.h5", locomotions="*", actions="*")
    text = "\n".join(summary.lines())
    assert "units differ" not in text and "8 had the action retargeted" in text, text
    with MotionDatabase.open(tmp_path / "all.h5") as out:
        assert len(out) == 12
        for name in out.names:  # each result as tall as its locomotion's skeleton says (m or cm)
            m = out.read(name)
            size = float(m.global_positions()[0].max(0).values[1] - m.global_positions()[0].min(0).values[1])
            unit = out.skeleton_info(out.clip_info(name)["skeleton"]).units
            assert 1.2 < size * (100 if unit == "m" else 1) / 100 < 2.2, (name, size, unit)


def test_a_metre_file_read_back_as_centimetres_is_warned_about(mocap_dir, tmp_path):
    db = tmp_path / "m.h5"
    src = mocap_dir / BANDAI / "dataset-2_walk_normal_008.bvh"
    import_bvh([src], db, units="m")
    bvh = tmp_path / "bvh" / "dataset-2_walk_normal_008.bvh"
    bvh.parent.mkdir()
    export_clips(db, ["dataset-2_walk_normal_008"], out=bvh)
    report = import_bvh([bvh], tmp_path / "again.h5")
    assert not report.skipped and len(report.imported) == 1
    err = "\n".join(why for _, why in report.warnings)
    size = f"{read_bvh(src).skeleton.size() / 100:.3g} cm"  # the metre figure, read as centimetres
    assert "not a human's size" in err and f"measures {size} across" in err and err.count("not a human") == 1, err
