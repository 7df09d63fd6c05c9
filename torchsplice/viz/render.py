"""Stick-figure previews of clips: an animated GIF or MP4, or a PNG filmstrip (:func:`render`).

Each clip gets a panel: its bones as line segments from parent to child (end sites included:
head top, hands, toes), left limbs blue and right limbs red (by joint name), a head circle, a
ground grid on the floor plane and a short trail of the root's recent path on the floor.

The parts, each its own module:

- :mod:`torchsplice.viz.stick_figure`: the clip's points by forward kinematics and its bones by side;
- :mod:`torchsplice.viz.camera`: the up axis, the projection (:func:`view_rotation`,
  :func:`project`; its conventions are in that module's docstring) and the camera that follows
  each clip's root and turns with its heading (``camera="heading"``, the default; ``"world"``
  keeps its direction fixed);
- :mod:`torchsplice.viz.panels`: the panels, the grid, the titles and the legend;
- :mod:`torchsplice.viz.writers`: the GIF and MP4 writers;
- :mod:`torchsplice.viz.style`: the inks.

The grid is fixed in the world, so it slides under a walking figure, and a trail shows the last
two seconds of the root's path on the floor. The scale is fixed over time and equal in x and y.
Panels share one scale, so sizes and speeds compare, unless the skeletons differ in size by more
than a factor of 1.5 (other units); then each panel is scaled to its own skeleton.

A panel may hold several clips drawn over each other (``motions`` entries that are sequences):
the first in the side colours, the camera its; the others in grey, at the same times, seen
from the first's camera (e.g. a naive result over the splice, as in the paper's Figure 4).

Forward kinematics runs once per clip, vectorised over frames; drawing a frame only sets the
data of a few ``Line2D`` artists. An animation plays in real time to the longest clip; a
shorter clip stops at its last frame, drawn faded (opacity
:data:`~torchsplice.viz.style.ENDED_ALPHA`) with ``(end)`` under it. A filmstrip row spans its
own clip (:func:`filmstrip_frames`), so every column shows another frame of it. Left and right
are named in a legend above the panels. GIFs default to :data:`GIF_FPS` and :data:`GIF_DPI` and
draw the grid's crossings as dots (lines sliding under a followed figure would make most of the
file). Figures are made with :class:`matplotlib.figure.Figure` on the Agg canvas directly (no
pyplot, no display, no global backend switch) and are released when done. Every output is
written atomically (:func:`~torchsplice.store.atomic.atomic_path`).

Units: positions in the clips' file units and axes; angles in degrees; sizes in inches; frame
rates in frames per second.
"""

from __future__ import annotations

import math
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ..core.errors import TorchspliceError
from ..core.motion import Motion
from ..store.atomic import atomic_path
from .camera import Clip, check_up_axis, prepare_clip
from .defaults import (CAMERAS, DEFAULT_AZIMUTH, DEFAULT_CAMERA, DEFAULT_ELEVATION, DEFAULT_FRAMES, DEFAULT_MAX_SECONDS,
                       SUPPORTED_SUFFIXES, MAX_FILMSTRIP)
from .camera import canonical_axes, heading_yaw, project, view_rotation, view_rotations  # noqa: F401 (re-exported)
from .panels import animation_figure, filmstrip_figure, make_scene, release
from .panels import fit_title  # noqa: F401 (re-exported)
from .stick_figure import Figure3D, figure_points, head_joint  # noqa: F401 (re-exported)
from .writers import GIF_DPI, GIF_FPS, GIF_MAX_FPS, abandon, ffmpeg_available, ffmpeg_complaint, gif_delay, make_writer

__all__ = ["render", "render_clips", "RenderOptions", "project", "view_rotation", "SUPPORTED_SUFFIXES", "CAMERAS"]

_GIF_MAX_PIXELS = 1.2e9
"""A GIF is assembled in memory (one byte a pixel, twice over while Pillow encodes it): more
pixels over all frames than this is refused with a hint (``max_seconds``, smaller, ``.mp4``)."""


def filmstrip_frames(num_frames: int, columns: int) -> np.ndarray:
    """The frames a filmstrip row shows: ``columns`` evenly spaced over the clip's own length,
    first and last frame included (distinct whenever the clip has that many frames)."""
    if columns <= 1 or num_frames <= 1:
        return np.zeros(max(1, columns), dtype=np.int64)
    return np.rint(np.linspace(0.0, num_frames - 1, columns)).astype(np.int64)


def _truncate(m: Motion, max_seconds: float | None) -> Motion:
    if max_seconds is None:
        return m
    n = max(1, int(math.floor(max_seconds * m.fps + 1e-9)))
    return m.slice(0, n) if n < m.num_frames else m


@dataclass(frozen=True)
class RenderOptions:
    """How :func:`render` draws and writes: its arguments but the clips, the output and the titles,
    as :func:`render` builds them for :func:`render_clips`.

    Attributes:
        up_axis: the vertical axis of the data (0, 1, 2 or ``"x"``, ``"y"``, ``"z"``); the
            dataset spec's.
        fps: the animation's frame rate; for MP4 the clips' (the highest, if they differ) by
            default; for a GIF :data:`GIF_FPS` by default, and any rate becomes the nearest one
            GIF stores exactly, ``100 / gif_delay(fps)``, at most 50 (see :data:`GIF_MAX_FPS`).
            Each output frame shows, per clip, the frame nearest its time, so the output
            plays in real time.
        frames: number of columns of the PNG filmstrip, at most :data:`~.defaults.MAX_FILMSTRIP`.
        size: width of one panel in inches (its height follows the figures' proportions).
        dpi: pixels per inch; :data:`GIF_DPI` for a GIF, 100 otherwise, by default.
        max_seconds: keep only the first ``max_seconds`` of each clip.
        azimuth, elevation: the camera, degrees (see :func:`view_rotation`); with
            ``camera="heading"`` the azimuth at the first frame.
        camera: ``"heading"`` (the camera turns with the character's heading, smoothed over a
            second) or ``"world"`` (its direction never changes); one of :data:`CAMERAS`.
    """

    up_axis: int | str = 1
    fps: float | None = None
    frames: int = DEFAULT_FRAMES
    size: float = 3.0
    dpi: int | None = None
    max_seconds: float | None = DEFAULT_MAX_SECONDS
    azimuth: float = DEFAULT_AZIMUTH
    elevation: float = DEFAULT_ELEVATION
    camera: str = DEFAULT_CAMERA

    def checked(self, suffix: str) -> tuple[int, int]:
        """``(up axis, dpi)``: the up axis as 0, 1 or 2 and the pixels per inch for an output of
        ``suffix`` (its default where none is given), once every option is checked.

        Raises:
            TorchspliceError: a bad camera, up axis or number (one line naming it).
        """
        azimuth, elevation = self.azimuth, self.elevation
        if not (math.isfinite(azimuth) and math.isfinite(elevation) and -90.0 <= elevation <= 90.0):
            raise TorchspliceError(f"azimuth must be a number and elevation from -90 to 90 degrees, got {azimuth}, {elevation}")
        if self.camera not in CAMERAS:
            raise TorchspliceError(f"camera must be one of {', '.join(CAMERAS)}, got {self.camera!r}")
        up = check_up_axis(self.up_axis)
        if self.fps is not None and not self.fps > 0:
            raise TorchspliceError(f"fps must be positive, got {self.fps}")
        if not 1 <= int(self.frames) <= MAX_FILMSTRIP:
            raise TorchspliceError(f"{{frames}} must be from 1 to {MAX_FILMSTRIP} (a filmstrip's columns), got {self.frames}",
                                   options=("frames",))
        dpi = self.dpi if self.dpi is not None else GIF_DPI if suffix == ".gif" else 100
        if not self.size > 0 or not dpi > 0:
            raise TorchspliceError(f"size and dpi must be positive, got size={self.size}, dpi={dpi}")
        if self.max_seconds is not None and not self.max_seconds > 0:
            raise TorchspliceError(f"max_seconds must be positive, got {self.max_seconds}")
        return up, int(dpi)


def render(
    motions: Sequence[Motion | Sequence[Motion]],
    output,
    titles: Sequence[str] | None = None,
    up_axis: int = 1,
    fps: float | None = None,
    frames: int = DEFAULT_FRAMES,
    size: float = 3.0,
    dpi: int | None = None,
    max_seconds: float | None = DEFAULT_MAX_SECONDS,
    *,
    azimuth: float = DEFAULT_AZIMUTH,
    elevation: float = DEFAULT_ELEVATION,
    camera: str = DEFAULT_CAMERA,
) -> Path:
    """Draw clips as stick figures side by side and write ``output``; returns its path.

    Args:
        motions: the clips, one panel each (any skeletons, lengths and frame rates). Each is
            drawn from its own ``rotations`` ``(T, J, 4)`` (WXYZ), ``root_translation``
            ``(T, 3)`` and ``translations``, in file units. An entry that is a sequence of
            clips is one panel drawing them over each other: the first in the side colours
            (the panel's camera and length are its), the others in grey at the same times.
        output: the file to write; its suffix picks the type (see :data:`SUPPORTED_SUFFIXES`):
            ``.gif`` an animation (matplotlib's PillowWriter), ``.mp4`` an animation (matplotlib's
            FFMpegWriter, H.264; needs ``ffmpeg`` on ``PATH``), ``.png`` a filmstrip: one row per
            clip, ``frames`` columns at evenly spaced frames from the clip's first to its last
            (each row its own length), the time and frame number under each figure.
        titles: one title per panel; the (first) clips' names by default.
        up_axis, fps, frames, size, dpi, max_seconds, azimuth, elevation, camera: how it is drawn
            and written, the attributes of :class:`RenderOptions` (see there for each).

    The animation has as many frames as the longest clip needs at ``fps``; shorter clips hold
    their last frame, faded (their label says ``(end)``). A GIF is assembled in memory and refused
    beyond about a gigapixel over all frames (a minute of four panels at the defaults); MP4
    streams to ffmpeg. The output appears complete or not at all: it is written to a
    temporary file beside it and renamed.

    Raises:
        TorchspliceError: an unsupported suffix (naming the supported ones), ``.mp4`` without
            ffmpeg, no clips, titles that do not match the clips, bad numbers, or an OS error
            while writing (one line naming the file).
    """
    options = RenderOptions(up_axis=up_axis, fps=fps, frames=frames, size=size, dpi=dpi, max_seconds=max_seconds,
                            azimuth=azimuth, elevation=elevation, camera=camera)
    return render_clips(motions, output, options, titles)


def render_clips(motions: Sequence[Motion | Sequence[Motion]], output, options: RenderOptions,
                 titles: Sequence[str] | None = None) -> Path:
    """:func:`render` with its options in one :class:`RenderOptions`: the output's type and the
    panels checked, then the options, then the clips prepared and laid out in panels, then the
    filmstrip or the animation drawn and written (atomically)."""
    output = Path(output)
    suffix = _output_suffix(output)
    groups, titles = _panels(motions, titles)
    up, dpi = options.checked(suffix)
    prepared = _prepare_panels(groups, up, options)
    scene = make_scene(prepared, up, float(options.size))
    with atomic_path(output) as tmp:
        if suffix == ".png":
            _write_filmstrip(tmp, scene, prepared, titles, int(options.frames), dpi)
        else:
            _write_animation(tmp, output, suffix, scene, prepared, titles, _output_rate(suffix, options.fps, prepared), dpi)
    return output


def _output_suffix(output: Path) -> str:
    """The output's type, its suffix in lower case: one that can be written here."""
    suffix = output.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise TorchspliceError(
            f"{output}: cannot render to {output.suffix or 'a file without a suffix'!r}; "
            f"write one of {', '.join(SUPPORTED_SUFFIXES)}"
        )
    if suffix == ".mp4" and not ffmpeg_available():
        raise TorchspliceError(".mp4 needs ffmpeg on PATH; write .gif or .png instead")
    return suffix


def _panels(motions, titles) -> tuple[list[list[Motion]], list[str]]:
    """``(groups, titles)``: the clips of each panel (one, or several drawn over each other) and
    the panels' titles (the first clips' names by default), one per panel."""
    groups = [[m] if isinstance(m, Motion) else list(m) for m in motions]
    if not groups or not all(groups):
        raise TorchspliceError("render needs at least one clip" if not groups else "a panel of no clips; give each one")
    titles = [g[0].name for g in groups] if titles is None else [str(t) for t in titles]
    if len(titles) != len(groups):
        raise TorchspliceError(f"{len(titles)} titles for {len(groups)} panel{'s' if len(groups) != 1 else ''}; "
                              "give one title per panel")
    return groups, titles


def _prepare_panels(groups: list[list[Motion]], up: int, options: RenderOptions) -> list[list[Clip]]:
    """Each panel's clips cut to ``max_seconds`` and prepared for drawing (:func:`prepare_clip`):
    the first with its own camera, the others seen from the first's."""
    o = options
    prepared = []
    for g in groups:
        lead = prepare_clip(_truncate(g[0], o.max_seconds), up, o.azimuth, o.elevation, o.camera)
        prepared.append([lead] + [prepare_clip(_truncate(m, o.max_seconds), up, o.azimuth, o.elevation, o.camera, leader=lead)
                                  for m in g[1:]])
    return prepared


def _output_rate(suffix: str, fps: float | None, prepared: list[list[Clip]]) -> float:
    """An animation's frames per second: ``fps``, else the panels' highest; for a GIF the nearest
    rate it stores exactly (100 over a whole number of hundredths), :data:`GIF_FPS` by default."""
    rate = float(fps) if fps is not None else max(g[0].fps for g in prepared)
    if suffix == ".gif":  # a rate GIF stores exactly: 100 / a whole number of hundredths
        rate = 100.0 / gif_delay(min(float(fps) if fps is not None else GIF_FPS, GIF_MAX_FPS))
    return rate


def _frame_of(c: Clip, t: float) -> tuple[int, bool]:
    """The frame of clip ``c`` shown at time ``t`` (the nearest, its last after it ends) and whether it has ended."""
    f = int(round(t * c.fps))
    return min(f, c.num_frames - 1), f > c.num_frames - 1


def _write_filmstrip(tmp, scene, prepared: list[list[Clip]], titles: list[str], columns: int, dpi: int) -> None:
    """The PNG filmstrip, to ``tmp``: a row per panel, ``columns`` frames spread over its own clip."""
    fig, cells = filmstrip_figure(scene, prepared, titles, columns, dpi)
    try:
        for row, g in zip(cells, prepared):
            for panel, f in zip(row, filmstrip_frames(g[0].num_frames, columns)):
                panel.show(int(f))
        fig.savefig(tmp, format="png", dpi=dpi)
    finally:
        release(fig)


def _write_animation(tmp, output: Path, suffix: str, scene, prepared: list[list[Clip]], titles: list[str], rate: float,
                     dpi: int) -> None:
    """The GIF or MP4 animation, to ``tmp``, at ``rate`` frames per second to the end of the
    longest clip; a GIF too large to assemble is refused before any drawing, and ffmpeg's
    failures are told in one line naming ``output``."""
    clips = [g[0] for g in prepared]
    last = max((c.num_frames - 1) / c.fps for c in clips)  # time of the last frame of the longest clip
    n_out = int(math.floor(last * rate + 1e-6)) + 1
    fig, panels, clock = animation_figure(scene, prepared, titles, dpi, grid_dots=suffix == ".gif")
    same_rate = all(c.fps == rate for c in clips)
    try:
        canvas = fig.canvas
        w, h = canvas.get_width_height()
        if suffix == ".gif" and n_out * w * h > _GIF_MAX_PIXELS:
            raise TorchspliceError(
                f"{output}: a GIF of {n_out} frames of {w}x{h} pixels is too large to assemble in memory; "
                f"shorten it (max_seconds), make it smaller (size, dpi) or write .mp4")
        canvas.draw()  # the static background, once
        background = canvas.copy_from_bbox(fig.bbox)
        writer = make_writer(suffix, rate)
        writer.setup(fig, str(tmp), dpi)
        done = False
        try:
            for k in range(n_out):
                _draw_frame(fig, canvas, background, panels, clock, k, rate, same_rate)
                writer.grab_frame()
            done = True
        except BrokenPipeError:  # ffmpeg stopped reading: say why
            raise TorchspliceError(f"{output}: ffmpeg failed: {ffmpeg_complaint(writer)}") from None
        finally:
            if done:
                writer.finish()
            else:
                abandon(writer)
    except subprocess.CalledProcessError as exc:  # ffmpeg failed at the end
        err = (exc.stderr if isinstance(exc.stderr, str) else "").strip().splitlines()
        raise TorchspliceError(f"{output}: ffmpeg failed: {err[-1] if err else exc}") from None
    finally:
        release(fig)


def _draw_frame(fig, canvas, background, panels, clock, k: int, rate: float, same_rate: bool) -> None:
    """Output frame ``k`` over the static ``background``: each panel at its clip's frame of that
    time (blitted), and the clock (seconds, and the frame number where every clip has ``rate``)."""
    t = k / rate
    canvas.restore_region(background)
    for p in panels:
        p.show(*_frame_of(p.clip, t))
        p.blit()
    clock.set_text(f"{t:.2f} s   frame {k}" if same_rate else f"{t:.2f} s")
    fig.draw_artist(clock)
