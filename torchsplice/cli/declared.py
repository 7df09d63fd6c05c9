"""The library's declared values (allowed values, defaults), read without importing torch.

An option is declared once, in the library: ``--timing``'s choices are
``torchsplice.splice.standing.TIMINGS``, ``--max-run``'s default is ``JobConfig.max_run``. The
modules that declare them import torch, numpy or h5py, which the command line must not load for
``--help`` (tests/cli/test_cli_startup.py). So :func:`declared` reads such a value from the module's
source when the module is not loaded yet: the literal it is assigned (a module constant, a
dataclass field's default, a function parameter's default; a name of another constant of the
same module is followed, and so is a name imported from another torchsplice module). Once the module is loaded (any command that does work loads it), the
live value is read instead, and a value that is not a literal imports the module. So the value
is always the library's; tests/cli/test_cli_options.py checks every parser choice and default
against the imported library, and this reader against the live values.

Names: ``"CONST"``, ``"Class.field"`` (a dataclass field's plain default), ``"function.param"``.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import sys
from functools import lru_cache
from pathlib import Path
from typing import Any

__all__ = ["declared", "static_value", "live_value", "ASKED"]

_PACKAGE = Path(__file__).resolve().parents[1]  # torchsplice/
_MISSING = object()
ASKED: set[tuple[str, str]] = set()
"""Every ``(module, name)`` asked for so far (tests check the source reading of each)."""


def declared(module: str, name: str) -> Any:
    """The value ``name`` of library module ``module`` (see the module docstring)."""
    ASKED.add((module, name))
    if module not in sys.modules:
        value = static_value(module, name)
        if value is not _MISSING:
            return value
    return live_value(importlib.import_module(module), name)


def live_value(mod, name: str) -> Any:
    """``name`` read from the imported module ``mod``."""
    first, *rest = name.split(".")
    obj = getattr(mod, first)
    for part in rest:
        if inspect.isfunction(obj):
            obj = inspect.signature(obj).parameters[part].default
        elif dataclasses.is_dataclass(obj) and isinstance(obj, type):
            f = {f.name: f for f in dataclasses.fields(obj)}[part]
            if f.default is dataclasses.MISSING:
                raise KeyError(f"{name}: the field has no plain default")
            obj = f.default
        else:
            obj = getattr(obj, part)
    return obj


def static_value(module: str, name: str) -> Any:
    """``name`` read from ``module``'s source, or ``_MISSING`` when it is not a literal there."""
    tree = _tree(module)
    if tree is None:
        return _MISSING
    first, *rest = name.split(".")
    node = _top_level(tree, first)
    value = _MISSING
    if isinstance(node, ast.ClassDef) and rest:
        node = _binding(node.body, rest[0]) if len(rest) == 1 else None
        if node is None:
            return _MISSING
        value = _literal(module, _default(node))
    elif isinstance(node, ast.FunctionDef) and len(rest) == 1:
        value = _literal(module, _parameter_default(node, rest[0]))
    elif node is not None and not rest and not isinstance(node, (ast.ClassDef, ast.FunctionDef)):
        value = _literal(module, node)
    elif node is None and not rest:
        value = _literal(module, ast.Name(id=first, ctx=ast.Load()))
    return value


@lru_cache(maxsize=None)
def _tree(module: str) -> ast.Module | None:
    parts = module.split(".")
    if parts[0] != "torchsplice":
        return None
    path = _PACKAGE.joinpath(*parts[1:])
    path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
    try:
        return ast.parse(path.read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError):
        return None


def _top_level(tree: ast.Module, name: str):
    """The class, function, or value bound to ``name`` at the module's top level."""
    return _binding(tree.body, name)


def _binding(body: list, name: str):
    """What the statements ``body`` bind ``name`` to last (a class, a function or an assigned
    expression); ``None`` when the name is not bound there, or is also bound in a way this
    reader does not follow (``+=``, inside ``if``/``try``, an import): then the module is imported."""
    found = None
    for node in body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)) and node.name == name:
            found = node
        elif isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets):
            found = node.value
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.target.id == name:
            found = node.value
        elif isinstance(node, ast.AugAssign) and isinstance(node.target, ast.Name) and node.target.id == name:
            return None
        elif isinstance(node, (ast.If, ast.Try, ast.Import, ast.ImportFrom)) and any(
                isinstance(n, ast.Name) and n.id == name and isinstance(n.ctx, ast.Store) or
                isinstance(n, ast.alias) and (n.asname or n.name).split(".")[0] == name for n in ast.walk(node)):
            return None
    return found


def _imported_from(module: str, tree: ast.Module, name: str) -> str | None:
    """The torchsplice module ``name`` is imported from (under its own name) at ``module``'s top
    level, when that import is its only binding there; else ``None``."""
    origin = None
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and any(a.name == name and a.asname in (None, name) for a in node.names):
            if node.level:
                package = module.split(".") if _PACKAGE.joinpath(*module.split(".")[1:]).is_dir() \
                    else module.split(".")[:-1]
                base = package[:len(package) - node.level + 1]
                origin = ".".join(base + ([node.module] if node.module else []))
            else:
                origin = node.module
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign, ast.FunctionDef, ast.ClassDef)) and any(
                isinstance(n, ast.Name) and n.id == name and isinstance(n.ctx, ast.Store) for n in ast.walk(node)) \
                or isinstance(node, (ast.FunctionDef, ast.ClassDef)) and node.name == name:
            return None  # bound here too: not followed
    return origin if origin is not None and origin.split(".")[0] == "torchsplice" else None


def _is_field_call(node) -> bool:
    return isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "field"


def _default(node):
    """A field's default expression: ``x = 3`` -> ``3``; ``field(default=3)`` -> ``3``."""
    if _is_field_call(node):
        for kw in node.keywords:
            if kw.arg == "default":
                return kw.value
        return None
    return node


def _parameter_default(fn: ast.FunctionDef, name: str):
    a = fn.args
    positional = a.posonlyargs + a.args
    for arg, default in zip(positional[len(positional) - len(a.defaults):], a.defaults):
        if arg.arg == name:
            return default
    for arg, default in zip(a.kwonlyargs, a.kw_defaults):
        if arg.arg == name:
            return default
    return None


def _literal(module: str, node, depth: int = 0):
    """The value of a literal expression in ``module`` (a name of a module constant is followed,
    into the module it is imported from where it is); ``_MISSING`` for anything else."""
    if node is None or depth > 8:
        return _MISSING
    if isinstance(node, ast.Name):
        tree = _tree(module)
        origin = _imported_from(module, tree, node.id) if tree is not None else None
        if origin is not None:
            return _literal(origin, node, depth + 1)
        return _literal(module, _top_level(tree, node.id), depth + 1) if tree is not None else _MISSING
    try:
        return ast.literal_eval(node)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        return _MISSING
