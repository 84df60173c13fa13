"""Errors raised by the model layer: each names the problem and the offending input."""

from __future__ import annotations

import numpy as np


class InputError(ValueError):
    """Bad numeric input: wrong shape, NaN or infinite values."""


class SceneFileError(ValueError):
    """A scene or preset file that is malformed or misses a required field."""


class ConvergenceError(RuntimeError):
    """An iterative solver that did not converge for some points."""


class NotFittedError(RuntimeError):
    """A learned method asked to predict before ``fit`` was called."""


def as_points(ground: np.ndarray, name: str = "ground") -> np.ndarray:
    """Validate ground coordinates and return them as float64 of shape (N, 3).

    Parameters
    ----------
    ground : array_like, shape (N, 3) or (3,)
        Points in the local ENU frame, metres.
    name : str
        Argument name used in error messages.

    Raises
    ------
    InputError
        If the shape is not (N, 3) or any value is NaN or infinite.
    """
    arr = np.asarray(ground, dtype=np.float64)
    if arr.ndim == 1 and arr.shape[0] == 3:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"{name} must have shape (N, 3), got {arr.shape}")
    check_finite(arr, name)
    return arr


def check_finite(values: np.ndarray, name: str) -> np.ndarray:
    """Raise :class:`InputError` naming ``name`` and the first bad index if any value is not finite."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.size and np.isfinite(np.add.reduce(arr, axis=None)):
        return arr  # a NaN or an infinity makes the sum non-finite; the element check runs otherwise
    bad = ~np.isfinite(arr)
    if bad.any():
        first = tuple(int(v) for v in np.argwhere(bad)[0])
        raise InputError(
            f"{name} contains {int(bad.sum())} NaN/infinite value(s); first at index {first}"
        )
    return arr
