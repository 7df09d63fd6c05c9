"""BVH reading and writing: real files from every source, dialects, malformed input, the CLI.

Real files come from ``../shared/mocap`` (see ``conftest.py``); each folder's README.md tables
every clip's frame count and fps, which the reader must reproduce. Small hand-made BVH strings
cover the dialects and every kind of malformed input.
"""

from __future__ import annotations

import contextlib
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from torchsplice.core.errors import BVHError, MotionError
from torchsplice.core.motion import Motion
from torchsplice.core.skeleton import Skeleton
from torchsplice.formats.bvh import BVHWarning, format_bvh, parse_bvh, read_bvh, write_bvh

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
def check_real_file_matches_readme(path, m):
    """``m``: the file as :func:`read_bvh` reads it by default (tests/formats/test_real_files.py)."""
    joints, fps, all_positions = SOURCES[path.parent.name]
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


def check_real_file_round_trip(path, m, tmp_path):
    """``m``: the file read in float64 (tests/formats/test_real_files.py)."""
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
# importing malformed files: each skipped with its reason (import_bvh), one line each (the CLI)
# --------------------------------------------------------------------------------------------
def _skipped_naming(report, name: str) -> list[tuple[str, str]]:
    return [(f, why) for f, why in report.skipped if Path(f).name == name]


def test_import_of_only_bad_files_skips_each_with_its_reason_and_writes_nothing(tmp_path):
    from torchsplice.formats.importer import NothingImportedError, import_bvh

    bad1 = write(tmp_path, base_with({LINE["f1"]: "1 2 3 10 20 30 5 6"}), "bad_count.bvh")
    bad2 = write(tmp_path, base_with(drop={1}), "bad_header.bvh")
    out = tmp_path / "db" / "out.h5"
    out.parent.mkdir()
    with pytest.raises(NothingImportedError) as caught:
        import_bvh([bad1, bad2], out)
    report = caught.value.report
    for bad, phrase in ((bad1, "expected 9 values"), (bad2, "missing HIERARCHY")):
        naming = _skipped_naming(report, bad.name)
        assert len(naming) == 1, report.skipped
        assert naming[0][0] == str(bad) and phrase in naming[0][1]
    assert report.imported == []
    assert not out.exists()
    assert list(out.parent.iterdir()) == []  # no partial file either


def test_import_of_one_bad_file_skips_it_with_its_reason(tmp_path):
    from torchsplice.formats.importer import NothingImportedError, import_bvh

    bad = write(tmp_path, base_with({LINE["spine_offset"]: "    OFFSET 0 ten 0"}), "bad.bvh")
    out = tmp_path / "out.h5"
    with pytest.raises(NothingImportedError) as caught:
        import_bvh([bad], out)
    naming = _skipped_naming(caught.value.report, "bad.bvh")
    assert len(naming) == 1 and "non-numeric OFFSET" in naming[0][1]
    assert not out.exists()


def test_import_of_one_good_one_bad_file_lands_the_good_one(tmp_path, mocap_dir):
    from torchsplice.formats.importer import import_bvh
    from torchsplice.store.database import MotionDatabase

    good = mocap_dir / "bandai_namco_research_motiondataset" / "dataset-1_dash_normal_001.bvh"
    bad = write(tmp_path, base_with({LINE["f2"]: "2 4 6 20 40 sixty 10 12 14"}), "bad.bvh")
    out = tmp_path / "out.h5"
    report = import_bvh([good, bad], out)
    assert not report.ok
    naming = _skipped_naming(report, "bad.bvh")
    assert len(naming) == 1 and "non-numeric" in naming[0][1]
    assert not _skipped_naming(report, good.name)
    assert [c.name for c in report.imported] == [good.stem]
    with MotionDatabase.open(out) as db:
        assert db.names == [good.stem]
        assert db.read(good.stem).num_frames == 20


def _stderr_lines(capsys) -> tuple[str, list[str]]:
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "Traceback" not in cap.out
    return cap.out, [l for l in cap.err.splitlines() if l.strip()]


def test_cli_import_of_bad_files_says_one_line_each_naming_file_and_fault(tmp_path, capsys):
    """The command line's words for what import_bvh skips (the exit code of an import with good
    files too: tests/cli/test_cli.py)."""
    from torchsplice.cli import main

    bad1 = write(tmp_path, base_with({LINE["f1"]: "1 2 3 10 20 30 5 6"}), "bad_count.bvh")
    bad2 = write(tmp_path, base_with(drop={1}), "bad_header.bvh")
    bad3 = write(tmp_path, base_with({LINE["spine_offset"]: "    OFFSET 0 ten 0"}), "bad_offset.bvh")
    out = tmp_path / "out.h5"
    code = main(["import", str(bad1), str(bad2), str(bad3), "-o", str(out), "-q"])
    assert code != 0
    _, err = _stderr_lines(capsys)
    for bad, phrase in ((bad1, "expected 9 values"), (bad2, "missing HIERARCHY"), (bad3, "non-numeric OFFSET")):
        naming = [l for l in err if bad.name in l]
        assert len(naming) == 1, err
        assert phrase in naming[0] and str(bad) in naming[0]
    assert not out.exists()


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
    # BVH nests each subtree: the file holds the joints depth-first, the same joints by name
    assert not sk.is_depth_first and sk.depth_first_order() == [0, 1, 3, 2, 4]
    write_bvh(m, out)
    back = read_bvh(out, dtype=torch.float64)
    assert back.skeleton.names == ("Root", "A", "A1", "B", "B1") and back.skeleton.is_depth_first
    at = [back.skeleton.names.index(n) for n in sk.names]
    assert torch.allclose(back.global_positions()[:, at], m.global_positions(), atol=1e-5)
    assert torch.allclose(back.skeleton.end_site_offsets, sk.end_site_offsets)


# --------------------------------------------------------------------------------------------
# issue 10: nothing lost, no traceback
# --------------------------------------------------------------------------------------------
def _read_same_as_base(path: Path, **kw) -> Motion:
    ref = parse_bvh(BASE, dtype=torch.float64)
    m = read_bvh(path, dtype=torch.float64, **kw)
    _assert_same_motion(ref, m)
    return m


def test_utf8_byte_order_mark_is_read(tmp_path):
    p = tmp_path / "bom.bvh"
    p.write_bytes(b"\xef\xbb\xbf" + BASE.encode())
    _read_same_as_base(p)
    p.write_bytes(b"\xef\xbb\xbf" + BASE.replace("\n", "\r\n").encode())
    _read_same_as_base(p)
    _assert_same_motion(parse_bvh(BASE, dtype=torch.float64), parse_bvh("\ufeff" + BASE, dtype=torch.float64))


def test_utf16_with_byte_order_mark_is_read(tmp_path):
    p = tmp_path / "utf16.bvh"
    p.write_bytes(("\ufeff" + BASE).encode("utf-16-le"))
    _read_same_as_base(p)


@pytest.mark.parametrize("line", ["Frame\tTime: 0.0333333", "Frame  Time: 0.0333333", "Frame Time:\t0.0333333",
                                  "  frame \t time :0.0333333", "FRAME TIME:   0.0333333"])
def test_frame_time_line_tolerates_whitespace(tmp_path, line):
    _read_same_as_base(write(tmp_path, base_with({LINE["frame_time"]: line})))


@pytest.mark.parametrize("line", ["Frames:\t3", "Frames:  3", "Frames:3", "\tFrames : 3 ", "FRAMES: 03"])
def test_frames_line_tolerates_whitespace(tmp_path, line):
    _read_same_as_base(write(tmp_path, base_with({LINE["frames"]: line})))


def test_bvh_warning_is_exported():
    import torchsplice.formats.bvh as bvh

    assert "BVHWarning" in bvh.__all__ and issubclass(BVHWarning, UserWarning)
    assert "BVHWarning" in (bvh.__doc__ or "")
    w = BVHWarning("a.bvh", "something", 7)
    assert str(w) == "a.bvh:7: something" and (w.path, w.line, w.problem) == ("a.bvh", 7, "something")


def test_lines_after_the_declared_frames_are_ignored_with_one_warning(tmp_path):
    # QAvimator / Second Life: keyframe indices after the frames
    p = write(tmp_path, BASE + "1 2\n0\n\n", "qavimator.bvh")
    with pytest.warns(BVHWarning) as rec:
        _read_same_as_base(p)
    assert len(rec) == 1
    msg = str(rec[0].message)
    assert msg == f"{p}:22: 2 lines after the declared 3 frames ignored", msg
    # the header declares fewer frames than the file holds: the declared ones are read
    p = write(tmp_path, base_with({LINE["frames"]: "Frames: 2"}), "fewer.bvh")
    with pytest.warns(BVHWarning, match=r"fewer\.bvh:21: 1 line after the declared 2 frames ignored") as rec:
        m = read_bvh(p, dtype=torch.float64)
    assert len(rec) == 1 and m.num_frames == 2
    ref = parse_bvh(BASE, dtype=torch.float64)
    torch.testing.assert_close(m.rotations, ref.rotations[:2], rtol=0, atol=0)
    # no warning for a clean file, nor for blank lines at its end
    with warnings_as_errors():
        read_bvh(write(tmp_path, BASE + "\n \n\t\n", "blank_tail.bvh"))


@contextlib.contextmanager
def warnings_as_errors():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def test_a_refused_file_does_not_also_warn(tmp_path):
    with warnings_as_errors():
        err = _bvh_error(tmp_path, base_with({LINE["f1"]: "1 2 3 10 20 30 5 6 x"}) + "1 2 3\n")
    _check(err, LINE["f1"], "non-numeric", "'x'")


def test_error_frame_time_that_overflows(tmp_path):
    err = _bvh_error(tmp_path, base_with({LINE["frame_time"]: "Frame Time: 5e-324"}))
    _check(err, LINE["frame_time"], "frame time", "5e-324", "1 to 1,000 fps")


@pytest.mark.parametrize("frame_time", ["0.0009", "1.5", "2", "1e9", "0", "-0.0333333", "nan", "inf", "1e-300"])
def test_error_frame_rate_outside_1_to_1000_fps(tmp_path, frame_time):
    err = _bvh_error(tmp_path, base_with({LINE["frame_time"]: f"Frame Time: {frame_time}"}))
    _check(err, LINE["frame_time"], "frame time")


@pytest.mark.parametrize("frame_time, fps", [("0.001", 1000.0), ("1", 1.0), ("0.5", 2.0)])
def test_frame_rate_edges_are_read(frame_time, fps):
    assert parse_bvh(base_with({LINE["frame_time"]: f"Frame Time: {frame_time}"})).fps == fps


@pytest.mark.parametrize("count", ["\u00b3", "\u0663", "\uff13", "\u2083", "3.0", "+3", "-3"])
def test_error_channel_count_not_ascii_digits(tmp_path, count):
    line = f"    CHANNELS {count} Zrotation Xrotation Yrotation"
    err = _bvh_error(tmp_path, base_with({LINE["spine_channels"]: line}))
    _check(err, LINE["spine_channels"], "channel count")


@pytest.mark.parametrize("count", ["\u00b3", "\u0663", "\u0663\u0660", "\uff13", "+3", "-3", "3.0", "3 frames", ""])
def test_error_frame_count_not_ascii_digits(tmp_path, count):
    err = _bvh_error(tmp_path, base_with({LINE["frames"]: f"Frames: {count}"}))
    _check(err, LINE["frames"], "frame count")


def test_error_channel_count_beyond_the_possible(tmp_path):
    err = _bvh_error(tmp_path, base_with({LINE["spine_channels"]: "    CHANNELS 99999999999999999999999 Zrotation"}))
    _check(err, LINE["spine_channels"], "Spine", "at most 9")


@pytest.mark.parametrize("char", ["\x00", "\x01", "\x1b", "\x7f", "\x9f"])
def test_error_control_character_in_joint_name(tmp_path, char):
    err = _bvh_error(tmp_path, BASE.replace("JOINT Spine", f"JOINT Sp{char}ine"))
    _check(err, 6, "control character", f"U+{ord(char):04X}")


def _chain_text(n: int) -> tuple[str, np.ndarray]:
    """A chain of ``n`` joints J0 <- J1 <- ... (not indented: the text stays linear in ``n``)."""
    rng = np.random.default_rng(n)
    angles = rng.uniform(-20, 20, size=(2, n, 3))
    lines = ["HIERARCHY"]
    for j in range(n):
        ch = "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" if j == 0 else \
            "CHANNELS 3 Zrotation Xrotation Yrotation"
        lines += [f"{'ROOT' if j == 0 else 'JOINT'} J{j}", "{", "OFFSET 0 1 0", ch]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * n + ["MOTION", "Frames: 2", "Frame Time: 0.0333333"]
    lines += ["1 2 3 " + " ".join(f"{v:.6f}" for v in angles[t].reshape(-1)) for t in range(2)]
    return "\n".join(lines) + "\n", angles


def test_deep_chain_is_read_and_written(tmp_path):
    n = 1500  # past Python's default recursion limit (1,000)
    text, angles = _chain_text(n)
    m = parse_bvh(text, dtype=torch.float64)
    assert m.skeleton.names == tuple(f"J{j}" for j in range(n))
    assert m.skeleton.parents == (-1,) + tuple(range(n - 1))
    assert m.skeleton.end_site_parents == (n - 1,)
    assert m.num_frames == 2
    np.testing.assert_allclose(quat_matrix(m.rotations[1, n - 1]), euler_matrix("ZXY", angles[1, n - 1]), atol=1e-12)
    out = tmp_path / "deep.bvh"
    write_bvh(m, out)  # the writer walks the hierarchy without recursion too
    m2 = read_bvh(out, dtype=torch.float64)
    same_skeleton(m.skeleton, m2.skeleton)
    torch.testing.assert_close(m2.rotations.abs(), m.rotations.abs(), rtol=0, atol=1e-6)


def test_error_more_than_10000_joints(tmp_path):
    from torchsplice.formats.bvh import MAX_JOINTS

    assert MAX_JOINTS == 10_000
    text, _ = _chain_text(MAX_JOINTS + 1)
    err = _bvh_error(tmp_path, text, "huge.bvh")
    _check(err, None, "more than 10,000 joints")


@pytest.mark.parametrize("token", ["nan", "-nan", "inf", "-Infinity", "1e999"])
@pytest.mark.parametrize("where", ["spine_offset", "end_site"])
def test_error_non_finite_offset(tmp_path, token, where):
    line = {"spine_offset": LINE["spine_offset"], "end_site": LINE["end_site_close"] - 1}[where]
    err = _bvh_error(tmp_path, base_with({line: f"    OFFSET 0 {token} 0"}))
    _check(err, line, "OFFSET", token)


@pytest.mark.parametrize("token", ["1e300", "-1e13", "1e999", "-1e999"])
def test_error_absurd_or_overflowing_frame_value(tmp_path, token):
    err = _bvh_error(tmp_path, base_with({LINE["f2"]: f"2 4 6 20 40 60 10 12 {token}"}))
    _check(err, LINE["f2"], token, "frame 2", "Spine Yrotation")


def test_error_absurd_offset(tmp_path):
    err = _bvh_error(tmp_path, base_with({LINE["spine_offset"]: "    OFFSET 0 1e14 0"}))
    _check(err, LINE["spine_offset"], "absurd OFFSET", "1e14")


@pytest.mark.parametrize("token", ["\u0661", "\u00b2", "1_000", "0x10", "\x00", "1,5"])
def test_error_non_ascii_or_odd_numbers_in_frames(tmp_path, token):
    err = _bvh_error(tmp_path, base_with({LINE["f1"]: f"1 2 3 10 {token} 30 5 6 7"}))
    _check(err, LINE["f1"], "non-numeric")


def test_error_huge_frame_count_without_allocating(tmp_path):
    import time
    import tracemalloc

    for frames, phrase in (("99999999999", "truncated"), ("9" * 5000, "absurd frame count")):
        p = write(tmp_path, base_with({LINE["frames"]: f"Frames: {frames}"}))
        tracemalloc.start()
        t0 = time.perf_counter()
        try:
            with pytest.raises(BVHError) as ei:
                read_bvh(p)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert time.perf_counter() - t0 < 5 and peak < 20e6, peak
        _check(ei.value, None, phrase)
        assert len(str(ei.value)) < 300


_MB = "Q" * 1_000_000


@pytest.mark.parametrize("where", ["offset", "channel", "frame", "frames", "frame_time", "keyword", "hierarchy",
                                   "name_nul", "name_dup", "end_site", "after_root"])
def test_error_messages_stay_short_with_a_1mb_token(tmp_path, where):
    text = {
        "offset": base_with({LINE["spine_offset"]: f"OFFSET 0 {_MB} 0"}),
        "channel": base_with({LINE["spine_channels"]: f"CHANNELS 3 Zrotation {_MB} Yrotation"}),
        "frame": base_with({LINE["f1"]: f"1 2 3 10 {_MB} 30 5 6 7"}),
        "frames": base_with({LINE["frames"]: f"Frames: {_MB}"}),
        "frame_time": base_with({LINE["frame_time"]: f"Frame Time: {_MB}"}),
        "keyword": base_with({1: _MB}),
        "hierarchy": base_with({LINE["spine_channels"] + 1: _MB}),
        "name_nul": BASE.replace("JOINT Spine", f"JOINT {_MB}\x00"),
        "name_dup": BASE.replace("JOINT Spine", f"JOINT {_MB}").replace("ROOT Hips", f"ROOT {_MB}"),
        "end_site": base_with({LINE["end_site_close"] - 3: f"End {_MB}"}),
        "after_root": BASE.replace("MOTION", f"{_MB}\nMOTION"),
    }[where]
    err = _bvh_error(tmp_path, text)
    assert len(str(err)) < 300, len(str(err))
    assert "..." in str(err)


def test_error_message_of_a_wide_root_stays_short(tmp_path):
    lines = ["HIERARCHY", "ROOT Root", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
    for j in range(4999):
        lines += [f"JOINT Child{j % 4998}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation", "}"]
    lines += ["}", "MOTION", "Frames: 1", "Frame Time: 0.0333333", " ".join(["0"] * (6 + 3 * 4999))]
    err = _bvh_error(tmp_path, "\n".join(lines) + "\n")
    _check(err, None, "'Child0' appears twice")
    assert len(str(err)) < 300
    # the same without the duplicate reads
    ok = "\n".join(lines).replace("JOINT Child0\n{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n}\n", "", 1)
    ok = ok.replace(" ".join(["0"] * (6 + 3 * 4999)), " ".join(["0"] * (6 + 3 * 4998)))
    assert parse_bvh(ok).skeleton.num_joints == 4999


def _finite_motion(T=4) -> Motion:
    frames = [[t, 0, 0, 10 * t, 0, 0, 5, 0, 0] for t in range(T)]
    return parse_bvh(_chain_bvh(["ZXY", "ZXY"], [(0, 0, 0), (0, 1, 0)], frames), dtype=torch.float64, name="walk")


@pytest.mark.parametrize("what", ["rotations", "root_translation", "translations", "offsets", "end_site_offsets"])
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_writer_refuses_non_finite_values_and_writes_nothing(tmp_path, what, value):
    m = _finite_motion()
    if what in ("rotations", "root_translation"):
        getattr(m, what)[2, 0] = value
        where = "frame 2"
    elif what == "translations":
        m.translations = m.local_translations()
        m.translations[3, 1, 0] = value
        where = "frame 3"
    else:
        getattr(m.skeleton, what)[0, 1] = value
        where = "OFFSET"
    with pytest.raises(MotionError) as ei:
        format_bvh(m)
    msg = str(ei.value)
    assert "'walk'" in msg and where in msg and "\n" not in msg and len(msg) < 300
    out = tmp_path / "walk.bvh"
    with pytest.raises(MotionError):
        write_bvh(m, out)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fps", [0.5, 1500.0, math.inf])
def test_writer_refuses_frame_rates_the_reader_refuses(tmp_path, fps):
    m = _finite_motion()
    m.fps = fps
    with pytest.raises(MotionError, match="fps"):
        write_bvh(m, tmp_path / "x.bvh")
    assert list(tmp_path.iterdir()) == []


def test_writer_refuses_joint_names_that_would_not_read_back(tmp_path):
    m = _finite_motion()
    for bad in ("Sp\nine", "Sp\x00ine", " Spine", "a { b", ""):
        sk = m.skeleton
        names = (sk.names[0], bad)
        m.skeleton = Skeleton(names, sk.parents, sk.offsets, sk.channels, sk.end_site_parents, sk.end_site_offsets)
        with pytest.raises(MotionError, match="would not read back"):
            write_bvh(m, tmp_path / "x.bvh")
    assert list(tmp_path.iterdir()) == []


def test_write_bvh_checks_its_argument_types(tmp_path):
    m = _finite_motion()
    out = tmp_path / "x.bvh"
    with pytest.raises(TypeError, match="swapped"):
        write_bvh(out, m)
    with pytest.raises(TypeError, match="swapped"):
        write_bvh(str(out), m)
    with pytest.raises(TypeError, match="must be a Motion"):
        write_bvh(m.rotations, out)
    with pytest.raises(TypeError, match="path must be"):
        write_bvh(m, 3)
    with pytest.raises(TypeError, match="must be a Motion"):
        format_bvh("walk.bvh")
    assert list(tmp_path.iterdir()) == []
    write_bvh(m, str(out))
    assert read_bvh(out).num_frames == 4


def test_non_utf8_bytes_are_read_as_latin1_or_refused_cleanly(tmp_path):
    p = tmp_path / "latin1.bvh"
    p.write_bytes(BASE.replace("Spine", "R\u00fccken").encode("latin-1"))
    assert read_bvh(p).skeleton.names == ("Hips", "R\u00fccken")
    for i, junk in enumerate([b"\xff", b"\x80\x81", b"\xc3\x28", b"\xfe\xff\x00"]):
        p = tmp_path / f"junk{i}.bvh"
        p.write_bytes(BASE.replace("1 2 3 10", "1 2 3 1").encode().replace(b"3 1", b"3 1" + junk, 1))
        with pytest.raises(BVHError, match=f"junk{i}.bvh:{LINE['f1']}: non-numeric"):
            read_bvh(p)
    p = tmp_path / "random.bvh"
    p.write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8)))
    with pytest.raises(BVHError, match="random.bvh"):
        read_bvh(p)


def test_line_numbers_count_only_cr_and_lf(tmp_path):
    # a form feed or a vertical tab is whitespace inside a line, not a line break
    text = base_with({LINE["spine_offset"]: "    OFFSET 0\x0c10\x0b0"})
    _read_same_as_base(write(tmp_path, text, "ff.bvh"))
    err = _bvh_error(tmp_path, text.replace("2 4 6 20 40 60", "2 4 6 20 40 x"))
    _check(err, LINE["f2"], "non-numeric")


def test_smpl22_clips_export_to_bvh_and_read_back_by_joint_name(sample_db, tmp_path):
    """SMPL's joint order is not depth-first (its spine comes after both legs): the BVH holds the
    joints depth-first, and reads back with every joint where it was (to float32's rounding)."""
    from torchsplice.formats.exporters import export_clips
    from torchsplice.retarget.clips import retarget_clips
    from torchsplice.store.database import MotionDatabase

    smpl = tmp_path / "smpl.h5"
    retarget_clips(sample_db, ["walk_straight", "carry_box"], to="smpl22", out=smpl)
    export_clips(smpl, out=tmp_path / "bvh", format="bvh")
    with MotionDatabase.open(smpl) as db:
        for name in db.names:
            m = db.read(name, dtype=torch.float64)
            assert not m.skeleton.is_depth_first
            back = read_bvh(tmp_path / "bvh" / f"{name}.bvh", dtype=torch.float64)
            at = [back.skeleton.names.index(n) for n in m.skeleton.names]
            assert back.skeleton.is_depth_first and sorted(back.skeleton.names) == sorted(m.skeleton.names)
            err = (back.global_positions()[:, at] - m.global_positions()).abs().max()
            assert float(err) < 1e-4 * m.skeleton.size(), (name, float(err))
