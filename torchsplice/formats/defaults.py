"""The option defaults and allowed values of importing and exporting, declared once:
:func:`~.importer.import_bvh` and :func:`~.exporters.export_clips` take them from here, and so
does the command line. Standard library only (see :mod:`torchsplice.splice.defaults` for the
``defaults`` modules' convention). The export formats' own options are declared with each
format (:attr:`.exporters.Exporter.options`) as an :class:`ExportOption` each, torch-free too:
the ``export`` command makes its flags from them, a plug-in format's as the built-ins'."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

__all__ = ["ExportOption", "IMPORT_FORMATS", "DEFAULT_IMPORT_FORMAT", "DEFAULT_SPEC", "DEFAULT_UNITS", "DEFAULT_FILE_UNITS",
           "DEFAULT_NAME_PREFIX", "DEFAULT_IMPORT_WINDOW", "DEFAULT_IMPORT_WINDOW_OVERLAP", "DEFAULT_FORMAT",
           "DEFAULT_EXPORT_INDEX"]

IMPORT_FORMATS = ("auto", "bvh", "humanml3d")
"""What :func:`~.importer.import_bvh` reads: ``auto`` takes a folder holding ``new_joint_vecs/`` as a
HumanML3D folder and anything else as BVH."""
DEFAULT_IMPORT_FORMAT = "auto"
DEFAULT_SPEC = "auto"
"""The dataset spec of an import (``auto``: picked per file)."""
DEFAULT_UNITS: str | None = None
"""The units an import converts every clip to (``None``: each file's own)."""
DEFAULT_FILE_UNITS: str | None = None
"""The units the files are in, where their spec does not say (``None``: unknown)."""
DEFAULT_NAME_PREFIX = ""
"""Put before every imported clip's name."""
DEFAULT_IMPORT_WINDOW: float | None = None
"""Seconds of the windows an import cuts long takes into (``None``: takes kept whole)."""
DEFAULT_IMPORT_WINDOW_OVERLAP = 1.0
"""Seconds consecutive windows overlap."""

DEFAULT_FORMAT = "bvh"
"""The format of an export that names none, whose output's suffix is no format's and whose
options no format needs (a folder of BVH files)."""
DEFAULT_EXPORT_INDEX = True
"""An export of several clips writes ``index.csv`` and the split lists beside them."""


@dataclass(frozen=True)
class ExportOption:
    """An option a format takes (a keyword of :func:`~.exporters.export_clips`), as its
    :class:`~.exporters.Exporter` declares it in ``options``; the ``export`` command makes it the
    flag ``--NAME`` (underscores as dashes, the format's name before its help).

    Attributes:
        default: its value when none is given (``None`` given is the default too).
        choices: its allowed values (``None``: any).
        type: what reads the flag's text (``int``, ``float``; ``None``: the text); an option whose
            default is ``False`` or ``True`` is a switch (``--NAME``; ``--NAME``/``--no-NAME`` if on).
        help: the flag's help.
        metavar: the flag's value in the help (``N``, ``FILE``).
    """

    default: Any = None
    choices: tuple | None = None
    type: Callable[[str], Any] | None = None
    help: str = ""
    metavar: str | None = None
