"""``scripts/benchmark.py --json FILE``: what each section printed, kept with the run's facts.

The docs' Speed page (``docs/reference/speed.md``) is generated from such a file
(``docs/reference/benchmark-runs.json``), so the figures it shows are the ones a run printed,
never retyped. A run replaces the sections it ran and keeps the others, each section with its
own date, machine and command line: the slow sections (a whole dataset's job) can be recorded
on another day than the quick ones, and the page says which is which.

The file, UTF-8 JSON::

    {"sections": {"NAME": {"date": "2026-12-05", "machine": "...", "command": "...",
                           "seconds": 12.3, "load": [0.4, 1.9],
                           "lines": ["what the section printed", ...]}}}

A section run on a whole dataset (``--mix-db``, ``--held-back``, ``--big-db``: jobs of minutes to
half an hour) is recorded as ``NAME`` + :data:`WHOLE`, beside its run on ``--mocap``'s files.

``load`` is the machine's one-minute load average when the section started and when it ended
(``os.getloadavg``): a figure measured beside other work says so.

A printed line ends with its target in brackets where it has one (``... 2.1x  [>= 1x]``).
"""

from __future__ import annotations

import io
import json
import os
import platform
import shlex
import sys
import time
from datetime import date
from pathlib import Path

__all__ = ["Recorder", "WHOLE", "machine", "load_runs", "split_target"]

WHOLE = ", whole dataset"
"""What a section's name gains in the record where it ran on a whole dataset."""


def machine() -> str:
    """The machine in a few words: CPU model, cores, memory, GPU where torch sees one."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    words = [f"{os.cpu_count()} cores ({cpu})"]
    try:
        pages = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        words.append(f"{pages / 2**30:.0f} GiB")
    except (ValueError, OSError, AttributeError):
        pass
    try:
        import torch

        words.append(f"torch {torch.__version__}")
        if torch.cuda.is_available():
            words.append(torch.cuda.get_device_name(0))
        else:
            words.append("no GPU")
    except ImportError:
        pass
    return ", ".join(words)


def _load() -> float | None:
    """The one-minute load average, ``None`` where the system has none."""
    try:
        return round(os.getloadavg()[0], 2)
    except (OSError, AttributeError):
        return None


def split_target(line: str) -> tuple[str, str]:
    """``(figure, target)`` of a printed line: its trailing ``[...]`` is the target."""
    text = line.rstrip()
    if text.endswith("]") and "[" in text:
        at = text.rfind("[")
        return text[:at].rstrip(), text[at + 1 : -1].strip()
    return text, ""


def load_runs(path: Path) -> dict:
    """The recorded sections of ``path`` (``{}`` where there is no file yet)."""
    if not path.is_file():
        return {}
    return json.loads(path.read_text(encoding="utf-8")).get("sections", {})


class _Tee(io.TextIOBase):
    """Writes go to the terminal and are kept, line by line."""

    def __init__(self, out):
        self.out, self.lines, self.partial = out, [], ""

    def write(self, s: str) -> int:
        self.out.write(s)
        self.partial += s
        *done, self.partial = self.partial.split("\n")
        self.lines += [ln for ln in done if ln.strip()]
        return len(s)

    def flush(self) -> None:
        self.out.flush()


class Recorder:
    """Keeps what each section prints (``with recorder.section(name): ...``) and, with a path,
    writes them into it when :meth:`save` is called (atomically: a run killed midway leaves the
    file as it was)."""

    def __init__(self, path: Path | None):
        self.path, self.sections = path, {}

    def section(self, name: str) -> "_Section":
        return _Section(self, name)

    def save(self) -> None:
        if self.path is None or not self.sections:
            return
        runs = load_runs(self.path)
        runs.update(self.sections)
        tmp = self.path.with_name(f".{self.path.name}.partial")
        tmp.write_text(json.dumps({"sections": dict(sorted(runs.items()))}, indent=1, ensure_ascii=False) + "\n",
                       encoding="utf-8")
        os.replace(tmp, self.path)


class _Section:
    def __init__(self, recorder: Recorder, name: str):
        self.recorder, self.name = recorder, name

    def __enter__(self):
        self.t0, self.stdout, self.load0 = time.perf_counter(), sys.stdout, _load()
        self.tee = sys.stdout = _Tee(self.stdout)
        return self

    def __exit__(self, kind, value, tb):
        sys.stdout = self.stdout
        if kind is None:  # a section that failed is not recorded
            self.recorder.sections[self.name] = {
                "date": date.today().isoformat(),
                "machine": machine(),
                "command": shlex.join(["python", "scripts/benchmark.py", *sys.argv[1:]]),
                "seconds": round(time.perf_counter() - self.t0, 1),
                "load": [self.load0, _load()],
                "lines": self.tee.lines + ([self.tee.partial] if self.tee.partial.strip() else []),
            }
        return False
