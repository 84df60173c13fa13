"""explorer._threads: parts cover every point once, aligned to the kernel's blocks, whatever the thread count."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from explorer import _threads


@pytest.mark.parametrize("threads", [1, 2, 3])
@pytest.mark.parametrize("n", [0, 1, 511, 512, 9_999, 10_000, 100_000, 100_003])
def test_parts_cover_each_point_once_and_align(monkeypatch, threads, n):
    monkeypatch.setattr(_threads, "n_threads", lambda: threads)
    seen = np.zeros(n, np.int64)
    slices = []
    lock = threading.Lock()

    def run(sl: slice) -> None:
        with lock:
            slices.append(sl)
        seen[sl] += 1

    _threads.run_in_parts(run, n, align=512, min_points=10_000)
    assert np.all(seen == 1)
    assert len(slices) == max(1, min(threads, n // 10_000))
    for sl in sorted(slices, key=lambda s: s.start)[:-1]:
        assert sl.start % 512 == 0 and sl.stop % 512 == 0


def test_part_errors_reach_the_caller(monkeypatch):
    monkeypatch.setattr(_threads, "n_threads", lambda: 2)

    def run(sl: slice) -> None:
        if sl.start > 0:
            raise ValueError("second part failed")

    with pytest.raises(ValueError, match="second part failed"):
        _threads.run_in_parts(run, 50_000, align=512, min_points=10_000)


def test_forked_child_gets_a_working_pool(monkeypatch):
    """A process forked after the pool started (multiprocessing, Dask) must not wait for threads it lacks."""
    import multiprocessing as mp

    monkeypatch.setattr(_threads, "n_threads", lambda: 2)
    _threads.run_in_parts(lambda sl: None, 50_000, align=512, min_points=10_000)  # the pool exists now

    def child(queue) -> None:
        seen = np.zeros(50_000, np.int64)

        def run(sl: slice) -> None:
            seen[sl] += 1

        _threads.run_in_parts(run, 50_000, align=512, min_points=10_000)
        queue.put(int(seen.sum()))

    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    proc = ctx.Process(target=child, args=(queue,))
    proc.start()
    proc.join(60)
    assert proc.exitcode == 0
    assert queue.get(timeout=5) == 50_000
