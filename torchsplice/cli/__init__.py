"""The ``torchsplice`` command line: a thin layer over the library.

Each command parses its flags, calls the library and prints what it returns; it holds no
library logic (exports, for instance, are :func:`torchsplice.formats.exporters.export_clips`,
all or nothing, the same from Python). Layout:

- :mod:`.base`: the :class:`~.base.Command` base class and the command registry (a command is
  one module and one :func:`~.base.register_command` call);
- :mod:`.common`: what commands share (errors said with flags, output checks, argument types);
- the flags' defaults and allowed values are the library's, declared once in each package's
  torch-free ``defaults`` module (``torchsplice.job.defaults``, ...), which the library and the
  commands both import (tests/cli/test_cli_options.py checks them);
- one module per group of commands: :mod:`.databases` (``sample``, ``import``, ``info``),
  :mod:`.export`, :mod:`.splice` (``splice``, ``plot-alignment``), :mod:`.views` (``render``,
  ``view``), :mod:`.evaluate`, :mod:`.jobs` (``splice-all``, ``merge``);
- :mod:`.main`: the parser and :func:`main`.

Every user mistake prints one line ``torchsplice: error: ...`` and exits non-zero; tracebacks
are for bugs only. Exit codes: 0 success, 1 finished with problems (e.g. some files skipped),
2 error or bad usage, 130 interrupted (143 terminated). ``--help`` and ``--version`` import no
torch, numpy or h5py.
"""

from __future__ import annotations

from .common import cli_message
from .main import build_parser, main

__all__ = ["main", "build_parser", "cli_message"]
