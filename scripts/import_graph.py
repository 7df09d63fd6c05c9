"""Check the package's import graph: no import cycle inside the listed packages, no HDF5 outside
the storage package.

    python scripts/import_graph.py [--cycles torchsplice.store torchsplice.specs] [--all]

Every ``torchsplice/**/*.py`` is parsed (never imported); each ``import`` and ``from ... import``
anywhere in a module, inside functions, classes and ``if TYPE_CHECKING`` blocks too, is an
edge to the module it names (relative imports resolved; ``from package import name`` is an
edge to ``package.name`` where that is a module, else to the package). Strongly connected
components of more than one module are cycles. Exits 1, naming them, when a package listed
with ``--cycles`` holds one, when a module outside ``torchsplice.store`` imports ``h5py``, or
when a module of those packages imports another module's underscore-private name; ``--all``
also lists the cycles anywhere else in the package (without failing).
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "torchsplice"
STORE = "torchsplice.store"


def modules(root: Path = ROOT) -> dict[str, Path]:
    """Module name -> file, for every ``.py`` under the package."""
    out = {}
    for path in sorted((root / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    """The absolute module of a (possibly relative) import in ``module``."""
    if level == 0:
        return name or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[:len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def imports(known: dict[str, Path]) -> tuple[dict[str, set[str]], dict[str, set[str]], list[tuple[str, str, str]]]:
    """``(edges, external, private)``: module -> the package modules it imports; module -> the
    top-level outside packages it imports; ``(importer, imported module, name)`` of every import
    of an underscore-private name from another package module."""
    edges: dict[str, set[str]] = {m: set() for m in known}
    external: dict[str, set[str]] = {m: set() for m in known}
    private = []
    for mod, path in known.items():
        is_package = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                for a in node.names:
                    targets = [(a.name, None)]
                    _add(mod, targets, known, edges, external, private)
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(mod, is_package, node.level, node.module)
                targets = []
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    targets.append((sub, None) if sub in known else (base, a.name))
                _add(mod, targets, known, edges, external, private)
    return edges, external, private


def _add(mod, targets, known, edges, external, private) -> None:
    for target, name in targets:
        if target.split(".")[0] != PACKAGE:
            external[mod].add(target.split(".")[0])
            continue
        while target and target not in known:  # a name inside a module: the module
            target = target.rpartition(".")[0]
        if target and target != mod:
            edges[mod].add(target)
            if name is not None and name.startswith("_") and not name.startswith("__"):
                private.append((mod, target, name))


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for start in sorted(edges):
        if start in index:
            continue
        work = [(start, iter(sorted(edges[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.append(w)
                    if w == v:
                        break
                if len(component) > 1:
                    out.append(sorted(component))
    return sorted(out)


def inside(module: str, packages) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", nargs="+", default=["torchsplice.store", "torchsplice.specs"],
                        help="packages that must hold no import cycle (default: store and specs)")
    parser.add_argument("--all", action="store_true", help="also list the cycles elsewhere in the package")
    args = parser.parse_args(argv)
    known = modules()
    edges, external, private = imports(known)
    failed = False
    for pkg in args.cycles:
        sub = {m: {t for t in e if inside(t, [pkg])} for m, e in edges.items() if inside(m, [pkg])}
        for c in cycles(sub):
            print(f"cycle in {pkg}: {' -> '.join(c)}")
            failed = True
    for mod in sorted(m for m, ext in external.items() if "h5py" in ext and not inside(m, [STORE])):
        print(f"h5py imported outside {STORE}: {mod} ({known[mod].relative_to(ROOT)})")
        failed = True
    for mod, target, name in sorted(private):
        if inside(mod, args.cycles) and inside(target, args.cycles):
            print(f"private name imported: {mod} imports {name} from {target}")
            failed = True
    if args.all:
        for c in cycles(edges):
            if not any(all(inside(m, [p]) for m in c) for p in args.cycles):
                print(f"cycle (not checked): {' -> '.join(c)}")
    if not failed:
        print(f"ok: {len(known)} modules, {sum(map(len, edges.values()))} imports; no cycle in "
              f"{', '.join(args.cycles)}; h5py only in {STORE}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
