"""Newton-Raphson best-scanline search (``nr``), safeguarded by bisection.

Chen & Rau (1993), "A unified solution for digital terrain model and orthoimage generation from
SPOT stereopairs", IEEE Trans. Geosci. Remote Sens. 31(6):1243-1252, solve the first
collinearity component for the scanline time with Newton-Raphson, as restated in Ahooei Nezhad,
Valadan Zoej & Jannati (2020, eq. 3): ``f(t) = m1(t) . (P - S(t)) = 0`` with ``m1`` the first row
of the object -> sensor rotation.  For a straight detector line through the principal point that
is the same root as ``x(t) = 0``; here ``f`` is the general along-track residual
``x_d(t) - x_detector(y_d(t))`` of :meth:`explorer.scene.Scene.along_track_residual` (lens
distortion and a curved or displaced detector line included), in pixels, as a function of the
(fractional) row.

Derivative (``derivative="analytic"``, default): by the chain rule through the MPC model,
``dv/dt = v x Omega - R^T dS/dt`` with ``v = R^T (P - S)`` and ``Omega`` the body angular
velocity of ``R = R_x(omega) R_y(phi) R_z(kappa)``,
``Omega = omega' (cos phi cos kappa, -cos phi sin kappa, sin phi) + phi' (sin kappa, cos kappa, 0)
+ kappa' (0, 0, 1)``, then through ``x = -f v_x / v_z``, the radial distortion and the detector
line polynomial.  It is computed together with the residual from the same ``S(t)``, ``R(t)``
(plus ``dS/dt`` and the angle rates), so one iteration costs **one** collinearity evaluation
(CE); the derivative adds about half an evaluation's arithmetic, which shows in the timings, not
in the CE count.  ``derivative="central"`` uses instead a central difference of
:meth:`Scene.along_track_residual` over +-``fd_step_px`` rows: three CE per iteration.

Safeguard: the root is searched in the bracket ``[-0.5 - margin_px, rows - 0.5 + margin_px]``
(rows).  The residual is monotone in time over a scene, so each evaluation tells on which side
of the iterate the root lies and shrinks the bracket.  A Newton step that leaves the bracket goes
to the bracket end instead while that end is unevaluated (so a root beyond the image is detected
in one evaluation), else bisects; a step that did not reduce ``|f|`` is followed by a bisection.
Stop when the Newton step is below ``tol_px`` rows.  A point whose residual has the same sign
beyond an evaluated bracket end (root outside the bracket) gets ``converged=False`` and
``row=NaN``; a root inside the bracket but off the image (in the margin) is returned and flagged
``inside=False`` by the base class; a point still iterating after ``max_iter`` is returned at its
last iterate with ``converged=False``.

The column is taken from the focal-plane ``y`` of the last evaluation (at most ``tol_px`` rows
from the returned row, so its error is ``|dcol/drow| * tol_px``, below 1e-12 px), at no extra
CE.

Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

from explorer.geometry.collinearity import sensor_vectors
from explorer.geometry.rotations import rotation_from_opk
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.scene import CHUNK, Scene
from explorer.sensor import has_polynomial_exterior

DERIVATIVES = ("analytic", "central")
TABLE_MODEL_TOL_PX = 1e-8
"""Least step tolerance (rows) on a sensor without MPC polynomials (the round-off floor of its residual)."""
PREDICTED_STOP_MAX_STEP = 1e-2
"""On a sensor without MPC polynomials (3 CE per iteration: central differences) ``nr`` also stops when Newton's
error estimate of the next iterate, ``K step^2`` with ``K = |f''| / (2 |f'|)`` from the derivatives at the last
two iterates (times :data:`PREDICTED_STOP_SAFETY`), is below ``tol_px`` and the step is below this many rows:
its column is then evaluated at the returned row (1 CE) instead of a further iteration (3 CE).  Without it
``nr`` took 3-4 iterations (9-12 CE) on the Pleiades DIMAP model where the second one had already landed
within its round-off (measured 11.3 CE per point)."""
PREDICTED_STOP_SAFETY = 10.0


def residual_and_derivative(
    scene: Scene, ground: np.ndarray, rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along-track residual, its derivative with respect to the row, and the column (one CE).

    Parameters
    ----------
    scene, ground, rows
        As :func:`explorer.methods._common.residual_px`: the scene, ground points (N, 3) in local ENU
        metres and fractional rows (N,).

    Returns
    -------
    f : ndarray, shape (N,)
        ``x_d - x_detector(y_d)`` in pixels (equal to ``Scene.along_track_residual / pitch``).
    dfdr : ndarray, shape (N,)
        ``df / d row``, pixels per row (analytic).
    col : ndarray, shape (N,)
        Column of the point at that row.
    """
    n = ground.shape[0]
    if n > CHUNK:  # bound the (N, 3, 3) work arrays like Scene.focal_plane does
        out = [np.empty(n) for _ in range(3)]
        for a in range(0, n, CHUNK):
            sl = slice(a, min(a + CHUNK, n))
            for o, r in zip(out, residual_and_derivative(scene, ground[sl], rows[sl]), strict=True):
                o[sl] = r
        return out[0], out[1], out[2]
    ext, inner = scene.exterior, scene.interior
    t = scene.scanline_time(rows)
    s = ext.position(t)
    s_dot = ext.velocity(t)
    ang = ext.angles(t)
    rate = ext.angle_rates(t)
    rot = rotation_from_opk(ang[:, 0], ang[:, 1], ang[:, 2])
    v = sensor_vectors(ground, s, rot)
    sp, cp = np.sin(ang[:, 1]), np.cos(ang[:, 1])
    sk, ck = np.sin(ang[:, 2]), np.cos(ang[:, 2])
    omega_body = np.stack(
        [
            rate[:, 0] * cp * ck + rate[:, 1] * sk,
            -rate[:, 0] * cp * sk + rate[:, 1] * ck,
            rate[:, 0] * sp + rate[:, 2],
        ],
        axis=-1,
    )
    v_dot = np.cross(v, omega_body) - np.einsum("nji,nj->ni", rot, s_dot)
    foc = inner.focal_length_m
    vz = v[:, 2]
    x = -foc * v[:, 0] / vz
    y = -foc * v[:, 1] / vz
    x_dot = -foc * (v_dot[:, 0] * vz - v[:, 0] * v_dot[:, 2]) / (vz * vz)
    y_dot = -foc * (v_dot[:, 1] * vz - v[:, 1] * v_dot[:, 2]) / (vz * vz)
    xd, yd = inner.distort(x, y)
    if inner.radial_distortion:
        r2 = x * x + y * y
        r2_dot = 2.0 * (x * x_dot + y * y_dot)
        fac = np.ones_like(r2)
        fac_dot = np.zeros_like(r2)
        power = np.ones_like(r2)  # r2 ** (i - 1)
        for i, k in enumerate(inner.radial_distortion, start=1):
            fac_dot = fac_dot + i * k * power * r2_dot
            power = power * r2
            fac = fac + k * power
        xd_dot = x_dot * fac + x * fac_dot
        yd_dot = y_dot * fac + y * fac_dot
    else:
        xd_dot, yd_dot = x_dot, y_dot
    slope = np.zeros_like(yd)  # d x_detector / d y at yd
    power = np.ones_like(yd)
    for k, c in enumerate(inner.line_curvature, start=1):
        slope = slope + k * c * power
        power = power * yd
    pitch = scene.pixel_size_m
    f = (xd - inner.detector_x(yd)) / pitch
    dfdr = (xd_dot - slope * yd_dot) * (scene.timing.line_period_s / pitch)
    return f, dfdr, inner.y_to_column(yd)


def _kernel_params(scene: Scene, *, required: bool):
    """The scene packed for the compiled kernels, or None where they do not apply (no numba, not an
    MPC scene) and ``required`` is False."""
    from explorer.geometry.kernels import NUMBA_AVAILABLE, collinearity_params_or_none

    params = collinearity_params_or_none(scene)
    if params is None and required:
        reason = "numba is not available" if not NUMBA_AVAILABLE else f"{scene.name} is not an MPC scene"
        raise ValueError(f"evaluator='compiled' does not apply: {reason}")
    return params


@register
class NewtonRaphson(BestScanlineMethod):
    """Safeguarded Newton-Raphson on the along-track collinearity residual (Chen & Rau 1993).

    See the module docstring for the iteration, the safeguard and the CE accounting.

    Parameters
    ----------
    scene : Scene
    start : {"reference", "centre"} or float
        Initial row: the scene's reference row (``t = 0``, default), the image centre
        ``(rows - 1) / 2`` or a given row.
    tol_px : float
        Stop when the Newton step is below this many rows (default 1e-10).
    max_iter : int
        Iterations (evaluations) per point before giving up with ``converged=False`` (default 50).
    margin_px : float
        The bracket extends this many rows beyond the image edges (default 1.0): roots there are
        found and flagged outside; roots farther out give ``converged=False``.
    derivative : {"analytic", "central"}
        Analytic chain-rule derivative (1 CE per iteration, default) or a central difference of
        the residual over +-``fd_step_px`` rows (3 CE per iteration).  A sensor without MPC polynomials
        (``has_polynomial_exterior`` False: rigorous DIMAP / DG models, CSM cameras) always takes the central
        difference of its own residual: the analytic derivative is the MPC collinearity's.
    fd_step_px : float
        Step of the central difference, rows (default 0.5).
    evaluator : {"auto", "compiled", "numpy"}
        ``"compiled"``: the whole iteration of each point in one numba ``prange`` loop
        (:func:`explorer.geometry.newton_kernel.solve_newton_raphson`; MPC scenes, numba); ``"numpy"``:
        the plain vectorised loop over the points still iterating (the naive baseline of
        ``docs/performance.md``); ``"auto"`` (default): compiled where it applies, else numpy.  Same
        iteration and decisions either way; the residuals differ by round-off (about 1e-10 px).
        Traces (``trace=True``) and ``derivative="central"`` always use the numpy loop.
    """

    name = "nr"
    label = "Newton-Raphson (NR)"
    reference = (
        "Chen & Rau (1993), A unified solution for digital terrain model and orthoimage generation "
        "from SPOT stereopairs, IEEE TGRS 31(6):1243-1252"
    )

    def __init__(
        self,
        scene: Scene,
        *,
        start: str | float = "reference",
        tol_px: float = 1e-10,
        max_iter: int = 50,
        margin_px: float = 1.0,
        derivative: str = "analytic",
        fd_step_px: float = 0.5,
        evaluator: str = "auto",
    ) -> None:
        if evaluator not in ("auto", "compiled", "numpy"):
            raise ValueError(f"evaluator must be 'auto', 'compiled' or 'numpy', got {evaluator!r}")
        if evaluator == "compiled" and derivative != "analytic":
            raise ValueError("the compiled evaluator gives the analytic derivative only")
        if derivative not in DERIVATIVES:
            raise ValueError(f"derivative must be one of {DERIVATIVES}, got {derivative!r}")
        if not (tol_px > 0 and max_iter >= 1 and margin_px >= 0 and fd_step_px > 0):
            raise ValueError("tol_px and fd_step_px must be > 0, max_iter >= 1 and margin_px >= 0")
        if isinstance(start, str) and start not in ("reference", "centre"):
            raise ValueError(f"start must be 'reference', 'centre' or a row, got {start!r}")
        super().__init__(scene, start=start, tol_px=tol_px, max_iter=max_iter, margin_px=margin_px,
                         derivative=derivative, fd_step_px=fd_step_px, evaluator=evaluator)
        self.evaluator = evaluator
        self.kernel_params = None
        if evaluator != "numpy" and derivative == "analytic":
            self.kernel_params = _kernel_params(scene, required=evaluator == "compiled")
        if self.kernel_params is None:
            self.chunk_points = 1_000_000  # the numpy active-set loop keeps several (N,) arrays per iteration
        if derivative == "analytic" and not has_polynomial_exterior(scene):
            # the analytic chain rule is that of the MPC collinearity; a sensor with interpolated tables and its
            # own lines of sight (aberration, refraction; a CSM camera) has its own residual, which the central
            # difference differentiates exactly as the model defines it
            derivative = "central"
            # and the residual of such a model (interpolated tables, iterated corrections) carries round-off of
            # a few 1e-10 px, so a step below 1e-10 rows is not always reached: its floor is the tolerance
            tol_px = max(float(tol_px), TABLE_MODEL_TOL_PX)
        #: Stop when Newton's own error estimate of the next iterate is below ``tol_px`` (table models: see
        #: :data:`PREDICTED_STOP_MAX_STEP`), not only when a step is.
        #: Only where the sensor declares its root resolution (a rigorous DIMAP / DG model): on a CSM camera the
        #: estimate from two iterates' derivatives stopped 7e-6 rows short (tests/test_explore_export.py).
        self.predicted_stop = getattr(scene, "root_resolution_rows", None) is not None
        self.start = start
        self.tol_px = float(tol_px)
        self.max_iter = int(max_iter)
        self.margin_px = float(margin_px)
        self.derivative = derivative
        self.fd_step_px = float(fd_step_px)

    @property
    def start_row(self) -> float:
        """The initial row of every point."""
        if self.start == "reference":
            return float(self.scene.timing.reference_row)
        if self.start == "centre":
            return (self.scene.n_rows - 1) / 2.0
        return float(self.start)

    @property
    def bracket(self) -> tuple[float, float]:
        """(lowest, highest) row searched."""
        return -0.5 - self.margin_px, self.scene.n_rows - 0.5 + self.margin_px

    def _evaluate(self, ground: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """Residual (px), derivative (px/row), column and the CE spent per point."""
        if self.kernel_params is not None:  # compiled evaluation inside the numpy loop (traces)
            from explorer.geometry.kernels import residual_and_rate

            sc = self.scene
            g, g_t, c = residual_and_rate(self.kernel_params, ground, sc.scanline_time(rows))
            return g / sc.pixel_size_m, g_t * (sc.timing.line_period_s / sc.pixel_size_m), c, 1
        if self.derivative == "analytic":
            f, d, c = residual_and_derivative(self.scene, ground, rows)
            return f, d, c, 1
        sc, h = self.scene, self.fd_step_px
        x, y = sc.focal_plane(ground, sc.scanline_time(rows))
        f = (x - sc.interior.detector_x(y)) / sc.pixel_size_m
        fp = sc.along_track_residual(ground, sc.scanline_time(rows + h)) / sc.pixel_size_m
        fm = sc.along_track_residual(ground, sc.scanline_time(rows - h)) / sc.pixel_size_m
        return f, (fp - fm) / (2.0 * h), sc.interior.y_to_column(y), 3

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        n = ground.shape[0]
        lo0, hi0 = self.bracket
        start = self.start_row
        if not lo0 <= start <= hi0:
            raise ValueError(f"start row {start} is outside the bracket [{lo0}, {hi0}]")
        if self.kernel_params is not None and not trace:
            from explorer.geometry.newton_kernel import solve_newton_raphson

            row, col, converged, ce = solve_newton_raphson(
                self.kernel_params, ground, start_row=start, bracket=(lo0, hi0), tol=self.tol_px,
                max_iter=self.max_iter,
            )
            info = {"iterations": ce, "start_row": start, "bracket": (lo0, hi0), "evaluator": "compiled"}
            return self._result(ground, row, converged, ce, col=col, info=info)
        row_out = np.full(n, np.nan)
        col_out = np.full(n, np.nan)
        converged = np.zeros(n, dtype=bool)
        ce = np.zeros(n, dtype=np.int64)
        iterations = np.zeros(n, dtype=np.int64)
        tr: list[np.ndarray] | None = [] if trace else None

        # active-set state (arrays over the points still iterating)
        act = np.arange(n)
        g = ground
        t = np.full(n, start)
        lo = np.full(n, lo0)
        hi = np.full(n, hi0)
        lo_known = np.zeros(n, dtype=bool)  # bracket end evaluated (root proven on its right)
        hi_known = np.zeros(n, dtype=bool)
        f_prev = np.full(n, np.inf)
        t_last = np.full(n, np.nan)  # the previous iterate and its derivative (Newton's error estimate)
        fd_last = np.full(n, np.nan)
        predicted = np.zeros(n, dtype=bool)  # stopped on the error estimate: column evaluated at the row
        for _ in range(self.max_iter):
            if not act.size:
                break
            f, fd, col, cost = self._evaluate(g, t)
            ce[act] += cost
            iterations[act] += 1
            if tr is not None:
                rec = np.full(n, np.nan)
                rec[act] = t
                tr.append(rec)
            col_out[act] = col
            row_out[act] = t  # best estimate so far (kept for max_iter failures)
            # which side of t holds the root (monotone residual): root below t when f and f' agree
            below = (f * fd) > 0
            exact = f == 0.0
            hi = np.where(below, t, hi)
            hi_known |= below
            lo = np.where(~below & ~exact, t, lo)
            lo_known |= ~below & ~exact
            # root beyond an evaluated image end: no root in the bracket
            outside = ~exact & (lo >= hi)
            fd_ok = np.isfinite(fd) & (fd != 0.0)
            step = np.where(fd_ok, f / np.where(fd_ok, fd, 1.0), np.inf)
            t_newton = t - step
            done = (exact | (np.abs(step) < self.tol_px)) & ~outside
            if self.predicted_stop:
                with np.errstate(divide="ignore", invalid="ignore"):
                    k_est = np.abs(fd - fd_last) / np.abs(t - t_last) / (2.0 * np.abs(fd))
                near = (np.isfinite(k_est) & (np.abs(step) < PREDICTED_STOP_MAX_STEP) & (t_newton > lo)
                        & (t_newton < hi) & (np.abs(f) < f_prev)
                        & (PREDICTED_STOP_SAFETY * k_est * step * step < self.tol_px))
                landed = near & ~done & ~outside
                predicted[act[landed]] = True
                done |= landed
            row_out[act[done]] = np.where(exact[done], t[done], t_newton[done])
            converged[act[done]] = True
            row_out[act[outside]] = np.nan
            col_out[act[outside]] = np.nan
            # next iterate: Newton, or the unevaluated bracket end it overshoots, or bisection
            slow = np.abs(f) >= f_prev
            leave_hi = ~(t_newton < hi)
            leave_lo = ~(t_newton > lo)
            t_next = np.where(slow | ~fd_ok, 0.5 * (lo + hi), t_newton)
            t_next = np.where(~slow & fd_ok & leave_hi, np.where(hi_known, 0.5 * (lo + hi), hi), t_next)
            t_next = np.where(~slow & fd_ok & leave_lo, np.where(lo_known, 0.5 * (lo + hi), lo), t_next)
            keep = ~(done | outside)
            act, g = act[keep], g[keep]
            t_last, fd_last = t[keep], fd[keep]
            t, lo, hi = t_next[keep], lo[keep], hi[keep]
            lo_known, hi_known, f_prev = lo_known[keep], hi_known[keep], np.abs(f[keep])
        # points still active hit max_iter: last iterate, converged False (already stored)
        if predicted.any():  # the column at the returned row (the last evaluation was a Newton step away)
            idx = np.flatnonzero(predicted)
            _, y = self.scene.focal_plane(ground[idx], self.scene.scanline_time(row_out[idx]))
            col_out[idx] = self.scene.interior.y_to_column(y)
            ce[idx] += 1
        info = {"iterations": iterations, "start_row": start, "bracket": (lo0, hi0), "evaluator": "numpy",
                "predicted_stop": predicted}
        return self._result(ground, row_out, converged, ce, col=col_out, trace=tr, info=info)
