"""Commands of the ``torchsplice`` command line: one :class:`Command` per command, in a registry.

A command is its name, a one-line ``help`` (the command list of ``torchsplice --help``), a
``description`` (its own ``--help``), :meth:`Command.add_arguments` declaring its flags and
:meth:`Command.run` doing the work (parse nothing more, call the library, print what it says,
return the exit code). A new command is one module with a subclass and one call::

    from torchsplice.cli.base import Command, register_command

    class Hello(Command):
        name, help = "hello", "say hello"

        def add_arguments(self, parser):
            parser.add_argument("who")

        def run(self, args) -> int:
            print(f"hello {args.who}")
            return 0

    register_command(Hello())

The parser lists the commands in the order they registered (the built-in modules are imported
in :data:`torchsplice.cli.main.COMMAND_MODULES`'s order). Conventions of every command: a user's
mistake raises :class:`~torchsplice.core.errors.TorchspliceError` (the entry point prints it as
one line ``torchsplice: error: ...`` and exits with 2); heavy modules (torch, numpy, h5py) are
imported inside :meth:`Command.run`, never at module level, so that ``--help`` stays fast.
"""

from __future__ import annotations

import argparse

from ..core.errors import TorchspliceError

__all__ = ["Command", "register_command", "registered_commands", "CliParser"]


class Command:
    """One command (see the module docstring)."""

    name: str = ""
    help: str = ""
    description: str | None = None

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        """Declare the command's arguments on its sub-parser."""

    def prepare(self, args: argparse.Namespace) -> None:
        """Called once the command line is parsed, before signal handlers are installed and
        :meth:`run` is called (e.g. to start worker processes early)."""

    def run(self, args: argparse.Namespace) -> int:
        """Do the work; return the exit code (0 success, 1 finished with problems)."""
        raise NotImplementedError


_COMMANDS: dict[str, Command] = {}


def register_command(command: Command) -> Command:
    """Add ``command`` (an instance) to the command line; returns it."""
    if not isinstance(command, Command) or not command.name:
        raise TorchspliceError(f"register_command takes a named torchsplice.cli.base.Command, got {command!r}")
    old = _COMMANDS.get(command.name)
    if old is not None and type(old) is not type(command) and (type(old).__module__, type(old).__qualname__) != (
            type(command).__module__, type(command).__qualname__):
        raise TorchspliceError(f"command {command.name!r} is already registered (by {type(old).__module__})")
    _COMMANDS[command.name] = command
    return command


def registered_commands() -> tuple[Command, ...]:
    """The registered commands, in registration order."""
    return tuple(_COMMANDS.values())


class CliParser(argparse.ArgumentParser):
    """argparse, with a usage mistake (a missing or malformed flag) said in one line, as every
    other error is, pointing at ``--help`` instead of printing the whole usage."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}{_did_you_mean(message)} (see {self.prog} --help)\n")


def _did_you_mean(message: str) -> str:
    """``"; did you mean 'splice-all'?"`` for an invalid choice close to a valid one (a mistyped
    command or choice), else ``""``."""
    import difflib
    import re

    m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
    if not m:
        return ""
    choices = re.findall(r"'([^']*)'", m.group(2))
    close = difflib.get_close_matches(m.group(1), choices, n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""
