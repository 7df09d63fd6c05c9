"""Exclusive locks on outputs: one writer at a time, stale locks taken over.

A lock is a small file beside what it guards, holding JSON (``host``, ``pid``, ``started``,
``command``) and held with ``flock`` for as long as the process lives: the kernel lets go of
it when the process dies, however it dies, so two processes can never both hold it on one
host. A second writer is refused at once with one line naming the holder. A lock file whose
process is gone is taken over. A lock file written from another host is never broken (its
process cannot be checked from here), even where ``flock`` does not reach across hosts.
"""

from __future__ import annotations

import fcntl
import glob
import hashlib
import json
import os
import re
import socket
import time
from pathlib import Path

from ..core.errors import LockedError, TorchspliceError

__all__ = ["FileLock", "LockedError", "host_pid", "pid_alive", "output_lock", "remove_stale_temporaries"]


def host_pid() -> str:
    """``HOST-PID``: what temporary names of this process carry."""
    return f"{socket.gethostname()}-{os.getpid()}"


def temp_path(path, kind: str = "partial") -> Path:
    """The temporary file this process writes ``path`` through: ``.NAME.KIND-HOST-PID`` beside
    it, with a long ``NAME`` cut and ended by a hash of it, so that the temporary name stays
    within file systems' 255 bytes whatever the output's (see :data:`MAX_NAME_BYTES`)."""
    path = Path(path)
    name = path.name
    if len(name.encode()) > _TEMP_NAME_BYTES:
        digest = hashlib.sha1(name.encode("utf-8", "surrogatepass")).hexdigest()[:10]
        name = name.encode()[: _TEMP_NAME_BYTES - 11].decode(errors="ignore") + "~" + digest
    return path.with_name(f".{name}.{kind}-{host_pid()}")


MAX_NAME_BYTES = 240
"""The longest output file name torchsplice writes (UTF-8 bytes): its lock ``.NAME.lock`` and
work folder ``.NAME.parts`` beside it must fit the 255 bytes file systems allow."""
_TEMP_NAME_BYTES = 120


def check_name_length(path) -> None:
    """One line when ``path``'s file name is longer than :data:`MAX_NAME_BYTES`."""
    n = len(Path(path).name.encode("utf-8", "surrogatepass"))
    if n > MAX_NAME_BYTES:
        raise TorchspliceError(
            f"{path}: the output's file name is {n} bytes long; torchsplice writes files beside it "
            f"whose names add a few bytes, so it takes at most {MAX_NAME_BYTES}"
        )


_TEMP = re.compile(r"\.(?P<kind>partial|staged)-(?P<host>.+)-(?P<pid>\d+)$")


def remove_stale_temporaries(folder: Path, kind: str = "partial", of: Path | None = None) -> None:
    """Delete temporary files (``.NAME.KIND-HOST-PID``, ``kind`` ``"partial"`` or
    ``"staged"``) of dead processes on this host in ``folder`` (``of``: only those of that
    output); those of other hosts are left alone (their processes cannot be checked from here)."""
    folder = Path(folder)
    if not folder.is_dir():
        return
    me = socket.gethostname()
    pattern = f".*.{kind}-*" if of is None else glob.escape(temp_path(of, kind).name[: -len(host_pid())]) + "*"
    for f in folder.glob(pattern):
        m = _TEMP.search(f.name)
        if m and m["kind"] == kind and m["host"] == me and not pid_alive(int(m["pid"])):
            f.unlink(missing_ok=True)


def pid_alive(pid: int) -> bool:
    """Whether a process with this PID runs on this host (a zombie, dead but not yet reaped by
    its parent, does not: ``kill(pid, 0)`` alone would say it lives)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            state = f.read().rsplit(b")", 1)[1].split()[0]
        return state not in (b"Z", b"X")
    except (OSError, IndexError):  # no /proc (not Linux): kill's answer stands
        return True


_HELD: dict[str, list] = {}  # absolute lock path -> [fd, holds] of the locks this process holds


def output_lock(output, command: str = "") -> "FileLock":
    """The lock that guards writing ``output``: ``.NAME.lock`` beside it (not yet taken); for a
    path without a name of its own (``.``, ``""``, ``dir/..``), beside the folder it names."""
    output = Path(output)
    if output.name in ("", ".", ".."):
        output = Path(os.path.abspath(output))
    if not output.name:
        raise TorchspliceError(f"{output}: the file system's root cannot be written to; name a file or folder")
    return FileLock(output.with_name(f".{output.name}.lock"), str(output), command)


class FileLock:
    """``with FileLock(path, what):`` holds ``path`` for this process (``what`` names the guarded output).

    Re-entrant within a process: a second :class:`FileLock` on a path this process already
    holds shares the hold (a job that locks its output, then writes it through
    :class:`~torchsplice.store.database.MotionDatabase`, which locks it too).
    """

    def __init__(self, path: Path, what: str, command: str = ""):
        self.path, self.what, self.command = Path(path), what, command
        self.fd: int | None = None
        self._key = os.path.abspath(self.path)

    @property
    def held(self) -> bool:
        return self.fd is not None

    def holder(self) -> dict | None:
        """What the lock file says of its holder (``None``: no readable lock)."""
        try:
            return json.loads(self.path.read_text() or "null")
        except (OSError, ValueError):
            return None

    @staticmethod
    def stale(holder: dict) -> bool:
        """Whether ``holder`` is a dead process of this host."""
        return holder.get("host") == socket.gethostname() and not pid_alive(int(holder.get("pid", -1)))

    def _refuse(self, holder: dict | None) -> None:
        h = holder or {}
        raise LockedError(
            f"{self.what} is being written by process {h.get('pid', '?')} on {h.get('host', '?')} "
            f"since {h.get('started', '?')} (lock {self.path}); wait for it to finish, or stop it"
        )

    def acquire(self) -> "FileLock":
        if self.fd is not None:
            return self
        held = _HELD.get(self._key)
        if held is not None:
            held[1] += 1
            self.fd = held[0]
            return self
        for _ in range(20):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o644)
            except OSError as exc:
                raise TorchspliceError(f"{self.path}: cannot take the lock: {exc.strerror or exc}") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                os.close(fd)
                self._refuse(self.holder())
            try:
                if os.fstat(fd).st_ino != os.stat(self.path).st_ino:  # removed and made anew meanwhile: again
                    os.close(fd)
                    continue
            except FileNotFoundError:
                os.close(fd)
                continue
            holder = self.holder()
            if holder and holder.get("host") != socket.gethostname():
                os.close(fd)
                self._refuse(holder)  # flock may not reach across hosts: trust the other host's word
            if holder and not self.stale(holder) and holder.get("pid") != os.getpid():
                os.close(fd)
                self._refuse(holder)  # a live holder that took no flock (an older torchsplice)
            me = {
                "host": socket.gethostname(),
                "pid": os.getpid(),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "command": self.command,
            }
            os.ftruncate(fd, 0)
            os.pwrite(fd, json.dumps(me).encode(), 0)
            self.fd = fd
            _HELD[self._key] = [fd, 1]
            return self
        raise LockedError(f"{self.what}: the lock {self.path} keeps changing; is another job starting?")

    def release(self) -> None:
        if self.fd is not None:
            held = _HELD.get(self._key)
            if held is not None and held[1] > 1:
                held[1] -= 1
                self.fd = None
                return
            _HELD.pop(self._key, None)
            try:
                self.path.unlink(missing_ok=True)  # while still held: a waiter then finds a new file
            finally:
                os.close(self.fd)
                self.fd = None

    def __enter__(self) -> "FileLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
