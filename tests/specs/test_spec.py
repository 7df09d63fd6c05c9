"""Dataset specs: loading, validation, binding to real skeletons, clip metadata, guessing, detection."""

from __future__ import annotations

from dataclasses import replace

import functools
from pathlib import Path

import pytest
import torch

from realdata import real_bvh_files
from torchsplice.core.errors import SpecError
from torchsplice.core.skeleton import Skeleton
from torchsplice.specs import (
    DatasetSpec, SkeletonRoles, detect_spec, guess_spec, list_specs, load_spec,
)

SHIPPED = ("bandai_namco", "cmu", "cmu_max", "generic", "lafan1")
ROLE_KEYS = ("root", "pelvis", "hips", "knees", "feet", "shoulders")


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def real_skeleton(path: Path) -> Skeleton:
    from torchsplice.formats.bvh import read_bvh

    return read_bvh(path).skeleton


def family(path: Path) -> str:
    """The hand-written spec each real file belongs to (by its folder and, for CMU, its naming)."""
    folder = path.parent.name
    if folder.startswith("bandai_namco"):
        return "bandai_namco"
    if folder.startswith("lafan1"):
        return "lafan1"
    if folder.startswith("cmu"):
        # cmu_12_01_walk: MotionBuilder-friendly names; 131_*: 3ds Max-friendly names (CMU README)
        return "cmu" if path.name.startswith("cmu_") else "cmu_max"
    raise AssertionError(f"no spec family known for {path}")


def make_skeleton(joints: list[tuple[str, str | None]], animated: set[str] | None = None) -> Skeleton:
    """A skeleton from ``(name, parent name)`` pairs in topological order; ``animated`` joints
    (the root by default) get position channels."""
    names = [n for n, _ in joints]
    parents = [-1 if p is None else names.index(p) for _, p in joints]
    animated = animated if animated is not None else {names[0]}
    rot = ("Zrotation", "Xrotation", "Yrotation")
    channels = [(("Xposition", "Yposition", "Zposition") if n in animated else ()) + rot for n in names]
    offsets = torch.zeros(len(names), 3, dtype=torch.float64)
    offsets[1:, 1] = 1.0
    return Skeleton(names, parents, offsets, channels)


def lafan_like() -> Skeleton:
    """A LAFAN1-named skeleton (no real data needed)."""
    j = [("Hips", None)]
    for s in ("Left", "Right"):
        j += [(f"{s}UpLeg", "Hips"), (f"{s}Leg", f"{s}UpLeg"), (f"{s}Foot", f"{s}Leg"), (f"{s}Toe", f"{s}Foot")]
    j += [("Spine", "Hips"), ("Spine1", "Spine"), ("Spine2", "Spine1"), ("Neck", "Spine2"), ("Head", "Neck")]
    for s in ("Left", "Right"):
        j += [(f"{s}Shoulder", "Spine2"), (f"{s}Arm", f"{s}Shoulder"), (f"{s}ForeArm", f"{s}Arm"),
              (f"{s}Hand", f"{s}ForeArm")]
    return make_skeleton(j)


VALID = """\
[dataset]
name = "mine"
description = "a test spec"
up_axis = "y"
units = "cm"
files = ["mine_*"]

[joints]
root = "Hips"
pelvis = "Spine"
spine = ["Spine", "Spine1", "Spine2", "Neck"]
hips = ["LeftUpLeg", "RightUpLeg"]
knees = ["LeftLeg", "RightLeg"]
feet = ["LeftFoot", "RightFoot"]
toes = ["LeftToe", "RightToe"]
shoulders = ["LeftArm", "RightArm"]
hands = ["LeftHand", "RightHand"]
head = "Head"

[clips]
pattern = '^(?P<content>[a-z]+)_(?P<take>\\d+)$'
default_role = "locomotion"

[[clips.role]]
role = "action"
labels = { content = ["wave"] }
"""


def write_spec(tmp_path: Path, text: str, stem: str = "mine") -> Path:
    path = tmp_path / f"{stem}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def assert_one_line_naming(exc: SpecError, *fragments: str) -> None:
    msg = str(exc)
    assert "\n" not in msg, msg
    for f in fragments:
        assert f in msg, f"{f!r} not in: {msg}"


# --------------------------------------------------------------------------------------------
# shipped specs
# --------------------------------------------------------------------------------------------
def test_list_specs_has_the_shipped_specs():
    assert set(SHIPPED) <= set(list_specs())
    assert list_specs() == sorted(list_specs())


@pytest.mark.parametrize("name", list_specs())
def test_every_shipped_spec_loads(name):
    spec = load_spec(name)
    assert spec.name == name
    assert spec.path is not None and spec.path.is_file() and spec.path.stem == name
    assert spec.up_axis in ("x", "y", "z")
    assert DatasetSpec.from_json(spec.to_json()) == spec
    assert load_spec(spec.path) == spec  # the same file by path


def test_generic_spec_guesses():
    spec = load_spec("generic")
    assert spec.guess and spec.up_axis == "y" and spec.units == "unknown"
    sk = lafan_like()
    assert spec.bind(sk) == guess_spec(sk).bind(sk)
    resolved = spec.resolve(sk)
    assert not resolved.guess and resolved.pelvis == "Spine" and resolved.notes
    assert load_spec("lafan1").resolve(sk) is load_spec("lafan1")


def test_unknown_spec_name_lists_shipped():
    with pytest.raises(SpecError) as e:
        load_spec("bandai")
    assert_one_line_naming(e.value, "'bandai'", *SHIPPED)


def test_missing_spec_file(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(SpecError) as e:
        load_spec(path)
    assert_one_line_naming(e.value, str(path), "no such spec file")


def test_valid_file_loads(tmp_path):
    spec = load_spec(write_spec(tmp_path, VALID))
    assert spec.name == "mine" and spec.hips == ("LeftUpLeg", "RightUpLeg") and spec.head == "Head"
    assert spec.metres_per_unit == pytest.approx(0.01)
    assert spec.clip_metadata("wave_003") == ("action", {"content": "wave", "take": "003"})
    assert spec.clip_metadata("walk_001.bvh") == ("locomotion", {"content": "walk", "take": "001"})
    assert spec.clip_metadata("Not-Matching") == ("locomotion", {})


# --------------------------------------------------------------------------------------------
# malformed files
# --------------------------------------------------------------------------------------------
MALFORMED = [
    ("syntax", lambda t: t.replace("[joints]", "[joints"), "not valid TOML"),
    ("no-joints-table", lambda t: t.split("[joints]")[0], "missing table [joints]"),
    ("no-dataset-table", lambda t: t.split("[joints]", 1)[1].join(["[joints]", ""]), "missing table [dataset]"),
    ("missing-root", lambda t: t.replace('root = "Hips"\n', ""), "[joints] root: missing"),
    ("root-not-string", lambda t: t.replace('root = "Hips"', "root = 3"), "[joints] root: expected a string"),
    ("empty-pelvis", lambda t: t.replace('pelvis = "Spine"', 'pelvis = ""'), "[joints] pelvis: must not be empty"),
    ("bad-up-axis", lambda t: t.replace('up_axis = "y"', 'up_axis = "w"'), "[dataset] up_axis: 'w'"),
    ("bad-units", lambda t: t.replace('units = "cm"', 'units = "furlong"'), "[dataset] units: 'furlong'"),
    ("name-not-stem", lambda t: t.replace('name = "mine"', 'name = "yours"'), "must equal the file's stem"),
    ("pair-of-one", lambda t: t.replace('hips = ["LeftUpLeg", "RightUpLeg"]', 'hips = ["LeftUpLeg"]'),
     "[joints] hips: expected two joint names [left, right]"),
    ("pair-of-three", lambda t: t.replace('feet = ["LeftFoot", "RightFoot"]', 'feet = ["A", "B", "C"]'),
     "[joints] feet: expected two joint names"),
    ("pair-not-list", lambda t: t.replace('knees = ["LeftLeg", "RightLeg"]', 'knees = "LeftLeg"'),
     "[joints] knees: expected a list"),
    ("pair-same-joint", lambda t: t.replace('shoulders = ["LeftArm", "RightArm"]', 'shoulders = ["LeftArm", "LeftArm"]'),
     "[joints] shoulders: left and right are the same joint"),
    ("pair-not-strings", lambda t: t.replace('toes = ["LeftToe", "RightToe"]', "toes = [1, 2]"),
     "[joints] toes: expected a non-empty list of non-empty strings"),
    ("spine-not-from-pelvis", lambda t: t.replace('spine = ["Spine", ', 'spine = ['), "[joints] spine: must start at the pelvis"),
    ("typo-key", lambda t: t.replace('head = "Head"', 'haed = "Head"'), "[joints] haed: unknown key"),
    ("unknown-table", lambda t: t + "\n[extra]\nx = 1\n", "[extra]"),
    ("bad-regex", lambda t: t.replace("pattern = '^(?P<content>", "pattern = '^((?P<content>"),
     "[clips] pattern: not a valid regular expression"),
    ("bad-default-role", lambda t: t.replace('default_role = "locomotion"', 'default_role = "walk"'),
     "[clips] default_role: 'walk'"),
    ("bad-rule-role", lambda t: t.replace('role = "action"', 'role = "upper"'), "[clips.role #1] role: 'upper'"),
    ("rule-without-role", lambda t: t.replace('role = "action"\n', ""), "[clips.role #1] role: missing"),
    ("rule-matches-nothing-given", lambda t: t.replace('labels = { content = ["wave"] }', ""),
     "a rule needs names or labels"),
    ("rule-label-not-list", lambda t: t.replace('labels = { content = ["wave"] }', 'labels = { content = "wave" }'),
     "content: expected a list"),
    ("rule-names-not-list", lambda t: t.replace('labels = { content = ["wave"] }', 'names = "*wave*"'),
     "names: expected a list"),
    ("role-not-array-of-tables", lambda t: t.replace("[[clips.role]]\nrole = \"action\"\nlabels = { content = [\"wave\"] }", "role = \"action\""),
     "[clips] role: expected a list"),
    ("dataset-not-table", lambda t: 'dataset = 3\n' + t.split("\n", 6)[6].replace("[dataset]", ""), "[dataset] must be a table"),
    ("bool-as-string", lambda t: t.replace('description = "a test spec"', "description = true"),
     "[dataset] description: expected a string"),
]


@pytest.mark.parametrize("mutate, fragment", [pytest.param(m, f, id=i) for i, m, f in MALFORMED])
def test_malformed_spec_names_file_and_problem(tmp_path, mutate, fragment):
    text = mutate(VALID)
    assert text != VALID
    path = write_spec(tmp_path, text)
    with pytest.raises(SpecError) as e:
        load_spec(path)
    assert_one_line_naming(e.value, str(path), fragment)


def test_non_utf8_spec(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_bytes(b"[dataset]\nname = \"\xff\xfe\"\n")
    with pytest.raises(SpecError) as e:
        load_spec(path)
    assert_one_line_naming(e.value, str(path), "UTF-8")


def test_spec_path_is_a_directory(tmp_path):
    path = tmp_path / "dir.toml"
    path.mkdir()
    with pytest.raises(SpecError) as e:
        load_spec(path)
    assert_one_line_naming(e.value, str(path))


# --------------------------------------------------------------------------------------------
# binding (synthetic skeletons: always run)
# --------------------------------------------------------------------------------------------
def test_bind_gives_indices_and_body_split(tmp_path):
    sk = lafan_like()
    roles = load_spec(write_spec(tmp_path, VALID)).bind(sk)
    assert isinstance(roles, SkeletonRoles)
    assert roles.root == sk.index("Hips") and roles.pelvis == sk.index("Spine")
    assert roles.hips == (sk.index("LeftUpLeg"), sk.index("RightUpLeg"))
    assert roles.head == sk.index("Head") and roles.up_axis == 1 and roles.units == "cm"
    assert roles.upper_body == tuple(sk.descendants(sk.index("Spine")))
    assert set(roles.upper_body) | set(roles.lower_body) == set(range(sk.num_joints))
    assert not set(roles.upper_body) & set(roles.lower_body)
    assert list(roles.lower_body) == sorted(roles.lower_body)


def test_unknown_joint_names_joint_and_lists_available(tmp_path):
    path = write_spec(tmp_path, VALID.replace('pelvis = "Spine"', 'pelvis = "Pelvis"')
                      .replace('spine = ["Spine", ', 'spine = ["Pelvis", '))
    sk = lafan_like()
    with pytest.raises(SpecError) as e:
        load_spec(path).bind(sk)
    assert_one_line_naming(e.value, str(path), "'Pelvis'", "pelvis", "LeftUpLeg, LeftLeg", "RightHand")


def test_optional_joints_absent(tmp_path):
    text = VALID.replace('toes = ["LeftToe", "RightToe"]\n', "").replace('hands = ["LeftHand", "RightHand"]\n', "")
    roles = load_spec(write_spec(tmp_path, text.replace('head = "Head"\n', ""))).bind(lafan_like())
    assert roles.toes is None and roles.hands is None and roles.head is None


@pytest.mark.parametrize("old, new, fragment", [
    # the pelvis above the legs: the legs would be spliced with the upper body
    ('pelvis = "Spine"', 'pelvis = "Hips"', "lies below the pelvis 'Hips'"),
    # root below the pelvis
    ('root = "Hips"', 'root = "Spine1"', "root 'Spine1' must be the pelvis 'Spine' or one of its ancestors"),
    # knees and feet swapped
    ('knees = ["LeftLeg", "RightLeg"]\nfeet = ["LeftFoot", "RightFoot"]',
     'knees = ["LeftFoot", "RightFoot"]\nfeet = ["LeftLeg", "RightLeg"]', "must lie below knees"),
    # hands on the wrong arm side chain
    ('hands = ["LeftHand", "RightHand"]', 'hands = ["RightHand", "LeftHand"]', "must lie below shoulders"),
    # spine listed top-down
    ('spine = ["Spine", "Spine1", "Spine2", "Neck"]', 'spine = ["Spine", "Neck", "Spine2"]', "spine: 'Spine2' must lie below 'Neck'"),
])
def test_bind_refuses_contradictory_hierarchy(tmp_path, old, new, fragment):
    text = VALID.replace(old, new)
    if 'pelvis = "Hips"' in text:
        text = text.replace('spine = ["Spine", ', 'spine = ["Hips", "Spine", ')
    assert text != VALID
    path = write_spec(tmp_path, text)
    with pytest.raises(SpecError) as e:
        load_spec(path).bind(lafan_like())
    assert_one_line_naming(e.value, str(path), fragment)


def test_body_overrides(tmp_path):
    sk = lafan_like()
    # a lower body that also takes the first spine joint: the upper body is the rest
    lower = ["Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToe", "RightUpLeg", "RightLeg", "RightFoot", "RightToe", "Spine"]
    text = VALID.replace('head = "Head"', f'head = "Head"\nlower_body = {lower!r}'.replace("'", '"'))
    text = text.replace('pelvis = "Spine"', 'pelvis = "Spine1"').replace('spine = ["Spine", ', 'spine = [')
    roles = load_spec(write_spec(tmp_path, text)).bind(sk)
    assert roles.lower_body == tuple(sorted(sk.indices(lower)))
    assert roles.upper_body == tuple(j for j in range(sk.num_joints) if sk.names[j] not in lower)
    # overlapping overrides are refused
    bad = text.replace('head = "Head"', 'head = "Head"\nupper_body = ["Spine", "Spine1"]')
    path = write_spec(tmp_path, bad)
    with pytest.raises(SpecError) as e:
        load_spec(path).bind(sk)
    assert_one_line_naming(e.value, str(path), "in both upper_body and lower_body", "'Spine'")


# --------------------------------------------------------------------------------------------
# JSON
# --------------------------------------------------------------------------------------------
def test_json_round_trip(tmp_path):
    specs = [load_spec(n) for n in list_specs()] + [load_spec(write_spec(tmp_path, VALID)), guess_spec(lafan_like())]
    for spec in specs:
        text = spec.to_json()
        back = DatasetSpec.from_json(text)
        assert back == spec and back.to_json() == text
        assert back.notes == spec.notes and back.path == spec.path and back.rules == spec.rules
    assert specs[-1].notes  # the guess says what it guessed


def test_json_has_top_level_name():
    import json

    data = json.loads(load_spec("cmu_max").to_json())
    assert data["name"] == data["dataset"]["name"] == "cmu_max"
    data["name"] = "cmu"
    with pytest.raises(SpecError) as e:
        DatasetSpec.from_json(json.dumps(data))
    assert_one_line_naming(e.value, "spec JSON", "'cmu'", "'cmu_max'")


@pytest.mark.parametrize("text", ["not json", "[1, 2]", '{"dataset": {"name": "x"}}', '{"dataset": 1, "joints": {}}'])
def test_from_json_refuses_garbage(text):
    with pytest.raises(SpecError) as e:
        DatasetSpec.from_json(text)
    assert_one_line_naming(e.value, "spec JSON")


# --------------------------------------------------------------------------------------------
# clip metadata
# --------------------------------------------------------------------------------------------
BANDAI_CLIPS = [
    ("dataset-1_walk_normal_001", "locomotion", "1", "walk", "normal", "001"),
    ("dataset-1_walk-back_normal_001", "locomotion", "1", "walk-back", "normal", "001"),
    ("dataset-2_walk-turn-left_normal_025", "locomotion", "2", "walk-turn-left", "normal", "025"),
    ("dataset-2_run_normal_028.bvh", "locomotion", "2", "run", "normal", "028"),
    ("dataset-1_walk-back_not-confident_001", "both", "1", "walk-back", "not-confident", "001"),
    ("dataset-1_dash_chimpira_001", "both", "1", "dash", "chimpira", "001"),
    ("dataset-2_walk-turn-right_elderly_020", "both", "2", "walk-turn-right", "elderly", "020"),
    ("dataset-2_run_youthful_010", "both", "2", "run", "youthful", "010"),
    ("dataset-1_bow_normal_001", "action", "1", "bow", "normal", "001"),
    ("dataset-1_bye_normal_001", "action", "1", "bye", "normal", "001"),
    ("dataset-1_byebye_normal_001", "action", "1", "byebye", "normal", "001"),
    ("dataset-1_call_normal_002", "action", "1", "call", "normal", "002"),
    ("dataset-1_punch_normal_002", "action", "1", "punch", "normal", "002"),
    ("dataset-1_kick_normal_001", "action", "1", "kick", "normal", "001"),
    ("dataset-1_bow_happy_001", "action", "1", "bow", "happy", "001"),  # a styled gesture is still an action
    ("dataset-2_wave-left-hand_normal_001", "action", "2", "wave-left-hand", "normal", "001"),
    ("dataset-2_raise-up-both-hands_normal_001", "action", "2", "raise-up-both-hands", "normal", "001"),
]


@pytest.mark.parametrize("clip, role, dataset, content, style, take", BANDAI_CLIPS)
def test_bandai_namco_clip_metadata(clip, role, dataset, content, style, take):
    got = load_spec("bandai_namco").clip_metadata(clip)
    assert got == (role, {"dataset": dataset, "content": content, "style": style, "take": take})


@pytest.mark.parametrize("spec, clip, role, labels", [
    ("cmu", "cmu_12_01_walk", "locomotion", {"subject": "12", "trial": "01", "content": "walk"}),
    ("cmu_max", "131_01", "both", {"subject": "131", "trial": "01"}),
    ("cmu_max", "131_02.bvh", "both", {"subject": "131", "trial": "02"}),
    ("lafan1", "test", "both", {}),
    ("lafan1", "test2", "locomotion", {}),
    ("lafan1", "aiming2_subject5", "both", {"content": "aiming", "take": "2", "subject": "5"}),
    ("lafan1", "walk3_subject1", "locomotion", {"content": "walk", "take": "3", "subject": "1"}),
    ("lafan1", "fight1_subject2", "action", {"content": "fight", "take": "1", "subject": "2"}),
    ("generic", "anything", "both", {}),
])
def test_other_clip_metadata(spec, clip, role, labels):
    assert load_spec(spec).clip_metadata(clip) == (role, labels)


@pytest.mark.realdata
def test_every_real_bandai_name_is_parsed_and_ruled(mocap_dir):
    """Every real Bandai Namco file name matches the pattern and some rule (none falls to the default)."""
    spec = load_spec("bandai_namco")
    files = sorted(mocap_dir.glob("bandai_namco*/*.bvh"))
    assert files
    for f in files:
        role, labels = spec.clip_metadata(f.stem)
        assert set(labels) == {"dataset", "content", "style", "take"}, f.name
        assert any(r.matches(f.stem, labels) for r in spec.rules), f"{f.name}: no rule matched"
        in_place = labels["content"] in ("bow", "bye", "byebye", "call", "guide", "respond", "punch", "kick") \
            or labels["content"].startswith(("wave-", "raise-up-"))
        expected = "action" if in_place else ("locomotion" if labels["style"] == "normal" else "both")
        assert role == expected, f.name


# --------------------------------------------------------------------------------------------
# real skeletons
# --------------------------------------------------------------------------------------------
def check_spec_binds_real_skeleton(path, sk):
    """``sk``: the real file's skeleton, :func:`real_skeleton` (tests/formats/test_real_files.py)."""
    spec = load_spec(family(path))
    roles = spec.bind(sk)
    assert sk.names[roles.root] == spec.root and sk.names[roles.pelvis] == spec.pelvis
    assert roles.up_axis == 1
    for j in (*roles.hips, *roles.knees, *roles.feet, roles.root):
        assert j in roles.lower_body
    for j in (*roles.shoulders, *roles.hands, roles.head, *roles.spine):
        assert j in roles.upper_body
    assert sorted(roles.upper_body + roles.lower_body) == list(range(sk.num_joints))
    # the world trajectory joint is animated (Bandai Namco's BVH root joint_Root is not the root)
    assert sk.translation_animated[roles.root]


def check_guess_agrees_with_hand_written_spec(path, sk):
    """The guess matches the hand-written spec on every role on every real family: the specs pick
    no alternatives (the shoulder is the glenohumeral joint in both, e.g. CMU Max LeftShoulder,
    MotionBuilder LeftArm; CMU Max's hand is LeftWrist, the joint MotionBuilder calls LeftHand).
    ``sk``: the real file's skeleton, :func:`real_skeleton` (tests/formats/test_real_files.py)."""
    spec, guess = load_spec(family(path)), guess_spec(sk)
    for key in (*ROLE_KEYS, "spine", "toes", "hands", "head"):
        assert getattr(guess, key) == getattr(spec, key), key
    assert guess.bind(sk).upper_body == spec.bind(sk).upper_body
    assert guess.notes and guess.path is None


def check_detect_spec_picks_the_family(path, sk):
    """``sk``: the real file's skeleton, :func:`real_skeleton` (tests/formats/test_real_files.py)."""
    assert detect_spec(sk, path).name == family(path)
    assert detect_spec(sk, path.name).name == family(path)
    assert detect_spec(sk).name == family(path)  # by skeleton alone


@pytest.mark.realdata
def test_unknown_joint_on_real_skeleton(mocap_dir):
    """The Bandai Namco spec on the LAFAN1 skeleton: the first joint LAFAN1 lacks is Chest."""
    path = next(f for f in real_bvh_files() if family(f) == "lafan1")
    sk = real_skeleton(path)
    spec = load_spec("bandai_namco")
    with pytest.raises(SpecError) as e:
        spec.bind(sk)
    assert_one_line_naming(e.value, str(spec.path), "'Chest'", ", ".join(sk.names))
    assert not load_spec("cmu").binds(sk) and not load_spec("cmu_max").binds(sk)


# --------------------------------------------------------------------------------------------
# guessing on other namings (synthetic)
# --------------------------------------------------------------------------------------------
def smpl_like() -> Skeleton:
    j = [("pelvis", None), ("left_hip", "pelvis"), ("right_hip", "pelvis"), ("spine1", "pelvis"),
         ("left_knee", "left_hip"), ("right_knee", "right_hip"), ("spine2", "spine1"),
         ("left_ankle", "left_knee"), ("right_ankle", "right_knee"), ("spine3", "spine2"),
         ("left_foot", "left_ankle"), ("right_foot", "right_ankle"), ("neck", "spine3"),
         ("left_collar", "spine3"), ("right_collar", "spine3"), ("head", "neck"),
         ("left_shoulder", "left_collar"), ("right_shoulder", "right_collar"),
         ("left_elbow", "left_shoulder"), ("right_elbow", "right_shoulder"),
         ("left_wrist", "left_elbow"), ("right_wrist", "right_elbow")]
    return make_skeleton(j)


def mixamo_like() -> Skeleton:
    m = "mixamorig:"
    j = [(m + "Hips", None), (m + "Spine", m + "Hips"), (m + "Spine1", m + "Spine"), (m + "Spine2", m + "Spine1"),
         (m + "Neck", m + "Spine2"), (m + "Head", m + "Neck"), (m + "HeadTop_End", m + "Head")]
    for s in ("Left", "Right"):
        j += [(f"{m}{s}Shoulder", m + "Spine2"), (f"{m}{s}Arm", f"{m}{s}Shoulder"),
              (f"{m}{s}ForeArm", f"{m}{s}Arm"), (f"{m}{s}Hand", f"{m}{s}ForeArm"),
              (f"{m}{s}HandIndex1", f"{m}{s}Hand"), (f"{m}{s}HandThumb1", f"{m}{s}Hand")]
    for s in ("Left", "Right"):
        j += [(f"{m}{s}UpLeg", m + "Hips"), (f"{m}{s}Leg", f"{m}{s}UpLeg"), (f"{m}{s}Foot", f"{m}{s}Leg"),
              (f"{m}{s}ToeBase", f"{m}{s}Foot")]
    return make_skeleton(j)


def biped_like() -> Skeleton:
    """3ds Max Biped: the trajectory on Bip01, the thighs hanging from Bip01 Spine."""
    j = [("Bip01", None), ("Bip01 Pelvis", "Bip01"), ("Bip01 Spine", "Bip01 Pelvis"),
         ("Bip01 L Thigh", "Bip01 Spine"), ("Bip01 L Calf", "Bip01 L Thigh"), ("Bip01 L Foot", "Bip01 L Calf"),
         ("Bip01 L Toe0", "Bip01 L Foot"), ("Bip01 R Thigh", "Bip01 Spine"), ("Bip01 R Calf", "Bip01 R Thigh"),
         ("Bip01 R Foot", "Bip01 R Calf"), ("Bip01 R Toe0", "Bip01 R Foot"), ("Bip01 Spine1", "Bip01 Spine"),
         ("Bip01 Neck", "Bip01 Spine1"), ("Bip01 Head", "Bip01 Neck"),
         ("Bip01 L Clavicle", "Bip01 Neck"), ("Bip01 L UpperArm", "Bip01 L Clavicle"),
         ("Bip01 L Forearm", "Bip01 L UpperArm"), ("Bip01 L Hand", "Bip01 L Forearm"),
         ("Bip01 R Clavicle", "Bip01 Neck"), ("Bip01 R UpperArm", "Bip01 R Clavicle"),
         ("Bip01 R Forearm", "Bip01 R UpperArm"), ("Bip01 R Hand", "Bip01 R Forearm")]
    return make_skeleton(j)


def upper_names_only() -> Skeleton:
    """Knees unnamed (``shinbone``?): found below the thighs (``l_thigh``), elbows above the hands."""
    j = [("root", None), ("l_thigh", "root"), ("l_a", "l_thigh"), ("l_ankle", "l_a"),
         ("r_thigh", "root"), ("r_a", "r_thigh"), ("r_ankle", "r_a"), ("torso", "root"), ("chest", "torso"),
         ("l_clavicle", "chest"), ("l_upperarm", "l_clavicle"), ("l_b", "l_upperarm"), ("l_hand", "l_b"),
         ("r_clavicle", "chest"), ("r_upperarm", "r_clavicle"), ("r_b", "r_upperarm"), ("r_hand", "r_b")]
    return make_skeleton(j)


@pytest.mark.parametrize("make, expected", [
    (smpl_like, dict(root="pelvis", pelvis="spine1", spine=("spine1", "spine2", "spine3", "neck"),
                     hips=("left_hip", "right_hip"), knees=("left_knee", "right_knee"),
                     feet=("left_ankle", "right_ankle"), toes=("left_foot", "right_foot"),
                     shoulders=("left_shoulder", "right_shoulder"), hands=("left_wrist", "right_wrist"),
                     head="head")),
    (mixamo_like, dict(root="mixamorig:Hips", pelvis="mixamorig:Spine",
                       hips=("mixamorig:LeftUpLeg", "mixamorig:RightUpLeg"),
                       knees=("mixamorig:LeftLeg", "mixamorig:RightLeg"),
                       toes=("mixamorig:LeftToeBase", "mixamorig:RightToeBase"),
                       shoulders=("mixamorig:LeftArm", "mixamorig:RightArm"),
                       hands=("mixamorig:LeftHand", "mixamorig:RightHand"), head="mixamorig:Head")),
    # Biped: legs and arms branch at Bip01 Spine (not animated), so the root is Bip01
    (biped_like, dict(root="Bip01", pelvis="Bip01 Spine1", spine=("Bip01 Spine1", "Bip01 Neck"),
                      hips=("Bip01 L Thigh", "Bip01 R Thigh"), knees=("Bip01 L Calf", "Bip01 R Calf"),
                      feet=("Bip01 L Foot", "Bip01 R Foot"), toes=("Bip01 L Toe0", "Bip01 R Toe0"),
                      shoulders=("Bip01 L UpperArm", "Bip01 R UpperArm"), head="Bip01 Head")),
    (upper_names_only, dict(root="root", pelvis="torso", spine=("torso", "chest"), hips=("l_thigh", "r_thigh"),
                            knees=("l_a", "r_a"), feet=("l_ankle", "r_ankle"), toes=None,
                            shoulders=("l_upperarm", "r_upperarm"), hands=("l_hand", "r_hand"), head=None)),
])
def test_guess_spec_other_namings(make, expected):
    sk = make()
    spec = guess_spec(sk)
    for key, value in expected.items():
        assert getattr(spec, key) == value, key
    spec.bind(sk)
    assert spec.name == "generic" and spec.units == "unknown" and spec.notes
    if make is smpl_like:  # the shipped smpl22 spec binds, with the roles the guess found
        shipped = detect_spec(sk, "whatever.bvh")
        assert shipped.name == "smpl22" and replace(shipped.bind(sk), units="unknown") == spec.bind(sk)
    else:
        assert detect_spec(sk, "whatever.bvh") == spec  # no shipped spec binds: the guess


def test_guess_spec_without_sides_says_what_is_missing():
    j = [("Hips", None), ("UpLegA", "Hips"), ("KneeA", "UpLegA"), ("FootA", "KneeA"),
         ("UpLegB", "Hips"), ("KneeB", "UpLegB"), ("FootB", "KneeB"), ("Spine", "Hips")]
    with pytest.raises(SpecError) as e:
        guess_spec(make_skeleton(j))
    assert_one_line_naming(e.value, "no left knee found", "UpLegA, KneeA")


def test_guess_spec_without_arms():
    j = [("Hips", None), ("LeftUpLeg", "Hips"), ("LeftLeg", "LeftUpLeg"), ("LeftFoot", "LeftLeg"),
         ("RightUpLeg", "Hips"), ("RightLeg", "RightUpLeg"), ("RightFoot", "RightLeg"), ("Spine", "Hips")]
    with pytest.raises(SpecError) as e:
        load_spec("generic").bind(make_skeleton(j))
    assert_one_line_naming(e.value, "no left elbow found")


def test_detect_spec_file_glob_first(tmp_path):
    """A synthetic LAFAN1-named skeleton: detected as lafan1 by name or by skeleton alone."""
    sk = lafan_like()
    assert detect_spec(sk, "walk1_subject5.bvh").name == "lafan1"
    # the Bandai Namco glob matches but its spec does not bind: the first spec that binds is taken
    spec = detect_spec(sk, "dataset-1_walk_normal_001.bvh")
    assert spec.name == "lafan1" and spec.binds(sk)
    assert detect_spec(sk).name == "lafan1"


def test_guess_spec_without_hand_joints():
    """Elbows with two unnamed children: no hands (optional), said in the notes."""
    sk = lafan_like()
    j = [(n, sk.names[p] if p >= 0 else None) for n, p in zip(sk.names, sk.parents)]
    j += [("LeftX", "LeftForeArm"), ("RightX", "RightForeArm")]
    j = [(n.replace("Hand", "Paw"), p.replace("Hand", "Paw") if p else p) for n, p in j]
    spec = guess_spec(make_skeleton(j))
    assert spec.hands is None and spec.shoulders == ("LeftArm", "RightArm")
    assert any("no hand/wrist joints" in n for n in spec.notes)
