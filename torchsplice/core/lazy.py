"""Names a package imports on first use, so that the command line (and ``import torchsplice``)
starts without loading torch: every package of torchsplice declares its public names in one
table, name -> the module that defines it, and gets its ``__getattr__`` and ``__dir__`` here.

    __getattr__, __dir__ = lazy_names(__name__, {"MotionDataset": ".dataset", ...})
"""

from __future__ import annotations

import importlib
import sys

__all__ = ["lazy_names"]


def lazy_names(package: str, where: dict[str, str]):
    """``(__getattr__, __dir__)`` for module ``package``: ``where`` maps each lazy name to the
    module that defines it (relative to ``package``, as ``".dataset"``), or to the subpackage
    of that name itself. A name is imported on first use and then kept in the package, so later
    uses cost nothing."""

    def __getattr__(name: str):
        if name in where:
            module = importlib.import_module(where[name], package)
            value = module if module.__name__ == f"{package}.{name}" else getattr(module, name)
            setattr(sys.modules[package], name, value)
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(where))

    return __getattr__, __dir__
