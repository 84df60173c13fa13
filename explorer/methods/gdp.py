"""General (generalized) distance prediction, GDP (Geng, Xu, Xing, Lan 2019, Earth and
Space Science 6:1805-1830), as described in the introduction of Ahooei Nezhad et al.
(2024), "Best Scanline Determination of Pushbroom Images for a Direct Object to Image Space
Transformation Using Multilayer Perceptron", Remote Sensing 16:2787.

The ground point is back-projected with the exterior orientation of the **first**
scanline; the "generalized distance" between the back-projected image point and the
(possibly curved) detector line, ``x - x_detector(y)`` (the along-track collinearity
residual), converted to lines with the detector pitch (square pixels: one line is one
pitch on the focal plane), predicts how many lines away the best scanline is.  The
estimate jumps to that integer line and the prediction is repeated from there until
the predicted distance is below ``tol`` lines.  The best scanline is then found by
linear interpolation of the residual between the two bracketing integer lines (the
current line and its neighbour in the predicted direction; if the residual has no sign
change there the window is widened one line at a time), using the weighted mean of
eq. 4 of the 2020 paper (``explorer.methods._common.weighted_mean_row``), which is the
same straight-line interpolation.

Each prediction costs one collinearity evaluation (CE), the neighbour one more, and the
column at the final row one more (counted by the base class).  The result is exact up to
the linear-interpolation error over one line, ``|x''| / (8 |x'|)`` rows: below 1e-7 px on
the paper presets, about 1e-4 px under the attitude jitter of the ``agile`` preset (the
paper itself reports better than 1e-4 px).

The search window is the integer lines ``[-1, rows]``: a prediction beyond it is clipped
to its edge, and a point still predicted outside from the edge has no best scanline in
the image (``converged=False``, ``row=NaN``).  Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

from explorer.errors import InputError
from explorer.methods._common import residual_px
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.methods.hybrid import LineWindows, interpolate_in_widened_windows
from explorer.scene import Scene


@register
class GeneralDistancePrediction(BestScanlineMethod):
    """Geng et al.'s generalized distance prediction from the first scanline.

    Parameters
    ----------
    scene : Scene
    start_row : int
        Integer line the first back-projection uses (default 0, the first scanline).
    tol : float
        Stop predicting when the predicted distance is below this many lines (>= 0.5;
        default 1: the best scanline then lies between the current line and its
        neighbour, which are interpolated).
    max_iter : int
        Predictions allowed; points still moving after that get ``converged=False``.
    max_widen : int
        Extra one-line widening steps allowed when the neighbour does not bracket the root.
    """

    chunk_points = 1_000_000  # per-point work arrays (network layers / window search) grow with N

    name = "gdp"
    label = "General distance prediction (GDP)"
    reference = (
        "Geng X., Xu Q., Xing S., Lan C. (2019), A robust ground-to-image transformation algorithm and its "
        "applications in the geometric processing of linear pushbroom images, Earth and Space Science "
        "6:1805-1830, doi:10.1029/2019EA000646"
    )

    def __init__(
        self,
        scene: Scene,
        *,
        start_row: int = 0,
        tol: float = 1.0,
        max_iter: int = 30,
        max_widen: int = 16,
    ) -> None:
        super().__init__(scene, start_row=start_row, tol=tol, max_iter=max_iter, max_widen=max_widen)
        if not (-1 <= int(start_row) <= scene.n_rows) or int(start_row) != start_row:
            raise InputError(f"start_row must be an integer line in [-1, {scene.n_rows}], got {start_row}")
        if not tol >= 0.5:
            raise InputError(f"tol must be >= 0.5 lines (the estimate moves by whole lines), got {tol}")
        if int(max_iter) < 1 or int(max_widen) < 0:
            raise InputError(f"max_iter must be >= 1 and max_widen >= 0, got {max_iter}, {max_widen}")
        self.start_row = int(start_row)
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        self.max_widen = int(max_widen)
        self.setup_ce = 0

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        sc = self.scene
        n = ground.shape[0]
        line_min, line_max = -1.0, float(sc.n_rows)
        line = np.full(n, float(self.start_row))
        f_line = np.full(n, np.nan)  # residual (px) on the current line
        ce = np.zeros(n, dtype=np.int64)
        row = np.full(n, np.nan)
        converged = np.zeros(n, dtype=bool)
        ready = np.zeros(n, dtype=bool)  # predicted distance below tol: go to interpolation
        active = np.ones(n, dtype=bool)
        path: list[np.ndarray] | None = [line.copy()] if trace else None
        current = line.copy()
        iterations = 0

        # ---- distance prediction on integer lines
        for _ in range(self.max_iter):
            idx = np.flatnonzero(active)
            if idx.size == 0:
                break
            iterations += 1
            f = residual_px(sc, ground[idx], line[idx])
            ce[idx] += 1
            f_line[idx] = f
            done = np.abs(f) < self.tol
            ready[idx[done]] = True
            active[idx[done]] = False
            move = ~done
            target = np.rint(line[idx] + f)
            target = np.where(target == line[idx], line[idx] + np.sign(f), target)  # |f| >= tol >= 0.5
            new = np.clip(target, line_min, line_max)
            stalled = move & (new == line[idx])  # clipped at the window edge: the root is beyond it
            active[idx[stalled]] = False
            go = move & ~stalled
            line[idx[go]] = new[go]
            if path is not None:
                current[idx[go]] = new[go]
                path.append(current.copy())

        # ---- bracketing neighbour and linear interpolation (eq. 4)
        idx = np.flatnonzero(ready)
        if idx.size:
            g = ground[idx]
            f0 = f_line[idx]
            l0 = line[idx]
            exact = f0 == 0
            row[idx[exact]] = l0[exact]
            converged[idx[exact]] = True
            keep = ~exact
            idx, g, f0, l0 = idx[keep], g[keep], f0[keep], l0[keep]
            partner = l0 + np.sign(f0)
            inside = (partner >= line_min) & (partner <= line_max)
            idx, g, f0, l0, partner = idx[inside], g[inside], f0[inside], l0[inside], partner[inside]
            if idx.size:
                f1 = residual_px(sc, g, partner)
                ce_sub = ce[idx] + 1
                if path is not None:
                    current[idx] = partner
                    path.append(current.copy())
                interpolate_in_widened_windows(
                    sc, g, LineWindows.between(l0, partner, f0, f1), ce_sub, idx, (row, converged, ce),
                    max_steps=self.max_widen, line_min=line_min, line_max=line_max, current=current, trace=path,
                )
        if path is not None:
            path.append(row.copy())
        return self._result(ground, row, converged, ce, trace=path, info={"iterations": iterations})
