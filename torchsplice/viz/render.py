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

__all__ = ["render", "project", "view_rotation", "SUPPORTED_SUFFIXES", "CAMERAS"]

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
    output = Path(output)
    suffix = output.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise TorchspliceError(
            f"{output}: cannot render to {output.suffix or 'a file without a suffix'!r}; "
            f"write one of {', '.join(SUPPORTED_SUFFIXES)}"
        )
    if suffix == ".mp4" and not ffmpeg_available():
        raise TorchspliceError(".mp4 needs ffmpeg on PATH; write .gif or .png instead")
    groups = [[m] if isinstance(m, Motion) else list(m) for m in motions]
    if not groups or not all(groups):
        raise TorchspliceError("render needs at least one clip" if not groups else "a panel of no clips; give each one")
    titles = [g[0].name for g in groups] if titles is None else [str(t) for t in titles]
    if len(titles) != len(groups):
        raise TorchspliceError(f"{len(titles)} titles for {len(groups)} panel{'s' if len(groups) != 1 else ''}; "
                              "give one title per panel")
    if not (math.isfinite(azimuth) and math.isfinite(elevation) and -90.0 <= elevation <= 90.0):
        raise TorchspliceError(f"azimuth must be a number and elevation from -90 to 90 degrees, got {azimuth}, {elevation}")
    if camera not in CAMERAS:
        raise TorchspliceError(f"camera must be one of {', '.join(CAMERAS)}, got {camera!r}")
    up = check_up_axis(up_axis)
    if fps is not None and not fps > 0:
        raise TorchspliceError(f"fps must be positive, got {fps}")
    if not 1 <= int(frames) <= MAX_FILMSTRIP:
        raise TorchspliceError(f"{{frames}} must be from 1 to {MAX_FILMSTRIP} (a filmstrip's columns), got {frames}",
                               options=("frames",))
    if dpi is None:
        dpi = GIF_DPI if suffix == ".gif" else 100
    if not size > 0 or not dpi > 0:
        raise TorchspliceError(f"size and dpi must be positive, got size={size}, dpi={dpi}")
    if max_seconds is not None and not max_seconds > 0:
        raise TorchspliceError(f"max_seconds must be positive, got {max_seconds}")

    prepared = []
    for g in groups:
        lead = prepare_clip(_truncate(g[0], max_seconds), up, azimuth, elevation, camera)
        prepared.append([lead] + [prepare_clip(_truncate(m, max_seconds), up, azimuth, elevation, camera, leader=lead)
                                  for m in g[1:]])
    clips = [g[0] for g in prepared]
    scene = make_scene(prepared, up, float(size))
    rate = float(fps) if fps is not None else max(c.fps for c in clips)
    if suffix == ".gif":  # a rate GIF stores exactly: 100 / a whole number of hundredths
        rate = 100.0 / gif_delay(min(float(fps) if fps is not None else GIF_FPS, GIF_MAX_FPS))
    last = max((c.num_frames - 1) / c.fps for c in clips)  # time of the last frame of the longest clip

    def frame_of(c: Clip, t: float) -> tuple[int, bool]:
        f = int(round(t * c.fps))
        return min(f, c.num_frames - 1), f > c.num_frames - 1

    with atomic_path(output) as tmp:
        if suffix == ".png":
            n_cols = int(frames)
            fig, cells = filmstrip_figure(scene, prepared, titles, n_cols, int(dpi))
            try:
                for row, c in zip(cells, clips):
                    for panel, f in zip(row, filmstrip_frames(c.num_frames, n_cols)):
                        panel.show(int(f))
                fig.savefig(tmp, format="png", dpi=int(dpi))
            finally:
                release(fig)
        else:
            n_out = int(math.floor(last * rate + 1e-6)) + 1
            fig, panels, clock = animation_figure(scene, prepared, titles, int(dpi), grid_dots=suffix == ".gif")
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
                writer.setup(fig, str(tmp), int(dpi))
                done = False
                try:
                    for k in range(n_out):
                        t = k / rate
                        canvas.restore_region(background)
                        for p in panels:
                            p.show(*frame_of(p.clip, t))
                            p.blit()
                        clock.set_text(f"{t:.2f} s   frame {k}" if same_rate else f"{t:.2f} s")
                        fig.draw_artist(clock)
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
    return output
