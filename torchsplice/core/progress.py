"""Progress of long work: a tqdm bar on a terminal, and a line every so often everywhere else.

A job's log, a pipe or a cluster's output file gets no bar (tqdm hides itself there), so long
commands printed nothing for minutes. :func:`progress_bar` gives tqdm's bar on a terminal and
otherwise a :class:`LogProgress`, which prints ``desc: 1,234/5,000 files (25%), 41.2/s, about
1m33s left`` to stderr at most every :data:`LOG_SECONDS` (``TORCHSPLICE_PROGRESS_SECONDS``; 0
for every update), and once at the end when it printed any, as training tools log their
progress; work shorter than that prints nothing.
"""

from __future__ import annotations

import os
import sys
import time

__all__ = ["LOG_SECONDS", "LogProgress", "progress_bar"]

LOG_SECONDS = 30.0
"""Seconds between two progress lines when stderr is not a terminal."""


def _interval() -> float:
    try:
        return max(0.0, float(os.environ.get("TORCHSPLICE_PROGRESS_SECONDS", LOG_SECONDS)))
    except ValueError:
        return LOG_SECONDS


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}h{m:02d}m" if h else (f"{m}m{s:02d}s" if m else f"{s}s")


class LogProgress:
    """tqdm's interface as far as torchsplice uses it (iterate, ``update``,
    ``set_postfix_str``, ``close``), as a line every :data:`LOG_SECONDS` on ``file``."""

    def __init__(
        self,
        iterable=None,
        total: int | None = None,
        desc: str = "",
        unit: str = "it",
        initial: int = 0,
        file=None,
        every: float | None = None,
    ):
        self.iterable, self.total, self.desc, self.unit = iterable, total, desc, unit
        self.n, self.start_n = initial, initial
        self.file = file if file is not None else sys.stderr
        self.every = _interval() if every is None else every
        self.started = self.last = time.monotonic()
        self.postfix = ""
        self.closed = self.printed = False

    def __iter__(self):
        try:
            for item in self.iterable:
                yield item
                self.update(1)
        finally:
            self.close()

    def __len__(self):
        return self.total if self.total is not None else len(self.iterable)

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        self.postfix = str(text)

    def line(self) -> str:
        """The progress line as it stands."""
        elapsed = time.monotonic() - self.started
        done = self.n - self.start_n
        rate = done / elapsed if elapsed > 0 else 0.0
        unit = self.unit if (self.total or self.n) == 1 else f"{self.unit}s"
        text = f"{self.desc}: {self.n:,}" + (
            f"/{self.total:,} {unit} ({100.0 * self.n / self.total:.0f}%)" if self.total else f" {unit}"
        )
        text += f", {rate:,.1f}/s" if rate else ""
        if self.total and rate and self.n < self.total:
            text += f", about {_duration((self.total - self.n) / rate)} left"
        elif self.closed:
            text += f", done in {_duration(elapsed)}"
        return text + (f" ({self.postfix})" if self.postfix else "")

    def update(self, n: int = 1) -> None:
        self.n += n
        now = time.monotonic()
        if now - self.last >= self.every:
            self.last, self.printed = now, True
            print(self.line(), file=self.file, flush=True)

    def close(self) -> None:
        """The closing line, for work that took long enough to be logged at all."""
        if self.closed:
            return
        self.closed = True
        if self.n > self.start_n and (self.printed or time.monotonic() - self.started >= self.every):
            print(self.line(), file=self.file, flush=True)


def progress_bar(
    iterable=None,
    total: int | None = None,
    desc: str = "",
    unit: str = "it",
    initial: int = 0,
    show: bool = True,
    **tqdm_options,
):
    """tqdm's bar on stderr when it is a terminal, a :class:`LogProgress` otherwise; nothing
    (a disabled bar) without ``show``."""
    from tqdm import tqdm  # on first use: this module is stdlib-only (the command line may import it)

    if not show:
        return tqdm(iterable, total=total, desc=desc, unit=unit, initial=initial, disable=True)
    if sys.stderr.isatty():
        return tqdm(
            iterable,
            total=total,
            desc=desc,
            unit=unit,
            initial=initial,
            file=sys.stderr,
            dynamic_ncols=True,
            **tqdm_options,
        )
    return LogProgress(iterable, total=total, desc=desc, unit=unit, initial=initial)
