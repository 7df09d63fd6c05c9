"""The package as installed: every subpackage listed in pyproject.toml, the shipped specs found."""

import sys

from conftest import REPO

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def test_every_subpackage_is_listed_in_pyproject():
    listed = set(tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(REPO).parts) for p in (REPO / "torchsplice").rglob("__init__.py")}
    found.add("torchsplice.datasets_spec")
    assert found == listed, f"pyproject.toml [tool.setuptools] packages must list exactly {sorted(found)}"


def test_shipped_specs_are_package_resources():
    import importlib.resources

    names = {p.name for p in importlib.resources.files("torchsplice.datasets_spec").iterdir()}
    on_disk = {p.name for p in (REPO / "datasets_spec").glob("*.toml")}
    assert on_disk and on_disk <= names


def test_readme_commands_exist():
    readme = (REPO / "README.md").read_text()
    for cmd in ("bash scripts/demo.sh", "bash scripts/test.sh"):
        assert cmd in readme
        assert (REPO / cmd.split()[1]).is_file()
    assert "scripts/test.sh" in (REPO / ".ci" / "run").read_text()
