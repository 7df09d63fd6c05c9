"""The compiled CPU backend: the numba kernels of :mod:`torchsplice.cpu`, one pair per thread.

Prepared clips are a :class:`~torchsplice.cpu.bank.ClipBank` (forward kinematics and grid
features computed once per clip, float64), which the n x m job builds once and maps into its
workers. Only the built-in methods run here; :func:`warm_up` compiles the kernels ahead of use.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from ...core.method_table import BUILTINS
from ...core.ranges import lengths_to_starts
from . import Backend, PairFailedError, SplicedBatch

# The kernels (numba), torch and the torch code are imported where used: choosing a backend
# (resolve_backend, prepares_once) loads neither, so the command line decides early, without torch,
# whether it starts the job's fork server.

__all__ = ["CompiledBackend", "BACKEND", "WARM_PARTS", "kernels_cached", "mark_cached", "warm_up"]


WARM_PARTS = ("splicer", "others")
"""The warm-up's two halves, about even in compile time (:func:`warm_up`'s ``parts``): the
whole-pair splicer alone, and every other kernel of the default paths."""


def _warmed(dtype) -> Path:
    """The record a finished :func:`warm_up` of ``dtype`` leaves in the kernel cache's folder."""
    from ...cpu import cache_dir

    return cache_dir() / f"{np.dtype(dtype).name}.warm"


def kernels_cached(dtype=np.float32) -> bool:
    """Whether a warm-up compiled every kernel of the default paths for ``dtype`` frames, for
    this version of the kernels (:func:`mark_cached`'s record). Kernels cached by a first splice,
    or by a warm-up cut short, do not count: the next warm-up compiles the rest."""
    return _warmed(dtype).is_file()


def mark_cached(dtype=np.float32) -> None:
    """Record that :func:`warm_up` compiled every part for ``dtype`` frames (in the kernels'
    cache folder, which a change to their sources replaces)."""
    _warmed(dtype).write_text(f"every kernel of the default paths is compiled for {np.dtype(dtype).name} frames\n")


def warm_up(quiet: bool = False, parts: tuple[str, ...] = WARM_PARTS, force: bool = False,
            dtype=np.float32) -> float:
    """Run every kernel of the default paths once on the built-in sample (those of ``parts``, see
    :data:`WARM_PARTS`), compiling them where the cache lacks them; returns the seconds taken
    (0 when the cache was already warm, unless ``force``); having run every part, it records so
    (:func:`mark_cached`). ``dtype``: the frames' (the splicer's
    output, the body test's and the correction's input, the alignment's grids): numba compiles
    each kernel once per type, so float64 work (``SpliceOptions(dtype=torch.float64)``, float64
    clips) needs its own warm-up (``python -m torchsplice.warmup --float64``)."""
    if kernels_cached(dtype) and not force:
        return 0.0
    t0 = time.perf_counter()
    if not quiet:
        print("setup: compiling the CPU splicer for this machine (once; one to three minutes)", file=sys.stderr, flush=True)
    from ...cpu.bank import ClipBank, splice_bank, standing_bank
    from ...sample import sample_motions
    from ...specs import load_spec
    from ..standing import standing_tables

    import torch

    frames = torch.float64 if dtype == np.float64 else torch.float32
    clips = sample_motions(frames)[:4]
    roles = load_spec("sample").bind(clips[0].skeleton)
    bank = ClipBank.from_motions(clips, clips[0].skeleton, roles)
    if "splicer" in parts:
        for method in (m.name for m in BUILTINS):
            splice_bank(bank, np.array([0, 1]), np.array([2, 3]), method, ref=np.array([0, 1]), dtype=dtype)
    if "others" not in parts:
        return time.perf_counter() - t0
    tables = standing_tables(roles, clips[0].skeleton, clips[0].fps)
    for method in (m.name for m in BUILTINS):
        for timing in ("loop", "hold", "fit"):
            standing_bank(bank, np.array([0, 1]), np.array([2, 3]), np.array([[True, False], [True, True]]), tables,
                          method, timing, dtype=dtype)
    from ...align.timewarp import cumulative_cost, timewarp

    grid = torch.rand(2, 8, 9, dtype=frames)
    timewarp(grid, max_run=3)
    cumulative_cost(grid, max_run=3)  # plot-alignment's
    from ...ops.body import body_of
    from ...ops.hands import arms_of

    m = clips[0]
    body = body_of(m.skeleton, roles)
    rot, trans = m.rotations.numpy(), m.local_translations().numpy()
    CompiledBackend().inside_body(rot, trans, [m.num_frames], m.skeleton, body)
    CompiledBackend().keep_hands_out(rot, trans, [m.num_frames], m.fps, m.skeleton, body, arms_of(m.skeleton, roles, body),
                                     [0.0])
    from ...ops.plausibility import figure_joints

    CompiledBackend().figures(rot, trans, [m.num_frames], m.fps, m.skeleton, figure_joints(m.skeleton, roles), 1, 1.0)
    if set(WARM_PARTS) <= set(parts):
        mark_cached(dtype)
    return time.perf_counter() - t0


def _floor(body) -> float:
    """How deep the body test measures each frame exactly (a little under
    :data:`~torchsplice.ops.plausibility.FRAME_FLOOR` of the margin, so that a correction whose
    target is just that may still use the measure)."""
    from ...ops.plausibility import FRAME_FLOOR

    return FRAME_FLOOR * float(body.margin) * (1.0 - 1e-5)


class CompiledBackend(Backend):
    """The compiled CPU splicer (see the module docstring)."""

    name = "compiled"
    prepares_once = True
    runs_plugins = False
    devices = ("cpu",)
    priority = 10

    def available(self) -> bool:
        from ...cpu import available

        return available()

    @property
    def dynamic_program(self):
        """The compiled DP of :mod:`torchsplice.cpu.timewarp` (CPU tensors)."""
        from ...align.timewarp import COMPILED_DP

        return COMPILED_DP

    def prepare(self, motions, skeleton, roles, options):
        from ...cpu.bank import ClipBank

        return ClipBank.from_motions(list(motions), skeleton, roles, options.align.landmarks)

    def positions(self, prepared, rows=None):
        return prepared.padded_positions(rows)

    def splice(self, prepared, loco, action, reference, method, options, fps, *, buffers=None, keep_going=False):
        from ...cpu.bank import splice_bank
        from ...cpu.splice import STATUS
        from ..options import bank_kwargs

        out = splice_bank(prepared, loco, action, method.name, ref=reference if method.needs_reference else None,
                          dtype=_dtype(options), buffers=buffers, on_error="keep", **bank_kwargs(options, fps))
        failed = {b: f"the alignment failed ({STATUS[int(s)]})" for b, s in enumerate(out.status) if s != 0}
        if failed and not keep_going:
            b = min(failed)
            raise PairFailedError(b, STATUS[int(out.status[b])])
        return SplicedBatch(out.start, out.frames, out.rotations, out.translations, out.curve,
                            np.degrees(out.correction, out=out.correction), out.crop, out.cost, np.degrees(out.posture),
                            _Paths(out.cells, out.path_length), failed, parts=_parts(out))

    def standing(self, prepared, loco, action, acting, tables, method, options, fps, *, buffers=None, keep_going=False):
        from ...cpu.bank import standing_bank
        from ..standing import LIMBS

        masks = [[n in a for n in LIMBS] for a in acting]
        out = standing_bank(prepared, loco, action, masks, tables, method.name, options.timing, dtype=_dtype(options),
                            buffers=buffers)
        B = len(out.frames)
        return SplicedBatch(out.start, out.frames, out.rotations, out.translations, out.curve, out.correction, out.crop,
                            out.cost, out.posture, [np.zeros((0, 2), np.int64)] * B, {}, parts=_parts(out))

    def inside_body(self, rotations, translations, lengths, skeleton, body, per_frame=False):
        from ...cpu.body import inside_clips
        from ...cpu.fk import joint_closure

        lengths = np.asarray(lengths, dtype=np.int64)
        starts = lengths_to_starts(lengths)
        ends = body.end_joints.numpy()
        share, depth, deepest = np.zeros(len(lengths)), np.zeros(len(lengths)), np.full(int(lengths.sum()), -np.inf)
        if len(lengths):
            inside_clips(np.ascontiguousarray(rotations), np.ascontiguousarray(translations),
                         np.asarray(skeleton.parents, dtype=np.int64), joint_closure(skeleton.parents, np.unique(ends)),
                         ends[:, 0].copy(), ends[:, 1].copy(), body.end_shares.numpy(), body.radii.numpy(),
                         np.asarray(body.probes, dtype=np.int64), np.asarray(body.obstacles, dtype=np.int64),
                         float(body.margin), _floor(body), starts, lengths, share, depth, deepest)
        return (share, depth) + ((deepest,) if per_frame else ())

    def figures(self, rotations, translations, lengths, fps, skeleton, joints, up_axis, per_metre):
        from ...cpu.figures import GMD, figures_clips
        from ...cpu.fk import joint_closure

        lengths = np.asarray(lengths, dtype=np.int64)
        B = len(lengths)
        starts = lengths_to_starts(lengths)
        feet, upper, chest = joints
        out = {k: np.zeros(B) for k in ("foot_skate", "foot_slide", "floor", "jerk")}
        if not B:
            return out
        figures_clips(np.ascontiguousarray(rotations), np.ascontiguousarray(translations),
                      np.asarray(skeleton.parents, dtype=np.int64),
                      joint_closure(skeleton.parents, np.unique([*feet, *upper, chest])), np.asarray(feet, np.int64),
                      np.asarray(upper, np.int64), int(chest), int(up_axis), float(per_metre), *GMD, starts, lengths,
                      np.asarray(fps, np.float64) * np.ones(B), out["foot_skate"], out["foot_slide"], out["floor"],
                      out["jerk"])
        out["foot_slide"] *= 100.0 / per_metre
        out["floor"] *= 100.0 / per_metre
        out["jerk"] /= per_metre
        return out

    def keep_hands_out(self, rotations, translations, lengths, fps, skeleton, body, arms, allowed, deepest=None,
                       starts=None, out=None, changed=None):
        from ...cpu.fk import joint_closure
        from ...cpu.hands import hands_out_clips
        from ...ops.hands import CLEARANCE, FLEX, HINGE_MIN, ITERATIONS, RAMP, ROUND, SLACK

        lengths = np.asarray(lengths, dtype=np.int64)
        starts = lengths_to_starts(lengths) if starts is None else np.asarray(starts, np.int64)
        rotations = np.ascontiguousarray(rotations)
        out = rotations.copy() if out is None else out  # the kernel reads a clip's rows before it writes them
        if not len(lengths):
            return out, np.zeros(0, np.int64)
        if not (out.flags.c_contiguous and out.flags.writeable and out.dtype == rotations.dtype
                and out.shape == rotations.shape):
            raise ValueError(f"out: a writable C-contiguous {rotations.dtype} array of shape {rotations.shape} is needed")
        if changed is not None and not (changed.dtype == np.uint8 and changed.shape == (len(rotations),)
                                        and changed.flags.c_contiguous and changed.flags.writeable):
            raise ValueError(f"changed: a writable contiguous uint8 array of {len(rotations)} frames is needed")
        if deepest is not None and len(deepest) != len(rotations):
            raise ValueError(f"deepest: one value per frame of the rotations ({len(rotations)}) is needed, not {len(deepest)}")
        ends = body.end_joints.numpy()
        parents = np.asarray(skeleton.parents, dtype=np.int64)
        chain = [arms.chest, *arms.shoulder, *arms.elbow, *arms.wrist]
        arm = joint_closure(skeleton.parents, np.unique(chain))
        rest = np.setdiff1d(joint_closure(skeleton.parents, np.unique(ends)), arm)  # ascending: parents first
        corrected = np.zeros(len(lengths), np.int64)
        target = np.maximum(np.asarray(allowed, np.float64), CLEARANCE * body.margin) * np.ones(len(lengths))
        w = np.maximum(np.round(RAMP * np.asarray(fps, np.float64) * np.ones(len(lengths))), 1).astype(np.int64)
        frame_deepest = np.zeros(0) if deepest is None else np.ascontiguousarray(deepest, dtype=np.float64)
        hands_out_clips(rotations, np.ascontiguousarray(translations), parents, arm, rest, ends[:, 0].copy(),
                        ends[:, 1].copy(), body.end_shares.numpy(), body.radii.numpy(),
                        np.asarray(arms.probes, np.int64), np.asarray(body.obstacles, np.int64),
                        np.array([body.names[o] in ROUND for o in body.obstacles], np.bool_), int(arms.chest),
                        np.asarray(arms.shoulder, np.int64), np.asarray(arms.elbow, np.int64),
                        np.asarray(arms.wrist, np.int64), parents[list(arms.shoulder)].copy(),
                        parents[list(arms.elbow)].copy(), starts, lengths, target, w, float(SLACK * body.margin),
                        int(ITERATIONS), float(HINGE_MIN), float(FLEX), frame_deepest, _floor(body),
                        out, corrected, np.zeros(0, np.uint8) if changed is None else changed)
        return out, corrected

    def assembly_bank(self, prepared):
        b = prepared
        return {"rotations": np.asarray(b.rot), "translations": np.asarray(b.trans), "lengths": np.asarray(b.lengths),
                "upper": np.flatnonzero(b.joints.upper).tolist(), "pelvis": b.joints.pelvis}

    def threads(self):
        from ...cpu import get_threads

        return get_threads()

    def set_threads(self, n):
        from ...cpu import set_threads

        set_threads(n)

    def new_buffers(self):
        from ...cpu.bank import Buffers

        return Buffers()

    def preload(self):
        """Before a fork: numba's ``workqueue`` threading layer (it survives a fork; GNU
        OpenMP, numba's usual one, does not) and the job's kernels loaded from the cache."""
        import numba

        numba.config.THREADING_LAYER = "workqueue"
        from ...cpu.preload import preload

        preload()

    def save(self, prepared, folder):
        prepared.save(folder)

    def load(self, folder):
        from ...cpu.bank import ClipBank

        return ClipBank.load(folder)

    def prepared_bytes(self, prepared):
        b = prepared
        return sum(a.nbytes for a in (b.rot, b.trans, b.pos, b.grot, *b.feat))


class _Paths:
    """Each pair's DP path ``(P, 2)``, cut from the kernel's padded cells when asked for (the
    job never asks)."""

    def __init__(self, cells: np.ndarray, lengths: np.ndarray):
        self.cells, self.lengths = cells, lengths

    def __len__(self) -> int:
        return len(self.lengths)

    def __getitem__(self, b: int) -> np.ndarray:
        return self.cells[b, :int(self.lengths[b])]

    def __iter__(self):
        return (self[b] for b in range(len(self)))


def _parts(out) -> dict:
    """A :class:`~torchsplice.cpu.bank.PackedSplices`' parts, as :attr:`SplicedBatch.parts`."""
    return {"curve": out.part_curve, "pelvis": out.pelvis, "crop": np.asarray(out.crop, np.int64).copy(),
            "window": out.window, "loops": out.loops}


def _dtype(options):
    import torch

    return np.float64 if options.dtype == torch.float64 else np.float32


BACKEND = CompiledBackend()
