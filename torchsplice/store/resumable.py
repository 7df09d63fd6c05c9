"""HDF5 files written across runs: what lets a killed writer's file be reopened where it stood.

A resumable database (:meth:`~torchsplice.store.database.MotionDatabase.create` with a
``staging`` path) is written in HDF5's single-writer/multiple-reader (SWMR) mode, whose
writes are ordered so that the file on disk is always consistent: a process killed at any
moment leaves a file that opens, holding at least everything written before its last flush.
Such a file is marked "open for writing" in its superblock, and HDF5 refuses to open it for
writing again until the mark is cleared (what HDF5's ``h5clear --status --increment`` tool
does); :func:`clear_status_flags` clears it in place. Nothing here reads or writes frames: the
database returns to its last checkpoint itself.

Beside the staging file ``STAGING`` lie two records of the writer's: ``STAGING.rows``, the
clip-table rows appended so far (:class:`RowLog`), and ``STAGING.commit``, one JSON line per
checkpoint (:func:`last_checkpoint` reads the last complete one).

:func:`detach` closes an open file while discarding every write HDF5 still holds, as a killed
process would: after a write has failed (a full disk), closing normally would try to flush
HDF5's caches and could crash the process; detached, the file stays as the failure left it.
"""

from __future__ import annotations

import json
import os
import pickle
import struct
from pathlib import Path

__all__ = ["lookup3", "clear_status_flags", "detach", "RowLog", "commit_path", "rows_path", "last_checkpoint"]

_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_M = 0xFFFFFFFF


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _M


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle`` of ``data``: the checksum of HDF5's metadata
    (``H5_checksum_lookup3``), here for the 44 bytes of a version 2 or 3 superblock."""
    n = len(data)
    a = b = c = (0xDEADBEEF + n + initval) & _M
    i = 0
    word = lambda k: data[k] | (data[k + 1] << 8) | (data[k + 2] << 16) | (data[k + 3] << 24)  # noqa: E731
    while n > 12:
        a, b, c = (a + word(i)) & _M, (b + word(i + 4)) & _M, (c + word(i + 8)) & _M
        # the reference's mix, a line per step of it
        # fmt: off
        a = (a - c) & _M; a ^= _rot(c, 4); c = (c + b) & _M  # noqa: E702
        b = (b - a) & _M; b ^= _rot(a, 6); a = (a + c) & _M  # noqa: E702
        c = (c - b) & _M; c ^= _rot(b, 8); b = (b + a) & _M  # noqa: E702
        a = (a - c) & _M; a ^= _rot(c, 16); c = (c + b) & _M  # noqa: E702
        b = (b - a) & _M; b ^= _rot(a, 19); a = (a + c) & _M  # noqa: E702
        c = (c - b) & _M; c ^= _rot(b, 4); b = (b + a) & _M  # noqa: E702
        # fmt: on
        n -= 12
        i += 12
    if n == 0:
        return c
    tail = bytes(data[i : i + n]) + bytes(12 - n)
    w = lambda k: tail[k] | (tail[k + 1] << 8) | (tail[k + 2] << 16) | (tail[k + 3] << 24)  # noqa: E731
    a, b, c = (a + w(0)) & _M, (b + w(4)) & _M, (c + w(8)) & _M
    # the reference's final, a line per step of it
    # fmt: off
    c ^= b; c = (c - _rot(b, 14)) & _M  # noqa: E702
    a ^= c; a = (a - _rot(c, 11)) & _M  # noqa: E702
    b ^= a; b = (b - _rot(a, 25)) & _M  # noqa: E702
    c ^= b; c = (c - _rot(b, 16)) & _M  # noqa: E702
    a ^= c; a = (a - _rot(c, 4)) & _M  # noqa: E702
    b ^= a; b = (b - _rot(a, 14)) & _M  # noqa: E702
    c ^= b; c = (c - _rot(b, 24)) & _M  # noqa: E702
    # fmt: on
    return c


def clear_status_flags(path: Path) -> None:
    """Clear the "open for writing" mark a killed writer left in ``path``'s superblock, and
    set its end-of-allocation address to at least the file's size, in place (HDF5's
    ``h5clear --status --increment=0``). Only version 2 and 3 superblocks at the start of the
    file (what ``libver="latest"`` writes) carry the mark; ``ValueError`` for anything else."""
    with open(path, "r+b") as f:
        sb = bytearray(f.read(48))
        if len(sb) < 48 or sb[:8] != _SIGNATURE or sb[8] not in (2, 3) or sb[9] != 8:
            raise ValueError(f"{path}: not an HDF5 file with a version 2 or 3 superblock at its start")
        if struct.unpack("<I", sb[44:48])[0] != lookup3(bytes(sb[:44])):
            raise ValueError(f"{path}: the superblock's checksum does not match")
        size = os.fstat(f.fileno()).st_size
        eoa = struct.unpack("<Q", sb[28:36])[0]
        if sb[11] == 0 and eoa >= size:
            return
        sb[11] = 0
        sb[28:36] = struct.pack("<Q", max(eoa, size))
        sb[44:48] = struct.pack("<I", lookup3(bytes(sb[:44])))
        f.seek(0)
        f.write(sb)


def detach(h5) -> None:
    """Close the h5py file ``h5`` without writing anything more to it (see the module docstring)."""
    try:
        fd = h5.id.get_vfd_handle()
        null = os.open(os.devnull, os.O_RDWR)
        try:
            os.dup2(null, fd)
        finally:
            os.close(null)
    except Exception:  # not a POSIX file: close it as it is
        pass
    try:
        h5.close()
    except Exception:
        pass


# --------------------------------------------------------------------------------------------
# the records beside a staging file
# --------------------------------------------------------------------------------------------
class RowLog:
    """The clip-table rows of a resumable database, appended to a file beside its staging file
    (``STAGING.rows``): one length-prefixed pickle per append (column -> array). Appends only;
    :meth:`truncate` returns it to a checkpoint's size."""

    def __init__(self, path: Path, fresh: bool):
        self.path = path
        self.file = open(path, "wb" if fresh else "r+b")
        self.file.seek(0, os.SEEK_END)

    def append(self, rows: dict) -> None:
        data = pickle.dumps(rows, protocol=pickle.HIGHEST_PROTOCOL)
        self.file.write(len(data).to_bytes(8, "little") + data)

    def size(self) -> int:
        self.file.flush()
        return self.file.tell()

    def truncate(self, size: int) -> None:
        self.file.flush()
        if os.fstat(self.file.fileno()).st_size < size:
            raise ValueError(f"{self.path} holds fewer rows than its checkpoint")
        self.file.truncate(size)
        self.file.seek(size)

    def records(self):
        """Every append, in order."""
        self.file.flush()
        with open(self.path, "rb") as f:
            while head := f.read(8):
                yield pickle.loads(f.read(int.from_bytes(head, "little")))

    def close(self) -> None:
        self.file.close()


def commit_path(staging: Path) -> Path:
    """Where a resumable database staged at ``staging`` records its last checkpoint."""
    return staging.with_name(f"{staging.name}.commit")


def rows_path(staging: Path) -> Path:
    """Where a resumable database staged at ``staging`` logs its clip-table rows."""
    return staging.with_name(f"{staging.name}.rows")


def last_checkpoint(staging: Path) -> dict | None:
    """The last complete record of ``STAGING.commit`` (``None`` when it has none)."""
    try:
        lines = commit_path(Path(staging)).read_text().splitlines()
    except OSError:
        return None
    for line in reversed(lines):
        try:
            record = json.loads(line)
        except ValueError:
            continue
        if isinstance(record, dict) and isinstance(record.get("note"), dict):
            return record
    return None
