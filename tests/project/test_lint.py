"""The code passes its linter, formatter and type checker, as ``pyproject.toml`` configures them:
ruff's lint over every file, ruff's formatting over :data:`FORMATTED` and mypy over the packages
``[tool.mypy] files`` lists. ``scripts/test.sh`` installs both tools (the ``test`` extra); a
package joins :data:`FORMATTED` (and mypy's list) once it passes."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
FORMATTED = ["torchsplice/core", "torchsplice/specs", "torchsplice/store"]


def _tool(name: str) -> list[str]:
    """The command that runs ``name`` from this Python's environment (a skip saying why without it,
    a failure under CI)."""
    found = shutil.which(name, path=str(Path(sys.executable).parent)) or shutil.which(name)
    if found:
        return [found]
    reason = f"{name} is not installed (pip install -e '.[test]' installs it)"
    if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
        pytest.fail(reason + "; CI must lint", pytrace=False)
    pytest.skip(reason)


def _run(cmd: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600)


def test_ruff_finds_nothing_to_report():
    p = _run([*_tool("ruff"), "check", "--output-format", "concise", "."])
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:]


def test_the_formatted_packages_are_as_ruff_formats_them():
    p = _run([*_tool("ruff"), "format", "--check", *FORMATTED])
    assert p.returncode == 0, "run: ruff format " + " ".join(FORMATTED) + "\n" + p.stdout[-4000:] + p.stderr[-2000:]


def test_mypy_finds_no_type_error():
    p = _run([*_tool("mypy")])
    assert p.returncode == 0 and "Success" in p.stdout, p.stdout[-4000:] + p.stderr[-2000:]
