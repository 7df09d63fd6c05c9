"""Length units: converting clips between units (``torchsplice.ops.units``) and ``import --units``.

Known answers: a CMU clip (spec units ``cmu``, 1/0.45 inch) converted to centimetres has legs
2.54 / 0.45 times as long, forward-kinematics positions scaled by exactly that factor,
rotations untouched; round trips through inches return the original to 1e-9; and CMU plus
Bandai Namco imported with ``units="cm"`` (``import --units cm``) share one centimetre database.
The imports go through :func:`import_bvh`; the command line keeps its one-line refusal.
"""

from __future__ import annotations

import json

import pytest
import torch

from torchsplice import import_bvh
from torchsplice.core.errors import TorchspliceError
from torchsplice.formats.bvh import read_bvh
from torchsplice.formats.importer import NothingImportedError
from torchsplice.store.database import MotionDatabase
from torchsplice.specs import UNITS, detect_spec, load_spec
from torchsplice.ops.units import convert_units, scale_motion, unit_factor
from torchsplice.job.plan import leg_length
from cli_helpers import run

F64 = torch.float64


@pytest.fixture(scope="module")
def cmu_walk(mocap_dir):
    """The CMU walk in its own units, float64, with its spec."""
    f = mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh"
    m = read_bvh(f, dtype=F64)
    return m, detect_spec(m.skeleton, f.name)


def test_unit_factors_are_the_table_ratios():
    assert unit_factor("in", "cm") == pytest.approx(2.54, rel=1e-15)
    assert unit_factor("ft", "in") == pytest.approx(12.0, rel=1e-15)
    assert unit_factor("m", "mm") == pytest.approx(1000.0, rel=1e-15)
    assert unit_factor("cmu", "in") == pytest.approx(1 / 0.45, rel=1e-15)
    for a in ("m", "cm", "mm", "in", "ft", "cmu"):
        assert unit_factor(a, a) == 1.0
        for b in ("m", "cm", "mm", "in", "ft", "cmu"):
            assert unit_factor(a, b) * unit_factor(b, a) == pytest.approx(1.0, rel=1e-15)
            assert unit_factor(a, b) == pytest.approx(UNITS[a] / UNITS[b], rel=1e-15)


@pytest.mark.parametrize("a, b, why", [("unknown", "cm", "units are unknown"), ("cm", "furlong", "unknown length unit"),
                                       ("cm", "unknown", "unknown units")])
def test_unknown_units_are_refused_in_one_line(a, b, why):
    with pytest.raises(TorchspliceError, match=why) as exc:
        unit_factor(a, b, "mine.toml")
    assert str(exc.value).startswith("mine.toml: ") and "\n" not in str(exc.value)


def test_cmu_to_cm_scales_legs_positions_and_end_sites(cmu_walk):
    m, spec = cmu_walk
    assert spec.units == "cmu"
    cm, spec_cm = convert_units(m, spec, "cm")
    k = 2.54 / 0.45
    assert spec_cm.units == "cm" and spec_cm.name == spec.name and spec_cm.pelvis == spec.pelvis
    roles = spec.bind(m.skeleton)
    assert leg_length(cm.skeleton, spec_cm.bind(cm.skeleton)) == pytest.approx(k * leg_length(m.skeleton, roles), rel=1e-12)
    # the known height: hips about 16 CMU units high, about 90 cm
    hips_cm = float(cm.global_positions()[:, roles.root, 1].mean())
    assert 80 < hips_cm < 100
    torch.testing.assert_close(cm.global_positions(), m.global_positions() * k, rtol=1e-12, atol=1e-9)
    assert torch.equal(cm.rotations, m.rotations)
    torch.testing.assert_close(cm.skeleton.end_site_offsets, m.skeleton.end_site_offsets * k, rtol=1e-15, atol=0)
    assert cm.skeleton.end_site_parents == m.skeleton.end_site_parents and len(m.skeleton.end_site_parents) > 0
    assert cm.skeleton.size() == pytest.approx(k * m.skeleton.size(), rel=1e-12)


def test_round_trips_through_inches_return_the_original(cmu_walk):
    m, spec = cmu_walk
    inch, spec_in = convert_units(m, spec, "in")
    back, spec_back = convert_units(inch, spec_in, "cmu")
    assert spec_back.units == "cmu"
    for a, b in ((back.root_translation, m.root_translation), (back.skeleton.offsets, m.skeleton.offsets),
                 (back.skeleton.end_site_offsets, m.skeleton.end_site_offsets)):
        assert float((a - b).abs().max()) < 1e-9
    cm, spec_cm = convert_units(m, spec, "cm")
    again, _ = convert_units(*convert_units(cm, spec_cm, "in"), "cm")
    assert float((again.global_positions() - cm.global_positions()).abs().max()) < 1e-9


def test_animated_joint_translations_scale_too(mocap_dir):
    f = sorted((mocap_dir / "bandai_namco_research_motiondataset").glob("dataset-2_walk_*.bvh"))[0]
    m = read_bvh(f, dtype=F64)
    assert m.translations is not None
    metres = scale_motion(m, unit_factor("cm", "m"))
    torch.testing.assert_close(metres.translations, m.translations / 100, rtol=1e-15, atol=0)
    torch.testing.assert_close(metres.global_positions(), m.global_positions() / 100, rtol=1e-12, atol=1e-12)


def test_same_units_are_returned_unchanged(cmu_walk):
    m, spec = cmu_walk
    same, s = convert_units(m, spec, "cmu")
    assert same is m and s is spec
    with pytest.raises(TorchspliceError, match="units are unknown"):
        convert_units(m, load_spec("generic"), "cm")


def test_import_units_cm_puts_cmu_and_bandai_namco_in_one_centimetre_database(mocap_dir, tmp_path):
    cmu = mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh"
    bandai = sorted((mocap_dir / "bandai_namco_research_motiondataset").glob("dataset-2_walk_*.bvh"))[:2]
    out = tmp_path / "mixed.h5"
    report = import_bvh([cmu, *bandai], out, units="cm")
    assert not report.skipped and len(report.imported) == 3
    plain = tmp_path / "plain.h5"
    assert not import_bvh([cmu], plain).skipped

    def summary(path) -> dict:  # what ``info --json`` prints
        with MotionDatabase.open(path) as db:
            return db.summary()

    info = summary(out)
    assert info["units"] == "cm" and {k["units"] for k in info["skeletons"]} == {"cm"}
    assert {k["spec"] for k in info["skeletons"]} == {"cmu", "bandai_namco"}
    with MotionDatabase.open(out) as db, MotionDatabase.open(plain) as ref:
        k = db.clip_info("cmu_12_01_walk")["skeleton"]
        assert json.loads(db.spec_json(k))["dataset"]["units"] == "cm"
        a, b = db.read("cmu_12_01_walk", dtype=F64), ref.read("cmu_12_01_walk", dtype=F64)
        torch.testing.assert_close(a.global_positions(), b.global_positions() * (2.54 / 0.45), rtol=1e-6, atol=1e-4)
        # the Bandai Namco clips were already in centimetres: stored as read
        m = read_bvh(bandai[0])
        assert torch.equal(db.read(bandai[0].stem).root_translation, m.root_translation)
    # appending in another unit converts to it too; without units the file's units are mixed
    assert not import_bvh([cmu.parent / "131_01.bvh"], out, append=True, units="cm").skipped
    assert summary(out)["units"] == "cm"
    assert not import_bvh([cmu.parent / "131_02.bvh"], out, append=True).skipped
    assert summary(out)["units"] == "mixed"


def test_import_units_refuses_unknown_units_per_file(mocap_dir, tmp_path):
    f = mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh"
    with pytest.raises(NothingImportedError) as exc:
        import_bvh([f], tmp_path / "g.h5", spec="generic", units="cm")
    assert [why for _, why in exc.value.report.skipped if "units are unknown" in why], exc.value.report.skipped
    assert not (tmp_path / "g.h5").exists()
    with pytest.raises(TorchspliceError, match="unknown length unit 'furlong'") as exc:
        import_bvh([f], tmp_path / "g.h5", units="furlong")
    assert "\n" not in str(exc.value)
    assert not (tmp_path / "g.h5").exists()


def test_the_import_command_refuses_unknown_units_in_one_line(mocap_dir, tmp_path, capsys):
    f = mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh"
    rc, _, err = run(capsys, "import", f, "-o", tmp_path / "g.h5", "--spec", "generic", "--units", "cm", "-q")
    assert rc == 2 and "units are unknown" in err and "Traceback" not in err
    rc, _, err = run(capsys, "import", f, "-o", tmp_path / "g.h5", "--units", "furlong")
    assert rc == 2 and "unknown length unit 'furlong'" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "g.h5").exists()
