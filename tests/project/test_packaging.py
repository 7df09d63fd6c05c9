"""The package as installed: every subpackage listed in pyproject.toml, the shipped specs found."""

import sys

from realdata import REPO

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


def test_viewer_files_are_package_data():
    """The viewer's page template and the vendored three.js ship in the wheel: pyproject's
    package-data globs cover them, and they read back as package resources."""
    import fnmatch
    import importlib.resources

    data = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["torchsplice.viz"]
    viz = REPO / "torchsplice" / "viz"
    needed = ["viewer_template.html", "vendor/three.core.min.js", "vendor/three.module.min.js",
              "vendor/OrbitControls.js", "vendor/LICENSE", "vendor/VERSION"]
    for rel in needed:
        assert (viz / rel).is_file(), rel
        assert any(fnmatch.fnmatch(rel, g) for g in data), f"{rel} is not in pyproject's package-data"
        assert importlib.resources.files("torchsplice.viz").joinpath(rel).read_bytes() == (viz / rel).read_bytes()
    version = (viz / "vendor" / "VERSION").read_text().strip()
    assert f'version="${{1:-{version}}}"' in (REPO / "scripts" / "vendor_threejs.sh").read_text()
    assert "MIT" in (viz / "vendor" / "LICENSE").read_text()
