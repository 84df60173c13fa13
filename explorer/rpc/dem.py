"""Image to ground of a rational function model on a DEM: the first intersection of each pixel's line of sight
with the terrain.

A gridded DEM goes through the compiled cell walk of :mod:`explorer.geometry.dem_intersection` (by
:meth:`explorer.rpc.inverse.RPCInverse.on_dem`), any other height source through a sampled search on the
model's exact localisation.  The function lives beside the model, not in it: the model
(:mod:`explorer.rpc.model`) knows nothing of terrains or of the fitted inverse, so the inverse may name the
model without an import circle.  Heights are above the ellipsoid (``docs/conventions.md#frames``; SRTM and
other geoid-referenced DEMs are converted when read, :func:`explorer.real.from_rpc.load_dem`).
"""

from __future__ import annotations

from typing import Any, Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from explorer.errors import InputError
from explorer.geometry.dem_intersection import OK, OUTSIDE_DEM
from explorer.rpc.inverse import RPCInverse
from explorer.rpc.model import RationalFunctionModel
from explorer.rpc.polynomial import FloatArray, HeightSource, _as_float_array
from explorer.terrain_io import height_grid_of

__all__ = ["localization_on_dem"]


@overload
def localization_on_dem(rpc: RationalFunctionModel, row: ArrayLike, col: ArrayLike, dem: HeightSource | Any, *,
                        h_min: float | None = ...,
                        h_max: float | None = ..., n_levels: int = ..., height_tol: float = ..., tol: float = ...,
                        max_iter: int = ..., return_flags: Literal[False] = False,
                        ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]: ...
@overload
def localization_on_dem(rpc: RationalFunctionModel, row: ArrayLike, col: ArrayLike, dem: HeightSource | Any, *,
                        h_min: float | None = ...,
                        h_max: float | None = ..., n_levels: int = ..., height_tol: float = ..., tol: float = ...,
                        max_iter: int = ..., return_flags: Literal[True],
                        ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_], NDArray[np.int8]]: ...
def localization_on_dem(
    rpc: RationalFunctionModel,
    row: ArrayLike,
    col: ArrayLike,
    dem: HeightSource | Any,
    *,
    h_min: float | None = None,
    h_max: float | None = None,
    n_levels: int = 65,
    height_tol: float = 1e-4,
    tol: float = 1e-10,
    max_iter: int = 50,
    return_flags: bool = False,
) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]] | tuple[FloatArray, FloatArray, FloatArray,
                                                                         NDArray[np.bool_], NDArray[np.int8]]:
    """Intersect each pixel's line of sight with a DEM: the first intersection from the sensor.

    A gridded DEM (:class:`~explorer.terrain_io.GeoDEM`, :class:`~explorer.terrain_io.EllipsoidalDEM`
    or a :class:`~explorer.geometry.dem_intersection.HeightGrid` in lon/lat) goes through the compiled
    kernel (:meth:`explorer.rpc.inverse.RPCInverse.on_dem`: the line of sight walked cell by cell
    between the DEM's highest and lowest heights, exact per bilinear cell, then refined on the exact RPC
    to 1e-9 px and 1e-6 m; ``h_min``, ``h_max``, ``n_levels``, ``height_tol``, ``tol`` and ``max_iter``
    do not apply).  With ``return_flags=True`` a fifth array gives the reason of each failure
    (``explorer.geometry.dem_intersection``: OK, OUTSIDE_DEM, NODATA, NO_INTERSECTION, NOT_CONVERGED).

    Any other height source (a callable, or an object with ``height(lon, lat)``) goes through the
    sampled search below (slow; kept for such sources):

    The line of sight is sampled at ``n_levels`` heights from ``h_max`` down to ``h_min``
    (each level localised with :meth:`localization`); the first level (from the top) where
    the ray passes below the terrain brackets the intersection, which is then refined by
    bisection on the height until the bracket is below ``height_tol`` metres. Because the
    highest crossing is kept, a ridge that the ray clips before reaching lower terrain is
    not skipped as long as it spans at least one height level.

    Parameters
    ----------
    rpc : RationalFunctionModel
    row, col : array_like
        0-based pixel-centre image coordinates, broadcastable.
    dem : object with ``height(lon, lat) -> ndarray`` or a callable ``(lon, lat) -> ndarray``
        Terrain heights above the ellipsoid (metres), NaN where unknown.
    h_min, h_max : float, optional
        Search interval in metres; default: ``dem.min``/``dem.max`` (widened by 1 m) when the
        DEM has them, else :meth:`height_range`.
    n_levels : int
        Number of sampled heights (>= 2).
    height_tol : float
        Bisection stops when the height bracket is below this (metres).
    tol, max_iter : float, int
        Passed to :meth:`localization`.

    Returns
    -------
    lon, lat, h : ndarray
        Intersection (degrees, metres); NaN where not found.
    found : ndarray of bool
        False where no crossing was found in [h_min, h_max], where the DEM was undefined
        at the bracketing levels, or where localisation did not converge.
    """
    row_a = _as_float_array(row, "row")
    col_a = _as_float_array(col, "col")
    row_a, col_a = np.broadcast_arrays(row_a, col_a)
    shape = row_a.shape
    row_f = row_a.ravel()
    col_f = col_a.ravel()
    grid = height_grid_of(dem)
    inverse = None
    if grid is not None:
        try:
            inverse = RPCInverse.for_model(rpc, grid.z_min - 1.0, grid.z_max + 1.0)
        except InputError:  # no inverse can be fitted (image and normalisation box apart): sampled search
            inverse = None
    if grid is not None and inverse is not None:
        lon_k, lat_k, h_k, flags = inverse.on_dem(row_f, col_f, grid)
        if flags.size and np.all(flags == OUTSIDE_DEM):
            source = getattr(dem, "source_path", None) or getattr(getattr(dem, "dem", None), "source_path", "")
            raise InputError(f"DEM {source or ''} does not cover any of the {flags.size} pixel(s)' lines of "
                             f"sight (DEM lon from {grid.x0:.5f}, lat from {grid.y0:.5f}; first pixel "
                             f"row {row_f[0]:.1f}, col {col_f[0]:.1f})")
        out = (lon_k.reshape(shape), lat_k.reshape(shape), h_k.reshape(shape), (flags == OK).reshape(shape))
        return (*out, flags.reshape(shape)) if return_flags else out
    height_fn: Any = dem.height if hasattr(dem, "height") else dem  # a HeightSource or a callable
    if h_min is None or h_max is None:
        if hasattr(dem, "min") and hasattr(dem, "max"):
            dem_min, dem_max = float(dem.min) - 1.0, float(dem.max) + 1.0
        else:
            dem_min, dem_max = rpc.height_range()
        h_min = dem_min if h_min is None else h_min
        h_max = dem_max if h_max is None else h_max
    if not h_max > h_min:
        raise ValueError(f"h_max ({h_max}) must be greater than h_min ({h_min})")
    if n_levels < 2:
        raise ValueError("n_levels must be >= 2")

    levels = np.linspace(h_max, h_min, n_levels)
    n = row_f.size
    lev = np.repeat(levels[:, None], n, axis=1)  # (n_levels, n)
    lon_l, lat_l, ok_l = rpc.localization(
        np.broadcast_to(row_f, lev.shape), np.broadcast_to(col_f, lev.shape), lev,
        tol=tol, max_iter=max_iter,
    )  # fmt: skip
    terrain = np.full(lev.shape, np.nan)
    if ok_l.any():
        terrain[ok_l] = np.asarray(height_fn(lon_l[ok_l], lat_l[ok_l]), dtype=np.float64)
    above = lev - terrain  # > 0: ray above terrain
    crossing = (above[:-1] > 0) & (above[1:] <= 0)  # finite on both sides implied
    found = crossing.any(axis=0)
    first = np.argmax(crossing, axis=0)
    upper = np.where(found, levels[first], np.nan)
    lower = np.where(found, levels[np.minimum(first + 1, n_levels - 1)], np.nan)

    fi = np.flatnonzero(found)
    hi = upper[fi]
    lo = lower[fi]
    step = (h_max - h_min) / (n_levels - 1)
    n_bisect = max(0, int(np.ceil(np.log2(step / height_tol)))) if step > height_tol else 0
    ok_b = np.ones(fi.size, dtype=bool)
    for _ in range(n_bisect):
        mid = 0.5 * (hi + lo)
        lon_m, lat_m, ok_m = rpc.localization(row_f[fi], col_f[fi], mid, tol=tol, max_iter=max_iter)
        t_m = np.full(mid.shape, np.nan)
        if ok_m.any():
            t_m[ok_m] = np.asarray(height_fn(lon_m[ok_m], lat_m[ok_m]), dtype=np.float64)
        below = mid - t_m <= 0
        ok_b &= np.isfinite(t_m)
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    # final point: middle of the last bracket
    h_out = np.full(n, np.nan)
    lon_out = np.full(n, np.nan)
    lat_out = np.full(n, np.nan)
    if fi.size:
        h_fin = 0.5 * (hi + lo)
        lon_f, lat_f, ok_f = rpc.localization(row_f[fi], col_f[fi], h_fin, tol=tol, max_iter=max_iter)
        good = ok_b & ok_f
        h_out[fi] = np.where(good, h_fin, np.nan)
        lon_out[fi] = np.where(good, lon_f, np.nan)
        lat_out[fi] = np.where(good, lat_f, np.nan)
        found[fi] = good
    out = (lon_out.reshape(shape), lat_out.reshape(shape), h_out.reshape(shape), found.reshape(shape))
    if return_flags:  # the sampled search does not tell the reasons apart
        return (*out, np.where(found, 0, 3).astype(np.int8).reshape(shape))
    return out
