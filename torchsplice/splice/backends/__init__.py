"""Splicing backends: one interface for splicing a batch of pairs, whatever computes it.

A backend takes clips of one skeleton at one frame rate, *prepared* once (:meth:`Backend.prepare`),
and splices batches of pairs of them, given as indices into the prepared clips. Everything above
(:func:`torchsplice.splice.splice_pairs` and the n x m job) calls only this interface; which
backend runs is decided once, by :func:`resolve_backend`.

Built in:

- ``"compiled"`` (:mod:`.compiled`): the numba kernels of :mod:`torchsplice.cpu` on the CPU, one
  pair per thread, float64; the built-in methods only.
- ``"torch"`` (:mod:`.torch_backend`): each method's torch function on padded pair tensors, on
  any device; every method, plug-ins too. It is the reference the compiled kernels are tested
  against.

A new backend is one module: a :class:`Backend` subclass and a :func:`register_backend` call
(from a plug-in module, see :func:`torchsplice.splice.registry.load_plugins`). It declares the
devices it computes on and a priority (:attr:`Backend.devices`, :attr:`Backend.priority`):
``"auto"`` runs the available backend of highest priority on the job's device. It gives the
time alignment's DP it computes with too (:attr:`Backend.dynamic_program`): the torch DP unless
it overrides it; :func:`~torchsplice.align.timewarp.timewarp` asks the registered backends for it
(:func:`dynamic_program_for`), by the same rule, so one registration serves both.

Conventions of :class:`SplicedBatch` (the one result type of every backend): pair ``b``'s frames
are rows ``start[b] : start[b] + frames[b]`` of the packed arrays; rotations are local WXYZ
quaternions, translations local (row 0 the root's position), in the skeleton's units; ``curve``
and ``crop`` count action frames *at the locomotion's frame rate*; angles are in degrees.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

from ...core.errors import TorchspliceError
from ...core.priority import highest_priority

if TYPE_CHECKING:
    import numpy as np

__all__ = ["Backend", "SplicedBatch", "PairFailedError", "register_backend", "get_backend", "available_backends", "backend_choices",
           "resolve_backend", "backend_for", "device_type", "dynamic_program_for"]

# numpy, torch and the modules that load them are imported where used: the command line lists the
# backends without them.


@dataclass
class SplicedBatch:
    """Spliced pairs, packed along frames (see the module docstring for the conventions).

    Attributes:
        start, frames: ``(B,)`` int64: where each pair's frames start, and how many (0 for a
            pair that failed).
        rotations ``(N, J, 4)``, translations ``(N, J, 3)``: the result frames (float32 or
            float64 numpy arrays, or torch tensors from a torch backend).
        curve ``(N,)`` float64: for each frame, the action frame it carries (at the locomotion's
            rate, from the action's first frame).
        correction ``(N,)`` float64: per-frame pelvis correction, degrees.
        crop ``(B,)``: action frames skipped at the start (at the locomotion's rate).
        cost ``(B,)``: mean lower-body frame distance along the path (NaN: not aligned).
        posture ``(B,)``: posture-transfer angle, degrees.
        paths: a sequence, per pair, of the ``(P, 2)`` int64 DP path (locomotion frame, cropped
            action frame).
        failed: pair index -> why it could not be spliced (those pairs have no frames).
        parts: what the frames were assembled from, where the backend gives it (the compiled
            splicer; ``None`` otherwise): ``curve (N,)`` float64 (the action frame counted from
            the crop, at the locomotion's rate), ``pelvis (N, 4)`` (timewarp pairs) or ``None``,
            and per pair ``crop``, ``window``, ``loops (B, 2)`` in the bank's frames (see
            :mod:`torchsplice.cpu.assemble`).
    """

    start: np.ndarray
    frames: np.ndarray
    rotations: Any
    translations: Any
    curve: np.ndarray
    correction: np.ndarray
    crop: np.ndarray
    cost: np.ndarray
    posture: np.ndarray
    paths: Any
    failed: dict
    parts: dict | None = None

    def __len__(self) -> int:
        return len(self.frames)

    def rows(self, b: int) -> slice:
        """The packed rows of pair ``b``."""
        s = int(self.start[b])
        return slice(s, s + int(self.frames[b]))

    @classmethod
    def concat(cls, parts: list["SplicedBatch"]) -> "SplicedBatch":
        """The batches ``parts``, one after another, as one batch (pairs renumbered in order)."""
        import numpy as np
        from ...core.ranges import lengths_to_starts

        frames = np.concatenate([p.frames for p in parts]).astype(np.int64)
        start = lengths_to_starts(frames)
        failed, at = {}, 0
        for p in parts:
            failed.update({at + b: why for b, why in p.failed.items()})
            at += len(p)

        def cat(name):
            arrays = [getattr(p, name) for p in parts]
            if isinstance(arrays[0], np.ndarray):
                return np.concatenate(arrays)
            import torch

            return torch.cat(arrays)

        return cls(start, frames, cat("rotations"), cat("translations"), cat("curve"), cat("correction"), cat("crop"),
                   cat("cost"), cat("posture"), [q for p in parts for q in p.paths], failed)


class PairFailedError(ValueError):
    """A pair a backend could not splice: ``pair`` (its index in the call) and ``reason``."""

    def __init__(self, pair: int, reason: str):
        super().__init__(f"pair {pair}: {reason}")
        self.pair, self.reason = pair, reason


class Backend:
    """One way to compute splices (see the module docstring). Subclasses set :attr:`name` and
    implement :meth:`prepare`, :meth:`positions`, :meth:`splice` and :meth:`standing`.

    Attributes:
        name: the name ``SpliceOptions.backend`` and the job's options select it by.
        prepares_once: whether prepared clips are worth building once per job and sharing with
            its workers (saved with :meth:`save` and mapped with :meth:`load`).
        runs_plugins: whether it runs any method (else only methods marked ``compiled``; the
            others fall back to ``"torch"``).
        devices: the torch device types it computes on (``("cpu",)``, ``("cuda",)``), or
            ``None`` for any device torch has.
        priority: how strongly ``"auto"`` prefers it: :func:`resolve_backend` chooses, among the
            registered backends available here that run on the device, the one of highest
            priority (the first registered of equals). The torch backend has 0, the compiled
            splicer 10; a GPU backend would declare ``devices=("cuda",)`` and a priority above 0.
    """

    name = ""
    prepares_once = False
    runs_plugins = True
    devices: tuple[str, ...] | None = None
    priority = 0

    def available(self) -> bool:
        """Whether it can run in this installation."""
        return True

    def runs_on(self, device: str | None) -> bool:
        """Whether it computes on ``device`` (``None``: the CPU): its type is one of :attr:`devices`."""
        return self.devices is None or device_type(device) in self.devices

    @property
    def dynamic_program(self):
        """The time alignment's DP it computes with (a
        :class:`~torchsplice.align.timewarp.DynamicProgram`): what
        :func:`~torchsplice.align.timewarp.timewarp` runs on a device this backend is chosen for
        (:func:`dynamic_program_for`). The torch DP by default, which runs on any device; a backend
        with a DP of its own (the compiled splicer's, a GPU kernel) gives it here."""
        from ...align.timewarp import TORCH_DP

        return TORCH_DP

    def prepare(self, motions: list, skeleton, roles, options) -> Any:
        """Clips ``motions`` (one skeleton, one frame rate) made ready to splice; pairs then name
        clips by their index in ``motions``."""
        raise NotImplementedError

    def positions(self, prepared, rows=None) -> tuple:
        """``(positions (B, T, J, 3) float32, lengths (B,))`` of prepared clips ``rows`` (all by
        default), padded: what the locomotion check reads."""
        raise NotImplementedError

    def inside_body(self, rotations, translations, lengths, skeleton, body, per_frame: bool = False) -> tuple:
        """``(share, depth)`` per result of how it puts a hand inside its ``body``
        (:func:`~torchsplice.ops.plausibility.penetration_packed`; depth in the skeleton's units)
        from its packed frames: ``rotations (N, J, 4)``, ``translations (N, J, 3)`` (row 0 the
        root), ``lengths (B,)``. With ``per_frame``, also each frame's deepest ``(N,)``, which
        :func:`~torchsplice.ops.plausibility.penetration_of_frames` turns into the same two (exact
        where deeper than :data:`~torchsplice.ops.plausibility.FRAME_FLOOR` of the body's margin,
        no deeper than that elsewhere). By torch here; a backend may compute the same figures its
        way."""
        import numpy as np
        import torch

        from ...core.fk import forward_kinematics
        from ...ops.body import inside_depth
        from ...ops.plausibility import penetration_of_frames

        t = torch.as_tensor(np.asarray(translations, dtype=np.float64))
        positions, _ = forward_kinematics(torch.as_tensor(np.asarray(rotations, dtype=np.float64)), t[:, 0],
                                          skeleton.offsets, skeleton.parents, t)
        deepest = inside_depth(positions, body).flatten(-2).amax(-1)
        share, depth = penetration_of_frames(deepest, np.asarray(lengths, dtype=np.int64), body.margin)
        return (share.numpy(), depth.numpy()) + ((deepest.numpy(),) if per_frame else ())

    def figures(self, rotations, translations, lengths, fps, skeleton, joints, up_axis: int, per_metre: float) -> dict:
        """The job's figures of what a person would reject, per result, from its packed frames (as
        :meth:`inside_body` takes them): ``foot_skate``, ``foot_slide`` (cm/s), ``floor`` (cm) and
        ``jerk`` (m/s^3) ``(B,)`` numpy (:func:`~torchsplice.ops.plausibility.clip_figures`;
        ``joints`` its :func:`~torchsplice.ops.plausibility.figure_joints`). By torch here, one
        padded batch; a backend may compute the same its way."""
        import numpy as np
        from ...core.ranges import lengths_to_starts
        import torch

        from ...core.fk import forward_kinematics
        from ...ops.plausibility import clip_figures

        lengths = np.asarray(lengths, np.int64)
        B, T = len(lengths), int(lengths.max()) if len(lengths) else 0
        starts = lengths_to_starts(lengths)
        rows = np.minimum(starts[:, None] + np.arange(T)[None, :], starts[:, None] + np.maximum(lengths - 1, 0)[:, None])
        t = torch.as_tensor(np.asarray(translations, np.float64)[rows])
        pos, grot = forward_kinematics(torch.as_tensor(np.asarray(rotations, np.float64)[rows]), t[..., 0, :],
                                       skeleton.offsets.to(torch.float64), skeleton.parents, t)
        out = clip_figures(pos, grot, torch.as_tensor(lengths), torch.as_tensor(np.asarray(fps, np.float64)).expand(B),
                           joints, up_axis, per_metre)
        return {k: v.numpy() for k, v in out.items()}

    def keep_hands_out(self, rotations, translations, lengths, fps: float, skeleton, body, arms, allowed,
                       deepest=None, starts=None, out=None, changed=None) -> tuple:
        """``(rotations, corrected)``: packed result frames (as :meth:`inside_body` takes them)
        with the arms moved out of ``body`` where a forearm goes deeper than ``allowed`` ``(B,)``
        (the skeleton's units), and the frames changed per result
        (:func:`~torchsplice.ops.hands.keep_hands_out`). ``starts`` ``(B,)``: where each result's
        frames begin in the arrays (default one after another; the ranges must not overlap), so
        that a few results of a larger batch are corrected where they lie; ``out``: the array to
        write, holding the rotations already (``rotations`` itself, or a copy: a backend may
        write only the values it changes; default a copy), returned. ``deepest`` ``(N,)``, where
        given, is each frame's from :meth:`inside_body` (``per_frame``), indexed as the
        rotations: a backend may skip the frames it shows cannot be pushed, for the same result.
        ``changed`` ``(N,)`` uint8, where given, gets or-ed in per frame a bit per joint of
        ``arms.moved`` (bit ``i`` its ``i``-th) whose value changed; a joint given back its own
        value (NaN counting as equal to NaN) keeps its bits in ``out`` (a zero's sign included).
        The job reads the corrected arms from these bits alone: a backend that overrides this
        method fills them. By torch here, on every frame; a backend may do the same its way."""
        import numpy as np
        from ...core.ranges import lengths_to_starts, ranges_to_rows
        import torch

        from ...ops.hands import keep_hands_out

        lengths = np.asarray(lengths, np.int64)
        starts = lengths_to_starts(lengths) if starts is None else np.asarray(starts, np.int64)
        rows = ranges_to_rows(starts, lengths)
        rotations = np.asarray(rotations)
        new, corrected = keep_hands_out(torch.as_tensor(rotations[rows]), torch.as_tensor(np.asarray(translations)[rows]),
                                        lengths, fps, skeleton, body, arms, torch.as_tensor(np.asarray(allowed, np.float64)))
        out = np.array(rotations, copy=True) if out is None else out
        moved = list(arms.moved)
        was = out[rows[:, None], moved]  # (R, 4, 4): what `out` holds of the moved joints
        now = new.numpy().astype(out.dtype, copy=False)[:, moved]
        differs = ((now != was) & ~(np.isnan(now) & np.isnan(was))).any(-1)  # (R, 4): the joints whose value changed
        r, j = np.nonzero(differs)
        out[rows[r], np.asarray(moved)[j]] = now[r, j]
        if changed is not None:
            changed[rows] |= (differs * (1 << np.arange(4))).sum(-1).astype(np.uint8)
        return out, corrected.numpy()

    def locomotion_checks(self, prepared, loco_rows, action_rows, roles, fps: float, options) -> tuple[list, list]:
        """The locomotion checks (:func:`~torchsplice.splice.locomotion.check_locomotion`) of
        prepared clips ``loco_rows`` and ``action_rows``; by default one padded batch of both."""
        from ..clips import ClipTensors
        from ..locomotion import check_locomotion

        rows = [*loco_rows, *action_rows]
        pos, lengths = self.positions(prepared, rows)
        checks = check_locomotion(ClipTensors(None, None, lengths, pos, None), roles, fps)
        return checks[:len(loco_rows)], checks[len(loco_rows):]

    def splice(self, prepared, loco, action, reference, method, options, fps: float, *, buffers=None,
               keep_going: bool = False) -> SplicedBatch:
        """Splice pairs ``(loco[b], action[b])`` of prepared clips (``reference[b]`` too, for a
        method that needs one) with ``method`` (a :class:`~torchsplice.splice.registry.Method`).
        A pair that cannot be spliced raises (:class:`PairFailedError`, or the method's own
        error), or with ``keep_going`` is listed in ``failed``."""
        raise NotImplementedError

    def standing(self, prepared, loco, action, acting, tables, method, options, fps: float, *,
                 buffers=None, keep_going: bool = False) -> SplicedBatch:
        """Splice standing actions (see :mod:`torchsplice.splice.standing`): ``acting[b]`` the
        arms pair ``b`` takes from its action (names of :data:`~torchsplice.splice.standing.LIMBS`),
        ``tables`` from :func:`~torchsplice.splice.standing.standing_tables`; ``keep_going`` as
        for :meth:`splice`."""
        raise NotImplementedError

    # Resources. A backend that computes in threads of its own says how many here.
    def assembly_bank(self, prepared) -> dict | None:
        """What an alignment store keeps of prepared clips whose pairs this backend gives parts
        for (:attr:`SplicedBatch.parts`): ``rotations (N, J, 4)`` and ``translations (N, J, 3)``
        float64, packed, ``lengths (C,)``, the upper-body joint indices ``upper`` and the
        ``pelvis``; ``None`` for a backend that gives no parts."""
        return None

    def threads(self) -> int | None:
        return None

    def set_threads(self, n: int | None) -> None:
        return None

    def new_buffers(self):
        """Output room reused from batch to batch by one caller (``None``: none)."""
        return None

    def preload(self) -> None:
        """Load what a forked worker would otherwise load itself (before a fork)."""
        return None

    def save(self, prepared, folder) -> None:
        raise NotImplementedError

    def load(self, folder):
        raise NotImplementedError

    def prepared_bytes(self, prepared) -> int:
        """Bytes :meth:`save` writes for ``prepared``."""
        return 0


_REGISTRY: dict[str, Callable[[], Backend]] = {}
_INSTANCES: dict[str, Backend] = {}
_BUILTIN = {"compiled": ".compiled", "torch": ".torch_backend"}


def register_backend(name: str, factory: Callable[[], Backend], replace_existing: bool = False) -> None:
    """Make backend ``name`` available to ``SpliceOptions(backend=name)`` and the job: ``factory()``
    gives the :class:`Backend` (made once per process, on first use)."""
    if not isinstance(name, str) or not name or name == "auto":
        raise TorchspliceError(f"a backend needs a name other than 'auto', got {name!r}")
    if (name in _REGISTRY or name in _BUILTIN) and not replace_existing:
        raise TorchspliceError(f"a backend named {name!r} is registered already")
    _REGISTRY[name] = factory
    _INSTANCES.pop(name, None)


def available_backends() -> list[str]:
    """Names of the registered backends (the built-in ones first)."""
    return list(dict.fromkeys([*_BUILTIN, *_REGISTRY]))


def backend_choices() -> tuple[str, ...]:
    """What ``SpliceOptions.backend`` accepts: ``"auto"`` and every registered backend."""
    return ("auto", *available_backends())


def get_backend(name: str) -> Backend:
    """The backend registered as ``name``."""
    if name not in _INSTANCES:
        if name in _REGISTRY:
            made = _REGISTRY[name]()
        elif name in _BUILTIN:
            made = importlib.import_module(_BUILTIN[name], __name__).BACKEND
        else:
            raise TorchspliceError(f"unknown backend {name!r}; choose one of {', '.join(backend_choices())}")
        if not isinstance(made, Backend):
            raise TorchspliceError(f"backend {name!r} is not a torchsplice Backend (got {type(made).__name__})")
        _INSTANCES[name] = made
    return _INSTANCES[name]


def device_type(device) -> str:
    """The type of a torch device given as ``None`` (the CPU), a string (``"cuda:1"``) or a
    ``torch.device``: ``"cpu"``, ``"cuda"``, ... (without importing torch)."""
    if device is None:
        return "cpu"
    return str(getattr(device, "type", device)).split(":")[0]


def resolve_backend(backend: str, device: str | None) -> str:
    """The backend's name that ``backend`` (a name, or ``"auto"``) means on ``device``:
    ``"auto"`` is, among every registered backend available in this installation that runs on
    ``device``, the one of highest :attr:`Backend.priority` (so the compiled splicer on the CPU
    when numba is installed, else torch)."""
    if backend not in backend_choices():
        raise TorchspliceError(f"unknown backend {backend!r}; choose one of {', '.join(backend_choices())}")
    if backend == "auto":
        best = highest_priority((get_backend(name) for name in available_backends()), device)
        if best is None:
            raise TorchspliceError(f"no backend runs on device {device!r}")
        return best.name
    chosen = get_backend(backend)
    if not chosen.runs_on(device):
        there = [n for n in available_backends() if get_backend(n).runs_on(device)]
        where = "the CPU" if chosen.devices == ("cpu",) else f"{' or '.join(chosen.devices or ())} devices"
        raise TorchspliceError(f"the {backend} backend runs on {where}; device {device!r} needs backend "
                               f"{' or '.join(repr(n) for n in [*there, 'auto'])}")
    return backend


def dynamic_program_for(backend: str, device):
    """The DP (:attr:`Backend.dynamic_program`) that :func:`~torchsplice.align.timewarp.timewarp`
    runs for a grid on ``device`` (a ``torch.device``) when ``backend`` is asked for: the named
    backend's, or with ``"auto"`` that of the backend :func:`resolve_backend` chooses there (so the
    compiled DP for CPU tensors where numba is installed, else torch, unless a registered backend of
    higher priority runs there).

    Raises:
        ValueError: (the DP's contract) an unknown name, or a backend named for a device it does
            not run on.
    """
    if backend == "auto":
        return get_backend(resolve_backend("auto", device)).dynamic_program
    if backend not in available_backends():
        names = [repr(n) for n in backend_choices()]
        raise ValueError(f"backend must be {', '.join(names[:-1])} or {names[-1]}, got {backend!r}")
    chosen = get_backend(backend)
    if not chosen.runs_on(device):
        where = " or ".join(d.upper() for d in chosen.devices or ())
        raise ValueError(f"the {backend} backend runs on {where} tensors, got a grid on {device}")
    return chosen.dynamic_program


def backend_for(method, backend: str) -> Backend:
    """The backend that splices ``method`` when ``backend`` (resolved) is chosen: a backend that
    runs only the built-in methods hands the others to ``"torch"``."""
    chosen = get_backend(backend)
    if chosen.runs_plugins or getattr(method, "compiled", False):
        return chosen
    return get_backend("torch")
