"""Writing the animations: the GIF writer (one fixed palette, frame delays GIF stores exactly) and
the MP4 writer (H.264 through ffmpeg), both taking the frame the canvas already holds (blitted),
not a fresh full draw; and what to do when ffmpeg fails part-way.

Units: frame rates in frames per second; GIF frame delays in hundredths of a second
(:func:`gif_delay`); resolutions in pixels per inch (:data:`GIF_DPI`). Frames are the Agg
canvas's RGBA buffer, ``height x width x 4`` bytes.
"""

from __future__ import annotations

import numpy as np
from matplotlib.animation import FFMpegWriter, PillowWriter
from matplotlib.colors import to_rgb

from .style import COLORS, GHOST_COLOR, GRID_COLOR, TEXT_COLORS, TRAIL_COLOR

__all__ = ["GIF_FPS", "GIF_DPI", "GIF_MAX_FPS", "gif_delay", "GifWriter", "MP4Writer", "ffmpeg_available",
           "make_writer", "ffmpeg_complaint", "abandon"]

GIF_MAX_FPS = 50.0
"""GIF frame delays are whole hundredths of a second and browsers slow down delays under two,
so a GIF plays at most 50 frames per second; faster clips (CMU's 120) are sampled down."""

GIF_FPS = 20.0
"""A GIF's default frame rate: its delay (5 hundredths) is exact in the format (30 fps is not
a whole number of hundredths: written as 3, it would play 11% fast), and it keeps a 10 s GIF
of four clips under 3 MB (see :data:`GIF_DPI`). Clips are sampled at it, each output frame
showing each clip's frame nearest its time."""

GIF_DPI = 80
"""A GIF's default pixels per inch (PNG and MP4: 100): with :data:`GIF_FPS` and the grid's
crossings as dots, a 10 s GIF of four clips at 30 fps is about 2.6 MB."""


def gif_delay(fps: float) -> int:
    """The GIF frame delay in hundredths of a second nearest to ``1 / fps``, at least 2
    (browsers slow down shorter delays); the GIF then plays at ``100 / delay`` fps."""
    return max(2, int(round(100.0 / fps)))


_PALETTE_LEVELS = 4
"""Blends of each ink with white and with the grid in quarters: antialiased edges take fewer
distinct colours, which GIF's LZW compresses better (10% smaller than eighths)."""


def _palette():
    """A fixed GIF palette: every colour drawn, blended with white and with the grid colour
    in eighths (antialiased edges), so frames map to it without per-frame quantising.

    Returns the palette image to map against and the ``768`` palette values to write.
    """
    from PIL import Image  # Pillow: imported where GIFs are made

    white, grid = np.ones(3), np.array(to_rgb(GRID_COLOR))
    inks = [np.array(to_rgb(c)) for c in (*COLORS.values(), GRID_COLOR, TRAIL_COLOR, GHOST_COLOR, *TEXT_COLORS)]
    entries = {(255, 255, 255)}
    for ink in inks:
        for a in np.linspace(1.0 / _PALETTE_LEVELS, 1.0, _PALETTE_LEVELS):
            for under in (white, grid):
                entries.add(tuple(int(round(255 * v)) for v in a * ink + (1 - a) * under))
    flat = [v for rgb in sorted(entries) for v in rgb][:768]
    flat += flat[:3] * (256 - len(flat) // 3)
    # Pillow maps a pixel to the entry nearest the lower corner of its 4x4x4 colour cell, so
    # pure white would go to a light grey; mapping against entries floored to their cells'
    # corners and then writing the true colours back keeps every drawn colour exact
    lookup = Image.new("P", (1, 1))
    lookup.putpalette([v & ~3 for v in flat])
    return lookup, flat


class GifWriter(PillowWriter):
    """PillowWriter that grabs the blitted canvas and maps it onto one fixed palette.

    Pillow's default quantises every frame on its own (~40 ms a frame); mapping onto the
    fixed palette of :func:`_palette` without dithering costs ~1 ms, suits flat line
    drawings, and keeps one byte a pixel in memory. The format is named, so the temporary
    file's name does not matter. GIF stores frame durations in hundredths of a second: 30 fps
    is written as 30 ms a frame (33.3 rounded to GIF's resolution).
    """

    def setup(self, fig, outfile, dpi=None):
        super().setup(fig, outfile, dpi=dpi)
        self._lookup, self._palette = _palette()

    def grab_frame(self, **savefig_kwargs):
        from PIL import Image

        w, h = self.fig.canvas.get_width_height()
        rgb = Image.frombuffer("RGBA", (w, h), bytes(self.fig.canvas.buffer_rgba()), "raw", "RGBA", 0, 1).convert("RGB")
        frame = rgb.quantize(palette=self._lookup, dither=Image.Dither.NONE)
        frame.putpalette(self._palette)
        self._frames.append(frame)

    def finish(self):
        # Pillow takes milliseconds and stores hundredths: a whole number of them, exactly
        self._frames[0].save(self.outfile, format="GIF", save_all=True, append_images=self._frames[1:],
                             duration=10 * gif_delay(self.fps), loop=0)


class MP4Writer(FFMpegWriter):
    """FFMpegWriter (H.264, yuv420p, MP4 named, so the temporary file's name does not matter)
    that pipes the blitted canvas instead of redrawing the figure."""

    def __init__(self, fps):
        super().__init__(fps=fps, codec="h264", extra_args=["-pix_fmt", "yuv420p", "-f", "mp4"])
        self.frame_format = "rgba"

    def grab_frame(self, **savefig_kwargs):
        self._proc.stdin.write(bytes(self.fig.canvas.buffer_rgba()))


def ffmpeg_available() -> bool:
    return FFMpegWriter.isAvailable()


def make_writer(suffix: str, fps: float):
    """The movie writer for ``suffix`` (``.gif`` or ``.mp4``) at ``fps`` frames per second."""
    return GifWriter(fps=fps) if suffix == ".gif" else MP4Writer(fps)


def ffmpeg_complaint(writer) -> str:
    """The last line ffmpeg wrote to its error stream, once it has exited."""
    proc = getattr(writer, "_proc", None)
    if proc is None:
        return "it stopped reading frames"
    try:
        _, err = proc.communicate(timeout=10)
    except Exception:  # noqa: BLE001 - a best effort for the message only
        return "it stopped reading frames"
    lines = (err or b"").decode("utf-8", "replace").strip().splitlines()
    return lines[-1] if lines else f"exit status {proc.returncode}"


def abandon(writer) -> None:
    """Stop a writer that failed part-way without finishing the file (the caller removes it)."""
    proc = getattr(writer, "_proc", None)  # ffmpeg, fed through a pipe
    if proc is not None and proc.poll() is None:
        proc.kill()
        proc.communicate()
    if hasattr(writer, "_frames"):
        writer._frames = []
