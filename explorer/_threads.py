"""Run a compiled serial loop over parts of the points on several threads.

numba's ``parallel=True`` outlines a ``prange`` loop into a gufunc whose inner loops LLVM optimises less well
(the RPC-on-DEM loop took 9.3 ms of CPU per 100,000 pixels on one thread against 7.1 ms for the same code
compiled serially), and its OpenMP threads spin while they wait, which doubles the CPU time on a machine
whose other core is busy.  A serial kernel compiled with ``nogil=True`` and called on contiguous parts of
the points from a small pool of Python threads has neither cost.

The parts start at multiples of ``align`` (the kernel's block of points), so that every point is computed
in the same block -- with the same neighbours -- whatever the number of threads: the results are the same to
the bit on any machine.
"""

from __future__ import annotations

import contextlib
import ctypes
import glob
import os
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor

__all__ = ["blas_thread_count", "blas_threads", "cpus_available", "n_threads", "run_in_parts"]

_POOL: ThreadPoolExecutor | None = None


def cpus_available() -> int:
    """CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def n_threads() -> int:
    """Threads to use: numba's thread count (``NUMBA_NUM_THREADS``), else the CPUs this process may use."""
    try:
        import numba

        return max(1, int(numba.get_num_threads()))
    except ImportError:  # pragma: no cover - numba missing
        return max(1, cpus_available())


def _forget_pool() -> None:
    """In a forked child the pool's threads do not exist: start a new pool there."""
    global _POOL
    _POOL = None


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def _pool() -> ThreadPoolExecutor:
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=max(1, n_threads() - 1), thread_name_prefix="explorer-part")
    return _POOL


def run_in_parts(run: Callable[[slice], None], n: int, *, align: int, min_points: int) -> None:
    """Call ``run(part)`` on contiguous slices covering ``range(n)``, concurrently.

    Parameters
    ----------
    run : callable
        Processes the points of one slice (a kernel compiled with ``nogil=True``, so that the threads overlap).
    n : int
        Number of points.
    align : int
        Every slice but the last starts and ends at a multiple of this.
    min_points : int
        Fewer points than this run in the calling thread alone (waking another costs more than it saves).
    """
    parts = min(n_threads(), max(1, n // max(1, min_points)))
    if parts <= 1:
        run(slice(0, n))
        return
    step = -(-n // parts)
    step = -(-step // align) * align
    bounds = [(start, min(start + step, n)) for start in range(0, n, step)]
    futures = [_pool().submit(run, slice(a, b)) for a, b in bounds[1:]]
    run(slice(*bounds[0]))  # the calling thread takes the first part
    for future in futures:
        future.result()


# ----------------------------------------------------------------------------- BLAS threads
#: The OpenBLAS thread setters and getters numpy's wheels export (scipy-openblas, 64-bit or 32-bit integers, or a
#: system OpenBLAS); in each loaded OpenBLAS library the first pair found is used.
_OPENBLAS_SYMBOLS = (("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
                     ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),
                     ("openblas_set_num_threads64_", "openblas_get_num_threads64_"),
                     ("openblas_set_num_threads", "openblas_get_num_threads"))
_BLAS_LOCK = threading.Lock()
_blas_state: dict = {"apis": None, "modules": -1, "depth": 0, "saved": None}


def _openblas_libraries() -> list[str]:
    """Paths of the OpenBLAS libraries this process has loaded (Linux: /proc/self/maps), then numpy's and scipy's
    bundled ones even when not loaded yet.

    scipy's is loaded late: numba's compiled ``np.dot`` takes its BLAS from ``scipy.linalg.cython_blas`` at its first
    call, which can come inside a :func:`blas_threads` block (a network's training).  Missed there, that library
    kept its threads for the block: the same training gave other bits in a process where scipy.linalg had been
    imported before it (the export's sweep worker) than in one where the training loaded it -- the mlp sweep at
    1,000 SCOPs differed in its 12th digit between a serial export and one shared with the worker.  Opened here by
    path (the loader keeps one copy of a library), it is set before anything uses it."""
    import importlib.util

    import numpy as np

    paths: list[str] = []
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                path = line.split(maxsplit=5)[-1].strip()
                if "openblas" in os.path.basename(path).lower() and path not in paths:
                    paths.append(path)
    except OSError:
        pass
    bundled = [os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs")]
    scipy_spec = importlib.util.find_spec("scipy")  # located, not imported
    if scipy_spec is not None and scipy_spec.submodule_search_locations:
        bundled.append(os.path.join(list(scipy_spec.submodule_search_locations)[0], os.pardir, "scipy.libs"))
    for libs_dir in bundled:
        paths += [p for p in sorted(glob.glob(os.path.join(libs_dir, "*openblas*"))) if p not in paths]
    return paths


def _openblas_apis() -> list[tuple[Callable[[int], None], Callable[[], int]]]:
    """(set, get) of the thread count of every OpenBLAS loaded in the process, numpy's first ([] when none is
    found).  numpy and scipy each bundle their own OpenBLAS (scipy-openblas64 and scipy-openblas32): setting only
    the first library found -- scipy's, when scipy was imported first -- left numpy's on its threads."""
    import sys

    apis = _blas_state["apis"]
    if apis is not None and (_blas_state["depth"] or _blas_state["modules"] == len(sys.modules)):
        return apis  # looked since the last import (a library is loaded by an import), or inside a block
    import numpy as np

    numpy_libs = os.path.realpath(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs"))
    found: dict[str, tuple[Callable[[int], None], Callable[[], int]]] = {}
    for path in _openblas_libraries():
        real = os.path.realpath(path)
        if real in found:
            continue
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for set_name, get_name in _OPENBLAS_SYMBOLS:
            setter, getter = getattr(lib, set_name, None), getattr(lib, get_name, None)
            if setter is not None and getter is not None:
                setter.argtypes, setter.restype = [ctypes.c_int], None
                getter.argtypes, getter.restype = [], ctypes.c_int
                found[real] = (setter, getter)
                break
    order = sorted(found, key=lambda real: not real.startswith(numpy_libs + os.sep))  # numpy's first (stable)
    apis = [found[real] for real in order]
    _blas_state["apis"], _blas_state["modules"] = apis, len(sys.modules)
    return apis


def _openblas_api() -> tuple[Callable[[int], None], Callable[[], int]] | None:
    """(set, get) of numpy's OpenBLAS thread count, or None when numpy does not use an OpenBLAS found here."""
    apis = _openblas_apis()
    return apis[0] if apis else None


def blas_thread_count() -> int | None:
    """numpy's OpenBLAS thread count now (None when it is not found)."""
    with _BLAS_LOCK:
        api = _openblas_api()
        return None if api is None else int(api[1]())


@contextlib.contextmanager
def blas_threads(n: int = 1) -> Iterator[None]:
    """Run numpy's and scipy's linear algebra (every OpenBLAS loaded) on ``n`` threads inside the block, then
    restore the setting.

    Many small least-squares solves (a few hundred rows, tens of columns) are where OpenBLAS's threads cost more
    than they give: on the shared 2-core machine (load 12-17) the 760 solves of ``ogp``'s genetic term selection
    on 700 x 21 designs took 4.3 s with OpenBLAS's 2 threads and 0.17 s with one.  The setting is process-wide:
    nested and concurrent blocks share it (the first sets it, the last out restores it).  A no-op when no
    OpenBLAS is found in the process (then nothing is changed).
    """
    with _BLAS_LOCK:
        apis = _openblas_apis()
        if apis:
            if _blas_state["depth"] == 0:
                _blas_state["saved"] = [int(get()) for _, get in apis]
                for setter, _ in apis:
                    setter(max(1, int(n)))
            _blas_state["depth"] += 1
    try:
        yield
    finally:
        if apis:
            with _BLAS_LOCK:
                _blas_state["depth"] -= 1
                if _blas_state["depth"] == 0:
                    for (setter, _), saved in zip(apis, _blas_state["saved"], strict=True):
                        setter(int(saved))
