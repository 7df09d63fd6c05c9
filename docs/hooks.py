"""mkdocs hooks: the pages the site generates from the code when it is built.

- ``<!-- generated: cli -->``: every command's usage and options, from the argparse parsers
  (:func:`torchsplice.cli.main.build_parser`), so the page cannot drift from ``--help``.
- ``<!-- generated: errors -->``: the error classes, their hints in the library's and the command
  line's words, and the exit codes, from :mod:`torchsplice.core.errors` and the command line.
- ``<!-- generated: benchmark -->``: the benchmark's sections, what each measures and its
  target, from the docstring of ``scripts/benchmark.py`` (read, not run: it takes long).
- ``<!-- generated: benchmark-runs -->``: the figures ``scripts/benchmark.py --json`` recorded,
  each section with its date, machine and command line (``docs/reference/benchmark-runs.json``).
- ``<!-- generated: benchmark-runs-whole -->``: the same for the sections run on a whole dataset
  (``--mix-db``, ``--held-back``, ``--big-db``).
- ``<!-- generated: spec-format -->``: ``datasets_spec/README.md``, the dataset spec format.
- The API pages' docstrings are written for Sphinx (``:func:`name```, ``:class:`~a.b```): each
  role becomes code, linked to the object's entry where the site documents it (a cross-reference
  that mkdocs-autorefs resolves once every page is built, and leaves as code where none is).
- The pictures the pages show live in ``torchsplice/viz/`` (where the tests refresh them); they
  are added to the site as ``images/NAME.png``.

``mkdocs.yml`` names this file under ``hooks``; ``tests/project/test_docs.py`` builds the site strictly.
"""

from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PICTURES = REPO / "torchsplice" / "viz"
MARKER = re.compile(r"<!-- generated: ([a-z-]+) -->")
#: a Sphinx role as the API pages render it: ``:func:<code>~torchsplice.x.y</code>``
ROLE = re.compile(r":(?:func|meth|class|mod|attr|data|exc|obj|const):<code>(~?)([^<]+)</code>")


# ------------------------------------------------------------------------------------ helpers
def _plain(value: str) -> str:
    value = value.replace("\\", "\\\\")
    for ch in "*_[]`":
        value = value.replace(ch, "\\" + ch)
    return value.replace("<", "&lt;").replace(">", "&gt;").replace("|", "&#124;")


def _text(value: str) -> str:
    """Text of help strings and docstrings made safe inside Markdown (no emphasis, links or HTML
    by accident); what they quote in backticks (```x``` or ``x``) stays code."""
    out, at = [], 0
    for m in re.finditer(r"``(.+?)``|`([^`]+)`", value):
        code = m.group(1) or m.group(2)
        out += [_plain(value[at:m.start()]), f"`{code}`"]
        at = m.end()
    return "".join(out) + _plain(value[at:])


def _first_paragraph(doc: str | None) -> str:
    return " ".join((doc or "").strip().split("\n\n")[0].split())


# ------------------------------------------------------------------------------------ the CLI
def _flags(action: argparse.Action) -> str:
    if not action.option_strings:
        return f"`{action.metavar or action.dest}`" + (" ..." if action.nargs in ("*", "+") else "")
    takes = action.nargs != 0
    metavar = action.metavar or (action.dest.upper() if takes else "")
    if isinstance(metavar, tuple):
        metavar = " ".join(metavar)
    return ", ".join(f"`{o} {metavar}`" if takes and metavar else f"`{o}`" for o in action.option_strings)


def _action_lines(parser: argparse.ArgumentParser, action: argparse.Action) -> list[str]:
    if action.help == argparse.SUPPRESS or isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
        return []
    helptext = parser._get_formatter()._expand_help(action) if action.help else ""
    extra = []
    if action.choices is not None and not isinstance(action.choices, dict):
        extra.append("choices: " + ", ".join(f"`{c}`" for c in action.choices))
    line = f"- {_flags(action)}: {_text(helptext)}" if helptext else f"- {_flags(action)}"
    if extra:
        line += f" ({'; '.join(extra)})"
    return [line]


def _parser_section(parser: argparse.ArgumentParser, heading: str, summary: str = "") -> list[str]:
    out = [f"## {heading}", ""]
    if summary:
        out += [_text(summary[:1].upper() + summary[1:]) + ".", ""]
    if parser.description:
        out += [_text(parser.description), ""]
    usage = parser.format_usage().strip()
    out += ["```text", usage.replace("usage: ", "", 1), "```", ""]
    for group in parser._action_groups:
        lines = [ln for a in group._group_actions for ln in _action_lines(parser, a)]
        if lines:
            title = {"positional arguments": "Arguments", "options": "Options"}.get(group.title or "", group.title)
            out += [f"**{_text(title or 'Options')}**", "", *lines, ""]
    return out


def cli_reference() -> str:
    """Markdown for every command, in the order ``torchsplice --help`` lists them."""
    from torchsplice.cli.main import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help for c in sub._choices_actions}
    out = ["| command | what it does |", "|---|---|"]
    out += [f"| [`{name}`](#torchsplice-{name}) | {_text(helps.get(name) or '')} |" for name in sub.choices]
    out.append("")
    out += _parser_section(parser, "torchsplice", "options before the command, for every command")
    for name, sp in sub.choices.items():
        out += _parser_section(sp, f"torchsplice {name}", helps.get(name) or "")
    return "\n".join(out)


# ------------------------------------------------------------------------------------ errors
def errors_reference() -> str:
    """Markdown for the error classes, their hints and the exit codes."""
    import torchsplice.cli.main as cli_main
    from torchsplice.cli import common
    from torchsplice.core import errors

    out = ["## Error classes", "",
           "Every class below is importable from `torchsplice.core.errors`; catch `TorchspliceError` "
           "for all of them.", "",
           "| class | is a | what | hint |", "|---|---|---|---|"]
    for name in errors.__all__:
        cls = getattr(errors, name)
        if not (isinstance(cls, type) and issubclass(cls, errors.TorchspliceError)):
            continue
        bases = ", ".join(f"`{b.__name__}`" for b in cls.__bases__ if b is not Exception)
        hint = f"`{cls.hint}`" if cls.hint else ""
        out.append(f"| `{name}` | {bases} | {_text(_first_paragraph(cls.__doc__))} | {hint} |")
    out += ["", "## Hints", "",
            "A hint says what gets past an error. The library words it for Python callers, the "
            "command line with its flags:", "",
            "| hint | from Python | on the command line |", "|---|---|---|"]
    cli_hints = getattr(common, "_CLI_HINTS", {})
    for key, said in errors.HINTS.items():
        out.append(f"| `{key}` | {_text(said)} | {_text(cli_hints.get(key, ''))} |")
    codes = re.search(r"Exit codes: (.*?)\.\n", cli_main.__doc__ or "", re.S)
    if codes:
        out += ["", "## Exit codes", "", "The `torchsplice` command exits with " + _text(" ".join(codes.group(1).split())) + "."]
    return "\n".join(out) + "\n"


# ------------------------------------------------------------------------------------ speed
def benchmark_reference() -> str:
    """Markdown for the sections of ``scripts/benchmark.py`` (its docstring, read without running it)."""
    script = REPO / "scripts" / "benchmark.py"
    doc = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8"))) or ""
    usage = [ln.strip() for ln in doc.splitlines() if ln.strip().startswith("python scripts/benchmark.py")]
    body = doc.split("Sections:", 1)[1] if "Sections:" in doc else ""
    sections: list[list[str]] = []
    closing: list[str] = []
    for line in body.splitlines():
        m = re.match(r"^  (\w+)\s+(.*)$", line)
        if m:
            sections.append([m.group(1), m.group(2).strip()])
        elif line.startswith("    ") and sections and not closing:
            sections[-1][1] += " " + line.strip()
        elif line.strip():
            closing.append(line.strip())
    out = ["```bash", *usage, "```", "",
           "| section | what it measures | target |", "|---|---|---|"]
    for name, what in sections:
        m = re.search(r"\s*\[([^\[\]]*)\]\s*$", what)
        target = m.group(1) if m else ""
        what = what[:m.start()] if m else what
        out.append(f"| `{name}` | {_text(' '.join(what.split()))} | {_text(target)} |")
    if closing:
        out += ["", _text(" ".join(closing))]
    return "\n".join(out) + "\n"


#: what ``scripts/benchmark.py --json`` recorded, section by section (see scripts/bench_record.py)
RUNS = REPO / "docs" / "reference" / "benchmark-runs.json"


def benchmark_runs(whole: bool = False) -> str:
    """Markdown for the figures the benchmark's runs printed (:data:`RUNS`): per section its
    date, machine and command line, then each printed line beside its target; the sections run
    on ``--mocap``'s files, or (``whole``) those run on a whole dataset."""
    import sys

    sys.path.insert(0, str(REPO / "scripts"))
    from bench_record import WHOLE, load_runs, split_target

    sections = {name: run for name, run in load_runs(RUNS).items() if name.endswith(WHOLE) == whole}
    if not sections:
        flags = " --mix-db DB --big-db DB" if whole else ""
        return f"No run is recorded yet: `python scripts/benchmark.py{flags} --json docs/reference/benchmark-runs.json`.\n"
    out: list[str] = []
    for name, run in sections.items():
        data = [ln[len("data: "):] for ln in run["lines"] if ln.startswith("data: ")]
        out += [f"### `{name.removesuffix(WHOLE)}`" + (" on the whole dataset" if whole else ""), "",
                _text(f"{run['date']}, {run['machine']}; {run['seconds']:,.0f} s{_load_words(run)}; ``{run['command']}``"
                      + (f"; {data[0]}" if data else "") + "."), "",
                "| what it printed | target |", "|---|---|"]
        for line in run["lines"]:
            if not line.startswith("data: "):
                text, target = split_target(line)
                out.append(f"| {_text(' '.join(text.split()))} | {_text(target)} |")
        out.append("")
    return "\n".join(out)


def _load_words(run: dict) -> str:
    """``", load 0.4 to 1.9"``: the one-minute load average as the section started and ended."""
    load = run.get("load") or [None, None]
    if None in load:
        return ""
    return f", load {load[0]:.1f} to {load[1]:.1f}"


# ------------------------------------------------------------------------------------ specs
def spec_format() -> str:
    """``datasets_spec/README.md``, as shipped with the package; its links into the docs
    (``../docs/PAGE.md``, right beside the repository's files) made relative to the page it
    becomes, ``reference/spec-format.md``."""
    return (REPO / "datasets_spec" / "README.md").read_text(encoding="utf-8").replace("](../docs/", "](../")


GENERATORS = {"cli": cli_reference, "errors": errors_reference, "benchmark": benchmark_reference,
              "benchmark-runs": benchmark_runs, "benchmark-runs-whole": lambda: benchmark_runs(whole=True),
              "spec-format": spec_format}


# ------------------------------------------------------------------------------------ hooks
def on_files(files, config, **kwargs):
    """Add the pictures of ``torchsplice/viz`` as ``images/NAME.png``."""
    from mkdocs.structure.files import File

    for picture in sorted(PICTURES.glob("*.png")):
        files.append(File.generated(config, f"images/{picture.name}", abs_src_path=str(picture)))
    return files


def on_page_markdown(markdown, page, config, files, **kwargs):
    """Replace each ``<!-- generated: NAME -->`` marker with what its generator writes."""
    def generate(m: re.Match) -> str:
        name = m.group(1)
        if name not in GENERATORS:
            raise ValueError(f"{page.file.src_uri}: no generator named {name!r} (known: {', '.join(GENERATORS)})")
        return GENERATORS[name]()

    return MARKER.sub(generate, markdown)


def _role(m: re.Match) -> str:
    short, target = m.group(1) == "~", m.group(2).strip()
    text = target.rsplit(".", 1)[-1] if short else target.lstrip(".")
    if target.startswith("torchsplice."):  # a full name: linked where the site has its entry
        return f'<autoref identifier="{target}" optional><code>{text}</code></autoref>'
    return f"<code>{text}</code>"


def on_page_content(html, page, config, files, **kwargs):
    """Sphinx roles in the API pages' docstrings as code, cross-referenced (see the module docstring)."""
    return ROLE.sub(_role, html)
