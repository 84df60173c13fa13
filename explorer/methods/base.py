"""The best-scanline method interface and registry.

Every method is a class registered by name (``@register``), constructed on a sensor
(:class:`explorer.sensor.Sensor`: a :class:`~explorer.scene.Scene`, a rigorous or CSM line-scan model, an
RPC), optionally ``fit`` on SCOPs, then asked ``ground_to_image(ground)`` for the scanline (fractional row),
the column, a validity mask and the number of collinearity evaluations spent.  The bench, CLI, explorer and
notebooks only use :func:`available` / :func:`create` / :func:`unavailable_reason`.

What a method needs from the sensor is declared on its class, never discovered by trying:
``needs_line_geometry`` (the search methods: the sensor's scanlines, :class:`explorer.sensor.LineGeometrySensor`;
on a sensor without them -- an RPC -- :func:`unavailable_reason` says why and :func:`create` refuses with
:class:`~explorer.errors.MethodUnavailableError`).  The learned and generalized methods need only ground / image
pairs; one that predicts only the row (``column_source = "collinearity"``) takes its column from the collinearity
at that row where the sensor has line geometry, else from a polynomial column model fitted on the same SCOPs
(:class:`explorer.methods._polynomial.PairColumnModel`; ``fit_info["column_model"]`` describes it).
Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import importlib
import pkgutil
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from explorer import _log
from explorer._threads import blas_threads
from explorer.errors import MethodUnavailableError, NotFittedError, UnknownNameError, as_points
from explorer.geometry.kernels import CollinearityParams, collinearity_params_or_none, columns_at_rows
from explorer.methods._compiled import inside_flags
from explorer.methods._polynomial import PairColumnModel
from explorer.points import PointSet
from explorer.scene import Scene
from explorer.sensor import has_line_coverage, has_line_geometry, rows_covered

_REGISTRY: dict[str, type[BestScanlineMethod]] = {}
_DISCOVERED = False
#: Method modules that failed to import during :func:`discover`: module name -> error.
DISCOVERY_ERRORS: dict[str, str] = {}


@dataclass
class ScanlineResult:
    """Output of :meth:`BestScanlineMethod.ground_to_image`.

    Attributes
    ----------
    row : ndarray, shape (N,)
        Best scanline as a fractional row (0-based, pixel centre); NaN where unknown.
    col : ndarray, shape (N,)
        Column at that scanline; NaN where unknown.
    converged : ndarray of bool, shape (N,)
        The method's own success flag (iteration converged / model applicable).
    inside : ndarray of bool, shape (N,)
        (row, col) lies on the image (pixel edges included).
    ce_evaluations : ndarray of int, shape (N,)
        Collinearity evaluations spent on each point (0 for purely learned methods).
    trace : list of ndarray (N,), optional
        Candidate rows visited per iteration, when requested (for the explorer).
    info : dict
        Method-specific extras (status counts, a learned model's domain ``in_domain`` ...).
    covered : ndarray of bool, shape (N,), optional
        False where the row is on a line the sensor's tables do not cover (a CSM camera whose tables stop
        mid-image, :class:`explorer.sensor.LineCoverageSensor`): the camera's own status 5, flagged in every
        method's result by :meth:`BestScanlineMethod.ground_to_image`.  None: every line is covered.
    """

    row: np.ndarray
    col: np.ndarray
    converged: np.ndarray
    inside: np.ndarray
    ce_evaluations: np.ndarray
    trace: list[np.ndarray] | None = None
    info: dict = field(default_factory=dict)
    covered: np.ndarray | None = None

    @property
    def valid(self) -> np.ndarray:
        """Converged, inside the image and on a covered line: the points whose (row, col) may be used."""
        ok = self.converged & self.inside
        return ok if self.covered is None else ok & self.covered

    def __len__(self) -> int:
        return int(self.row.shape[0])


class BestScanlineMethod(ABC):
    """Base class of all ground -> image (best scanline) methods.

    Subclasses set ``name`` (registry key), ``label`` (the paper's name),
    ``reference`` (citation), ``family`` ("search", "learned", "generalized"),
    ``needs_fit`` and implement :meth:`_locate`.

    Parameters
    ----------
    scene : Scene
    **params
        Method-specific parameters (documented per class).
    """

    name: ClassVar[str] = ""
    label: ClassVar[str] = ""
    reference: ClassVar[str] = ""
    family: ClassVar[str] = "search"
    needs_fit: ClassVar[bool] = False
    # the fit is a long iterative training (a network trained by Levenberg-Marquardt, a genetic search: up to
    # seconds): the explorer starts it once the first maps of the other methods are on screen, so it never delays
    # them (it shows its progress meanwhile)
    long_fit: ClassVar[bool] = False
    exactness: ClassVar[str] = "exact"  # "exact", "pixel" or "approximate"
    # where the column comes from: "collinearity" (the rigorous model at the returned row) or "model"
    # (the method's own image model, e.g. a fitted RFM or network that predicts both coordinates)
    column_source: ClassVar[str] = "collinearity"
    # the method searches the sensor's scanlines (line time, perspective centre, attitude, look direction):
    # unavailable on a sensor without line geometry (an RPC; :func:`unavailable_reason`).  The learned and
    # generalized methods, which need only ground / image pairs, declare False.
    needs_line_geometry: ClassVar[bool] = True
    # points per _locate call when the method's working arrays grow with N (numpy active-set loops keep
    # several (N,) and (N, 3) arrays per iteration); None: all at once.  Results do not depend on it.
    chunk_points: int | None = None

    def __init__(self, scene: Scene, **params) -> None:
        reason = type(self).unavailable_reason(scene)
        if reason is not None:
            raise MethodUnavailableError(reason)
        self.scene = scene
        self.params = params
        self._fitted = not self.needs_fit
        self.fit_info: dict = {}
        self._column_model: PairColumnModel | None = None
        self._kernel_params: CollinearityParams | None = None
        self._kernel_params_known = False  # packed on first use

    @classmethod
    def unavailable_reason(cls, sensor: object) -> str | None:
        """Why this method cannot run on ``sensor`` (from the declared needs and capabilities), or None."""
        if cls.needs_line_geometry and not has_line_geometry(sensor):
            return (f"method {cls.name!r} searches the scanlines of a line-scan sensor; "
                    f"{getattr(sensor, 'name', type(sensor).__name__)!r} has none (an RPC has no physical lines: "
                    "ask for its resected MPC, --as-mpc, a stand-in)")
        return None

    # ------------------------------------------------------------------ API
    def fit(self, control: PointSet) -> BestScanlineMethod:
        """Train on SCOPs (no-op for search methods).  Returns self.

        A row-only method (``column_source == "collinearity"``) on a sensor without line geometry also fits
        its column model on the SCOPs (:class:`~explorer.methods._polynomial.PairColumnModel`), described in
        ``fit_info["column_model"]``."""
        if self.needs_fit:
            if len(control) == 0:
                raise ValueError(f"{self.name}: no control points to fit")
            # one OpenBLAS thread: a fit is many small solves (the RFM of nn-rfm, ogp's term selection, the
            # PairColumnModel), where a second thread costs more than it gives -- 6-250x per least-squares solve
            # on the shared 2-core machine (0.2 s instead of 0.8 ms per 760 x 39 solve at load 4), the default
            # export's CPU 25-31 s -> 17 s; the results are the same to the bit (tests/methods/test_fit_threads.py)
            with blas_threads(1):
                self._fit(control)
                if self.column_source == "collinearity" and not has_line_geometry(self.scene):
                    self._column_model = PairColumnModel(control, self.name)
                    self.fit_info["column_model"] = self._column_model.info()
        self._fitted = True
        return self

    def ground_to_image(self, ground: np.ndarray, *, trace: bool = False) -> ScanlineResult:
        """Best scanline and column of ground points.

        Parameters
        ----------
        ground : ndarray, shape (N, 3)
            Local ENU metres.
        trace : bool
            Record the rows visited per iteration (small N only).

        Returns
        -------
        ScanlineResult
        """
        if not self._fitted:
            raise NotFittedError(f"method {self.name!r} must be fit on control points before use")
        ground = as_points(ground)
        step = self.chunk_points
        if step and len(ground) > step and not trace:  # bound the working memory of numpy loops
            result = concatenate_results([self._locate(ground[a:a + step], trace=False)
                                          for a in range(0, len(ground), step)])
        else:
            result = self._locate(ground, trace=trace)  # inside: set by _result from (row, col), NaN outside
        if has_line_coverage(self.scene):  # a row on a line the tables do not cover has no answer: flag it
            result.covered = ~np.isfinite(result.row) | rows_covered(self.scene, result.row)
        return result

    # ------------------------------------------------------------- helpers
    def _fit(self, control: PointSet) -> None:  # pragma: no cover - overridden by learned methods
        raise NotImplementedError

    @abstractmethod
    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        """Compute the result for validated ground points (N, 3)."""

    def _result(
        self,
        ground: np.ndarray,
        row: np.ndarray,
        converged: np.ndarray,
        ce_evaluations: np.ndarray,
        *,
        col: np.ndarray | None = None,
        trace: list[np.ndarray] | None = None,
        info: dict | None = None,
        mask: np.ndarray | None = None,
    ) -> ScanlineResult:
        """Assemble a result; the column comes from the collinearity at ``row`` unless given
        (that costs one more collinearity evaluation per point, counted here), or from the column model
        fitted on the SCOPs on a sensor without line geometry (no collinearity evaluation).  ``inside`` is
        (row, col) on the image (:func:`explorer.methods._compiled.inside_flags`; NaN is outside)
        and ``mask`` where given (e.g. a learned model's training domain)."""
        ce = np.asarray(ce_evaluations, dtype=np.int64)
        if col is None and self._column_model is not None:
            col = np.where(np.isfinite(row), self._column_model(ground), np.nan)
        elif col is None:
            col = self._column_at_row(ground, row)
            ce = ce + np.isfinite(row)  # a new array: the caller's is left as it was
        inside = inside_flags(row, col, self.scene.n_rows, self.scene.n_columns, mask)
        return ScanlineResult(row, col, np.asarray(converged, bool), inside, ce, trace, info or {})

    def _column_at_row(self, ground: np.ndarray, row: np.ndarray) -> np.ndarray:
        """Column (N,) of ground points at rows (N,) by the collinearity (NaN where the row is NaN):
        the compiled evaluator for MPC scenes, :meth:`Scene.column_at_row` otherwise."""
        if not self._kernel_params_known:
            self._kernel_params = collinearity_params_or_none(self.scene)
            self._kernel_params_known = True
        if self._kernel_params is not None:
            return columns_at_rows(self._kernel_params, ground, row)
        col = np.full(row.shape, np.nan)
        ok = np.isfinite(row)
        col[ok] = self.scene.column_at_row(ground[ok], row[ok])
        return col


def concatenate_results(parts: list[ScanlineResult]) -> ScanlineResult:
    """One result from results of consecutive point chunks (no traces).  ``info`` entries that are
    per-point arrays are concatenated; others are taken from the first chunk, except ``status_counts``
    (summed)."""
    first = parts[0]
    info: dict = {}
    for key, value in first.info.items():
        if isinstance(value, np.ndarray) and value.ndim >= 1 and value.shape[0] == len(first):
            info[key] = np.concatenate([p.info[key] for p in parts])
        elif key == "status_counts":
            info[key] = {k: sum(p.info[key][k] for p in parts) for k in value}
        else:
            info[key] = value
    def joined(field: str) -> np.ndarray:
        return np.concatenate([getattr(p, field) for p in parts])

    covered = None if any(p.covered is None for p in parts) else joined("covered")
    return ScanlineResult(joined("row"), joined("col"), joined("converged"), joined("inside"),
                          joined("ce_evaluations"), None, info, covered)


def register(cls: type[BestScanlineMethod]) -> type[BestScanlineMethod]:
    """Class decorator adding a method to the registry under ``cls.name``."""
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no name")
    if cls.name in _REGISTRY and _REGISTRY[cls.name] is not cls:
        raise ValueError(f"method name {cls.name!r} registered twice")
    _REGISTRY[cls.name] = cls
    return cls


def discover() -> None:
    """Import every method module of this package once so their ``@register`` decorators run.

    Plug-in discovery by file name (``importlib``): every public module next to this one is a
    method module.  A module that fails to import does not hide the others: its error is kept in
    :data:`DISCOVERY_ERRORS` and reported with a warning (the test suite asserts there is none).
    """
    global _DISCOVERED
    if _DISCOVERED:
        return
    for mod in pkgutil.iter_modules([str(Path(__file__).parent)]):
        if mod.name in ("base",) or mod.name.startswith("_"):
            continue
        try:
            importlib.import_module(f"{__package__}.{mod.name}")
        except Exception as exc:  # noqa: BLE001 - reported, never swallowed silently
            DISCOVERY_ERRORS[mod.name] = f"{type(exc).__name__}: {exc}"
            _log.warn(f"method module {mod.name!r} failed to import: {exc}")  # one line (explorer/_log.py)
    _DISCOVERED = True


def registry() -> dict[str, type[BestScanlineMethod]]:
    """Name -> class of every registered method (after discovering all method modules)."""
    discover()
    return dict(_REGISTRY)


def available(family: str | None = None) -> list[str]:
    """Registered method names, optionally of one family."""
    return [n for n, c in registry().items() if family is None or c.family == family]


def unavailable_reason(name: str, sensor: object) -> str | None:
    """Why the registered method ``name`` cannot run on ``sensor`` (its declared needs against the sensor's
    declared capabilities, e.g. a search method on an RPC), or None when it can."""
    reg = registry()
    if name not in reg:
        raise UnknownNameError("method", name, sorted(reg))
    return reg[name].unavailable_reason(sensor)


def create(name: str, scene: Scene, **params) -> BestScanlineMethod:
    """Instantiate a registered method by name.

    Raises
    ------
    MethodUnavailableError
        The sensor lacks what the method needs (:func:`unavailable_reason`), before any work.
    """
    reason = unavailable_reason(name, scene)
    if reason is not None:
        raise MethodUnavailableError(reason)
    return registry()[name](scene, **params)
