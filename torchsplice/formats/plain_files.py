"""Reading a user's small files safely: only regular files (a FIFO would block the read forever,
``/dev/zero`` would fill the memory), only inside the folder being imported (a symlink out of
it is not followed), and only up to a size, each refusal one line naming the file.

Used where torchsplice reads files it did not write: a HumanML3D folder's motions, captions
and split lists, and a ``--captions`` file.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..core.errors import TorchspliceError

__all__ = ["MAX_TEXT_BYTES", "MAX_ARRAY_BYTES", "not_regular", "checked_file", "read_capped_text"]

MAX_TEXT_BYTES = 256 << 20
"""The largest text file read (a split list of millions of IDs is tens of megabytes)."""
MAX_ARRAY_BYTES = 1 << 30
"""The largest ``.npy`` motion read (a (N, 263) float32 motion of an hour at 20 fps is 76 MB)."""


def not_regular(mode: int) -> str | None:
    """What a file of ``st_mode`` ``mode`` is when it is not a regular file (``"a named pipe
    (FIFO)"``...), else ``None``: what a reader must not open (it would block, or never end)."""
    if stat.S_ISREG(mode):
        return None
    return "a named pipe (FIFO)" if stat.S_ISFIFO(mode) else "a folder" if stat.S_ISDIR(mode) else "a device or socket"


def checked_file(path, inside=None, limit: int | None = None) -> Path:
    """``path``, once it is a regular file of at most ``limit`` bytes and, with ``inside`` (a
    folder), within that folder once symlinks are resolved; else one
    :class:`~torchsplice.core.errors.TorchspliceError` line naming it."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise TorchspliceError(f"{path}: missing") from None
    except OSError as exc:
        raise TorchspliceError(f"{path}: cannot be read ({' '.join(str(exc).split())})") from None
    if (kind := not_regular(st.st_mode)) is not None:
        raise TorchspliceError(f"{path}: is {kind}, not a regular file; not read")
    if inside is not None:
        root = Path(inside).resolve()
        if root not in path.resolve().parents:
            raise TorchspliceError(f"{path}: leads out of {inside} (a symlink to {path.resolve()}); not followed")
    if limit is not None and st.st_size > limit:
        raise TorchspliceError(f"{path}: {st.st_size:,} bytes, more than the {limit:,} such a file can hold; not read")
    return path


def read_capped_text(path, inside=None, limit: int = MAX_TEXT_BYTES) -> str:
    """The UTF-8 text of ``path`` checked by :func:`checked_file` (read at most ``limit`` bytes
    even if it grows meanwhile); undecodable bytes are one line naming it."""
    path = checked_file(path, inside, limit)
    with open(path, "rb") as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise TorchspliceError(f"{path}: more than {limit:,} bytes; not read")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise TorchspliceError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
