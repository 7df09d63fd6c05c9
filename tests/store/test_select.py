"""The clip selection language (:mod:`torchsplice.store.select`) on a hand-made clip table, then
on a real spliced database for the job, the dataset and the exports alike."""

from __future__ import annotations

import json

import numpy as np
import pytest

from realdata import BANDAI
from torchsplice.core.errors import TorchspliceError
from torchsplice.job import parse_selector, select_clips
from torchsplice.store import ClipTable
from torchsplice import import_bvh, splice_all
from torchsplice.data import MotionDataset
from torchsplice.store.database import MotionDatabase

ROWS = [  # name, role, labels
    ("walk_normal", "locomotion", {"content": "walk", "style": "normal", "dataset": "2"}),
    ("walk-turn-left_normal", "locomotion", {"content": "walk-turn-left", "style": "normal", "dataset": "2"}),
    ("walk-turn-right_proud", "both", {"content": "walk-turn-right", "style": "proud", "dataset": "1"}),
    ("run_Proud", "both", {"content": "run", "style": "proud", "dataset": "1"}),
    ("wave_normal", "action", {"content": "wave-left-hand", "style": "normal", "dataset": "2"}),
    ("carry_box", "action", {}),
    ("mystery", "", {}),
]


@pytest.fixture
def table():
    C = len(ROWS)
    return ClipTable.from_columns({  # as a database stores them: labels as JSON, "" for none
        "name": np.array([r[0] for r in ROWS]), "source": np.array([""] * C), "role": np.array([r[1] for r in ROWS]),
        "labels": np.array([json.dumps(r[2]) if r[2] else "" for r in ROWS]), "skeleton": np.zeros(C, np.int32),
        "start": np.arange(C, dtype=np.int64) * 10, "length": np.full(C, 10, np.int64), "fps": np.full(C, 30.0),
    }, {}, "db.h5")


def names(table, *selectors):
    return [table.names[i] for i in select_clips(table, list(selectors), "--locomotions", "db.h5")]


def test_name_globs_are_case_sensitive_and_whole_name(table):
    assert names(table, "walk*") == ["walk_normal", "walk-turn-left_normal", "walk-turn-right_proud"]
    assert names(table, "*_proud") == ["walk-turn-right_proud"]  # run_Proud differs in case
    assert names(table, "*_[Pp]roud") == ["walk-turn-right_proud", "run_Proud"]
    assert names(table, "carry_box") == ["carry_box"]
    assert names(table, "wave?normal") == ["wave_normal"]
    with pytest.raises(TorchspliceError):
        names(table, "walk")  # a glob matches the whole name, not a part of it


def test_a_name_holding_a_comma_or_colon_is_reached_exactly_and_bracketed(tmp_path):
    """An exact name matches before any splitting; inside a longer selector its , and : are
    bracketed (names_or_selector does so for the commands' clip arguments)."""
    from torchsplice.store.select import names_or_selector

    rows = ["x,y", "x", "y", "a:b", "role:odd", "walk_1"]
    C = len(rows)
    t = ClipTable.from_columns({
        "name": np.array(rows), "source": np.array([""] * C), "role": np.array(["action"] * C),
        "labels": np.array([""] * C), "skeleton": np.zeros(C, np.int32), "start": np.arange(C, dtype=np.int64) * 10,
        "length": np.full(C, 10, np.int64), "fps": np.full(C, 30.0)}, {}, "db.h5")
    assert names(t, "x,y") == ["x,y"] and names(t, "a:b") == ["a:b"] and names(t, "role:odd") == ["role:odd"]
    assert names(t, "x[,]y,walk_*") == ["x,y", "walk_1"] and names(t, "a[:]b,x") == ["x", "a:b"]
    assert names(t, "x,walk_*") == ["x", "walk_1"]  # not a name: alternatives, as before
    listed, selector = names_or_selector(t, ["x,y", "walk_*", "a:b"])
    assert listed is None and names(t, selector) == ["x,y", "a:b", "walk_1"]


def test_a_selector_written_with_an_equals_sign_gets_the_colon_form_as_a_hint(table):
    with pytest.raises(TorchspliceError, match=r"did you mean 'role:locomotion'\?"):
        names(table, "role=locomotion")
    with pytest.raises(TorchspliceError, match=r"did you mean 'label:style=normal'\?"):
        names(table, "style=normal")


def test_role_selects_exact_role(table):
    assert names(table, "role:locomotion") == ["walk_normal", "walk-turn-left_normal"]
    assert names(table, "role:both") == ["walk-turn-right_proud", "run_Proud"]
    assert names(table, "role:action") == ["wave_normal", "carry_box"]


def test_label_key_value_with_globs(table):
    assert names(table, "label:style=proud") == ["walk-turn-right_proud", "run_Proud"]
    assert names(table, "label:content=walk-turn-*") == ["walk-turn-left_normal", "walk-turn-right_proud"]
    assert names(table, "label:content=wave-*-hand") == ["wave_normal"]
    assert names(table, "label:dataset=[12]") == [r[0] for r in ROWS if r[2]]
    assert names(table, "label:content=*") == [r[0] for r in ROWS if r[2]]  # clips without the key never match
    # the value is everything after the first '='
    assert parse_selector("label:note=a=b") == [("label", "note", "a=b")]


def test_comma_alternatives_are_or(table):
    assert names(table, "role:locomotion,role:both") == [
        "walk_normal", "walk-turn-left_normal", "walk-turn-right_proud", "run_Proud"]
    # kinds mix, order of the result is the table's row order, duplicates collapse
    assert names(table, "carry_box, label:style=proud ,walk_normal,run_*") == [
        "walk_normal", "walk-turn-right_proud", "run_Proud", "carry_box"]
    # an alternative that matches nothing is fine while another one matches
    assert names(table, "nothing_like_this,role:action") == ["wave_normal", "carry_box"]
    assert parse_selector("a*, role:x ,label:k=v") == [("name", "", "a*"), ("role", "", "x"), ("label", "k", "v")]


def test_repeated_selectors_are_and(table):
    assert names(table, "label:style=normal", "label:content=walk-turn-*") == ["walk-turn-left_normal"]
    assert names(table, "role:locomotion,role:both", "label:dataset=1") == ["walk-turn-right_proud", "run_Proud"]
    assert names(table, "label:content=walk-turn-*", "role:both") == ["walk-turn-right_proud"]
    # the order of the selectors does not matter
    assert names(table, "label:dataset=1", "role:locomotion,role:both") == ["walk-turn-right_proud", "run_Proud"]


def test_selector_matching_nothing_names_it_and_the_database(table):
    with pytest.raises(TorchspliceError) as e:
        select_clips(table, ["role:locomotion", "label:style=angry"], "--actions", "/data/db.h5")
    msg = str(e.value)
    assert "'label:style=angry'" in msg and "--actions" in msg and "/data/db.h5" in msg
    assert "\n" not in msg
    with pytest.raises(TorchspliceError) as e:
        select_clips(table, ["ROLE:action"], "--locomotions", "db.h5")  # a name glob, matching no clip
    assert "'ROLE:action'" in str(e.value)


def test_selector_matching_nothing_says_what_the_database_has_of_its_kind(table):
    """A role selector lists the roles there are, a label selector that key's values (or the
    keys), a name glob the first clip names."""
    def message(selector):
        with pytest.raises(TorchspliceError) as e:
            select_clips(table, [selector], "--actions", "db.h5")
        return str(e.value)

    assert message("role:walker").endswith("(its roles: action, both, locomotion)")
    assert message("label:style=angry").endswith("(its style labels: normal, proud)")
    assert message("label:mood=x").endswith("(its label keys: content, dataset, style)")
    assert message("zz*").endswith("(its clips: walk_normal, walk-turn-left_normal, walk-turn-right_proud, "
                                   "run_Proud, wave_normal, carry_box, ...)")


def test_selectors_each_matching_but_not_together(table):
    with pytest.raises(TorchspliceError) as e:
        select_clips(table, ["role:action", "label:style=proud"], "--locomotions", "db.h5")
    msg = str(e.value)
    assert "'role:action'" in msg and "'label:style=proud'" in msg and "together" in msg and "db.h5" in msg


@pytest.mark.parametrize("bad", ["label:style", "label:=normal", "walk*,label:content"])
def test_malformed_label_selector_names_it(table, bad):
    with pytest.raises(TorchspliceError) as e:
        select_clips(table, [bad], "--locomotions", "db.h5")
    part = [p for p in bad.split(",") if p.startswith("label:")][0]
    assert repr(part) in str(e.value) and "label:KEY=VALUE" in str(e.value)


@pytest.mark.parametrize("bad", ["", "walk*,", ",walk*", "walk*,,run*", " , "])
def test_empty_alternative_is_an_error(table, bad):
    with pytest.raises(TorchspliceError) as e:
        select_clips(table, [bad], "--locomotions", "db.h5")
    assert repr(bad) in str(e.value) and "empty" in str(e.value)


# --------------------------------------------------------------------------------------------
# the same language on a real database's clip table, for the job, the dataset and the exports
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def spliced_db(sample_db, tmp_path_factory):
    """A spliced database of the sample with two methods (method, flags, timing columns)."""
    from torchsplice.job import splice_all

    out = tmp_path_factory.mktemp("select") / "spliced.h5"
    splice_all(sample_db, out, methods="splice,naive", workers=1, copy_sources=True, progress=False)
    return out


def _brute(table, keep):
    return [n for i, n in enumerate(table.names) if keep(i)]


def test_column_and_skeleton_selectors_on_a_spliced_database(spliced_db):
    from torchsplice.store import MotionDatabase

    with MotionDatabase.open(spliced_db) as db:
        t = db.clip_table()
    method, timing = t.extra["method"], t.extra["timing"]
    pick = lambda *s: [t.names[i] for i in select_clips(t, list(s), "select", "db")]  # noqa: E731
    assert pick("method:naive") == _brute(t, lambda i: method[i] == "naive") != []
    assert pick("method:s*", "role:spliced") == _brute(t, lambda i: method[i] == "splice")
    assert pick("timing:timewarp,timing:loop") == _brute(t, lambda i: timing[i] in ("timewarp", "loop")) != []
    assert pick("skeleton:0") == t.names  # the sample has one skeleton
    assert pick("role:locomotion,role:both", "skeleton:0") == _brute(t, lambda i: t.role[i] in ("locomotion", "both"))
    with pytest.raises(TorchspliceError) as e:
        pick("method:cpmc")
    assert str(e.value).endswith("(its method values: '', 'naive', 'splice')")
    with pytest.raises(TorchspliceError) as e:
        pick("skeleton:3")
    assert str(e.value).endswith("(its skeletons: 0)")
    with pytest.raises(TorchspliceError, match="must read skeleton:K"):
        pick("skeleton:x")
    with pytest.raises(TorchspliceError, match=r"unknown prefix 'mthod'.*method:VALUE"):
        pick("mthod:naive")


def test_number_columns_are_compared_with_numbers(spliced_db):
    """``COLUMN<VALUE`` and its kin on the number columns (``alignment_distance``, ``cost``,
    ``jerk``...): the brute-force comparison; NaN selects nothing; a name that is not a number
    column, or a value that is not a number, is one line naming the selector. (The plausibility
    columns on values that differ: the tests below.)"""
    from torchsplice.store import MotionDatabase

    with MotionDatabase.open(spliced_db) as db:
        t = db.clip_table()
    dist = np.asarray(t.extra["alignment_distance"], dtype=np.float64)
    pick = lambda *s: [t.names[i] for i in select_clips(t, list(s), "select", "db")]  # noqa: E731
    cut = float(np.median(dist[np.isfinite(dist)]))
    assert pick(f"alignment_distance<{cut!r}") == _brute(t, lambda i: dist[i] < cut) != []
    assert pick(f"alignment_distance >= {cut!r}") == _brute(t, lambda i: dist[i] >= cut) != []
    assert pick(f"alignment_distance<={cut!r},method:naive") == _brute(t, lambda i: dist[i] <= cut or
                                                                       t.extra["method"][i] == "naive")
    jerk = np.asarray(t.extra["jerk"], dtype=np.float64)  # the sample's penetration is 0 throughout: see below
    above = float(np.median(jerk[np.isfinite(jerk)]))
    assert pick(f"jerk>{above!r}") == _brute(t, lambda i: jerk[i] > above) != []
    with pytest.raises(TorchspliceError, match=r"selects no clip of db \(its alignment_distance values: .* to .*\)"):
        pick("alignment_distance>1e9")
    with pytest.raises(TorchspliceError, match=r"'alignment_distanse' is not a number column \(number columns: .*cost"):
        pick("alignment_distanse<1")
    with pytest.raises(TorchspliceError, match=r"'x1' is not a number"):
        pick("cost>x1")


def test_the_job_the_dataset_and_the_exports_select_the_same_clips(spliced_db, tmp_path):
    from torchsplice.data import MotionDataset
    from torchsplice.formats.exporters import export_clips
    from torchsplice.store import MotionDatabase

    selectors = ["role:spliced", "method:naive", "label:action.content=carry_*,label:action.content=wave"]
    with MotionDatabase.open(spliced_db) as db:
        t = db.clip_table()
    want = _brute(t, lambda i: t.role[i] == "spliced" and t.extra["method"][i] == "naive"
                  and t.labels[i].get("action.content") in ("carry_box", "carry_cup", "wave"))
    assert want and [t.names[i] for i in select_clips(t, selectors, "{actions}", "db")] == want
    assert MotionDataset(spliced_db, select=selectors).names == want
    result = export_clips(spliced_db, out=tmp_path / "bvh", format="bvh", select=selectors)
    assert result.names == want and len(result.files) == len(want)
    unselected = next(n for i, n in enumerate(t.names) if t.extra["method"][i] == "splice")
    one = export_clips(spliced_db, [unselected, want[0]], out=tmp_path / "one.bvh", format="bvh", select="method:naive")
    assert one.names == [want[0]] and (tmp_path / "one.bvh").is_file()  # the named clips that select picks
    with pytest.raises(TorchspliceError, match="none of the clips named is selected"):
        export_clips(spliced_db, [unselected], out=tmp_path / "none.bvh", format="bvh", select="method:naive")
    from torchsplice.data import DatasetError

    with pytest.raises(DatasetError, match="'method:cpmc' selects no clip"):
        MotionDataset(spliced_db, select="method:cpmc")


def test_6_flags_are_codes_that_selections_filter_with_the_figures_in_their_own_columns(mocap_dir, tmp_path):
    """A run's upper body onto a walking turn aligns poorly (0.16 leg lengths apart): its flag is
    the code, its figure a number in a column of its own."""
    folder = mocap_dir / BANDAI
    db = tmp_path / "b.h5"
    names = ["dataset-2_walk-turn-left_normal_025", "dataset-1_run_chimpira_001", "dataset-2_walk_elderly_006"]
    assert import_bvh([folder / f"{n}.bvh" for n in names], db).ok
    out = tmp_path / "sp.h5"
    splice_all(db, out, locomotions=names[0], actions=f"{names[1]},{names[2]}", force_locomotion=True)
    with MotionDatabase.open(out) as d:
        t = d.clip_table()
        rows = {t.names[r]: {c: t.extra[c][r] for c in ("flags", "flag_details", "alignment_distance")}
                for r in range(len(t))}
    for name, row in rows.items():
        codes = set(str(row["flags"]).split(",")) - {""}
        assert codes <= {"poor_alignment", "action_not_locomoting", "locomotion_not_locomoting"}, row
        assert ("poor_alignment" in codes) == (float(row["alignment_distance"]) > 0.10), (name, row)
        assert bool(codes) == bool(row["flag_details"]), row
    flagged = {n for n, r in rows.items() if r["flags"]}
    assert flagged and flagged != set(rows), rows
    clean = MotionDataset(out, where={"flags": ""}, features=("rotations",))
    assert set(clean.names) == set(rows) - flagged
    assert set(MotionDataset(out, select="flags:*poor_alignment*", features=("rotations",)).names) == \
        {n for n, r in rows.items() if "poor_alignment" in r["flags"]}


# --------------------------------------------------------------------------------------------
# the plausibility columns (penetration, foot_skate, jerk, the self_penetration flag) on values
# that differ from clip to clip, so that a wrong selection selects other rows
# --------------------------------------------------------------------------------------------
NAN = float("nan")
FIGURES = [  # name, penetration, foot_skate, jerk, flags
    ("a", 0.0, 0.10, 120.0, ""),
    ("b", 0.02, 0.25, 900.0, ""),
    ("c", 0.05, 0.40, 60.0, "self_penetration"),
    ("d", 0.12, 0.05, 1500.0, "poor_alignment,self_penetration"),
    ("e", NAN, NAN, NAN, ""),  # a copied source clip: no figures
    ("f", 0.0, 0.30, 300.0, "poor_alignment"),
]


@pytest.fixture
def figures():
    C = len(FIGURES)
    cols = {"penetration": "float", "foot_skate": "float", "jerk": "float", "flags": "str"}
    return ClipTable.from_columns({
        "name": np.array([r[0] for r in FIGURES]), "source": np.array([""] * C), "role": np.array(["spliced"] * C),
        "labels": np.array([""] * C), "skeleton": np.zeros(C, np.int32), "start": np.arange(C, dtype=np.int64) * 10,
        "length": np.full(C, 10, np.int64), "fps": np.full(C, 30.0),
        **{c: np.array([r[k] for r in FIGURES], dtype=np.float64 if kind == "float" else str)
           for k, (c, kind) in enumerate(cols.items(), start=1)},
    }, cols, "db.h5")


def test_plausibility_columns_select_the_rows_of_their_values(figures):
    """Each comparison selects the rows the values above say (worked out by hand; a value on the
    cut tells ``<`` from ``<=``), NaN none of them, and ``flags:`` globs the codes."""
    assert names(figures, "penetration<=0") == ["a", "f"]
    assert names(figures, "penetration<0.05") == ["a", "b", "f"]
    assert names(figures, "penetration>=0.05") == ["c", "d"]
    assert names(figures, "penetration>0.05") == ["d"]
    assert names(figures, "foot_skate>0.25") == ["c", "f"]
    assert names(figures, "foot_skate<=0.25") == ["a", "b", "d"]
    assert names(figures, "jerk<300") == ["a", "c"]
    assert names(figures, "jerk>=300") == ["b", "d", "f"]
    assert names(figures, "flags:*self_penetration*") == ["c", "d"]
    assert names(figures, "flags:") == ["a", "b", "e"]  # no flag
    assert names(figures, "flags:*self_penetration*", "penetration>0.05") == ["d"]  # repeated: and
    assert names(figures, "penetration<=0,flags:*self_penetration*") == ["a", "c", "d", "f"]  # alternatives: or
    with pytest.raises(TorchspliceError, match=r"'penetration<0' selects no clip of db.h5 \(its penetration values: "):
        names(figures, "penetration<0")


HANDS_LOCOMOTIONS = ["dataset-1_dash_chimpira_001", "dataset-1_dash_tired_001", "dataset-1_run_chimpira_001",
                     "dataset-1_run_giant_001"]
HANDS_ACTIONS = ["dataset-2_raise-up-both-hands_normal_001", "dataset-2_raise-up-right-hand_normal_001",
                 "dataset-1_byebye_normal_001", "dataset-2_wave-left-hand_normal_001", "dataset-1_guide_normal_001"]


@pytest.fixture(scope="module")
def hands_in(mocap_dir, tmp_path_factory):
    """Real runs and dashes x raised hands, waves, a bye-bye and a guide (20 pairs), spliced with
    the arms as they come (``keep_hands_out=False``) and the sources copied: some results have a
    hand inside the body (penetration from 0 to about 0.1, a few flagged ``self_penetration``),
    foot_skate and jerk differ from pair to pair, and the sources have no figures (NaN)."""
    folder = tmp_path_factory.mktemp("hands_in")
    db, out = folder / "bn.h5", folder / "out.h5"
    assert import_bvh([mocap_dir / BANDAI / f"{n}.bvh" for n in HANDS_LOCOMOTIONS + HANDS_ACTIONS], db).ok
    summary = splice_all(db, out, locomotions=",".join(HANDS_LOCOMOTIONS), actions=",".join(HANDS_ACTIONS),
                         keep_hands_out=False, copy_sources=True, workers=1, progress=False)
    assert summary.spliced == len(HANDS_LOCOMOTIONS) * len(HANDS_ACTIONS)
    return out


def test_plausibility_selectors_on_a_real_output_select_the_rows_their_figures_say(hands_in, tmp_path):
    """On a real output whose figures differ: every selector on ``penetration``, ``foot_skate``,
    ``jerk`` and the ``self_penetration`` flag selects the rows a brute-force pass over the
    figures keeps (neither none nor every result), through the selection language, the
    database's ``summary(select=)``, the dataset's ``where=`` and ``select=`` and the exports'
    ``select=``; the flagged rows are those whose penetration exceeds both sources' by more than
    :data:`~torchsplice.job.task.SELF_PENETRATION`."""
    from torchsplice.formats.exporters import export_clips
    from torchsplice.job.task import SELF_PENETRATION

    with MotionDatabase.open(hands_in) as db:
        t = db.clip_table()
        summary = lambda *s: [c["name"] for c in db.summary(select=list(s))["clips"]]  # noqa: E731
        e = t.extra
        pen, skate, jerk = (np.asarray(e[c], dtype=np.float64) for c in ("penetration", "foot_skate", "jerk"))
        of_loco, of_action = (np.asarray(e[c], dtype=np.float64)
                              for c in ("penetration_locomotion", "penetration_action"))
        codes = [set(str(f).split(",")) - {""} for f in e["flags"]]
        results = _brute(t, lambda i: t.role[i] == "spliced")
        pick = lambda *s: [t.names[i] for i in select_clips(t, list(s), "select", "db")]  # noqa: E731
        inside = _brute(t, lambda i: pen[i] > max(of_loco[i], of_action[i]) + SELF_PENETRATION)
        assert _brute(t, lambda i: "self_penetration" in codes[i]) == inside
        cut = {name: float(np.median(v[np.isfinite(v) & (v > 0)])) for name, v in
               (("penetration", pen), ("foot_skate", skate), ("jerk", jerk))}
        cases = {
            "penetration<=0": lambda i: pen[i] <= 0,
            "penetration>0": lambda i: pen[i] > 0,
            f"penetration>={cut['penetration']!r}": lambda i: pen[i] >= cut["penetration"],
            f"foot_skate<{cut['foot_skate']!r}": lambda i: skate[i] < cut["foot_skate"],
            f"foot_skate>={cut['foot_skate']!r}": lambda i: skate[i] >= cut["foot_skate"],
            f"jerk>{cut['jerk']!r}": lambda i: jerk[i] > cut["jerk"],
            f"jerk<={cut['jerk']!r}": lambda i: jerk[i] <= cut["jerk"],
            "flags:*self_penetration*": lambda i: "self_penetration" in codes[i],
        }
        for selector, keep in cases.items():
            want = _brute(t, keep)
            assert want and set(want) < set(results), (selector, want)  # some results, not all of them
            assert pick(selector) == want, selector
            assert summary(selector) == want, selector
        calm = f"jerk<={cut['jerk']!r}"
        both = _brute(t, lambda i: pen[i] > 0 and jerk[i] <= cut["jerk"])
        assert both and pick("penetration>0", calm) == summary("penetration>0", calm) == both
    # the dataset: where= (predicates on the columns) and select= keep the same rows
    dataset = lambda **kw: MotionDataset(hands_in, features=("rotations",), **kw).names  # noqa: E731
    assert dataset(where={"penetration": lambda v: v > 0}) == _brute(t, lambda i: pen[i] > 0)
    assert dataset(where={"jerk": lambda v: v <= cut["jerk"]}) == _brute(t, lambda i: jerk[i] <= cut["jerk"])
    assert dataset(where={"flags": lambda f: "self_penetration" in f.split(",")}) == inside
    assert dataset(select="flags:*self_penetration*") == inside
    assert dataset(where={"penetration": lambda v: v > 0}, select=calm) == both
    # the exports: the files (and the index) of the selected clips, no other
    result = export_clips(hands_in, out=tmp_path / "bvh", format="bvh", select="flags:*self_penetration*")
    assert result.names == inside and len(result.files) == len(inside)
    assert sorted(p.stem for p in (tmp_path / "bvh").glob("*.bvh")) == sorted(inside)
    result = export_clips(hands_in, out=tmp_path / "both", format="bvh", select=["penetration>0", calm])
    assert result.names == both
