"""The entry point: the parser built from the registered commands, and :func:`main`.

Every user mistake (a malformed file, an unknown clip, a spec that does not fit) prints one
line ``torchsplice: error: ...`` and exits non-zero; tracebacks are for bugs only.
Exit codes: 0 success, 1 finished with problems (e.g. some files skipped), 2 error or bad
usage, 130 interrupted (143 terminated).
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings

from ..core.errors import TorchspliceError
from ..core.version import __version__
from .base import CliParser, registered_commands
from ..core.stop import clear_stop
from .common import cli_message, on_sigint, on_sigterm, one_line, stop_code, stopped

__all__ = ["main", "build_parser", "COMMAND_MODULES"]

COMMAND_MODULES = ("databases", "retarget", "mirror", "export", "splice", "views", "evaluate", "jobs")
"""The built-in commands' modules, in the order their commands are listed."""


def _plugins_in(argv: list[str]) -> list[str]:
    """The ``--plugin MODULE`` values of a command line, read before the parser is built (so that
    plug-in methods, engines and export formats appear in its help and choices)."""
    out = []
    for k, a in enumerate(argv):
        if a == "--plugin" and k + 1 < len(argv):
            out.append(argv[k + 1])
        elif a.startswith("--plugin="):
            out.append(a.split("=", 1)[1])
    return out


def _command_in(argv: list[str]) -> str | None:
    """The command a command line names (its first word that is not a top-level option), or ``None``."""
    skip = False
    for a in argv:
        if skip:
            skip = False
        elif a == "--plugin":
            skip = True
        elif not a.startswith("-"):
            return a
    return None


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every registered command (plug-ins loaded before it is built show in its choices).

    ``only``: a command whose options alone are declared (the others are listed, with their
    help, but their flags are not built, nor the registries they list read): what a command line
    that names one pays at start-up. Unknown, or ``None``: every command's."""
    from ..splice.registry import available_methods

    available_methods()  # loads the entry points and TORCHSPLICE_PLUGINS first: their formats and engines are choices
    for module in COMMAND_MODULES:
        importlib.import_module(f"{__package__}.{module}")
    p = CliParser(
        prog="torchsplice",
        description="Splice upper-body actions onto locomotion for every pair of clips in a motion database.",
    )
    p.add_argument("--version", action="version", version=f"torchsplice {__version__}")
    p.add_argument("--plugin", action="append", metavar="MODULE", default=[],
                   help="import this module first: a plug-in that registers splicing methods, engines or export "
                        "formats (repeatable; also TORCHSPLICE_PLUGINS=MODULE[,MODULE...] and the torchsplice.methods "
                        "entry point group)")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    commands = registered_commands()
    everyone = only not in {c.name for c in commands}
    for command in commands:
        s = sub.add_parser(command.name, help=command.help, description=command.description)
        if everyone or command.name == only:
            command.add_arguments(s)
        s.set_defaults(func=command.run, cli_command=command)
    return p


def _unknown_flags(parser, args, extra: list[str]) -> None:
    """Exit 2 with one line naming the arguments the command does not take, with the closest
    of its own flags for a mistyped one (``--wrokers``: did you mean ``--workers``?)."""
    import difflib

    name = getattr(args, "command", None)
    sub = next((a.choices[name] for a in parser._actions if isinstance(a, argparse._SubParsersAction)
                and name in a.choices), None)
    flags = [o for a in (sub or parser)._actions for o in a.option_strings if o.startswith("--")]
    hint = ""
    for item in extra:
        if item.startswith("-"):
            close = difflib.get_close_matches(item.split("=", 1)[0], flags, n=1, cutoff=0.6)
            if close:
                hint = f"; did you mean {close[0]!r}?"
                break
    prog = sub.prog if sub is not None else parser.prog
    parser.exit(2, f"torchsplice: error: unrecognized arguments: {' '.join(extra)}{hint} (see {prog} --help)\n")


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` for the command line: ``torchsplice: warning: ...``, one line."""
    print(f"torchsplice: warning: {one_line(message, limit=1000)}", file=file or sys.stderr)


def _fail(exc: TorchspliceError) -> int:
    """A user's mistake: its one line, exit code 2."""
    print(f"torchsplice: error: {one_line(cli_message(exc), limit=1000)}", file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    import signal
    import threading

    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        from ..splice.registry import load_plugins

        load_plugins(_plugins_in(argv))
        parser = build_parser(only=_command_in(argv))  # only that command's options: a quicker start
    except TorchspliceError as exc:
        return _fail(exc)
    args, extra = parser.parse_known_args(argv)
    if extra:  # a mistyped flag: said against the command's own flags, pointing at its help
        _unknown_flags(parser, args, extra)
    args.argv = argv
    if getattr(args, "output", None) == "":  # an empty name would mean the current folder
        print("torchsplice: error: the output name is empty; name a file or folder", file=sys.stderr)
        return 2
    try:
        args.cli_command.prepare(args)
    except TorchspliceError as exc:
        return _fail(exc)
    except KeyboardInterrupt as exc:
        print(f"torchsplice: {stopped(exc)}", file=sys.stderr)
        return stop_code(exc)
    previous = None
    if threading.current_thread() is threading.main_thread():
        clear_stop()
        previous = signal.signal(signal.SIGTERM, on_sigterm)  # stop as Ctrl-C does: outputs discarded, work kept
        previous_int = signal.getsignal(signal.SIGINT)
        if previous_int is signal.default_int_handler:  # not when the caller chose otherwise (ignored, its own)
            signal.signal(signal.SIGINT, on_sigint)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning  # the library's warnings as one line each
            return args.func(args)
    except TorchspliceError as exc:
        return _fail(exc)
    except KeyboardInterrupt as exc:
        print(f"torchsplice: {stopped(exc)}", file=sys.stderr)
        return stop_code(exc)
    except BrokenPipeError:
        return 0
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
            signal.signal(signal.SIGINT, previous_int)
            clear_stop()  # this command's stop: not the next in-process caller's
