"""Atomic file output: write beside the target, then rename over it.

A reader never sees a half-written file: until the rename, the target is either absent or
still holds its previous contents. A full disk or any other OS error becomes a one-line
:class:`~torchsplice.core.errors.TorchspliceError` naming the file, and the partial file is
removed.
"""

from __future__ import annotations

import contextlib
import errno
import os
from pathlib import Path

from ..core.errors import OutputExistsError, TorchspliceError
from .lock import check_name_length, temp_path

__all__ = ["atomic_path", "os_error_message", "same_file", "check_output"]


def os_error_message(path, exc: OSError) -> str:
    """One line describing an OS error while writing ``path``."""
    if exc.errno == errno.ENOSPC:
        return f"{path}: no space left on the device"
    if exc.errno in (errno.EACCES, errno.EPERM):
        return f"{path}: permission denied"
    return f"{path}: {exc.strerror or exc}"


def same_file(a, b) -> bool:
    """Whether paths ``a`` and ``b`` name one file (the same path, or links to one file)."""
    a, b = Path(a), Path(b)
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_output(path, suffixes: tuple[str, ...], what: str, inputs=(), overwrite: bool = False) -> Path:
    """``path`` checked as the output of a command, before any work; one-line errors.

    Its suffix must be one of ``suffixes`` (``what`` names the kind of file, e.g. "a report"),
    its name must fit beside it the files written through it (:func:`check_name_length`),
    it must not be a folder or one of the command's ``inputs`` (whatever ``overwrite`` says:
    writing it would destroy the input), its folder must exist, and an existing file is
    refused unless ``overwrite``.
    """
    path = Path(path)
    check_name_length(path)
    if path.suffix.lower() not in suffixes:
        ends = suffixes[0] if len(suffixes) == 1 else f"{', '.join(suffixes[:-1])} or {suffixes[-1]}"
        raise TorchspliceError(f"{path}: the output is {what}, so its name must end in {ends}")
    if path.is_dir():
        raise TorchspliceError(f"{path}: is a folder; give the output a file name ending in {suffixes[0]}")
    for source in inputs:
        if same_file(path, source):
            raise TorchspliceError(f"{path}: is also an input of this command; write the output to another file")
    if not path.parent.is_dir():
        raise TorchspliceError(f"{path}: folder {path.parent} does not exist")
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: already exists")
    return path


@contextlib.contextmanager
def atomic_path(path, suffix: str = ".partial"):
    """Yield a temporary path beside ``path``; on success rename it to ``path``.

    The temporary name is ``.NAME<suffix>-HOST-PID`` in the same folder (see :func:`temp_path`) (so the rename is atomic
    on one file system). On any exception the temporary file is removed and the target is
    left untouched; ``OSError`` is re-raised as :class:`TorchspliceError`.
    """
    path = Path(path)
    if path.parent and not path.parent.exists():
        raise TorchspliceError(f"{path}: folder {path.parent} does not exist")
    tmp = temp_path(path, suffix.lstrip("."))
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        _remove(tmp)
        raise TorchspliceError(os_error_message(path, exc)) from exc
    except BaseException:
        _remove(tmp)
        raise


def _remove(p: Path) -> None:
    with contextlib.suppress(OSError):
        p.unlink()
