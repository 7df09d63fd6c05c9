"""The camera: the up axis, the orthographic projection, and each clip framed by a camera that
follows its root (and turns with its heading), as screen coordinates ready to draw.

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
  reaches.

Units: positions in the file's units and axes, angles in degrees (yaw in radians where a name
says so), screen coordinates ``(x right, y up)`` in file units, relative to the camera centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from ..core.errors import TorchspliceError
from ..core.motion import Motion
from .defaults import CAMERAS, DEFAULT_AZIMUTH, DEFAULT_ELEVATION  # declared there (read by the command line)
from .stick_figure import figure_points, head_joint

__all__ = ["check_up_axis", "canonical_axes", "view_rotation", "view_rotations", "heading_yaw", "project",
           "moving_average", "Clip", "at_times", "prepare_clip", "DEFAULT_AZIMUTH", "DEFAULT_ELEVATION", "CAMERAS",
           "FOLLOW_SECONDS", "HEADING_SECONDS"]

FOLLOW_SECONDS = 0.5  # smoothing window of the follow camera
HEADING_SECONDS = 1.0  # smoothing window of the heading camera (a gait's twist averages out)


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


def moving_average(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average along axis 0 of ``(T, ...)``, edges padded with the end values."""
    if width <= 1 or x.shape[0] < 2:
        return x.copy()
    h = width // 2
    pad = np.concatenate([np.repeat(x[:1], h, 0), x, np.repeat(x[-1:], h, 0)])
    c = np.cumsum(np.concatenate([np.zeros_like(x[:1]), pad]), axis=0)
    return (c[2 * h + 1:] - c[:-2 * h - 1]) / (2 * h + 1)


@dataclass
class Clip:
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


def at_times(n: int, fps: float, leader: Clip) -> np.ndarray:
    """``(leader's frames,)`` the frame of a clip of ``n`` frames at ``fps`` nearest each of the
    leader's frames' times (held at its last)."""
    return np.minimum(np.rint(np.arange(leader.num_frames) / leader.fps * fps).astype(np.int64), n - 1)


def prepare_clip(motion: Motion, up: int, azimuth: float, elevation: float, camera: str,
             leader: Clip | None = None) -> Clip:
    """Forward kinematics once for the whole clip, then everything drawing needs, as numpy.
    With ``leader``, the clip is resampled to the leader's frames (its frame nearest each of
    their times, held at its end; nothing past the leader's end) and seen from the leader's
    camera at each (an overlay)."""
    sk = motion.skeleton
    fig3 = figure_points(motion)
    pts, lines, follow, drawn = fig3.points, fig3.lines, fig3.follow, fig3.drawn
    fps = motion.fps
    if leader is not None:
        pts, fps = pts[at_times(pts.shape[0], fps, leader)], leader.fps
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
        smooth = moving_average(floor_xy, max(1, int(round(FOLLOW_SECONDS * motion.fps))) | 1)
        cam3 = np.zeros((T, 3))
        cam3[:, axes[0]], cam3[:, axes[1]], cam3[:, up] = smooth[:, 0], smooth[:, 1], floor
        root3[:, up] = floor
        az = np.full(T, float(azimuth))
        if camera == "heading" and fig3.follow_rotation is not None and T > 1:
            yaw = heading_yaw(fig3.follow_rotation, up)
            yaw = moving_average(yaw[:, None], max(1, int(round(HEADING_SECONDS * motion.fps))) | 1)[:, 0]
            az = az + np.degrees(yaw - yaw[0])
        view = view_rotations(up, az, elevation)[:, :2]  # (T, 2, 3)

    scr = np.einsum("tpk,tik->tpi", pts - cam3[:, None], view)  # (T, P, 2), relative to the camera centre
    screen = np.concatenate([scr, np.full((T, 1, 2), np.nan)], axis=1)

    head, head_size = head_joint(sk, pts, up)
    if head is not None:
        head = np.einsum("tk,tik->ti", head - cam3, view)
    return Clip(
        name=motion.name, fps=fps, screen=screen, lines=lines, head=head, head_size=head_size,
        root=root3, center=cam3, view=view, floor_center=smooth, floor=floor,
        height=max(top - floor, 0.25 * sk.size(), 1e-9), size=max(sk.size(), 1e-9), drawn=drawn,
    )
