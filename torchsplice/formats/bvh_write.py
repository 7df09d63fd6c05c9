"""Writing BVH: a clip's skeleton as the HIERARCHY and its frames as Euler angles in each
joint's channel order (see :mod:`.bvh` for the conventions, which reading and writing share).
The file is written under a temporary name and renamed into place."""

from __future__ import annotations

import dataclasses
import io
import math
import os
from pathlib import Path

import numpy as np
import torch

from ..core.errors import MotionError
from ..core.motion import Motion
from ..core.names import CONTROL, quoted
from ..core.rotations import quat_to_rotmat, rotmat_to_euler
from ..core.skeleton import Skeleton, channel_columns
from ..store.atomic import atomic_path
from .bvh_limits import MAX_ABS_VALUE, MAX_FRAME_TIME, MIN_FRAME_TIME

__all__ = ["format_bvh", "write_bvh"]


def _fmt(v: float) -> str:
    return f"{v:.6f}"


def _hierarchy_text(sk: Skeleton) -> str:
    """The HIERARCHY block; End Sites and child joints keep the order they were read in."""
    J = len(sk.names)
    ends = [[] for _ in range(J)]
    for e, p in enumerate(sk.end_site_parents):
        ends[p].append(e)
    first_end = [min(ends[j], default=len(sk.end_site_parents)) for j in range(J)]  # per subtree
    for j in range(J - 1, 0, -1):
        first_end[sk.parents[j]] = min(first_end[sk.parents[j]], first_end[j])
    kids = [[] for _ in range(J)]
    for j, p in enumerate(sk.parents):
        if p >= 0:
            kids[p].append(j)
    items = [[] for _ in range(J)]  # per joint: (kind, index), child joints in index order (the channels')
    for j in range(J):
        pending = sorted(ends[j])
        for k in kids[j]:  # an End Site read before a child's subtree is written before it
            while pending and pending[0] < first_end[k]:
                items[j].append((0, pending.pop(0)))
            items[j].append((1, k))
        items[j] += [(0, e) for e in pending]
    out = ["HIERARCHY"]
    offsets, end_offsets = sk.offsets.tolist(), sk.end_site_offsets.tolist()
    # iterative depth-first walk (a chain of thousands of joints must not hit the recursion limit):
    # ("open", joint, depth) writes a joint's head and queues its items, then ("close", ...) its '}'
    todo = [("open", 0, 0)]
    while todo:
        what, j, depth = todo.pop()
        ind = "\t" * depth
        if what == "close":
            out.append(f"{ind}}}")
            continue
        if what == "end":
            out.extend([f"{ind}End Site", f"{ind}{{",
                        f"{ind}\tOFFSET " + " ".join(_fmt(v) for v in end_offsets[j]), f"{ind}}}"])
            continue
        out.append(f"{ind}{'ROOT' if j == 0 else 'JOINT'} {sk.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET " + " ".join(_fmt(v) for v in offsets[j]))
        if sk.channels[j]:
            out.append(f"{ind}\tCHANNELS {len(sk.channels[j])} " + " ".join(sk.channels[j]))
        todo.append(("close", j, depth))
        todo.extend(("open" if kind == 1 else "end", k, depth + 1) for kind, k in reversed(items[j]))
    return "\n".join(out)


def _unwrap_degrees(a: np.ndarray) -> np.ndarray:
    """Remove 360-degree jumps between consecutive frames (axis 0), keeping the first frame."""
    if a.shape[0] < 2:
        return a
    jumps = np.round(np.diff(a, axis=0) / 360.0)
    return a - 360.0 * np.concatenate([np.zeros_like(a[:1]), np.cumsum(jumps, axis=0)])


def _frame_columns(motion: Motion) -> np.ndarray:
    """The motion block as a ``(T, C)`` float64 array in the skeleton's channel layout."""
    sk = motion.skeleton
    T = motion.num_frames
    rot = motion.rotations.detach().to("cpu", torch.float64)
    trans = motion.local_translations().detach().to("cpu", torch.float64)
    cols, n = channel_columns([list(c) for c in sk.channels])
    out = np.zeros((T, n))
    identity = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=torch.float64)
    for j in range(len(sk.channels)):
        order = sk.rotation_order(j)
        if order:
            eul = rotmat_to_euler(quat_to_rotmat(rot[:, j]), order).numpy()
            eul = _unwrap_degrees(eul)
            for k, a in enumerate(order):
                out[:, cols[j][f"{a}rotation"]] = eul[:, k]
        elif (rot[:, j] @ identity).abs().min() < 1 - 1e-6:
            raise MotionError(f"clip {quoted(motion.name)}: joint {quoted(sk.names[j])} rotates but has no rotation channels")
        for axis, a in enumerate("XYZ"):
            c = cols[j].get(f"{a}position")
            if c is not None:
                out[:, c] = trans[:, j, axis].numpy()
            elif (trans[:, j, axis] - sk.offsets[j, axis]).abs().max() > 1e-5 * max(sk.size(), 1.0):
                raise MotionError(
                    f"clip {quoted(motion.name)}: joint {quoted(sk.names[j])} translates along {a} but has no "
                    f"{a}position channel"
                )
    return out


def format_bvh(motion: Motion) -> str:
    """The clip as BVH text (channel layout and Euler orders from its skeleton).

    BVH nests each joint's subtree inside it, so a skeleton whose joints are in another order
    (SMPL's, whose spine comes after both legs) is written in depth-first order
    (:meth:`Skeleton.depth_first_order`): the file's joints are the same, by name, in the order
    a BVH reader gives them. Raises :class:`MotionError` (one line naming the clip) for what
    :func:`read_bvh` would refuse: non-finite values (naming the first bad frame), values beyond
    1e12, fps outside 1 to 1,000, joint names that would not read back.
    """
    if not isinstance(motion, Motion):
        raise TypeError(f"format_bvh: motion must be a Motion, got {type(motion).__name__}")
    _check_writable(motion)
    if not motion.skeleton.is_depth_first:
        order = motion.skeleton.depth_first_order()
        motion = dataclasses.replace(
            motion, skeleton=motion.skeleton.reordered(order), rotations=motion.rotations[:, order],
            translations=None if motion.translations is None else motion.translations[:, order])
    data = _frame_columns(motion)
    bad = ~np.isfinite(data) | (np.abs(np.nan_to_num(data)) > MAX_ABS_VALUE)
    if bad.any():
        f = int(np.argwhere(bad)[0][0])
        raise MotionError(f"clip {quoted(motion.name)}: frame {f} gives a non-finite or absurd (beyond "
                          f"{MAX_ABS_VALUE:g}) channel value; nothing written")
    buf = io.StringIO()
    buf.write(_hierarchy_text(motion.skeleton))
    buf.write(f"\nMOTION\nFrames: {motion.num_frames}\nFrame Time: {1.0 / motion.fps:.7f}\n")
    np.savetxt(buf, data, fmt="%.6f", delimiter=" ")
    return buf.getvalue()


def _check_writable(motion: Motion) -> None:
    """Refuse (:class:`MotionError`) a clip whose BVH text :func:`read_bvh` would refuse."""
    clip = f"clip {quoted(motion.name)}"
    if motion.num_frames == 0:
        raise MotionError(f"{clip}: no frames; BVH needs at least one")
    fps = motion.fps
    if not (math.isfinite(fps) and MIN_FRAME_TIME <= float(f"{1.0 / fps:.7f}") <= MAX_FRAME_TIME):
        raise MotionError(f"{clip}: fps {fps:g} is outside 1 to 1,000, which BVH readers refuse; nothing written")
    for what, t in (("rotation", motion.rotations), ("root translation", motion.root_translation),
                    ("translation", motion.translations)):
        if t is None:
            continue
        bad = ~torch.isfinite(t.detach().reshape(t.shape[0], -1)).all(dim=1)
        if bool(bad.any()):
            raise MotionError(f"{clip}: non-finite {what} value at frame {int(bad.nonzero()[0])}; nothing written")
    sk = motion.skeleton
    for what, t, owners in (("OFFSET", sk.offsets, sk.names),
                            ("End Site OFFSET", sk.end_site_offsets, [sk.names[p] for p in sk.end_site_parents])):
        bad = ~torch.isfinite(t).all(dim=1) | (t.abs() > MAX_ABS_VALUE).any(dim=1)
        if bool(bad.any()):
            j = int(bad.nonzero()[0])
            raise MotionError(f"{clip}: {what} of joint {quoted(owners[j])} is non-finite or absurd; nothing written")
    for jname in sk.names:
        toks = jname.split()
        if not toks or " ".join(toks) != jname or "{" in toks or CONTROL.search(jname):
            raise MotionError(f"{clip}: joint name {quoted(jname)} would not read back from BVH (empty, control "
                              "characters, a '{' word or stray whitespace); nothing written")


def write_bvh(motion: Motion, path) -> None:
    """Write the clip to ``path`` atomically (a partial file never replaces a good one).

    Raises ``TypeError`` for arguments of the wrong type (e.g. ``write_bvh(path, motion)``)
    and :class:`MotionError` for a clip BVH cannot hold (see :func:`format_bvh`); nothing is
    written then.
    """
    if not isinstance(motion, Motion):
        swapped = isinstance(path, Motion) and isinstance(motion, (str, os.PathLike))
        raise TypeError("write_bvh(motion, path): the arguments are swapped; pass the Motion first" if swapped
                        else f"write_bvh(motion, path): motion must be a Motion, got {type(motion).__name__}")
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"write_bvh(motion, path): path must be a str or os.PathLike, got {type(path).__name__}")
    text = format_bvh(motion)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text)
