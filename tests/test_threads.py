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


def test_blas_threads_sets_openblas_to_one_thread_and_restores_it_nested_and_across_threads():
    before = _threads.blas_thread_count()
    if before is None:
        pytest.skip("numpy's BLAS is not an OpenBLAS found in this process")
    with _threads.blas_threads(1):
        assert _threads.blas_thread_count() == 1
        with _threads.blas_threads(1):
            assert _threads.blas_thread_count() == 1
        assert _threads.blas_thread_count() == 1  # the inner block does not restore while the outer runs
        seen = []
        worker = threading.Thread(target=lambda: seen.append(_threads.blas_thread_count()))
        worker.start()
        worker.join()
        assert seen == [1]  # process-wide: the setting OpenBLAS's own getter reports
    assert _threads.blas_thread_count() == before
    with pytest.raises(RuntimeError), _threads.blas_threads(1):
        raise RuntimeError("restored on error too")
    assert _threads.blas_thread_count() == before
