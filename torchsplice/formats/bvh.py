"""BVH (Biovision Hierarchy) reading and writing.

Dialects read: any of the six Euler orders per joint (mixed within one file), position
channels on any joint in any axis order (Bandai Namco animates every joint's translation;
they are kept, not dropped), unit scale channels (``Xscale``...; dropped, anything but 1 is
refused), End Sites, frame times from 0.001 s to 1 s (1 to 1,000 fps), CRLF, LF or CR line
ends, tabs or any number of spaces between tokens (also inside ``Frame Time:``), a UTF-8 byte
order mark, joint names with spaces, and text that is not UTF-8 (read as Latin-1). Numbers
are ASCII only (``12``, ``-1.5e3``); counts are ASCII digits only.

Lines after the declared frames (QAvimator and Second Life animations keep keyframe indices
there) are not frames: the declared frames are read and one :class:`BVHWarning` is issued
through :func:`warnings.warn`, ``"FILE:LINE: N lines after the declared F frames ignored"``,
which a caller can catch (``warnings.catch_warnings``) and print as one line.

Conventions of the result (a :class:`~torchsplice.core.motion.Motion`):

- rotations ``(T, J, 4)`` unit quaternions, **WXYZ**; a channel list ``Zrotation Xrotation
  Yrotation`` with angles ``(a, b, c)`` means ``R = R_Z(a) R_X(b) R_Y(c)`` (degrees in the file);
- position channels give the joint's local translation and replace its OFFSET (as Blender,
  MotionBuilder and the CMU and LAFAN1 tools read them);
- lengths in the file's units; fps ``= 1 / Frame Time``, rounded to an integer when within
  1e-4 of one (``0.0333333`` reads as 30 fps).

The motion block is parsed in one vectorised call (``numpy.loadtxt``); errors name the file,
the line and the problem, as :class:`~torchsplice.core.errors.BVHError`, on one line of at
most about 300 characters (long tokens and long lists of names are cut short). Refused: joint
names with control characters (e.g. NUL), more than 10,000 joints, non-finite or absurd
(beyond 1e12) OFFSET and channel values, and frame times outside [0.001, 1] s.

:func:`write_bvh` and :func:`format_bvh` refuse non-finite values (naming the clip and the
first bad frame) and anything the reader would refuse, and write nothing then.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from pathlib import Path

import numpy as np
import torch

from ..core.errors import BVHError
from ..core.motion import Motion
from ..core.names import CONTROL, quoted
from ..core.rotations import euler_to_quat
from ..core.skeleton import POSITION_CHANNELS, ROTATION_CHANNELS, Skeleton, channel_columns
from .bvh_limits import MAX_ABS_VALUE, MAX_FRAME_TIME, MAX_JOINTS, MIN_FRAME_TIME
from .plain_files import not_regular

__all__ = ["read_bvh", "parse_bvh", "write_bvh", "format_bvh", "BVHWarning"]

_SCALE_CHANNELS = ("Xscale", "Yscale", "Zscale")
_CHANNEL_NAMES = {c.lower(): c for c in ROTATION_CHANNELS + POSITION_CHANNELS + _SCALE_CHANNELS}

_MAX_PROBLEM = 200  # characters of a message after "FILE:LINE: "
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z", re.ASCII)
_NON_FINITE = re.compile(r"[+-]?(?:nan|inf|infinity)\Z", re.IGNORECASE)
_COUNT = re.compile(r"\d+\Z", re.ASCII)


class BVHWarning(UserWarning):
    """Something in a BVH file that was read past, not refused: ``"FILE:LINE: what"``.

    Issued with :func:`warnings.warn` (e.g. lines after the declared frames, which are
    ignored); a caller that wants one line per file catches this category.
    """

    def __init__(self, path, problem: str, line: int | None = None):
        where = f"{path}:{line}" if line is not None else f"{path}"
        super().__init__(f"{where}: {problem}")
        self.path, self.line, self.problem = path, line, problem


def _error(path, problem: str, line: int | None = None) -> BVHError:
    """A :class:`BVHError` whose problem is one line of bounded length."""
    problem = " ".join(str(problem).splitlines())
    if len(problem) > _MAX_PROBLEM:
        problem = problem[: _MAX_PROBLEM - 3] + "..."
    return BVHError(path, problem, line)


def _number(tok: str, what: str, path, line: int) -> float:
    """One ASCII number, finite and not absurd; a :class:`BVHError` otherwise."""
    if _NUMBER.match(tok):
        v = float(tok)
        if not math.isfinite(v):
            raise _error(path, f"{what} value {quoted(tok)} is too large (not finite)", line)
        if abs(v) > MAX_ABS_VALUE:
            raise _error(path, f"absurd {what} value {quoted(tok)} (beyond {MAX_ABS_VALUE:g})", line)
        return v
    if _NON_FINITE.match(tok):
        raise _error(path, f"non-finite {what} value {quoted(tok)}", line)
    raise _error(path, f"non-numeric {what} value {quoted(tok)}", line)


def _decode(raw: bytes) -> str:
    """Text of a file: UTF-8 (with or without a byte order mark), UTF-16 with a byte order
    mark, anything else as Latin-1 (which never fails)."""
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError:
            pass
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _split_lines(text: str) -> list[str]:
    """Lines split at CRLF, LF or CR only (so line numbers are those an editor shows)."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return lines


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------
def read_bvh(path, dtype: torch.dtype = torch.float32, name: str | None = None) -> Motion:
    """Read a BVH file into a :class:`Motion` (float32 by default, float64 on request).

    The clip is named after the file's stem unless ``name`` is given; ``source`` is the path.
    Raises :class:`BVHError` (``"FILE:LINE: problem"``, one line) for a malformed file; warns
    with :class:`BVHWarning` when lines after the declared frames are ignored.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"read_bvh: path must be a str or os.PathLike, got {type(path).__name__}")
    path = Path(path)
    try:
        if (kind := not_regular(os.stat(path).st_mode)) is not None:  # a FIFO would block forever
            raise _error(path, f"is {kind}, not a regular file; not read")
        raw = path.read_bytes()
    except OSError as exc:
        raise _error(path, f"cannot read file ({exc.strerror or exc})") from None
    except ValueError as exc:  # e.g. a NUL byte in the path
        raise _error(path, f"cannot read file ({exc})") from None
    return parse_bvh(_decode(raw), path=path, dtype=dtype, name=name if name is not None else path.stem)


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
    """Parse lines[0:stop] (HIERARCHY ... up to the MOTION line).

    Iterative (an explicit stack of open joints), so a chain of thousands of joints reads
    like any other; more than :data:`MAX_JOINTS` joints are refused.
    """
    toks = _tokens(lines, 0, stop)
    h = _Header()
    seen: set[str] = set()
    pos = 0

    def err(msg, line=None):
        return _error(path, msg, line if line is not None else (toks[pos][1] if pos < len(toks) else stop))

    def take(expected=None):
        nonlocal pos
        if pos >= len(toks):
            raise err(f"unexpected end of hierarchy{f', expected {expected!r}' if expected else ''}")
        tok, line = toks[pos]
        if expected is not None and tok.upper() != expected.upper():
            raise err(f"expected {expected!r}, found {quoted(tok)}", line)
        pos += 1
        return tok, line

    def floats(n, what):
        return [_number(tok, what, path, line) for tok, line in (take() for _ in range(n))]

    def open_joint(parent: int, kw_line: int) -> int:
        """Read a joint's name (the rest of its ROOT/JOINT line), OFFSET and CHANNELS."""
        parts = []
        while pos < len(toks) and toks[pos][1] == kw_line and toks[pos][0] != "{":
            parts.append(take()[0])
        if not parts:
            raise err("joint without a name", kw_line)
        jname = " ".join(parts)
        bad = CONTROL.search(jname)
        if bad:
            raise err(f"joint name {quoted(jname)} contains control character U+{ord(bad.group()):04X}", kw_line)
        if jname in seen:
            raise err(f"joint name {quoted(jname)} appears twice", kw_line)
        if len(h.names) >= MAX_JOINTS:
            raise err(f"more than {MAX_JOINTS:,} joints; this is not a skeleton torchsplice can use", kw_line)
        idx = len(h.names)
        seen.add(jname)
        h.names.append(jname)
        h.parents.append(parent)
        take("{")
        take("OFFSET")
        h.offsets.append(floats(3, "OFFSET"))
        h.channels.append([])
        if pos < len(toks) and toks[pos][0].upper() == "CHANNELS":
            take()
            tok, cline = take()
            if not _COUNT.match(tok):
                raise err(f"channel count must be a whole number (ASCII digits), found {quoted(tok)}", cline)
            count = int(tok) if len(tok) <= 6 else 10**6
            if count > len(_CHANNEL_NAMES):
                raise err(f"joint {quoted(jname)} declares {quoted(tok)} channels; at most {len(_CHANNEL_NAMES)} exist", cline)
            for _ in range(count):
                ctok, cl = take()
                c = _CHANNEL_NAMES.get(ctok.lower())
                if c is None:
                    hint = " (CHANNELS count too large?)" if ctok.upper() in ("JOINT", "END", "}") else ""
                    raise err(f"bad channel name {quoted(ctok)} for joint {quoted(jname)}{hint}", cl)
                if c in h.channels[idx]:
                    raise err(f"channel {c} repeated for joint {quoted(jname)}", cl)
                h.channels[idx].append(c)
            rot = [c for c in h.channels[idx] if c in ROTATION_CHANNELS]
            if len(rot) not in (0, 3):
                raise err(f"joint {quoted(jname)} has {len(rot)} rotation channels; 0 or 3 are supported", cline)
        return idx

    if not toks or toks[0][0].upper() != "HIERARCHY":
        found = f", found {quoted(toks[0][0])}" if toks else ""
        raise _error(path, f"missing HIERARCHY at the start of the file{found}", toks[0][1] if toks else 1)
    take("HIERARCHY")
    _, root_line = take("ROOT")
    stack = [open_joint(-1, root_line)]  # the joints whose '}' is still to come
    while stack:
        tok, tline = take()
        up = tok.upper()
        if up == "}":
            stack.pop()
        elif up == "JOINT":
            stack.append(open_joint(stack[-1], tline))
        elif up == "END":
            take("Site")
            take("{")
            take("OFFSET")
            h.end_parents.append(stack[-1])
            h.end_offsets.append(floats(3, "End Site OFFSET"))
            take("}")
        else:
            hint = " (CHANNELS count too small?)" if tok.lower() in _CHANNEL_NAMES else ""
            raise err(f"unexpected {quoted(tok)} in joint {quoted(h.names[stack[-1]])}{hint}", tline)
    if pos < len(toks):
        tok, line = toks[pos]
        if tok.upper() == "ROOT":
            raise err("more than one ROOT; only single-root skeletons are supported", line)
        raise err(f"unexpected {quoted(tok)} after the hierarchy (one '}}' too many?)", line)
    return h


def _find_motion(lines: list[str], path) -> tuple[int, int, float, int]:
    """Locate MOTION; return (motion line index, frame count, frame time, first data line index)."""
    motion = next((i for i, l in enumerate(lines) if l.strip().upper() == "MOTION"), None)
    if motion is None:
        if not any(l.strip() for l in lines):
            raise _error(path, "empty file")
        first = next(i for i, l in enumerate(lines) if l.strip())
        head = lines[first].split()[0]
        if head.upper() != "HIERARCHY":  # neither section: some other kind of file
            shown = head if len(head) <= 30 else head[:27] + "..."
            raise _error(path, f"not a BVH file: it starts with {shown!r}, and a BVH file starts with HIERARCHY "
                               "and holds a MOTION section", first + 1)
        raise _error(path, "missing MOTION section (truncated file?)", len(lines))
    i = motion + 1

    def field(i, key):
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i >= len(lines):
            raise _error(path, f"missing '{key}:' line after MOTION (truncated file?)", i)
        text = lines[i].strip()
        k, sep, v = text.partition(":")
        if not sep or " ".join(k.split()).lower() != key.lower():
            raise _error(path, f"expected '{key}:', found {quoted(text, 50)}", i + 1)
        return i, v.strip()

    i, frames = field(i, "Frames")
    if not _COUNT.match(frames):
        raise _error(path, f"frame count must be a whole number (ASCII digits), found {quoted(frames)}", i + 1)
    if len(frames.lstrip("0")) > 12:
        raise _error(path, f"absurd frame count {quoted(frames)}", i + 1)
    n = int(frames)
    if n <= 0:
        raise _error(path, f"zero frames (Frames: {n})", i + 1)
    i, ft = field(i + 1, "Frame Time")
    if not _NUMBER.match(ft):
        raise _error(path, f"frame time is not a number: {quoted(ft)}", i + 1)
    dt = float(ft)
    if not MIN_FRAME_TIME <= dt <= MAX_FRAME_TIME:
        raise _error(path, f"frame time {quoted(ft)} s is outside [{MIN_FRAME_TIME:g}, {MAX_FRAME_TIME:g}] s "
                           "(1 to 1,000 fps)", i + 1)
    return motion, n, dt, i + 1


def _parse_rows_slowly(lines: list[str], rows: list[int], n_channels: int, path) -> np.ndarray:
    """Token by token, after a failed vectorised parse: the values, or the first offending line."""
    data = np.empty((len(rows), n_channels))
    last_row = rows[-1] if rows else -1
    for r, i in enumerate(rows):
        parts = lines[i].split()
        for p in parts:
            if not (_NUMBER.match(p) or _NON_FINITE.match(p)):
                raise _error(path, f"non-numeric value {quoted(p)} in frame {r}", i + 1)
        if len(parts) != n_channels:
            cut = i == last_row and len(parts) < n_channels and not any(l.strip() for l in lines[i + 1:])
            hint = " (truncated file?)" if cut else ""
            raise _error(path, f"expected {n_channels} values in the frame, found {len(parts)}{hint}", i + 1)
        data[r] = [float(p) for p in parts]
    return data


def _parse_frames(lines: list[str], first: int, n_frames: int, labels: list[str], path):
    """The declared frames as a ``(n_frames, C)`` float64 array, with the number of non-blank
    lines after them and the line number of the first (``0, None`` when there are none).

    ``labels`` names the ``C`` channel columns (``"joint channel"``) for messages. The frame
    count is never used to allocate: a file that declares more frames than it holds is
    refused once its lines run out.
    """
    n_channels = len(labels)
    if n_channels == 0:
        raise _error(path, "no joint has CHANNELS, so the frames hold nothing to animate", first)
    rows, i, L = [], first, len(lines)
    while i < L and len(rows) < n_frames:
        if lines[i].strip():
            rows.append(i)
        i += 1
    if not rows:
        raise _error(path, f"truncated file: header says {n_frames} frames, found 0", L)
    data = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = np.loadtxt([lines[j] for j in rows], dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        pass
    if data is None or data.shape != (len(rows), n_channels):
        data = _parse_rows_slowly(lines, rows, n_channels, path)
    if len(rows) < n_frames:
        raise _error(path, f"truncated file: header says {n_frames} frames, found {len(rows)}", L)
    finite = np.isfinite(data)
    bad = ~finite | (np.abs(np.where(finite, data, 0.0)) > MAX_ABS_VALUE)
    if bad.any():
        r, c = (int(v) for v in np.argwhere(bad)[0])
        parts = lines[rows[r]].split()
        token = parts[c] if c < len(parts) else str(data[r, c])
        what = f"non-finite value {quoted(token)}" if not finite[r, c] else \
            f"absurd value {quoted(token)} (beyond {MAX_ABS_VALUE:g})"
        raise _error(path, f"{what} in frame {r} (channel {c}: {quoted(labels[c], 50)})", rows[r] + 1)
    extra = [j for j in range(i, L) if lines[j].strip()]
    return data, len(extra), (extra[0] + 1 if extra else None)


def parse_bvh(text: str, path="<string>", dtype: torch.dtype = torch.float32, name: str = "") -> Motion:
    """Parse BVH text into a :class:`Motion`; ``path`` is only used in messages.

    ``text`` may also be the file's bytes (decoded as :func:`read_bvh` does). Raises
    :class:`BVHError`; warns with :class:`BVHWarning` when lines after the declared frames
    are ignored (once the rest of the file has been read without error).
    """
    if isinstance(text, (bytes, bytearray)):
        text = _decode(bytes(text))
    if not isinstance(text, str):
        raise TypeError(f"parse_bvh: text must be a str or bytes, got {type(text).__name__}")
    if not (isinstance(dtype, torch.dtype) and dtype.is_floating_point):
        raise TypeError(f"parse_bvh: dtype must be a floating torch.dtype, got {dtype!r}")
    if text.startswith("\ufeff"):
        text = text[1:]
    lines = _split_lines(text)
    motion_line, n_frames, dt, first = _find_motion(lines, path)
    h = _parse_hierarchy(lines, motion_line, path)
    cols, n_channels = channel_columns(h.channels)
    labels = [f"{jn} {c}" for jn, ch in zip(h.names, h.channels) for c in ch]
    data, n_extra, extra_line = _parse_frames(lines, first, n_frames, labels, path)

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
            raise _error(path, f"joint {quoted(h.names[j])} has non-unit {a}scale values; scaling is not supported")

    channels = [[c for c in ch if c not in _SCALE_CHANNELS] for ch in h.channels]
    try:
        skeleton = Skeleton(h.names, h.parents, offsets, channels, h.end_parents, h.end_offsets)
    except ValueError as exc:
        raise _error(path, str(exc)) from None
    fps = 1.0 / dt
    if abs(fps - round(fps)) <= 1e-4 * fps:
        fps = float(round(fps))
    if n_extra:
        warnings.warn(BVHWarning(path, f"{n_extra} line{'s' if n_extra > 1 else ''} after the declared "
                                       f"{n_frames} frames ignored", extra_line), stacklevel=2)
    return Motion(
        skeleton=skeleton,
        rotations=rot.to(dtype),
        root_translation=trans[:, 0].to(dtype),
        translations=trans.to(dtype) if skeleton.has_joint_translations else None,
        fps=fps,
        name=name,
        source=str(path),
    )


from .bvh_write import format_bvh, write_bvh  # noqa: E402 (users read and write BVH from this module)
