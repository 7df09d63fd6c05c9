"""Work shared out over threads of this process, for compiled kernels that release the GIL
(numba's ``nogil=True``): each thread runs the kernel on its own clips and writes its own rows of
preallocated outputs, so the result is the one thread's, bit for bit.

- :func:`split_by_weight`: contiguous chunks of items, each about the same total weight (frames);
- :func:`run_in_threads`: a function applied to each chunk, on this thread and a pool of this process.

The pool is made on first use and again in a forked child (threads do not survive a fork), so a
``DataLoader`` worker that asks for threads gets its own. Callers choose the count: a reader in a
worker process that shares the cores with its siblings asks for one (``torch.get_num_threads()``
is 1 there); a command that has the machine asks for
:func:`~torchsplice.job.defaults.usable_cores`.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Sequence

import numpy as np

__all__ = ["split_by_weight", "run_in_threads"]

_pool: ThreadPoolExecutor | None = None
_pool_key: tuple[int, int] = (0, 0)
_lock = threading.Lock()


def split_by_weight(weights, parts: int) -> list[np.ndarray]:
    """``(C,)`` weights -> at most ``parts`` int64 index arrays, contiguous and in order, that
    together hold ``0 .. C - 1`` once, each about ``weights.sum() / parts`` (no empty array)."""
    weights = np.asarray(weights, np.float64).reshape(-1)
    if len(weights) == 0:
        return []
    parts = max(1, min(int(parts), len(weights)))
    ends = np.cumsum(weights)
    total = float(ends[-1])
    cuts = (
        np.searchsorted(ends, total * np.arange(1, parts) / parts, side="left") + 1
        if total > 0
        else (np.arange(1, parts) * len(weights) // parts)
    )
    bounds = np.unique(np.concatenate(([0], np.minimum(cuts, len(weights)), [len(weights)])))
    return [np.arange(a, b, dtype=np.int64) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def _pool_of(threads: int) -> ThreadPoolExecutor:
    global _pool, _pool_key
    key = (os.getpid(), threads)
    with _lock:
        if _pool is None or _pool_key != key:
            if _pool is not None and _pool_key[0] == key[0]:
                _pool.shutdown(wait=False)
            _pool, _pool_key = ThreadPoolExecutor(threads, thread_name_prefix="torchsplice"), key
        return _pool


def run_in_threads(fn: Callable[[np.ndarray], None], chunks: Sequence[np.ndarray], threads: int) -> None:
    """``fn(chunk)`` for each chunk, on ``threads`` threads of this process: this one and
    ``threads - 1`` of a pool, each taking the next chunk not yet taken (in this thread alone when
    ``threads`` is 1 or there is one chunk; the caller works rather than waits, which saves a
    hand-over per call). The first exception a call raises, in the chunks' order, is raised here
    after every call has ended."""
    if threads <= 1 or len(chunks) <= 1:
        for c in chunks:
            fn(c)
        return
    todo = iter(range(len(chunks)))
    taking = threading.Lock()
    errors: list[BaseException | None] = [None] * len(chunks)

    def drain() -> None:
        while True:
            with taking:
                i = next(todo, None)
            if i is None:
                return
            try:
                fn(chunks[i])
            except BaseException as e:  # raised below, once every chunk has run
                errors[i] = e

    helpers = [_pool_of(threads - 1).submit(drain) for _ in range(min(threads, len(chunks)) - 1)]
    drain()
    for h in helpers:
        h.result()
    for e in errors:
        if e is not None:
            raise e
