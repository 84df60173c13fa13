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


_EVERY_OPENBLAS = r"""
import ctypes, glob, os, sys
import scipy.linalg  # scipy's own OpenBLAS loaded (and listed in the process's maps) before numpy's is looked up
import numpy as np
from explorer import _threads

def counts(set_to=None):
    out = {}
    for pkg in ("numpy", "scipy"):
        mod = sys.modules[pkg]
        for path in glob.glob(os.path.join(os.path.dirname(mod.__file__), os.pardir, pkg + ".libs", "*openblas*")):
            lib = ctypes.CDLL(path)
            for suffix in ("64_", ""):
                get = getattr(lib, "scipy_openblas_get_num_threads" + suffix, None)
                if get is not None:
                    if set_to is not None:
                        getattr(lib, "scipy_openblas_set_num_threads" + suffix)(ctypes.c_int(set_to))
                    get.restype = ctypes.c_int
                    out[pkg] = get()
                    break
    return out

before = counts(set_to=2)
with _threads.blas_threads(1):
    inside = counts()
print(before, inside, counts())
"""


def test_blas_threads_sets_numpys_and_scipys_openblas_when_scipy_was_imported_first():
    """numpy and scipy bundle one OpenBLAS each; with scipy imported first only scipy's was set (numpy's lstsq kept
    its threads: nn-rfm's fits 2x the CPU at load 4).  Read back from each package's own library file."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _EVERY_OPENBLAS], capture_output=True, text=True, timeout=120,
                         check=True).stdout
    before, inside, after = (eval(part) for part in out.strip().replace("} {", "}|{").split("|"))
    if "numpy" not in before or before["numpy"] < 2:
        pytest.skip(f"numpy's OpenBLAS not found or on one thread here: {before}")
    assert inside["numpy"] == 1
    if "scipy" in inside:
        assert inside["scipy"] == 1
    assert after == before


_SCIPY_LOADED_INSIDE = r"""
import ctypes, glob, os, sys
import numpy as np
from explorer import _threads
assert "scipy.linalg" not in sys.modules

def scipy_count():
    import importlib.util
    base = list(importlib.util.find_spec("scipy").submodule_search_locations)[0]
    for path in glob.glob(os.path.join(base, os.pardir, "scipy.libs", "*openblas*")):
        lib = ctypes.CDLL(path)
        get = getattr(lib, "scipy_openblas_get_num_threads", None)
        if get is not None:
            get.restype = ctypes.c_int
            return get()
    return None

with _threads.blas_threads(1):
    import scipy.linalg.cython_blas  # what numba's np.dot does at its first call: scipy's OpenBLAS loaded now
    inside = scipy_count()
print(inside, scipy_count(), os.cpu_count())
"""


def test_blas_threads_also_sets_scipys_openblas_loaded_inside_the_block():
    """numba's compiled np.dot loads scipy's OpenBLAS (scipy.linalg.cython_blas) at its first call, which may come
    inside a blas_threads block (a network's training): it must run on the block's threads too.  Missed, the mlp
    sweep at 1,000 SCOPs gave other last bits in the export's worker (scipy imported first) than in the command
    (the training loaded it): a shared export differed from a serial one."""
    import os
    import subprocess
    import sys

    # OpenBLAS starts on the threads OPENBLAS_NUM_THREADS names (else on what it finds: one thread in a CI run,
    # where the test then proved nothing): two, so that one thread inside the block is the block's doing
    env = dict(os.environ, OPENBLAS_NUM_THREADS="2")
    out = subprocess.run([sys.executable, "-c", _SCIPY_LOADED_INSIDE], capture_output=True, text=True, timeout=120,
                         check=True, env=env).stdout.split()
    inside, after, cpus = (None if v == "None" else int(v) for v in out)
    if inside is None:
        pytest.skip("scipy's bundled OpenBLAS not found")
    if after is None or after < 2:
        pytest.skip(f"scipy's OpenBLAS runs on {after} thread(s) here (one CPU?): nothing to limit")
    assert inside == 1
    assert after >= 2  # restored after the block
