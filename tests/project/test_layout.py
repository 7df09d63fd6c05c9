"""The package's layout, checked from its import graph and syntax trees (see ARCHITECTURE.md).

- Layers import only downward: a package imports from its own modules and from packages of a
  lower layer (:data:`LAYERS`), never from its layer's other packages or above.
- No import cycle between modules (imports inside functions count; ``if TYPE_CHECKING:``
  blocks do not: they never run).
- No module imports another module's private (``_underscore``) name.
- A package's ``defaults`` module (its options' defaults and allowed values, which the library
  and the command line both import) imports only the standard library and other ``defaults``
  modules: it sits in its package's layer, and the command line reads it without torch.
- HDF5 (h5py) is opened only in the storage package; the compiled kernels are reached only by
  the alignment and the splicer (whose backends the job calls).
- No library module is over :data:`MAX_LINES` lines unless its docstring says why
  (``Longer than 600 lines because ...``).
"""

from __future__ import annotations

import ast
import functools
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2] / "torchsplice"
MAX_LINES = 600
LONG_REASON = "Longer than 600 lines because"

LAYERS = [
    ["core"],                           # types, rotations, skeletons, forward kinematics, errors
    ["specs", "kinematics", "sample"],  # dataset specs and roles; derived kinematics; the built-in sample
    ["cpu", "ops"],                     # compiled kernels; transforms on clips
    ["store"],                          # HDF5 storage (an alignment store assembles its clips with cpu.assemble)
    ["align", "data"],                  # time and space alignment; the training dataset
    ["splice", "formats"],              # methods and backends; file formats in and out
    ["viz", "retarget"],                # pictures and the viewer; retargeting clips of a database
    ["evaluation", "job"],              # metrics and reports; the n x m job
    ["cli"],                            # the command line
    [""],                               # the top-level modules: the package, __main__, warmup
]
LAYER = {pkg: n for n, pkgs in enumerate(LAYERS) for pkg in pkgs}


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        if "vendor" in path.parts:
            continue
        parts = ["torchsplice", *path.relative_to(ROOT).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _runtime_nodes(tree: ast.AST, type_checking: bool = False):
    """Every node but those under ``if TYPE_CHECKING:`` (those too with ``type_checking``)."""
    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if not type_checking and isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                todo.extend(child.orelse)
                continue
            todo.append(child)


@functools.cache  # every test reads the same modules: parse each once per session
def _imports(module: str, type_checking: bool = False) -> tuple[tuple[str, tuple[str, ...], int], ...]:
    """``(imported module, names imported from it, line)`` of every runtime import in ``module``
    (and, with ``type_checking``, of those only a type checker reads)."""
    path = MODULES[module]
    tree = ast.parse(path.read_text(), str(path))
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    out = []
    for node in _runtime_nodes(tree, type_checking):
        if isinstance(node, ast.Import):
            out += [(a.name, (), node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            out.append((name, tuple(a.name for a in node.names), node.lineno))
    return tuple(out)


def _edges(type_checking: bool = False) -> dict[str, dict[str, int]]:
    """Module -> {torchsplice module it imports: line} (``type_checking``: see :func:`_imports`)."""
    edges: dict[str, dict[str, int]] = {}
    for module in MODULES:
        out = edges.setdefault(module, {})
        for name, names, line in _imports(module, type_checking):
            if not name.startswith("torchsplice"):
                continue
            subs = [f"{name}.{n}" for n in names if f"{name}.{n}" in MODULES]
            for target in subs or [name]:
                while target not in MODULES and "." in target:
                    target = target.rsplit(".", 1)[0]
                if target != module:
                    out.setdefault(target, line)
    return edges


def _package(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and MODULES[module].name == "__init__.py") else ""


def test_every_package_has_a_layer():
    assert {_package(m) for m in MODULES} <= set(LAYER), sorted({_package(m) for m in MODULES} - set(LAYER))


def test_layers_import_only_downward():
    wrong = []
    for module, targets in _edges().items():
        src = _package(module)
        for target, line in targets.items():
            dst = _package(target)
            if dst == src or target == "torchsplice":  # the package's own modules; the root's version and lazy names
                if target == "torchsplice" and module != "torchsplice":
                    wrong.append(f"{module}:{line} imports the package root (import what it names from its module)")
                continue
            if LAYER[dst] >= LAYER[src]:
                wrong.append(f"{module}:{line} imports {target} (layer {LAYER[dst]} {dst!r} from layer {LAYER[src]} {src!r})")
    assert not wrong, "\n".join(wrong)


def _cycles(edges: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in edges:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    assert _cycles(_edges()) == []


def test_no_import_cycles_even_through_the_type_checkers_imports():
    """A cycle that only ``if TYPE_CHECKING:`` hides is a tangle all the same (the job's config,
    engines and plan once were one)."""
    assert _cycles(_edges(type_checking=True)) == []


def test_the_cycle_finder_finds_a_cycle():
    edges = {"a": {"b": 1}, "b": {"c": 1}, "c": {"a": 1}, "d": {"a": 1}}
    assert _cycles(edges) == [["a", "b", "c"]]
    assert _cycles({"a": {"b": 1}, "b": {}}) == []


def test_no_module_imports_another_modules_private_names():
    wrong = []
    for module in MODULES:
        for name, names, line in _imports(module):
            if not name.startswith("torchsplice") or name == module:
                continue
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private:
                wrong.append(f"{module}:{line} imports {', '.join(private)} from {name}")
    assert not wrong, "\n".join(wrong)


def test_defaults_modules_import_only_the_standard_library_and_each_other():
    defaults = [m for m in MODULES if m.endswith(".defaults")]
    assert len(defaults) >= 7, defaults
    wrong = [f"{m}:{line} imports {name}" for m in defaults for name, _, line in _imports(m)
             if not (name.split(".")[0] in sys.stdlib_module_names or name.startswith("torchsplice.") and name.endswith(".defaults"))]
    assert not wrong, "\n".join(wrong)


def test_hdf5_is_opened_only_in_the_storage_package():
    wrong = [f"{m}:{line}" for m in MODULES for name, _, line in _imports(m)
             if name.split(".")[0] == "h5py" and _package(m) != "store"]
    assert not wrong, wrong


def test_the_compiled_kernels_are_reached_only_through_alignment_and_the_splicer():
    allowed = {"cpu", "align", "splice"}
    wrong = [f"{m}:{line} imports {t}" for m, targets in _edges().items() for t, line in targets.items()
             if _package(t) == "cpu" and _package(m) not in allowed
             and not (_package(m) == "store" and t == "torchsplice.cpu.assemble")]  # reads of an alignment store
    assert not wrong, "\n".join(wrong)


def test_the_job_calls_the_splicing_backends_only_through_their_interface():
    wrong = [f"{m}:{line} imports {t}" for m, targets in _edges().items() for t, line in targets.items()
             if _package(m) == "job" and t.startswith("torchsplice.splice.backends.")]
    assert not wrong, "\n".join(wrong)


def test_modules_stay_small_or_say_why():
    long = []
    for module, path in MODULES.items():
        lines = len(path.read_text().splitlines())
        if lines > MAX_LINES:
            doc = ast.get_docstring(ast.parse(path.read_text())) or ""
            if LONG_REASON not in doc:
                long.append(f"{module}: {lines} lines")
    assert not long, "\n".join(long)


@pytest.mark.parametrize("package", sorted({_package(m) for m in MODULES} - {""}))
def test_every_package_says_what_it_is(package):
    init = ROOT / package / "__init__.py"
    assert init.exists() and ast.get_docstring(ast.parse(init.read_text())), f"torchsplice/{package}/__init__.py needs a docstring"
