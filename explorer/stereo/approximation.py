"""How wrong is each approximation of the epipolar geometry, and where: :func:`approximation_maps`.

Over a regular sample of left pixels, each map gives the largest distance (pixels, right image) over a height
range between the exact epipolar curve (:func:`explorer.stereo.epipolar_curve`) and an approximation of it:

``straight line``
    the straight line through the curve's points at the lowest and highest height (what a two-height
    colocalisation gives): the curve's largest distance from that chord.
``local affine``
    an affine model ``right (row, col) = A [left row, left col, h, 1]`` fitted by least squares to the exact
    correspondences of the 3 x 3 left pixels ``affine_window_px`` apart around the pixel, at every height of
    the range (an affine camera per tile): its largest error at the pixel.
``grid``
    the epipolar resampling grids (:func:`explorer.stereo.epipolar_grids`) read bilinearly, as a stereo tool
    reads them: the pixel's epipolar position (inverse of the left grid) and the epipolar position of each exact
    curve point (inverse of the right grid) should lie on one epipolar row; the map is the largest row
    difference, i.e. how far off the epipolar row the true match lies in the resampled pair.
``grid interpolation``
    the same grids at their own height only: the distance between the right grid's bilinear position at the
    pixel's epipolar position and the pixel's exact colocalisation at that height (the interpolation error
    alone, 0 at the nodes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explorer.errors import InputError
from explorer.stereo.epipolar import epipolar_curve
from explorer.stereo.grids import EpipolarGrids, _coloc
from explorer.stereo.sensors import as_sensor, mean_height

MAP_NAMES = ("straight line", "local affine", "grid", "grid interpolation")


@dataclass(frozen=True)
class ApproximationMaps:
    """Approximation residual maps over a sample of left pixels.

    Attributes
    ----------
    rows, cols : ndarray, shape (R,), (C,)
        Left pixels of the map (package pixels).
    heights : ndarray, shape (K,)
        Ellipsoidal heights the curves span, metres.
    maps : dict of str -> ndarray (R, C)
        Largest distance from the exact curve per approximation, pixels (NaN where undefined).
    step : float or None
        The grid step of the ``grid`` maps.
    """

    rows: np.ndarray
    cols: np.ndarray
    heights: np.ndarray
    maps: dict[str, np.ndarray] = field(default_factory=dict)
    step: float | None = None

    def summary(self) -> dict[str, dict[str, float]]:
        """Per map: median, 95th percentile and maximum, pixels."""
        out = {}
        for name, values in self.maps.items():
            v = values[np.isfinite(values)]
            if v.size:
                out[name] = {"median_px": float(np.median(v)), "p95_px": float(np.percentile(v, 95)),
                             "max_px": float(np.max(v))}
        return out


def approximation_maps(left: Any, right: Any, *, heights: Any = None, shape: tuple[int, int] = (12, 20),
                       grids: EpipolarGrids | None = None, affine_window_px: float = 500.0,
                       margin_px: float = 0.0) -> ApproximationMaps:
    """Maps of how far each approximation of the epipolar geometry is from the exact curve.

    Parameters
    ----------
    left, right : Sensor or RationalFunctionModel
    heights : array_like, optional
        Heights the curves span (>= 3 values); default 9 heights over the mean scene height +- 500 m.
    shape : (int, int)
        Left pixels per map, rows x columns (regular over the image, pixel centres ``margin_px`` inside).
    grids : EpipolarGrids, optional
        Grids for the ``grid`` maps (left out without them).
    affine_window_px : float
        Spacing of the 3 x 3 pixels the local affine model is fitted to.
    margin_px : float
        Distance of the outermost map pixels from the image edges.

    Returns
    -------
    ApproximationMaps
    """
    left_s = as_sensor(left, "left")
    right_s = as_sensor(right, "right")
    if heights is None:
        h0 = 0.5 * (mean_height(left_s) + mean_height(right_s))
        heights = np.linspace(h0 - 500.0, h0 + 500.0, 9)
    heights = np.asarray(heights, dtype=np.float64).ravel()
    if heights.size < 3 or not np.isfinite(heights).all():
        raise InputError(f"heights must hold at least 3 finite values, got {heights.size}")
    n_r, n_c = int(shape[0]), int(shape[1])
    if n_r < 1 or n_c < 1:
        raise InputError(f"shape must be positive, got {shape}")
    rows = np.linspace(margin_px, left_s.n_rows - 1 - margin_px, n_r)
    cols = np.linspace(margin_px, left_s.n_columns - 1 - margin_px, n_c)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    curve = epipolar_curve(left_s, right_s, rr, cc, heights)  # (R, C, K)
    maps: dict[str, np.ndarray] = {"straight line": np.nanmax(np.abs(curve.chord_deviation_px), axis=-1)}

    # local affine: 3 x 3 pixels around each map pixel, every height
    offsets = np.array([-1.0, 0.0, 1.0]) * float(affine_window_px)
    du, dv = np.meshgrid(offsets, offsets, indexing="ij")
    nb_r = rr[..., None] + du.ravel()  # (R, C, 9)
    nb_c = cc[..., None] + dv.ravel()
    nb = epipolar_curve(left_s, right_s, nb_r, nb_c, heights)  # (R, C, 9, K)
    k = heights.size
    design = np.stack(np.broadcast_arrays(
        (nb_r[..., None] - rr[..., None, None]) / affine_window_px,
        (nb_c[..., None] - cc[..., None, None]) / affine_window_px,
        np.broadcast_to((heights - heights.mean()) / 100.0, nb_r.shape + (k,)),
        np.ones(nb_r.shape + (k,))), axis=-1).reshape(n_r, n_c, 9 * k, 4)
    target = np.stack([nb.row, nb.col], axis=-1).reshape(n_r, n_c, 9 * k, 2)
    ok = np.isfinite(target).all(axis=-1, keepdims=True)
    a_mat = np.where(ok, design, 0.0)
    b_mat = np.where(ok, target, 0.0)
    normal = np.einsum("rcki,rckj->rcij", a_mat, a_mat)
    rhs = np.einsum("rcki,rckj->rcij", a_mat, b_mat)
    with np.errstate(invalid="ignore"):
        try:
            coef = np.linalg.solve(normal, rhs)  # (R, C, 4, 2)
        except np.linalg.LinAlgError:
            coef = np.full((n_r, n_c, 4, 2), np.nan)
    centre = np.stack(np.broadcast_arrays(np.zeros(k), np.zeros(k), (heights - heights.mean()) / 100.0,
                                          np.ones(k)), axis=-1)  # (K, 4)
    pred = np.einsum("ki,rcij->rckj", centre, coef)
    maps["local affine"] = np.nanmax(np.hypot(pred[..., 0] - curve.row, pred[..., 1] - curve.col), axis=-1)

    step = None
    if grids is not None:
        step = grids.step
        e_row, e_col = grids.to_epipolar("left", rr, cc)
        er_r, _ = grids.to_epipolar("right", curve.row, curve.col)
        maps["grid"] = np.nanmax(np.abs(er_r - e_row[..., None]), axis=-1)
        g_r, g_c = grids.to_sensor("right", e_row, e_col)
        x_r, x_c, _ = _coloc(left_s, right_s, rr.ravel(), cc.ravel(), np.full(rr.size, grids.height))
        maps["grid interpolation"] = np.hypot(g_r - x_r.reshape(rr.shape), g_c - x_c.reshape(rr.shape))
    return ApproximationMaps(rows, cols, heights, maps, step)


__all__ = ["MAP_NAMES", "ApproximationMaps", "approximation_maps"]
