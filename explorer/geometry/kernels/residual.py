"""The along-track residual, its rate and the column for many points (:func:`residual_and_rate`), and the
collinearity column at given rows (:func:`columns_at_rows`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, njit, prange
from explorer.geometry.kernels.evaluators import _ce_fixed, _ce_fixed_py, _collinearity_point_py, collinearity_point
from explorer.geometry.kernels.params import CollinearityParams

if TYPE_CHECKING:  # typing only: the scene layer sits above geometry
    from explorer.scene import Scene


# --------------------------------------------------------------------------- residual kernel
@njit(parallel=True, fastmath=False, cache=True)
def _residual_nb(
    ground, t, pos, dpos, att, datt, jit, focal, offset, curv, dist, sc0, fast, pitch, pc, g_out, gt_out, col_out
):  # pragma: no cover - compiled
    for i in prange(ground.shape[0]):
        g, gt, yd, ydt, vz = collinearity_point(
            ground[i, 0],
            ground[i, 1],
            ground[i, 2],
            t[i],
            pos, dpos, att, datt, jit, focal, offset, curv, dist, sc0, fast,
        )
        g_out[i] = g
        gt_out[i] = gt
        col_out[i] = yd / pitch + pc


@njit(parallel=True, fastmath=False, cache=True)
def _residual_fixed_nb(ground, t_all, fx, focal, offset, pitch, pc, g_out, gt_out, col_out):  # pragma: no cover
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    for i in prange(ground.shape[0]):
        X, Y, Z = ground[i, 0], ground[i, 1], ground[i, 2]
        t = t_all[i]
        g, gt, yd, ydt, vz = _ce_fixed(
            X, Y, Z, t, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, focal, offset
        )
        g_out[i] = g
        gt_out[i] = gt
        col_out[i] = yd / pitch + pc


def _use_numba(backend: str) -> bool:
    if backend not in ("auto", "numba", "numpy"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'numpy', got {backend!r}")
    if backend == "numba" and not NUMBA_AVAILABLE:
        raise RuntimeError("backend='numba' requested but numba is not available")
    return NUMBA_AVAILABLE and backend != "numpy"


def _params(scene_or_params: Scene | CollinearityParams) -> CollinearityParams:
    if isinstance(scene_or_params, CollinearityParams):
        return scene_or_params
    return CollinearityParams.from_scene(scene_or_params)


def residual_and_rate(
    scene: Scene | CollinearityParams,
    ground: np.ndarray,
    t: np.ndarray,
    *,
    backend: str = "auto",
    evaluator: str = "reference",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along-track residual, its time derivative and the column: one collinearity evaluation.

    Parameters
    ----------
    scene : Scene or CollinearityParams
    ground : ndarray, shape (N, 3)
        Local ENU metres.
    t : ndarray, shape (N,) or scalar
        Scanline times, seconds.
    backend : {"auto", "numba", "numpy"}
        "auto" uses numba when available.
    evaluator : {"reference", "fast", "fixed"}
        "reference" reproduces :meth:`Scene.along_track_residual` bit for bit; "fast" uses the
        addition-theorem sines; "fixed" the branch-free evaluator the solvers use (times must lie
        within the image +-64 rows; raises ValueError where the scene does not fit it).

    Returns
    -------
    g : ndarray, shape (N,)
        ``x_d - x_det(y_d)`` metres (as :meth:`Scene.along_track_residual`; divide by the pitch for
        pixels).
    g_t : ndarray, shape (N,)
        ``dg/dt``, metres per second (analytic).
    col : ndarray, shape (N,)
        Image column at time ``t``.
    """
    if evaluator not in ("reference", "fast", "fixed"):
        raise ValueError(f"evaluator must be 'reference', 'fast' or 'fixed', got {evaluator!r}")
    p = _params(scene)
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    t = np.ascontiguousarray(np.broadcast_to(np.asarray(t, dtype=np.float64), ground.shape[:1]))
    n = ground.shape[0]
    if evaluator == "fixed":
        fm = p.fixed_model((-64.5, p.n_rows + 63.5))
        if fm is None:
            raise ValueError("the fixed evaluator does not apply to this scene (see CollinearityParams.fixed_model)")
        if _use_numba(backend):
            g, gt, col = np.empty(n), np.empty(n), np.empty(n)
            _residual_fixed_nb(ground, t, fm.args(), p.focal, p.offset, p.pitch, p.principal_column, g, gt, col)
            return g, gt, p.to_columns(col)
        g, gt, yd, _, _ = _ce_fixed_py(ground[:, 0], ground[:, 1], ground[:, 2], t, *fm.args(), p.focal, p.offset)
        return g, gt, p.to_columns(yd / p.pitch + p.principal_column)
    fast = evaluator == "fast"
    if _use_numba(backend):
        g, gt, col = np.empty(n), np.empty(n), np.empty(n)
        _residual_nb(ground, t, *p.model_args(fast), p.pitch, p.principal_column, g, gt, col)
        return g, gt, p.to_columns(col)
    g, gt, yd, _, _ = _collinearity_point_py(ground[:, 0], ground[:, 1], ground[:, 2], t, *p.model_args(fast))
    return g, gt, p.to_columns(yd / p.pitch + p.principal_column)


# --------------------------------------------------------------------------- column at given rows
COLUMN_WINDOW_MARGIN = 64.0  # rows beyond the image where the column kernel uses the fixed evaluator


@njit(parallel=True, fastmath=False, cache=True)
def _column_fixed_nb(ground, rows, fx, focal, offset, pitch, pc, line_period, ref_row, r_lo, r_hi, col_out):
    # pragma: no cover - compiled
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    n_out = 0
    for i in prange(ground.shape[0]):
        r = rows[i]
        inside = (r >= r_lo) & (r <= r_hi)  # False for NaN
        rr = r if inside else r_lo
        _, _, yd, _, _ = _ce_fixed(
            ground[i, 0], ground[i, 1], ground[i, 2], (rr - ref_row) * line_period, P, V, A, AR, sc0f, jn, jp, jt,
            js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, focal, offset,
        )
        col_out[i] = yd / pitch + pc if inside else np.nan
        n_out += 0 if inside or not np.isfinite(r) else 1
    return n_out


def collinearity_params_or_none(scene: Scene) -> CollinearityParams | None:
    """:meth:`CollinearityParams.from_scene`, or None where the compiled kernels do not apply: numba
    missing or disabled, or a scene that does not declare the capability ``has_polynomial_exterior``
    (MPC polynomials of time; see :class:`explorer.sensor.PolynomialExteriorSensor`), such as a
    rigorous line-scan model."""
    if not NUMBA_AVAILABLE or not getattr(scene, "has_polynomial_exterior", False):
        return None
    return CollinearityParams.from_scene(scene)


def columns_at_rows(params: CollinearityParams, ground: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Image columns of ground points at given (fractional) rows: one CE per finite row, compiled.

    The column of the learned methods, which predict the row only (``docs/conventions.md``).  Rows
    within the image +-``COLUMN_WINDOW_MARGIN`` use the branch-free evaluator (vectorised), others the
    reference evaluator; equal to :meth:`explorer.scene.Scene.column_at_row` to round-off.

    Parameters
    ----------
    params : CollinearityParams
    ground : ndarray, shape (N, 3)
        Local ENU metres.
    rows : ndarray, shape (N,)
        Rows (NaN gives NaN).

    Returns
    -------
    ndarray, shape (N,)
    """
    p = params
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    rows = np.ascontiguousarray(rows, dtype=np.float64)
    window = (-0.5 - COLUMN_WINDOW_MARGIN, p.n_rows - 0.5 + COLUMN_WINDOW_MARGIN)
    fm = p.fixed_model(window) if NUMBA_AVAILABLE else None
    t = (rows - p.reference_row) * p.line_period
    if fm is None:
        return residual_and_rate(p, ground, t)[2]
    col = np.empty(rows.shape[0])
    n_out = _column_fixed_nb(
        ground, rows, fm.args(), p.focal, p.offset, p.pitch, p.principal_column, p.line_period, p.reference_row,
        window[0], window[1], col,
    )
    col = p.to_columns(col)
    if n_out:  # rows far off the image: the reference evaluator
        far = np.flatnonzero(np.isfinite(rows) & ~((rows >= window[0]) & (rows <= window[1])))
        col[far] = residual_and_rate(p, ground[far], t[far])[2]
    return col
