"""Splicing methods as plug-ins: one :class:`Method` object per method, in a registry.

A method is its name, a description, whether it needs a plain-locomotion reference clip, and a
function that splices a padded batch of pairs (:class:`MethodInput`) into a common result
(:class:`MethodOutput`: the clips, the action frame of every result frame and the method's
diagnostics). :func:`~torchsplice.splice.splice_pairs`, the ``splice`` and ``splice-all``
commands, the n x m job and the evaluation report all read the registry, so a new method is
one file that calls :func:`register_method`::

    from torchsplice.splice.registry import Method, MethodOutput, register_method

    def copy_upper(inp):                       # inp.loco, inp.act: ClipTensors (B, T, J, ...)
        ...
        return MethodOutput(clips, times)      # cost, crop, paths ... default to "not measured"

    register_method(Method("copy_upper", "the action's upper body, frame by frame", copy_upper))

Plug-in modules are found in three ways: installed packages declaring an entry point in the
group ``torchsplice.methods`` (``toy = "mypackage.toy"``; the module is imported, and an entry
point naming a :class:`Method` or a function registers it or calls it), the environment
variable ``TORCHSPLICE_PLUGINS`` (comma-separated module names) and the command line's
``--plugin MODULE``. The job records the module of every plug-in method it runs in its plan,
and each worker (local processes or Ray) imports it before splicing, so the module must be
importable there (installed, or on ``PYTHONPATH``).

The built-in ``splice``, ``naive`` and ``cpmc`` are declared once, in the table
:data:`torchsplice.core.method_table.BUILTINS`, and registered from it in
:mod:`torchsplice.splice.builtin_methods`. They also run in the compiled CPU splicer
(:mod:`torchsplice.cpu`, ``compiled=True``); a plug-in method runs in torch on any device.

This module imports no torch: the command line lists the methods without loading it.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import re
import types
import warnings
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Callable, Iterable

from ..core.errors import MotionError, TorchspliceError
from ..core.method_table import BUILTINS, builtin
from ..core.names import printable

if TYPE_CHECKING:  # pragma: no cover
    import torch

    from ..specs.roles import SkeletonRoles
    from .options import SpliceOptions
    from .clips import ClipTensors

__all__ = ["Method", "MethodInput", "MethodOutput", "MethodFailedError", "run_checked", "register_method", "get_method", "available_methods",
           "load_plugins", "plugin_modules", "PLUGINS_ENV", "ENTRY_POINT_GROUP", "BUILTIN_METHODS"]

PLUGINS_ENV = "TORCHSPLICE_PLUGINS"
ENTRY_POINT_GROUP = "torchsplice.methods"
BUILTIN_METHODS = tuple(m.name for m in BUILTINS)
"""The built-in methods' names (from :data:`torchsplice.core.method_table.BUILTINS`)."""
_NAME = re.compile(r"^[a-z][a-z0-9_-]*$")


@dataclass
class MethodInput:
    """A padded batch of ``B`` pairs for a method's function, all at the locomotion's frame rate.

    Attributes:
        loco, act: :class:`~torchsplice.splice.clips.ClipTensors` of the pairs' locomotions and
            actions (row ``b`` of each is pair ``b``): rotations ``(B, T, J, 4)`` local WXYZ,
            translations ``(B, T, J, 3)`` (file units, Y up as the spec says), lengths ``(B,)``,
            positions and global rotations by FK.
        ref: the plain-locomotion references of the actions, for a method with
            ``needs_reference`` (else ``None``).
        roles: the skeleton's joint roles (:class:`~torchsplice.specs.roles.SkeletonRoles`).
        skeleton: the shared :class:`~torchsplice.core.skeleton.Skeleton`.
        options: the :class:`~torchsplice.splice.SpliceOptions` of the call.
        fps: the frame rate of every clip in the batch.
    """

    loco: "ClipTensors"
    act: "ClipTensors"
    ref: "ClipTensors | None"
    roles: "SkeletonRoles"
    skeleton: Any
    options: "SpliceOptions"
    fps: float


@dataclass
class MethodOutput:
    """What a method's function returns for a batch of ``B`` pairs.

    Attributes:
        clips: the spliced clips (:class:`~torchsplice.splice.clips.ClipTensors`, no FK needed):
            rotations ``(B, T, J, 4)``, translations ``(B, T, J, 3)``, lengths ``(B,)``. They keep
            the locomotion's skeleton and frame rate.
        times: ``(B, T)`` float, for each result frame the action frame (at the locomotion's
            rate, counted from the action's first frame) whose upper body it carries.
        cost: ``(B,)`` average lower-body frame distance along the alignment (file units
            squared); ``None``: not aligned (NaN in the results).
        crop: ``(B,)`` action frames skipped at the start (at the locomotion's rate); ``None``: 0.
        paths: per pair, the ``(P, 2)`` DP path (locomotion frame, cropped action frame);
            ``None``: empty.
        pelvis_correction: ``(B, T)`` per-frame spatial-alignment angle, degrees; ``None``: 0.
        posture_deg: ``(B,)`` posture-transfer angle, degrees; ``None``: 0.
    """

    clips: "ClipTensors"
    times: "torch.Tensor"
    cost: "torch.Tensor | None" = None
    crop: "torch.Tensor | None" = None
    paths: "list[torch.Tensor] | None" = None
    pelvis_correction: "torch.Tensor | None" = None
    posture_deg: "torch.Tensor | None" = None


@dataclass(frozen=True)
class Method:
    """One splicing method (see the module docstring).

    Attributes:
        name: what users type (``--method NAME``): lower case letters, digits, ``_`` and ``-``.
            A result clip is named ``LOCO+ACTION.NAME`` (``LOCO+ACTION`` for ``splice``).
        description: one line for ``--help`` and the documentation.
        run: ``run(MethodInput) -> MethodOutput``, batched over pairs (torch, any device).
        needs_reference: the method needs a plain-locomotion reference clip of the action's
            performer for actions that locomote (found by the spec's ``[clips.reference]`` rule).
        compiled: the compiled CPU splicer implements it under ``name`` (built-ins only).
        standing: for actions that do not locomote (standing actions),
            ``standing(MethodInput, timing, acting) -> (clips, times)``; ``None``: the method's
            ``run`` takes every pair, standing or not.
        diagnostics: which of ``"cost"``, ``"crop"`` and ``"posture"`` it measures (what
            ``torchsplice splice`` prints and the poor-alignment check reads).
        module: the module that defines it (set on registration; imported by job workers).
    """

    name: str
    description: str
    run: Callable[[MethodInput], MethodOutput]
    needs_reference: bool = False
    compiled: bool = False
    standing: Callable | None = None
    diagnostics: tuple[str, ...] = ()
    module: str = ""

    @property
    def builtin(self) -> bool:
        return self.name in BUILTIN_METHODS and self.module.startswith("torchsplice.")

    @property
    def uses_acting_limbs(self) -> bool:
        """Its standing variant takes only the acting arms from the action (a built-in's table
        row says: ``splice``); the limbs it used are then reported."""
        row = builtin(self.name)
        return row is not None and row.acting_limbs

    def clip_name(self, locomotion: str, action: str) -> str:
        """The name of a spliced clip: ``LOCO+ACTION`` for ``splice`` (a built-in without
        :attr:`~torchsplice.core.method_table.BuiltinMethod.suffix`), else ``LOCO+ACTION.NAME``."""
        row = builtin(self.name)
        return f"{locomotion}+{action}" if row is not None and not row.suffix else f"{locomotion}+{action}.{self.name}"


class MethodFailedError(MotionError):
    """A plug-in method's function raised, or returned a malformed or non-finite result: the
    pairs it was given are not spliced (the job skips them with this reason)."""


QUAT_NORM_TOLERANCE = 1e-2
"""How far from 1 a plug-in's rotation quaternions may be (then they are normalised); further
is a failure: a zero or huge quaternion is no rotation."""


def run_checked(method: Method, fn: Callable, inp: MethodInput, *args):
    """``fn(inp, *args)`` (a method's ``run`` or ``standing``), checked for a plug-in method.

    Returns what ``fn`` returns: a :class:`MethodOutput`, or ``(clips, times)`` for ``standing``.
    A plug-in whose function raises anything but a :class:`TorchspliceError` (``sys.exit``
    included), or returns clips whose rotations ``(B, T, J, 4)``, translations ``(B, T, J, 3)``,
    lengths ``(B,)`` (1 to ``T``) or times ``(B, T)`` are missing, of the wrong shape, not
    floating point (lengths: not integers), on the ``meta`` device, not finite on a valid frame,
    or whose quaternions are not of unit norm (within :data:`QUAT_NORM_TOLERANCE`), raises a
    one-line :class:`MethodFailedError` naming the method (its exception's text escaped and
    cut to 300 characters). What passes is detached from autograd, moved to the input's
    device and float type, and its quaternions normalised. Built-ins are trusted.
    """
    import torch  # here: the registry lists the methods without torch (the command line's choices)

    from .clips import ClipTensors

    who = f"method {method.name!r}" + (f" ({method.module})" if method.module else "")
    try:
        got = fn(inp, *args)
    except TorchspliceError:
        raise
    except (Exception, SystemExit) as exc:
        if method.builtin:
            raise
        text = f"called sys.exit({exc.code!r})" if isinstance(exc, SystemExit) else \
            f"{type(exc).__name__}: {' '.join(str(exc).split())}"
        raise MethodFailedError(f"{who} failed: {printable(text, limit=300)}") from None
    if method.builtin:
        return got
    if isinstance(got, MethodOutput):
        clips, times = got.clips, got.times
    elif isinstance(got, tuple) and len(got) == 2 and fn is method.standing:
        clips, times = got
    else:
        raise MethodFailedError(f"{who} returned {type(got).__name__}, not a MethodOutput")
    B, J = int(inp.loco.rotations.shape[0]), int(inp.skeleton.num_joints)
    rot, trans = getattr(clips, "rotations", None), getattr(clips, "translations", None)
    lengths = getattr(clips, "lengths", None)
    tensors = all(isinstance(x, torch.Tensor) for x in (rot, trans, lengths, times))
    T = int(rot.shape[1]) if tensors and rot.ndim == 4 else -1
    shapes = tensors and (tuple(rot.shape), tuple(trans.shape), tuple(lengths.shape), tuple(times.shape)) == (
        (B, T, J, 4), (B, T, J, 3), (B,), (B, T))
    if not shapes:
        got_shapes = ", ".join(f"{k} {tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__}"
                               for k, x in (("rotations", rot), ("translations", trans), ("lengths", lengths),
                                            ("times", times)))
        raise MethodFailedError(f"{who} returned arrays of the wrong shape for {B} pairs of {J} joints: {got_shapes} "
                                "(expected (B, T, J, 4), (B, T, J, 3), (B,) and (B, T))")
    named = (("rotations", rot), ("translations", trans), ("lengths", lengths), ("times", times))
    for what, x in named:
        if x.device.type == "meta":
            raise MethodFailedError(f"{who} returned {what} on the meta device (no data)")
        if what == "lengths" and (x.dtype == torch.bool or x.dtype.is_floating_point or x.dtype.is_complex):
            raise MethodFailedError(f"{who} returned lengths of type {x.dtype}, not integers")
        if what != "lengths" and not x.dtype.is_floating_point:
            raise MethodFailedError(f"{who} returned {what} of type {x.dtype}, not floating point")
    device, dtype = inp.loco.rotations.device, inp.loco.rotations.dtype
    rot, trans, times = (x.detach().to(device=device, dtype=dtype) for x in (rot, trans, times))
    lengths = lengths.detach().to(device=device, dtype=torch.long)
    if T < 1 or bool((lengths < 1).any()) or bool((lengths > T).any()):
        raise MethodFailedError(f"{who} returned lengths {lengths.tolist()[:8]} outside 1 to {T} frames")
    valid = torch.arange(T, device=device)[None] < lengths[:, None]  # (B, T)

    def first_bad(ok) -> str:
        b, t = (int(v) for v in (~ok).nonzero()[0])
        return f"pair {b} of {B}, frame {t}" if B > 1 else f"frame {t}"

    for what, x in (("rotations", rot), ("translations", trans), ("times", times)):
        ok = torch.isfinite(x).reshape(B, T, -1).all(-1) | ~valid
        if not bool(ok.all()):
            raise MethodFailedError(f"{who} returned {what} that are not finite ({first_bad(ok)})")
    norm = rot.norm(dim=-1)  # (B, T, J)
    ok = ((norm - 1).abs() <= QUAT_NORM_TOLERANCE).all(-1) | ~valid
    if not bool(ok.all()):
        raise MethodFailedError(f"{who} returned rotations that are not unit quaternions ({first_bad(ok)}: norms "
                                f"from {float(norm.min()):.3g} to {float(norm.max()):.3g})")
    off = valid[..., None] & ((norm - 1).abs() > 1e-5)  # quaternions off unit norm by more than rounding
    rot = torch.where(off[..., None], rot / norm.clamp_min(1e-12)[..., None], rot)
    clips = ClipTensors(rot, trans, lengths, None, None)  # results need no FK
    return replace(got, clips=clips, times=times) if isinstance(got, MethodOutput) else (clips, times)


_REGISTRY: dict[str, Method] = {}
_LOADED = {"builtins": False, "entry_points": False, "env": None, "env_loading": None}
_PLUGIN_MODULES: list[str] = []


def register_method(method: Method, replace_existing: bool = False) -> Method:
    """Add ``method`` to the registry and return it (with ``module`` filled in).

    Raises :class:`~torchsplice.core.errors.TorchspliceError` for a malformed name, a name
    already taken by another method (unless ``replace_existing``) or a missing function.
    Registering the same method again (a module imported twice) is harmless.
    """
    _ensure_loaded_builtins()  # the built-ins come first, whoever registers first
    if not isinstance(method, Method):
        raise TorchspliceError(f"register_method takes a torchsplice.splice.registry.Method, got {type(method).__name__}")
    if not isinstance(method.name, str) or not _NAME.fullmatch(method.name):
        raise TorchspliceError(f"method name {method.name!r} must be lower case letters, digits, '_' or '-', "
                               "starting with a letter")
    if not callable(method.run):
        raise TorchspliceError(f"method {method.name!r}: run must be a function MethodInput -> MethodOutput")
    if not method.module:
        method = replace(method, module=getattr(method.run, "__module__", "") or "")
    old = _REGISTRY.get(method.name)
    if old is not None and not replace_existing and (old.module, getattr(old.run, "__qualname__", None)) != (
            method.module, getattr(method.run, "__qualname__", None)):
        raise TorchspliceError(f"method {method.name!r} is already registered (by {old.module}); choose another name")
    if old is not None and replace_existing and old.run is not method.run:
        warnings.warn(f"method {method.name!r} of {old.module or '?'} is replaced by {method.module or '?'}'s "
                      "(replace_existing)", stacklevel=2)
    _REGISTRY[method.name] = method
    return method


def _ensure_loaded() -> None:
    """Register the built-ins, the entry points and ``TORCHSPLICE_PLUGINS`` (each once). A plug-in
    that fails to load is tried, and reported, again on the next call, rather than leaving the
    plug-ins after it unloaded without a word; a plug-in that asks for the methods while it loads
    sees those registered so far."""
    _ensure_loaded_builtins()
    if _LOADED["entry_points"] is False:
        _LOADED["entry_points"] = None  # loading
        try:
            for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
                where = f"plug-in {ep.name!r} ({ep.value}, entry point group {ENTRY_POINT_GROUP})"
                try:
                    obj = ep.load()
                    if isinstance(obj, Method):
                        register_method(obj)
                    elif callable(obj):
                        obj()
                    elif not isinstance(obj, types.ModuleType):  # a module registered its methods on import
                        raise TorchspliceError(f"names a {type(obj).__name__}, neither a Method nor a function")
                except TorchspliceError as exc:
                    raise TorchspliceError(f"{where}: {exc}") from None
                except (Exception, SystemExit) as exc:
                    raise TorchspliceError(f"{where} cannot be loaded: {type(exc).__name__}: {exc}") from None
                _remember(ep.value.split(":")[0])
        except BaseException:
            _LOADED["entry_points"] = False
            raise
        _LOADED["entry_points"] = True
    env = os.environ.get(PLUGINS_ENV, "")
    if env not in (_LOADED["env"], _LOADED["env_loading"]):
        _LOADED["env_loading"] = env
        try:
            load_plugins([m for m in env.split(",") if m.strip()])
        finally:
            _LOADED["env_loading"] = None
        _LOADED["env"] = env


def _remember(module: str) -> None:
    if module not in _PLUGIN_MODULES:
        _PLUGIN_MODULES.append(module)


def load_plugins(modules: Iterable[str]) -> list[str]:
    """Import plug-in modules by name (each registers its methods on import); returns the
    names of the methods registered now. A module that cannot be imported gives one clear
    :class:`~torchsplice.core.errors.TorchspliceError`."""
    _ensure_loaded_builtins()
    before = set(_REGISTRY)
    for name in modules:
        name = name.strip()
        if not name:
            continue
        try:
            importlib.import_module(name)
        except TorchspliceError as exc:  # it imports, but registers what it cannot (a taken name)
            raise TorchspliceError(f"plug-in module {name!r}: {exc}") from None
        except SystemExit as exc:  # a script's sys.exit() on import would end the job quietly
            raise TorchspliceError(f"plug-in module {name!r} called sys.exit({exc.code!r}) on import; "
                                   "a plug-in registers its methods and returns") from None
        except Exception as exc:
            raise TorchspliceError(f"plug-in module {name!r} cannot be imported: {type(exc).__name__}: {exc} "
                                   "(is it installed, or on PYTHONPATH?)") from None
        _remember(name)
    return [n for n in _REGISTRY if n not in before]


def _ensure_loaded_builtins() -> None:
    if not _LOADED["builtins"]:
        _LOADED["builtins"] = True
        importlib.import_module("torchsplice.splice.builtin_methods")


def get_method(name: str | Method) -> Method:
    """The registered method called ``name`` (a :class:`Method` is returned as it is); a clear
    error naming the available methods otherwise."""
    if isinstance(name, Method):
        return name
    _ensure_loaded()
    method = _REGISTRY.get(name)
    if method is None:
        raise TorchspliceError(f"unknown method {name!r}; choose one of {', '.join(available_methods())}")
    return method


def available_methods() -> tuple[str, ...]:
    """The names of every registered method: the built-ins first, then plug-ins in the order
    they registered."""
    _ensure_loaded()
    return tuple(_REGISTRY)


def plugin_modules(names: Iterable[str]) -> list[str]:
    """The modules a process must import to run the methods ``names``: those of the plug-in
    methods among them (the built-ins need none), in a stable order."""
    out = []
    for n in names:
        m = get_method(n)
        if not m.builtin and m.module and m.module not in out:
            out.append(m.module)
    return sorted(out)

