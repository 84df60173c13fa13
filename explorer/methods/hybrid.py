"""Hybrid object-space best-scanline determination (Jannati 2012), as summarised by
Ahooei Nezhad, Valadan Zoej and Jannati (2020), J. Geospatial Information Technology
8(1), section 2-4 and eq. 4 ("Accuracy improvement of best scanline search algorithms", 2020).

The method is not an iterative search; the best scanline of a ground point is
determined in three stages:

1. **Object-space approximation.**  A projective (default) or affine transformation
   ground -> row is built once, at construction, from the rigorous model: a
   ``grid_size x grid_size`` image grid (corners, edge midpoints, centre for the
   default 3) is mapped to the ground on two height planes with
   :meth:`Scene.image_to_ground`.  These ``2 * grid_size**2`` ray intersections are a
   one-off setup cost, reported in :attr:`HybridObjectSpace.setup_ce`; no control
   points are fitted.
2. **Neighbouring integer scanlines.**  The along-track collinearity component is
   evaluated at the two integer lines around the approximation; where it has no sign
   change the window is widened one line at a time, towards the smaller residual, until
   it has one (vectorised over points, at most ``max_widen`` steps).
3. **Sub-pixel interpolation** by the weighted mean of eq. 4,
   ``t = (t1/|x1| + t2/|x2|) / (1/|x1| + 1/|x2|)``, i.e. linear interpolation of the
   residual between the two lines.

The result is exact up to the linear-interpolation error over one line,
``|x''| / (8 |x'|)`` rows: below 1e-7 px on the smooth orbits of the paper presets,
about 1e-4 px under the 41-67 Hz attitude jitter of the ``agile`` preset.

Points whose root is not bracketed by integer lines in the window ``[-1, rows]``
come back with ``converged=False`` and ``row=NaN``; roots in ``[-1, -0.5)`` or
``(rows - 0.5, rows]`` are returned and flagged ``inside=False`` by the base class.
Conventions (pixel centre, row <-> time, the residual): ``docs/conventions.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from explorer.errors import InputError
from explorer.methods._common import changes_sign, residual_px, weighted_mean_row
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.scene import Scene


@dataclass
class LineWindows:
    """One-line windows ``[lo, hi]`` (integer lines, ``hi = lo + 1``) of M points and the residuals
    (px) on their two lines, all shape (M,).  :func:`widen_to_sign_change` updates them in place."""

    lo: np.ndarray
    hi: np.ndarray
    f_lo: np.ndarray
    f_hi: np.ndarray

    @classmethod
    def between(cls, a: np.ndarray, b: np.ndarray, f_a: np.ndarray, f_b: np.ndarray) -> LineWindows:
        """The windows of neighbouring lines ``a`` and ``b`` (either order) with residuals ``f_a``, ``f_b``."""
        up = b > a
        return cls(np.where(up, a, b), np.where(up, b, a), np.where(up, f_a, f_b), np.where(up, f_b, f_a))


def widen_to_sign_change(
    scene: Scene,
    ground: np.ndarray,
    windows: LineWindows,
    ce: np.ndarray,
    *,
    max_steps: int,
    line_min: float,
    line_max: float,
    current: np.ndarray | None = None,
    trace: list[np.ndarray] | None = None,
    index: np.ndarray | None = None,
) -> np.ndarray:
    """Shift a one-line window ``[lo, lo + 1]`` until the residual changes sign in it.

    Each step moves the window by one line towards the smaller ``|residual|`` and
    evaluates the residual on the new line (one CE).  Arrays are updated in place.

    Parameters
    ----------
    scene : Scene
    ground : ndarray, shape (M, 3)
        Points of the windows (already subset).
    windows : LineWindows
        The windows and their residuals, updated in place.
    ce : ndarray of int, shape (M,)
        CE counters, incremented in place.
    max_steps : int
        Widening steps allowed.
    line_min, line_max : float
        Search window: lines outside it are never evaluated.
    current, trace, index : optional
        When tracing: the full (N,) array of current candidate rows, the trace list and the
        positions (M,) of these points in it; a copy of ``current`` is appended per step.

    Returns
    -------
    ndarray of bool, shape (M,)
        True where a sign change was found.
    """
    lo, hi, f_lo, f_hi = windows.lo, windows.hi, windows.f_lo, windows.f_hi
    found = changes_sign(f_lo, f_hi)
    alive = ~found & np.isfinite(f_lo) & np.isfinite(f_hi)
    for _ in range(max_steps):
        idx = np.flatnonzero(alive)
        if idx.size == 0:
            break
        up = np.abs(f_hi[idx]) < np.abs(f_lo[idx])
        new = np.where(up, hi[idx] + 1.0, lo[idx] - 1.0)
        out = (new < line_min) | (new > line_max)
        alive[idx[out]] = False
        idx, up, new = idx[~out], up[~out], new[~out]
        if idx.size == 0:
            break
        f_new = residual_px(scene, ground[idx], new)
        ce[idx] += 1
        lo_new = np.where(up, hi[idx], new)
        hi_new = np.where(up, new, lo[idx])
        flo_new = np.where(up, f_hi[idx], f_new)
        fhi_new = np.where(up, f_new, f_lo[idx])
        lo[idx], hi[idx], f_lo[idx], f_hi[idx] = lo_new, hi_new, flo_new, fhi_new
        ok = changes_sign(flo_new, fhi_new)
        found[idx[ok]] = True
        alive[idx[ok]] = False
        if trace is not None and current is not None and index is not None:
            current[index[idx]] = new
            trace.append(current.copy())
    return found


def interpolate_in_widened_windows(
    scene: Scene,
    ground: np.ndarray,
    windows: LineWindows,
    ce_sub: np.ndarray,
    idx: np.ndarray,
    out: tuple[np.ndarray, np.ndarray, np.ndarray],
    **widen,
) -> None:
    """Finish of ``gdp`` and ``hybrid``: :func:`widen_to_sign_change` on the windows of the points
    ``idx``, then eq. 4 (:func:`~explorer.methods._common.weighted_mean_row`) where a sign change was
    found.  Writes ``row``, ``converged`` and ``ce`` of ``out = (row, converged, ce)`` at ``idx``;
    ``widen`` are the keyword arguments of :func:`widen_to_sign_change` (``index=idx`` is added)."""
    row, converged, ce = out
    found = widen_to_sign_change(scene, ground, windows, ce_sub, index=idx, **widen)
    row[idx[found]] = weighted_mean_row(windows.lo[found], windows.hi[found], windows.f_lo[found],
                                        windows.f_hi[found])
    converged[idx[found]] = True
    ce[idx] = ce_sub


@register
class HybridObjectSpace(BestScanlineMethod):
    """Jannati's three-stage hybrid object-space method (approximation, neighbours, eq. 4).

    Parameters
    ----------
    scene : Scene
    approximation : {"projective", "affine"}
        Stage-1 transformation ground (X, Y, Z) -> row.  ``"projective"``:
        ``row = (a0 + a.P) / (1 + b.P)`` (7 coefficients); ``"affine"``: ``row = a0 + a.P``
        (4 coefficients).  Both are least-squares fits on normalised coordinates.
    grid_size : int
        The image grid of stage 1 is ``grid_size x grid_size`` (>= 2; default 3: corners,
        edge midpoints, centre).
    heights : (float, float), optional
        Heights of the two grid planes, metres; default the terrain's min/max, widened to
        +-500 m around the mean when the terrain is flat.
    max_widen : int
        Stage-2 widening steps allowed (one CE each) before a point is declared
        unbracketed (``converged=False``).

    Attributes
    ----------
    setup_ce : int
        Ray/ground intersections spent once at construction (``2 * grid_size**2``).
    coefficients : ndarray
        The stage-1 transformation coefficients (normalised coordinates).
    """

    name = "hybrid"
    label = "Hybrid object-space (Jannati)"
    reference = (
        "Jannati M. (2012), MSc thesis, K. N. Toosi University of Technology; summarised in Ahooei Nezhad, "
        "Valadan Zoej, Jannati (2020), J. Geospatial Information Technology 8(1):23-38, sec. 2-4, eq. 4"
    )

    def __init__(
        self,
        scene: Scene,
        *,
        approximation: str = "projective",
        grid_size: int = 3,
        heights: tuple[float, float] | None = None,
        max_widen: int = 16,
    ) -> None:
        super().__init__(scene, approximation=approximation, grid_size=grid_size, heights=heights,
                         max_widen=max_widen)
        if approximation not in ("projective", "affine"):
            raise InputError(f"approximation must be 'projective' or 'affine', got {approximation!r}")
        if int(grid_size) < 2:
            raise InputError(f"grid_size must be >= 2, got {grid_size}")
        if int(max_widen) < 0:
            raise InputError(f"max_widen must be >= 0, got {max_widen}")
        self.approximation = approximation
        self.grid_size = int(grid_size)
        self.max_widen = int(max_widen)
        if heights is None:
            lo, hi = scene.terrain.min_height, scene.terrain.max_height
            if hi - lo < 1.0:
                lo, hi = scene.terrain.mean_height - 500.0, scene.terrain.mean_height + 500.0
            heights = (lo, hi)
        self.heights = (float(heights[0]), float(heights[1]))
        self._build_approximation()

    # ------------------------------------------------------------- stage 1
    def _build_approximation(self) -> None:
        """Map the image grid to the two height planes and fit the stage-1 transformation."""
        sc = self.scene
        rows = np.linspace(0.0, sc.n_rows - 1.0, self.grid_size)
        cols = np.linspace(0.0, sc.n_columns - 1.0, self.grid_size)
        rr, cc = (a.ravel() for a in np.meshgrid(rows, cols, indexing="ij"))
        ground = np.vstack([sc.image_to_ground(rr, cc, height=h) for h in self.heights])
        target = np.concatenate([rr] * len(self.heights))
        hit = np.isfinite(ground[:, 0])  # lines a sensor flags (e.g. past a CSM camera's tables) are left out
        if hit.sum() < 2 * ground.shape[1] + 1:
            raise ValueError(f"{sc.name}: only {int(hit.sum())} of {hit.size} approximation grid points reach the "
                             "ground")
        ground, target = ground[hit], target[hit]
        self.setup_ce = int(ground.shape[0])
        self._centre = ground.mean(axis=0)
        scale = np.abs(ground - self._centre).max(axis=0)
        scale[scale == 0] = 1.0
        self._scale = scale
        g = self._normalise(ground)
        ones = np.ones((g.shape[0], 1))
        if self.approximation == "affine":
            design = np.hstack([ones, g])
        else:  # row * (1 + b.g) = a0 + a.g  ->  linear least squares in (a0, a, b)
            design = np.hstack([ones, g, -target[:, None] * g])
        self.coefficients, *_ = np.linalg.lstsq(design, target, rcond=None)
        self.approximation_residual_px = float(np.max(np.abs(self._approximate_normalised(g) - target)))

    def _normalise(self, ground: np.ndarray) -> np.ndarray:
        return (ground - self._centre) / self._scale

    def _approximate_normalised(self, g: np.ndarray) -> np.ndarray:
        c = self.coefficients
        num = c[0] + g @ c[1:4]
        if self.approximation == "affine":
            return num
        with np.errstate(divide="ignore", invalid="ignore"):
            return num / (1.0 + g @ c[4:7])

    def approximate_rows(self, ground: np.ndarray) -> np.ndarray:
        """Stage-1 approximate rows (N,) of ground points (N, 3); no collinearity evaluation."""
        return self._approximate_normalised(self._normalise(np.asarray(ground, dtype=np.float64)))

    # ------------------------------------------------------------ stages 2-3
    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        sc = self.scene
        n = ground.shape[0]
        line_min, line_max = -1.0, float(sc.n_rows)
        r0 = self.approximate_rows(ground)
        row = np.full(n, np.nan)
        converged = np.zeros(n, dtype=bool)
        ce = np.zeros(n, dtype=np.int64)
        path: list[np.ndarray] | None = [r0.copy()] if trace else None
        current = r0.copy()

        near = np.isfinite(r0) & (r0 >= line_min - self.max_widen) & (r0 <= line_max + self.max_widen)
        idx = np.flatnonzero(near)
        if idx.size:
            g = ground[idx]
            lo = np.clip(np.floor(r0[idx]), line_min, line_max - 1.0)
            hi = lo + 1.0
            windows = LineWindows(lo, hi, residual_px(sc, g, lo), residual_px(sc, g, hi))
            m = idx.size
            ce_sub = np.full(m, 2, dtype=np.int64)
            if path is not None:
                current[idx] = lo
                path.append(current.copy())
                current[idx] = hi
                path.append(current.copy())
            interpolate_in_widened_windows(
                sc, g, windows, ce_sub, idx, (row, converged, ce), max_steps=self.max_widen,
                line_min=line_min, line_max=line_max, current=current, trace=path,
            )
        if path is not None:
            path.append(row.copy())
        return self._result(ground, row, converged, ce, trace=path,
                            info={"setup_ce": self.setup_ce, "approximate_row": r0})
