"""numba, or stand-ins when it is missing or disabled (``EXPLORER_DISABLE_NUMBA=1``): the compiled
kernels of the package import ``njit``/``prange`` from here and check :data:`NUMBA_AVAILABLE` to pick
their numpy fallbacks."""

from __future__ import annotations

import os

_DISABLED = os.environ.get("EXPLORER_DISABLE_NUMBA", "").strip() not in ("", "0")
try:
    if _DISABLED:
        raise ImportError("numba disabled by EXPLORER_DISABLE_NUMBA")
    import numba
    from numba import njit, prange
    from numba.extending import overload

    NUMBA_AVAILABLE = True
except ImportError:  # pragma: no cover - exercised only without numba
    numba = None
    overload = None
    NUMBA_AVAILABLE = False
    prange = range

    def njit(*args, **kwargs):  # noqa: D103 - identity decorator when numba is missing
        if args and callable(args[0]):
            return args[0]
        return lambda f: f


__all__ = ["NUMBA_AVAILABLE", "njit", "numba", "overload", "prange"]
