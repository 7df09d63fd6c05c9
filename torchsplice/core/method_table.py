"""The built-in splicing methods, declared once: :data:`BUILTINS`, one :class:`BuiltinMethod` row each.

Everything that knows the built-ins reads this table: the method registry
(:mod:`torchsplice.splice.registry` and :mod:`torchsplice.splice.builtin_methods`, which register
one :class:`~torchsplice.splice.registry.Method` per row), the standing-action assembly of
:mod:`torchsplice.splice.standing`, the compiled kernels (:mod:`torchsplice.cpu`: their method
codes, frozen into the kernels as module-level ints), the compiled backend's warm-up, the job's
size estimate and what the ``splice`` command prints. Third-party methods are plug-ins of the
registry and have no row here.

The implementations are named by ``"module:function"`` (imported when first used: listing the
methods loads no torch, and this layer imports nothing above it).

A method's ``code`` selects its branch in the compiled kernels and is written to alignment stores
(``assembly_method``): a code, once given, is never changed or reused. Numba freezes it into the
cached kernels, which is why this file is part of the kernels' cache key
(:mod:`torchsplice.cpu`).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

__all__ = ["BuiltinMethod", "SPLICE", "NAIVE", "CPMC", "BUILTINS", "builtin", "resolve"]


@dataclass(frozen=True)
class BuiltinMethod:
    """One built-in method (see the module docstring).

    Attributes:
        name: what users type (``--method NAME``).
        code: its number in the compiled kernels and in alignment stores (distinct, never reused).
        description: one line for ``--help`` and the documentation.
        run: ``"module:function"``, its torch function ``run(MethodInput) -> MethodOutput``.
        standing: ``"module:function"``, how its standing-action variant assembles the upper body
            (see :func:`torchsplice.splice.standing.standing_tensors`).
        aligns_time: it timewarps the action onto the locomotion (and so measures cost and crop).
        needs_reference: it needs a plain-locomotion reference clip of the action's performer.
        diagnostics: which of ``"cost"``, ``"crop"`` and ``"posture"`` it measures.
        stores: what an alignment store keeps of its spliced locomotion pairs: ``"parts"`` (the
            alignment curve and the pelvis's rotation, the frames assembled on reading) or
            ``"frames"`` (the spliced frames). Standing pairs are parts for every method.
        acting_limbs: its standing variant takes only the acting arms from the action (the idle
            arm keeps the locomotion's swing), so the limbs it used are reported.
        suffix: its results are named ``LOCO+ACTION.NAME`` (else ``LOCO+ACTION``).
    """

    name: str
    code: int
    description: str
    run: str
    standing: str
    aligns_time: bool
    needs_reference: bool
    diagnostics: tuple[str, ...]
    stores: str
    acting_limbs: bool
    suffix: bool


SPLICE = BuiltinMethod(
    name="splice",
    code=0,
    description="Heck, Kovar & Gleicher 2006: timewarp, spatial alignment, posture transfer",
    run="torchsplice.splice.heck:run_method",
    standing="torchsplice.splice.standing:splice_upper",
    aligns_time=True,
    needs_reference=False,
    diagnostics=("cost", "crop", "posture"),
    stores="parts",
    acting_limbs=True,
    suffix=False,
)
NAIVE = BuiltinMethod(
    name="naive",
    code=1,
    description="per-bone replacement of the upper body, frame by frame, no timewarp (game engines' layer masks)",
    run="torchsplice.splice.methods:run_naive",
    standing="torchsplice.splice.standing:naive_upper",
    aligns_time=False,
    needs_reference=False,
    diagnostics=(),
    stores="parts",
    acting_limbs=False,
    suffix=True,
)
CPMC = BuiltinMethod(
    name="cpmc",
    code=2,
    description="differencing against a plain-locomotion reference of the action's performer (additive layers)",
    run="torchsplice.splice.methods:run_cpmc",
    standing="torchsplice.splice.standing:cpmc_upper",
    aligns_time=True,
    needs_reference=True,
    diagnostics=("cost", "crop"),
    stores="frames",
    acting_limbs=False,
    suffix=True,
)

BUILTINS: tuple[BuiltinMethod, ...] = (SPLICE, NAIVE, CPMC)
"""Every built-in method, in the order they are listed (the first is the default)."""

_BY_NAME = {m.name: m for m in BUILTINS}


def builtin(name: str) -> BuiltinMethod | None:
    """The built-in method called ``name``; ``None`` for any other name (a plug-in's)."""
    return _BY_NAME.get(name)


def resolve(ref: str) -> Any:
    """The object a ``"module:function"`` reference names (its module imported)."""
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)
