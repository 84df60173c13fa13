"""Building blocks shared by the collinearity search methods (one place for each formula).

Conventions: ``docs/conventions.md#best-scanline``.
"""

from __future__ import annotations

import numpy as np

from explorer.scene import Scene


def residual_px(scene: Scene, ground: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Along-track collinearity residual in pixels (one CE per point).

    Parameters
    ----------
    scene : Scene
    ground : ndarray, shape (N, 3)
        Local ENU metres.
    rows : ndarray, shape (N,)
        Candidate (fractional) rows.

    Returns
    -------
    ndarray, shape (N,)
        ``(x - x_detector(y)) / pitch``; positive when the point is still ahead of the
        detector line (its best scanline is a later row).
    """
    return scene.along_track_residual(ground, scene.scanline_time(rows)) / scene.pixel_size_m


def residual_and_column_px(scene: Scene, ground: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`residual_px` and the image column at the same rows, from one CE per point."""
    x, y = scene.focal_plane(ground, scene.scanline_time(rows))
    f = (x - scene.interior.detector_x(y)) / scene.pixel_size_m
    return f, scene.interior.y_to_column(y)


def changes_sign(f_lo: np.ndarray, f_hi: np.ndarray) -> np.ndarray:
    """True where a root lies in the closed interval between residuals ``f_lo`` and ``f_hi``."""
    return (np.sign(f_lo) * np.sign(f_hi)) <= 0


def weighted_mean_row(lo: np.ndarray, hi: np.ndarray, f_lo: np.ndarray, f_hi: np.ndarray) -> np.ndarray:
    """Eq. 4 of Ahooei Nezhad et al. (2020): ``(t1/|x1| + t2/|x2|) / (1/|x1| + 1/|x2|)``, shape (N,).

    Written as ``(t1 |x2| + t2 |x1|) / (|x1| + |x2|)`` so that a residual that is exactly
    zero on a line returns that line instead of NaN.  Rows are linear in time, so the
    mean is taken on rows directly.
    """
    a, b = np.abs(f_lo), np.abs(f_hi)
    s = a + b
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(s > 0, (lo * b + hi * a) / s, lo)
