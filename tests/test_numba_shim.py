"""numba's on-disk cache: no two compiled variants share a cache entry (explorer/_numba.py)."""

from __future__ import annotations

import importlib
import pkgutil

import pytest

import explorer
from explorer._numba import NUMBA_AVAILABLE, njit, serial_twin


def _dispatchers():
    from numba.core.registry import CPUDispatcher

    for info in pkgutil.walk_packages(explorer.__path__, "explorer."):
        if info.name.startswith(("explorer.app", "explorer.notebook", "explorer.commands", "explorer.__main__")):
            continue
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if isinstance(obj, CPUDispatcher) and getattr(obj, "__module__", None) == module.__name__:
                yield f"{module.__name__}.{name}", obj


@pytest.mark.skipif(not NUMBA_AVAILABLE, reason="numba missing")
def test_no_two_cached_kernels_share_a_cache_entry():
    """Two dispatchers of one Python function (a parallel and a serial loop) would load each other's code."""
    seen: dict[tuple, str] = {}
    clashes = []
    for label, disp in _dispatchers():
        fn = disp.py_func
        key = (fn.__module__, fn.__qualname__, fn.__code__.co_firstlineno)
        options = tuple(sorted((k, str(v)) for k, v in disp.targetoptions.items()))
        if key in seen and seen[key][1] != options:
            clashes.append((seen[key][0], label))
        seen.setdefault(key, (label, options))
    assert not clashes, f"compiled variants sharing a cache entry: {clashes}"


@pytest.mark.skipif(not NUMBA_AVAILABLE, reason="numba missing")
def test_serial_twin_compiles_to_the_same_results_with_its_own_cache_entry():
    import numpy as np

    def body(x):
        out = np.empty_like(x)
        for i in range(x.shape[0]):
            out[i] = x[i] * x[i] + 1.0
        return out

    twin = serial_twin(body)
    assert twin.__qualname__ != body.__qualname__ and twin.__code__ is body.__code__
    x = np.linspace(-2.0, 2.0, 11)
    np.testing.assert_array_equal(njit(body)(x), njit(twin)(x))
    np.testing.assert_array_equal(njit(twin)(x), x * x + 1.0)
