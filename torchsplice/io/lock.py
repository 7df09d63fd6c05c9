"""Exclusive locks on outputs: one writer at a time, stale locks taken over.

A lock is a small JSON file (``host``, ``pid``, ``started``, ``command``) created with
``O_EXCL`` beside what it guards. A second writer is refused at once with one line naming the
holder. A lock whose process is gone (same host, PID not alive) is stale and taken over; a
lock held from another host is never broken (its process cannot be checked from here).
"""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path

from ..core.errors import TorchspliceError

__all__ = ["FileLock", "LockedError", "host_pid", "pid_alive"]


class LockedError(TorchspliceError):
    """Someone else holds the lock."""


def host_pid() -> str:
    """``HOST-PID``: what temporary names of this process carry."""
    return f"{socket.gethostname()}-{os.getpid()}"


def pid_alive(pid: int) -> bool:
    """Whether a process with this PID exists on this host."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class FileLock:
    """``with FileLock(path, what):`` holds ``path`` for this process (``what`` names the guarded output)."""

    def __init__(self, path: Path, what: str, command: str = ""):
        self.path, self.what, self.command = Path(path), what, command
        self.held = False

    def acquire(self) -> "FileLock":
        me = {"host": socket.gethostname(), "pid": os.getpid(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
              "command": self.command}
        for _ in range(3):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                holder = self._holder()
                if holder is not None and self._stale(holder):
                    self.path.unlink(missing_ok=True)  # its process is gone: take it over
                    continue
                if holder is None:  # being written this instant, or unreadable: look again
                    time.sleep(0.05)
                    continue
                raise LockedError(f"{self.what} is being written by process {holder.get('pid')} on "
                                  f"{holder.get('host')} since {holder.get('started')} (lock {self.path}); "
                                  "wait for it to finish, or stop it") from None
            except OSError as exc:
                raise TorchspliceError(f"{self.path}: cannot take the lock: {exc.strerror or exc}") from None
            with os.fdopen(fd, "w") as f:
                json.dump(me, f)
            self.held = True
            return self
        raise LockedError(f"{self.what}: the lock {self.path} is unreadable; remove it if no job is running")

    def _holder(self) -> dict | None:
        try:
            return json.loads(self.path.read_text() or "null")
        except (OSError, ValueError):
            return None

    @staticmethod
    def _stale(holder: dict) -> bool:
        return holder.get("host") == socket.gethostname() and not pid_alive(int(holder.get("pid", -1)))

    def release(self) -> None:
        if self.held:
            holder = self._holder()
            if holder is not None and holder.get("pid") == os.getpid() and holder.get("host") == socket.gethostname():
                self.path.unlink(missing_ok=True)
            self.held = False

    def __enter__(self) -> "FileLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
