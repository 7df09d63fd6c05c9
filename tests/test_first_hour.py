"""What a newcomer hit in the first hour (the issue "The first hour"), item by item; each test
failed before its fix.

- 5: a dataset of clips on several skeletons batches with ``ds.batch_sampler(B)`` (each batch one
  topology), and mixing them in one batch is one line naming two clips and the way out;
- 7: windows of one take (``import --split``) are not spliced onto each other;
- 9: a Markdown file given as BVH says it is not BVH; ``-o walk.fbx`` names the formats there
  are; a mistyped command or choice gets "did you mean"; a skeleton mismatch names a clip.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from cli_helpers import error_line, run
from torchsplice.cli import main
from torchsplice.data import DatasetError, MotionDataset, collate_motion
from torchsplice.store.database import MotionDatabase
from torchsplice.core.errors import TorchspliceError
from torchsplice.formats.exporters import export_clips

BANDAI = "bandai_namco_research_motiondataset"


@pytest.fixture(scope="module")
def mixed(mocap_dir, tmp_path_factory) -> Path:
    """Two Bandai Namco clips (22 joints) and the CMU walk (31 joints)."""
    out = tmp_path_factory.mktemp("first_hour") / "mixed.h5"
    files = [mocap_dir / BANDAI / "dataset-1_walk_normal_001.bvh", mocap_dir / BANDAI / "dataset-1_bye_normal_001.bvh",
             mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh"]
    assert main(["import", *map(str, files), "-o", str(out), "--units", "cm", "-q"]) == 0
    return out


def test_5_a_mixed_dataset_batches_one_skeleton_topology_at_a_time(mixed):
    from torch.utils.data import DataLoader

    ds = MotionDataset(mixed, window=30, stride=30, features=("rotations",))
    with pytest.raises(DatasetError) as info:
        collate_motion([ds[0], ds[len(ds) - 1]])
    text = str(info.value)
    assert "\n" not in text and "cmu_12_01_walk" in text and "batch_sampler" in text and "where={'skeleton'" in text
    sampler = ds.batch_sampler(4, shuffle=True, seed=3)
    seen = []
    for batch in DataLoader(ds, batch_sampler=sampler, collate_fn=collate_motion):
        joints = {ds.skeletons[k].num_joints for k in batch["skeleton"]}
        assert len(joints) == 1 and batch["rotations"].shape[2] == joints.pop()
        seen += list(zip(batch["index"], batch["start"]))
    assert len(seen) == len(ds) == len(set(seen))  # every item once an epoch
    first, again = [list(b) for b in sampler], [list(b) for b in sampler]
    assert first != again and len(first) == len(sampler)
    assert sorted(sum(first, [])) == sorted(sum(again, [])) == list(range(len(ds)))
    fixed = ds.batch_sampler(4, shuffle=True, seed=3)
    assert [list(b) for b in fixed] == [list(b) for b in ds.batch_sampler(4, shuffle=True, seed=3)]
    assert all(len(b) == 4 for b in ds.batch_sampler(4, drop_last=True))


def test_7_windows_of_one_take_are_not_spliced_onto_each_other(sample_db, tmp_path, capsys):
    bvh = tmp_path / "bvh"
    assert main(["export", str(sample_db), "walk_straight", "jog", "-o", str(bvh), "-q"]) == 0
    db = tmp_path / "win.h5"
    assert main(["import", str(bvh), "-o", str(db), "--window", "2", "--window-overlap", "0.5", "-q"]) == 0
    out = tmp_path / "sp.h5"
    rc, stdout, _ = run(capsys, "splice-all", db, "-o", out, "--locomotions", "walk_straight*", "--actions",
                        "walk_straight*,jog*")
    assert rc == 0 and "windows of one take are not spliced onto each other" in stdout
    with MotionDatabase.open(out) as d:
        table = d.clip_table()
        pairs = [(lab["locomotion.split_from"], lab["action.split_from"]) for lab in table.labels]
    assert pairs and all(a != b for a, b in pairs)
    assert {b for _, b in pairs} == {"jog"}  # every walk window onto every jog window, none onto a walk window


def test_9_a_file_that_is_not_bvh_says_so(tmp_path, capsys):
    md = tmp_path / "README.md"
    md.write_text("# My clips\n\nSome notes.\n")
    rc, _, err = run(capsys, "import", md, "-o", tmp_path / "x.h5")
    assert rc == 2 and "README.md:1: not a BVH file: it starts with '#'" in err and "MOTION section (truncated" not in err
    cut = tmp_path / "cut.bvh"
    cut.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n")
    rc, _, err = run(capsys, "import", cut, "-o", tmp_path / "y.h5")
    assert rc == 2 and "missing MOTION section (truncated file?)" in err


def test_9_an_output_suffix_no_format_writes_names_the_formats(sample_db, tmp_path, capsys):
    rc, _, err = run(capsys, "export", sample_db, "walk_straight", "-o", tmp_path / "walk.fbx")
    line = error_line(err)
    assert rc == 2 and "no export format writes .fbx files" in line and "bvh (.bvh)" in line and "--format" in line
    rc, _, err = run(capsys, "export", sample_db, "walk_straight", "-o", tmp_path / "walk.fbx", "--format", "bvh")
    assert rc == 2 and "the output is BVH, so its name must end in .bvh" in error_line(err)


def test_9_a_mistyped_command_or_choice_gets_did_you_mean(capsys):
    with pytest.raises(SystemExit):
        main(["splce-all", "a.h5", "-o", "b.h5"])
    assert "did you mean 'splice-all'?" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["export", "a.h5", "--all", "-o", "x", "--format", "hmanml3d"])
    assert "did you mean 'humanml3d'?" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["zzz"])
    assert "did you mean" not in capsys.readouterr().err


def test_a_mistyped_flag_gets_did_you_mean_and_its_commands_help(capsys):
    for argv, flag, command in ((["splice-all", "a.h5", "-o", "b.h5", "--wrokers", "2"], "--workers", "splice-all"),
                                (["info", "a.h5", "--jsno"], "--json", "info"),
                                (["export", "a.h5", "--all", "-o", "x", "--pakced"], "--packed", "export")):
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        err = capsys.readouterr().err
        assert exit_.value.code == 2 and len(err.strip().splitlines()) == 1, err
        assert f"did you mean '{flag}'?" in err and f"(see torchsplice {command} --help)" in err, err
    with pytest.raises(SystemExit):
        main(["info", "a.h5", "--zzzzzzzz"])
    err = capsys.readouterr().err
    assert "unrecognized arguments: --zzzzzzzz" in err and "did you mean" not in err


def test_9_a_skeleton_mismatch_names_a_clip_of_each_skeleton(mixed, tmp_path, capsys):
    rc, _, err = run(capsys, "export", mixed, "--all", "--packed", "-o", tmp_path / "all.npz")
    line = error_line(err)
    assert rc == 2 and "cmu_12_01_walk" in line and "dataset-1_walk_normal_001" in line, line
    ds = MotionDataset(mixed, features=("rotations",))
    with pytest.raises(DatasetError) as info:
        ds.statistics(("rotations",))
    assert "cmu_12_01_walk" in str(info.value) and "dataset-1_walk_normal_001" in str(info.value), str(info.value)


def test_8_evaluate_writes_every_row_for_scripts_and_says_where_its_tables_stop(sample_db, tmp_path, capsys):
    import csv
    import json

    spliced = tmp_path / "sp.h5"
    assert main(["splice-all", str(sample_db), "-o", str(spliced), "-q"]) == 0
    rc, out, _ = run(capsys, "evaluate", spliced, "-o", tmp_path / "r.md", "--no-pictures", "--max-rows", "4",
                     "--csv", tmp_path / "r.csv", "--json", tmp_path / "r.json")
    assert rc == 0 and "r.csv" in out and "r.json" in out
    rows = list(csv.DictReader(open(tmp_path / "r.csv")))
    doc = json.loads((tmp_path / "r.json").read_text())
    with MotionDatabase.open(spliced) as d:
        names = set(d.names)
    assert {r["name"] for r in rows} == {c["name"] for c in doc["clips"]} == names and len(rows) == len(names) == 25
    assert set(doc["aggregates"]) == {"splice"} and doc["aggregates"]["splice"]["clips"] == 25
    assert float(rows[0]["foot_skate"]) == pytest.approx(doc["clips"][0]["foot_skate"])
    assert "21 more (the table stops at 4 rows; every row: evaluate's csv or json)" in (tmp_path / "r.md").read_text()
    rc, _, err = run(capsys, "evaluate", spliced, "-o", tmp_path / "s.md", "--csv", tmp_path / "r.txt")
    assert rc == 2 and "must end in .csv" in error_line(err) and not (tmp_path / "s.md").exists()


def test_3_export_and_info_take_the_selection_language(sample_db, tmp_path, capsys):
    import json

    spliced = tmp_path / "sp.h5"
    assert main(["splice-all", str(sample_db), "-o", str(spliced), "-q", "--method", "splice,naive"]) == 0
    rc, out, _ = run(capsys, "export", spliced, "role:spliced", "-o", tmp_path / "all")
    assert rc == 0 and len(list((tmp_path / "all").glob("*.bvh"))) == 50
    rc, out, _ = run(capsys, "export", spliced, "--all", "--select", "method:naive", "--select", "action:wave",
                     "-o", tmp_path / "naive_waves")
    names = sorted(f.stem for f in (tmp_path / "naive_waves").glob("*.bvh"))
    assert rc == 0 and len(names) == 5 and all(n.endswith("+wave.naive") for n in names), names
    rc, out, err = run(capsys, "export", spliced, "--select", "method:naive", "--select", "action:wave",
                       "-o", tmp_path / "select_alone")  # --select alone, as retarget and mirror take it
    assert rc == 0 and sorted(f.stem for f in (tmp_path / "select_alone").glob("*.bvh")) == names, err
    rc, _, _ = run(capsys, "export", spliced, "walk_curve+wave", "jog+*", "-o", tmp_path / "mix", "--format", "npz")
    assert rc == 0 and len(list((tmp_path / "mix").glob("*.npz"))) == 1 + 10  # one named, jog's ten by a glob
    rc, _, err = run(capsys, "export", spliced, "nothing*", "-o", tmp_path / "none")
    assert rc == 2 and "'nothing*' selects no clip" in error_line(err) and not (tmp_path / "none").exists()
    rc, out, _ = run(capsys, "info", spliced, "label:action.content=punch", "--json", "--select", "method:splice")
    assert rc == 0 and [c["name"] for c in json.loads(out)["clips"]] == [
        "walk_straight+punch", "walk_curve+punch", "turn_sharp+punch", "sidestep+punch", "jog+punch"]
    rc, out, _ = run(capsys, "info", spliced, "--limit", "3")
    lines = out.splitlines()
    assert rc == 0 and lines[-1] == "... 47 more clips (--limit; select some with CLIP or --select)"
    assert sum(1 for ln in lines if "+" in ln.split()[0]) == 3


def test_11_long_titles_fit_their_panels_on_two_lines():
    from torchsplice.viz.render import fit_title

    assert fit_title("walk_curve+carry_box", 2.2) == ("walk_curve+carry_box", 10)
    text, size = fit_title("dataset-2_walk-turn-left_normal_025+dataset-2_wave-right-hand_normal_001", 2.2)
    room = int(2.2 * 72 / (0.6 * size))
    lines = text.split("\n")
    assert size < 10 and len(lines) == 2 and all(len(ln) <= room for ln in lines)
    assert lines[0].startswith("dataset-2_walk") and lines[0].endswith("_025+") and lines[1].endswith("normal_001")
    text, _ = fit_title("x" * 500, 1.0)
    assert all(len(ln) <= int(72 / (0.6 * 8)) for ln in text.split("\n"))


def test_10_the_docs_say_what_info_shows_of_bandai_namcos_skeletons(mocap_dir, tmp_path, capsys):
    """The figures of docs/mixing.md (clips per skeleton and dataset, the Head End Sites' distance)
    are what importing the Bandai Namco clips of ../shared/mocap gives and ``info`` prints."""
    import re

    from conftest import REPO

    said = re.search(r"shows skeleton 0 \((\d+) clips of dataset 1\) and\s+skeleton 1 \((\d+) of dataset 1 and (\d+) "
                     r"of dataset 2\): the same (\d+) joints, their Head End Site (\d+) cm\s+apart",
                     (REPO / "docs" / "mixing.md").read_text())
    assert said, "docs/mixing.md no longer says what info shows of Bandai Namco's skeletons"
    db = tmp_path / "bandai.h5"
    assert main(["import", str(mocap_dir / BANDAI), "-o", str(db), "-q"]) == 0
    rc, text, _ = run(capsys, "info", db, "--limit", "0")
    assert rc == 0
    with MotionDatabase.open(db) as d:
        table = d.clip_table()
        count = {}
        for k, labels in zip(table.skeleton, table.labels):
            count[(int(k), labels["dataset"])] = count.get((int(k), labels["dataset"]), 0) + 1
        heads = [sk.end_site_offsets[sk.end_site_parents.index(sk.names.index("Head"))] for sk in d.skeletons]
        joints = {sk.num_joints for sk in d.skeletons}
    zero, one_1, one_2, n_joints, apart = map(int, said.groups())
    assert count == {(0, "1"): zero, (1, "1"): one_1, (1, "2"): one_2} and joints == {n_joints}
    assert round(float((heads[0] - heads[1]).norm())) == apart
    assert f"skeleton 0: {n_joints} joints" in text and f"{zero} clips" in text and f"{one_1 + one_2} clips" in text


def test_12_the_package_imports_from_the_clones_parent_folder(tmp_path):
    """Run from the folder holding a clone named torchsplice, Python sees that folder as an empty
    namespace package unless the environment puts the repository itself on sys.path (the setup's
    compat editable install); then the real package wins."""
    import subprocess
    import sys

    repo = Path(__file__).resolve().parents[1]
    (tmp_path / "torchsplice").mkdir()  # a clone's folder: no __init__.py at its top
    (tmp_path / "torchsplice" / "README.md").write_text("a clone")
    env = {"PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", "from torchsplice import __version__; import torchsplice; "
                          "print(__version__, torchsplice.__file__)"], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[1] == str(repo / "torchsplice" / "__init__.py")


def test_training_splits_by_source_clip_in_the_dataset_match_the_export(sample_db, tmp_path):
    import csv

    from torchsplice.formats.exporters import export_clips

    spliced = tmp_path / "sp.h5"
    assert main(["splice-all", str(sample_db), "-o", str(spliced), "-q"]) == 0
    ratios = (0.4, 0.3, 0.3)
    parts = {s: MotionDataset(spliced, split=s, split_ratios=ratios, split_seed=5, features=("labels",))
             for s in ("train", "val", "test")}
    sources = {s: {(lab["locomotion"], lab["action"]) for lab in (ds[i]["labels"] for i in range(len(ds)))}
               for s, ds in parts.items()}
    locos = {s: {a for a, _ in v} for s, v in sources.items()}
    acts = {s: {b for _, b in v} for s, v in sources.items()}
    for a in ("train", "val", "test"):
        for b in ("train", "val", "test"):
            if a != b:
                assert not locos[a] & locos[b] and not acts[a] & acts[b], (a, b)
    out = tmp_path / "h"
    export_clips(spliced, out=out, format="humanml3d", split_ratios=ratios, split_seed=5)
    exported = {r["clip"]: r["split"] for r in csv.DictReader(open(out / "index.csv"))}
    for s, ds in parts.items():
        assert all(exported[n] == s for n in ds.names), s
    loco = sorted(locos["train"])[0]
    some = MotionDataset(spliced, split="train", split_ratios=ratios, split_seed=5, select=f"locomotion:{loco}")
    assert set(some.names) == {n for n in parts["train"].names if n.startswith(loco + "+")} != set()
    with pytest.raises(DatasetError, match="split must be one of train, val, test"):
        MotionDataset(spliced, split="dev")


def test_6_flags_are_codes_that_selections_filter_with_the_figures_in_their_own_columns(mocap_dir, tmp_path):
    """A run's upper body onto a walking turn aligns poorly (0.16 leg lengths apart): its flag is
    the code, its figure a number in a column of its own."""
    folder = mocap_dir / BANDAI
    db = tmp_path / "b.h5"
    names = ["dataset-2_walk-turn-left_normal_025", "dataset-1_run_chimpira_001", "dataset-2_walk_elderly_006"]
    assert main(["import", *[str(folder / f"{n}.bvh") for n in names], "-o", str(db), "-q"]) == 0
    out = tmp_path / "sp.h5"
    assert main(["splice-all", str(db), "-o", str(out), "-q", "--locomotions", names[0], "--actions",
                 f"{names[1]},{names[2]}", "--force-locomotion"]) == 0
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


def test_3_render_view_and_evaluate_take_the_selection_language_too(sample_db, tmp_path, capsys):
    spliced = tmp_path / "sp.h5"
    assert main(["splice-all", str(sample_db), "-o", str(spliced), "-q"]) == 0
    rc, out, _ = run(capsys, "render", spliced, "walk_curve+*", "jog+wave", "-o", tmp_path / "r.png", "--frames", "2")
    assert rc == 0 and "6 clips" in out  # five by the glob, one by name
    rc, out, _ = run(capsys, "view", spliced, "action:wave", "-o", tmp_path / "v.html")
    assert rc == 0 and "v.html" in out
    rc, out, _ = run(capsys, "evaluate", spliced, "-o", tmp_path / "r.md", "--no-pictures", "--select", "action:wave",
                     "--select", "locomotion:walk_*", "--json", tmp_path / "r.json")
    import json

    assert rc == 0 and sorted(c["name"] for c in json.loads((tmp_path / "r.json").read_text())["clips"]) == [
        "walk_curve+wave", "walk_straight+wave"]
    rc, _, err = run(capsys, "render", spliced, "zz*", "-o", tmp_path / "z.png")
    assert rc == 2 and "'zz*' selects no clip" in error_line(err)


def test_12_files_a_generic_spec_reads_can_be_given_their_units(sample_db, tmp_path, capsys):
    bvh = tmp_path / "bvh"
    assert main(["export", str(sample_db), "walk_straight", "jog", "-o", str(bvh), "-q"]) == 0
    rc, _, err = run(capsys, "import", bvh, "-o", tmp_path / "a.h5", "--spec", "generic", "--units", "m")
    assert rc == 2 and "cannot" in err.lower() and not (tmp_path / "a.h5").exists()
    rc, _, err = run(capsys, "import", bvh, "-o", tmp_path / "b.h5", "--spec", "generic", "--file-units", "cm",
                     "--units", "m", "-q")
    assert rc == 0, err
    with MotionDatabase.open(tmp_path / "b.h5") as d, MotionDatabase.open(sample_db) as s:
        assert d.skeleton_info(0).units == "m"
        a, b = d.read("walk_straight"), s.read("walk_straight")
    assert float((a.global_positions() * 100 - b.global_positions()).abs().max()) < 1e-3
    rc, _, err = run(capsys, "import", bvh, "-o", tmp_path / "c.h5", "--spec", "sample", "--file-units", "m")
    assert rc == 2 and "its spec 'sample' says its units are 'cm', not 'm'" in err
    rc, _, err = run(capsys, "import", bvh, "-o", tmp_path / "d.h5", "--file-units", "furlong")
    assert rc == 2 and "--file-units: unknown length unit 'furlong'" in error_line(err)


def test_per_clip_metrics_as_csv_for_any_database(sample_db, tmp_path, capsys):
    import csv

    spliced = tmp_path / "sp.h5"
    assert main(["splice-all", str(sample_db), "-o", str(spliced), "-q", "--method", "splice,naive"]) == 0
    rc, _, _ = run(capsys, "info", spliced, "method:naive", "--csv", tmp_path / "naive.csv", "--limit", "0")
    rows = list(csv.DictReader(open(tmp_path / "naive.csv")))
    assert rc == 0 and len(rows) == 25 and all(r["method"] == "naive" for r in rows)
    with MotionDatabase.open(spliced) as d:
        t = d.clip_table()
        cost = {t.names[r]: float(t.extra["cost"][r]) for r in range(len(t))}
    for r in rows:
        assert {"flags", "alignment_distance", "coverage", "labels"} <= set(r)
        want = cost[r["name"]]  # NaN where unset (the naive method aligns nothing): an empty cell
        assert (r["cost"] == "") if want != want else float(r["cost"]) == pytest.approx(want)
    rc, _, err = run(capsys, "info", spliced, "--csv", tmp_path / "x.txt")
    assert rc == 2 and "must end in .csv" in error_line(err)


def test_11_the_demo_draws_the_pair_where_the_naive_splice_loses_the_actions_posture_most():
    """The demo's preview pair is, of the sample's 25, the one whose naive and method's splices
    differ most in mean trunk lean, and the figures the README and the docs' home page give for it
    hold (both describe the picture): the box carrier leans
    back about 12 degrees, the method's splice keeps it, the naive one stands at about 5."""
    from test_splice import leans
    from torchsplice.sample import sample_motions
    from torchsplice.specs import load_spec
    from torchsplice.splice import splice

    spec = load_spec("sample")
    clips = {c.name: c for c in sample_motions()}
    roles = spec.bind(clips["jog"].skeleton)
    locomotions = ["walk_straight", "walk_curve", "turn_sharp", "sidestep", "jog"]
    actions = ["carry_box", "carry_cup", "wave", "punch", "arms_out"]
    lean = {}
    for lo in locomotions:
        for ac in actions:
            for method in ("splice", "naive"):
                lean[lo, ac, method] = float(leans(splice(clips[lo], clips[ac], spec, method=method).motion, roles).mean())
    gap = {(lo, ac): abs(lean[lo, ac, "splice"] - lean[lo, ac, "naive"]) for lo in locomotions for ac in actions}
    assert max(gap, key=gap.get) == ("jog", "carry_box")
    action = float(leans(clips["carry_box"], roles).mean())
    assert abs(action + 12) < 1 and abs(lean["jog", "carry_box", "splice"] + 12) < 1  # leans: forward positive
    assert abs(lean["jog", "carry_box", "naive"] + 5) < 1
    demo = (Path(__file__).resolve().parents[1] / "scripts" / "demo.sh").read_text()
    assert "--overlay jog+carry_box jog+carry_box.naive" in demo
    for page in ("README.md", "docs/index.md"):
        text = (Path(__file__).resolve().parents[1] / page).read_text()
        assert "leans back (12 degrees" in text and "stands straighter (5 degrees)" in text, page


def test_every_export_of_several_clips_writes_an_index_and_splits_by_source_clip(sample_db, tmp_path, capsys):
    """A BVH folder: index.csv (each file's clip, split and metrics, in export order) and
    train/val/test.txt, the splits the dataset gives (no locomotion or action in two splits); a
    packed file: NAME.npz.index.csv beside it; one clip or --no-index: none; a bad ratio: nothing."""
    import csv

    spliced = tmp_path / "sp.h5"
    assert main(["splice-all", str(sample_db), "-o", str(spliced), "-q", "--workers", "1", "--method", "splice,naive"]) == 0
    out = tmp_path / "bvh"
    rc, text, err = run(capsys, "export", spliced, "--all", "-o", out, "--split-ratios", "0.4,0.3,0.3", "--split-seed", "5")
    assert rc == 0, err
    with MotionDatabase.open(spliced) as d:
        names, cost = d.names, {n: float(c) for n, c in zip(d.names, d.clip_table().extra["cost"])}
    rows = list(csv.DictReader(open(out / "index.csv")))
    assert [r["clip"] for r in rows] == names and all((out / r["file"]).is_file() for r in rows)
    for r in rows:  # a naive splice has no cost (NaN in the table, empty here)
        c = cost[r["clip"]]
        assert (r["cost"] == "") if c != c else abs(float(r["cost"]) - c) <= 1e-9 * max(1.0, c)
    assert any(r["cost"] for r in rows)
    assert {"flags", "coverage", "alignment_distance", "locomotion", "action", "method"} <= set(rows[0])
    for s in ("train", "val", "test"):
        listed = (out / f"{s}.txt").read_text().split()
        assert listed == [r["file"] for r in rows if r["split"] == s]
        ds = MotionDataset(spliced, split=s, split_ratios=(0.4, 0.3, 0.3), split_seed=5, features=("rotations",))
        assert sorted(ds.names) == sorted(r["clip"] for r in rows if r["split"] == s)
    by = {s: [r for r in rows if r["split"] == s] for s in ("train", "val", "test")}
    for a in by:
        for b in by:
            if a != b:  # no source clip in two splits
                assert not {r["locomotion"] for r in by[a]} & {r["locomotion"] for r in by[b]}
                assert not {r["action"] for r in by[a]} & {r["action"] for r in by[b]}
    assert f"index.csv, train/val/test {len(by['train'])}/{len(by['val'])}/{len(by['test'])}" in text
    rc, _, err = run(capsys, "export", spliced, "method:naive", "--packed", "-o", tmp_path / "naive.npz")
    assert rc == 0, err
    packed = list(csv.DictReader(open(tmp_path / "naive.npz.index.csv")))
    assert {r["file"] for r in packed} == {"naive.npz"} and all(r["method"] == "naive" for r in packed)
    assert run(capsys, "export", spliced, "--all", "-o", tmp_path / "plain", "--no-index")[0] == 0
    assert not list((tmp_path / "plain").glob("*.csv")) and not list((tmp_path / "plain").glob("*.txt"))
    assert run(capsys, "export", spliced, names[0], "-o", tmp_path / "one.bvh")[0] == 0
    assert sorted(p.name for p in tmp_path.glob("one*")) == ["one.bvh"]
    rc, _, err = run(capsys, "export", spliced, "--all", "-o", tmp_path / "bad", "--split-ratios", "0.5,0.5")
    assert rc == 2 and "split-ratios" in error_line(err) and not (tmp_path / "bad").exists()
    rc, _, err = run(capsys, "export", spliced, "--all", "-o", tmp_path / "bad", "--split-ratios", "0.5,0.5", "--no-index")
    assert rc == 2 and "split-ratios" in error_line(err) and not (tmp_path / "bad").exists(), err  # with no index too
    for index in (True, False):
        with pytest.raises(TorchspliceError, match="split_seed must be a whole number, got 'x'"):
            export_clips(spliced, None, out=tmp_path / "bad", split_seed="x", index=index)
    packed_one = export_clips(spliced, names[:1], out=tmp_path / "one.npz", packed=True)  # a packed file, even of one
    assert [p.name for p in packed_one.index_files] == ["one.npz.index.csv"]


def test_indexes_are_named_after_their_whole_output_and_never_meet(sample_db, tmp_path, capsys):
    """a.h5 and a.hdf5, t.npz and t.h5, out.h5 and out.npz: each output's index is its own, and
    no command writes, replaces or removes another output's."""
    from torchsplice.formats.exporters import export_clips
    from torchsplice.job import splice_all

    splice_all(sample_db, tmp_path / "a.h5", locomotions="jog", workers=1)
    first = (tmp_path / "a.h5.index.csv").read_bytes()
    splice_all(sample_db, tmp_path / "a.hdf5", locomotions="walk_curve", workers=1)
    assert (tmp_path / "a.h5.index.csv").read_bytes() == first and (tmp_path / "a.hdf5.index.csv").is_file()
    export_clips(sample_db, out=tmp_path / "t.npz", format="npz", packed=True)
    packed = (tmp_path / "t.npz.index.csv").read_bytes()
    splice_all(sample_db, tmp_path / "t.h5", locomotions="jog", workers=1, index=False)
    splice_all(sample_db, tmp_path / "t.h5", locomotions="jog", workers=1, overwrite=True)
    assert (tmp_path / "t.npz.index.csv").read_bytes() == packed and (tmp_path / "t.h5.index.csv").is_file()
    rc, _, err = run(capsys, "export", tmp_path / "a.h5", "--all", "--packed", "-o", tmp_path / "a.npz", "-q")
    assert rc == 0, err
    assert (tmp_path / "a.npz.index.csv").is_file() and (tmp_path / "a.h5.index.csv").read_bytes() == first


def test_every_job_output_gets_an_index_of_its_clips_metrics_and_splits(sample_db, tmp_path, capsys):
    """``splice-all`` writes ``OUT.h5.index.csv`` beside its output (every clip's cost, flags,
    coverage, labels and split by source clip, as the exports' index and ``info --csv``), and
    so does ``merge`` after sliced runs; ``--no-index`` (``index=False``) writes none."""
    import csv

    from torchsplice.data.splits import table_splits
    from torchsplice.job import splice_all

    out = tmp_path / "sp.h5"
    rc, text, err = run(capsys, "splice-all", sample_db, "-o", out, "--workers", "1", "--method", "splice,naive")
    assert rc == 0, err
    assert "every clip's metrics and split in sp.h5.index.csv" in text
    rows = list(csv.DictReader(open(tmp_path / "sp.h5.index.csv")))
    with MotionDatabase.open(out) as d:
        table = d.clip_table()
        names, cost = list(table.names), [float(c) for c in table.extra["cost"]]
        splits = table_splits(table)
    assert [r["clip"] for r in rows] == names and {r["file"] for r in rows} == {"sp.h5"}
    assert [r["split"] for r in rows] == splits and {"train", "val", "test"} & set(splits)
    assert all((r["cost"] == "") if c != c else abs(float(r["cost"]) - c) <= 1e-9 * max(1.0, c) for r, c in zip(rows, cost))
    assert {"flags", "coverage", "alignment_distance", "locomotion", "action", "method", "labels"} <= set(rows[0])
    rc, _, _ = run(capsys, "info", out, "--csv", tmp_path / "info.csv")
    info = list(csv.DictReader(open(tmp_path / "info.csv")))
    assert rc == 0 and [{k: r["clip" if k == "name" else k] for k in info[0]} for r in rows] == info  # the same values
    splice_all(sample_db, tmp_path / "plain.h5", locomotions="jog", workers=1, index=False)
    assert sorted(p.name for p in tmp_path.glob("plain*")) == ["plain.h5"]
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", out, "--workers", "1", "--locomotions", "jog", "--force",
                     "--no-index", "-q")
    assert rc == 0 and not (tmp_path / "sp.h5.index.csv").exists(), err  # an earlier run's index is not left beside it
    for k in (1, 2):
        assert run(capsys, "splice-all", sample_db, "-o", tmp_path / "sliced.h5", "--locomotions", "jog", "--workers", "1",
                   "--shard", f"{k}/2", "-q")[0] == 0
    assert not (tmp_path / "sliced.h5.index.csv").exists()  # a slice writes no output, so no index
    rc, text, err = run(capsys, "merge", tmp_path / "sliced.h5")
    assert rc == 0 and "sliced.h5.index.csv" in text, err
    merged = list(csv.DictReader(open(tmp_path / "sliced.h5.index.csv")))
    with MotionDatabase.open(tmp_path / "sliced.h5") as d:
        assert [r["clip"] for r in merged] == list(d.names)


def test_a_full_disk_while_writing_the_jobs_index_says_the_output_is_complete(sample_db, tmp_path, capsys, monkeypatch):
    import errno

    real = Path.open

    class Full:  # a file on a full disk: every write fails
        def __init__(self, f):
            self.f = f

        def write(self, text):
            raise OSError(errno.ENOSPC, "No space left on device")

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    def full(self, mode="r", *a, **k):
        f = real(self, mode, *a, **k)
        return Full(f) if ".index.csv" in self.name and "w" in mode else f

    monkeypatch.setattr(Path, "open", full)
    out = tmp_path / "sp.h5"
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", out, "--locomotions", "jog", "--workers", "1", "-q")
    line = error_line(err)
    assert rc != 0 and "sp.h5.index.csv" in line and "no space left" in line.lower() and "sp.h5 itself is complete" in line
    assert out.is_file() and sorted(p.name for p in tmp_path.iterdir()) == ["sp.h5"]  # no temporary left


def test_a_wrong_spec_on_a_folder_is_said_once_with_the_count_and_the_spec_auto_picks(mocap_dir, tmp_path, capsys):
    folder = tmp_path / "takes"
    folder.mkdir()
    takes = sorted((mocap_dir / "bandai_namco_research_motiondataset").glob("*walk*.bvh"))[:6]
    for f in takes:
        (folder / f.name).symlink_to(f)
    rc, _, err = run(capsys, "import", folder, "--spec", "lafan1", "-o", tmp_path / "x.h5")
    lines = [ln for ln in err.splitlines() if ln.startswith("skipped")]
    assert rc == 2 and len(lines) == 1, err
    assert lines[0].startswith(f"skipped {len(takes)} files (") and "--spec auto picks 'bandai_namco' for them" in lines[0]


def test_one_of_anything_is_said_in_the_singular(sample_db, tmp_path, capsys):
    args = ["splice-all", sample_db, "--locomotions", "jog", "--actions", "wave", "--method", "naive", "--workers", "1"]
    rc, out, err = run(capsys, *args, "-o", tmp_path / "one.h5", "--dry-run")
    assert rc == 0 and "1 spliced clip in 1 task" in out, out + err
    rc, out, err = run(capsys, *args, "-o", tmp_path / "one.h5")
    assert rc == 0 and "1 spliced clip in" in out and "1 spliced clips" not in out, out + err
    for argv, words in ((["export", tmp_path / "one.h5", "--all", "--packed", "-o", tmp_path / "one.npz"], "1 clip packed"),
                        (["export", tmp_path / "one.h5", "--all", "-o", tmp_path / "bvh"], "jog+wave.naive, 150 frames"),
                        (["export", tmp_path / "one.h5", "--all", "--format", "humanml3d", "-o", tmp_path / "h"],
                         "1 clip as HumanML3D, 1 motion")):
        rc, out, err = run(capsys, *argv)
        assert rc == 0 and words in out, out + err


def test_long_commands_print_progress_lines_to_a_log(sample_db, tmp_path, capsys, monkeypatch):
    """Not on a terminal (a pipe, a log, capsys here), export and splice-all print progress
    lines (every 30 s; here every update) instead of nothing; --quiet prints none."""
    monkeypatch.setenv("TORCHSPLICE_PROGRESS_SECONDS", "0")
    rc, _, err = run(capsys, "export", sample_db, "--all", "-o", tmp_path / "bvh")
    assert rc == 0 and "export bvh: 10/10 files (100%)" in err, err
    rc, _, err = run(capsys, "splice-all", sample_db, "-o", tmp_path / "s.h5", "--locomotions", "jog", "--workers", "1")
    assert rc == 0 and "splice-all: " in err and "splices (100%)" in err, err
    rc, _, err = run(capsys, "export", sample_db, "--all", "-o", tmp_path / "q", "-q")
    assert rc == 0 and "export bvh" not in err
