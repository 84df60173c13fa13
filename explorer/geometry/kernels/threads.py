"""The number of threads the compiled kernels use."""

from __future__ import annotations

from explorer._numba import NUMBA_AVAILABLE, numba


def set_threads(n: int | None) -> int:
    """Set numba's thread count (``None``: leave it); returns the count in use (1 without numba)."""
    if not NUMBA_AVAILABLE:
        return 1
    if n is not None:
        numba.set_num_threads(int(n))
    return int(numba.get_num_threads())
