"""BVH reading and writing: real files from every source, dialects, malformed input, the CLI.

Real files come from ``../shared/mocap`` (see ``conftest.py``); each folder's README.md tables
every clip's frame count and fps, which the reader must reproduce. Small hand-made BVH strings
cover the dialects and every kind of malformed input.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from conftest import bvh_params
from torchsplice.core.errors import BVHError, MotionError
from torchsplice.core.motion import Motion
from torchsplice.core.skeleton import Skeleton
from torchsplice.io.bvh import format_bvh, parse_bvh, read_bvh, write_bvh

# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------
SOURCES = {  # folder: (joints, fps, every joint has position channels)
    "bandai_namco_research_motiondataset": (22, 30.0, True),
    "cmu_graphics_lab": (31, 120.0, False),
    "lafan1_via_pypi_bvhtools": (22, 30.0, False),
}

# A handful of frame counts copied by hand from the READMEs' tables.
README_FRAMES = {
    "dataset-2_walk_normal_008.bvh": 255,
    "dataset-2_raise-up-both-hands_normal_001.bvh": 51,
    "dataset-1_dash_normal_001.bvh": 20,
    "dataset-1_kick_normal_001.bvh": 358,
    "cmu_12_01_walk.bvh": 524,
    "131_01.bvh": 994,
    "131_02.bvh": 1247,
    "test.bvh": 7184,
    "test2.bvh": 3945,
}

_readme_cache: dict[Path, dict[str, tuple[int, int]]] = {}


def readme_table(folder: Path) -> dict[str, tuple[int, int]]:
    """file name -> (frames, fps) from the ``| file | frames | fps | ...`` table of a README."""
    if folder not in _readme_cache:
        rows = {}
        for line in (folder / "README.md").read_text(encoding="utf-8").splitlines():
            m = re.match(r"\|\s*([^|]+?\.bvh)\s*\|\s*(\d+)\s*\|\s*(\d+)\s*\|", line)
            if m:
                rows[m.group(1)] = (int(m.group(2)), int(m.group(3)))
        _readme_cache[folder] = rows
    return _readme_cache[folder]


def axis_matrix(axis: str, degrees: float) -> np.ndarray:
    """Rotation matrix about one axis (column vectors, right-handed)."""
    t = math.radians(degrees)
    c, s = math.cos(t), math.sin(t)
    if axis == "X":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "Y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def euler_matrix(order: str, angles) -> np.ndarray:
    """R = R_a(a0) R_b(a1) R_c(a2) for an order 'abc'."""
    return axis_matrix(order[0], angles[0]) @ axis_matrix(order[1], angles[1]) @ axis_matrix(order[2], angles[2])


def quat_matrix(q) -> np.ndarray:
    """Rotation matrix of a unit WXYZ quaternion (written here, independent of the library)."""
    w, x, y, z = (float(v) for v in q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def same_skeleton(a: Skeleton, b: Skeleton, atol: float = 1e-6) -> None:
    assert a.names == b.names
    assert a.parents == b.parents
    assert a.channels == b.channels
    torch.testing.assert_close(a.offsets, b.offsets, rtol=0, atol=atol)
    assert a.end_site_parents == b.end_site_parents
    torch.testing.assert_close(a.end_site_offsets, b.end_site_offsets, rtol=0, atol=atol)


def write(tmp_path: Path, text: str, name: str = "clip.bvh", newline: str = "\n") -> Path:
    p = tmp_path / name
    p.write_bytes(text.replace("\n", newline).encode("utf-8"))
    return p


# A small valid file; line numbers below refer to it (1-based).
BASE = """\
HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0333333
0 0 0 0 0 0 0 0 0
1 2 3 10 20 30 5 6 7
2 4 6 20 40 60 10 12 14
"""
BASE_LINES = BASE.splitlines()
LINE = {  # 1-based line numbers in BASE
    "spine_offset": 8, "spine_channels": 9, "end_site_close": 13, "spine_close": 14,
    "root_close": 15, "motion": 16, "frames": 17, "frame_time": 18, "f0": 19, "f1": 20, "f2": 21,
}


def base_with(replace: dict[int, str] | None = None, drop: set[int] = frozenset()) -> str:
    lines = []
    for i, l in enumerate(BASE_LINES, start=1):
        if i in drop:
            continue
        lines.append((replace or {}).get(i, l))
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# real files
# --------------------------------------------------------------------------------------------
@pytest.mark.realdata
@pytest.mark.parametrize("path", bvh_params())
def test_real_file_matches_readme(path, mocap_dir):
    joints, fps, all_positions = SOURCES[path.parent.name]
    m = read_bvh(path)
    frames, readme_fps = readme_table(path.parent)[path.name]
    assert m.skeleton.num_joints == joints
    assert m.num_frames == frames
    assert m.fps == fps == readme_fps
    if path.name in README_FRAMES:
        assert m.num_frames == README_FRAMES[path.name]
    assert m.name == path.stem and m.source == str(path)
    if all_positions:
        for name, ch in zip(m.skeleton.names, m.skeleton.channels):
            assert {"Xposition", "Yposition", "Zposition"} <= set(ch), name
        assert m.translations is not None
        assert m.skeleton.has_joint_translations
    else:
        assert m.translations is None
        assert not m.skeleton.has_joint_translations
    assert m.rotations.dtype == torch.float32
    norms = m.rotations.double().norm(dim=-1)
    torch.testing.assert_close(norms, torch.ones_like(norms), rtol=0, atol=1e-5)
    assert torch.isfinite(m.root_translation).all()


def test_readme_handful_is_in_tables(mocap_dir):
    """The hand-copied frame counts agree with the parsed README tables (guards the parser)."""
    tables = {}
    for folder in SOURCES:
        tables.update(readme_table(mocap_dir / folder))
    for name, frames in README_FRAMES.items():
        assert tables[name][0] == frames


def test_every_real_file_is_covered(mocap_dir):
    for folder in SOURCES:
        files = {p.name for p in (mocap_dir / folder).glob("*.bvh")}
        assert files and files == set(readme_table(mocap_dir / folder))


@pytest.mark.realdata
@pytest.mark.parametrize("path", bvh_params())
def test_real_file_round_trip(path, mocap_dir, tmp_path):
    m = read_bvh(path, dtype=torch.float64)
    assert m.rotations.dtype == torch.float64
    assert m.root_translation.dtype == torch.float64
    if m.translations is not None:
        assert m.translations.dtype == torch.float64
    out = tmp_path / path.name
    write_bvh(m, out)
    assert not [p for p in tmp_path.iterdir() if p != out]  # no temporary left beside it
    m2 = read_bvh(out, dtype=torch.float64)
    same_skeleton(m.skeleton, m2.skeleton)
    assert m2.num_frames == m.num_frames and m2.fps == m.fps
    p1, p2 = m.global_positions(), m2.global_positions()
    err = (p1 - p2).abs().max().item()
    assert err <= 1e-4 * m.skeleton.size(), f"round trip moved a joint by {err}"


# --------------------------------------------------------------------------------------------
# dialects
# --------------------------------------------------------------------------------------------
def _assert_same_motion(a: Motion, b: Motion) -> None:
    same_skeleton(a.skeleton, b.skeleton, atol=0)
    assert torch.equal(a.rotations, b.rotations)
    assert torch.equal(a.root_translation, b.root_translation)
    assert (a.translations is None) == (b.translations is None)
    if a.translations is not None:
        assert torch.equal(a.translations, b.translations)
    assert a.fps == b.fps and a.num_frames == b.num_frames


def test_line_ends_and_whitespace_do_not_matter(tmp_path):
    ref = read_bvh(write(tmp_path, BASE, "lf.bvh"), dtype=torch.float64)
    crlf = read_bvh(write(tmp_path, BASE, "crlf.bvh", newline="\r\n"), dtype=torch.float64)
    def rejoin(line: str, sep: str) -> str:
        # "Frame Time:" is one key: keep its inner space, vary the whitespace everywhere else
        return sep.join(line.replace("Frame Time:", "Frame\0Time:").split()).replace("\0", " ")

    tabs_text = "\n".join(re.match(r" *", l).group(0).replace(" ", "\t") + rejoin(l, "\t") for l in BASE_LINES) + "\n"
    tabs = read_bvh(write(tmp_path, tabs_text, "tabs.bvh"), dtype=torch.float64)
    spaces_text = "\n".join("   " + rejoin(l, "    ") + "  " for l in BASE_LINES) + "\n"
    spaces = read_bvh(write(tmp_path, spaces_text, "spaces.bvh"), dtype=torch.float64)
    mixed = read_bvh(write(tmp_path, tabs_text.replace("\n", "\r\n", 7), "mixed.bvh"), dtype=torch.float64)
    assert "\t" in tabs_text and "\r\n" in (tmp_path / "crlf.bvh").read_bytes().decode()
    for other in (crlf, tabs, spaces, mixed):
        _assert_same_motion(ref, other)
    # and the values are the ones in the file
    assert ref.root_translation[1].tolist() == [1.0, 2.0, 3.0]


ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


def _chain_bvh(orders, offsets, frames, root_pos_channels=True, frame_time="0.0333333") -> str:
    """A chain of joints J0 <- J1 <- ... with the given per-joint Euler orders."""
    lines = ["HIERARCHY"]
    for j, (order, off) in enumerate(zip(orders, offsets)):
        ind = "  " * j
        lines.append(f"{ind}{'ROOT' if j == 0 else 'JOINT'} J{j}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}  OFFSET {off[0]} {off[1]} {off[2]}")
        ch = [f"{a}rotation" for a in order]
        if j == 0 and root_pos_channels:
            ch = ["Xposition", "Yposition", "Zposition"] + ch
        lines.append(f"{ind}  CHANNELS {len(ch)} " + " ".join(ch))
    ind = "  " * len(orders)
    lines += [f"{ind}End Site", f"{ind}{{", f"{ind}  OFFSET 0 1 0", f"{ind}}}"]
    for j in range(len(orders) - 1, -1, -1):
        lines.append("  " * j + "}")
    lines += ["MOTION", f"Frames: {len(frames)}", f"Frame Time: {frame_time}"]
    lines += [" ".join(repr(float(v)) for v in f) for f in frames]
    return "\n".join(lines) + "\n"


def test_all_six_euler_orders_mixed_in_one_file():
    offsets = [(1.0, 2.0, 3.0), (0.0, 10.0, 0.0), (5.0, 0.0, 0.0), (0.0, 0.0, 7.0), (3.0, 4.0, 0.0), (0.0, -6.0, 2.0)]
    rng = np.random.default_rng(0)
    angles = [rng.uniform(-170, 170, size=(len(ORDERS), 3)) for _ in range(4)]
    angles[0][:] = [[30.0, 45.0, 60.0]] * len(ORDERS)  # a frame of round numbers too
    root = [np.array([1.5, -2.0, 0.25]) * (t + 1) for t in range(4)]
    frames = [np.concatenate([root[t], angles[t].reshape(-1)]) for t in range(4)]
    m = parse_bvh(_chain_bvh(ORDERS, offsets, frames), dtype=torch.float64)
    assert m.skeleton.channels[0][:3] == ("Xposition", "Yposition", "Zposition")
    for j, order in enumerate(ORDERS):
        assert m.skeleton.rotation_order(j) == order
    pos = m.global_positions()
    for t in range(4):
        R_global = np.eye(3)
        p = root[t]
        for j, order in enumerate(ORDERS):
            R_local = euler_matrix(order, angles[t][j])
            np.testing.assert_allclose(quat_matrix(m.rotations[t, j]), R_local, atol=1e-10, err_msg=f"{order} t={t}")
            if j > 0:
                p = p + R_global @ np.array(offsets[j])
            np.testing.assert_allclose(pos[t, j].numpy(), p, atol=1e-9)
            R_global = R_global @ R_local


def test_single_axis_rotation_sense():
    """Zrotation 90 turns +X into +Y (right-handed, column vectors)."""
    m = parse_bvh(_chain_bvh(["ZXY", "ZXY"], [(0, 0, 0), (1, 0, 0)], [[0, 0, 0, 90, 0, 0, 0, 0, 0]]), dtype=torch.float64)
    np.testing.assert_allclose(m.global_positions()[0, 1].numpy(), [0.0, 1.0, 0.0], atol=1e-12)


def test_position_channels_on_a_non_root_joint_are_honoured():
    text = """HIERARCHY
ROOT Root
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Mid
  {
    OFFSET 0 10 0
    CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
    JOINT Tip
    {
      OFFSET 0 5 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 1 0
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
1 2 3 0 0 0 0 10 0 0 0 0 0 0 0
1 2 3 0 0 0 4 25 -6 0 0 0 0 0 0
"""
    m = parse_bvh(text, dtype=torch.float64)
    assert m.translations is not None
    assert m.skeleton.has_joint_translations
    pos = m.global_positions()
    np.testing.assert_allclose(pos[0, 1].numpy(), [1, 12, 3])
    np.testing.assert_allclose(pos[1, 1].numpy(), [5, 27, -3])  # moved with its channels
    np.testing.assert_allclose(pos[1, 2].numpy(), [5, 32, -3])
    np.testing.assert_allclose(m.translations[1, 1].numpy(), [4, 25, -6])
    np.testing.assert_allclose(m.translations[1, 2].numpy(), [0, 5, 0])  # not animated: its offset


def test_position_channels_in_unusual_order():
    text = """HIERARCHY
ROOT Root
{
  OFFSET 0 0 0
  CHANNELS 6 Yrotation Zposition Xposition Zrotation Yposition Xrotation
  End Site
  {
    OFFSET 0 1 0
  }
}
MOTION
Frames: 1
Frame Time: 0.0333333
30 3 1 40 2 50
"""
    m = parse_bvh(text, dtype=torch.float64)
    np.testing.assert_allclose(m.root_translation[0].numpy(), [1, 2, 3])
    assert m.skeleton.rotation_order(0) == "YZX"
    np.testing.assert_allclose(quat_matrix(m.rotations[0, 0]), euler_matrix("YZX", (30, 40, 50)), atol=1e-12)

    text2 = """HIERARCHY
ROOT Root
{
  OFFSET 0 0 0
  CHANNELS 6 Zposition Xposition Yposition Zrotation Xrotation Yrotation
  JOINT Child
  {
    OFFSET 0 1 0
    CHANNELS 3 Zposition Xposition Yposition
  }
}
MOTION
Frames: 1
Frame Time: 0.0333333
3 1 2 0 0 0 30 10 20
"""
    m = parse_bvh(text2, dtype=torch.float64)
    np.testing.assert_allclose(m.root_translation[0].numpy(), [1, 2, 3])
    np.testing.assert_allclose(m.translations[0, 1].numpy(), [10, 20, 30])
    np.testing.assert_allclose(m.global_positions()[0, 1].numpy(), [11, 22, 33])


SCALED = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 9 Xposition Yposition Zposition Zrotation Xrotation Yrotation Xscale Yscale Zscale
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 0 0 0 0 0 1 1 1 0 0 0
1 2 3 10 20 30 1.000000 1 1 5 6 7
"""


def test_unit_scale_channels_read_fine():
    m = parse_bvh(SCALED, dtype=torch.float64)
    assert m.skeleton.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    ref = parse_bvh(base_with(drop={LINE["f2"]}).replace("Frames: 3", "Frames: 2"), dtype=torch.float64)
    torch.testing.assert_close(m.rotations, ref.rotations)
    torch.testing.assert_close(m.root_translation, ref.root_translation)


def test_non_unit_scale_raises(tmp_path):
    bad = SCALED.replace("1.000000 1 1", "1 2 1")
    p = write(tmp_path, bad, "scaled.bvh")
    with pytest.raises(BVHError) as ei:
        read_bvh(p)
    msg = str(ei.value)
    assert "scaled.bvh" in msg and "Yscale" in msg and "Hips" in msg


def test_end_sites_are_kept():
    text = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Left Leg
  {
    OFFSET 1 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -4 0.5
    }
  }
  JOINT Right Leg
  {
    OFFSET -1 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -4 -0.5
    }
  }
  End Site
  {
    OFFSET 0 3 0
  }
}
MOTION
Frames: 1
Frame Time: 0.0333333
0 0 0 0 0 0 0 0 0 0 0 0
"""
    sk = parse_bvh(text).skeleton
    assert sk.names == ("Hips", "Left Leg", "Right Leg")
    assert sk.end_site_parents == (1, 2, 0)
    torch.testing.assert_close(sk.end_site_offsets, torch.tensor([[0, -4, 0.5], [0, -4, -0.5], [0, 3, 0]], dtype=torch.float64))


def test_frame_time_reads_as_integer_fps():
    assert parse_bvh(base_with({LINE["frame_time"]: "Frame Time: 0.0083333"})).fps == 120.0
    assert parse_bvh(base_with({LINE["frame_time"]: "Frame Time: .0083333"})).fps == 120.0
    assert parse_bvh(base_with({LINE["frame_time"]: "Frame Time: 0.033333"})).fps == 30.0
    assert parse_bvh(base_with({LINE["frame_time"]: "Frame Time: 0.0166667"})).fps == 60.0
    assert parse_bvh(base_with({LINE["frame_time"]: "Frame Time: 0.04"})).fps == 25.0
    odd = parse_bvh(base_with({LINE["frame_time"]: "Frame Time: 0.03"})).fps
    assert odd == pytest.approx(100 / 3)


def test_joint_names_with_spaces():
    text = BASE.replace("ROOT Hips", "ROOT My Hips").replace("JOINT Spine", "JOINT Lower  Spine\t01")
    m = parse_bvh(text)
    assert m.skeleton.names == ("My Hips", "Lower Spine 01")
    assert m.skeleton.index("Lower Spine 01") == 1


def test_float64_on_request_and_float32_by_default():
    m32 = parse_bvh(BASE)
    m64 = parse_bvh(BASE, dtype=torch.float64)
    assert m32.rotations.dtype == m32.root_translation.dtype == torch.float32
    assert m64.rotations.dtype == m64.root_translation.dtype == torch.float64
    assert m64.skeleton.offsets.dtype == torch.float64
    torch.testing.assert_close(m32.rotations.double(), m64.rotations, rtol=0, atol=1e-7)


# --------------------------------------------------------------------------------------------
# malformed input
# --------------------------------------------------------------------------------------------
def _bvh_error(tmp_path, text, name="bad.bvh") -> BVHError:
    p = write(tmp_path, text, name)
    with pytest.raises(BVHError) as ei:
        read_bvh(p)
    err = ei.value
    msg = str(err)
    assert str(p) in msg, msg
    assert "\n" not in msg
    assert "Traceback" not in msg
    return err


def _check(err: BVHError, line: int | tuple[int, ...] | None, *phrases: str) -> None:
    msg = str(err).lower()
    for ph in phrases:
        assert ph.lower() in msg, f"{ph!r} not in {str(err)!r}"
    if line is not None:
        lines = line if isinstance(line, tuple) else (line,)
        assert err.line in lines, f"line {err.line}, expected {lines}: {err}"
        assert f":{err.line}:" in str(err)


def test_error_wrong_value_count_in_a_frame(tmp_path):
    err = _bvh_error(tmp_path, base_with({LINE["f1"]: "1 2 3 10 20 30 5 6"}))
    _check(err, LINE["f1"], "expected 9 values", "found 8")
    err = _bvh_error(tmp_path, base_with({LINE["f0"]: "0 0 0 0 0 0 0 0 0 0"}), "extra.bvh")
    _check(err, LINE["f0"], "expected 9 values", "found 10")


def test_error_missing_motion(tmp_path):
    err = _bvh_error(tmp_path, "\n".join(BASE_LINES[: LINE["root_close"]]) + "\n")
    _check(err, None, "missing MOTION")


def test_error_missing_hierarchy(tmp_path):
    err = _bvh_error(tmp_path, base_with(drop={1}))
    _check(err, 1, "missing HIERARCHY")


def test_error_bad_channel_name(tmp_path):
    err = _bvh_error(tmp_path, base_with({LINE["spine_channels"]: "    CHANNELS 3 Zrotation Xrotaton Yrotation"}))
    _check(err, LINE["spine_channels"], "bad channel name", "Xrotaton")


def test_error_non_numeric_value(tmp_path):
    err = _bvh_error(tmp_path, base_with({LINE["f2"]: "2 4 6 20 40 sixty 10 12 14"}))
    _check(err, LINE["f2"], "non-numeric", "sixty")


@pytest.mark.parametrize("token", ["nan", "NaN", "inf", "-inf"])
def test_error_nan_value(tmp_path, token):
    err = _bvh_error(tmp_path, base_with({LINE["f1"]: f"1 2 3 10 {token} 30 5 6 7"}))
    _check(err, LINE["f1"], token.lower().lstrip("-"), "frame 1")


def test_error_truncated_file_last_frame_cut(tmp_path):
    # cut in the middle of the last line
    err = _bvh_error(tmp_path, "\n".join(BASE_LINES[:-1] + ["2 4 6 20 4"]))
    _check(err, LINE["f2"], "expected 9 values", "truncated")
    # the last line missing altogether
    err = _bvh_error(tmp_path, base_with(drop={LINE["f2"]}), "short.bvh")
    _check(err, (LINE["f1"], LINE["f2"]), "truncated", "3 frames", "found 2")


def test_error_zero_frames(tmp_path):
    err = _bvh_error(tmp_path, base_with({LINE["frames"]: "Frames: 0"}, drop={LINE["f0"], LINE["f1"], LINE["f2"]}))
    _check(err, LINE["frames"], "zero frames")


def test_error_non_numeric_offset(tmp_path):
    err = _bvh_error(tmp_path, base_with({LINE["spine_offset"]: "    OFFSET 0 ten 0"}))
    _check(err, LINE["spine_offset"], "non-numeric OFFSET", "ten")


def test_error_unexpected_end_of_hierarchy(tmp_path):
    # the closing braces of Spine and Hips are missing: the hierarchy stops at the End Site's "}"
    err = _bvh_error(tmp_path, base_with(drop={LINE["spine_close"], LINE["root_close"]}))
    # the last line of the hierarchy or the MOTION line after it
    _check(err, (LINE["end_site_close"], LINE["end_site_close"] + 1), "unexpected end of hierarchy")


def test_error_non_numeric_frame_count_and_frame_time(tmp_path):
    err = _bvh_error(tmp_path, base_with({LINE["frames"]: "Frames: many"}))
    _check(err, LINE["frames"], "frame count")
    err = _bvh_error(tmp_path, base_with({LINE["frame_time"]: "Frame Time: 0"}), "ft.bvh")
    _check(err, LINE["frame_time"], "frame time")


def test_error_missing_file(tmp_path):
    with pytest.raises(BVHError, match="nope.bvh"):
        read_bvh(tmp_path / "nope.bvh")


# --------------------------------------------------------------------------------------------
# the command line on malformed files
# --------------------------------------------------------------------------------------------
def _stderr_lines(capsys) -> tuple[str, list[str]]:
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "Traceback" not in cap.out
    return cap.out, [l for l in cap.err.splitlines() if l.strip()]


def test_cli_import_only_bad_files(tmp_path, capsys):
    from torchsplice.cli import main

    bad1 = write(tmp_path, base_with({LINE["f1"]: "1 2 3 10 20 30 5 6"}), "bad_count.bvh")
    bad2 = write(tmp_path, base_with(drop={1}), "bad_header.bvh")
    out = tmp_path / "db" / "out.h5"
    out.parent.mkdir()
    code = main(["import", str(bad1), str(bad2), "-o", str(out), "-q"])
    assert code != 0
    _, err = _stderr_lines(capsys)
    for bad, phrase in ((bad1, "expected 9 values"), (bad2, "missing HIERARCHY")):
        naming = [l for l in err if bad.name in l]
        assert len(naming) == 1, err
        assert phrase in naming[0] and str(bad) in naming[0]
    assert not out.exists()
    assert list(out.parent.iterdir()) == []  # no partial file either


def test_cli_import_single_bad_file_no_traceback(tmp_path, capsys):
    from torchsplice.cli import main

    bad = write(tmp_path, base_with({LINE["spine_offset"]: "    OFFSET 0 ten 0"}), "bad.bvh")
    out = tmp_path / "out.h5"
    code = main(["import", str(bad), "-o", str(out)])
    assert code != 0
    _, err = _stderr_lines(capsys)
    naming = [l for l in err if "bad.bvh" in l]
    assert len(naming) == 1 and "non-numeric OFFSET" in naming[0]
    assert not out.exists()


def test_cli_import_one_good_one_bad(tmp_path, capsys, mocap_dir):
    from torchsplice.cli import main
    from torchsplice.io.database import MotionDatabase

    good = mocap_dir / "bandai_namco_research_motiondataset" / "dataset-1_dash_normal_001.bvh"
    bad = write(tmp_path, base_with({LINE["f2"]: "2 4 6 20 40 sixty 10 12 14"}), "bad.bvh")
    out = tmp_path / "out.h5"
    code = main(["import", str(good), str(bad), "-o", str(out), "-q"])
    assert code == 1
    _, err = _stderr_lines(capsys)
    naming = [l for l in err if "bad.bvh" in l]
    assert len(naming) == 1 and "non-numeric" in naming[0]
    assert not any(good.name in l for l in err)
    with MotionDatabase.open(out) as db:
        assert db.names == [good.stem]
        assert db.read(good.stem).num_frames == 20


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------
def _skeleton_no_rot_channels() -> Skeleton:
    return Skeleton(
        names=["Root", "Fixed", "Tip"], parents=[-1, 0, 1],
        offsets=[[0, 0, 0], [0, 1, 0], [0, 1, 0]],
        channels=[["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"], [],
                  ["Zrotation", "Xrotation", "Yrotation"]],
        end_site_parents=[2], end_site_offsets=[[0, 0.5, 0]],
    )


def test_writer_refuses_rotation_without_channels(tmp_path):
    sk = _skeleton_no_rot_channels()
    T = 4
    rot = torch.zeros(T, 3, 4, dtype=torch.float64)
    rot[..., 0] = 1.0
    ok = Motion(sk, rot.clone(), torch.zeros(T, 3, dtype=torch.float64), 30.0, name="ok")
    text = format_bvh(ok)  # identity on the channel-less joint: fine
    again = parse_bvh(text, dtype=torch.float64)
    same_skeleton(sk, again.skeleton)
    rot[2, 1] = torch.tensor([math.cos(0.2), math.sin(0.2), 0.0, 0.0])
    bad = Motion(sk, rot, torch.zeros(T, 3, dtype=torch.float64), 30.0, name="rotating")
    with pytest.raises(MotionError, match="Fixed"):
        format_bvh(bad)
    out = tmp_path / "x.bvh"
    with pytest.raises(MotionError):
        write_bvh(bad, out)
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_writer_refuses_translation_without_channels():
    sk = _skeleton_no_rot_channels()
    T = 2
    rot = torch.zeros(T, 3, 4, dtype=torch.float64)
    rot[..., 0] = 1.0
    trans = sk.offsets.expand(T, 3, 3).clone()
    trans[1, 2, 0] += 0.5  # Tip has no position channels
    m = Motion(sk, rot, torch.zeros(T, 3, dtype=torch.float64), 30.0, translations=trans, name="sliding")
    with pytest.raises(MotionError, match="Tip"):
        format_bvh(m)


def test_written_hierarchy_rereads_to_same_skeleton(tmp_path):
    text = """HIERARCHY
ROOT My Root
{
  OFFSET 0.5 90.25 -1
  CHANNELS 6 Zposition Xposition Yposition Yrotation Xrotation Zrotation
  JOINT Spine A
  {
    OFFSET 0 10.125 0
    CHANNELS 6 Xposition Yposition Zposition XYZ_PLACEHOLDER
    JOINT Head
    {
      OFFSET 0 8 1
      CHANNELS 3 Xrotation Zrotation Yrotation
      End Site
      {
        OFFSET 0 3 0
      }
    }
    JOINT Arm
    {
      OFFSET 4 0 0
      End Site
      {
        OFFSET 2 0 0
      }
    }
  }
  JOINT Leg
  {
    OFFSET 0 -9 0
    CHANNELS 3 Yrotation Zrotation Xrotation
    End Site
    {
      OFFSET 0 -40 0.123456
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0083333
""".replace("XYZ_PLACEHOLDER", "Xrotation Yrotation Zrotation")
    rng = np.random.default_rng(3)
    frames = rng.uniform(-80, 80, size=(3, 6 + 6 + 3 + 3))
    text += "\n".join(" ".join(f"{v:.6f}" for v in f) for f in frames) + "\n"
    m = parse_bvh(text, dtype=torch.float64, name="synthetic")
    out = tmp_path / "synthetic.bvh"
    write_bvh(m, out)
    m2 = read_bvh(out, dtype=torch.float64)
    same_skeleton(m.skeleton, m2.skeleton)
    assert m2.skeleton.names == ("My Root", "Spine A", "Head", "Arm", "Leg")
    assert m2.fps == 120.0
    torch.testing.assert_close(m2.global_positions(), m.global_positions(), rtol=0, atol=1e-4)
    # raw channel values come back as written (no Euler ambiguity within +-80 degrees)
    np.testing.assert_allclose(
        np.loadtxt(out.read_text().split("Frame Time:")[1].splitlines()[1:]), frames, atol=2e-6)


def test_written_hierarchy_keeps_end_site_order(tmp_path):
    """An End Site written before a child JOINT keeps its index on re-reading."""
    text = """HIERARCHY
ROOT Root
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  End Site
  {
    OFFSET 0 -1 0
  }
  JOINT Child
  {
    OFFSET 0 1 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 2 0
    }
  }
}
MOTION
Frames: 1
Frame Time: 0.0333333
0 0 0 10 20 30 40 50 60
"""
    m = parse_bvh(text, dtype=torch.float64)
    assert m.skeleton.end_site_parents == (0, 1)
    m2 = parse_bvh(format_bvh(m), dtype=torch.float64)
    same_skeleton(m.skeleton, m2.skeleton)


def test_written_hierarchy_of_a_breadth_first_skeleton(tmp_path):
    """A valid Skeleton whose joints are topologically but not depth-first ordered."""
    sk = Skeleton(
        names=["Root", "A", "B", "A1", "B1"], parents=[-1, 0, 0, 1, 2],
        offsets=[[0, 0, 0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]],
        channels=[["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"]]
        + [["Zrotation", "Xrotation", "Yrotation"]] * 4,
        end_site_parents=[3, 4], end_site_offsets=[[0, 1, 0], [0, -1, 0]],
    )
    T = 2
    g = torch.Generator().manual_seed(0)
    rot = torch.nn.functional.normalize(torch.randn(T, 5, 4, generator=g, dtype=torch.float64), dim=-1)
    m = Motion(sk, rot, torch.randn(T, 3, generator=g, dtype=torch.float64), 30.0, name="bfs")
    out = tmp_path / "bfs.bvh"
    # BVH nesting cannot keep this joint order: refuse clearly rather than reorder silently
    assert not sk.is_depth_first
    with pytest.raises(MotionError, match="depth-first"):
        write_bvh(m, out)
    assert not out.exists()
