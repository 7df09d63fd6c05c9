"""How much disk a job's output takes, estimated from its plan before any work.

A standing action's result is as long as its locomotion and a time-aligned one at most as long
as the shorter clip of its pair, so the output's frames are known, about, from the plan. Each frame stores a rotation per joint (16 bytes), the
root position (12), each joint's translation where the skeleton animates them (12 per joint)
and the action frame (4); each clip about :data:`TABLE_BYTES_PER_CLIP` of table (names,
labels, provenance). :data:`STORED` gives, per compression, the share of those bytes that
reaches the disk, measured on the shipped datasets (Bandai Namco, CMU, LAFAN1 and the
sample): rotations do not shrink under ``auto`` (stored raw) and shrink to 0.6-0.8 under
``lzf`` and ``gzip``; translations that barely move (Bandai Namco's joints) shrink tenfold,
roots that travel to about 0.75. Each share is the largest seen, so the estimate errs on the
large side by a few percent (the 307,372-clip Bandai Namco job: 20.6 GB estimated, 19.6 GB
written).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.method_table import builtin
from .plan import action_key
from .sources import clip_key
from .task import OUTPUT_COLUMNS

__all__ = ["OutputSize", "estimate_output", "STORED", "TABLE_BYTES_PER_CLIP", "format_bytes"]

TABLE_BYTES_PER_CLIP = 1300
"""Bytes of clip table per clip (its strings included), measured at 1,220 on Bandai Namco."""

COLUMN_BYTES = 36_000
"""Bytes an output column takes beyond its clips' values (its dataset's first chunk: measured
at 35,200 for a float column)."""
FILE_BYTES = (1 << 20) + (len(OUTPUT_COLUMNS) - 17) * COLUMN_BYTES
"""Bytes of a database beyond its clips' frames and table (HDF5's structures): measured at 1 MiB
when the output had 17 columns; each further column adds :data:`COLUMN_BYTES`."""

CHUNK_FRAMES = 256
"""Frames per chunk of an output (see :class:`~torchsplice.job.sink.HDF5Sink`): each skeleton's
last chunk is stored whole."""

STORED = {
    None: {"rotations": 1.0, "root_translation": 1.0, "translations": 1.0, "action_frame": 1.0},
    "auto": {"rotations": 1.0, "root_translation": 0.8, "translations": 0.1, "action_frame": 0.85},
    "lzf": {"rotations": 0.85, "root_translation": 0.8, "translations": 0.1, "action_frame": 0.85},
    "gzip": {"rotations": 0.8, "root_translation": 0.75, "translations": 0.06, "action_frame": 0.85},
}
"""Share of each frame dataset's raw bytes written to disk, per compression (see the module docstring)."""


@dataclass
class OutputSize:
    """An output's expected ``frames``, ``clips`` and ``bytes`` on disk."""

    frames: int
    clips: int
    bytes: int


def frame_bytes(joints: int, joint_translations: bool, compression) -> float:
    """Expected bytes on disk of one frame of a skeleton of ``joints`` joints."""
    f = STORED[compression]
    return (16 * joints * f["rotations"] + 12 * f["root_translation"] + 4 * f["action_frame"]
            + (12 * joints * f["translations"] if joint_translations else 0.0))


PART_BYTES = {"timewarp": 0.9 * (8 + 16 + 4), "standing": 0.9 * 4}  # measured: 0.9 of raw under LZF
"""An alignment store's bytes on disk per spliced frame (``--store alignment``): the curve
(float64) and the pelvis's rotation (float32) of a timewarp clip, and the action frame, under
LZF; a standing clip's frames take only their action frame."""
PART_TABLE_BYTES = 100
"""An alignment store's further table bytes per clip (its parts' integers)."""
BANK_SHARE = 0.75
"""Share of a bank's raw float32 rotations and translations that LZF writes to disk."""


def _alignment_bytes(plan, skeleton_of, info) -> float:
    """The banks of an alignment store: every clip of every group once per frame rate."""
    seen, total = set(), 0.0
    for n, g in enumerate(plan.groups):
        J = skeleton_of(n).num_joints
        for key in g.clips:
            if (key, g.fps) not in seen and key in info:
                seen.add((key, g.fps))
                frames, fps = info[key]
                total += frames * g.fps / fps * J * 28 * BANK_SHARE
    return total


def _pair_frames(plan, info) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per pair of ``plan``, each ``(N,)`` float64: its locomotion's frames, its action's frames
    and the action's frame rate (as its group holds the action), looked up once per clip."""
    pairs, same = plan.pairs, plan.same_db
    rows, at = np.unique(pairs.column("loco"), return_inverse=True)
    loco = np.array([info[clip_key("L", r, same)][0] for r in rows.tolist()], dtype=np.float64)[at]
    target = pairs.column("target").astype(np.int64)
    k = int(target.max(initial=-1)) + 2  # one code per (action, target)
    codes, at = np.unique(pairs.column("action").astype(np.int64) * k + target + 1, return_inverse=True)
    act = np.array([info[action_key(c // k, None if c % k == 0 else c % k - 1, same)] for c in codes.tolist()],
                   dtype=np.float64).reshape(-1, 2)[at]
    return loco, act[:, 0], act[:, 1]


def estimate_output(plan, skeleton_of, compression, copied: list | None = None, store: str = "motion") -> OutputSize:
    """The expected size of ``plan``'s output. ``skeleton_of(group)`` gives a locomotion group's
    :class:`~torchsplice.core.skeleton.Skeleton`; ``copied`` lists ``(frames, skeleton)`` of
    the source clips copied in as well (``copy_sources``). A standing action's result is as long
    as its locomotion; a time-aligned one at most as long as the shorter clip of the pair.
    ``store="alignment"``: its parts (:data:`PART_BYTES`) and banks instead of the spliced
    clips' frames (but those of the built-ins that store frames, cpmc, through the timewarp, and of
    plug-ins: :attr:`~torchsplice.core.method_table.BuiltinMethod.stores`)."""
    frames = clips = 0
    total = 0.0
    info = {k: (c.frames, c.fps) for k, c in plan.clips.items()}
    if store == "alignment":
        total += _alignment_bytes(plan, skeleton_of, info)
    for g in {t.group for t in plan.tasks}:  # the last, partly filled chunk of each skeleton's frames
        sk = skeleton_of(g)
        total += CHUNK_FRAMES * frame_bytes(sk.num_joints, sk.has_joint_translations, None)
    loco_frames, act_frames, act_fps = _pair_frames(plan, info)
    for t in plan.tasks:
        g = plan.groups[t.group]
        lf = loco_frames[t.start:t.stop]
        n = lf if t.mode == "standing" else np.minimum(lf, act_frames[t.start:t.stop] * g.fps / act_fps[t.start:t.stop])
        count = int(n.sum())
        sk = skeleton_of(t.group)
        frames += count
        clips += t.size
        row = builtin(t.method)
        if store == "alignment" and (t.mode == "standing" or (row is not None and row.stores == "parts")):
            total += count * PART_BYTES["standing" if t.mode == "standing" else "timewarp"] + t.size * PART_TABLE_BYTES
        else:
            total += count * frame_bytes(sk.num_joints, sk.has_joint_translations, compression)
    for n, sk in copied or ():
        frames += n
        clips += 1
        total += n * frame_bytes(sk.num_joints, sk.has_joint_translations, compression)
    return OutputSize(frames=frames, clips=clips, bytes=int(total + clips * TABLE_BYTES_PER_CLIP + FILE_BYTES))


def format_bytes(n: float) -> str:
    """``1.2 GB``, ``340 MB``, ``12 kB``."""
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if abs(n) >= size:
            return f"{n / size:,.1f} {unit}"
    return f"{int(n)} bytes"
