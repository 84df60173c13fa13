"""Fitting rational function models (RPC00B form) to a ground-to-image function or to GCPs.

Image coordinates are 0-based with integer = pixel centre (``docs/conventions.md``,
``docs/rpc.md``); ground coordinates are degrees and metres above the ellipsoid.

Both fits solve, for each image coordinate ``u`` (row or column, normalised), the linearised
equations ``N(X) - u * (D(X) - 1) = u`` (``D`` has constant term 1), weighted by ``1 / D(X)``
from the previous iteration (so that the residual approximates the true ``u - N/D``), with an
optional Tikhonov term ``regularization * ||coefficients||^2`` on all but the constant terms.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from explorer.rpc.model import RationalFunctionModel, rpc00b_monomials

__all__ = ["RFMFit", "fit_rfm_from_gcps", "fit_rfm_terrain_independent"]

FloatArray = NDArray[np.float64]
GroundToImage = Callable[[FloatArray, FloatArray, FloatArray], tuple[FloatArray, FloatArray]]

#: Number of RPC00B terms used for each polynomial order (first, second, third order).
TERMS_PER_ORDER = {1: 4, 2: 10, 3: 20}


@dataclass(frozen=True)
class RFMFit:
    """Result of a fit: the model and its residuals in pixels.

    Attributes
    ----------
    model : RationalFunctionModel
    rms_px, max_px : float
        Residuals on the fitting points (Euclidean row/col distance, pixels).
    check_rms_px, check_max_px : float
        Residuals on the independent check grid (NaN for GCP fits without check points).
    n_points, n_check_points : int
    """

    model: RationalFunctionModel
    rms_px: float
    max_px: float
    check_rms_px: float
    check_max_px: float
    n_points: int
    n_check_points: int


def _solve_rational(
    monomials: FloatArray,
    target: FloatArray,
    n_terms: int,
    *,
    rational: bool,
    regularization: float,
    n_reweight: int,
) -> tuple[FloatArray, FloatArray]:
    """Numerator and denominator (20 coefficients each, zeros beyond n_terms) for one coordinate."""
    m = monomials[:, :n_terms]
    if rational:
        design = np.hstack([m, -target[:, None] * m[:, 1:]])
    else:
        design = m
    n_unknowns = design.shape[1]
    reg_rows = np.sqrt(regularization) * np.eye(n_unknowns)[1:] if regularization > 0 else None
    weights = np.ones_like(target)
    num = np.zeros(20)
    den = np.zeros(20)
    den[0] = 1.0
    for _ in range(n_reweight if rational else 1):
        a = design * weights[:, None]
        b = target * weights
        if reg_rows is not None:
            a = np.vstack([a, reg_rows])
            b = np.concatenate([b, np.zeros(reg_rows.shape[0])])
        # column scaling for conditioning
        norms = np.linalg.norm(a, axis=0)
        norms[norms == 0] = 1.0
        sol, *_ = np.linalg.lstsq(a / norms, b, rcond=None)
        sol = sol / norms
        num[:n_terms] = sol[:n_terms]
        if rational:
            den[1:n_terms] = sol[n_terms:]
            d_values = m @ den[:n_terms]
            weights = 1.0 / np.where(np.abs(d_values) > 1e-12, d_values, 1e-12)
    return num, den


def _normalisation(values: FloatArray) -> tuple[float, float]:
    lo, hi = float(np.min(values)), float(np.max(values))
    offset = 0.5 * (lo + hi)
    scale = 0.5 * (hi - lo)
    return offset, (scale if scale > 0 else 1.0)


def _fit(
    lon: FloatArray,
    lat: FloatArray,
    h: FloatArray,
    row: FloatArray,
    col: FloatArray,
    n_terms: int,
    *,
    rational: bool,
    regularization: float,
    n_reweight: int,
    ground_norm: tuple[tuple[float, float], ...] | None = None,
) -> RationalFunctionModel:
    if ground_norm is None:
        ground_norm = (_normalisation(lon), _normalisation(lat), _normalisation(h))
    (lon_o, lon_s), (lat_o, lat_s), (h_o, h_s) = ground_norm
    row_o, row_s = _normalisation(row)
    col_o, col_s = _normalisation(col)
    mono = rpc00b_monomials((lon - lon_o) / lon_s, (lat - lat_o) / lat_s, (h - h_o) / h_s)
    kwargs: dict[str, Any] = dict(rational=rational, regularization=regularization, n_reweight=n_reweight)
    row_num, row_den = _solve_rational(mono, (row - row_o) / row_s, n_terms, **kwargs)
    col_num, col_den = _solve_rational(mono, (col - col_o) / col_s, n_terms, **kwargs)
    return RationalFunctionModel(
        row_num=row_num, row_den=row_den, col_num=col_num, col_den=col_den,
        row_offset=row_o, col_offset=col_o, lat_offset=lat_o, lon_offset=lon_o,
        height_offset=h_o, row_scale=row_s, col_scale=col_s, lat_scale=lat_s,
        lon_scale=lon_s, height_scale=h_s, source_format="fitted",
    )  # fmt: skip


def _residuals(
    model: RationalFunctionModel, lon: FloatArray, lat: FloatArray, h: FloatArray,
    row: FloatArray, col: FloatArray,
) -> tuple[float, float]:  # fmt: skip
    r, c = model.projection(lon, lat, h)
    dist = np.hypot(r - row, c - col)
    return float(np.sqrt(np.mean(dist**2))), float(np.max(dist))


def fit_rfm_terrain_independent(
    ground_to_image: GroundToImage,
    lon_range: tuple[float, float],
    lat_range: tuple[float, float],
    h_range: tuple[float, float],
    grid: tuple[int, int, int] = (15, 15, 7),
    *,
    regularization: float = 0.0,
    n_reweight: int = 4,
) -> RFMFit:
    """Terrain-independent RPC00B fit of a ground-to-image function on a 3-D grid.

    Parameters
    ----------
    ground_to_image : callable ``(lon, lat, h) -> (row, col)``
        Vectorised; degrees, metres above the ellipsoid, 0-based pixel-centre output.
    lon_range, lat_range : (float, float)
        Degrees.
    h_range : (float, float)
        Metres.
    grid : (nx, ny, nz)
        Grid nodes along lon, lat, h (each >= 2; at least 39 points in total).
    regularization : float
        Tikhonov weight on the (column-scaled) coefficients; 0 for plain least squares.
    n_reweight : int
        Iterations of the denominator re-weighting.

    Returns
    -------
    RFMFit
        With residuals on the grid and on a check grid offset by half a cell
        (``(nx-1) x (ny-1) x (nz-1)`` cell centres).
    """
    nx, ny, nz = grid
    if min(grid) < 2 or nx * ny * nz < 39:
        raise ValueError(f"grid {grid} too small: need >= 2 nodes per axis and >= 39 points")
    axes = [np.linspace(lo, hi, n) for (lo, hi), n in zip((lon_range, lat_range, h_range), grid,
                                                            strict=True)]
    lon, lat, h = (a.ravel() for a in np.meshgrid(*axes, indexing="ij"))
    row, col = (np.asarray(v, dtype=np.float64).ravel() for v in ground_to_image(lon, lat, h))
    ground_norm = tuple(_normalisation(v) for v in (lon, lat, h))
    model = _fit(lon, lat, h, row, col, 20, rational=True, regularization=regularization,
                 n_reweight=n_reweight, ground_norm=ground_norm)
    rms, mx = _residuals(model, lon, lat, h, row, col)
    centres = [0.5 * (a[1:] + a[:-1]) for a in axes]
    lon_c, lat_c, h_c = (a.ravel() for a in np.meshgrid(*centres, indexing="ij"))
    row_c, col_c = (np.asarray(v, dtype=np.float64).ravel() for v in ground_to_image(lon_c, lat_c,
                                                                                      h_c))
    rms_c, mx_c = _residuals(model, lon_c, lat_c, h_c, row_c, col_c)
    return RFMFit(model, rms, mx, rms_c, mx_c, lon.size, lon_c.size)


def fit_rfm_from_gcps(
    lon: ArrayLike,
    lat: ArrayLike,
    h: ArrayLike,
    row: ArrayLike,
    col: ArrayLike,
    *,
    order: int = 1,
    rational: bool = True,
    regularization: float = 0.0,
    n_reweight: int = 4,
) -> RFMFit:
    """Terrain-dependent fit from ground control points, terms limited by ``order``.

    Parameters
    ----------
    lon, lat, h, row, col : array_like, shape (N,)
        GCPs: degrees, metres above the ellipsoid, 0-based pixel-centre image coordinates.
    order : {1, 2, 3}
        Polynomial order: the first 4, 10 or 20 RPC00B terms in each numerator/denominator.
    rational : bool
        Fit numerator/denominator (``2 n - 1`` unknowns per image coordinate) or a plain
        polynomial (denominator 1, ``n`` unknowns).
    regularization : float
        Tikhonov weight (see :func:`fit_rfm_terrain_independent`).
    n_reweight : int
        Denominator re-weighting iterations.

    Returns
    -------
    RFMFit
        Residuals on the GCPs (check fields are NaN).

    Raises
    ------
    ValueError
        Unknown order, mismatched lengths, NaN, or fewer GCPs than unknowns.
    """
    if order not in TERMS_PER_ORDER:
        raise ValueError(f"order must be 1, 2 or 3, got {order}")
    arrays = []
    for name, value in (("lon", lon), ("lat", lat), ("h", h), ("row", row), ("col", col)):
        a = np.asarray(value, dtype=np.float64).ravel()
        if np.isnan(a).any():
            raise ValueError(f"{name} contains NaN")
        arrays.append(a)
    lon_a, lat_a, h_a, row_a, col_a = arrays
    if len({a.size for a in arrays}) != 1:
        raise ValueError("lon, lat, h, row, col must have the same length")
    n_terms = TERMS_PER_ORDER[order]
    needed = 2 * n_terms - 1 if rational else n_terms
    if lon_a.size < needed:
        kind = "rational" if rational else "polynomial"
        raise ValueError(
            f"too few GCPs for an order-{order} {kind} fit: {lon_a.size} given, at least "
            f"{needed} needed ({needed} unknowns per image coordinate)"
        )
    model = _fit(lon_a, lat_a, h_a, row_a, col_a, n_terms, rational=rational,
                 regularization=regularization, n_reweight=n_reweight)
    rms, mx = _residuals(model, lon_a, lat_a, h_a, row_a, col_a)
    return RFMFit(model, rms, mx, float("nan"), float("nan"), lon_a.size, 0)
