"""Accuracy and cost of a best-scanline method on check points: the papers'
RMSE (Eq. 4) and dr_max (Eq. 5) of the scanline, plus the column error, fit and
ground-to-image times, collinearity evaluations per point and converged fraction.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np

from explorer.methods.base import BestScanlineMethod, ScanlineResult
from explorer.points import PointSet
from explorer.sensor import StandIn


@dataclass
class Evaluation:
    """Measured performance of one method on one set of check points (see ``docs/results.md``)."""

    method: str
    n_scops: int
    n_scps: int
    n_evaluated: int
    rmse_px: float
    dr_max_px: float
    col_rmse_px: float
    fit_s: float
    locate_s: float
    ce_evals_per_point: float
    converged_frac: float
    valid_frac: float
    ce_evals_max: int = 0
    residual_row: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    residual_col: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    evaluated_index: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0, dtype=np.int64))

    def summary(self) -> dict:
        """JSON-ready dict without the per-point arrays."""
        d = asdict(self)
        for k in ("residual_row", "residual_col", "evaluated_index"):
            d.pop(k)
        return d


def _rms(values: np.ndarray) -> float:
    """Root mean square of ``values`` (N,); NaN when there is none."""
    return float(np.sqrt(np.mean(values**2))) if values.size else float("nan")


def scanline_errors(result: ScanlineResult, check: PointSet) -> tuple[np.ndarray, np.ndarray]:
    """Signed row and column residuals (estimated - exact), each (N,), pixels; NaN where invalid."""
    dr = np.where(result.valid, result.row - check.row, np.nan)
    dc = np.where(result.valid, result.col - check.col, np.nan)
    return dr, dc


def evaluate_method(
    method: BestScanlineMethod,
    check: PointSet,
    control: PointSet | None = None,
    *,
    max_points: int | None = None,
    seed: int = 0,
    fit: bool = True,
) -> Evaluation:
    """Fit (when ``control`` is given and the method learns) and evaluate on ``check``.

    Parameters
    ----------
    method : BestScanlineMethod
    check : PointSet
        SCPs with exact rows/columns.
    control : PointSet, optional
        SCOPs for learned methods.
    max_points : int, optional
        Evaluate on a seeded random subsample of this size (reported in ``n_evaluated``).
    seed : int
    fit : bool
        Fit the method on ``control`` first (default).  False: the caller has fit it already
        (and timed the fit itself); ``fit_s`` is then 0 and ``control`` only sets ``n_scops``.
    """
    fit_s = 0.0
    if method.needs_fit and fit:
        if control is None:
            raise ValueError(f"{method.name} needs control points")
        t0 = time.perf_counter()
        method.fit(control)
        fit_s = time.perf_counter() - t0
    index = np.arange(len(check))
    if max_points is not None and max_points < len(check):
        rng = np.random.default_rng(seed)
        index = np.sort(rng.choice(len(check), size=max_points, replace=False))
    sub = check.subset(index) if index.size != len(check) else check
    t0 = time.perf_counter()
    res = method.ground_to_image(sub.ground)
    locate_s = time.perf_counter() - t0
    dr, dc = scanline_errors(res, sub)
    ok = np.isfinite(dr)
    return Evaluation(
        method=method.name,
        n_scops=len(control) if (control is not None and method.needs_fit) else 0,
        n_scps=len(check),
        n_evaluated=len(sub),
        rmse_px=_rms(dr[ok]),
        dr_max_px=float(np.max(np.abs(dr[ok]))) if ok.any() else float("nan"),
        col_rmse_px=_rms(dc[ok]),
        fit_s=fit_s,
        locate_s=locate_s,
        ce_evals_per_point=float(res.ce_evaluations.mean()) if len(res) else 0.0,
        converged_frac=float(res.converged.mean()) if len(res) else 0.0,
        valid_frac=float(res.valid.mean()) if len(res) else 0.0,
        ce_evals_max=int(res.ce_evaluations.max()) if len(res) else 0,
        residual_row=dr,
        residual_col=dc,
        evaluated_index=index,
    )


STAND_IN_METHOD = "stand-in"
"""Method name of a stand-in's evaluation (maps, ``residuals.csv``)."""


def evaluate_stand_in(stand_in: StandIn, check: PointSet, name: str = STAND_IN_METHOD) -> tuple[Evaluation, np.ndarray]:
    """A stand-in model's error against the sensor at check points (exact rows / columns: the sensor's).

    Parameters
    ----------
    stand_in : explorer.sensor.StandIn
        E.g. the MPC fitted to a CSM camera, the vendor RPC of a rigorous DIMAP / DG model.
    check : PointSet
        Ground points in the sensor's frame with the sensor's own image positions.
    name : str
        The evaluation's method name.

    Returns
    -------
    Evaluation
        Residuals stand-in minus sensor (NaN where the stand-in gives no point), no CE.
    status : ndarray of int8 (N,)
        0 where the stand-in gives a point, 3 (no image point) elsewhere.
    """
    t0 = time.perf_counter()
    row, col = stand_in.ground_to_image(check.ground)
    dt = time.perf_counter() - t0
    dr, dc = row - check.row, col - check.col
    ok = np.isfinite(dr) & np.isfinite(dc)
    dr, dc = np.where(ok, dr, np.nan), np.where(ok, dc, np.nan)
    n = len(check)
    ev = Evaluation(method=name, n_scops=0, n_scps=n, n_evaluated=n, rmse_px=_rms(dr[ok]),
                    dr_max_px=float(np.max(np.abs(dr[ok]))) if ok.any() else float("nan"),
                    col_rmse_px=_rms(dc[ok]), fit_s=0.0, locate_s=dt, ce_evals_per_point=0.0,
                    converged_frac=float(ok.mean()) if n else 0.0, valid_frac=float(ok.mean()) if n else 0.0,
                    residual_row=dr, residual_col=dc, evaluated_index=np.arange(n))
    return ev, np.where(ok, 0, 3).astype(np.int8)
