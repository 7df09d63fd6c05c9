"""Stick-figure rendering: real files read back, a projection that can be checked by hand,
images that must (and must not) change, one-line errors and atomic output."""

import math
import shutil

import numpy as np
import pytest
import torch
from PIL import Image

import matplotlib.pyplot as plt

import torchsplice.viz.camera as camera_mod
import torchsplice.viz.panels as panels_mod
import torchsplice.viz.render as render_mod
import torchsplice.viz.writers as writers_mod
from cli_helpers import run
from torchsplice.cli import main
from torchsplice.core.errors import TorchspliceError
from torchsplice.core.motion import Motion
from torchsplice.core.skeleton import Skeleton
from torchsplice.sample import sample_motion
from torchsplice.store.database import MotionDatabase
from torchsplice.viz.render import project, render, view_rotation
from torchsplice.viz.style import GHOST_COLOR

SMALL = dict(size=1.6, dpi=50)  # small pictures keep the file fast


@pytest.fixture(scope="module")
def clips():
    """Short sample clips (30 fps): two walks and an action, 45, 45 and 30 frames."""
    return {
        "walk": sample_motion("walk_straight", dtype=torch.float64).slice(0, 45),
        "curve": sample_motion("walk_curve", dtype=torch.float64).slice(0, 45),
        "box": sample_motion("carry_box", dtype=torch.float64).slice(0, 30),
    }


def pixels(path) -> np.ndarray:
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=np.int16)


def shifted(m: Motion, by) -> Motion:
    """The same clip moved by ``by`` in the world."""
    return Motion(m.skeleton, m.rotations, m.root_translation + torch.tensor(by, dtype=m.dtype), m.fps, name=m.name)


def axes_cycled(m: Motion) -> Motion:
    """The same clip with its axes renamed (x, y, z) -> (y, z, x): Y-up data becomes Z-up.

    A cyclic permutation is a proper rotation, so quaternions permute their vector part the
    same way and the picture must not change when the up axis follows.
    """
    perm = [2, 0, 1]  # new (x, y, z) = old (z, x, y)
    sk = m.skeleton
    sk2 = Skeleton(sk.names, sk.parents, sk.offsets[:, perm], sk.channels, sk.end_site_parents, sk.end_site_offsets[:, perm])
    q = m.rotations
    q2 = torch.cat([q[..., :1], q[..., 1:][..., perm]], dim=-1)
    return Motion(sk2, q2, m.root_translation[:, perm], m.fps, name=m.name)


def pole(position=(0.0, 0.0, 0.0), along=(0.0, 100.0, 0.0), frames=2) -> Motion:
    """A hand-made two-joint 'skeleton': a root and one joint ``along`` from it (a pole), plus
    a short end site sideways (+X) at the top, standing still at ``position``."""
    sk = Skeleton(["base", "tip"], [-1, 0], torch.tensor([[0.0, 0, 0], list(along)], dtype=torch.float64),
                  [["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"], ["Zrotation", "Xrotation", "Yrotation"]],
                  end_site_parents=[1], end_site_offsets=torch.tensor([[30.0, 0, 0]], dtype=torch.float64))
    rot = torch.zeros(frames, 2, 4, dtype=torch.float64)
    rot[..., 0] = 1.0
    root = torch.tensor(position, dtype=torch.float64).expand(frames, 3).clone()
    return Motion(sk, rot, root, 30.0, name="pole")


# -- the projection -----------------------------------------------------------------------------


@pytest.mark.parametrize("up", [0, 1, 2])
def test_view_is_a_rotation_and_up_is_screen_up(up):
    V = view_rotation(up, azimuth=-55.0, elevation=22.0)
    assert np.allclose(V @ V.T, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(V), 1.0)
    h = np.zeros(3)
    h[up] = 100.0
    x, y = project(h, up, azimuth=-55.0, elevation=22.0)
    assert abs(x) < 1e-9 and y == pytest.approx(100.0 * math.cos(math.radians(22.0)))
    # level view: heights keep their length; looking down: the floor point nearest the camera
    # is lower on the screen than the one opposite it
    assert project(h, up, elevation=0.0)[1] == pytest.approx(100.0)
    towards = np.zeros(3)
    towards[[(up + 1) % 3, (up + 2) % 3]] = V[2, [(up + 1) % 3, (up + 2) % 3]]
    assert project(100 * towards, up)[1] < 0 < project(-100 * towards, up)[1]


def test_projection_known_answers_y_up():
    # azimuth 0 = camera on +Z (in front of the sample's characters), elevation 0: screen
    # right is +X (the character's left, as seen face to face), screen up is Y
    p = project(torch.tensor([[10.0, 20.0, 30.0], [0.0, 0.0, 0.0]]), up_axis=1, azimuth=0.0, elevation=0.0)
    assert np.allclose(p, [[10.0, 20.0], [0.0, 0.0]])
    # azimuth 90 puts the camera on +X, looking at the character's left side: forward (+Z)
    # points to the screen's left
    assert np.allclose(project([0.0, 0.0, 30.0], 1, azimuth=90.0, elevation=0.0), [-30.0, 0.0])
    # the projection is linear: a translation moves every point alike
    pts = np.random.default_rng(0).normal(size=(5, 3))
    assert np.allclose(project(pts + [7.0, -3.0, 2.0], 1) - project(pts, 1), project([7.0, -3.0, 2.0], 1))
    # up axes by name, as dataset specs spell them
    assert np.allclose(view_rotation("z"), view_rotation(2))


def test_pole_lands_where_expected_in_the_picture(tmp_path):
    """A pole standing far from the origin: drawn upright at the panel's centre (the camera
    follows it), its sideways end site at the top; laid along the floor it is drawn flat."""
    def dark_pixels(m, name):
        out = render([m], tmp_path / name, titles=[""], frames=1, size=2.0, dpi=60, elevation=10.0)
        rgb = pixels(out)
        ink = rgb.max(axis=-1) < 90  # the bone colour; the grid and trail are light
        ink[-int(0.3 * 60):] = False  # the time label under the panel
        rows, cols = np.nonzero(ink)
        return rgb.shape, rows, cols

    shape, rows, cols = dark_pixels(pole(position=(500.0, 0.0, -300.0)), "standing.png")
    height, width = rows.max() - rows.min(), cols.max() - cols.min()
    assert height > 4 * width  # upright
    assert abs(np.median(cols) - shape[1] / 2) < 0.05 * shape[1]  # followed: at the centre
    top, bottom = rows < np.percentile(rows, 15), rows > np.percentile(rows, 85)
    assert np.ptp(cols[top]) > 3 * max(np.ptp(cols[bottom]), 1)  # the stub is at the top: up is up

    _, rows, cols = dark_pixels(pole(position=(500.0, 0.0, -300.0), along=(0.0, 0.0, 100.0)), "lying.png")
    assert rows.max() - rows.min() < cols.max() - cols.min()  # on the floor, seen from 10 degrees up


# -- PNG filmstrip ------------------------------------------------------------------------------


def test_png_filmstrip_reads_back(tmp_path, clips):
    out = render([clips["walk"], clips["box"], clips["curve"]], tmp_path / "strip.png", frames=4, **SMALL)
    assert out == tmp_path / "strip.png" and out.is_file()
    with Image.open(out) as im:
        assert im.format == "PNG"
        w, h = im.size
    # 4 columns of 1.6-inch panels at 50 dpi, plus small gaps; 3 rows, each a panel plus
    # its title and labels
    assert 4 * 1.6 * 50 <= w <= 4 * 1.6 * 50 * 1.1
    assert 3 * (0.75 * 1.6 * 50) < h < 3 * (1.6 * 1.6 + 0.7) * 50
    rgb = pixels(out)
    assert rgb.std() > 10  # not blank
    blue = (rgb[..., 2] > 150) & (rgb[..., 0] < 90)
    red = (rgb[..., 0] > 170) & (rgb[..., 2] < 90)
    assert blue.mean() > 0.002 and red.mean() > 0.002  # left and right limbs are drawn
    assert plt.get_fignums() == []


def test_png_changes_with_the_clip_and_only_then(tmp_path, clips):
    a = pixels(render([clips["walk"]], tmp_path / "a.png", frames=3, **SMALL))
    again = pixels(render([clips["walk"]], tmp_path / "again.png", frames=3, **SMALL))
    b = pixels(render([clips["box"]], tmp_path / "b.png", frames=3, **SMALL))
    assert np.array_equal(a, again)  # deterministic
    if a.shape == b.shape:
        assert np.abs(a - b).mean() > 0.5  # another pose, another picture
    # and in the same clip, later frames differ from the first
    w = a.shape[1] // 3
    assert np.abs(a[:, :w] - a[:, w:2 * w]).mean() > 0.5


def test_camera_follows_the_root(tmp_path, clips):
    """A clip moved far away (by whole grid cells: the grid is 1 m here) looks the same; moved
    by part of a cell, the figure is the same but the world-fixed grid slides under it."""
    walk = clips["walk"]
    a = pixels(render([walk], tmp_path / "here.png", frames=3, **SMALL))
    far = pixels(render([shifted(walk, (3.0e4, 0.0, -5.0e4))], tmp_path / "far.png", frames=3, **SMALL))
    assert a.shape == far.shape and np.abs(a - far).max() <= 2
    part = pixels(render([shifted(walk, (37.0, 0.0, 0.0))], tmp_path / "part.png", frames=3, **SMALL))
    assert (np.abs(a - part).max(axis=-1) > 8).mean() > 0.03  # grid lines moved across the panels


def test_up_axis_is_followed(tmp_path, clips):
    walk = clips["walk"]
    y_up = pixels(render([walk], tmp_path / "y.png", frames=2, up_axis=1, **SMALL))
    z_up = pixels(render([axes_cycled(walk)], tmp_path / "z.png", frames=2, up_axis=2, **SMALL))
    assert y_up.shape == z_up.shape and np.abs(y_up - z_up).max() <= 2
    wrong = pixels(render([axes_cycled(walk)], tmp_path / "wrong.png", frames=2, up_axis=1, **SMALL))
    assert wrong.shape != y_up.shape or np.abs(wrong - y_up).mean() > 1


def strip_cells(rgb: np.ndarray, rows: int, cols: int, size: float, dpi: int) -> list[list[np.ndarray]]:
    """The panels of a filmstrip, cut by the layout of ``filmstrip_figure`` (inches to pixels)."""
    H, W = rgb.shape[:2]
    row_h = (H - (panels_mod.MARGIN + panels_mod.LEGEND_H) * dpi) / rows
    top0 = (panels_mod.LEGEND_H + panels_mod.MARGIN / 2) * dpi
    col_w = W / cols
    cells = []
    for r in range(rows):
        y0 = int(top0 + r * row_h + panels_mod.TITLE_H * dpi) + 2
        y1 = int(top0 + (r + 1) * row_h - panels_mod.LABEL_H * dpi) - 2
        w = int(col_w) - 8
        cells.append([rgb[y0:y1, int(k * col_w) + 4:int(k * col_w) + 4 + w] for k in range(cols)])
    return cells


def test_filmstrip_rows_show_their_own_frames(tmp_path, clips):
    """Each row spans its own clip: a 15-frame clip beside a 45-frame one shows 5 different
    frames, its first and its last, not its last frame repeated after its end."""
    assert list(render_mod.filmstrip_frames(15, 5)) == [0, 4, 7, 10, 14]
    assert list(render_mod.filmstrip_frames(45, 5)) == [0, 11, 22, 33, 44]
    assert list(render_mod.filmstrip_frames(3, 1)) == [0]
    short = clips["box"].slice(0, 15)
    rgb = pixels(render([clips["walk"], short], tmp_path / "two.png", frames=5, **SMALL))
    cells = strip_cells(rgb, rows=2, cols=5, size=1.6, dpi=50)
    for row in cells:
        for a, b in zip(row, row[1:]):
            assert a.shape == b.shape and np.abs(a - b).mean() > 0.3  # every column another frame


def test_pictures_have_a_legend(tmp_path, clips):
    """The side colours are named in a band above the panels: its blue and red ink are there."""
    for name in ("strip.png", "anim.gif"):
        out = render([clips["walk"]], tmp_path / name, frames=2, size=2.0, dpi=60)
        with Image.open(out) as im:
            rgb = np.asarray(im.convert("RGB"), dtype=np.int16)
        band = rgb[:int(panels_mod.LEGEND_H * 60)]
        blue = (band[..., 2] > 150) & (band[..., 0] < 90)
        red = (band[..., 0] > 170) & (band[..., 2] < 90)
        assert blue.sum() >= 5 and red.sum() >= 5, name
        assert (band.max(axis=-1) < 160).sum() > 20, name  # the words


# -- GIF ----------------------------------------------------------------------------------------


def gif_info(path):
    with Image.open(path) as im:
        assert im.format == "GIF" and im.is_animated
        n = im.n_frames
        durations = []
        first = np.asarray(im.convert("RGB"), dtype=np.int16)
        for k in range(n):
            im.seek(k)
            durations.append(im.info["duration"])
        last = np.asarray(im.convert("RGB"), dtype=np.int16)
    return n, durations, first, last


def test_gif_plays_to_the_longest_clip_at_20_fps(tmp_path, clips):
    """30 fps clips are sampled at the GIF's 20 fps (delays of exactly 5 hundredths), in real
    time: the frames span the longest clip's 44 frame steps (1.467 s)."""
    out = render([clips["walk"], clips["box"]], tmp_path / "anim.gif", **SMALL)  # 45 and 30 frames
    n, durations, first, last = gif_info(out)
    assert render_mod.GIF_FPS == 20.0 and render_mod.gif_delay(20.0) == 5
    assert n == math.floor(44 / 30 * 20) + 1 == 30
    assert all(d == 50 for d in durations)  # GIF keeps hundredths of a second: 5 of them
    assert (n - 1) * 0.05 <= 44 / 30 < n * 0.05  # the last frame shows the clip's end, on time
    assert np.abs(first - last).mean() > 0.5  # it moves
    assert plt.get_fignums() == []


@pytest.mark.parametrize("fps, delay", [(30.0, 3), (25.0, 4), (24.0, 4), (60.0, 2), (7.0, 14)])
def test_gif_rate_is_what_the_file_plays(tmp_path, clips, fps, delay):
    """A requested rate becomes the nearest one GIF stores exactly (100 / whole hundredths) and
    the clip is sampled at that rate, so the GIF lasts as long as the clip: 30 fps is written
    as 3 hundredths and sampled at 33.3 fps, not sampled at 30 and played 11% fast."""
    assert render_mod.gif_delay(fps) == delay
    n, durations, _, _ = gif_info(render([clips["walk"]], tmp_path / "r.gif", fps=fps, size=1.0, dpi=30))
    assert all(d == 10 * delay for d in durations)
    assert n == math.floor(44 / 30 * 100 / delay + 1e-6) + 1
    assert abs(sum(durations[:-1]) / 1000 - 44 / 30) < delay / 100  # as long as the clip


def test_gif_max_seconds_and_fps(tmp_path, clips):
    n, _, _, _ = gif_info(render([clips["walk"], clips["box"]], tmp_path / "cut.gif", max_seconds=0.5, **SMALL))
    assert n == 10  # 0.5 s at 30 fps keeps 15 frames, 0 to 0.467 s: at 20 fps 0, 0.05, ..., 0.45 s
    n, durations, _, _ = gif_info(render([clips["walk"]], tmp_path / "slow.gif", fps=10, **SMALL))
    assert n == 15  # 44 frames at 30 fps last 1.47 s: frames at 0, 0.1, ..., 1.4 s
    assert all(d == 100 for d in durations)


def test_gif_of_fast_clips_plays_at_50_fps(tmp_path, clips):
    """GIF delays are whole hundredths and browsers slow down shorter ones: asked for 120 fps
    (CMU's rate), a GIF is sampled at 50 fps, in real time."""
    walk = clips["walk"]
    fast = Motion(walk.skeleton, walk.rotations, walk.root_translation, 120.0, name="fast")  # 44/120 s
    n, durations, _, _ = gif_info(render([walk, fast], tmp_path / "fast.gif", fps=120.0, **SMALL))
    assert n == math.floor(44 / 30 * 50) + 1
    assert all(d == 20 for d in durations)


def test_finished_clip_fades_and_playing_ones_move(tmp_path, clips):
    """In a GIF a clip shorter than the longest stops at its last frame, drawn faded: the same
    pose, lighter; the other panel keeps moving."""
    walk, box = clips["walk"], clips["box"].slice(0, 15)  # 1.47 s and 0.47 s
    out = render([walk, box], tmp_path / "fade.gif", size=1.6, dpi=50)
    frames = []
    with Image.open(out) as im:
        for k in range(im.n_frames):
            im.seek(k)
            frames.append(np.asarray(im.convert("RGB"), dtype=np.int16))
    W = frames[0].shape[1]
    left, right = slice(0, W // 2), slice(W // 2, W)
    end = round(14 / 30 * 20)  # the GIF frame showing the short clip's last frame (frame 14)
    at_end, later = frames[end][:, right], frames[-1][:, right]
    changed = np.abs(at_end - later).max(axis=-1) > 20
    changed[-int(0.55 * 50):] = False  # the "(end)" label and the clock under the panels
    assert changed.sum() > 30
    assert (later[changed].sum(-1) > at_end[changed].sum(-1)).mean() > 0.9  # lighter where they differ
    before = frames[end - 1][:, right]
    assert np.abs(before - at_end)[: -int(0.55 * 50)].mean() > 0.05  # it moved until its end
    assert np.abs(frames[-2][:, left] - frames[-1][:, left]).mean() > 0.05  # the walk still moves


def ten_seconds(name: str) -> Motion:
    """A sample clip played forwards then backwards, cut to 10 s at 30 fps (300 frames)."""
    m = sample_motion(name)
    idx = torch.cat([torch.arange(m.num_frames), torch.arange(m.num_frames - 1, -1, -1)])[:300]
    return Motion(m.skeleton, m.rotations[idx], m.root_translation[idx], 30.0, name=name)


def test_ten_second_gif_of_four_clips_is_under_3_mb(tmp_path):
    """The defaults (20 fps, 80 dpi, a quarter-step palette, the grid's crossings as dots) keep
    a 10 s GIF of four 30 fps clips under 3 MB, 201 frames of 5 hundredths: 10 s."""
    motions = [ten_seconds(n) for n in ("walk_straight", "walk_curve", "carry_box", "jog")]
    out = render(motions, tmp_path / "ten.gif")
    n, durations, first, last = gif_info(out)
    assert n == math.floor(299 / 30 * 20) + 1 == 200 and set(durations) == {50}
    assert out.stat().st_size < 3_000_000
    assert np.abs(first - last).mean() > 0.5


# -- errors and atomic output ---------------------------------------------------------------------


def test_mp4_without_ffmpeg_is_one_line(tmp_path, clips, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))  # no ffmpeg anywhere on PATH
    if writers_mod.FFMpegWriter.isAvailable():
        pytest.skip("ffmpeg is configured by absolute path here (animation.ffmpeg_path)")
    with pytest.raises(TorchspliceError) as err:
        render([clips["walk"]], tmp_path / "movie.mp4")
    assert str(err.value) == ".mp4 needs ffmpeg on PATH; write .gif or .png instead"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg is not on PATH")
def test_mp4_with_ffmpeg(tmp_path, clips):
    out = render([clips["walk"], clips["box"]], tmp_path / "movie.mp4", **SMALL)
    data = out.read_bytes()
    assert data[4:8] == b"ftyp" and len(data) > 1000
    assert [p.name for p in tmp_path.iterdir()] == ["movie.mp4"]


@pytest.mark.parametrize("name", ["out.jpg", "out", "out.GIFF"])
def test_unknown_suffix(tmp_path, clips, name):
    with pytest.raises(TorchspliceError, match=r"\.gif, \.mp4, \.png") as err:
        render([clips["walk"]], tmp_path / name)
    assert "\n" not in str(err.value)
    assert list(tmp_path.iterdir()) == []


def test_bad_arguments(tmp_path, clips):
    with pytest.raises(TorchspliceError, match="at least one clip"):
        render([], tmp_path / "x.png")
    with pytest.raises(TorchspliceError, match="one title per panel"):
        render([clips["walk"]], tmp_path / "x.png", titles=["a", "b"])
    with pytest.raises(TorchspliceError, match="up_axis"):
        render([clips["walk"]], tmp_path / "x.png", up_axis=3)
    with pytest.raises(TorchspliceError, match="does not exist"):
        render([clips["walk"]], tmp_path / "missing" / "x.png")
    with pytest.raises(TorchspliceError, match="elevation from -90 to 90"):  # the command's --elevation 95 too
        render([clips["walk"]], tmp_path / "x.png", elevation=95)
    from torchsplice.viz.defaults import MAX_FILMSTRIP

    for frames in (0, MAX_FILMSTRIP + 1):  # a filmstrip that would not fit a screen: refused before any drawing
        with pytest.raises(TorchspliceError, match=f"frames must be from 1 to {MAX_FILMSTRIP}") as err:
            render([clips["walk"]], tmp_path / "x.png", frames=frames)
        assert err.value.options == ("frames",) and "\n" not in str(err.value)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".gif", ".png"])
def test_failure_mid_render_leaves_nothing(tmp_path, clips, monkeypatch, suffix):
    """The writer has written part of the file when it fails: neither that nor the output remains,
    and an older output of the same name is left as it was."""
    def half_written(path):
        with open(path, "wb") as f:
            f.write(b"GIF89a-partial" if suffix == ".gif" else b"\x89PNG-partial")
        raise RuntimeError("disk on fire")

    if suffix == ".gif":
        monkeypatch.setattr(writers_mod.GifWriter, "finish", lambda self: half_written(self.outfile))
    else:
        import matplotlib.figure
        monkeypatch.setattr(matplotlib.figure.Figure, "savefig", lambda self, path, **kw: half_written(path))
    with pytest.raises(RuntimeError, match="disk on fire"):
        render([clips["walk"]], tmp_path / f"fresh{suffix}", **SMALL)
    assert list(tmp_path.iterdir()) == []

    old = tmp_path / f"old{suffix}"
    old.write_bytes(b"previous contents")
    with pytest.raises(RuntimeError):
        render([clips["walk"]], old, **SMALL)
    assert old.read_bytes() == b"previous contents"
    assert [p.name for p in tmp_path.iterdir()] == [old.name]
    assert plt.get_fignums() == []


def test_failure_at_the_first_frame_is_reported_as_it_is(tmp_path, clips, monkeypatch):
    def broken(self, **kwargs):
        raise RuntimeError("no frame for you")

    monkeypatch.setattr(writers_mod.GifWriter, "grab_frame", broken)
    with pytest.raises(RuntimeError, match="no frame for you"):
        render([clips["walk"]], tmp_path / "x.gif", **SMALL)
    assert list(tmp_path.iterdir()) == []


def test_oversized_gif_is_refused_before_drawing(tmp_path, clips, monkeypatch):
    monkeypatch.setattr(render_mod, "_GIF_MAX_PIXELS", 1000.0)
    with pytest.raises(TorchspliceError, match="max_seconds") as err:
        render([clips["walk"]], tmp_path / "x.gif", **SMALL)
    assert "\n" not in str(err.value)
    assert list(tmp_path.iterdir()) == []


# -- the heading camera and overlay panels (the issue "The first hour", item 11) ------------------


def _yaw_quat(deg, up=1) -> torch.Tensor:
    """``(T, 4)`` WXYZ rotations by ``deg`` about axis ``up``."""
    h = torch.deg2rad(torch.as_tensor(deg, dtype=torch.float64)) / 2
    q = torch.zeros(h.shape + (4,), dtype=torch.float64)
    q[..., 0], q[..., 1 + up] = torch.cos(h), torch.sin(h)
    return q


def _qmul(a, b):
    w1, x1, y1, z1 = a.unbind(-1)
    w2, x2, y2, z2 = b.unbind(-1)
    return torch.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], -1)


@pytest.mark.parametrize("up", [0, 1, 2])
def test_heading_yaw_recovers_turns_beyond_half_a_turn_under_any_tilt(up):
    deg = torch.linspace(-30.0, 400.0, 90, dtype=torch.float64)
    tilt = torch.zeros(90, 4, dtype=torch.float64)  # a swing about another axis, after the yaw
    tilt[:, 0], tilt[:, 1 + (up + 1) % 3] = math.cos(math.radians(10)), math.sin(math.radians(10))
    q = _qmul(_yaw_quat(deg, up), tilt)
    yaw = np.degrees(render_mod.heading_yaw(q.numpy(), up))
    assert np.allclose(yaw, deg.numpy(), atol=1e-9)
    d = np.degrees(render_mod.heading_yaw(-q.numpy(), up)) - yaw  # -q is the same rotation: whole turns apart
    assert np.allclose(d, d[0], atol=1e-9) and abs(d[0] / 360 - round(d[0] / 360)) < 1e-9


def _turning_in_place(frames=90, degrees=120.0) -> Motion:
    """The sample walk's first pose held still, its root yawing at a constant rate."""
    m = sample_motion("walk_straight", dtype=torch.float64).slice(0, 1)
    rot = m.rotations.expand(frames, -1, -1).clone()
    rot[:, 0] = _qmul(_yaw_quat(torch.linspace(0.0, degrees, frames, dtype=torch.float64)), rot[:, 0])
    root = m.root_translation.expand(frames, 3).clone()
    return Motion(m.skeleton, rot, root, 30.0, name="turning")


def test_the_heading_camera_turns_with_the_character_and_the_world_camera_does_not():
    m = _turning_in_place()
    half = 15  # half the heading camera's one-second window at 30 fps: inside it the smoothing is exact
    heading = camera_mod.prepare_clip(m, 1, -55.0, 22.0, "heading").screen[half:-half, :-1]
    world = camera_mod.prepare_clip(m, 1, -55.0, 22.0, "world").screen[half:-half, :-1]
    assert np.abs(heading - heading[:1]).max() < 1e-9  # seen from the same side all the way round
    assert np.abs(world - world[:1]).max() > 20.0  # centimetres: the figure turns in front of it


def test_an_overlaid_clip_is_seen_from_the_first_clips_camera(clips):
    walk = clips["curve"]
    lead = camera_mod.prepare_clip(walk, 1, -55.0, 22.0, "heading")
    same = camera_mod.prepare_clip(walk, 1, -55.0, 22.0, "heading", leader=lead)
    assert np.array_equal(same.screen, lead.screen, equal_nan=True)
    by = np.array([10.0, 0.0, -4.0])
    moved = camera_mod.prepare_clip(shifted(walk, list(by)), 1, -55.0, 22.0, "heading", leader=lead)
    want = lead.screen[:, :-1] + np.einsum("tik,k->ti", lead.view, by)[:, None]
    assert np.allclose(moved.screen[:, :-1], want, atol=1e-9)  # not re-centred on its own root


def test_an_overlaid_clip_at_another_frame_rate_is_drawn_at_the_first_clips_times_and_no_longer(clips):
    """The same walk stored at twice the rate (each frame twice) and longer than the first clip:
    drawn from the first clip's camera at its frames' times, exactly where the walk is, and its
    frames past the first clip's end take no part (the panel's limits are the first clip's)."""
    walk = clips["curve"]
    lead = camera_mod.prepare_clip(walk.slice(0, walk.num_frames - 20), 1, -55.0, 22.0, "heading")
    double = Motion(walk.skeleton, walk.rotations.repeat_interleave(2, 0), walk.root_translation.repeat_interleave(2, 0),
                    2 * walk.fps, name="double")
    ghost = camera_mod.prepare_clip(double, 1, -55.0, 22.0, "heading", leader=lead)
    assert ghost.num_frames == lead.num_frames and ghost.fps == lead.fps
    assert np.allclose(ghost.screen, lead.screen, atol=1e-9, equal_nan=True)


def test_the_heading_holds_through_frames_that_are_not_finite():
    q = _yaw_quat(torch.linspace(0.0, 90.0, 10, dtype=torch.float64)).numpy()
    q[[0, 4, 5]] = np.nan
    yaw = np.degrees(render_mod.heading_yaw(q, 1))
    want = np.linspace(0.0, 90.0, 10)
    want[[0]], want[[4, 5]] = want[1], want[3]  # the first finite before the start; the last before a gap
    assert np.allclose(yaw, want, atol=1e-9)
    assert np.array_equal(render_mod.heading_yaw(np.full((3, 4), np.nan), 1), np.zeros(3))


def test_an_overlay_panel_draws_the_further_clips_in_grey(tmp_path, clips):
    from matplotlib.colors import to_rgb

    grey = np.array([round(255 * v) for v in to_rgb(GHOST_COLOR)])
    walk, box = clips["walk"], clips["box"]
    alone = pixels(render([walk], tmp_path / "alone.png", frames=2, **SMALL))
    over = pixels(render([[walk, shifted(box, (40.0, 0.0, 0.0))]], tmp_path / "over.png", frames=2, **SMALL))
    n_alone, n_over = ((np.abs(p[40:] - grey).max(-1) <= 3).sum() for p in (alone, over))  # below the legend
    assert n_over > 60 and n_over > 4 * n_alone, (n_alone, n_over)


def test_render_command_takes_an_overlay_a_camera_and_its_angles(tmp_path, capsys, sample_db):
    from cli_helpers import error_line, run

    out = tmp_path / "o.png"
    rc, text, _ = run(capsys, "render", sample_db, "walk_curve", "--overlay", "walk_curve", "jog", "--camera", "world",
                      "--azimuth", "-90", "--elevation", "5", "--frames", "2", "-o", out)
    assert rc == 0 and "1 clip and a panel of 2 drawn over each other" in text and out.is_file()
    rc, _, err = run(capsys, "render", sample_db, "walk_curve", "--elevation", "95", "-o", tmp_path / "x.png")
    assert rc != 0 and "elevation from -90 to 90" in error_line(err) and not (tmp_path / "x.png").exists()


def test_render_frames_are_bounded(sample_db, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["render", str(sample_db), "walk_straight", "-o", str(tmp_path / "x.png"), "--frames", "100000"])
    assert e.value.code == 2
    assert "must be from 1 to 64" in capsys.readouterr().err
    with MotionDatabase.open(sample_db) as db:
        short = min(db.names, key=lambda n: db.clip_info(n)["length"])
        T = db.clip_info(short)["length"]
    if T < 64:
        rc, _, err = run(capsys, "render", sample_db, short, "-o", tmp_path / "x.png", "--frames", "64")
        assert rc == 0 and f"drawing {T}" in err


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
