"""All-or-nothing output of several files: what every export writes through.

:func:`staged_files` yields ``stage(file) -> path``: the exporter writes each file at the path
it is given, a hidden name beside it (``.NAME.staged-HOST-PID``). When every file is written,
they are installed under their names; on an error or an interrupt (while writing, or while
installing) no file of the export appears and none it replaced is lost: the staged files go,
the files already installed are taken back (those they replaced, moved aside meanwhile, are put
back), and the folders made for the export (a folder format's subfolders too) are removed if
they are empty again. The same export then runs again as it was.

The output (a file, or the folder of the export) is locked meanwhile (:func:`~torchsplice.store.lock.output_lock`):
a second export to it is refused at once. Staged files a killed export left in a folder (of
dead processes of this host) are removed the first time a file is staged there.

This module imports no torch: it only moves files.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Callable, Iterator, Sequence

from ..core.errors import OutputExistsError, TorchspliceError
from ..store.atomic import os_error_message
from ..store.lock import output_lock, remove_stale_temporaries, temp_path

__all__ = ["staged_files", "make_folder"]


def make_folder(folder: Path) -> None:
    """Create the output folder of an export; an OS error (permission, full disk) is one line."""
    try:
        folder.mkdir(exist_ok=True)
    except OSError as exc:
        raise TorchspliceError(os_error_message(folder, exc)) from None
    if not folder.is_dir():
        raise TorchspliceError(f"{folder}: is a file; several clips go to a folder, one file each")


@contextlib.contextmanager
def staged_files(output, folder: Path | Sequence[Path] | None = None, overwrite: bool = False,
                 command: str = "") -> Iterator[Callable[[Path], Path]]:
    """Write files all or none (see the module docstring).

    Args:
        output: what the export writes (its one file, or its folder): the lock guards it.
        folder: the folder to create for the files, or several (parents before children;
            ``None``: none to create); those it made are removed again, if empty, when the
            export fails.
        overwrite: replace existing files; without it a file that appeared meanwhile (another
            process wrote it) is refused with :class:`~torchsplice.core.errors.OutputExistsError`.
        command: what the lock records as its holder's command.

    Yields ``stage(file) -> path``, the temporary path to write ``file`` at.
    """
    staged: dict[Path, Path] = {}
    cleaned: set[Path] = set()

    def stage(f) -> Path:
        f = Path(f)
        if f.parent not in cleaned:  # what a killed export left there goes first
            remove_stale_temporaries(f.parent, "staged")
            cleaned.add(f.parent)
        staged[f] = temp_path(f, "staged")
        return staged[f]

    folders = [] if folder is None else [Path(folder)] if isinstance(folder, (str, Path)) else [Path(f) for f in folder]
    made: list[Path] = []
    with output_lock(Path(output), command):
        try:
            for f in folders:
                if not f.is_dir():
                    make_folder(f)
                    made.append(f)
            yield stage
            taken = [f for f in staged if f.exists()] if not overwrite else []
            if taken:  # written meanwhile by another process
                raise OutputExistsError(f"{taken[0]}: already exists")
            _install(staged)
        except BaseException:
            for tmp in staged.values():
                with contextlib.suppress(OSError):
                    tmp.unlink()
            for f in reversed(made):
                with contextlib.suppress(OSError):
                    f.rmdir()  # made for this export, and empty again
            raise


def _install(staged: dict[Path, Path]) -> None:
    """Rename every staged file to its name; if one rename fails, undo those done (a file they
    replaced was moved aside first, and is put back) and raise a one-line error."""
    done: list[tuple[Path, Path | None]] = []  # (installed file, the file it replaced, moved aside)
    target = None
    try:
        for target, tmp in staged.items():
            aside = None
            if target.exists() or target.is_symlink():  # overwritten: kept aside until every file is in
                aside = temp_path(target.with_name(target.name + ".old"), "staged")
                os.replace(target, aside)
            done.append((target, aside))
            os.replace(tmp, target)
    except BaseException as exc:
        for f, aside in reversed(done):
            with contextlib.suppress(OSError):
                if aside is not None:
                    os.replace(aside, f)
                elif not staged[f].exists():  # installed by this export: taken back
                    f.unlink()
        if isinstance(exc, OSError):
            raise TorchspliceError(os_error_message(target, exc)) from None
        raise
    for _, aside in done:
        if aside is not None:
            with contextlib.suppress(OSError):
                aside.unlink()
