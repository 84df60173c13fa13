"""Central perspective plane (CPP) best-scanline search (Wang, Hu, Li, Pan 2009,
Photogramm. Eng. Remote Sens. 75:1059-1067), as described in the introductions of
Ahooei Nezhad et al., "Best Scanline Determination of Pushbroom Images for a Direct Object to
Image Space Transformation Using Multilayer Perceptron" (2024, Remote Sensing 16:2787) and "A Linear
Regression Approach for Best Scanline Determination" (2024, Sensors 24:5594).

The central perspective plane of scanline ``t`` is the plane through the perspective
centre ``S(t)`` that contains the lines of sight of the whole detector line.  For a
straight detector line at along-track offset ``x0`` it is spanned by
``R(t) (x0, 0, -f)`` and ``R(t) (0, 1, 0)``, so its unit normal is
``n(t) = R(t) (f, 0, x0) / sqrt(f^2 + x0^2)``.  A ground point ``P`` lies on the plane of
its best scanline; the signed distance

    d(t) = n(t) . (P - S(t)) = (f v_x + x0 v_z) / sqrt(f^2 + x0^2),   v = R(t)^T (P - S(t)),

is converted to a row step by the plane distance per line: the first step uses the
distance between the planes of two adjacent lines through the image-centre ground
point (measured once at construction, :attr:`CentralPerspectivePlane.line_step_m`), the
following steps the secant of the last two distances (``t <- t - d / (dd/dt)``), until
the step is below ``tol`` rows.  Each plane distance needs ``S(t)`` and ``R(t)`` -- the
expensive part of a collinearity evaluation -- and is counted as one CE.

Since ``x - x0 = -sqrt(f^2 + x0^2) d / v_z`` the plane root is the exact best scanline for
a straight, undistorted detector line.  For a curved line or lens distortion the
"plane" is really a curved surface (the limitation the 2024 papers point out), and a
collinearity refinement follows: a Newton step on the along-track residual with the
slope carried over from the plane iteration (``dx/dt = -sqrt(f^2 + x0^2) (dd/dt) / v_z``),
then secant steps, one CE each, until the step is below ``refine_tol``.  By default
(``refine=None``) the refinement runs only when the detector is not a straight
undistorted line, or the sensor's lines of sight are its own (no MPC polynomials: a rigorous model with
aberration / refraction, a CSM camera), whose residual the planes do not reproduce.

Roots outside the window of rows ``[-1, rows]`` (the model extrapolated beyond the
image) are returned as the method's estimate with ``converged=False``; the base class
flags them ``inside=False``.  Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

from explorer.errors import InputError
from explorer.geometry.collinearity import sensor_vectors
from explorer.methods._common import residual_px
from explorer.methods.base import BestScanlineMethod, ScanlineResult, register
from explorer.scene import CHUNK, Scene
from explorer.sensor import has_polynomial_exterior


@register
class CentralPerspectivePlane(BestScanlineMethod):
    """Wang et al.'s central-perspective-plane search with a collinearity refinement.

    Parameters
    ----------
    scene : Scene
    start_row : float, optional
        Row of the first plane (default: the image centre).
    tol : float
        Stop the plane iteration when the row step is below this, rows (default 1e-7).
    max_iter : int
        Plane evaluations allowed per point; points still moving get ``converged=False``.
    refine : bool, optional
        Run the collinearity refinement; ``None`` (default): only when the detector line
        is curved or the lens distorts (the plane root is exact otherwise).
    refine_tol : float
        Stop the refinement when its step is below this, rows (default 1e-7).
    max_refine : int
        Refinement CEs allowed per point.

    Attributes
    ----------
    line_step_m : float
        Plane distance per row at the image-centre ground point (signed, m/row).
    setup_ce : int
        One-off cost at construction (one ray intersection and two plane distances).
    """

    name = "cpp"
    label = "Central perspective plane (CPP)"
    reference = (
        "Wang M., Hu F., Li J., Pan J. (2009), A fast approach to best scanline search of airborne linear "
        "pushbroom images, Photogramm. Eng. Remote Sens. 75(9):1059-1067, doi:10.14358/PERS.75.9.1059"
    )

    def __init__(
        self,
        scene: Scene,
        *,
        start_row: float | None = None,
        tol: float = 1e-7,
        max_iter: int = 30,
        refine: bool | None = None,
        refine_tol: float = 1e-7,
        max_refine: int = 4,
    ) -> None:
        super().__init__(scene, start_row=start_row, tol=tol, max_iter=max_iter, refine=refine,
                         refine_tol=refine_tol, max_refine=max_refine)
        if not (tol > 0 and refine_tol > 0):
            raise InputError(f"tol and refine_tol must be positive, got {tol}, {refine_tol}")
        if int(max_iter) < 1 or int(max_refine) < 1:
            raise InputError(f"max_iter and max_refine must be >= 1, got {max_iter}, {max_refine}")
        self.start_row = (scene.n_rows - 1) / 2.0 if start_row is None else float(start_row)
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        # refine on the sensor's own residual where the planes are not the whole model: a curved detector or
        # distortion, or a sensor whose lines of sight are its own (aberration, refraction, a CSM camera: no
        # MPC polynomials)
        self.refine = (not scene.interior.is_straight_line or not has_polynomial_exterior(scene)) \
            if refine is None else bool(refine)
        self.refine_tol = float(refine_tol)
        self.max_refine = int(max_refine)
        f = scene.interior.focal_length_m
        x0 = scene.interior.along_track_offset_m
        self._norm = float(np.hypot(f, x0))
        self._normal_sensor = np.array([f, 0.0, x0]) / self._norm
        # Plane distance per line at the image-centre ground point (setup, not per point).
        rc, cc = (scene.n_rows - 1) / 2.0, (scene.n_columns - 1) / 2.0
        centre = scene.image_to_ground(np.array([rc]), np.array([cc]))
        if not np.all(np.isfinite(centre)):
            centre = scene.image_to_ground(np.array([rc]), np.array([cc]), height=scene.terrain.mean_height)
        d, _ = self.plane_distance(np.repeat(centre, 2, axis=0), np.array([rc - 0.5, rc + 0.5]))
        self.line_step_m = float(d[1] - d[0])
        if not (np.isfinite(self.line_step_m) and self.line_step_m != 0.0):
            raise InputError("the central perspective planes of adjacent lines coincide at the image centre")
        # the residual's orientation relative to the plane distance's (+1 for a physical residual; -1 where the
        # scene's residual is the convention's and the camera's image is mirrored against its sensor axes)
        e = residual_px(scene, np.repeat(centre, 2, axis=0), np.array([rc - 0.5, rc + 0.5]))
        _, vz_c = self.plane_distance(centre, np.array([rc]))
        physical = -self._norm * self.line_step_m / (vz_c[0] * scene.pixel_size_m)
        self.residual_orient = 1.0 if (e[1] - e[0]) * physical > 0 else -1.0
        self.setup_ce = 6

    def plane_distance(self, ground: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance of ground points from the central perspective plane of their rows.

        Parameters
        ----------
        ground, rows
            As :func:`explorer.methods._common.residual_px`: ground points (N, 3) in local ENU metres
            and candidate (fractional) rows (N,).

        Returns
        -------
        d : ndarray, shape (N,)
            ``n(t) . (P - S(t))``, metres; positive while the point is ahead of the plane.
        v_z : ndarray, shape (N,)
            Sensor-frame depth of the point (negative in front of the camera), metres.
        """
        ex = self.scene.exterior
        t = self.scene.scanline_time(rows)
        n = ground.shape[0]
        d = np.empty(n)
        vz = np.empty(n)
        for start in range(0, n, CHUNK):
            sl = slice(start, min(start + CHUNK, n))
            v = sensor_vectors(ground[sl], ex.position(t[sl]), ex.rotation(t[sl]))
            d[sl] = v @ self._normal_sensor
            vz[sl] = v[:, 2]
        return d, vz

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        sc = self.scene
        n = ground.shape[0]
        lo_guard, hi_guard = -float(sc.n_rows), 2.0 * sc.n_rows  # stop runaway extrapolation
        row = np.full(n, self.start_row)
        prev_row = np.full(n, np.nan)
        prev_d = np.full(n, np.nan)
        slope = np.full(n, self.line_step_m)  # d(distance)/d(row), m/row
        vz = np.full(n, np.nan)
        ce = np.zeros(n, dtype=np.int64)
        converged = np.zeros(n, dtype=bool)
        active = np.ones(n, dtype=bool)
        path: list[np.ndarray] | None = [row.copy()] if trace else None

        # ---- plane iteration (secant on the signed plane distance)
        for _ in range(self.max_iter):
            idx = np.flatnonzero(active)
            if idx.size == 0:
                break
            r = row[idx]
            d, vz[idx] = self.plane_distance(ground[idx], r)
            ce[idx] += 1
            with np.errstate(divide="ignore", invalid="ignore"):
                s = (d - prev_d[idx]) / (r - prev_row[idx])
            bad = ~np.isfinite(s) | (s * self.line_step_m <= 0)
            s = np.where(bad, slope[idx], s)
            step = -d / s
            prev_row[idx], prev_d[idx], slope[idx] = r, d, s
            new = r + step
            row[idx] = new
            done = np.abs(step) < self.tol
            runaway = ~np.isfinite(new) | (new < lo_guard) | (new > hi_guard)
            converged[idx[done & ~runaway]] = True
            active[idx[done | runaway]] = False
            if path is not None:
                path.append(row.copy())

        # ---- collinearity refinement (curved detector line / distortion)
        if self.refine:
            with np.errstate(divide="ignore", invalid="ignore"):
                slope_px = -self.residual_orient * self._norm * slope / (vz * sc.pixel_size_m)  # residual px/row
            todo = converged.copy()
            converged[:] = False
            prev_row[:] = np.nan
            prev_e = np.full(n, np.nan)
            for _ in range(self.max_refine):
                idx = np.flatnonzero(todo)
                if idx.size == 0:
                    break
                r = row[idx]
                e = residual_px(sc, ground[idx], r)
                ce[idx] += 1
                with np.errstate(divide="ignore", invalid="ignore"):
                    s = (e - prev_e[idx]) / (r - prev_row[idx])  # secant after the first (chord) step
                bad = ~np.isfinite(s) | (s * slope_px[idx] <= 0)
                s = np.where(bad, slope_px[idx], s)
                prev_row[idx], prev_e[idx] = r, e
                step = -e / s
                row[idx] = r + step
                done = np.abs(step) < self.refine_tol
                converged[idx[done]] = True
                todo[idx[done]] = False
                if path is not None:
                    path.append(row.copy())

        in_window = (row >= -1.0) & (row <= float(sc.n_rows))
        converged &= in_window
        return self._result(ground, row, converged, ce, trace=path,
                            info={"setup_ce": self.setup_ce, "line_step_m": self.line_step_m})
