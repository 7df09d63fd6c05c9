"""A clip's stick figure in the world: its points (joints and end sites) by forward kinematics,
once for the whole clip and vectorised over frames, its bones grouped by side, and its head.

Conventions: positions ``(T, P, 3)`` float64 in the file's units and axes, ``P`` the joints
``0..J-1`` then the end sites (head top, hands, toes); rotations unit quaternions WXYZ. Sides are
the character's own, read from joint names (:func:`side_of`; the indices of
:mod:`torchsplice.viz.style`). The pictures (:mod:`torchsplice.viz.render`) and the browser
viewer (:mod:`torchsplice.viz.viewer`) both draw these.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import torch

from ..core.fk import end_site_positions, forward_kinematics
from ..core.motion import Motion
from .style import CENTER, LEFT, RIGHT

__all__ = ["side_of", "head_joint", "Figure3D", "figure_points"]


def side_of(name: str) -> int:
    """Left, right or centre from a joint name (``LeftArm``, ``l_hip``, ``RHand``, ``hand_r`` ...)."""
    low = name.lower()
    if "left" in low:
        return LEFT
    if "right" in low:
        return RIGHT
    m = re.search(r"(?:^|[_:.\s])([LlRr])(?:[A-Z0-9_.:\s]|$)", name)
    if m:
        return LEFT if m.group(1) in "Ll" else RIGHT
    return CENTER


def head_joint(sk, pts: np.ndarray, up: int) -> tuple[np.ndarray | None, float]:
    """The head circle: centres ``(T, 3)`` (world) and diameter, or ``(None, 0)``.

    The head is the first centre joint named like ``head`` (else the joint under the end
    site highest in the rest pose). With an end site of some length (the sample's head top)
    the circle sits on that bone, as wide as it is long; with none or a zero-length one (Bandai
    Namco, LAFAN1) it sits on top of the joint, continuing the neck, 0.09 skeleton sizes wide.
    """
    J = sk.num_joints
    names = [n.lower() for n in sk.names]
    cand = [j for j in range(1, J) if "head" in names[j] and "end" not in names[j] and side_of(sk.names[j]) == CENTER]
    if cand:
        h = cand[0]
    elif sk.end_site_parents:
        _, rest_ends = sk.rest_positions()
        h = sk.end_site_parents[int(torch.argmax(rest_ends[:, up]))]
        if side_of(sk.names[h]) != CENTER or h == 0:
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
    (:func:`side_of`); a root child with animated translation is a trajectory, not a bone.
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
    segs: dict[int, list[int]] = {CENTER: [], LEFT: [], RIGHT: []}
    for j in range(1, J):
        if j not in skip_bone:
            segs[side_of(sk.names[j])] += [sk.parents[j], j, P]
    for e, p in enumerate(sk.end_site_parents):
        segs[side_of(sk.names[p])] += [p, J + e, P]
    lines = {k: np.asarray(v, dtype=np.int64) for k, v in segs.items() if v}
    drawn = np.unique(np.concatenate(list(lines.values())))[:-1] if lines else np.array([follow])
    return Figure3D(points=pts, lines=lines, follow=follow, drawn=drawn, follow_rotation=grot[:, follow].numpy())
