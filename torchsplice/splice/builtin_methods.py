"""The built-in methods, registered in :mod:`torchsplice.splice.registry` from their table
(:data:`torchsplice.core.method_table.BUILTINS`): ``splice`` (Heck, Kovar & Gleicher 2006),
``naive`` (per-bone replacement of the upper body) and ``cpmc`` (differencing against a
plain-locomotion reference, Al-Ghreimil & Hahn 2003).

Each row becomes one :class:`~torchsplice.splice.registry.Method`: its torch function (padded pair
tensors, any device; :func:`torchsplice.splice.heck.run_method`,
:func:`torchsplice.splice.methods.run_naive`, :func:`torchsplice.splice.methods.run_cpmc`) and its
standing-action variant (:func:`torchsplice.splice.standing.standing_tensors`); all of them also
run in the compiled CPU splicer (:mod:`torchsplice.cpu`), under the table's codes. The torch
modules are imported when a method first runs, so that listing the methods loads no torch.
"""

from __future__ import annotations

from ..core.method_table import BUILTINS, BuiltinMethod, resolve
from .registry import Method, MethodInput, MethodOutput, register_method

__all__ = ["method_of"]


def _run(row: BuiltinMethod):
    """The torch function of ``row`` (:attr:`BuiltinMethod.run`), imported on its first call."""
    def run(inp: MethodInput) -> MethodOutput:
        return resolve(row.run)(inp)

    run.__qualname__ = f"run_{row.name}"
    return run


def _standing(name: str):
    """The standing-action variant of built-in method ``name`` (see :mod:`torchsplice.splice.standing`)."""
    def run(inp: MethodInput, timing: str, acting):
        from .standing import standing_tensors

        return standing_tensors(inp.loco, inp.act, inp.roles, inp.skeleton, inp.fps, name, timing, acting)

    run.__qualname__ = f"standing_{name}"
    return run


def method_of(row: BuiltinMethod) -> Method:
    """The registry's :class:`~torchsplice.splice.registry.Method` of a row of the table."""
    return Method(row.name, row.description, _run(row), needs_reference=row.needs_reference, compiled=True,
                  standing=_standing(row.name), diagnostics=row.diagnostics)


for _row in BUILTINS:
    register_method(method_of(_row))
