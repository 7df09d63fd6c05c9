"""Drawing: the panels of a picture, their shared scene (limits and scale), the floor grid, the
root's trail, the bones and the head, the titles, the time labels and the side colours' legend,
on an Agg figure (no pyplot, no display).

Each clip gets a panel: its bones as line segments from parent to child (end sites included),
left limbs blue and right limbs red (:mod:`torchsplice.viz.style`), a head circle, a ground grid
on the floor plane and a short trail (:data:`TRAIL_SECONDS`) of the root's recent path on the
floor. The grid is fixed in the world, so it slides under a walking figure. Drawing a frame only
sets the data of a few ``Line2D`` artists (:meth:`Panel.show`).

Units: screen coordinates in the clips' file units, relative to each clip's camera centre
(:class:`~torchsplice.viz.camera.Clip`); a :class:`Scene`'s limits in reference units (times a
panel's scale); figure sizes and the layout constants (:data:`TITLE_H`, :data:`LABEL_H`,
:data:`MARGIN`, :data:`LEGEND_H`) in inches.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from .camera import Clip, canonical_axes
from .style import CENTER, COLORS, DOT_COLOR, ENDED_ALPHA, GHOST_COLOR, GRID_COLOR, LEFT, RIGHT, TRAIL_COLOR

__all__ = ["Scene", "make_scene", "grid_lines", "grid_crossings", "Panel", "new_figure", "legend", "fit_title",
           "animation_figure", "filmstrip_figure", "release", "TITLE_H", "LABEL_H", "MARGIN", "LEGEND_H",
           "TRAIL_SECONDS"]

TRAIL_SECONDS = 2.0
"""Seconds of the root's path on the floor that a panel's trail shows."""


def _nice(x: float) -> float:
    """The largest of 1, 2, 5 times a power of ten not above ``x`` (``x > 0``)."""
    e = 10.0 ** math.floor(math.log10(x))
    return max(m * e for m in (1.0, 2.0, 5.0) if m * e <= x * (1 + 1e-9))


@dataclass
class Scene:
    """What the panels share: fixed limits, grid layout, panel size.

    Limits and grid sizes are in *reference units*: panel ``i`` shows them times
    ``scale[i]`` in its clip's own units. ``scale`` is all ones (one scale for every panel,
    so sizes and speeds compare) unless the skeletons differ in size by more than a factor
    of 1.5 (other units, e.g. CMU's against centimetres); then each panel is scaled by its
    own skeleton's :meth:`~torchsplice.core.skeleton.Skeleton.size`.
    """

    up: int
    xlim: tuple[float, float]
    ylim: tuple[float, float]
    height: float  # the tallest figure (reference units): sets the grid spacing
    reach: float  # grid half-width around the camera centre (reference units)
    panel_w: float  # inches
    panel_h: float
    scale: list[float]


def make_scene(panels: list[list[Clip]], up: int, size: float) -> Scene:
    """Shared limits: every clip's every frame fits, equal aspect, a margin of floor in front.
    ``panels``: per panel its clips, the first leading (its size sets the panel's scale)."""
    sizes = [p[0].size for p in panels]
    scale = [1.0] * len(panels) if max(sizes) <= 1.5 * min(sizes) else sizes
    H = max(c.height / k for p, k in zip(panels, scale) for c in p)
    xs, ys = [np.zeros(1)], [np.zeros(1)]
    for c, k in ((c, k) for p, k in zip(panels, scale) for c in p):
        pts = c.screen[:, c.drawn] / k
        ok = np.isfinite(pts).all(-1)
        xs.append(pts[..., 0][ok])
        ys.append(pts[..., 1][ok])
        if c.head is not None:  # the head circle's outline
            r = 0.5 * c.head_size / k
            hd = c.head[np.isfinite(c.head).all(-1)] / k
            xs += [hd[:, 0] - r, hd[:, 0] + r]
            ys += [hd[:, 1] - r, hd[:, 1] + r]
    xs, ys = np.concatenate(xs), np.concatenate(ys)
    half_w = max(float(np.abs(xs).max()) + 0.08 * H, 0.45 * H)
    y0 = min(float(ys.min()), 0.0) - 0.15 * H
    y1 = max(float(ys.max()), 0.0) + 0.06 * H
    # panel shape follows the data, within reason; then widen the short side to match
    ratio = min(max((y1 - y0) / (2 * half_w), 0.75), 1.6)
    panel_w, panel_h = size, size * ratio
    if (y1 - y0) / (2 * half_w) > ratio:
        half_w = (y1 - y0) / ratio / 2
    else:
        extra = 2 * half_w * ratio - (y1 - y0)
        y0, y1 = y0 - 0.5 * extra, y1 + 0.5 * extra
    reach = 2.5 * max(half_w, y1 - y0)
    return Scene(up=up, xlim=(-half_w, half_w), ylim=(y0, y1), height=H, reach=reach,
                  panel_w=panel_w, panel_h=panel_h, scale=[float(k) for k in scale])


def grid_lines(scene: Scene, clip: Clip, f: int, k: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """World-fixed floor grid lines near the camera centre at frame ``f``, screen coordinates
    relative to the camera, NaN-separated (two arrays ``x``, ``y``); ``k``: the panel's scale.

    The spacing is a round number near half the tallest figure's height (1 m for people in
    centimetres); the lines are fixed in the world, so they slide as the camera follows.
    """
    R = k * scene.reach
    s = max(_nice(k * scene.height / 1.75), _nice(R / 30))  # at most ~60 lines each way
    c = clip.floor_center[f]
    out = []
    for a in (0, 1):  # lines of constant e_a, running along the other axis
        n_lo, n_hi = math.ceil((c[a] - R) / s), math.floor((c[a] + R) / s)
        k_lines = np.arange(n_lo, n_hi + 1)
        seg = np.zeros((len(k_lines), 3, 3))  # (line, start/end/NaN, (e1, e2, up))
        seg[:, :2, a] = (k_lines * s - c[a])[:, None]
        seg[:, 0, 1 - a], seg[:, 1, 1 - a] = -R, R
        seg[:, 2] = np.nan
        out.append(seg.reshape(-1, 3))
    canon = np.concatenate(out)
    world = np.zeros_like(canon)
    world[:, canonical_axes(scene.up)] = canon
    xy = world @ clip.view[f].T
    return xy[:, 0], xy[:, 1]


def grid_crossings(scene: Scene, clip: Clip, f: int, k: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The crossings of :func:`grid_lines`' lines, as points ``x``, ``y`` (screen, relative to
    the camera at frame ``f``): the same world-fixed grid, drawn as dots."""
    R = k * scene.reach
    s = max(_nice(k * scene.height / 1.75), _nice(R / 30))
    c = clip.floor_center[f]
    a = [np.arange(math.ceil((c[i] - R) / s), math.floor((c[i] + R) / s) + 1) * s - c[i] for i in (0, 1)]
    A, B = np.meshgrid(a[0], a[1], indexing="ij")
    canon = np.stack([A.ravel(), B.ravel(), np.zeros(A.size)], axis=-1)
    world = np.zeros_like(canon)
    world[:, canonical_axes(scene.up)] = canon
    xy = world @ clip.view[f].T
    return xy[:, 0], xy[:, 1]


class Panel:
    """One axes showing one clip (and ``others`` over it, in grey, at the same times);
    :meth:`show` puts frame ``f`` on it by setting line data.

    With ``animated=True`` the moving artists are left out of a full draw: the animation
    draws the static background once and blits them over it each frame (:meth:`blit`).
    """

    def __init__(self, fig, rect, scene: Scene, clip: Clip, k: float, title: str | None, animated: bool,
                 grid_dots: bool = False, others: Sequence[Clip] = ()):
        self.scene, self.clip, self.k = scene, clip, k
        ax = fig.add_axes(rect)
        ax.set_xlim(k * scene.xlim[0], k * scene.xlim[1])
        ax.set_ylim(k * scene.ylim[0], k * scene.ylim[1])
        ax.set_aspect("equal", adjustable="box")
        ax.set_axis_off()
        ax.add_patch(Rectangle((0, 0), 1, 1, transform=ax.transAxes, facecolor="white", edgecolor="#b5b5b5",
                               lw=0.8, zorder=0, clip_on=False))
        self.ax = ax
        self.grid_dots = grid_dots
        if grid_dots:  # the grid's crossings only (a GIF: moving lines would triple the file)
            self.grid = ax.add_line(Line2D([], [], ls="none", marker="o", markersize=2.5, markeredgewidth=0,
                                           markerfacecolor=DOT_COLOR, zorder=1))
        else:
            self.grid = ax.add_line(Line2D([], [], color=GRID_COLOR, lw=0.7, zorder=1))
        self.trail = ax.add_line(Line2D([], [], color=TRAIL_COLOR, lw=1.8, zorder=2, solid_capstyle="round"))
        lw = max(1.2, min(2.6, 0.9 * scene.panel_w))
        self.bones = []
        for side, idx in clip.lines.items():
            ln = Line2D([], [], color=COLORS[side], lw=lw, zorder=4 if side == CENTER else 3, marker="o",
                        markersize=lw * 1.3, markeredgewidth=0, solid_capstyle="round", solid_joinstyle="round")
            self.bones.append((ax.add_line(ln), idx))
        self.others = []
        for o in others:  # every bone of a further clip in one grey line, under the first clip's
            idx = np.concatenate(list(o.lines.values())) if o.lines else np.zeros(0, dtype=np.int64)
            ln = Line2D([], [], color=GHOST_COLOR, lw=lw, zorder=2.5, marker="o", markersize=lw * 1.3,
                        markeredgewidth=0, solid_capstyle="round", solid_joinstyle="round")
            self.others.append((ax.add_line(ln), idx, o))
        self.head = None
        if clip.head is not None:
            ppu = 72.0 * scene.panel_h / (k * (scene.ylim[1] - scene.ylim[0]))  # points per data unit
            self.head = ax.add_line(Line2D([], [], ls="none", marker="o", markersize=max(3.0, clip.head_size * 0.95 * ppu),
                                           markerfacecolor="white", markeredgecolor=COLORS[CENTER],
                                           markeredgewidth=0.8 * lw, zorder=6))
        x0, y0, w, h = rect
        if title is not None:
            text, size = fit_title(title, scene.panel_w)
            fig.text(x0 + w / 2, y0 + h + 0.02 * h, text, ha="center", va="bottom", fontsize=size, linespacing=1.0)
        # the filmstrip labels every cell with its time; the animation draws one time label for
        # the whole figure (text is the costliest artist to draw) and "(end)" under a held clip
        self.label = fig.text(x0 + w / 2, y0 - 0.015 * h, "" if not animated else "(end)", ha="center", va="top",
                              fontsize=8, color="#444444")
        self.animated = animated
        self.moving = ([self.grid, self.trail] + [ln for ln, _, _ in self.others] + [ln for ln, _ in self.bones]
                       + ([self.head] if self.head else []))
        for a in self.moving + [self.label]:
            a.set_animated(animated)
        self.held = False
        self._trail_frames = max(1, int(round(TRAIL_SECONDS * clip.fps)))

    def show(self, f: int, held: bool = False) -> None:
        """Set every moving artist to frame ``f`` (``held``: past the clip's end, for the label)."""
        c = self.clip
        gx, gy = (grid_crossings if self.grid_dots else grid_lines)(self.scene, c, f, self.k)
        self.grid.set_data(gx, gy)
        tr = (c.root[max(0, f - self._trail_frames):f + 1] - c.center[f]) @ c.view[f].T
        self.trail.set_data(tr[:, 0], tr[:, 1])
        pts = c.screen[f]
        for ln, idx in self.bones:
            xy = pts[idx]
            ln.set_data(xy[:, 0], xy[:, 1])
        if self.head is not None:
            self.head.set_data(c.head[f, :1], c.head[f, 1:])
        for ln, idx, o in self.others:  # resampled to this clip's frames (:func:`prepare_clip`)
            xy = o.screen[f][idx]
            ln.set_data(xy[:, 0], xy[:, 1])
        if held != self.held:  # past its end the clip holds its last frame, faded
            for ln, _ in self.bones:
                ln.set_alpha(ENDED_ALPHA if held else None)
            if self.head is not None:
                self.head.set_alpha(ENDED_ALPHA if held else None)
        self.held = held
        if not self.animated:
            self.label.set_text(f"{f / c.fps:.2f} s  frame {f}")

    def blit(self) -> None:
        """Draw the moving artists onto the canvas (after the background was restored)."""
        for a in self.moving:
            self.ax.draw_artist(a)
        if self.held:
            self.ax.figure.draw_artist(self.label)


def new_figure(width_in: float, height_in: float, dpi: int):
    """An Agg figure sized to whole, even pixel counts (video encoders need even sizes)."""
    w_px = 2 * max(1, math.ceil(width_in * dpi / 2))
    h_px = 2 * max(1, math.ceil(height_in * dpi / 2))
    fig = Figure(figsize=(w_px / dpi, h_px / dpi), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    return fig


# Layout, inches
TITLE_H = 0.32
LABEL_H = 0.24
MARGIN = 0.08
LEGEND_H = 0.2  # a band at the top for the side colours' legend


def legend(fig, x_in: float, y_in: float, grey: bool = False) -> None:
    """The side colours, left to right from (``x_in``, ``y_in``) inches: a short bone of each
    colour and its name ("left side", "right side": the character's own); with ``grey``, the
    colour of the clips drawn over another ("over it": named in the panel's title)."""
    W, H = fig.get_size_inches()
    x = x_in
    keys = [(COLORS[LEFT], "left side"), (COLORS[RIGHT], "right side")]
    for color, text in keys + ([(GHOST_COLOR, "drawn over it")] if grey else []):
        fig.add_artist(Line2D([x / W, (x + 0.22) / W], [y_in / H, y_in / H], transform=fig.transFigure,
                              color=color, lw=2.2, solid_capstyle="round"))
        fig.text((x + 0.28) / W, y_in / H, text, ha="left", va="center", fontsize=8, color="#666666")
        x += 1.05


def fit_title(title: str, width_in: float, size: int = 10) -> tuple[str, int]:
    """``(text, font size)`` of a panel's title that fits ``width_in`` inches: as it is when it
    fits; else on two lines in a smaller font, broken after a ``+`` (a spliced clip's sources) or
    a space where there is one, each line shortened in its middle (``dataset-2_walk…normal_025``)
    if it is still too long, so that neighbouring titles never overlap."""
    def per_line(points: int) -> int:
        return max(6, int(width_in * 72.0 / (0.6 * points)))

    if len(title) <= per_line(size):
        return title, size
    small = max(6, size - 2)
    room = per_line(small)
    cut = max((title.rfind(c, 0, len(title) // 2 + room // 2) for c in "+ "), default=-1)
    lines = [title[:cut + 1], title[cut + 1:]] if 0 < cut < len(title) - 1 else [title]
    if len(lines) == 1 and len(title) > room:
        lines = [title[:len(title) // 2], title[len(title) // 2:]]

    def shorten(line: str) -> str:
        if len(line) <= room:
            return line
        keep = room - 1
        return line[:(keep + 1) // 2] + "\u2026" + line[len(line) - keep // 2:]

    return "\n".join(shorten(line.strip()) for line in lines), small


def animation_figure(scene: Scene, groups: list[list[Clip]], titles: list[str], dpi: int, grid_dots: bool = False):
    """One row of panels, a title above and a time label under each, the side colours' legend."""
    n = len(groups)
    gap = 0.1
    W = n * scene.panel_w + (n + 1) * gap
    Hh = scene.panel_h + TITLE_H + 2 * LABEL_H + MARGIN + LEGEND_H
    fig = new_figure(W, Hh, dpi)
    W, Hh = fig.get_size_inches()
    panels = []
    for i, (group, title) in enumerate(zip(groups, titles)):
        rect = ((gap + i * (scene.panel_w + gap)) / W, (2 * LABEL_H + MARGIN / 2) / Hh, scene.panel_w / W, scene.panel_h / Hh)
        panels.append(Panel(fig, rect, scene, group[0], scene.scale[i], title, animated=True, grid_dots=grid_dots,
                             others=group[1:]))
    clock = fig.text(0.5, 0.04 / Hh, "", ha="center", va="bottom", fontsize=9, color="#333333", animated=True)
    legend(fig, gap, Hh - LEGEND_H / 2 - 0.02, grey=any(len(g) > 1 for g in groups))
    return fig, panels, clock


def filmstrip_figure(scene: Scene, groups: list[list[Clip]], titles: list[str], frames: int, dpi: int):
    """One row per panel (its title above the row), one column per frame shown, a time label under
    each, the side colours' legend at the top right."""
    n = len(groups)
    gap = 0.06
    row_h = TITLE_H + scene.panel_h + LABEL_H
    W = frames * scene.panel_w + (frames + 1) * gap
    Hh = n * row_h + MARGIN + LEGEND_H
    fig = new_figure(W, Hh, dpi)
    W, Hh = fig.get_size_inches()
    legend(fig, gap, Hh - LEGEND_H / 2 - 0.02, grey=any(len(g) > 1 for g in groups))
    cells = []
    for r, (group, title) in enumerate(zip(groups, titles)):
        clip = group[0]
        top = Hh - LEGEND_H - MARGIN / 2 - r * row_h
        fig.text(gap / W, (top - 0.04) / Hh, title, ha="left", va="top", fontsize=11, fontweight="bold")
        row = []
        for k in range(frames):
            rect = ((gap + k * (scene.panel_w + gap)) / W, (top - TITLE_H - scene.panel_h) / Hh,
                    scene.panel_w / W, scene.panel_h / Hh)
            row.append(Panel(fig, rect, scene, clip, scene.scale[r], None, animated=False, others=group[1:]))
        cells.append(row)
    return fig, cells


def release(fig) -> None:
    """Drop a figure's artists so its memory goes at once (it was never registered with pyplot)."""
    fig.clear()
