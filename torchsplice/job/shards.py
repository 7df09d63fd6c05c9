"""Slices of a job (``--shard K/N``) and the shards of a virtual output: where a run's shards
live (:func:`run_shards`), how they are installed beside the output in one atomic rename each,
and removed once no output reads them."""

from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path

from ..core.errors import TorchspliceError
from ..store.lock import FileLock
from .config import JobConfig
from .plan import Plan

__all__ = ["run_shards", "install_shards", "remove_shard_files", "slice_tasks", "refuse_live_slices", "gaps", "ranges",
           "output_lock_path", "clear_work"]


def gaps(have: list[int], n: int) -> list[tuple[int, int]]:
    """The runs ``(first, last)`` of 1..n missing from the sorted ``have``."""
    out, nxt = [], 1
    for k in have + [n + 1]:
        if k > nxt:
            out.append((nxt, k - 1))
        nxt = max(nxt, k + 1)
    return out


def ranges(items, shown: int = 8) -> str:
    """Numbers (or ``(first, last)`` runs) as ``1-3, 5, 7-9``: at most ``shown`` runs, then a count."""
    runs = []
    for x in items:
        a, b = x if isinstance(x, tuple) else (x, x)
        if runs and runs[-1][1] + 1 == a:
            runs[-1] = (runs[-1][0], b)
        else:
            runs.append((a, b))
    text = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs[:shown])
    return text + (f" and {len(runs) - shown} more runs" if len(runs) > shown else "")


def slice_tasks(tasks: list, k: int, n: int) -> list:
    """The K-th of N contiguous slices of the tasks (1-based)."""
    return tasks[(k - 1) * len(tasks) // n: k * len(tasks) // n]


def refuse_live_slices(work: Path) -> None:
    """A whole run or a merge must not touch the work folder while a slice writes into it."""
    if not work.is_dir():
        return
    for lock in sorted(work.glob("lock-*-of-*")):
        holder = FileLock(lock, "").holder()
        if holder is not None and not FileLock.stale(holder):
            raise TorchspliceError(f"{work}: slice {lock.name[5:].replace('-of-', '/')} is still running (process "
                                   f"{holder.get('pid')} on {holder.get('host')}); wait for it to finish")


def run_shards(config: JobConfig, plan: Plan) -> Path:
    """Where a ``virtual`` output of ``plan`` keeps its shards: ``OUT.h5.shards/<plan digest>/``.
    Each run of other settings has its own folder, so that an output renamed away keeps reading
    its own frames, and replacing an output never touches the frames it reads until the new one
    is in place."""
    return config.shards_folder / plan.digest()[:16]


def install_shards(work: Path, folder: Path, names: list[str]) -> None:
    """Move a virtual output's shards from ``work`` into ``folder``, one atomic rename each. A
    shard already there (a rerun of an install that was cut short, or of the same plan, whose
    shards are the same bits) is replaced in place: at every moment every output that reads
    ``folder`` finds whole shards."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        src = work / name
        if src.exists():
            os.replace(src, folder / name)
        elif not (folder / name).exists():
            raise TorchspliceError(f"{folder}: shard {name} is missing, and the job's work folder has it no more; "
                                   "rerun the job with {restart}", options=("restart",))


def remove_shard_files(files, shards_folder: Path) -> None:
    """Delete shard files no output reads any more, then the folders of ``shards_folder`` they
    leave empty (the folder itself too)."""
    for f in files:
        if shards_folder.resolve() in f.parents:  # never a file outside the output's shards
            f.unlink(missing_ok=True)
    if shards_folder.is_dir():
        for sub in sorted((p for p in shards_folder.iterdir() if p.is_dir()), reverse=True):
            with contextlib.suppress(OSError):
                sub.rmdir()  # only when empty
        with contextlib.suppress(OSError):
            shards_folder.rmdir()


def output_lock_path(output: Path) -> Path:
    return output.with_name(f".{output.name}.lock")


def clear_work(work: Path, keep: Path) -> None:
    """Discard an unfinished run's plan and shards (not the lock just taken)."""
    for f in work.iterdir():
        if f != keep:
            shutil.rmtree(f, ignore_errors=True) if f.is_dir() else f.unlink(missing_ok=True)
