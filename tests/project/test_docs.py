"""The documentation site builds strictly: ``mkdocs build --strict`` over ``mkdocs.yml`` and
``docs/``, so a broken link, a missing anchor or page, or an API reference to a name that is not
there fails the suite. The reference pages are generated while it builds (``docs/hooks.py``:
the command line from its parsers, the errors, the benchmark's sections); the checks below make
sure they hold what they are generated from. The README stays a short front page that links
into the site.

The ``docs`` extra installs mkdocs (``pip install -e '.[docs]'``; ``scripts/test.sh`` does).
Without it these tests skip, saying why, except under CI, where they fail.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import torchsplice

REPO = Path(__file__).resolve().parents[2]
README_MAX_LINES = 250


def _need_mkdocs() -> None:
    # mkdocs, mkdocs-material (the theme) and mkdocstrings-python (the API pages)
    missing = [m for m in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers") if importlib.util.find_spec(m) is None]
    if missing:
        reason = f"{', '.join(missing)} not installed (pip install -e '.[docs]' installs the site's tools)"
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            pytest.fail(reason + "; CI must build the docs", pytrace=False)
        pytest.skip(reason)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site, built strictly into a temporary folder (never into the repository)."""
    _need_mkdocs()
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    p = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--clean", "-f", str(REPO / "mkdocs.yml"),
                        "-d", str(out)], cwd=REPO, capture_output=True, text=True, timeout=600, env=env)
    log = p.stdout + p.stderr
    assert p.returncode == 0, log[-6000:]
    assert not re.search(r"^(WARNING|ERROR)\b", log, re.M), log[-6000:]
    return out


def _page_text(site: Path, page: str) -> str:
    import html

    raw = (site / page / "index.html").read_text(encoding="utf-8")
    return html.unescape(re.sub(r"<[^>]+>", " ", raw))


def test_the_site_builds_strictly(site):
    for page in ("index.html", "reference/cli/index.html", "reference/api/pipeline/index.html",
                 "reference/errors/index.html", "reference/speed/index.html", "images/preview.png"):
        assert (site / page).is_file(), page


def test_the_command_line_page_lists_every_command_and_flag(site):
    from torchsplice.cli.main import build_parser
    from torchsplice.formats.exporters import available_exporters, get_exporter

    text = _page_text(site, "reference/cli")
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    formats = [get_exporter(f) for f in available_exporters()]  # other tests' plug-ins' options are export's flags here too
    plugins_only = {k for e in formats if not e.__module__.startswith("torchsplice.") for k in e.options} - {
        k for e in formats if e.__module__.startswith("torchsplice.") for k in e.options}
    for name, command in sub.choices.items():
        assert f"torchsplice {name}" in text, name
        for action in command._actions:
            for flag in action.option_strings:
                if flag.startswith("--") and action.help != argparse.SUPPRESS and not (
                        name == "export" and action.dest in plugins_only):
                    assert flag in text, (name, flag)


def test_the_api_pages_document_the_main_verbs(site):
    import torchsplice

    pages = [(site / "reference" / "api" / p / "index.html").read_text(encoding="utf-8") for p in ("pipeline", "data")]
    raw = " ".join(pages)
    for verb in ("import_bvh", "splice", "splice_all", "export_clips", "MotionDatabase", "MotionDataset"):
        assert verb in torchsplice.__all__ and re.search(rf'id="torchsplice\.[\w.]*\b{verb}"', raw), verb
    assert "Parameters:" in _page_text(site, "reference/api/pipeline")  # docstrings rendered, not just names


def test_the_api_pages_show_sphinx_roles_as_code_and_links(site):
    pages = sorted((site / "reference" / "api").rglob("*.html"))
    raw = " ".join(p.read_text(encoding="utf-8") for p in pages)
    assert pages and not re.findall(r":(?:func|meth|class|mod|attr|data|exc):<code>", raw)
    # a role naming an object the site documents links to its entry
    assert re.search(r'<a class="autorefs autorefs-internal"[^>]*href="[^"]*#torchsplice\.[\w.]+"[^>]*><code>', raw)


def test_recorded_benchmark_runs_render_each_line_beside_its_target(tmp_path, monkeypatch):
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_hooks", REPO / "docs" / "hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    sys.path.insert(0, str(REPO / "scripts"))
    from bench_record import Recorder

    monkeypatch.setattr(hooks, "RUNS", tmp_path / "runs.json")
    assert "No run is recorded yet" in hooks.benchmark_runs()
    recorder = Recorder(hooks.RUNS)
    with recorder.section("store"):
        print("data: 4 clips")
        print("store   reads: 1.5x  [>= 1x]")
    recorder.save()
    page = hooks.benchmark_runs()
    assert "### `store`" in page and "| store reads: 1.5x | &gt;= 1x |" in page and "; 4 clips." in page
    # a section run on a whole dataset is recorded beside it, and shown apart
    from bench_record import WHOLE

    assert "No run is recorded yet" in hooks.benchmark_runs(whole=True)
    with recorder.section("store" + WHOLE):
        print("store   the default job: 12.5 min  [<= 30 min]")
    recorder.save()
    whole = hooks.benchmark_runs(whole=True)
    assert "### `store` on the whole dataset" in whole and "| store the default job: 12.5 min | &lt;= 30 min |" in whole
    assert "12.5 min" not in hooks.benchmark_runs() and "| store reads: 1.5x" not in whole
    page = hooks.benchmark_runs()
    import json
    import os

    load = json.loads(hooks.RUNS.read_text())["sections"]["store"]["load"]
    if hasattr(os, "getloadavg"):  # the machine's load as the section started and ended, on the page
        assert len(load) == 2 and all(x >= 0 for x in load)
        assert f", load {load[0]:.1f} to {load[1]:.1f};" in page


def test_the_errors_and_speed_pages_hold_what_they_are_generated_from(site):
    from torchsplice.core import errors

    text = _page_text(site, "reference/errors")
    for name in ("TorchspliceError", "OutputExistsError", "NotLocomotingError", "UnfinishedJobError", "LockedError"):
        assert name in text and hasattr(torchsplice, name)
    for said in errors.HINTS.values():
        assert said in text
    assert "--force" in text and "130" in text  # the command line's words and the exit codes
    speed = _page_text(site, "reference/speed")
    for section in ("parse", "stages", "splice", "job", "engines", "mix", "retarget", "humanml3d", "hands", "packed",
                    "store", "startup"):
        assert re.search(rf"\b{section}\b", speed), section
    sys.path.insert(0, str(REPO / "scripts"))
    from bench_record import load_runs, split_target

    def words(text: str) -> str:  # the figures and words, whatever markup sits between them
        return " ".join(re.findall(r"[\w.,%:/+-]+", text))

    runs = load_runs(REPO / "docs" / "reference" / "benchmark-runs.json")
    assert runs, "no benchmark run is recorded for the Speed page"
    for name, run in runs.items():  # every figure a recorded run printed is on the page
        for line in run["lines"]:
            if not line.startswith("data: "):
                assert words(split_target(line)[0]) in words(speed), (name, line)
    from bench_record import WHOLE

    assert {"mix" + WHOLE, "hands" + WHOLE, "store" + WHOLE} <= set(runs)  # the whole dataset's runs are recorded
    source = (REPO / "docs" / "reference" / "speed.md").read_text()  # every table on the page is generated:
    assert not re.search(r"^\|", source, re.M)  # no figure typed by hand beside the recorded ones
    assert "store on the whole dataset" in speed  # its default job, as its run printed (every line checked above)


def test_the_readme_is_a_short_front_page_linking_into_the_site():
    text = (REPO / "README.md").read_text()
    assert len(text.splitlines()) <= README_MAX_LINES
    for command in ("bash scripts/demo.sh", "bash scripts/test.sh", "pip install"):
        assert command in text
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    local = [link for link in links if "://" not in link]
    assert any(link.startswith("docs/") for link in local)
    for link in local:
        assert (REPO / link).exists(), f"README links to {link}, which is not there"
