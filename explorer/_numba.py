"""numba, or stand-ins when it is missing or disabled (``EXPLORER_DISABLE_NUMBA=1``): the compiled
kernels of the package import ``njit``/``prange`` from here and check :data:`NUMBA_AVAILABLE` to pick
their numpy fallbacks."""

from __future__ import annotations

import os
from typing import Any

_DISABLED = os.environ.get("EXPLORER_DISABLE_NUMBA", "").strip() not in ("", "0")
# Typed Any: the kernels are called with numpy arrays and tuples that numba's own annotations do not describe.
numba: Any
njit: Any
prange: Any
overload: Any
try:
    if _DISABLED:
        raise ImportError("numba disabled by EXPLORER_DISABLE_NUMBA")
    import numba as _numba_module
    from numba.extending import overload as _numba_overload

    numba, njit, prange, overload = _numba_module, _numba_module.njit, _numba_module.prange, _numba_overload
    NUMBA_AVAILABLE = True
except ImportError:  # pragma: no cover - exercised only without numba
    numba = None
    overload = None
    NUMBA_AVAILABLE = False
    prange = range

    def _identity_njit(*args: Any, **kwargs: Any) -> Any:
        """Identity decorator when numba is missing (``@njit`` and ``@njit(...)`` forms)."""
        if args and callable(args[0]):
            return args[0]
        return lambda f: f

    njit = _identity_njit


__all__ = ["NUMBA_AVAILABLE", "njit", "numba", "overload", "prange"]


def serial_twin(fn: Any) -> Any:
    """A copy of the Python function ``fn`` under its own name, to compile a second (serial) variant.

    numba's on-disk cache is keyed by the function's module, qualified name and first line, not by the
    compile options: ``njit(parallel=True, cache=True)(f)`` and ``njit(parallel=False, cache=True)(f)`` share
    one cache index, and whichever variant was compiled first is what the other one loads from then on (a
    "parallel" loop that runs on one thread). The twin has its own cache entry.
    """
    import types

    twin = types.FunctionType(fn.__code__, fn.__globals__, f"{fn.__name__}_serial", fn.__defaults__, fn.__closure__)
    twin.__qualname__ = f"{fn.__qualname__}_serial"
    twin.__module__ = fn.__module__
    twin.__doc__ = fn.__doc__
    return twin


__all__ += ["serial_twin"]


def kernel(**options: Any) -> Any:
    """Decorator: compile with the package's kernel options, or leave the function as it is without numba.

    Every kernel is cached on disk (``cache=True``), keeps IEEE semantics (``fastmath=False``) and numpy's
    error model (a division by zero gives inf/NaN, which the kernels test, not an exception); ``options`` adds
    to them (``inline="always"``, ``parallel=True``, ``nogil=True``).  Without numba the function runs
    interpreted: the same operations, slowly.
    """
    if not NUMBA_AVAILABLE:
        return lambda fn: fn
    return njit(cache=True, fastmath=False, error_model="numpy", **options)


__all__ += ["kernel"]


def kernel_array(a: Any, dtype: Any = None) -> Any:
    """``a`` as the one array type the kernels are compiled and cached for: C-contiguous, aligned, writable, of
    ``dtype`` (default float64); a copy only when ``a`` is not already that.

    numba compiles one machine-code variant per argument type, and a read-only array (a ``np.broadcast_to`` view,
    a read-only memory map) or a non-contiguous one is another type than the writable C array the warm-up
    compiled: passing it would compile (and cache) the kernel again on a user's first run.
    """
    import numpy as np

    arr = np.asarray(a, dtype=np.float64 if dtype is None else dtype)
    if arr.flags.c_contiguous and arr.flags.aligned and arr.flags.writeable:
        return arr
    return np.array(arr, order="C", copy=True)


__all__ += ["kernel_array"]


def prepare_kernel_loads() -> None:
    """Do now the one-off work of a process's first cached-kernel load (nothing without numba).

    Loading a kernel from numba's on-disk cache first refreshes numba's CPU target context; the first refresh in a
    process imports numba's lowering implementations and starts its runtime: 0.1-0.3 s of CPU that
    ``_focal_plane_loop_serial`` (or whichever kernel comes first) seemed to cost, later loads 4-50 ms each.  A
    process that waits for its work (the export's sweep worker waits ~0.7 s for the sensor) does it in that wait
    rather than in its first job.  Nothing else changes: the same refresh, made earlier.

    The refresh is numba's own internal (``numba.core.registry.cpu_target``, numba pinned in requirements/lock.txt):
    where another numba lacks it, nothing is done here and the first kernel load does that work as before.
    """
    if not NUMBA_AVAILABLE:
        return
    try:
        from numba.core.registry import cpu_target

        refresh = cpu_target.target_context.refresh
    except (ImportError, AttributeError):  # another numba's internals: an optimisation only, left out
        return
    refresh()
