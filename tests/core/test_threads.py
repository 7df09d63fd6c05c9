"""Work shared over threads (torchsplice.core.threads): chunks that cover every item once, in
order, of about equal weight; every chunk run, in threads, and a failure raised after all end."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

from torchsplice.core.threads import run_in_threads, split_by_weight


@pytest.mark.parametrize("parts", [1, 2, 3, 5, 40])
def test_chunks_cover_each_item_once_in_order_and_about_equally(parts):
    rng = np.random.default_rng(parts)
    weights = rng.integers(1, 300, size=23)
    chunks = split_by_weight(weights, parts)
    assert np.array_equal(np.concatenate(chunks), np.arange(23))
    assert 0 < len(chunks) <= min(parts, 23) and all(len(c) for c in chunks)
    if parts <= 3:  # each within one item of the even share
        share = weights.sum() / parts
        assert all(abs(weights[c].sum() - share) <= weights.max() for c in chunks)


def test_chunks_of_no_items_zero_weights_and_one_heavy_item():
    assert split_by_weight([], 4) == []
    zero = split_by_weight(np.zeros(6), 3)
    assert [c.tolist() for c in zero] == [[0, 1], [2, 3], [4, 5]]
    heavy = split_by_weight([1, 1000, 1, 1], 2)
    assert np.array_equal(np.concatenate(heavy), np.arange(4)) and heavy[0].tolist() == [0, 1]


@pytest.mark.parametrize("chunks, threads", [(4, 4), (4, 2), (2, 4), (7, 3)])
def test_every_chunk_runs_once_on_the_caller_and_the_pool_threads_at_once(chunks, threads):
    seen, names = [], set()
    lock = threading.Lock()
    inside = [threading.Barrier(min(chunks, threads), timeout=10)]  # every thread asked for runs a chunk at once

    def work(chunk):
        with lock:
            seen.extend(chunk.tolist())
            first = threading.current_thread().name not in names
            names.add(threading.current_thread().name)
        if first and inside:
            inside[0].wait()

    run_in_threads(work, split_by_weight(np.ones(10), chunks), threads=threads)
    assert sorted(seen) == list(range(10))
    caller = threading.current_thread().name
    assert caller in names and len(names) == min(chunks, threads)
    assert all(n.startswith("torchsplice") for n in names - {caller})
    names.clear()
    inside.clear()
    run_in_threads(work, split_by_weight(np.ones(10), chunks), threads=1)  # one thread: the caller's
    assert names == {caller}


def test_a_failure_is_raised_after_every_chunk_has_run():
    ran = []

    def work(chunk):
        ran.append(int(chunk[0]))
        if chunk[0] == 0:
            raise ValueError("chunk 0")

    with pytest.raises(ValueError, match="chunk 0"):
        run_in_threads(work, split_by_weight(np.ones(4), 4), threads=2)
    assert sorted(ran) == [0, 1, 2, 3]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork: POSIX only")
def test_a_forked_child_makes_its_own_pool():
    run_in_threads(lambda c: None, split_by_weight(np.ones(4), 2), threads=2)  # the parent's pool
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: the parent's pool threads are gone, a new pool runs the chunks
        try:
            out = []
            run_in_threads(lambda c: out.append(len(c)), split_by_weight(np.ones(6), 2), threads=2)
            os.write(w, str(sum(out)).encode())
        finally:
            os._exit(0)
    os.close(w)
    os.waitpid(pid, 0)
    assert os.read(r, 16) == b"6"

