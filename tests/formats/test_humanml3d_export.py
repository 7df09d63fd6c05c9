"""Exports as HumanML3D (``export_clips(format="humanml3d")``, ``torchsplice export --format humanml3d``): a folder text-to-motion training reads as HumanML3D.

Checked on the spliced sample (every pair of the built-in sample) and on real clips of Bandai
Namco, CMU and LAFAN1 (retargeted onto the SMPL body):

- positions recovered from the exported features equal ``new_joints`` (1e-5 m); features
  derived again from ``new_joints`` agree with ``new_joint_vecs`` away from the clip's end
  (5e-3, 60 frames: the heading is smoothed by a Gaussian of sigma 20 frames, and ``new_joints``
  lacks the clip's last frame) and contacts on 99% of frames;
- bones keep their lengths (1e-6 m) and the feet stand on y = 0 (the 5th percentile of the
  lowest joint within 1 cm);
- Mean/Std equal a brute-force computation over every file; the folder reads as MDM's loader
  reads it (split list, length filter, ``caption#tokens#start#end`` lines, ``word/POS``);
- splits leak no source clip; mirrored copies are the mirrored motion with left and right
  swapped in the captions; windows cut long clips; captions known answers; bad input one line.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from cli_helpers import error_line, run
from realdata import BANDAI
from torchsplice.core.errors import TorchspliceError
from torchsplice.formats.captions import gerund, mirror_caption, parse_caption_line
from torchsplice.formats.exporters import export_clips
from torchsplice.formats.importer import import_bvh
from torchsplice.job import splice_all
from torchsplice.evaluation.humanml3d import folder_properties
from torchsplice.formats.humanml3d_features import GROUPS
from torchsplice.specs.text import POS_TAGS


@pytest.fixture(scope="module")
def spliced(sample_db, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("h3") / "spliced.h5"
    splice_all(sample_db, out)
    return out


@pytest.fixture(scope="module")
def folder(spliced, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("h3out") / "HumanML3D"
    export_clips(spliced, out=out, format="humanml3d", mirror=True)
    return out


def _motions(folder: Path):
    for f in sorted((folder / "new_joint_vecs").glob("*.npy")):
        vecs = np.load(f)
        joints = np.load(folder / "new_joints" / f.name)
        yield f.stem, torch.from_numpy(vecs).double(), torch.from_numpy(joints).double()


def _index(folder: Path) -> list[dict]:
    with open(folder / "index.csv", newline="") as f:
        return list(csv.DictReader(f))


def _check_motions(folder: Path) -> dict:
    """The format's properties over every motion of an exported folder (the worst figures), the
    derived features 60 frames away from the clip's end."""
    worst = folder_properties(folder, margins=(60,))
    assert worst["motions"] == len(list((folder / "new_joint_vecs").glob("*.npy"))) > 0
    return {**worst, "derived": worst["derived60"]}


def test_the_folder_holds_the_formats_files(folder):
    index = _index(folder)
    ids = [r["id"] for r in index]
    assert len(ids) == 50 and sum(i.startswith("M") for i in ids) == 25  # 25 splices and their mirrors
    for i in ids:
        for sub, suffix in (("new_joint_vecs", ".npy"), ("new_joints", ".npy"), ("texts", ".txt")):
            assert (folder / sub / f"{i}{suffix}").is_file(), (sub, i)
    assert np.load(folder / "Mean.npy").shape == (263,) and np.load(folder / "Std.npy").shape == (263,)
    assert np.load(folder / "Mean.npy").dtype == np.float32
    all_ids = (folder / "all.txt").read_text().split()
    assert all_ids == [r["id"] for r in index if r["split"]]  # HumanML3D's all.txt: the splits' union
    train, val = (folder / "train.txt").read_text().split(), (folder / "val.txt").read_text().split()
    test = (folder / "test.txt").read_text().split()
    assert sorted(all_ids) == sorted(train + val + test) and len(set(train + val + test)) == len(train + val + test)
    assert (folder / "train_val.txt").read_text().split() == train + val
    assert not [p for p in folder.rglob(".*")]  # nothing staged is left


def test_the_index_carries_each_clips_checks_from_the_database(spliced, folder):
    from torchsplice.formats.humanml3d_exporter import CHECK_COLUMNS
    from torchsplice.store.database import MotionDatabase

    with MotionDatabase.open(spliced) as db:
        t = db.clip_table()
        of = {n: {c: t.extra[c][i] for c in CHECK_COLUMNS} for i, n in enumerate(t.name)}
    index = _index(folder)
    assert set(CHECK_COLUMNS) <= set(index[0])
    for r in index:
        want = of[r["clip"]]
        assert r["flags"] == str(want["flags"])
        assert r["corrected_frames"] == ("" if int(want["corrected_frames"]) < 0 else str(int(want["corrected_frames"])))
        for c in set(CHECK_COLUMNS) - {"flags", "corrected_frames"}:
            assert (r[c] == "") == (not np.isfinite(float(want[c]))), c  # empty for unknown units
            if r[c]:
                assert float(r[c]) == pytest.approx(float(want[c]), rel=1e-5, abs=1e-9), c


def test_an_earlier_versions_index_is_still_the_exports_own(spliced, tmp_path):
    from torchsplice.formats.humanml3d_exporter import INDEX_COLUMNS, HumanML3DExporter

    out = tmp_path / "h"
    export_clips(spliced, ["walk_straight+wave"], out=out, format="humanml3d")
    lines = (out / "index.csv").read_text().splitlines()
    old = [",".join(r.split(",")[:16]) for r in lines]  # the 16 columns before the checks
    assert lines[0].split(",") == list(INDEX_COLUMNS) and old[0].split(",") == list(INDEX_COLUMNS[:16])
    (out / "index.csv").write_text("\n".join(old) + "\n")
    assert HumanML3DExporter.earlier_ids(out) == ["000000"]
    (out / "index.csv").write_text("id,clip,something\n000000,x,1\n")
    assert HumanML3DExporter.earlier_ids(out) is None


def test_exported_motions_have_the_formats_properties(folder):
    worst = _check_motions(folder)
    assert worst["recover"] < 1e-5, worst
    assert worst["bones"] < 1e-6, worst
    assert worst["derived"] < 5e-3 and worst["contacts"] >= 0.99, worst
    assert abs(worst["floor_p5"]) < 0.01, worst


def test_mean_and_std_are_the_formats_over_every_file(folder):
    rows = np.concatenate([np.load(f).astype(np.float64) for f in sorted((folder / "new_joint_vecs").glob("*.npy"))])
    mean, std = rows.mean(0), rows.std(0)
    for a, b in GROUPS:
        std[a:b] = std[a:b].mean()
    std[std <= 1e-8] = 1.0
    assert np.allclose(np.load(folder / "Mean.npy"), mean, rtol=1e-5, atol=1e-6)
    assert np.allclose(np.load(folder / "Std.npy"), std, rtol=1e-5, atol=1e-6)


def _mdm_style_read(root: Path, split: str, min_len: int = 40, max_len: int = 200) -> dict:
    """How MDM's ``Text2MotionDatasetV2`` reads a HumanML3D folder (written here from the format's
    description): the split's ids, ``new_joint_vecs/ID.npy`` kept when ``min_len <= N < max_len``,
    each text line split at ``#`` into caption, ``word/POS`` tokens, start and end, then the
    motion normalized by Mean and Std."""
    mean, std = np.load(root / "Mean.npy"), np.load(root / "Std.npy")
    data = {}
    for name in (root / f"{split}.txt").read_text().splitlines():
        motion = np.load(root / "new_joint_vecs" / f"{name.strip()}.npy")
        if len(motion) < min_len or len(motion) >= max_len:
            continue
        texts = []
        for line in (root / "texts" / f"{name.strip()}.txt").read_text().splitlines():
            caption, tokens, f_tag, to_tag = line.strip().split("#")
            f_tag, to_tag = float(f_tag), float(to_tag)
            words = tokens.split(" ")
            assert caption and all(len(t.split("/")) == 2 and t.split("/")[1] in POS_TAGS for t in words), line
            assert all(t.split("/")[0].isalpha() for t in words), line
            assert (f_tag, to_tag) == (0.0, 0.0)
            texts.append({"caption": caption, "tokens": words})
        assert texts, name
        normalized = (motion - mean) / std
        assert np.isfinite(normalized).all()
        data[name] = (normalized, texts)
    return data


def test_the_folder_reads_as_mdms_loader_reads_it(folder):
    train = _mdm_style_read(folder, "train")
    test = _mdm_style_read(folder, "test")
    assert train and test
    for normalized, texts in train.values():
        assert normalized.shape[1] == 263 and 40 <= len(normalized) < 200
        assert 1 <= len(texts) <= 3


def test_splits_leak_no_source_clip_and_mirrors_follow_their_originals(folder):
    index = _index(folder)
    by_split: dict[str, set] = {}
    for r in index:
        if r["split"]:
            by_split.setdefault(r["split"], set()).update({("l", r["locomotion"]), ("a", r["action"])})
    sources = {s: {name for _, name in v} for s, v in by_split.items()}
    assert sources["train"] and sources["test"]
    assert not sources["train"] & sources["test"] and not sources["train"] & sources.get("val", set())
    split_of = {r["id"]: r["split"] for r in index}
    for i, s in split_of.items():
        if i.startswith("M"):
            assert s == split_of[i[1:]]
    for s in ("train", "val", "test"):
        assert set((folder / f"{s}.txt").read_text().split()) == {i for i, v in split_of.items() if v == s}


def test_the_split_is_seeded_and_its_ratios_are_options(spliced, tmp_path):
    a = export_clips(spliced, out=tmp_path / "a", format="humanml3d", split_seed=1, split_ratios="0.6,0.2,0.2")
    b = export_clips(spliced, out=tmp_path / "b", format="humanml3d", split_seed=1, split_ratios=(0.6, 0.2, 0.2))
    c = export_clips(spliced, out=tmp_path / "c", format="humanml3d", split_seed=2, split_ratios=(0.6, 0.2, 0.2))
    splits = [[r["split"] for r in _index(Path(x.output))] for x in (a, b, c)]
    assert splits[0] == splits[1] and splits[0] != splits[2]
    assert (Path(a.output) / "new_joint_vecs" / "000000.npy").read_bytes() == \
        (Path(c.output) / "new_joint_vecs" / "000000.npy").read_bytes()


def test_a_mirrored_copy_is_the_mirrored_motion_with_left_and_right_swapped_in_its_captions(folder):
    swap = [0, 2, 1, 3, 5, 4, 6, 8, 7, 9, 11, 10, 12, 14, 13, 15, 17, 16, 19, 18, 21, 20]
    joints = np.load(folder / "new_joints" / "000007.npy")
    mirrored = np.load(folder / "new_joints" / "M000007.npy")
    expect = joints[:, swap] * np.array([-1.0, 1.0, 1.0])
    assert np.abs(mirrored - expect).max() < 1e-4
    text = (folder / "texts" / "000007.txt").read_text().splitlines()
    mtext = (folder / "texts" / "M000007.txt").read_text().splitlines()
    assert "right hand" in text[0] and "left hand" in mtext[0]
    assert mtext == [mirror_caption(parse_caption_line(t, "t")).line() for t in text]


def test_captions_say_the_locomotion_and_the_action(folder):
    index = {r["clip"]: r["id"] for r in _index(folder) if r["mirrored"] == "0"}
    lines = (folder / "texts" / f"{index['walk_curve+wave']}.txt").read_text().splitlines()
    subjects = ("a person", "someone", "the person")
    legs = ("walks in a curve to the left", "walks forward curving left")
    arms = ("waving the right hand", "waving with the right arm overhead")
    allowed = {f"{s} {l} while {a}" for s in subjects for l in legs for a in arms}
    assert {ln.split("#")[0] for ln in lines} <= allowed, lines
    assert all(" while " in ln.split("#")[0] for ln in lines) and len(set(lines)) == len(lines) == 3
    tokens = lines[0].split("#")[1].split()
    assert "wave/VERB" in tokens and "walk/VERB" in tokens and "while/SCONJ" in tokens
    box = (folder / "texts" / f"{index['jog+carry_box']}.txt").read_text()
    assert "jogs" in box or "runs slowly" in box
    assert "carrying a heavy box" in box or "holding a big box" in box


def test_gerunds_of_common_verbs():
    assert [gerund(v) for v in ("wave", "run", "step", "jog", "carry", "lie", "see", "walk", "bow", "punch", "shrug",
                                 "beckon", "open")] == [
        "waving", "running", "stepping", "jogging", "carrying", "lying", "seeing", "walking", "bowing", "punching",
        "shrugging", "beckoning", "opening"]


def test_users_captions_per_source_clip_compose_the_same_way(spliced, tmp_path):
    captions = tmp_path / "captions.json"
    captions.write_text(json.dumps({
        "walk_curve": ["a man walks in a circle.#a/DET man/NOUN walk/VERB in/ADP a/DET circle/NOUN#0.0#0.0"],
        "wave": ["someone/PRON claps=clap/VERB the/DET hands=hand/NOUN"],
    }))
    out = tmp_path / "h"
    export_clips(spliced, ["walk_curve+wave", "walk_straight+wave"], out=out, format="humanml3d", captions=captions)
    index = {r["clip"]: r["id"] for r in _index(out)}
    text = (out / "texts" / f"{index['walk_curve+wave']}.txt").read_text().splitlines()
    assert text == ["someone walks in a circle while clapping the hands#someone/PRON walk/VERB in/ADP a/DET "
                    "circle/NOUN while/SCONJ clap/VERB the/DET hand/NOUN#0.0#0.0"]
    other = (out / "texts" / f"{index['walk_straight+wave']}.txt").read_text()
    assert "while clapping the hands" in other and "walks" in other


def test_a_window_cuts_long_clips_into_windows_with_the_clips_captions(spliced, tmp_path):
    out = tmp_path / "w"
    export_clips(spliced, ["walk_curve+wave"], out=out, format="humanml3d", window=3.0)
    rows = _index(out)
    whole = tmp_path / "whole"
    export_clips(spliced, ["walk_curve+wave"], out=whole, format="humanml3d")
    total = int(_index(whole)[0]["rows"]) + 1
    assert len(rows) == -(-total // 60) >= 2
    assert all(int(r["rows"]) == 59 for r in rows)
    assert float(rows[0]["start_s"]) == 0.0 and float(rows[-1]["end_s"]) == pytest.approx((total - 1) / 20.0)
    texts = {(out / "texts" / f"{r['id']}.txt").read_text() for r in rows}
    assert len(texts) == 1 and texts == {(whole / "texts" / "000000.txt").read_text()}


def _real_db(mocap_dir, tmp_path) -> Path:
    files = [mocap_dir / BANDAI / f"{n}.bvh" for n in (
        "dataset-1_walk_normal_001", "dataset-1_bye_normal_001", "dataset-2_walk-turn-left_normal_025",
        "dataset-2_walk_elderly_006")]
    files += [mocap_dir / "cmu_graphics_lab" / "cmu_12_01_walk.bvh", mocap_dir / "lafan1_via_pypi_bvhtools" / "test.bvh"]
    files = [f for f in files if f.is_file()]
    assert len(files) >= 5
    db = tmp_path / "real.h5"
    assert import_bvh(files, db).ok
    return db


def test_real_clips_of_three_datasets_export_with_the_formats_properties(mocap_dir, tmp_path):
    db = _real_db(mocap_dir, tmp_path)
    out = tmp_path / "real"
    result = export_clips(db, out=out, format="humanml3d", window=9.8)
    worst = _check_motions(out)
    assert worst["recover"] < 1e-5 and worst["bones"] < 1e-6, worst
    assert worst["derived"] < 5e-3 and worst["contacts"] >= 0.99, worst
    assert abs(worst["floor_p5"]) < 0.01, worst
    rows = _index(out)
    assert {r["clip"] for r in rows} >= {"dataset-2_walk_elderly_006", "cmu_12_01_walk", "test"}
    assert all(int(r["rows"]) < 196 for r in rows)
    elderly = [r for r in rows if r["clip"] == "dataset-2_walk_elderly_006"][0]
    assert "elderly person walks" in (out / "texts" / f"{elderly['id']}.txt").read_text() or \
        "old person walks" in (out / "texts" / f"{elderly['id']}.txt").read_text()
    assert "HumanML3D" in result.summary


def test_a_spliced_bandai_clip_is_captioned_from_both_sources(mocap_dir, tmp_path):
    db = _real_db(mocap_dir, tmp_path)
    spliced = tmp_path / "sp.h5"
    assert splice_all(db, spliced, locomotions="dataset-2_walk-turn-left_normal_025",
                      actions="dataset-2_walk_elderly_006,dataset-1_bye_normal_001").spliced == 2
    out = tmp_path / "sp"
    export_clips(spliced, out=out, format="humanml3d")
    texts = {r["action"]: (out / "texts" / f"{r['id']}.txt").read_text() for r in _index(out)}
    assert any(p in texts["dataset-2_walk_elderly_006"] for p in ("an elderly person walks", "an old person walks"))
    assert "turns" in texts["dataset-2_walk_elderly_006"] and " while " not in texts["dataset-2_walk_elderly_006"]
    assert "while waving goodbye" in texts["dataset-1_bye_normal_001"]


def _refusal(call) -> str:  # the one-line message of the TorchspliceError call() raises
    with pytest.raises(TorchspliceError) as caught:
        call()
    assert "\n" not in str(caught.value), caught.value
    return str(caught.value)


def test_bad_input_is_one_line_and_leaves_nothing(spliced, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"wave": ["waves"]}')
    for options, words in (
            ({"captions": bad}, "bad.json: 'wave': 'waves' is not word/POS"),
            ({"captions": tmp_path / "none.json"}, "none.json: no such captions file"),
            ({"window": 0.01}, "window must be a length in seconds"),
            *(({"split_ratios": r}, "split_ratios must be three numbers")
              for r in ((0.5, 0.6), (float("nan"), 1, 1), (float("inf"), float("-inf"), 1))),
            ({"paraphrases": 0}, "paraphrases must be a whole number")):
        out = tmp_path / "o"
        assert words in _refusal(lambda: export_clips(spliced, out=out, format="humanml3d", **options)), options
        assert not out.exists()
    (tmp_path / "file.txt").write_text("x")  # a file, and a file's suffix with an option only HumanML3D takes
    assert "writes a folder" in _refusal(lambda: export_clips(spliced, out=tmp_path / "file.txt", format="humanml3d"))
    assert "writes a folder" in _refusal(lambda: export_clips(spliced, out=tmp_path / "x.npz", mirror=True))
    assert not (tmp_path / "x.npz").exists() and (tmp_path / "file.txt").read_text() == "x"


def test_cli_names_its_flags_in_the_one_line_refusals_of_bad_options(spliced, tmp_path, capsys):
    """The command line's words for export_clips' refusals of the options above: its flags."""
    ratios, out = "--split-ratios must be three numbers", tmp_path / "o"
    for args, words in ((["--window", "0.01"], "--window must be a length in seconds"), (["--split-ratios", "0.5,0.6"], ratios),
                        (["--split-ratios", "nan,1,1"], ratios), (["--split-ratios", "inf,-inf,1"], ratios),
                        (["--paraphrases", "0"], "--paraphrases must be a whole number")):
        rc, _, err = run(capsys, "export", spliced, "--all", "-o", out, "--format", "humanml3d", *args)
        assert rc == 2 and words in error_line(err), (args, err)
        assert not out.exists()


def test_a_skeleton_that_does_not_map_onto_smpl_is_refused_naming_the_database(tmp_path):
    from rigs import armless_sample
    from torchsplice.store.database import MotionDatabase

    stump = armless_sample()
    db = tmp_path / "stumps.h5"
    with MotionDatabase.create(db) as w:
        w.append(stump)
    line = _refusal(lambda: export_clips(db, out=tmp_path / "o", format="humanml3d"))
    assert "stumps.h5" in line and "SMPL" in line and "elbow" in line, line
    assert not (tmp_path / "o").exists()


def test_a_failure_midway_leaves_no_file_and_a_rerun_writes_the_same(spliced, tmp_path, monkeypatch):
    from torchsplice.formats import humanml3d_exporter as hx

    out = tmp_path / "h"
    calls = {"n": 0}
    real = hx.HumanML3DExporter.write

    def failing(self, item, path):
        calls["n"] += 1
        if calls["n"] == 40:
            raise KeyboardInterrupt
        real(self, item, path)

    monkeypatch.setattr(hx.HumanML3DExporter, "write", failing)
    with pytest.raises(KeyboardInterrupt):
        export_clips(spliced, out=out, format="humanml3d")
    assert not out.exists()
    monkeypatch.setattr(hx.HumanML3DExporter, "write", real)
    export_clips(spliced, out=out, format="humanml3d")
    assert len(list((out / "new_joint_vecs").glob("*.npy"))) == 25


def test_a_malformed_phrase_table_is_one_line_when_the_spec_loads(tmp_path):
    from torchsplice.core.errors import SpecError
    from torchsplice.specs import load_spec

    base = (Path(__file__).resolve().parents[2] / "datasets_spec" / "sample.toml").read_text()
    base = base[:base.index("[text.locomotion]")]
    for table, words in (
            ('[text.action]\nwave = ["waves/VB"]\n', "mine.toml: [text.action] wave: 'waves/VB': unknown part of speech 'VB'"),
            ('[text.action]\nwave = ["waves"]\n', "'waves' is not word/POS or word=lemma/POS"),
            ('[text.moods]\nhappy = ["a/DET person/NOUN"]\n', "[text] moods: unknown key (allowed: locomotion, action, style)"),
            ('[text.style]\nkey = "style"\n', "names no label"),
            ('[text.action]\nwave = 3\n', "expected a list of phrases")):
        f = tmp_path / "mine.toml"
        f.write_text(base.replace('name = "sample"', 'name = "mine"') + table)
        with pytest.raises(SpecError) as info:
            load_spec(f)
        assert words in str(info.value) and "\n" not in str(info.value), (table, str(info.value))
    f.write_text(base.replace('name = "sample"', 'name = "mine"') + '[text.locomotion]\nkey = "{content}-{path}"\n'
                 '"walk-straight" = ["strolls=stroll/VERB"]\n')
    from torchsplice.specs.text import spec_phrase_table

    table = spec_phrase_table(load_spec(f))
    assert table.key("locomotion", {"content": "walk", "path": "straight"}) == "walk-straight"
    assert table.lookup("locomotion", {"content": "walk"}) is None
    assert [t.lemma for t in table.lookup("locomotion", {"content": "walk", "path": "straight"})[0]] == ["stroll"]


def test_a_spliced_clip_whose_action_or_locomotion_no_phrase_says_is_flagged_never_captioned_empty():
    from torchsplice.formats.captions import clip_captions
    from torchsplice.specs.text import parse_phrase_table

    table = parse_phrase_table({"locomotion": {"walk": ["walks=walk/VERB"], "float": []},
                                "action": {"wave": ["waves=wave/VERB"], "walk": []}}, "t.toml", "t")
    def said(loco, action):
        labels = {"locomotion.content": loco, "action.content": action}
        return clip_captions("x", "spliced", labels, [table], locomotion="l", action="a")

    captions, described = said("walk", "wave")
    assert described and "walks while waving" in captions[0].text
    captions, described = said("walk", "walk")  # the action says nothing more: described
    assert described and captions and all(" while " not in c.text for c in captions)
    for loco, action in (("walk", "juggle"), ("float", "wave"), ("swim", "wave")):
        captions, described = said(loco, action)
        assert not described and captions and all(" walks" in c.text or " moves" in c.text for c in captions), (loco, action)


def test_caption_lines_are_checked_as_the_loaders_split_them():
    from torchsplice.core.errors import TorchspliceError

    for line, words in (("one half#1/2/NUM#0.0#0.0", "token '1/2/NUM' is not word/POS"),
                        ("and or#and/or/CCONJ#0.0#0.0", "token 'and/or/CCONJ' is not word/POS"),
                        ("a b#a/DET b/NOUN#x#0.0", "start or end 'x' is not a number"),
                        ("a b#a/DET b/NOUN#2.0#1.0", "ends (1 s) before it starts (2 s)"),
                        ("a b#a/DET b/NOUN#0.0#0.0#7", "is not 'caption#tokens#start#end'")):
        with pytest.raises(TorchspliceError, match=None) as info:
            parse_caption_line(line, "c.json")
        assert words in str(info.value), (line, str(info.value))
    c = parse_caption_line("a person waves.#a/DET person/NOUN wave/VERB#1.5#3.0", "c")
    assert (c.start, c.end) == (1.5, 3.0) and c.line() == "a person waves.#a/DET person/NOUN wave/VERB#1.5#3.0"
    assert c.within(2.0, 10.0).line().endswith("#0.0#1.0") and c.within(3.5, 9.0) is None


def test_captions_made_from_real_sentences_read_as_one_sentence():
    from torchsplice.formats.captions import clip_captions

    user = {"l": [parse_caption_line("a person is walking forward.#a/DET person/NOUN is/AUX walk/VERB forward/ADV#0.0#0.0",
                                     "u")],
            "a": [parse_caption_line("a man waves his left hand while walking#a/DET man/NOUN wave/VERB his/DET left/ADJ "
                                     "hand/NOUN while/SCONJ walk/VERB#0.0#0.0", "u")],
            "b": [parse_caption_line("someone is clapping#someone/PRON is/AUX clap/VERB#0.0#0.0", "u")]}
    (caption,), _ = clip_captions("x", "spliced", {}, [], user, count=1, locomotion="l", action="a")
    assert caption.text == "a man is walking forward while waving his left hand", caption
    (caption,), _ = clip_captions("y", "spliced", {}, [], user, count=1, locomotion="l", action="b")
    assert caption.text == "someone is walking forward while clapping", caption
    assert [w for w, _ in caption.tokens] == ["someone", "is", "walk", "forward", "while", "clap"]


def test_mirroring_swaps_compound_words_once():
    c = parse_caption_line("a person turns counter-clockwise with a left-handed wave#a/DET person/NOUN turn/VERB "
                           "counterclockwise/ADV with/ADP a/DET lefthanded/ADJ wave/NOUN#0.0#0.0", "c")
    m = mirror_caption(c)
    assert m.text == "a person turns clockwise with a right-handed wave"
    assert ("clockwise", "ADV") in m.tokens and ("righthanded", "ADJ") in m.tokens
    assert mirror_caption(m).text == "a person turns counterclockwise with a left-handed wave"


def test_part_captions_go_to_the_windows_they_overlap_in_their_time(spliced, tmp_path):
    captions = tmp_path / "c.json"
    captions.write_text(json.dumps({"walk_curve+wave": [
        "a person walks#a/DET person/NOUN walk/VERB#0.0#0.0",
        "a person waves late#a/DET person/NOUN wave/VERB late/ADV#5.0#6.0"]}))
    out = tmp_path / "w"
    export_clips(spliced, ["walk_curve+wave"], out=out, format="humanml3d", window=3.0, captions=captions)
    for r in _index(out):
        lines = (out / "texts" / f"{r['id']}.txt").read_text().splitlines()
        assert lines[0] == "a person walks#a/DET person/NOUN walk/VERB#0.0#0.0"
        start, end = float(r["start_s"]), float(r["end_s"])
        late = [ln for ln in lines if "late" in ln]
        if end > 5.0:
            a, b = max(5.0, start) - start, min(6.0, end) - start
            assert late == [f"a person waves late#a/DET person/NOUN wave/VERB late/ADV#{round(a, 4)}#{round(b, 4)}"], (r, late)
        else:
            assert not late, r


def _foreign_dataset(folder):
    """A HumanML3D folder as the dataset ships it (no torchsplice index): what --force must not touch."""
    files = {}
    for sub, suffix in (("new_joint_vecs", ".npy"), ("new_joints", ".npy"), ("texts", ".txt")):
        (folder / sub).mkdir(parents=True, exist_ok=True)
        for i in ("005000", "M005000", "000000"):
            f = folder / sub / f"{i}{suffix}"
            if suffix == ".npy":
                np.save(f, np.full((3, 4), float(len(files))))
            else:
                f.write_text(f"a person walks#{len(files)}")
            files[f] = f.read_bytes()
    for name in ("Mean.npy", "Std.npy"):
        np.save(folder / name, np.ones(263))
        files[folder / name] = (folder / name).read_bytes()
    for name in ("all.txt", "train.txt"):
        (folder / name).write_text("005000\nM005000\n000000\n")
        files[folder / name] = (folder / name).read_bytes()
    return files


def test_force_never_removes_or_replaces_a_dataset_no_torchsplice_export_wrote(spliced, tmp_path, capsys):
    """A real HumanML3D folder (or one whose index.csv is not torchsplice's) is refused in one
    line with --force, every file as it was; an earlier export merged into a foreign folder
    removes with --force only the files its own index lists."""
    out = tmp_path / "HumanML3D"
    files = _foreign_dataset(out)
    for index in (None, "name,split\nx,train\n"):
        if index is not None:
            (out / "index.csv").write_text(index)
            files[out / "index.csv"] = (out / "index.csv").read_bytes()
        rc, _, err = run(capsys, "export", spliced, "--all", "--format", "humanml3d", "-o", out, "--force")
        assert rc == 2 and "no torchsplice export wrote" in error_line(err) and "--force" in error_line(err), err
        assert all(f.read_bytes() == b for f, b in files.items())
        with pytest.raises(TorchspliceError, match="overwrite replaces only"):
            export_clips(spliced, out=out, format="humanml3d", overwrite=True)
    # a torchsplice export beside foreign files: --force removes its own files only
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    export_clips(spliced, out=mixed, format="humanml3d")
    theirs = mixed / "new_joint_vecs" / "M005000.npy"
    np.save(theirs, np.zeros(3))
    export_clips(spliced, ["walk_straight+wave"], out=mixed, format="humanml3d", overwrite=True)
    assert theirs.exists() and sorted(f.stem for f in (mixed / "new_joint_vecs").iterdir()) == ["000000", "M005000"]


def test_an_export_with_force_into_an_earlier_one_leaves_none_of_its_files(spliced, tmp_path):
    out = tmp_path / "h"
    export_clips(spliced, out=out, format="humanml3d", mirror=True)
    assert len(list((out / "new_joint_vecs").glob("*.npy"))) == 50
    (out / "notes.md").write_text("mine")  # not the format's: kept
    export_clips(spliced, ["walk_straight+wave", "jog+punch"], out=out, format="humanml3d", overwrite=True)
    for sub in ("new_joint_vecs", "new_joints", "texts"):
        assert sorted(f.stem for f in (out / sub).iterdir()) == ["000000", "000001"], sub
    assert (out / "all.txt").read_text().split() == [r["id"] for r in _index(out) if r["split"]]
    assert (out / "notes.md").read_text() == "mine"
    rows = np.concatenate([np.load(f) for f in sorted((out / "new_joint_vecs").glob("*.npy"))]).astype(np.float64)
    assert np.allclose(np.load(out / "Mean.npy"), rows.mean(0), rtol=1e-5, atol=1e-6)


def test_the_summary_says_why_results_are_in_no_split_and_in_no_list(spliced, tmp_path):
    result = export_clips(spliced, ["walk_straight+wave"], out=tmp_path / "one", format="humanml3d",
                          split_ratios=(0.5, 0.0, 0.5), split_seed=1)
    rows = _index(tmp_path / "one")
    if rows[0]["split"]:  # this seed put both sources in one split: another does not
        result = export_clips(spliced, ["walk_straight+wave"], out=tmp_path / "two", format="humanml3d",
                              split_ratios=(0.5, 0.0, 0.5), split_seed=2)
        rows = _index(tmp_path / "two")
    assert rows[0]["split"] == "" and (result.output / "all.txt").read_text() == ""
    assert "1 in no split, so in no list, all.txt included" in result.summary
    assert "split_ratios 1,0,0 puts every result in train" in result.summary and "--" not in result.summary
    from torchsplice.cli.common import flag  # the command line says the option as its flag
    from torchsplice.core.errors import render_message

    said = render_message(result.summary_text, result.summary_options, flag)
    assert "--split-ratios 1,0,0 puts every result in train" in said


def test_export_mirror_does_not_mirror_the_mirrors_of_a_mirrored_database(sample_db, tmp_path):
    """A database made by ``torchsplice mirror`` holds originals and their images: --mirror makes
    a copy only of a clip that is not an image and whose image is not exported too."""
    from torchsplice.retarget.mirror import mirror_clips
    from torchsplice.store.database import MotionDatabase

    mirrored = tmp_path / "m.h5"
    mirror_clips(sample_db, ["walk_straight", "jog"], out=mirrored)
    with MotionDatabase.open(mirrored) as db:
        names = list(db.names)
    assert sorted(names) == ["jog", "jog.mirror", "walk_straight", "walk_straight.mirror"]
    result = export_clips(mirrored, out=tmp_path / "h", format="humanml3d", mirror=True)
    assert not [r for r in _index(tmp_path / "h") if r["mirrored"] == "1"]  # every clip is or has an image
    assert "4 clips not mirrored again" in result.summary
    # only the originals exported: their images are not, so they are mirrored
    export_clips(mirrored, ["walk_straight", "jog"], out=tmp_path / "o", format="humanml3d", mirror=True)
    assert sorted(r["clip"] for r in _index(tmp_path / "o") if r["mirrored"] == "1") == ["jog", "walk_straight"]


def test_user_captions_with_inflected_verbs_are_refused_and_unknown_keys_are_reported(spliced, tmp_path):
    """``waves/VERB`` became "wavesing": a verb that reads as inflected is one line; a key naming
    no clip is said in the summary, not silently unused; the shipped example reads."""
    from torchsplice.formats.captions import read_captions

    bad = tmp_path / "bad.json"
    for word in ("waves", "waved", "waving"):
        bad.write_text(json.dumps({"wave": [f"a/DET person/NOUN {word}/VERB"]}))
        line = _refusal(lambda: export_clips(spliced, out=tmp_path / "x", format="humanml3d", captions=bad))
        assert f"verb {word!r} reads as inflected" in line and "waves=wave/VERB" in line and not (tmp_path / "x").exists()
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"walk_straight": ["a/DET person/NOUN strolls=stroll/VERB"], "nope": ["a/DET man/NOUN"]}))
    result = export_clips(spliced, out=tmp_path / "h", format="humanml3d", captions=good)
    assert "captions for 1 clip the database does not hold, not used: 'nope'" in result.summary
    texts = " ".join(p.read_text() for p in (tmp_path / "h" / "texts").glob("*.txt"))
    assert "strolls" in texts and "strollsing" not in texts
    assert read_captions(Path(__file__).resolve().parents[2] / "datasets_spec" / "captions_example.json")
