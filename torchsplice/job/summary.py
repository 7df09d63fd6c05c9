"""What a run of the job did (:class:`JobSummary`), as the closing lines say it, and the progress bar."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from ..core.errors import render_message
from ..core.names import counted
from ..core.progress import progress_bar as core_progress_bar
from .size import OutputSize, format_bytes
from .plan import SKELETONS_DIFFER
from .task import FLAG_CODES

__all__ = ["JobSummary", "REASON_OPTIONS", "REASONS_SHOWN", "reason_lines", "progress_bar"]


REASON_OPTIONS = ("max_length_ratio", "force_locomotion", "retarget")
"""Options that skip reasons may name, as ``{name}``."""


@dataclass
class JobSummary:
    """What a run did. ``skipped`` maps a reason to the number of pairs it skipped, ``flagged``
    a kind of flag to the number of clips carrying it (``flagged_clips`` clips in all). A reason
    may name an option as ``{name}`` (of :data:`REASON_OPTIONS`, as errors do, see
    :mod:`torchsplice.core.errors`); :meth:`lines` writes it out."""

    output: Path
    pairs: int = 0
    spliced: int = 0
    resumed: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    flagged: dict[str, int] = field(default_factory=dict)
    flagged_clips: int = 0
    timings: dict[str, int] = field(default_factory=dict)
    copied: int = 0
    seconds: float = 0.0
    compute_seconds: float = 0.0
    engine: str = ""
    shard: tuple[int, int] | None = None
    tasks: int = 0
    tasks_done: int = 0
    merge: bool = False
    merged_shards: int = 0  # shards this run appended to the output (an earlier run's are not merged again)
    dry_run: bool = False
    standing: int = 0  # pairs of standing actions among the pairs
    retargeted: int = 0  # pairs whose action (and reference) were retargeted onto the locomotion's skeleton
    target: str = ""  # --target: what every clip was brought onto first, and where those clips are
    expected: OutputSize | None = None  # the output's expected size (see torchsplice.job.size)
    alignment: OutputSize | None = None  # a dry run of a motion store: what --store alignment would take
    written: int | None = None  # bytes the output took
    free: int | None = None  # bytes free beside the output when the job started
    index: Path | None = None  # NAME.h5.index.csv (or .csv.gz) written beside the output

    def lines(self, option_name=None) -> list[str]:
        """The closing summary, as printed by the command line; ``option_name(option)`` writes the
        options a skip reason names (default: the library's names; the command line: its flags)."""
        name = option_name or (lambda o: o)
        say = lambda why: render_message(why, REASON_OPTIONS, name)  # noqa: E731
        rate = (self.spliced - self.resumed) / self.compute_seconds if self.compute_seconds > 0 else float("nan")
        where = f" with {self.engine}" if self.engine else ""
        if self.dry_run:
            out = [f"would write {self.output}: {counted(self.pairs, 'spliced clip')} in {counted(self.tasks, 'task')}"
                   + (f" ({self.pairs - self.standing} time-aligned, {self.standing} standing actions)" if self.standing else "")
                   + f"; {self._room(option_name)}"]
        elif self.shard is not None:
            k, n = self.shard
            out = [f"slice {k}/{n}: {self.tasks_done} of {self.tasks} tasks done"
                   + (f" ({self.resumed} pairs from an earlier run)" if self.resumed else "")
                   + f" in {self.seconds:.1f} s{where}; when every slice is done: torchsplice merge {self.output}"]
        else:
            done = f" merged from the shards in {self.seconds:.1f} s" if self.merge else \
                f" in {self.seconds:.1f} s ({rate:,.0f} splices/s){where}"
            out = [f"wrote {self.output}: {counted(self.spliced, 'spliced clip')}"
                   + (f" ({self.resumed} pairs from an earlier run)" if self.resumed else "")
                   + (f" + {counted(self.copied, 'source clip')}" if self.copied else "") + done]
        standing = {t: n for t, n in self.timings.items() if t != "timewarp"}
        if standing:
            out.append(f"  {self.timings.get('timewarp', 0)} time-aligned (timewarp), "
                       + ", ".join(f"{n} standing actions ({t})" for t, n in sorted(standing.items())))
        if self.target:
            out.append(f"  every clip {'would be' if self.dry_run else 'was'} retargeted onto {self.target} first")
        if self.retargeted:
            out.append(f"  {self.retargeted} {'would have' if self.dry_run else 'had'} the action retargeted onto the "
                       "locomotion's skeleton (labels retargeted_from, retargeted_to)")
        if self.index is not None and not self.dry_run:
            out.append(f"  every clip's metrics and split in {self.index.name}")
        if self.written is not None and not self.dry_run:
            out.append(f"  {format_bytes(self.written)} on disk" + (f" (expected {format_bytes(self.expected.bytes)})"
                                                                    if self.expected is not None else ""))
        skipped = {w: n for w, n in self.skipped.items() if not w.startswith(SKELETONS_DIFFER)}
        apart = {w[len(SKELETONS_DIFFER):]: n for w, n in self.skipped.items() if w.startswith(SKELETONS_DIFFER)}
        if skipped:
            out.append(f"skipped {sum(skipped.values())} pairs:" if self.shard is None and not self.dry_run else
                       f"the whole job (every slice) skips {sum(skipped.values())} pairs:" if self.shard is not None else
                       f"would skip {sum(skipped.values())} pairs:")
            out += reason_lines(skipped, say)
        if apart:
            out.append(f"not formed: {sum(apart.values())} pairs whose clips are on skeletons of different joints that "
                       "could not be retargeted onto one another:")
            out += [f"  {n} x {say(why)}" for why, n in sorted(apart.items(), key=lambda kv: -kv[1])]
        if self.flagged:
            out.append(f"flagged {counted(self.flagged_clips, 'clip')} (their 'flags' column; 'flag_details' says why, clip by clip):")
            out += [f"  {n} x {code}: {FLAG_CODES.get(code, '')}".rstrip(": ")
                    for code, n in sorted(self.flagged.items(), key=lambda kv: -kv[1])]
        return out

    def _room(self, option_name=None) -> str:
        """Expected size and free room; for a motion store, what the alignment store would take
        (``option_name`` writes the option, as in :meth:`lines`)."""
        folder = self.output.parent
        expect = (f"expected output about {format_bytes(self.expected.bytes)} ({self.expected.frames:,} frames)"
                  if self.expected is not None else "")
        free = f"{format_bytes(self.free)} free in {folder}" if self.free is not None else ""
        fits = "" if self.expected is None or self.free is None else \
            ("" if self.free >= self.expected.bytes else " (it does not fit)")
        store = render_message("{store} alignment", ("store",), option_name or (lambda o: o))
        other = f"; with {store} about {format_bytes(self.alignment.bytes)}" if self.alignment is not None else ""
        return "; ".join(x for x in (expect, free) if x) + fits + other


REASONS_SHOWN = 8
"""Skip reasons of one kind (clips that do not locomote, clips too short) listed one by one; more
are summed up in one line."""


_KINDS = ((re.compile(r"^\S+ does not locomote \("), "clips that do not locomote"),
          (re.compile(r"^\S+ is too short to splice \("), "clips too short to splice"),
          (re.compile(r"^no plain-locomotion reference for \S+ \((\S+)\)$"), "actions with no plain-locomotion reference"))


def reason_lines(skipped: dict[str, int], say) -> list[str]:
    """``N x reason`` lines, most frequent first; reasons of one kind that name a clip (clips
    that do not locomote, are too short or have no reference) past the first
    :data:`REASONS_SHOWN` summed up in one line."""
    kinds: dict[str, list] = {}
    for why, n in sorted(skipped.items(), key=lambda kv: -kv[1]):
        text = say(why)
        kind = next((label for pattern, label in _KINDS if pattern.search(text)), text)
        kinds.setdefault(kind, []).append((n, text))
    out = []
    for kind, items in kinds.items():
        out += [f"  {n} x {text}" for n, text in items[:REASONS_SHOWN]]
        if len(items) > REASONS_SHOWN:
            rest = items[REASONS_SHOWN:]
            out.append(f"  {sum(n for n, _ in rest)} x {len(rest)} other {kind}")
    return out


def progress_bar(total: int, initial: int, show: bool):
    """The job's progress: a bar on a terminal, a line every 30 s in a log (:mod:`torchsplice.core.progress`)."""
    return core_progress_bar(total=total, desc="splice-all", unit="splice", initial=initial, show=show, smoothing=0.1)
