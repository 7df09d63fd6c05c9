"""Stick-figure previews of clips: an animated GIF or MP4, or a PNG filmstrip.

Each clip gets a panel: its bones as line segments from parent to child (end sites included:
head top, hands, toes), left limbs blue and right limbs red (by joint name), a head circle, a
ground grid on the floor plane and a short trail of the root's recent path on the floor.

Longer than 600 lines because it is one renderer: the camera, the panels' layout, the drawing
and the three writers share their state (the figure, the artists, the per-clip trajectories).

Camera and projection (:func:`view_rotation`, :func:`project`):

- The up axis comes from the dataset spec (``up_axis``: 0, 1 or 2 for X, Y or Z; 1 for every
  shipped dataset). Positions are taken in a right-handed frame ``(e1, e2, up)`` with
  ``e1 = (up+1) % 3`` and ``e2 = (up+2) % 3`` (for Y up: ``e1 = Z``, ``e2 = X``), so the
  picture is never mirrored.
- An orthographic view: the camera sits at ``azimuth`` degrees about the up axis from ``e1``
  (towards ``e2``) and ``elevation`` degrees above the floor, looking down at the character.
  The default (-55, 22) is an elevated three-quarter view: for Y up, from ``+Z`` and ``-X``,
  so the sample's characters, which face ``+Z`` with their left at ``+X``, are first seen
  from the front right. Up maps to screen up. With ``camera="heading"`` (the default) the
  camera turns about the up axis with the character's heading (the followed joint's yaw,
  smoothed over a second), so a curved walk or a turn stays seen from the same side as at
  its first frame and the grid turns under it; ``camera="world"`` keeps the direction fixed.
- The camera follows each clip's root in the floor plane (smoothed over half a second, so
  the gait's side-to-side sway stays visible; for a skeleton whose root stays on the ground
  and whose child is animated, like Bandai Namco's ``joint_Root`` and ``Hips``, it follows
  the child) and looks at the floor below it; the floor height is the lowest point a clip
  reaches. The grid is fixed in the world, so it slides under a walking figure, and a trail
  shows the last two seconds of the root's path on the floor.
- The scale is fixed over time and equal in x and y. Panels share one scale, so sizes and
  speeds compare, unless the skeletons differ in size by more than a factor of 1.5 (other
  units); then each panel is scaled to its own skeleton.

A panel may hold several clips drawn over each other (``motions`` entries that are sequences):
the first in the side colours, the camera its; the others in grey, at the same times, seen
from the first's camera (e.g. a naive result over the splice, as in the paper's Figure 4).

Forward kinematics runs once per clip, vectorised over frames; drawing a frame only sets the
data of a few ``Line2D`` artists. An animation plays in real time to the longest clip; a
shorter clip stops at its last frame, drawn faded (opacity :data:`_ENDED_ALPHA`) with
``(end)`` under it. A filmstrip row spans its own clip (:func:`filmstrip_frames`), so every
column shows another frame of it. Left and right are named in a legend above the panels.
GIFs default to :data:`GIF_FPS` and :data:`GIF_DPI` and draw the grid's crossings as dots
(lines sliding under a followed figure would make most of the file). Figures are made with :class:`matplotlib.figure.Figure` on the Agg canvas
directly (no pyplot, no display, no global backend switch) and are released when done. Every
output is written atomically (:func:`~torchsplice.store.atomic.atomic_path`).
"""

from __future__ import annotations

import math
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from matplotlib.animation import FFMpegWriter, PillowWriter

from ..core.errors import TorchspliceError
from ..core.motion import Motion
from ..store.atomic import atomic_path
from ..core.fk import end_site_positions, forward_kinematics

__all__ = ["render", "project", "view_rotation", "SUPPORTED_SUFFIXES", "CAMERAS"]

SUPPORTED_SUFFIXES = (".gif", ".mp4", ".png")
"""Output types :func:`render` writes, chosen by the output's suffix."""

DEFAULT_AZIMUTH = -55.0
DEFAULT_ELEVATION = 22.0
CAMERAS = ("heading", "world")
"""How the camera turns: with the character's heading, or never (it follows the root in both)."""

_CENTER, _LEFT, _RIGHT = 0, 1, 2
_COLORS = {_CENTER: "#2b2b2b", _LEFT: "#1f6fb4", _RIGHT: "#d0342c"}
_GRID_COLOR = "#cfd3d8"
_DOT_COLOR = "#a9b0b8"  # the grid's crossings in a GIF, a little darker than its lines
_TRAIL_COLOR = "#8fb9d9"
_GHOST_COLOR = "#9b9b9b"  # the further clips of an overlay panel
_FOLLOW_SECONDS = 0.5  # smoothing window of the follow camera
_HEADING_SECONDS = 1.0  # smoothing window of the heading camera (a gait's twist averages out)
_TRAIL_SECONDS = 2.0


# ---------------------------------------------------------------------------------------------
# Projection
# ---------------------------------------------------------------------------------------------


def check_up_axis(up_axis) -> int:
    """0, 1 or 2 from an index or a name (``"x"``, ``"y"``, ``"z"``, as dataset specs spell it)."""
    if isinstance(up_axis, str) and up_axis.lower() in ("x", "y", "z"):
        return "xyz".index(up_axis.lower())
    if isinstance(up_axis, bool) or up_axis not in (0, 1, 2):
        raise TorchspliceError(f"up_axis must be 0, 1 or 2 (or 'x', 'y', 'z'), got {up_axis!r}")
    return int(up_axis)


def canonical_axes(up_axis: int) -> list[int]:
    """Indices ``[e1, e2, up]`` of a right-handed frame with ``up`` last."""
    return [(up_axis + 1) % 3, (up_axis + 2) % 3, up_axis]


def view_rotation(up_axis: int = 1, azimuth: float = DEFAULT_AZIMUTH, elevation: float = DEFAULT_ELEVATION) -> np.ndarray:
    """The fixed view as a ``(3, 3)`` float64 rotation whose rows are world directions.

    Row 0 is the screen's right, row 1 the screen's up, row 2 points from the scene towards
    the camera (right-handed: ``row0 x row1 = row2``), all in the file's world coordinates.
    The camera direction (row 2) is ``(cos el cos az, cos el sin az, sin el)`` in the frame
    ``(e1, e2, up)`` of the module docstring; with ``elevation = 0`` the up axis is exactly the
    screen's up, and for ``0 < elevation < 90`` it still projects straight up the screen.
    """
    up = check_up_axis(up_axis)
    az, el = math.radians(azimuth), math.radians(elevation)
    ca, sa, ce, se = math.cos(az), math.sin(az), math.cos(el), math.sin(el)
    canon = np.array([
        [-sa, ca, 0.0],             # right
        [-se * ca, -se * sa, ce],   # up
        [ce * ca, ce * sa, se],     # towards the camera
    ])
    rot = np.zeros((3, 3))
    rot[:, canonical_axes(up)] = canon  # columns back in the file's axis order
    return rot


def view_rotations(up_axis: int, azimuth: np.ndarray, elevation: float = DEFAULT_ELEVATION) -> np.ndarray:
    """:func:`view_rotation` for each of ``(T,)`` azimuths (degrees): ``(T, 3, 3)`` float64."""
    up = check_up_axis(up_axis)
    az, el = np.radians(np.asarray(azimuth, dtype=np.float64)), math.radians(elevation)
    ca, sa, ce, se = np.cos(az), np.sin(az), math.cos(el), math.sin(el)
    zero = np.zeros_like(ca)
    canon = np.stack([
        np.stack([-sa, ca, zero], -1),
        np.stack([-se * ca, -se * sa, zero + ce], -1),
        np.stack([ce * ca, ce * sa, zero + se], -1),
    ], -2)
    rot = np.zeros(canon.shape)
    rot[..., canonical_axes(up)] = canon
    return rot


def heading_yaw(rotations: np.ndarray, up_axis: int) -> np.ndarray:
    """``(T,)`` unwrapped yaw in radians about the up axis of ``(T, 4)`` world rotations (WXYZ):
    the angle of each rotation's twist about that axis (swing-twist), continuous over frames. A
    frame whose rotation is not finite holds the yaw of the last finite frame before it (frames
    before the first finite one take its yaw; all 0 where none is finite)."""
    q = np.asarray(rotations, dtype=np.float64)
    if q.ndim != 2 or q.shape[-1] != 4:
        raise ValueError(f"rotations must be (T, 4), got {q.shape}")
    yaw = 2.0 * np.arctan2(q[:, 1 + check_up_axis(up_axis)], q[:, 0])
    ok = np.isfinite(yaw)
    if not ok.any():
        return np.zeros_like(yaw)
    last = np.maximum.accumulate(np.where(ok, np.arange(len(yaw)), int(np.argmax(ok))))  # the last finite frame
    return np.unwrap(yaw[last])


def project(points, up_axis: int = 1, azimuth: float = DEFAULT_AZIMUTH, elevation: float = DEFAULT_ELEVATION) -> np.ndarray:
    """Orthographic screen coordinates ``(..., 2)`` (x right, y up; file units) of ``(..., 3)`` points.

    ``points`` may be a numpy array or a torch tensor in the file's axes and units; the result
    is float64 numpy. The projection is linear, so translating the points translates the
    screen positions (the follow camera subtracts the projected camera centre).
    """
    if isinstance(points, torch.Tensor):
        points = points.detach().cpu().double().numpy()
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise ValueError(f"points must be (..., 3), got {p.shape}")
    return p @ view_rotation(up_axis, azimuth, elevation)[:2].T


# ---------------------------------------------------------------------------------------------
# Per-clip geometry (computed once, vectorised over frames)
# ---------------------------------------------------------------------------------------------


def _side(name: str) -> int:
    """Left, right or centre from a joint name (``LeftArm``, ``l_hip``, ``RHand``, ``hand_r`` ...)."""
    low = name.lower()
    if "left" in low:
        return _LEFT
    if "right" in low:
        return _RIGHT
    m = re.search(r"(?:^|[_:.\s])([LlRr])(?:[A-Z0-9_.:\s]|$)", name)
    if m:
        return _LEFT if m.group(1) in "Ll" else _RIGHT
    return _CENTER


def _nice(x: float) -> float:
    """The largest of 1, 2, 5 times a power of ten not above ``x`` (``x > 0``)."""
    e = 10.0 ** math.floor(math.log10(x))
    return max(m * e for m in (1.0, 2.0, 5.0) if m * e <= x * (1 + 1e-9))


def _moving_average(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average along axis 0 of ``(T, ...)``, edges padded with the end values."""
    if width <= 1 or x.shape[0] < 2:
        return x.copy()
    h = width // 2
    pad = np.concatenate([np.repeat(x[:1], h, 0), x, np.repeat(x[-1:], h, 0)])
    c = np.cumsum(np.concatenate([np.zeros_like(x[:1]), pad]), axis=0)
    return (c[2 * h + 1:] - c[:-2 * h - 1]) / (2 * h + 1)


@dataclass
class _Clip:
    """One clip, ready to draw. Screen coordinates are relative to the follow camera.

    ``screen``: ``(T, P + 1, 2)`` joints then end sites, the last row NaN (a line break);
    ``lines``: per side, an index array into ``P + 1`` (``a, b, NaN, a, b, NaN, ...``);
    ``head``: ``(T, 2)`` head circle centre or ``None``; ``head_size``: its diameter (units);
    ``root``: ``(T, 3)`` the floor point under the followed joint (world);
    ``center``: ``(T, 3)`` the camera centre (world, on the floor); ``view``: ``(T, 2, 3)``
    the screen's right and up at each frame (world directions; see :func:`view_rotation`);
    ``floor_center``: ``(T, 2)`` the camera centre in the floor plane ``(e1, e2)``; ``floor``:
    the floor's height;
    ``height``: the figure's greatest height above the floor (at least a quarter of the
    skeleton's size, for a figure lying flat); ``size``: the skeleton's size
    (units); ``drawn``: indices of the points that some bone uses.
    """

    name: str
    fps: float
    screen: np.ndarray
    lines: dict[int, np.ndarray]
    head: np.ndarray | None
    head_size: float
    root: np.ndarray
    center: np.ndarray
    view: np.ndarray
    floor_center: np.ndarray
    floor: float
    height: float
    size: float
    drawn: np.ndarray

    @property
    def num_frames(self) -> int:
        return self.screen.shape[0]


def head_joint(sk, pts: np.ndarray, up: int) -> tuple[np.ndarray | None, float]:
    """The head circle: centres ``(T, 3)`` (world) and diameter, or ``(None, 0)``.

    The head is the first centre joint named like ``head`` (else the joint under the end
    site highest in the rest pose). With an end site of some length (the sample's head top)
    the circle sits on that bone, as wide as it is long; with none or a zero-length one (Bandai
    Namco, LAFAN1) it sits on top of the joint, continuing the neck, 0.09 skeleton sizes wide.
    """
    J = sk.num_joints
    names = [n.lower() for n in sk.names]
    cand = [j for j in range(1, J) if "head" in names[j] and "end" not in names[j] and _side(sk.names[j]) == _CENTER]
    if cand:
        h = cand[0]
    elif sk.end_site_parents:
        _, rest_ends = sk.rest_positions()
        h = sk.end_site_parents[int(torch.argmax(rest_ends[:, up]))]
        if _side(sk.names[h]) != _CENTER or h == 0:
            return None, 0.0
    else:
        return None, 0.0
    ends = [e for e, p in enumerate(sk.end_site_parents) if p == h]
    lengths = [float(sk.end_site_offsets[e].norm()) for e in ends]
    if lengths and max(lengths) > 0.03 * sk.size():
        e = ends[int(np.argmax(lengths))]
        return 0.5 * (pts[:, h] + pts[:, J + e]), 0.95 * max(lengths)
    d = 0.09 * sk.size()
    along = pts[:, h] - pts[:, sk.parents[h]]
    norm = np.linalg.norm(along, axis=-1, keepdims=True)
    unit = np.where(norm > 1e-9, along / np.where(norm > 1e-9, norm, 1.0), 0.0)
    return pts[:, h] + 0.5 * d * unit, d


@dataclass
class Figure3D:
    """A clip's points in the world and the bones between them, as the pictures draw them.

    ``points``: ``(T, P, 3)`` float64 world positions in file units and axes, joints
    ``0..J-1`` then end sites (head top, hands, toes); ``lines``: per side (0 centre, 1 left,
    2 right), an index array ``a, b, P, a, b, P, ...`` into the points, ``P`` a line break;
    ``follow``: the joint whose floor path is the character's (the root, or a root child with
    animated translation such as Bandai Namco's ``Hips`` under ``joint_Root``); ``drawn``:
    indices of the points some bone uses; ``follow_rotation``: ``(T, 4)`` the followed joint's
    world rotation (WXYZ), whose yaw the heading camera turns with.
    """

    points: np.ndarray
    lines: dict[int, np.ndarray]
    follow: int
    drawn: np.ndarray
    follow_rotation: np.ndarray | None = None


def figure_points(motion: Motion) -> Figure3D:
    """Forward kinematics once for the whole clip (vectorised over frames) and its bones by side.

    Bones run parent -> joint and joint -> end site, coloured by the side of the joint's name
    (:func:`_side`); a root child with animated translation is a trajectory, not a bone.
    """
    sk = motion.skeleton
    rot = motion.rotations.detach().to("cpu", torch.float64)
    root_t = motion.root_translation.detach().to("cpu", torch.float64)
    trans = None if motion.translations is None else motion.translations.detach().to("cpu", torch.float64)
    pos, grot = forward_kinematics(rot, root_t, sk.offsets, sk.parents, trans)
    if sk.end_site_parents:
        ends = end_site_positions(pos, grot, sk.end_site_parents, sk.end_site_offsets)
        pts = torch.cat([pos, ends], dim=1).numpy()
    else:
        pts = pos.numpy()
    P = pts.shape[1]
    J = sk.num_joints
    animated = sk.translation_animated
    skip_bone = [c for c in sk.children(0) if animated[c]]  # a trajectory, not a bone
    follow = skip_bone[0] if skip_bone else 0
    segs: dict[int, list[int]] = {_CENTER: [], _LEFT: [], _RIGHT: []}
    for j in range(1, J):
        if j not in skip_bone:
            segs[_side(sk.names[j])] += [sk.parents[j], j, P]
    for e, p in enumerate(sk.end_site_parents):
        segs[_side(sk.names[p])] += [p, J + e, P]
    lines = {k: np.asarray(v, dtype=np.int64) for k, v in segs.items() if v}
    drawn = np.unique(np.concatenate(list(lines.values())))[:-1] if lines else np.array([follow])
    return Figure3D(points=pts, lines=lines, follow=follow, drawn=drawn, follow_rotation=grot[:, follow].numpy())


def _at_times(n: int, fps: float, leader: _Clip) -> np.ndarray:
    """``(leader's frames,)`` the frame of a clip of ``n`` frames at ``fps`` nearest each of the
    leader's frames' times (held at its last)."""
    return np.minimum(np.rint(np.arange(leader.num_frames) / leader.fps * fps).astype(np.int64), n - 1)


def _prepare(motion: Motion, up: int, azimuth: float, elevation: float, camera: str,
             leader: _Clip | None = None) -> _Clip:
    """Forward kinematics once for the whole clip, then everything drawing needs, as numpy.
    With ``leader``, the clip is resampled to the leader's frames (its frame nearest each of
    their times, held at its end; nothing past the leader's end) and seen from the leader's
    camera at each (an overlay)."""
    sk = motion.skeleton
    fig3 = figure_points(motion)
    pts, lines, follow, drawn = fig3.points, fig3.lines, fig3.follow, fig3.drawn
    fps = motion.fps
    if leader is not None:
        pts, fps = pts[_at_times(pts.shape[0], fps, leader)], leader.fps
    T = pts.shape[0]
    axes = canonical_axes(up)

    height = pts[:, drawn, up]
    finite = np.isfinite(height)
    floor = float(np.min(height[finite])) if finite.any() else 0.0
    top = float(np.max(height[finite])) if finite.any() else floor + 1.0

    floor_xy = pts[:, follow][:, axes[:2]]  # (T, 2) in (e1, e2)
    floor_xy = np.where(np.isfinite(floor_xy), floor_xy, 0.0)
    root3 = np.zeros((T, 3))
    root3[:, axes[0]], root3[:, axes[1]] = floor_xy[:, 0], floor_xy[:, 1]
    if leader is not None:
        cam3, view, smooth = leader.center, leader.view, leader.floor_center
        root3[:, up] = cam3[:, up]
    else:
        smooth = _moving_average(floor_xy, max(1, int(round(_FOLLOW_SECONDS * motion.fps))) | 1)
        cam3 = np.zeros((T, 3))
        cam3[:, axes[0]], cam3[:, axes[1]], cam3[:, up] = smooth[:, 0], smooth[:, 1], floor
        root3[:, up] = floor
        az = np.full(T, float(azimuth))
        if camera == "heading" and fig3.follow_rotation is not None and T > 1:
            yaw = heading_yaw(fig3.follow_rotation, up)
            yaw = _moving_average(yaw[:, None], max(1, int(round(_HEADING_SECONDS * motion.fps))) | 1)[:, 0]
            az = az + np.degrees(yaw - yaw[0])
        view = view_rotations(up, az, elevation)[:, :2]  # (T, 2, 3)

    scr = np.einsum("tpk,tik->tpi", pts - cam3[:, None], view)  # (T, P, 2), relative to the camera centre
    screen = np.concatenate([scr, np.full((T, 1, 2), np.nan)], axis=1)

    head, head_size = head_joint(sk, pts, up)
    if head is not None:
        head = np.einsum("tk,tik->ti", head - cam3, view)
    return _Clip(
        name=motion.name, fps=fps, screen=screen, lines=lines, head=head, head_size=head_size,
        root=root3, center=cam3, view=view, floor_center=smooth, floor=floor,
        height=max(top - floor, 0.25 * sk.size(), 1e-9), size=max(sk.size(), 1e-9), drawn=drawn,
    )


# ---------------------------------------------------------------------------------------------
# Drawing
# ---------------------------------------------------------------------------------------------


@dataclass
class _Scene:
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


def _scene(panels: list[list[_Clip]], up: int, size: float) -> _Scene:
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
    return _Scene(up=up, xlim=(-half_w, half_w), ylim=(y0, y1), height=H, reach=reach,
                  panel_w=panel_w, panel_h=panel_h, scale=[float(k) for k in scale])


def _grid_lines(scene: _Scene, clip: _Clip, f: int, k: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
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


def _grid_crossings(scene: _Scene, clip: _Clip, f: int, k: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The crossings of :func:`_grid_lines`' lines, as points ``x``, ``y`` (screen, relative to
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


class _Panel:
    """One axes showing one clip (and ``others`` over it, in grey, at the same times);
    :meth:`show` puts frame ``f`` on it by setting line data.

    With ``animated=True`` the moving artists are left out of a full draw: the animation
    draws the static background once and blits them over it each frame (:meth:`blit`).
    """

    def __init__(self, fig, rect, scene: _Scene, clip: _Clip, k: float, title: str | None, animated: bool,
                 grid_dots: bool = False, others: Sequence[_Clip] = ()):
        from matplotlib.lines import Line2D
        from matplotlib.patches import Rectangle

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
                                           markerfacecolor=_DOT_COLOR, zorder=1))
        else:
            self.grid = ax.add_line(Line2D([], [], color=_GRID_COLOR, lw=0.7, zorder=1))
        self.trail = ax.add_line(Line2D([], [], color=_TRAIL_COLOR, lw=1.8, zorder=2, solid_capstyle="round"))
        lw = max(1.2, min(2.6, 0.9 * scene.panel_w))
        self.bones = []
        for side, idx in clip.lines.items():
            ln = Line2D([], [], color=_COLORS[side], lw=lw, zorder=4 if side == _CENTER else 3, marker="o",
                        markersize=lw * 1.3, markeredgewidth=0, solid_capstyle="round", solid_joinstyle="round")
            self.bones.append((ax.add_line(ln), idx))
        self.others = []
        for o in others:  # every bone of a further clip in one grey line, under the first clip's
            idx = np.concatenate(list(o.lines.values())) if o.lines else np.zeros(0, dtype=np.int64)
            ln = Line2D([], [], color=_GHOST_COLOR, lw=lw, zorder=2.5, marker="o", markersize=lw * 1.3,
                        markeredgewidth=0, solid_capstyle="round", solid_joinstyle="round")
            self.others.append((ax.add_line(ln), idx, o))
        self.head = None
        if clip.head is not None:
            ppu = 72.0 * scene.panel_h / (k * (scene.ylim[1] - scene.ylim[0]))  # points per data unit
            self.head = ax.add_line(Line2D([], [], ls="none", marker="o", markersize=max(3.0, clip.head_size * 0.95 * ppu),
                                           markerfacecolor="white", markeredgecolor=_COLORS[_CENTER],
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
        self._trail_frames = max(1, int(round(_TRAIL_SECONDS * clip.fps)))

    def show(self, f: int, held: bool = False) -> None:
        """Set every moving artist to frame ``f`` (``held``: past the clip's end, for the label)."""
        c = self.clip
        gx, gy = (_grid_crossings if self.grid_dots else _grid_lines)(self.scene, c, f, self.k)
        self.grid.set_data(gx, gy)
        tr = (c.root[max(0, f - self._trail_frames):f + 1] - c.center[f]) @ c.view[f].T
        self.trail.set_data(tr[:, 0], tr[:, 1])
        pts = c.screen[f]
        for ln, idx in self.bones:
            xy = pts[idx]
            ln.set_data(xy[:, 0], xy[:, 1])
        if self.head is not None:
            self.head.set_data(c.head[f, :1], c.head[f, 1:])
        for ln, idx, o in self.others:  # resampled to this clip's frames (:func:`_prepare`)
            xy = o.screen[f][idx]
            ln.set_data(xy[:, 0], xy[:, 1])
        if held != self.held:  # past its end the clip holds its last frame, faded
            for ln, _ in self.bones:
                ln.set_alpha(_ENDED_ALPHA if held else None)
            if self.head is not None:
                self.head.set_alpha(_ENDED_ALPHA if held else None)
        self.held = held
        if not self.animated:
            self.label.set_text(f"{f / c.fps:.2f} s  frame {f}")

    def blit(self) -> None:
        """Draw the moving artists onto the canvas (after the background was restored)."""
        for a in self.moving:
            self.ax.draw_artist(a)
        if self.held:
            self.ax.figure.draw_artist(self.label)


def _new_figure(width_in: float, height_in: float, dpi: int):
    """An Agg figure sized to whole, even pixel counts (video encoders need even sizes)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    w_px = 2 * max(1, math.ceil(width_in * dpi / 2))
    h_px = 2 * max(1, math.ceil(height_in * dpi / 2))
    fig = Figure(figsize=(w_px / dpi, h_px / dpi), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    return fig


# Layout, inches
_TITLE_H = 0.32
_LABEL_H = 0.24
_MARGIN = 0.08
_LEGEND_H = 0.2  # a band at the top for the side colours' legend


def _legend(fig, x_in: float, y_in: float, grey: bool = False) -> None:
    """The side colours, left to right from (``x_in``, ``y_in``) inches: a short bone of each
    colour and its name ("left side", "right side": the character's own); with ``grey``, the
    colour of the clips drawn over another ("over it": named in the panel's title)."""
    from matplotlib.lines import Line2D

    W, H = fig.get_size_inches()
    x = x_in
    keys = [(_COLORS[_LEFT], "left side"), (_COLORS[_RIGHT], "right side")]
    for color, text in keys + ([(_GHOST_COLOR, "drawn over it")] if grey else []):
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


def _animation_figure(scene: _Scene, groups: list[list[_Clip]], titles: list[str], dpi: int, grid_dots: bool = False):
    """One row of panels, a title above and a time label under each, the side colours' legend."""
    n = len(groups)
    gap = 0.1
    W = n * scene.panel_w + (n + 1) * gap
    Hh = scene.panel_h + _TITLE_H + 2 * _LABEL_H + _MARGIN + _LEGEND_H
    fig = _new_figure(W, Hh, dpi)
    W, Hh = fig.get_size_inches()
    panels = []
    for i, (group, title) in enumerate(zip(groups, titles)):
        rect = ((gap + i * (scene.panel_w + gap)) / W, (2 * _LABEL_H + _MARGIN / 2) / Hh, scene.panel_w / W, scene.panel_h / Hh)
        panels.append(_Panel(fig, rect, scene, group[0], scene.scale[i], title, animated=True, grid_dots=grid_dots,
                             others=group[1:]))
    clock = fig.text(0.5, 0.04 / Hh, "", ha="center", va="bottom", fontsize=9, color="#333333", animated=True)
    _legend(fig, gap, Hh - _LEGEND_H / 2 - 0.02, grey=any(len(g) > 1 for g in groups))
    return fig, panels, clock


def _filmstrip_figure(scene: _Scene, groups: list[list[_Clip]], titles: list[str], frames: int, dpi: int):
    """One row per panel (its title above the row), one column per frame shown, a time label under
    each, the side colours' legend at the top right."""
    n = len(groups)
    gap = 0.06
    row_h = _TITLE_H + scene.panel_h + _LABEL_H
    W = frames * scene.panel_w + (frames + 1) * gap
    Hh = n * row_h + _MARGIN + _LEGEND_H
    fig = _new_figure(W, Hh, dpi)
    W, Hh = fig.get_size_inches()
    _legend(fig, gap, Hh - _LEGEND_H / 2 - 0.02, grey=any(len(g) > 1 for g in groups))
    cells = []
    for r, (group, title) in enumerate(zip(groups, titles)):
        clip = group[0]
        top = Hh - _LEGEND_H - _MARGIN / 2 - r * row_h
        fig.text(gap / W, (top - 0.04) / Hh, title, ha="left", va="top", fontsize=11, fontweight="bold")
        row = []
        for k in range(frames):
            rect = ((gap + k * (scene.panel_w + gap)) / W, (top - _TITLE_H - scene.panel_h) / Hh,
                    scene.panel_w / W, scene.panel_h / Hh)
            row.append(_Panel(fig, rect, scene, clip, scene.scale[r], None, animated=False, others=group[1:]))
        cells.append(row)
    return fig, cells


# ---------------------------------------------------------------------------------------------
# Writers: both take the frame the canvas already holds (blitted), not a fresh full draw
# ---------------------------------------------------------------------------------------------


_GIF_MAX_FPS = 50.0
"""GIF frame delays are whole hundredths of a second and browsers slow down delays under two,
so a GIF plays at most 50 frames per second; faster clips (CMU's 120) are sampled down."""

GIF_FPS = 20.0
"""A GIF's default frame rate: its delay (5 hundredths) is exact in the format (30 fps is not
a whole number of hundredths: written as 3, it would play 11% fast), and it keeps a 10 s GIF
of four clips under 3 MB (see :data:`GIF_DPI`). Clips are sampled at it, each output frame
showing each clip's frame nearest its time."""

_ENDED_ALPHA = 0.5
"""Opacity of a figure past its clip's end (a quarter step, so the GIF palette holds it)."""

GIF_DPI = 80
"""A GIF's default pixels per inch (PNG and MP4: 100): with :data:`GIF_FPS` and the grid's
crossings as dots, a 10 s GIF of four clips at 30 fps is about 2.6 MB."""


def gif_delay(fps: float) -> int:
    """The GIF frame delay in hundredths of a second nearest to ``1 / fps``, at least 2
    (browsers slow down shorter delays); the GIF then plays at ``100 / delay`` fps."""
    return max(2, int(round(100.0 / fps)))

_GIF_MAX_PIXELS = 1.2e9
"""A GIF is assembled in memory (one byte a pixel, twice over while Pillow encodes it): more
pixels over all frames than this is refused with a hint (``max_seconds``, smaller, ``.mp4``)."""

_TEXT_COLORS = ("#000000", "#333333", "#444444", "#b5b5b5")
_PALETTE_LEVELS = 4
"""Blends of each ink with white and with the grid in quarters: antialiased edges take fewer
distinct colours, which GIF's LZW compresses better (10% smaller than eighths)."""


def _palette():
    """A fixed GIF palette: every colour drawn, blended with white and with the grid colour
    in eighths (antialiased edges), so frames map to it without per-frame quantising.

    Returns the palette image to map against and the ``768`` palette values to write.
    """
    from matplotlib.colors import to_rgb
    from PIL import Image

    white, grid = np.ones(3), np.array(to_rgb(_GRID_COLOR))
    inks = [np.array(to_rgb(c)) for c in (*_COLORS.values(), _GRID_COLOR, _TRAIL_COLOR, _GHOST_COLOR, *_TEXT_COLORS)]
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


class _GifWriter(PillowWriter):
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


class _MP4Writer(FFMpegWriter):
    """FFMpegWriter (H.264, yuv420p, MP4 named, so the temporary file's name does not matter)
    that pipes the blitted canvas instead of redrawing the figure."""

    def __init__(self, fps):
        super().__init__(fps=fps, codec="h264", extra_args=["-pix_fmt", "yuv420p", "-f", "mp4"])
        self.frame_format = "rgba"

    def grab_frame(self, **savefig_kwargs):
        self._proc.stdin.write(bytes(self.fig.canvas.buffer_rgba()))


def _ffmpeg_available() -> bool:
    return FFMpegWriter.isAvailable()


def _make_writer(suffix: str, fps: float):
    """The movie writer for ``suffix`` (``.gif`` or ``.mp4``) at ``fps`` frames per second."""
    return _GifWriter(fps=fps) if suffix == ".gif" else _MP4Writer(fps)


# ---------------------------------------------------------------------------------------------
# The entry point
# ---------------------------------------------------------------------------------------------


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
    frames: int = 8,
    size: float = 3.0,
    dpi: int | None = None,
    max_seconds: float | None = None,
    *,
    azimuth: float = DEFAULT_AZIMUTH,
    elevation: float = DEFAULT_ELEVATION,
    camera: str = "heading",
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
            GIF stores exactly, ``100 / gif_delay(fps)``, at most 50 (see :data:`_GIF_MAX_FPS`).
            Each output frame shows, per clip, the frame nearest its time, so the output
            plays in real time.
        frames: number of columns of the PNG filmstrip.
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
    if suffix == ".mp4" and not _ffmpeg_available():
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
    if int(frames) < 1:
        raise TorchspliceError(f"frames must be at least 1, got {frames}")
    if dpi is None:
        dpi = GIF_DPI if suffix == ".gif" else 100
    if not size > 0 or not dpi > 0:
        raise TorchspliceError(f"size and dpi must be positive, got size={size}, dpi={dpi}")
    if max_seconds is not None and not max_seconds > 0:
        raise TorchspliceError(f"max_seconds must be positive, got {max_seconds}")

    prepared = []
    for g in groups:
        lead = _prepare(_truncate(g[0], max_seconds), up, azimuth, elevation, camera)
        prepared.append([lead] + [_prepare(_truncate(m, max_seconds), up, azimuth, elevation, camera, leader=lead)
                                  for m in g[1:]])
    clips = [g[0] for g in prepared]
    scene = _scene(prepared, up, float(size))
    rate = float(fps) if fps is not None else max(c.fps for c in clips)
    if suffix == ".gif":  # a rate GIF stores exactly: 100 / a whole number of hundredths
        rate = 100.0 / gif_delay(min(float(fps) if fps is not None else GIF_FPS, _GIF_MAX_FPS))
    last = max((c.num_frames - 1) / c.fps for c in clips)  # time of the last frame of the longest clip

    def frame_of(c: _Clip, t: float) -> tuple[int, bool]:
        f = int(round(t * c.fps))
        return min(f, c.num_frames - 1), f > c.num_frames - 1

    with atomic_path(output) as tmp:
        if suffix == ".png":
            n_cols = int(frames)
            fig, cells = _filmstrip_figure(scene, prepared, titles, n_cols, int(dpi))
            try:
                for row, c in zip(cells, clips):
                    for panel, f in zip(row, filmstrip_frames(c.num_frames, n_cols)):
                        panel.show(int(f))
                fig.savefig(tmp, format="png", dpi=int(dpi))
            finally:
                _release(fig)
        else:
            n_out = int(math.floor(last * rate + 1e-6)) + 1
            fig, panels, clock = _animation_figure(scene, prepared, titles, int(dpi), grid_dots=suffix == ".gif")
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
                writer = _make_writer(suffix, rate)
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
                    raise TorchspliceError(f"{output}: ffmpeg failed: {_ffmpeg_complaint(writer)}") from None
                finally:
                    if done:
                        writer.finish()
                    else:
                        _abandon(writer)
            except subprocess.CalledProcessError as exc:  # ffmpeg failed at the end
                err = (exc.stderr if isinstance(exc.stderr, str) else "").strip().splitlines()
                raise TorchspliceError(f"{output}: ffmpeg failed: {err[-1] if err else exc}") from None
            finally:
                _release(fig)
    return output


def _ffmpeg_complaint(writer) -> str:
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


def _abandon(writer) -> None:
    """Stop a writer that failed part-way without finishing the file (the caller removes it)."""
    proc = getattr(writer, "_proc", None)  # ffmpeg, fed through a pipe
    if proc is not None and proc.poll() is None:
        proc.kill()
        proc.communicate()
    if hasattr(writer, "_frames"):
        writer._frames = []


def _release(fig) -> None:
    """Drop a figure's artists so its memory goes at once (it was never registered with pyplot)."""
    fig.clear()
