"""Errors raised by the model layer: each names the problem and the offending input."""

from __future__ import annotations

import numpy as np


class ExplorerError(Exception):
    """Base of every error the package raises on purpose (bad input, bad file, no convergence).

    The command line turns any of them into one line on stderr and exit status 2; anything else is a bug.
    """


class InputError(ExplorerError, ValueError):
    """Bad numeric input: wrong shape, NaN or infinite values, a value out of its range."""


class SceneFileError(ExplorerError, ValueError):
    """A scene, preset or data file that is malformed, unreadable or misses a required field."""


class ConvergenceError(ExplorerError, RuntimeError):
    """An iterative solver that did not converge for some points."""


class MethodUnavailableError(ExplorerError, ValueError):
    """A method that cannot run on this sensor by what the sensor declares (no line geometry, ...); the bench
    and the explorer skip it with this reason and go on."""


class NotFittedError(ExplorerError, RuntimeError):
    """A learned method asked to predict before ``fit`` was called."""


class UnknownNameError(ExplorerError, KeyError):
    """An unknown name (preset, method, scene kind); the message suggests the closest known names.

    Parameters
    ----------
    kind : str
        What was looked up, e.g. ``"preset"``.
    name : str
        The name given.
    known : sequence of str
        The valid names.
    """

    def __init__(self, kind: str, name: str, known) -> None:
        import difflib

        known = list(known)
        by_lower = {k.lower(): k for k in known}
        close = difflib.get_close_matches(str(name).lower(), list(by_lower), n=3, cutoff=0.5)
        hint = f"; did you mean {', '.join(repr(by_lower[c]) for c in close)}?" if close else ""
        self.message = f"unknown {kind} {name!r}{hint} (available: {', '.join(known)})"
        super().__init__(self.message)

    def __str__(self) -> str:  # KeyError would print the repr of the message
        return self.message


class OutputError(ExplorerError, OSError):
    """An output path that cannot be written (a directory, a missing folder, no permission)."""


class MissingExtraError(ExplorerError, ImportError):
    """A feature needs an optional dependency group (an extra) that is not installed.

    Parameters
    ----------
    feature : str
        What the user asked for, e.g. ``"the notebook widgets"``.
    extra : str
        The extra of ``pushbroom-explorer`` that provides it, e.g. ``"notebooks"``.
    module : str
        The module that failed to import.
    """

    def __init__(self, feature: str, extra: str, module: str) -> None:
        super().__init__(
            f"{feature} needs the optional dependency {module!r}: "
            f"pip install 'pushbroom-explorer[{extra}]'"
        )
        self.feature, self.extra, self.module = feature, extra, module


def require(module: str, feature: str, extra: str):
    """Import ``module`` for ``feature`` or raise :class:`MissingExtraError` naming the extra to install.

    Returns
    -------
    module
        The imported module.
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingExtraError(feature, extra, module) from exc


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
