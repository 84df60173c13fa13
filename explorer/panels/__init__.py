"""Colour scales shared by the explorer's Plotly panels and its 3D scene.

This module is plotly-free and viser-free (numpy only), so the 3D scene
(:mod:`explorer.scene3d.builders`) and the Plotly figures
(:mod:`explorer.panels.figures`) colour a residual with exactly the same ramp:

* :data:`DIVERGING` -- signed scanline residuals, blue (negative) -> light grey (0)
  -> red (positive), Moreland's "cool to warm" map.  Always used with a symmetric
  limit ``[-L, +L]`` pixels centred at 0 (values beyond are clipped to the ends).
* :data:`HEIGHT` -- terrain height ramp (dark green -> brown -> snow).
* :data:`ITERATION` -- order of the scanlines a search method visited (first pale
  yellow -> last dark purple).

Each scale is a list of ``(position in [0, 1], (r, g, b))`` stops; :func:`ramp`
interpolates it linearly and :func:`plotly_colorscale` writes it the way Plotly
wants (a list of ``[position, "rgb(r,g,b)"]``).  Residual conventions:
``docs/conventions.md``; the explorer itself: ``docs/explorer.md``.
"""

from __future__ import annotations

import numpy as np

Stops = list[tuple[float, tuple[int, int, int]]]


def _evenly_spaced(*colours: tuple[int, int, int]) -> Stops:
    """A scale of ``colours`` at equal steps from position 0 to 1."""
    return [(k / (len(colours) - 1), rgb) for k, rgb in enumerate(colours)]


DIVERGING: Stops = _evenly_spaced(
    (59, 76, 192), (98, 130, 234), (141, 176, 254), (184, 208, 249), (221, 221, 221),
    (245, 196, 173), (244, 154, 123), (222, 96, 77), (180, 4, 38),
)
"""Signed residual scale: index 0 is the blue (negative) end, index -1 the red (positive) end."""

HEIGHT: Stops = [
    (0.0, (46, 94, 62)),
    (0.3, (112, 148, 82)),
    (0.6, (176, 150, 98)),
    (0.85, (150, 120, 100)),
    (1.0, (245, 245, 240)),
]
"""Terrain height ramp from the lowest (index 0) to the highest (index -1) height."""

ITERATION: Stops = _evenly_spaced((253, 231, 37), (33, 145, 140), (68, 1, 84))
"""First (index 0) to last (index -1) iteration of a search."""

FLAT_GROUND_RGB = (150, 162, 140)
"""Ground colour when the terrain is flat (no relief to ramp)."""
INVALID_RGB = (255, 0, 255)
"""Points a method flags as not converged or outside the image (no residual)."""
SCOP_RGB = (255, 200, 0)
"""Simulated control points."""

NEGATIVE_END = DIVERGING[0][1]
POSITIVE_END = DIVERGING[-1][1]


def ramp(values: np.ndarray, stops: Stops, lo: float, hi: float) -> np.ndarray:
    """Map values linearly onto a colour scale.

    Parameters
    ----------
    values : ndarray, shape (N,)
        Any real values; NaN maps to :data:`INVALID_RGB`.
    stops : list of (float, (int, int, int))
        Colour scale (positions increasing from 0 to 1).
    lo, hi : float
        Values mapped to the first and last stop; values outside are clipped.

    Returns
    -------
    ndarray of uint8, shape (N, 3)
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    span = hi - lo
    finite = np.isfinite(v)
    u = np.zeros_like(v) if span <= 0 else np.clip((np.where(finite, v, lo) - lo) / span, 0.0, 1.0)
    pos = np.array([s[0] for s in stops])
    rgb = np.array([s[1] for s in stops], dtype=np.float64)
    out = np.stack([np.interp(u, pos, rgb[:, k]) for k in range(3)], axis=1)
    out = np.rint(out).astype(np.uint8)
    out[~finite] = INVALID_RGB
    return out


def diverging_rgb(residual_px: np.ndarray, limit_px: float) -> np.ndarray:
    """Colours (N, 3) uint8 of signed residuals on :data:`DIVERGING` over ``[-limit, +limit]``.

    0 maps to the light-grey centre, ``>= +limit`` to the red end, ``<= -limit`` to
    the blue end, NaN to :data:`INVALID_RGB`.
    """
    if not limit_px > 0:
        raise ValueError(f"colour limit must be positive, got {limit_px}")
    return ramp(residual_px, DIVERGING, -limit_px, limit_px)


ROBUST_PERCENTILE = 99.0
"""Percentile of |residual| that sets an automatic colour limit (outliers saturate)."""
LOG_MAGNITUDE: Stops = _evenly_spaced((13, 8, 135), (126, 3, 168), (204, 71, 120), (248, 149, 64), (240, 249, 33))
"""Sequential scale (plasma) of log10 |residual|: small (index 0) to large (index -1)."""


def robust_limit(values: np.ndarray, percentile: float = ROBUST_PERCENTILE) -> float:
    """Automatic symmetric colour limit of signed residuals: the ``percentile`` of |value|.

    Scale-free, so residuals of 1e-10 px and of 10 px both fill their scale.  Falls back to
    the largest |value| when the percentile is 0, and to 1e-12 when every value is 0 or none is
    finite (the scale then shows a uniform zero honestly).

    Parameters
    ----------
    values : ndarray, shape (N,)
        Residuals, pixels; NaN ignored.
    percentile : float

    Returns
    -------
    float
        Limit L > 0, pixels: the scale spans ``[-L, +L]``.
    """
    a = np.abs(np.asarray(values, dtype=np.float64).ravel())
    a = a[np.isfinite(a)]
    if a.size == 0:
        return 1e-12
    lim = float(np.percentile(a, percentile))
    if not lim > 0:
        lim = float(a.max())
    return lim if lim > 0 else 1e-12


def percent_text(count: int, total: int) -> str:
    """``count`` of ``total`` as a percentage in words: ``"3.09 %"``, ``"100 %"``, ``"0.002 %"``;
    never exponent notation, and never "100 %" / "0 %" unless every / no point is counted."""
    total = max(int(total), 1)
    if count >= total:
        return "100 %"
    if count <= 0:
        return "0 %"
    p = 100.0 * count / total
    if p >= 99.9:
        return ">99.9 %"
    if p < 0.001:
        return "<0.001 %"
    digits = max(0, 2 - int(np.floor(np.log10(p))))  # three significant digits
    return f"{p:.{digits}f}".rstrip("0").rstrip(".") + " %"


def count_text(count: int, total: int) -> str:
    """``"2 of 40,000"`` for one or two points (a percentage of so few says nothing), else
    ``"1,234 (3.09 %)"`` (:func:`percent_text`)."""
    if count <= 2:
        return f"{count} of {total:,}"
    return f"{count:,} ({percent_text(count, total)})"


def height_rgb(height_m: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Colours (N, 3) uint8 of terrain heights on :data:`HEIGHT`; flat ground if ``hi <= lo``."""
    h = np.asarray(height_m, dtype=np.float64).ravel()
    if not hi > lo:
        return np.tile(np.array(FLAT_GROUND_RGB, dtype=np.uint8), (h.size, 1))
    return ramp(h, HEIGHT, lo, hi)


def plotly_colorscale(stops: Stops) -> list[list]:
    """The scale as Plotly's ``[[position, "rgb(r,g,b)"], ...]``."""
    return [[float(p), f"rgb({r},{g},{b})"] for p, (r, g, b) in stops]


def rgb_string(rgb: tuple[int, int, int]) -> str:
    """``"rgb(r,g,b)"`` for Plotly."""
    return "rgb({},{},{})".format(*(int(c) for c in rgb))


__all__ = [
    "DIVERGING", "FLAT_GROUND_RGB", "HEIGHT", "INVALID_RGB", "ITERATION", "LOG_MAGNITUDE", "NEGATIVE_END",
    "POSITIVE_END", "ROBUST_PERCENTILE", "SCOP_RGB", "count_text", "percent_text", "diverging_rgb", "height_rgb",
    "plotly_colorscale", "ramp", "rgb_string", "robust_limit",
]
