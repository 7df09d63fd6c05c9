"""BVH (Biovision Hierarchy) reading and writing.

Dialects read: any of the six Euler orders per joint (mixed within one file), position
channels on any joint in any axis order (Bandai Namco animates every joint's translation;
they are kept, not dropped), unit scale channels (``Xscale``...; dropped, anything but 1 is
refused), End Sites, any frame time, CRLF or LF line ends, tabs or spaces, joint names with
spaces.

Conventions of the result (a :class:`~torchsplice.core.motion.Motion`):

- rotations ``(T, J, 4)`` unit quaternions, **WXYZ**; a channel list ``Zrotation Xrotation
  Yrotation`` with angles ``(a, b, c)`` means ``R = R_Z(a) R_X(b) R_Y(c)`` (degrees in the file);
- position channels give the joint's local translation and replace its OFFSET (as Blender,
  MotionBuilder and the CMU and LAFAN1 tools read them);
- lengths in the file's units; fps ``= 1 / Frame Time``, rounded to an integer when within
  1e-4 of one (``0.0333333`` reads as 30 fps).

The motion block is parsed in one vectorised call (``numpy.loadtxt``); errors name the file,
the line and the problem, as :class:`~torchsplice.core.errors.BVHError`.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import torch

from ..core.errors import BVHError, MotionError
from ..core.motion import Motion
from ..core.rotations import euler_to_quat, quat_to_rotmat, rotmat_to_euler
from ..core.skeleton import POSITION_CHANNELS, ROTATION_CHANNELS, Skeleton
from .atomic import atomic_path

__all__ = ["read_bvh", "parse_bvh", "write_bvh", "format_bvh"]

_SCALE_CHANNELS = ("Xscale", "Yscale", "Zscale")
_CHANNEL_NAMES = {c.lower(): c for c in ROTATION_CHANNELS + POSITION_CHANNELS + _SCALE_CHANNELS}


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------
def read_bvh(path, dtype: torch.dtype = torch.float32, name: str | None = None) -> Motion:
    """Read a BVH file into a :class:`Motion` (float32 by default, float64 on request).

    The clip is named after the file's stem unless ``name`` is given; ``source`` is the path.
    Raises :class:`BVHError` (``"FILE:LINE: problem"``) for a malformed file.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise BVHError(path, f"cannot read file ({exc.strerror or exc})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return parse_bvh(text, path=path, dtype=dtype, name=name if name is not None else path.stem)


class _Header:
    """Result of parsing the HIERARCHY block."""

    def __init__(self):
        self.names: list[str] = []
        self.parents: list[int] = []
        self.offsets: list[list[float]] = []
        self.channels: list[list[str]] = []
        self.end_parents: list[int] = []
        self.end_offsets: list[list[float]] = []


def _tokens(lines: list[str], start: int, stop: int) -> list[tuple[str, int]]:
    """(token, 1-based line number) for lines[start:stop]."""
    return [(tok, i + 1) for i in range(start, stop) for tok in lines[i].split()]


def _parse_hierarchy(lines: list[str], stop: int, path) -> _Header:
    """Parse lines[0:stop] (HIERARCHY ... up to the MOTION line)."""
    toks = _tokens(lines, 0, stop)
    h = _Header()
    pos = 0

    def err(msg, line=None):
        return BVHError(path, msg, line if line is not None else (toks[pos][1] if pos < len(toks) else stop))

    def take(expected=None):
        nonlocal pos
        if pos >= len(toks):
            raise err(f"unexpected end of hierarchy{f', expected {expected!r}' if expected else ''}")
        tok, line = toks[pos]
        if expected is not None and tok.upper() != expected.upper():
            raise err(f"expected {expected!r}, found {tok!r}", line)
        pos += 1
        return tok, line

    def floats(n, what):
        vals = []
        for _ in range(n):
            tok, line = take()
            try:
                v = float(tok)
            except ValueError:
                raise err(f"non-numeric {what} value {tok!r}", line) from None
            if not math.isfinite(v):
                raise err(f"non-finite {what} value {tok!r}", line)
            vals.append(v)
        return vals

    def name_until_brace():
        parts = []
        while pos < len(toks) and toks[pos][0] != "{":
            parts.append(take()[0])
        if not parts:
            raise err("joint without a name")
        return " ".join(parts)

    def joint(parent: int):
        jname = name_until_brace()
        line = toks[pos][1] if pos < len(toks) else stop
        if jname in h.names:
            raise err(f"joint name {jname!r} appears twice", line)
        idx = len(h.names)
        h.names.append(jname)
        h.parents.append(parent)
        take("{")
        take("OFFSET")
        h.offsets.append(floats(3, "OFFSET"))
        h.channels.append([])
        if pos < len(toks) and toks[pos][0].upper() == "CHANNELS":
            take()
            tok, cline = take()
            if not tok.isdigit():
                raise err(f"channel count must be an integer, found {tok!r}", cline)
            for _ in range(int(tok)):
                ctok, cl = take()
                c = _CHANNEL_NAMES.get(ctok.lower())
                if c is None:
                    raise err(f"bad channel name {ctok!r} for joint {jname!r}", cl)
                if c in h.channels[idx]:
                    raise err(f"channel {c} repeated for joint {jname!r}", cl)
                h.channels[idx].append(c)
            rot = [c for c in h.channels[idx] if c in ROTATION_CHANNELS]
            if len(rot) not in (0, 3):
                raise err(f"joint {jname!r} has {len(rot)} rotation channels; 0 or 3 are supported", cline)
        while True:
            tok, tline = take()
            up = tok.upper()
            if up == "}":
                return
            if up == "JOINT":
                joint(idx)
            elif up == "END":
                take("Site")
                take("{")
                take("OFFSET")
                h.end_parents.append(idx)
                h.end_offsets.append(floats(3, "End Site OFFSET"))
                take("}")
            else:
                raise err(f"unexpected {tok!r} in joint {jname!r}", tline)

    if not toks or toks[0][0].upper() != "HIERARCHY":
        raise BVHError(path, "missing HIERARCHY at the start of the file", toks[0][1] if toks else 1)
    take("HIERARCHY")
    take("ROOT")
    joint(-1)
    if pos < len(toks):
        tok, line = toks[pos]
        if tok.upper() == "ROOT":
            raise err("more than one ROOT; only single-root skeletons are supported", line)
        raise err(f"unexpected {tok!r} after the hierarchy", line)
    return h


def _find_motion(lines: list[str], path) -> tuple[int, int, float, int]:
    """Locate MOTION; return (motion line index, frame count, frame time, first data line index)."""
    motion = next((i for i, l in enumerate(lines) if l.strip().upper() == "MOTION"), None)
    if motion is None:
        raise BVHError(path, "missing MOTION section (truncated file?)", len(lines))
    i = motion + 1

    def field(i, key):
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i >= len(lines):
            raise BVHError(path, f"missing '{key}:' line after MOTION (truncated file?)", i)
        text = lines[i].strip()
        k, sep, v = text.partition(":")
        if not sep or k.strip().lower() != key.lower():
            raise BVHError(path, f"expected '{key}:', found {text[:40]!r}", i + 1)
        return i, v.strip()

    i, frames = field(i, "Frames")
    try:
        n = int(frames)
    except ValueError:
        raise BVHError(path, f"frame count is not an integer: {frames!r}", i + 1) from None
    if n <= 0:
        raise BVHError(path, f"zero frames (Frames: {n})", i + 1)
    i, ft = field(i + 1, "Frame Time")
    try:
        dt = float(ft)
    except ValueError:
        raise BVHError(path, f"frame time is not a number: {ft!r}", i + 1) from None
    if not (math.isfinite(dt) and dt > 0):
        raise BVHError(path, f"frame time must be positive, found {ft!r}", i + 1)
    return motion, n, dt, i + 1


def _locate_bad_line(lines: list[str], first: int, n_channels: int, path) -> BVHError:
    """Slow path after a failed vectorised parse: the first offending data line."""
    for i in range(first, len(lines)):
        parts = lines[i].split()
        if not parts:
            continue
        for p in parts:
            try:
                float(p)
            except ValueError:
                return BVHError(path, f"non-numeric value {p!r} in frame data", i + 1)
        if len(parts) != n_channels:
            last = all(not l.strip() for l in lines[i + 1:])
            hint = " (truncated file?)" if last and len(parts) < n_channels else ""
            return BVHError(path, f"expected {n_channels} values in the frame, found {len(parts)}{hint}", i + 1)
    return BVHError(path, "frame data could not be parsed", first + 1)


def _parse_frames(lines: list[str], first: int, n_frames: int, n_channels: int, path) -> np.ndarray:
    """The motion block as a ``(n_frames, n_channels)`` float64 array."""
    data_lines = lines[first:]
    if n_channels == 0:
        return np.zeros((n_frames, 0))
    try:
        data = np.loadtxt(data_lines, dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        raise _locate_bad_line(lines, first, n_channels, path) from None
    if data.shape[0] and data.shape[1] != n_channels:
        raise _locate_bad_line(lines, first, n_channels, path)
    if data.shape[0] != n_frames:
        what = "truncated file" if data.shape[0] < n_frames else "extra frame lines"
        raise BVHError(path, f"{what}: header says {n_frames} frames, found {data.shape[0]}", len(lines))
    bad = ~np.isfinite(data)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        nonblank = [i for i in range(first, len(lines)) if lines[i].strip()]
        raise BVHError(path, f"{data[r, c]} value in frame {r} (channel {c})", nonblank[r] + 1)
    return data


def _columns(channels: list[list[str]]):
    """Column index of every (joint, channel) pair."""
    cols, c = [], 0
    for ch in channels:
        cols.append({name: c + k for k, name in enumerate(ch)})
        c += len(ch)
    return cols, c


def parse_bvh(text: str, path="<string>", dtype: torch.dtype = torch.float32, name: str = "") -> Motion:
    """Parse BVH text into a :class:`Motion`; ``path`` is only used in error messages."""
    lines = text.splitlines()
    motion_line, n_frames, dt, first = _find_motion(lines, path)
    h = _parse_hierarchy(lines, motion_line, path)
    cols, n_channels = _columns(h.channels)
    data = _parse_frames(lines, first, n_frames, n_channels, path)

    J = len(h.names)
    offsets = torch.tensor(h.offsets, dtype=torch.float64)
    rot = torch.zeros(n_frames, J, 4, dtype=torch.float64)
    rot[..., 0] = 1.0
    by_order: dict[str, list[int]] = {}
    for j, ch in enumerate(h.channels):
        order = "".join(c[0] for c in ch if c in ROTATION_CHANNELS)
        if order:
            by_order.setdefault(order, []).append(j)
    for order, joints in by_order.items():
        idx = [[cols[j][f"{a}rotation"] for a in order] for j in joints]
        angles = torch.from_numpy(data[:, np.asarray(idx)])  # (T, Jk, 3)
        rot[:, joints] = euler_to_quat(angles, order)

    trans = offsets.expand(n_frames, J, 3).clone()
    pos_cols = [(j, axis, cols[j][f"{a}position"]) for j in range(J) for axis, a in enumerate("XYZ")
                if f"{a}position" in cols[j]]
    if pos_cols:
        js, axes, cs = (list(x) for x in zip(*pos_cols))
        trans[:, js, axes] = torch.from_numpy(data[:, cs])
    scale_cols = [(j, a, cols[j][f"{a}scale"]) for j in range(J) for a in "XYZ" if f"{a}scale" in cols[j]]
    if scale_cols:
        bad = ~np.isclose(data[:, [c for _, _, c in scale_cols]], 1.0, atol=1e-6).all(axis=0)
        if bad.any():
            j, a, _ = scale_cols[int(np.argmax(bad))]
            raise BVHError(path, f"joint {h.names[j]!r} has non-unit {a}scale values; scaling is not supported")

    channels = [[c for c in ch if c not in _SCALE_CHANNELS] for ch in h.channels]
    try:
        skeleton = Skeleton(h.names, h.parents, offsets, channels, h.end_parents, h.end_offsets)
    except ValueError as exc:
        raise BVHError(path, str(exc)) from None
    fps = 1.0 / dt
    if abs(fps - round(fps)) <= 1e-4 * fps:
        fps = float(round(fps))
    return Motion(
        skeleton=skeleton,
        rotations=rot.to(dtype),
        root_translation=trans[:, 0].to(dtype),
        translations=trans.to(dtype) if skeleton.has_joint_translations else None,
        fps=fps,
        name=name,
        source=str(path),
    )


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------
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
    items = [[] for _ in range(J)]  # per joint: (sort key, kind, index)
    for j, p in enumerate(sk.parents):
        if p >= 0:
            items[p].append((first_end[j], 1, j))
    for j in range(J):
        items[j] += [(e, 0, e) for e in ends[j]]
        items[j].sort()
    out = ["HIERARCHY"]

    def emit(j, depth):
        ind = "\t" * depth
        out.append(f"{ind}{'ROOT' if j == 0 else 'JOINT'} {sk.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET " + " ".join(_fmt(v) for v in sk.offsets[j].tolist()))
        if sk.channels[j]:
            out.append(f"{ind}\tCHANNELS {len(sk.channels[j])} " + " ".join(sk.channels[j]))
        for _, kind, k in items[j]:
            if kind == 1:
                emit(k, depth + 1)
            else:
                out.extend([f"{ind}\tEnd Site", f"{ind}\t{{",
                            f"{ind}\t\tOFFSET " + " ".join(_fmt(v) for v in sk.end_site_offsets[k].tolist()),
                            f"{ind}\t}}"])
        out.append(f"{ind}}}")

    emit(0, 0)
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
    cols, n = _columns([list(c) for c in sk.channels])
    out = np.zeros((T, n))
    identity = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=torch.float64)
    for j, ch in enumerate(sk.channels):
        order = sk.rotation_order(j)
        if order:
            eul = rotmat_to_euler(quat_to_rotmat(rot[:, j]), order).numpy()
            eul = _unwrap_degrees(eul)
            for k, a in enumerate(order):
                out[:, cols[j][f"{a}rotation"]] = eul[:, k]
        elif (rot[:, j] @ identity).abs().min() < 1 - 1e-6:
            raise MotionError(f"clip {motion.name!r}: joint {sk.names[j]!r} rotates but has no rotation channels")
        for axis, a in enumerate("XYZ"):
            c = cols[j].get(f"{a}position")
            if c is not None:
                out[:, c] = trans[:, j, axis].numpy()
            elif (trans[:, j, axis] - sk.offsets[j, axis]).abs().max() > 1e-5 * max(sk.size(), 1.0):
                raise MotionError(
                    f"clip {motion.name!r}: joint {sk.names[j]!r} translates along {a} but has no {a}position channel"
                )
    return out


def format_bvh(motion: Motion) -> str:
    """The clip as BVH text (channel layout and Euler orders from its skeleton).

    The skeleton must be in depth-first order (every skeleton read from BVH is), since BVH
    nesting cannot express any other joint order.
    """
    if not motion.skeleton.is_depth_first:
        raise MotionError(f"clip {motion.name!r}: skeleton joints are not in depth-first order, which BVH cannot keep")
    data = _frame_columns(motion)
    buf = io.StringIO()
    buf.write(_hierarchy_text(motion.skeleton))
    buf.write(f"\nMOTION\nFrames: {motion.num_frames}\nFrame Time: {1.0 / motion.fps:.7f}\n")
    np.savetxt(buf, data, fmt="%.6f", delimiter=" ")
    return buf.getvalue()


def write_bvh(motion: Motion, path) -> None:
    """Write the clip to ``path`` atomically (a partial file never replaces a good one)."""
    text = format_bvh(motion)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text)
