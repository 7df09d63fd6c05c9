"""What the commands share: errors said with flags, output checks and locks, printing, and the
argument types and flag groups used by several commands.

Errors never name flags in the library (:mod:`torchsplice.core.errors`): an error names its
options (``{max_length_ratio}``) and a hint key, and :func:`cli_message` says them as this
command line's flags. Defaults and allowed values come from the library's ``defaults`` modules
(``torchsplice.<package>.defaults``: torch-free, so ``--help`` loads no torch).
"""

from __future__ import annotations

import argparse
import contextlib
import shlex
from pathlib import Path

from ..core.errors import OutputExistsError, TorchspliceError
from ..core.names import counted as n  # "1 clip", "2 clips"
from ..core.stop import Terminated, ask_stop, stop_kind
from ..viz.defaults import SUPPORTED_SUFFIXES

__all__ = ["cli_message", "flag", "output", "locked", "say", "n", "at", "one_line", "progress", "command_line",
           "positive_int", "positive_float", "share", "bounded_int", "add_output_flags", "device",
           "Terminated", "on_sigterm", "stopped", "stop_code", "expand_clips"]

_CLI_HINTS = {  # what the library's error hints (torchsplice.core.errors.HINTS) are on the command line
    "overwrite": "use --force to overwrite",
    "force_locomotion": "--force-locomotion splices it anyway",
    "restart": "pass --restart to discard it",
}
_FLAGS = {"overwrite": "--force", "output": "-o", "no_index": "--no-index", "skeletons": "--skeleton",
          "info": "torchsplice info"}  # library option -> flag, where it is not --the-same-name


def flag(option: str) -> str:
    """A library option's command-line flag (``max_length_ratio`` -> ``--max-length-ratio``)."""
    return _FLAGS.get(option, "--" + option.replace("_", "-"))


def cli_message(exc: BaseException) -> str:
    """An error's message as the command line says it: the options it names as flags
    (``{max_length_ratio}`` -> ``--max-length-ratio``) and its hint in flag terms."""
    from ..core.errors import HINTS, render_message

    if not isinstance(exc, TorchspliceError) or not hasattr(exc, "message"):
        return str(exc)
    text = render_message(exc.message, exc.options, flag)
    hint = _CLI_HINTS.get(exc.hint) or HINTS.get(exc.hint) if exc.hint else None
    return f"{text} ({hint})" if hint else text


def progress(iterable, total: int, desc: str, quiet: bool, unit: str = "file"):
    """Progress on stderr, hidden with --quiet: tqdm's bar on a terminal, a line every 30 s in a
    log or a pipe (:func:`torchsplice.core.progress.progress_bar`)."""
    from ..core.progress import progress_bar

    return progress_bar(iterable, total=total, desc=desc, unit=unit, show=not quiet)


def _outputs(kind: str) -> tuple[tuple[str, ...], str]:
    """A kind of output: (suffixes, what it is)."""
    from ..formats.importer import DATABASE_SUFFIXES

    if kind == "bvh":
        from ..formats.exporters import get_exporter

        bvh = get_exporter("bvh")
        return (bvh.suffix,), bvh.what
    return {
        "database": (DATABASE_SUFFIXES, "a database"),
        "report": ((".md",), "a Markdown report"),
        "plot": ((".png", ".pdf", ".svg"), "a picture"),
        "render": (tuple(SUPPORTED_SUFFIXES), "a GIF, MP4 or PNG filmstrip"),
        "viewer": ((".html", ".htm"), "an HTML page"),
    }[kind]


def output(args, kind: str) -> Path:
    """``args.output`` checked before any work: the right suffix for ``kind``, not a folder,
    not one of the command's inputs (its database and ``--sources``), and not an existing file
    unless ``--force``."""
    from ..store.atomic import check_output

    suffixes, what = _outputs(kind)
    inputs = [args.database, *(getattr(args, "sources", None) or [])] if getattr(args, "database", None) else []
    return check_output(args.output, suffixes, what, inputs=inputs, overwrite=getattr(args, "force", False))


def command_line(args) -> str:
    """The command as typed (what locks and run records say)."""
    return "torchsplice " + shlex.join(getattr(args, "argv", []))


@contextlib.contextmanager
def locked(out: Path, args):
    """Hold the output's lock while the command writes it: a second writer is refused at once."""
    from ..store.lock import output_lock

    with output_lock(out, command_line(args)):
        if out.exists() and not getattr(args, "force", False):  # written meanwhile by another process
            raise OutputExistsError(f"{out}: already exists")
        yield out


def say(args, msg: str) -> None:
    if not getattr(args, "quiet", False):
        print(msg)


def at(path, why: str) -> str:
    """``PATH: why``, or ``PATH:LINE: rest`` when ``why`` starts with a line number."""
    from ..core.names import printable

    head, sep, _ = why.partition(":")
    path = printable(path)  # a file's name may hold control characters
    return f"{path}:{why}" if sep and head.isdigit() else f"{path}: {why}"


def one_line(message, path=None, limit: int = 300) -> str:
    """``message`` as one line of at most ``limit`` characters, without a leading ``PATH:``."""
    from ..formats.importer import one_line as _one_line

    return _one_line(message, path, limit)


def device(name: str | None):
    """A torch device name checked up front: one clear line instead of a traceback later."""
    from ..job.config import check_device

    return check_device(name)


# --------------------------------------------------------------------------------------------
# argument types
# --------------------------------------------------------------------------------------------
def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def bounded_int(lo: int, hi: int):
    """An argparse type: a whole number from ``lo`` to ``hi``."""
    def parse(text: str) -> int:
        value = positive_int(text) if lo >= 1 else int(text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be from {lo} to {hi}, got {value}")
        return value
    return parse


def share(text: str) -> float:
    """argparse type: a number from 0 to 1."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a number from 0 to 1, got {text!r}")
    return value


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def add_output_flags(s, force_help: str = "overwrite an existing file", quiet_help: str = "print nothing on success") -> None:
    s.add_argument("-f", "--force", action="store_true", help=force_help)
    s.add_argument("-q", "--quiet", action="store_true", help=quiet_help)


# --------------------------------------------------------------------------------------------
# interrupts
# --------------------------------------------------------------------------------------------
def on_sigterm(signum, frame):
    ask_stop("terminate")  # seen by the job between tasks even if a library swallows the exception below
    raise Terminated()


def on_sigint(signum, frame):
    ask_stop("interrupt")  # Ctrl-C inside a finalizer or a weak reference's callback is printed and lost
    raise KeyboardInterrupt()


def _terminated(exc: BaseException) -> bool:
    return isinstance(exc, Terminated) or stop_kind() == "terminate"


def stopped(exc: BaseException) -> str:
    """``"terminated"`` (SIGTERM) or ``"interrupted"`` (Ctrl-C)."""
    return "terminated" if _terminated(exc) else "interrupted"


def stop_code(exc: BaseException) -> int:
    """The exit code of a stopped command: 143 for SIGTERM, 130 for Ctrl-C."""
    return 143 if _terminated(exc) else 130


def add_clip_arguments(s, verb: str) -> None:
    """A command's clips of one database: ``DATABASE [CLIP ...]``, ``--all``, ``--select``; read
    them back with :func:`chosen_clips`."""
    s.add_argument("database", help="motion database (.h5)")
    s.add_argument("clips", nargs="*", metavar="CLIP", help="clip names, or selectors ('walk_*', 'role:action')")
    s.add_argument("--all", action="store_true", help=f"{verb} every clip")
    s.add_argument("--select", action="append", default=None, metavar="SELECTOR",
                   help="only clips this selector selects (the selection language of splice-all: names, globs, "
                        "role:R, label:K=V, skeleton:K; repeat for all of several)")


def chosen_clips(args, verb: str) -> list[str] | None:
    """The clips :func:`add_clip_arguments` named (selectors expanded), or ``None`` for every clip
    (``--all``, or every one ``--select`` selects); one line when none or both are given."""
    if not (args.clips or args.all or args.select):
        raise TorchspliceError(f"name the clips to {verb} (as `torchsplice info` lists them), or pass --all or --select")
    if args.all and args.clips:
        raise TorchspliceError(f"name the clips to {verb}, or pass --all (not both)")
    return expand_clips(args.database, args.clips) if args.clips else None


def expand_clips(database, items) -> list[str]:
    """A command's clip arguments as names, in order: a clip name (of the database, or of a source
    database) as it is, a selector of the selection language (``'walk_*'``, ``'role:spliced'``,
    ``'method:naive,method:splice'``) replaced by the database's clips it selects, in row order."""
    from ..store.database import MotionDatabase
    from ..store.select import looks_like_selector, select_clips

    out: list[str] = []
    with MotionDatabase.open(database) as db:
        table = None
        for item in items:
            if item in db or not looks_like_selector(item):
                out.append(item)
                continue
            table = table if table is not None else db.clip_table()
            out += [table.names[r] for r in select_clips(table, item, "clip selector", str(database))]
    return list(dict.fromkeys(out))
