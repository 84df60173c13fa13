"""The exact epipolar curve of a pushbroom pair: :func:`epipolar_curve`.

For a pixel of the left image the points of the right image it can match trace a curve as the height varies:
each height gives one ground point on the left line of sight (the left sensor's exact localisation at that
ellipsoidal height), and its projection by the right sensor is the curve's point.  Each scanline of a pushbroom
image has its own perspective centre, so the curve is not a line; :attr:`EpipolarCurve.chord_deviation_px`
measures how far it bends away from the straight chord between its end points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from explorer.errors import InputError, check_finite
from explorer.stereo.sensors import as_sensor, localise, project

#: Height step of the curve's tangent (central difference), metres.
TANGENT_DH_M = 1.0


@dataclass(frozen=True)
class EpipolarCurve:
    """The right-image curve of left pixels over heights.

    Shapes: ``S + (K,)`` for K heights, where ``S`` is the shape of the left pixel arguments (``()`` for one
    pixel).

    Attributes
    ----------
    heights : ndarray, shape (K,)
        Ellipsoidal heights, metres.
    row, col : ndarray, shape S + (K,)
        Right-image position at each height (0-based, pixel centre); NaN where a localisation failed.
    chord_deviation_px : ndarray, shape S + (K,)
        Signed distance of each point from the straight chord between the curve's first and last points,
        pixels (positive to the left of the chord's direction in (col, row) axes).
    direction : ndarray, shape S + (K, 2)
        Unit tangent (d row, d col) of the curve at each height, pointing to increasing height.
    ground : ndarray, shape S + (K, 3)
        The ground points (ECEF, metres) on the left line of sight.
    """

    heights: np.ndarray
    row: np.ndarray
    col: np.ndarray
    chord_deviation_px: np.ndarray
    direction: np.ndarray
    ground: np.ndarray

    @property
    def max_chord_deviation_px(self) -> np.ndarray:
        """Largest absolute chord deviation per curve, shape S."""
        return np.nanmax(np.abs(self.chord_deviation_px), axis=-1)


def chord_deviation(row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """Signed distance of points ``(..., K)`` from the chord between their first and last points (pixels)."""
    dr = row[..., -1:] - row[..., :1]
    dc = col[..., -1:] - col[..., :1]
    length = np.hypot(dr, dc)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (dc * (row - row[..., :1]) - dr * (col - col[..., :1])) / length


def epipolar_curve(left: Any, right: Any, row: Any, col: Any, heights: Any) -> EpipolarCurve:
    """The exact epipolar curve in the right image of left pixel(s) over heights.

    Parameters
    ----------
    left, right : Sensor or RationalFunctionModel
        The pair (:func:`explorer.stereo.triangulate` takes the same).
    row, col : float or array_like, shape S
        Left pixel(s), 0-based pixel centre.
    heights : array_like, shape (K,)
        Ellipsoidal heights, metres (K >= 2, increasing or decreasing).

    Returns
    -------
    EpipolarCurve

    Raises
    ------
    InputError
        Fewer than two heights, or NaN/infinite inputs.
    """
    left_s = as_sensor(left, "left")
    right_s = as_sensor(right, "right")
    heights_a = check_finite(np.atleast_1d(np.asarray(heights, dtype=np.float64)), "heights").ravel()
    if heights_a.size < 2:
        raise InputError(f"heights must hold at least 2 values, got {heights_a.size}")
    row_a = check_finite(np.asarray(row, dtype=np.float64), "row")
    col_a = check_finite(np.asarray(col, dtype=np.float64), "col")
    row_a, col_a = np.broadcast_arrays(row_a, col_a)
    shape = row_a.shape
    k = heights_a.size
    rr = np.repeat(row_a.reshape(-1, 1), k, axis=1).ravel()
    cc = np.repeat(col_a.reshape(-1, 1), k, axis=1).ravel()
    hh = np.tile(heights_a, row_a.size)
    # the curve and the points half a tangent step either side, in one localisation and one projection
    all_h = np.concatenate([hh, hh - TANGENT_DH_M, hh + TANGENT_DH_M])
    ground, ok = localise(left_s, np.tile(rr, 3), np.tile(cc, 3), all_h)
    ground[~ok] = np.nan
    r_all, c_all = project(right_s, ground)
    m = hh.size
    r, c = r_all[:m], c_all[:m]
    dr = r_all[2 * m:] - r_all[m:2 * m]
    dc = c_all[2 * m:] - c_all[m:2 * m]
    norm = np.hypot(dr, dc)
    with np.errstate(invalid="ignore", divide="ignore"):
        direction = np.stack([dr / norm, dc / norm], axis=-1)
    r = r.reshape(shape + (k,))
    c = c.reshape(shape + (k,))
    return EpipolarCurve(
        heights=heights_a,
        row=r,
        col=c,
        chord_deviation_px=chord_deviation(r, c),
        direction=direction.reshape(shape + (k, 2)),
        ground=ground[:m].reshape(shape + (k, 3)),
    )


__all__ = ["EpipolarCurve", "chord_deviation", "epipolar_curve"]
