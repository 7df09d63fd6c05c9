"""Alignment pictures, the spec's ground-truth rule, and the evaluation report: through the Python
API (:func:`evaluate_database`, :func:`splice_all`, :func:`import_bvh`); the command line where
its words, its exit codes or a table only it writes (``info --csv``) are the subject."""

import shutil

import numpy as np
import pytest
import torch

from torchsplice import import_bvh, splice_all
from torchsplice.cli import main
from torchsplice.core.errors import SpecError, TorchspliceError
from torchsplice.evaluation.report import evaluate_database
from torchsplice.sample import sample_motions
from torchsplice.specs import DatasetSpec, load_spec
from torchsplice.viz.alignment import alignment_data, plot_alignment
from cli_helpers import error_line, run
from torchsplice.store.database import MotionDatabase

BANDAI = "bandai_namco_research_motiondataset"


@pytest.fixture(scope="module")
def sample():
    return {m.name: m for m in sample_motions()}


# -- the ground-truth rule --------------------------------------------------------------------
def test_ground_truth_labels_follow_the_rule():
    spec = load_spec("bandai_namco")
    loco = {"dataset": "2", "content": "walk-turn-left", "style": "normal", "take": "025"}
    act = {"dataset": "2", "content": "walk", "style": "elderly", "take": "006"}
    assert spec.ground_truth_labels(loco, act) == {"dataset": "2", "content": "walk-turn-left", "style": "elderly"}
    assert spec.ground_truth_labels({**loco, "style": "proud"}, act) is None  # locomotion must be normal style
    assert spec.ground_truth_labels(loco, {**act, "content": "wave-left-hand"}) is None  # action must be a walk
    assert spec.ground_truth_labels(loco, {"content": "walk"}) is None  # a label the template needs is missing
    assert spec.ground_truth_labels({**loco, "dataset": "1"}, act) is None  # sources from different datasets
    assert DatasetSpec.from_json(spec.to_json()).ground_truth == spec.ground_truth
    assert load_spec("sample").ground_truth_labels({}, {}) is None


def test_malformed_ground_truth_rule_is_a_spec_error(tmp_path):
    base = (load_spec("sample").path).read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(base.replace('name = "sample"', 'name = "bad"') + '\n[clips.ground_truth]\naction = { content = "walk" }\n')
    with pytest.raises(SpecError, match="ground_truth"):
        load_spec(bad)


# -- the alignment picture --------------------------------------------------------------------
def test_alignment_data_is_consistent(sample):
    loco, act = sample["walk_curve"], sample["carry_box"]
    d = alignment_data(loco, act, load_spec("sample"))
    assert d["grid"].shape == (loco.num_frames, act.num_frames)
    path = d["path"]
    assert tuple(path[0].tolist()) == (0, d["crop"])
    assert bool((path[1:] >= path[:-1]).all())
    curve = d["curve"]
    assert bool((curve[1:] > curve[:-1]).all()) and abs(float(curve[0]) - d["crop"]) < 1e-6
    # the path runs along low distances: its mean cost is the result's cost
    i, j = path[:, 0], path[:, 1]
    assert float(d["grid"][i, j].mean()) == pytest.approx(d["cost"], rel=1e-3)
    assert float(d["grid"][i, j].mean()) < 0.5 * float(d["grid"].mean())


def test_plot_alignment_writes_a_picture(sample, tmp_path):
    import matplotlib.image as mpimg
    import matplotlib.pyplot as plt

    out = plot_alignment(sample["walk_straight"], sample["wave"], load_spec("sample"), tmp_path / "a.png")
    img = mpimg.imread(out)
    assert img.shape[0] > 300 and img.shape[1] > 300 and float(np.std(img)) > 0.05
    assert plt.get_fignums() == []
    with pytest.raises(TorchspliceError, match="unsupported picture type"):
        plot_alignment(sample["walk_straight"], sample["wave"], load_spec("sample"), tmp_path / "a.bmpx")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png"]


def test_plot_alignment_command(sample_db, tmp_path, capsys):
    db = sample_db
    out = tmp_path / "a.png"
    assert main(["plot-alignment", str(db), "--locomotion", "walk_curve", "--action", "carry_box", "-o", str(out), "-q"]) == 0
    assert out.stat().st_size > 10_000
    assert main(["plot-alignment", str(db), "--locomotion", "walk_curve", "--action", "nope", "-o", str(out), "-f"]) == 2
    assert "nope" in capsys.readouterr().err


# -- the report -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sample_job(sample_db, tmp_path_factory):
    out = tmp_path_factory.mktemp("job") / "spliced.h5"
    assert splice_all(sample_db, out, methods="splice,naive").spliced == 50
    return out


def test_report_on_the_sample_ranks_splice_above_naive(sample_job, tmp_path):
    report = tmp_path / "report.md"
    agg = evaluate_database(sample_job, report, pictures=False)
    assert agg["splice"]["clips"] == agg["naive"]["clips"] == 25
    # the splice keeps the action's posture and the arm-leg coordination; naive copying does not
    assert agg["splice"]["posture"] < 0.5 * agg["naive"]["posture"]
    assert agg["splice"]["phase_in_range"] > agg["naive"]["phase_in_range"]
    assert agg["splice"]["phase"] < agg["naive"]["phase"]
    # the lower body comes from the locomotion either way: foot skate is about the same
    assert agg["splice"]["foot_speed_in_contact"] == pytest.approx(agg["naive"]["foot_speed_in_contact"], rel=0.2)
    text = report.read_text()
    assert "| splice | 25 |" in text and "| naive | 25 |" in text and "walk_curve+carry_box" in text


def test_figures_that_are_not_finite_print_as_a_dash(sample_job, tmp_path, capsys):
    """A result with huge values (a plug-in's translations of 1e30) leaves aggregates that are
    not finite: evaluate prints them as '-' and finishes, no traceback."""
    import h5py

    huge = tmp_path / "huge.h5"
    shutil.copy(sample_job, huge)
    with h5py.File(huge, "r+") as f:
        rt = f["skeletons/0/root_translation"]
        sign = np.where(np.arange(rt.shape[0]) % 2 == 0, 1.0, -1.0)[:, None]
        rt[...] = (sign * np.full(rt.shape, 3e38)).astype(rt.dtype)  # steps of 6e38: past float32's range
    rc = main(["evaluate", str(huge), "-o", str(tmp_path / "r.md"), "--no-pictures"])
    cap = capsys.readouterr()
    assert rc == 0 and "Traceback" not in cap.err, cap.err
    assert "foot speed in contact - " in cap.out and "splice: 25 clips" in cap.out and "naive: 25 clips" in cap.out


FIGURES = ("foot_skate", "foot_slide", "floor", "jerk", "jerk_action")
"""The job's per-result columns of the feet, the floor and the jerk (docs/job.md)."""


def _section(text: str, heading: str) -> str:
    """The report's section under ``heading``, up to the next section."""
    start = text.index(heading)
    end = text.find("\n## ", start + 1)
    return text[start:] if end < 0 else text[start:end]


def _rows(section: str) -> dict[str, list[str]]:
    """A section's table: its cells after the method's, per method."""
    return {ln.split("|")[1].strip(): [x.strip() for x in ln.split("|")[2:-1]]
            for ln in section.splitlines() if ln.startswith("| ") and not ln.startswith("| method")}


def test_report_shows_the_feet_floor_and_jerk_per_method_beside_the_actions_jerk(sample_job, tmp_path):
    """The job's foot_skate, foot_slide, floor and jerk (against jerk_action) as distributions per
    method, naive included, the numbers those of the output's own columns; the JSON's rows carry
    the job's columns under their names and the report's own measure as foot_speed_in_contact."""
    import json

    report, rows_json = tmp_path / "r.md", tmp_path / "r.json"
    agg = evaluate_database(sample_job, report, pictures=False, json=rows_json)
    with MotionDatabase.open(sample_job) as d:
        t = d.clip_table()
        method = np.asarray([str(m) for m in t.extra["method"]])
        col = {k: np.asarray(t.extra[k], dtype=np.float64) for k in FIGURES}
        names = list(t.names)
    section = _section(report.read_text(), "## Plausibility: feet, floor and jerk")
    rows = _rows(section)
    assert set(rows) == {"splice", "naive"}

    def q(v, p):
        return float(np.quantile(v, p, method="inverted_cdf"))

    for m in ("splice", "naive"):
        sel = method == m
        skate, slide, floor, jerk, act = (col[k][sel] for k in FIGURES)
        want = [str(int(sel.sum())), f"{q(skate, .5):.3f} / {q(skate, .95):.3f}", f"{q(slide, .5):.1f} / {q(slide, .95):.1f}",
                f"{q(floor, .05):.1f} / {q(floor, .5):.1f} / {q(floor, .95):.1f}", f"{q(jerk, .5):.0f} / {q(jerk, .95):.0f}",
                f"{q(act, .5):.0f} / {q(act, .95):.0f}", f"{q(jerk / act, .5):.2f} / {q(jerk / act, .95):.2f}"]
        assert rows[m] == want, (m, rows[m], want)
        assert agg[m]["jerk_median"] == q(jerk, .5) and agg[m]["foot_skate_p95"] == q(skate, .95)
        assert agg[m]["floor_p5"] == q(floor, .05)
    # naive copies the action's upper body frame by frame: its jerk in the chest's frame is the action's
    assert agg["naive"]["jerk_over_action_median"] == pytest.approx(1.0, abs=0.01)
    assert "The sources' foot figures are not in the output" in section
    doc = json.loads(rows_json.read_text())
    for c in doc["clips"]:
        i = names.index(c["name"])
        assert {k: c[k] for k in FIGURES} == pytest.approx({k: float(col[k][i]) for k in FIGURES})
        assert c["foot_speed_in_contact"] > 0 and "loco_skate" not in c
    # the two measures differ: GMD's share of steps against the evaluation's speed in cm/s
    assert doc["aggregates"]["splice"]["foot_speed_in_contact"] == pytest.approx(agg["splice"]["foot_speed_in_contact"])
    assert "foot_skate" not in doc["aggregates"]["splice"] and doc["aggregates"]["splice"]["foot_skate_median"] < 1


def test_feet_and_jerk_distributions_known_answer():
    """Per-clip rows whose figures are set: the medians and percentiles are the clips' values
    expected (NaN skipped, an action's jerk of 0 left out of the ratio), a figure no clip of a
    method has prints '-', and a figure no clip has gets no column."""
    from torchsplice.evaluation.plausibility import figure_stats, plausibility_section

    rng = np.random.default_rng(0)
    splice = [{"method": "splice", "name": f"s{k}", "jerk": float(j), "jerk_action": 10.0, "foot_skate": (j - 1) / 100}
              for k, j in enumerate(rng.permutation(np.arange(1, 21)))]  # jerk 1..20, foot skate 0.00..0.19
    splice.append({"method": "splice", "name": "nan", "jerk": float("nan"), "jerk_action": 0.0, "foot_skate": float("nan")})
    naive = [{"method": "naive", "name": f"n{k}", "jerk": j, "jerk_action": a, "foot_skate": 0.5, "floor": f}
             for k, (j, a, f) in enumerate([(5.0, 5.0, 2.0), (100.0, 10.0, -1.0), (7.0, 7.0, 4.0)])]
    st = figure_stats(splice)
    assert st == {"foot_skate_median": 0.09, "foot_skate_p95": 0.18, "jerk_median": 10.0, "jerk_p95": 19.0,
                  "jerk_action_median": 10.0, "jerk_action_p95": 10.0, "jerk_over_action_median": 1.0,
                  "jerk_over_action_p95": 1.9}
    assert figure_stats(naive)["jerk_p95"] == 100.0 and figure_stats(naive)["floor_p5"] == -1.0
    lines = plausibility_section(splice + naive, ["splice", "naive"], str)  # no penetration: no hands table
    assert "## Plausibility: a hand inside the body" not in lines and lines[0] == "## Plausibility: feet, floor and jerk"
    assert lines[2] == ("| method | clips | foot skate, GMD's ratio, median / 95th pct. | floor (cm), 5th pct. / median / "
                        "95th pct. | jerk (m/s^3), median / 95th pct. | the actions' jerk (m/s^3), median / 95th pct. | "
                        "jerk / the action's, median / 95th pct. |")
    assert lines[4] == "| splice | 21 | 0.090 / 0.180 | - / - / - | 10 / 19 | 10 / 10 | 1.00 / 1.90 |"
    assert lines[5] == "| naive | 3 | 0.500 / 0.500 | -1.0 / 2.0 / 4.0 | 7 / 100 | 7 / 10 | 1.00 / 10.00 |"
    assert "foot slide" not in lines[2]
    assert plausibility_section([{"method": "splice", "name": "a", "phase": 0.1}], ["splice"], str) == []


@pytest.mark.parametrize("dropped", [FIGURES, ("jerk_action",)], ids=["none", "no_jerk_action"])
def test_an_output_written_before_the_figures_evaluates_without_them(sample_job, tmp_path, dropped):
    """An output without the job's feet and jerk columns (as written before them) evaluates: no
    line of the figures it lacks, no key for them in the JSON, the hands' section as before."""
    import json

    old = tmp_path / "old.h5"
    shutil.copy(sample_job, old)
    import h5py

    with h5py.File(old, "r+") as f:
        extra = json.loads(f.attrs["extra_columns"])
        for c in dropped:
            del f["clips"][c], extra["clip"][c]
        f.attrs["extra_columns"] = json.dumps(extra)
    report, rows_json = tmp_path / "r.md", tmp_path / "r.json"
    agg = evaluate_database(old, report, pictures=False, json=rows_json)
    text = report.read_text()
    doc = json.loads(rows_json.read_text())
    assert "| naive | 25 |" in _section(text, "## Plausibility: a hand inside the body")
    assert all(not set(dropped) & set(c) for c in doc["clips"])
    assert all(c["foot_speed_in_contact"] > 0 for c in doc["clips"])
    if dropped == FIGURES:
        assert "## Plausibility: feet, floor and jerk" not in text and "GMD's ratio, median" not in text
        assert "(m/s^3)" not in text and "floor (cm)" not in text
        assert not any(k.startswith(FIGURES) for k in agg["naive"])
    else:  # the results' jerk stands alone
        section = _section(text, "## Plausibility: feet, floor and jerk")
        head = section.splitlines()[2]
        assert "| jerk (m/s^3), median / 95th pct. |" in head and "the actions' jerk" not in head and "/ the action's" not in head
        assert "jerk_over_action_median" not in agg["naive"] and agg["naive"]["jerk_median"] > 0
        assert len(_rows(section)["naive"]) == 5  # clips, foot skate, foot slide, floor, jerk


def test_report_needs_a_spliced_database(sample_db, tmp_path):
    with pytest.raises(TorchspliceError, match="not written by the splice job"):
        evaluate_database(sample_db, tmp_path / "r.md")
    assert not (tmp_path / "r.md").exists()


def test_report_with_ground_truth_on_real_clips(mocap_dir, tmp_path):
    names = ["dataset-2_walk-turn-left_normal_025", "dataset-2_walk-turn-right_normal_031",
             "dataset-2_walk_elderly_006", "dataset-2_walk_feminine_025",
             "dataset-2_walk-turn-left_elderly_003", "dataset-2_walk-turn-right_elderly_020",
             "dataset-2_walk-turn-left_feminine_025", "dataset-2_walk-turn-right_feminine_003"]
    src = tmp_path / "in"
    src.mkdir()
    for n in names:
        shutil.copy(mocap_dir / BANDAI / f"{n}.bvh", src)
    db, out, report = tmp_path / "b.h5", tmp_path / "o.h5", tmp_path / "r.md"
    assert len(import_bvh([src], db, spec="bandai_namco").imported) == len(names)
    splice_all(db, out, methods="splice,naive", locomotions="label:style=normal", actions="label:content=walk")
    agg = evaluate_database(out, report, pictures=False)
    assert agg["splice"]["gt_pairs"] == agg["naive"]["gt_pairs"] == 4  # 2 turns x 2 styles
    assert agg["splice"]["gt_error"] < agg["naive"]["gt_error"]
    assert "dataset-2_walk-turn-left_elderly_003" in report.read_text()
    for m in ("splice", "naive"):  # the breakdown per locomotion type: 2 styles per turn
        by = agg[m]["gt_by_type"]
        assert set(by) == {"all", "walk-turn-left", "walk-turn-right"}
        assert by["walk-turn-left"]["n"] == by["walk-turn-right"]["n"] == 2 and by["all"]["n"] == 4
        assert by["all"]["mean"] == pytest.approx(agg[m]["gt_error"])
        assert by["all"]["worst"] == max(by[k]["worst"] for k in ("walk-turn-left", "walk-turn-right"))
        assert agg[m]["gt_bound"] < agg[m]["gt_error"]  # the oracle posture beats the real one
        assert set(agg[m]["gt_bound_by_type"]) == set(by)
    text = report.read_text()
    assert "## Ground truth per locomotion type" in text and "| walk-turn-left | 2 |" in text and "| **all** | 4 |" in text


def test_best_constant_posture_bound_known_answers():
    from torchsplice.core.rotations import quat_to_rotmat, random_quat
    from torchsplice.evaluation.ground_truth import _best_posture_clouds, _mean_error

    g = torch.Generator().manual_seed(3)
    b = torch.randn(2, 9, 5, 3, generator=g, dtype=torch.float64) * 20      # (B, T, U, 3) capture
    R = quat_to_rotmat(random_quat((2,), dtype=torch.float64, generator=g))  # one rotation per pair
    pivot = 2
    a = torch.einsum("bij,btuj->btui", R, b - b[:, :, pivot:pivot + 1]) + b[:, :, pivot:pivot + 1]
    valid = torch.ones(2, 9, dtype=torch.float64)
    valid[1, 6:] = 0                                                         # pair 1: 6 aligned frames
    assert float(_mean_error(a, b, valid).min()) > 1.0                       # turned: far off
    assert float(_best_posture_clouds(a, b, valid, pivot).max()) < 1e-9      # the bound undoes the turn
    noisy = a.clone()
    noisy[1, 6:] += 1e3                                                      # frames past the alignment: ignored
    assert float(_best_posture_clouds(noisy, b, valid, pivot)[1]) < 1e-9
    moved = b + torch.tensor([0.0, 0.0, 5.0], dtype=torch.float64)           # a shift is no rotation
    assert float(_best_posture_clouds(moved, b, valid, pivot).min()) > 1.0


def test_error_stats_and_breakdown_by_type():
    from torchsplice.evaluation.report import error_stats, ground_truth_by_type

    assert error_stats([3.0, None, 1.0, 2.0]) == {"n": 3, "mean": 2.0, "median": 2.0, "worst": 3.0}
    assert error_stats([4.0, 1.0, 2.0, 10.0])["median"] == 3.0  # even count: the two middle values
    assert error_stats([None, float("nan")]) == {"n": 0, "mean": None, "median": None, "worst": None}
    rows = [{"method": "splice", "loco_type": t, "gt_error": e}
            for t, e in (("run", 1.0), ("run", 3.0), ("dash", 5.0), ("dash", None))]
    rows.append({"method": "naive", "loco_type": "run", "gt_error": 7.0})
    by = ground_truth_by_type(rows, ["splice", "naive", "cpmc"])
    assert set(by) == {"splice", "naive"}  # cpmc has no ground-truth row
    assert by["splice"]["run"] == {"n": 2, "mean": 2.0, "median": 2.0, "worst": 3.0}
    assert by["splice"]["dash"]["n"] == 1 and by["splice"]["all"]["mean"] == 3.0
    assert set(by["naive"]) == {"all", "run"}


def test_an_out_of_range_lag_never_prints_as_its_bound():
    from torchsplice.evaluation.report import _lag_text

    band = (-0.0469, 0.089)
    assert _lag_text(0.01, True, band) == "0.010"
    assert _lag_text(-0.0474, False, band) == "-0.0474 (out of range: below -0.0469)"
    assert _lag_text(0.2, False, band) == "0.200 (out of range: above 0.089)"
    assert _lag_text(float("nan"), False, band) == "-"


def test_8_evaluate_writes_every_row_for_scripts_and_says_where_its_tables_stop(sample_db, tmp_path, capsys):
    import csv
    import json

    spliced = tmp_path / "sp.h5"
    splice_all(sample_db, spliced)
    agg = evaluate_database(spliced, tmp_path / "r.md", pictures=False, max_rows=4, csv=tmp_path / "r.csv",
                            json=tmp_path / "r.json")
    assert set(agg) == {"splice"} and agg["splice"]["clips"] == 25
    rows = list(csv.DictReader(open(tmp_path / "r.csv")))
    doc = json.loads((tmp_path / "r.json").read_text())
    with MotionDatabase.open(spliced) as d:
        names = set(d.names)
    assert {r["name"] for r in rows} == {c["name"] for c in doc["clips"]} == names and len(rows) == len(names) == 25
    assert set(doc["aggregates"]) == {"splice"} and doc["aggregates"]["splice"]["clips"] == 25
    assert float(rows[0]["foot_speed_in_contact"]) == pytest.approx(doc["clips"][0]["foot_speed_in_contact"])
    assert "21 more (the table stops at 4 rows; every row: evaluate's csv or json)" in (tmp_path / "r.md").read_text()
    # the command's words: where it wrote its tables, and a table file of the wrong kind refused up front
    rc, out, _ = run(capsys, "evaluate", spliced, "-o", tmp_path / "t.md", "--no-pictures", "--csv", tmp_path / "t.csv",
                     "--json", tmp_path / "t.json")
    assert rc == 0 and out.splitlines()[-1] == f"wrote {tmp_path / 't.md'}, {tmp_path / 't.csv'}, {tmp_path / 't.json'}"
    rc, _, err = run(capsys, "evaluate", spliced, "-o", tmp_path / "s.md", "--csv", tmp_path / "r.txt")
    assert rc == 2 and "must end in .csv" in error_line(err) and not (tmp_path / "s.md").exists()


def test_per_clip_metrics_as_csv_for_any_database(sample_db, tmp_path, capsys):
    import csv

    spliced = tmp_path / "sp.h5"
    splice_all(sample_db, spliced, methods="splice,naive")
    from torchsplice.formats.index import write_rows_csv

    with MotionDatabase.open(spliced) as d:  # what `info DB method:naive --csv FILE` writes
        chosen = d.summary(clips=["method:naive"])
        assert chosen["num_clips"] == len(d) and d.summary(select=["method:naive"])["clips"] == chosen["clips"]
        from torchsplice.core.errors import DatabaseError

        with pytest.raises(DatabaseError, match="no clip named 'nosuch'"):
            d.summary(clips=["nosuch"])
        with pytest.raises(TorchspliceError, match="selects no clip"):
            d.summary(select=["method:cpmc"])
    write_rows_csv(tmp_path / "naive.csv", chosen["clips"])
    rows = list(csv.DictReader(open(tmp_path / "naive.csv")))
    assert len(rows) == 25 and all(r["method"] == "naive" for r in rows)
    rc, _, _ = run(capsys, "info", spliced, "method:naive", "--csv", tmp_path / "cli.csv", "--limit", "0")
    assert rc == 0 and (tmp_path / "cli.csv").read_text() == (tmp_path / "naive.csv").read_text()
    with MotionDatabase.open(spliced) as d:
        t = d.clip_table()
        cost = {t.names[r]: float(t.extra["cost"][r]) for r in range(len(t))}
    for r in rows:
        assert {"flags", "alignment_distance", "coverage", "labels"} <= set(r)
        want = cost[r["name"]]  # NaN where unset (the naive method aligns nothing): an empty cell
        assert (r["cost"] == "") if want != want else float(r["cost"]) == pytest.approx(want)
    rc, _, err = run(capsys, "info", spliced, "--csv", tmp_path / "x.txt")
    assert rc == 2 and "must end in .csv" in error_line(err)
