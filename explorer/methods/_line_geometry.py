"""Root finders on the line geometry of any line-scan sensor, vectorised over points.

The compiled kernels of ``exact`` and ``csm-secant`` (:mod:`explorer.geometry.kernels`) pack MPC
polynomials (``has_polynomial_exterior``).  A sensor whose exterior is interpolated tables -- a rigorous
DIMAP / DigitalGlobe model (:class:`~explorer.real.linescan.RigorousLineScanScene`), a USGS CSM camera
(:class:`~explorer.real.csm_sensor.CsmScene`) -- declares only the line geometry
(``has_line_geometry``): its along-track residual and column at a row, one collinearity evaluation (CE)
per point, through :meth:`~explorer.scene.Scene.focal_plane` (compiled for a CSM camera, numpy for the
rigorous models).  The solvers here iterate over *all unresolved points at once*: one call of the residual
per iteration, never a Python loop over points.

* :func:`solve_bracketed_secant` -- ``exact`` on line geometry: a seed row, then secant steps kept inside a
  bracket that every evaluation narrows (the residual is monotone in the row over a scene); a step that
  leaves the bracket probes the unevaluated window end once, else bisects.  Converged when a step is below
  ``tol`` rows; the row and column are those of the last evaluation.  Interpolated tables have no
  analytic time derivative, so the Newton step of ``exact`` is replaced by the secant through the last two
  evaluations (superlinear, order 1.6).
* :func:`solve_usgscsm_secant` -- ``csm-secant`` on line geometry: usgscsm's iteration as restated in
  :mod:`explorer.methods.csm_secant` (probe at +0.1 line, secant while the residual exceeds the precision,
  at most ``max_count`` steps), on the sensor's own residual.

Status codes are those of :mod:`explorer.geometry.kernels` (0 converged, 1 no root in the window,
2 behind the camera / invalid, 3 iteration limit).
"""

from __future__ import annotations

import numpy as np

from explorer.geometry.kernels import (
    STATUS_CONVERGED,
    STATUS_INVALID,
    STATUS_MAX_ITER,
    STATUS_NO_ROOT_IN_WINDOW,
)
from explorer.methods._common import residual_and_column_px
from explorer.scene import Scene


def residual_slope(scene: Scene, ground: np.ndarray, rows: np.ndarray) -> float:
    """Median ``d residual / d row`` (pixels per row) at points (N, 3) seen at rows (N,) (2 CE per point);
    its sign is the residual's orientation."""
    f1, _ = residual_and_column_px(scene, ground, rows + 0.5)
    f0, _ = residual_and_column_px(scene, ground, rows - 0.5)
    d = f1 - f0
    d = d[np.isfinite(d)]
    if d.size == 0 or not np.all(np.sign(d) == np.sign(d[0])) or d[0] == 0:
        raise ValueError(f"{scene.name}: the along-track residual is not monotone in the row near the image")
    return float(np.median(d))


def solve_bracketed_secant(
    scene: Scene, ground: np.ndarray, seed: np.ndarray, *, window: tuple[float, float], slope: float,
    tol: float = 1e-10, max_iter: int = 60,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Safeguarded secant on the residual from seed rows (see the module docstring).

    Parameters
    ----------
    scene : Scene
        Any scene with line geometry (its :meth:`~explorer.scene.Scene.focal_plane`).
    ground : ndarray (N, 3)
        Local ENU metres.
    seed : ndarray (N,)
        Starting rows.
    window : (float, float)
        Search window of rows.
    slope : float
        ``d residual / d row`` (pixels per row; its sign orients the bracket).
    tol : float
        Converged when a step is below this many rows.
    max_iter : int
        Residual evaluations per point at most.

    Returns
    -------
    row, col : ndarray (N,)
        NaN unless converged.
    status : ndarray of int8 (N,)
    evaluations : ndarray of int64 (N,)
    """
    n = ground.shape[0]
    lo_w, hi_w = float(window[0]), float(window[1])
    orient = 1.0 if slope > 0 else -1.0
    row = np.full(n, np.nan)
    col = np.full(n, np.nan)
    status = np.full(n, STATUS_MAX_ITER, np.int8)
    ce = np.zeros(n, np.int64)
    if n == 0:
        return row, col, status, ce
    # bracket [lo, hi]; *_seen: the end was evaluated (its sign is known)
    lo = np.full(n, lo_w)
    hi = np.full(n, hi_w)
    lo_seen = np.zeros(n, bool)
    hi_seen = np.zeros(n, bool)
    x1 = np.clip(np.where(np.isfinite(seed), seed, 0.5 * (lo_w + hi_w)), lo_w, hi_w)
    f1, c1 = residual_and_column_px(scene, ground, x1)
    ce += 1
    x0 = np.full(n, np.nan)
    f0 = np.full(n, np.nan)
    active = np.arange(n)
    bad = ~np.isfinite(f1)
    status[bad] = STATUS_INVALID
    for it in range(max_iter):
        keep = np.isfinite(f1[active]) if it == 0 else np.ones(active.size, bool)
        a = active[keep]
        if a.size == 0:
            break
        fa, xa = f1[a], x1[a]
        # narrow the bracket with the newest evaluation
        below = fa * orient < 0  # the root lies above xa
        above = fa * orient > 0
        exact = fa == 0
        lo[a[below]] = xa[below]
        lo_seen[a[below]] = True
        hi[a[above]] = xa[above]
        hi_seen[a[above]] = True
        done = exact.copy()
        # a window end evaluated on the wrong side: no root in the window
        none = (below & (xa >= hi_w)) | (above & (xa <= lo_w))
        status[a[none]] = STATUS_NO_ROOT_IN_WINDOW
        # converged: the last step was below tol
        step_ok = np.isfinite(x0[a]) & (np.abs(xa - x0[a]) <= tol)
        done |= step_ok & ~none
        fin = a[done]
        row[fin], col[fin], status[fin] = x1[fin], c1[fin], STATUS_CONVERGED
        a = a[~(done | none)]
        if a.size == 0:
            active = a
            break
        # next iterate: secant through the last two evaluations, else a slope step, kept inside the bracket
        xa, fa = x1[a], f1[a]
        with np.errstate(divide="ignore", invalid="ignore"):
            sec = xa - fa * (xa - x0[a]) / (fa - f0[a])
        nxt = np.where(np.isfinite(sec), sec, xa - fa / slope)
        inside = (nxt > lo[a]) & (nxt < hi[a])
        # outside the bracket: the unevaluated end of the window that lies that way, else bisect
        go_hi = nxt >= hi[a]
        probe = np.where(go_hi, hi[a], lo[a])
        probe_unseen = np.where(go_hi, ~hi_seen[a], ~lo_seen[a])
        mid = 0.5 * (lo[a] + hi[a])
        nxt = np.where(inside, nxt, np.where(probe_unseen, probe, mid))
        f_new, c_new = residual_and_column_px(scene, ground[a], nxt)
        ce[a] += 1
        lost = ~np.isfinite(f_new)  # behind the camera: bisect towards the evaluated side instead
        if lost.any():
            m2 = 0.5 * (xa[lost] + nxt[lost])
            f2, c2 = residual_and_column_px(scene, ground[a[lost]], m2)
            ce[a[lost]] += 1
            nxt[lost], f_new[lost], c_new[lost] = m2, f2, c2
            dead = ~np.isfinite(f_new)
            status[a[dead]] = STATUS_INVALID
            a_ok = ~dead
            a, xa, fa, nxt, f_new, c_new = a[a_ok], xa[a_ok], fa[a_ok], nxt[a_ok], f_new[a_ok], c_new[a_ok]
        x0[a], f0[a] = xa, fa
        x1[a], f1[a], c1[a] = nxt, f_new, c_new
        active = a
    return row, col, status, ce


def solve_usgscsm_secant(
    scene: Scene, ground: np.ndarray, seed: np.ndarray, *, precision: float, first_step: float, max_count: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """usgscsm's secant (:mod:`explorer.methods.csm_secant`) on the scene's residual, vectorised over points.

    Returns
    -------
    row : ndarray (N,)
        ``seed + dt1`` (the estimate, also where the precision was not met).
    col : ndarray (N,)
        The column at that row (one more evaluation).
    ok : ndarray of bool (N,)
        ``|e1| <= precision``.
    evaluations : ndarray of int64 (N,)
    """
    n = ground.shape[0]
    dt0 = np.zeros(n)
    dt1 = np.full(n, float(first_step))
    e0, _ = residual_and_column_px(scene, ground, seed + dt0)
    e1, _ = residual_and_column_px(scene, ground, seed + dt1)
    ce = np.full(n, 2, np.int64)
    active = np.flatnonzero(np.abs(e1) > precision)
    count = 0
    while active.size and count + 1 < max_count:
        count += 1
        a = active
        stall = e1[a] == e0[a]
        a = a[~stall & np.isfinite(e1[a]) & np.isfinite(e0[a])]
        if a.size == 0:
            break
        dt2 = dt1[a] - e1[a] * (dt1[a] - dt0[a]) / (e1[a] - e0[a])
        e2, _ = residual_and_column_px(scene, ground[a], seed[a] + dt2)
        ce[a] += 1
        dt0[a], e0[a] = dt1[a], e1[a]
        dt1[a], e1[a] = dt2, e2
        active = a[np.abs(e2) > precision]
    row = seed + dt1
    ok = np.abs(e1) <= precision
    col = np.full(n, np.nan)
    fin = np.flatnonzero(np.isfinite(row))
    col[fin] = residual_and_column_px(scene, ground[fin], row[fin])[1]
    ce[fin] += 1
    return row, col, ok, ce
