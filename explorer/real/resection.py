"""MPC space resection: fit the Multiple Projection Center model of a scene to control points.

The papers (Ahooei Nezhad et al. 2024, Remote Sensing 16:2787, Sec. 2.2, eq. (2); Sensors 24:5594)
obtain the exterior orientation of every scanline by a space resection of the MPC model on
ground control points: the perspective centre ``S(t)`` and the attitude angles
``(omega, phi, kappa)(t)`` are polynomials of the scanline time (degree 2), solved by
Levenberg-Marquardt.  This module is that step, independent of where the control points come
from (an RPC, a rigorous sensor model, measured GCPs):

* :func:`resect` -- Levenberg-Marquardt (``scipy.optimize.least_squares``) over the position
  and attitude polynomial coefficients (any degree), optionally the focal length, on the
  collinearity residuals at the control points' known scanline times;
* :func:`project_to_image` -- ground -> image of any :class:`~explorer.scene.Scene` by a
  bracketing root search of the best-scanline condition (used to report true pixel residuals);
* :class:`ResectionReport` -- per-point residuals and RMSE in pixels.

Conventions (pixels, time, frames, rotations): ``docs/conventions.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from explorer.errors import InputError, as_points
from explorer.geometry.bracket import bracket_best_scanline
from explorer.geometry.collinearity import ideal_focal_plane
from explorer.geometry.exterior import ExteriorOrientation, LineTiming, polyval_ascending
from explorer.geometry.frames import LocalFrame
from explorer.geometry.interior import InteriorOrientation
from explorer.geometry.rotations import opk_from_rotation, rotation_from_opk
from explorer.geometry.terrain import FlatTerrain, Terrain
from explorer.scene import Scene

__all__ = [
    "PRIOR_SIGMA",
    "ResectionReport",
    "image_residuals",
    "mpc_from_lines_of_sight",
    "project_to_image",
    "resect",
]

GM_EARTH = 3.986004418e14  # m^3 s^-2 (WGS84)

#: Standard deviations of the weak priors of :func:`resect` (per polynomial coefficient of the
#: normalised time, so the same for every degree).
PRIOR_SIGMA = {"position_m": 1000.0, "attitude_rad": 1e-3, "focal_relative": 1e-2, "column_px": 100.0}


# --------------------------------------------------------------------------- projection
#: Ground -> image for any scene by bracketing the best-scanline condition (Illinois regula falsi):
#: :func:`explorer.geometry.bracket.bracket_best_scanline`, the code behind
#: :meth:`explorer.scene.Scene.ground_to_image`, independent of the best-scanline methods under study.
project_to_image = bracket_best_scanline


def image_residuals(
    scene: Scene, ground: np.ndarray, row: np.ndarray, col: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(row, col) residuals ``projected - given`` in pixels of ground points (N, 3) vs image points (N,)."""
    r, c, _ = project_to_image(scene, ground, row_guess=row)
    return r - np.asarray(row, float), c - np.asarray(col, float)


# --------------------------------------------------------------------------- report
def _rms(a: np.ndarray) -> float:
    a = np.asarray(a, float)
    return float(np.sqrt(np.mean(a * a))) if a.size else float("nan")


@dataclass
class ResectionReport:
    """Outcome of a space resection, residuals in pixels.

    Attributes
    ----------
    gcp_row_residual_px, gcp_col_residual_px : ndarray, shape (N,)
        Projected minus given image coordinates of each control point (true ground -> image
        projection through the fitted scene, not the linearised residual).
    rmse_px, max_px : float
        RMSE and maximum of the Euclidean residual over the control points.
    check_row_residual_px, check_col_residual_px : ndarray, shape (M,)
        The same on independent check points (empty when none were given).
    check_rmse_px, check_max_px : float
        NaN without check points.
    initial_rmse_px : float
        Linearised (focal-plane) RMSE of the initial values, pixels.
    focal_length_m, detector_pitch_m : float
        Interior orientation after the fit.
    estimate_focal : bool
    degree : int
        Polynomial degree of position and attitude.
    column_terms : int
        Number of estimated non-uniform detector spacing terms.
    nfev : int
        Residual evaluations spent by the optimiser.
    success : bool
        The optimiser's own flag (its ``status > 0``).
    message : str
    info : dict
        Extra numbers (altitude, view angle, line period, height range of the GCPs...).
    convergence : dict
        How the solution was reached (:func:`resect`): each start's RMS (linearised, pixels),
        evaluations and optimiser status, ``best_start``, ``n_starts_at_best`` (starts that
        reached the best minimum), ``start_spread_px``, ``gauss_newton_gain_px`` (what one more
        Gauss-Newton step would still gain: zero at a minimum), ``condition_number`` of the
        column-scaled Jacobian and ``converged``.
    """

    gcp_row_residual_px: np.ndarray
    gcp_col_residual_px: np.ndarray
    rmse_px: float
    max_px: float
    check_row_residual_px: np.ndarray = field(default_factory=lambda: np.zeros(0))
    check_col_residual_px: np.ndarray = field(default_factory=lambda: np.zeros(0))
    check_rmse_px: float = float("nan")
    check_max_px: float = float("nan")
    initial_rmse_px: float = float("nan")
    focal_length_m: float = float("nan")
    detector_pitch_m: float = float("nan")
    estimate_focal: bool = False
    degree: int = 2
    column_terms: int = 0
    nfev: int = 0
    success: bool = False
    message: str = ""
    info: dict = field(default_factory=dict)
    convergence: dict = field(default_factory=dict)

    @property
    def n_gcps(self) -> int:
        return int(self.gcp_row_residual_px.shape[0])

    @property
    def n_check(self) -> int:
        return int(self.check_row_residual_px.shape[0])

    def with_check(self, drow: np.ndarray, dcol: np.ndarray) -> ResectionReport:
        """A copy with check-point residuals (pixels) and their statistics filled in."""
        d = np.hypot(drow, dcol)
        return replace(
            self,
            check_row_residual_px=np.asarray(drow, float),
            check_col_residual_px=np.asarray(dcol, float),
            check_rmse_px=_rms(d),
            check_max_px=float(np.max(d)) if d.size else float("nan"),
        )

    def to_dict(self, per_point: bool = False) -> dict:
        """JSON-ready summary (``per_point=True`` adds the residual arrays)."""
        out = {
            "n_gcps": self.n_gcps, "rmse_px": self.rmse_px, "max_px": self.max_px,
            "rmse_row_px": _rms(self.gcp_row_residual_px), "rmse_col_px": _rms(self.gcp_col_residual_px),
            "n_check": self.n_check, "check_rmse_px": self.check_rmse_px, "check_max_px": self.check_max_px,
            "initial_rmse_px": self.initial_rmse_px, "focal_length_m": self.focal_length_m,
            "detector_pitch_m": self.detector_pitch_m, "estimate_focal": self.estimate_focal,
            "degree": self.degree, "column_terms": self.column_terms, "nfev": self.nfev, "success": self.success,
            "message": self.message,
            **self.info,
        }  # fmt: skip
        if self.convergence:
            out["convergence"] = self.convergence
        if per_point:
            out["gcp_row_residual_px"] = self.gcp_row_residual_px.tolist()
            out["gcp_col_residual_px"] = self.gcp_col_residual_px.tolist()
            out["check_row_residual_px"] = self.check_row_residual_px.tolist()
            out["check_col_residual_px"] = self.check_col_residual_px.tolist()
        return {k: (v if not isinstance(v, np.floating) else float(v)) for k, v in out.items()}

    def _convergence_lines(self) -> list[str]:
        c = self.convergence
        if not c:
            return []
        return [
            f"  {c['n_starts_at_best']} of {c['n_starts']} starts reached the best minimum "
            f"(best: {c['best_start']}, spread {c['start_spread_px']:.2g} px); one more Gauss-Newton step "
            f"would gain {c['gauss_newton_gain_px']:.2g} px; condition number {c['condition_number']:.3g}"
        ]

    def summary(self) -> str:
        """A few human-readable lines."""
        lines = [
            f"MPC space resection (degree {self.degree}, focal {'estimated' if self.estimate_focal else 'fixed'}, "
            f"{self.column_terms} spacing term(s)):"
            f" {self.nfev} evaluations, {'converged' if self.success else 'NOT converged'} ({self.message})",
            f"  focal length {self.focal_length_m:.6f} m, detector pitch {self.detector_pitch_m * 1e6:.4f} um",
            f"  initial RMSE {self.initial_rmse_px:.3g} px (linearised)",
            *self._convergence_lines(),
            f"  {self.n_gcps} GCPs: RMSE {self.rmse_px:.4f} px (row {_rms(self.gcp_row_residual_px):.4f}, "
            f"col {_rms(self.gcp_col_residual_px):.4f}), max {self.max_px:.4f} px",
        ]
        if self.n_check:
            lines.append(
                f"  {self.n_check} check points: RMSE {self.check_rmse_px:.4f} px "
                f"(row {_rms(self.check_row_residual_px):.4f}, col {_rms(self.check_col_residual_px):.4f}), "
                f"max {self.check_max_px:.4f} px"
            )
        for k, v in self.info.items():
            if isinstance(v, float):
                lines.append(f"  {k}: {v:.6g}")
            elif isinstance(v, (int, str)):
                lines.append(f"  {k}: {v}")
        return "\n".join(lines)


# --------------------------------------------------------------------------- initial values
def mpc_from_lines_of_sight(
    row: np.ndarray,
    col: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    *,
    n_rows: int,
    n_columns: int,
    frame: LocalFrame,
    degree: int = 2,
    focal_length_m: float | None = None,
    detector_pitch_m: float = 1.0e-5,
    line_period_s: float | None = None,
    column_terms: int = 0,
    terrain: Terrain | None = None,
    name: str = "scene",
) -> tuple[Scene, dict]:
    """MPC scene from the lines of sight of a grid of image points (closed form, no iteration).

    Every image point ``(row[k], col[m])`` gives two points of its line of sight,
    ``low[k, m]`` and ``high[k, m]`` (local ENU, e.g. RPC localisations at two heights).
    For each sampled row:

    * the perspective centre is the least-squares intersection of the row's lines of sight;
    * the sensor ``z`` axis is opposite to the central column's viewing direction, ``y``
      follows increasing columns, ``x = y cross z``;
    * ``f / pitch`` (pixels) is fitted to ``col - principal_column = (f / pitch) tan(angle)``
      (with ``column_terms``, ``tan(angle)`` is a polynomial of the column: non-uniform spacing).

    Position and the ``(omega, phi, kappa)`` angles are then fitted by polynomials of the
    scanline time.  The time scale is free for an RPC: by default the line period makes the
    perspective centre move at the circular orbital speed ``sqrt(GM / r)``.

    Parameters
    ----------
    row : ndarray, shape (K,)
        Sampled rows (K >= degree + 1).
    col : ndarray, shape (M,)
        Sampled columns (M >= 3), spanning the image width.
    low, high : ndarray, shape (K, M, 3)
        Two points of each line of sight, ``high`` nearer the sensor; metres.
    n_rows, n_columns : int
        Image size.
    frame : LocalFrame
    degree : int
    focal_length_m : float, optional
        Fixed focal length (then ``pitch = f / (f / pitch)``); default ``(f / pitch) *
        detector_pitch_m``.
    detector_pitch_m : float
    line_period_s : float, optional
    column_terms : int
        Terms of ``InteriorOrientation.column_polynomial`` to fit (0: evenly spaced detectors).
    terrain : Terrain, optional
        Default flat at height 0.
    name : str

    Returns
    -------
    scene : Scene
    info : dict
        ``centre_rms_m`` (how far the lines of sight miss their perspective centres),
        ``coplanarity_rms_rad``, ``f_over_pitch_px``, ``line_period_s``, ``altitude_m``.
    """
    row = np.asarray(row, dtype=np.float64)
    col = np.asarray(col, dtype=np.float64)
    k_rows, m_cols = row.size, col.size
    if k_rows < degree + 1 or m_cols < 3:
        raise InputError(f"need at least {degree + 1} rows and 3 columns of lines of sight")
    d = high - low
    d /= np.linalg.norm(d, axis=-1, keepdims=True)  # upwards, (K, M, 3)
    proj = np.eye(3) - d[..., :, None] * d[..., None, :]  # (K, M, 3, 3)
    a = proj.sum(axis=1)
    b = np.einsum("kmij,kmj->ki", proj, low)
    centres = np.linalg.solve(a, b[..., None])[..., 0]  # (K, 3)
    miss = np.einsum("kmij,kmj->kmi", proj, centres[:, None, :] - low)
    centre_rms = float(np.sqrt(np.mean(np.sum(miss**2, axis=-1))))
    w = -d  # viewing directions, sensor -> ground
    pc = (n_columns - 1) / 2.0
    j_mid = int(np.argmin(np.abs(col - pc)))
    z_ax = -w[:, j_mid, :]
    span = w[:, -1, :] - w[:, 0, :]
    if col[-1] < col[0]:
        span = -span
    y_ax = span - np.sum(span * z_ax, axis=1, keepdims=True) * z_ax
    y_ax /= np.linalg.norm(y_ax, axis=1, keepdims=True)
    x_ax = np.cross(y_ax, z_ax)
    rot = np.stack([x_ax, y_ax, z_ax], axis=-1)  # (K, 3, 3) sensor -> object
    ws = np.einsum("kji,kmj->kmi", rot, w)  # viewing directions in the sensor frame
    tan_y = ws[..., 1] / -ws[..., 2]
    coplanarity = float(np.sqrt(np.mean((ws[..., 0] / -ws[..., 2]) ** 2)))
    u = np.broadcast_to(col - pc, tan_y.shape).ravel()
    # tan(angle) = c1 u + c2 u**2 + ...  ->  f / pitch = 1 / c1, column_polynomial a_k = c_k / c1
    half = max(pc, 1.0)
    design = np.stack([(u / half) ** k for k in range(1, column_terms + 2)], axis=1)
    coef = np.linalg.lstsq(design, tan_y.ravel(), rcond=None)[0] / half ** np.arange(1, column_terms + 2)
    if not coef[0] > 0:
        raise InputError("columns do not increase along the sensor y axis (mirrored image?)")
    f_over_pitch = float(1.0 / coef[0])
    column_polynomial = tuple(float(c / coef[0]) for c in coef[1:])
    # timing: perspective-centre speed = circular orbital speed
    earth_centre = frame.ecef_to_enu(np.zeros((1, 3)))[0]
    r_mid = centres[k_rows // 2] - earth_centre
    radius = float(np.linalg.norm(r_mid))
    if line_period_s is None:
        step = np.polyfit(row, centres, 1)[0]  # metres per row, (3,)
        line_period_s = float(np.linalg.norm(step) / np.sqrt(GM_EARTH / radius))
    timing = LineTiming(line_period_s, (n_rows - 1) / 2.0)
    t = timing.scanline_time(row)
    angles = np.unwrap(np.stack(opk_from_rotation(rot), axis=1), axis=0)  # (K, 3)
    pos = np.polynomial.polynomial.polyfit(t, centres, degree).T  # (3, degree + 1)
    att = np.polynomial.polynomial.polyfit(t, angles, degree).T
    if focal_length_m is None:
        pitch = float(detector_pitch_m)
        focal = f_over_pitch * pitch
    else:
        focal = float(focal_length_m)
        pitch = focal / f_over_pitch
    interior = InteriorOrientation(focal, pitch, n_columns, column_polynomial=column_polynomial)
    scene = Scene(name, interior, ExteriorOrientation(pos, att, []), timing, n_rows,
                  FlatTerrain(0.0) if terrain is None else terrain, frame, {})
    # rows must advance against the sensor x axis as time goes on (docs/conventions.md): the
    # along-track residual of a ground point decreases with time; a mirrored image inverts it
    mid = (high[k_rows // 2, j_mid] + low[k_rows // 2, j_mid])[None] / 2.0
    t_mid = t[k_rows // 2]
    slope = np.diff(scene.along_track_residual(np.repeat(mid, 2, axis=0), t_mid + np.array([-1e-3, 1e-3])))[0]
    if not slope < 0:
        raise InputError(
            "the image is mirrored: columns increase to the right of the direction in which rows advance, "
            "which the package's sensor frame cannot represent (docs/conventions.md#frames)"
        )
    _, _, alt = frame.enu_to_geodetic(centres[k_rows // 2][None])
    info = {
        "centre_rms_m": centre_rms, "coplanarity_rms_rad": coplanarity, "f_over_pitch_px": f_over_pitch,
        "line_period_s": line_period_s, "altitude_m": float(alt[0]),
    }  # fmt: skip
    return scene, info


# --------------------------------------------------------------------------- solver
#: RMS change of the residuals (pixels) produced by each central-difference probe of the
#: Jacobian.  The collinearity residuals carry a rounding noise of about 1e-10 px (a 700 km
#: lever arm in float64), so probes that move them by 1e-3 px give a Jacobian good to about
#: 1e-7, while the curvature of the model over such a step is far smaller.  Probing each
#: unknown by a fixed relative amount instead (the optimiser's default, 1.5e-8 of the value)
#: moves the residuals by ~1e-8 px, a Jacobian with 1 % errors whose rounding depends on the
#: CPU: the iteration then stalls at different points of the narrow-field-of-view valley on
#: different machines.
JACOBIAN_STEP_PX = 1e-3

#: Two starts reach the same minimum when their linearised RMS (pixels) differ by at most
#: this fraction (plus :data:`AGREEMENT_FLOOR_PX`).
AGREEMENT_RELATIVE = 1e-6
AGREEMENT_FLOOR_PX = 1e-7

#: Converged when one more Gauss-Newton step would lower the RMS by less than this fraction
#: (or by less than :data:`AGREEMENT_FLOOR_PX` in absolute terms).
CONVERGED_RELATIVE = 1e-8


def _pad(coeffs: np.ndarray, degree: int) -> np.ndarray:
    out = np.zeros((3, degree + 1))
    k = min(degree + 1, coeffs.shape[1])
    out[:, :k] = coeffs[:, :k]
    return out


class _ResectionProblem:
    """Unknowns and residuals of one resection (fixed degree), in conditioned units.

    Unknowns ``p`` are changes from the initial values: 1 m per position coefficient and
    1 urad per attitude coefficient of the normalised time ``tau = t / max|t|`` (so that every
    coefficient moves the image by a comparable amount), 1 ppm of focal length, 1 px at the
    array edge per spacing term.  :meth:`effect_scale` measures how many pixels each unit
    actually moves the residuals; the solver works on ``p * scale`` (every unknown worth
    1 px RMS).
    """

    pos_unit, att_unit, f_unit = 1.0, 1e-6, 1e-6

    def __init__(self, scene0: Scene, col: np.ndarray, ground: np.ndarray, t: np.ndarray, tau_scale: float, *,
                 degree: int, estimate_focal: bool, column_terms: int, prior_scale: float) -> None:
        self.scene0, self.col, self.ground, self.t = scene0, col, ground, t
        self.tau = t / tau_scale
        self.degree, self.estimate_focal, self.column_terms = degree, estimate_focal, column_terms
        self.prior_scale = prior_scale
        self.powers = tau_scale ** np.arange(degree + 1)
        self.pos0 = _pad(scene0.exterior.position_coeffs, degree) * self.powers  # coefficients of tau
        self.att0 = _pad(scene0.exterior.attitude_coeffs, degree) * self.powers
        self.n_pos = 3 * (degree + 1)
        self.n_par = 2 * self.n_pos + int(estimate_focal) + column_terms
        interior = scene0.interior
        half = max(interior.principal_column, scene0.n_columns - 1 - interior.principal_column, 1.0)
        self.a0 = np.zeros(column_terms)
        k0 = min(column_terms, len(interior.column_polynomial))
        self.a0[:k0] = interior.column_polynomial[:k0]
        self.a_unit = 1.0 / half ** np.arange(2, column_terms + 2)  # a_k u**k = 1 px at u = half
        self.i_f = 2 * self.n_pos
        self.i_a = self.i_f + int(estimate_focal)
        self.y_fixed = interior.column_to_y(col)
        self.sigma = np.concatenate([
            np.full(self.n_pos, PRIOR_SIGMA["position_m"] / self.pos_unit),
            np.full(self.n_pos, PRIOR_SIGMA["attitude_rad"] / self.att_unit),
            np.full(int(estimate_focal), PRIOR_SIGMA["focal_relative"] / self.f_unit),
            np.full(column_terms, PRIOR_SIGMA["column_px"]),
        ]) * prior_scale  # fmt: skip

    def tau_coefficients(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position and attitude coefficients of ``tau`` (each (3, degree + 1))."""
        d1 = self.degree + 1
        return (self.pos0 + self.pos_unit * p[: self.n_pos].reshape(3, d1),
                self.att0 + self.att_unit * p[self.n_pos : 2 * self.n_pos].reshape(3, d1))

    def interior(self, p: np.ndarray) -> InteriorOrientation:
        interior = self.scene0.interior
        if self.estimate_focal:
            interior = replace(interior, focal_length_m=interior.focal_length_m * (1.0 + self.f_unit * p[self.i_f]))
        if self.column_terms:
            a = self.a0 + self.a_unit * p[self.i_a : self.i_a + self.column_terms]
            interior = replace(interior, column_polynomial=tuple(float(v) for v in a))
        return interior

    def unpack(self, p: np.ndarray) -> tuple[ExteriorOrientation, InteriorOrientation]:
        pos, att = self.tau_coefficients(p)
        return ExteriorOrientation(pos / self.powers, att / self.powers, []), self.interior(p)

    def _state(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Perspective centres and (omega, phi, kappa) at the points' times, each (N, 3)."""
        pos, att = self.tau_coefficients(p)
        return polyval_ascending(pos, self.tau), polyval_ascending(att, self.tau)

    def _data(self, centre: np.ndarray, angles: np.ndarray, interior: InteriorOrientation) -> np.ndarray:
        rot = rotation_from_opk(angles[:, 0], angles[:, 1], angles[:, 2])
        x, y = interior.distort(*ideal_focal_plane(self.ground, centre, rot, interior.focal_length_m))
        y_obs = interior.column_to_y(self.col) if self.column_terms else self.y_fixed
        pitch = interior.detector_pitch_m
        return np.concatenate([(x - interior.detector_x(y)) / pitch, (y - y_obs) / pitch])

    def residuals(self, p: np.ndarray) -> np.ndarray:
        """Along-track then across-track residuals (2N,), pixels (then the priors, if any)."""
        data = self._data(*self._state(p), self.interior(p))
        if self.prior_scale <= 0:
            return data
        return np.concatenate([data, p / self.sigma])

    def jacobian(self, p: np.ndarray, step: np.ndarray) -> np.ndarray:
        """Central-difference Jacobian (M, P) of :meth:`residuals`, probes of ``step`` (P,) units.

        The exterior columns use the chain rule: the residuals of a point depend on the
        polynomial coefficients only through the centre and angles at its time, so 12 probes of
        those (steps of the constant terms) give every position and attitude column.
        """
        centre, angles = self._state(p)
        interior = self.interior(p)
        d1 = self.degree + 1
        tau_powers = np.tile(self.tau, 2)[:, None] ** np.arange(d1)  # (2N, d1)
        columns = np.empty((2 * self.tau.size, self.n_par))
        for block, (state, unit) in enumerate(((centre, self.pos_unit), (angles, self.att_unit))):
            for i in range(3):
                h = step[block * self.n_pos + i * d1] * unit
                plus, minus = state.copy(), state.copy()
                plus[:, i] += h
                minus[:, i] -= h
                args = ((plus, angles), (minus, angles)) if block == 0 else ((centre, plus), (centre, minus))
                deriv = (self._data(*args[0], interior) - self._data(*args[1], interior)) / (2.0 * h)
                k = block * self.n_pos + i * d1
                columns[:, k : k + d1] = deriv[:, None] * tau_powers * unit
        for k in range(2 * self.n_pos, self.n_par):
            e = np.zeros(self.n_par)
            e[k] = step[k]
            columns[:, k] = (self._data(centre, angles, self.interior(p + e))
                             - self._data(centre, angles, self.interior(p - e))) / (2.0 * step[k])
        if self.prior_scale <= 0:
            return columns
        return np.vstack([columns, np.diag(1.0 / self.sigma)])

    def n_evaluations(self) -> int:
        """Residual evaluations spent by one :meth:`jacobian`."""
        return 12 + 2 * (self.n_par - 2 * self.n_pos)

    def effect_scale(self, p: np.ndarray) -> np.ndarray:
        """RMS change of the residuals (pixels) per unit of each unknown at ``p`` (P,)."""
        n_obs = 2 * self.t.size
        jac = self.jacobian(p, np.full(p.size, 1e-3))[:n_obs]
        d = np.linalg.norm(jac, axis=0) / np.sqrt(n_obs)
        return np.where(d > 0, d, 1.0)

    def start_from(self, other: _ResectionProblem, p_other: np.ndarray) -> np.ndarray:
        """Unknowns of this problem that reproduce ``other``'s model at ``p_other`` exactly
        (missing higher-degree terms are zero)."""
        pos, att = other.tau_coefficients(p_other)
        p = np.zeros(self.n_par)
        p[: self.n_pos] = ((_pad(pos, self.degree) - self.pos0) / self.pos_unit).ravel()
        p[self.n_pos : 2 * self.n_pos] = ((_pad(att, self.degree) - self.att0) / self.att_unit).ravel()
        p[2 * self.n_pos :] = p_other[2 * other.n_pos :]
        return p


@dataclass
class _Run:
    """One start of the solver."""

    name: str
    x: np.ndarray
    cost: float
    nfev: int
    status: int
    message: str
    gauss_newton_steps: int


def _minimise(problem: _ResectionProblem, x0: np.ndarray, name: str, *, method: str, max_nfev: int | None,
              restarts: int, polish: int) -> _Run:
    """Levenberg-Marquardt from ``x0`` on the conditioned unknowns, then Gauss-Newton to the end."""
    # here, not at the module's top: scipy.optimize is ~0.2 s of CPU to import, and a process that only
    # unpickles a scene of this package (the export's sweep worker) never resects
    from scipy.optimize import least_squares

    calls = [0]

    def fun(p: np.ndarray) -> np.ndarray:
        calls[0] += 1
        return problem.residuals(p)

    scale = problem.effect_scale(x0)
    calls[0] += problem.n_evaluations()
    step = JACOBIAN_STEP_PX / scale

    def jac(p: np.ndarray) -> np.ndarray:
        calls[0] += problem.n_evaluations()
        return problem.jacobian(p, step)

    # each run's budget (the optimiser's own count, Jacobians apart): about 70 iterations suffice
    # on every test RPC; a problem that needs more has a direction the points cannot see
    kwargs = {"max_nfev": 30 * x0.size if max_nfev is None else max_nfev}
    # Position, attitude and interior are strongly correlated (narrow field of view): the damped
    # iteration can stop in a long curved valley.  Restarting from the last solution (fresh
    # damping) continues down the valley; stop when the cost no longer drops.
    x, cost, best = x0, np.inf, None  # best: the last scipy OptimizeResult that did not raise the cost
    for _ in range(restarts + 1):
        sol = least_squares(fun, x, jac=jac, method=method, x_scale=1.0 / scale, xtol=1e-15, ftol=1e-15,
                            gtol=1e-15, **kwargs)
        improved = sol.cost < cost * (1.0 - 1e-6)
        if sol.cost <= cost:
            x, cost, best = sol.x, float(sol.cost), sol
        if not improved:
            break
    # undamped Gauss-Newton (SVD least squares on the column-scaled system, step halving): the
    # damped iteration slows down in the valley, the undamped one finishes it
    f = fun(x)
    ss = float(f @ f)
    steps = 0
    for _ in range(polish):
        jac_s = jac(x) / scale
        dx = np.linalg.lstsq(jac_s, -f, rcond=1e-13)[0] / scale
        t = 1.0
        for _ in range(8):
            f_new = fun(x + t * dx)
            ss_new = float(f_new @ f_new)
            if ss_new < ss:
                break
            t *= 0.5
        else:
            break
        gain = (ss - ss_new) / ss
        x, f, ss = x + t * dx, f_new, ss_new
        steps += 1
        if gain < 1e-15:
            break
    assert best is not None  # the first least_squares run is always taken (its cost is below inf)
    return _Run(name, x, 0.5 * ss, calls[0], int(best.status), str(best.message), steps)


def _convergence_check(problem: _ResectionProblem, x: np.ndarray) -> dict:
    """What one more Gauss-Newton step would gain at ``x`` (zero at a minimum), and conditioning."""
    scale = problem.effect_scale(x)
    f = problem.residuals(x)
    jac_s = problem.jacobian(x, JACOBIAN_STEP_PX / scale) / scale
    u, s, _ = np.linalg.svd(jac_s, full_matrices=False)
    keep = s > 1e-13 * s[0]
    g = u[:, keep].T @ f
    n = f.size
    rms = float(np.sqrt(f @ f / n))
    rms_after = float(np.sqrt(max(f @ f - g @ g, 0.0) / n))
    return {
        "gauss_newton_gain_px": rms - rms_after,
        "condition_number": float(s[0] / max(s[-1], 1e-300 * s[0], 1e-300)),  # finite: JSON reports
        "converged": bool(rms - rms_after <= CONVERGED_RELATIVE * rms + AGREEMENT_FLOOR_PX),
    }


# --------------------------------------------------------------------------- resection
def resect(
    scene0: Scene,
    row: np.ndarray,
    col: np.ndarray,
    ground: np.ndarray,
    *,
    degree: int = 2,
    estimate_focal: bool = False,
    column_terms: int = 0,
    method: str = "lm",
    max_nfev: int | None = None,
    restarts: int = 3,
    prior_scale: float = 0.0,
    stage_columns: bool = False,
    polish: int = 50,
    staged: bool = True,
    random_starts: int = 0,
    start_spread_px: float = 1.0,
    seed: int = 0,
) -> tuple[Scene, ResectionReport]:
    """MPC space resection by Levenberg-Marquardt, reproducible to the last digits that matter.

    Unknowns: the ``3 x (degree + 1)`` position and ``3 x (degree + 1)`` attitude polynomial
    coefficients of ``scene0.exterior`` (the initial values; missing higher-order terms start at
    zero; jitter is dropped), the focal length when ``estimate_focal``, and ``column_terms``
    coefficients of a non-uniform detector spacing (``InteriorOrientation.column_polynomial``,
    quadratic first).  The detector pitch, principal column, line timing and detector line
    shape stay those of ``scene0``.

    Observations: for each control point seen at its known scanline time
    ``t = scene0.scanline_time(row)``, the along-track condition ``x - x_det(y) = 0`` and the
    across-track coordinate ``y = y(col)``, both divided by the pitch (pixels).  The report's
    residuals are then the true ground -> image projections (:func:`project_to_image`).

    Reproducibility (the same minimum on every CPU, whatever the order of the points):

    * conditioning: polynomials of the normalised time ``t / max|t|``; unknowns scaled so that
      each moves the residuals by 1 px RMS; a central-difference Jacobian whose probes move the
      residuals by :data:`JACOBIAN_STEP_PX` (far above the float64 rounding noise);
    * the points are put in a canonical order (sorted by row, column, ground coordinates)
      before the solve, so their input order cannot change a single bit of the result;
    * multi-start: from the initial values, from a staged solve (degree 1, then each degree
      up to ``degree``, each stage started from the previous one's model) and from
      ``random_starts`` seeded perturbations of the initial values; every start runs
      Levenberg-Marquardt then Gauss-Newton until a step no longer lowers the cost, and the
      lowest cost is kept;
    * a convergence report (``report.convergence``): every start's RMS and evaluations, how
      many reached the best minimum (within :data:`AGREEMENT_RELATIVE`), and what one more
      Gauss-Newton step would still gain at the solution (zero at a minimum).

    Parameters
    ----------
    scene0 : Scene
        Initial values and fixed quantities.
    row, col : ndarray, shape (N,)
        Image coordinates of the control points (0-based, pixel centre).
    ground : ndarray, shape (N, 3)
        Their local ENU coordinates, metres.
    degree : int
        Degree of the position and attitude polynomials (the papers: 2).
    estimate_focal : bool
        Also estimate the focal length (otherwise fixed at ``scene0``'s).
    column_terms : int
        Number of non-uniform spacing terms ``a2, a3, ...`` to estimate (0: evenly spaced
        detectors, as in the papers; 1 fits products resampled to a uniform ground spacing
        across track, e.g. IKONOS).
    method : {"lm", "trf"}
        ``scipy.optimize.least_squares`` method.
    max_nfev : int, optional
        Evaluation budget of each optimiser run (Jacobians apart; default 30 per unknown).
    restarts : int
        The optimiser is restarted from its solution while the cost drops by more than 1 ppm
        (at most this many times).
    prior_scale : float
        When positive, weak priors tie every unknown to its initial value with standard
        deviations ``prior_scale`` times :data:`PRIOR_SIGMA` (1 km of position per coefficient,
        1 mrad of attitude, 1 % of focal length, 100 px per spacing term).  They pin the
        directions the control points cannot see (a narrow field of view leaves
        position/attitude/focal length nearly interchangeable) when the initial values are
        poor, at the price of a bias (3e-3 px on an exact preset model with ``prior_scale=1``).
        Default 0: no priors (the lines-of-sight initial values are close enough).
    stage_columns : bool
        With ``column_terms`` beyond those of ``scene0``, first solve without the missing
        spacing terms, then release them from that solution.
    polish : int
        At most this many Gauss-Newton iterations after Levenberg-Marquardt (they stop earlier
        when a step no longer lowers the cost).
    staged : bool
        Add the staged start (degree 1, 2, ..., ``degree``) when ``degree >= 2``.
    random_starts : int
        Extra starts: the initial values moved by normal random amounts worth
        ``start_spread_px`` pixels RMS per unknown (seeded by ``seed``).
    start_spread_px : float
    seed : int

    Returns
    -------
    scene : Scene
        ``scene0`` with the fitted exterior (and focal length).
    report : ResectionReport
        Residuals at the control points (no check points; add them with
        :meth:`ResectionReport.with_check`) and ``convergence``.
    """
    row = np.asarray(row, dtype=np.float64)
    col = np.asarray(col, dtype=np.float64)
    ground = as_points(ground)
    if not (row.shape == col.shape == ground.shape[:1]):
        raise InputError(f"row {row.shape}, col {col.shape} and ground {ground.shape} disagree")
    if not (np.all(np.isfinite(row)) and np.all(np.isfinite(col))):
        raise InputError("control point rows and columns must be finite")
    if degree < 0:
        raise InputError(f"degree must be >= 0, got {degree}")
    if column_terms < 0:
        raise InputError(f"column_terms must be >= 0, got {column_terms}")
    if random_starts < 0 or not np.isfinite(start_spread_px) or start_spread_px < 0:
        raise InputError(f"random_starts ({random_starts}) and start_spread_px ({start_spread_px}) must be >= 0")
    n_par = 6 * (degree + 1) + int(estimate_focal) + column_terms
    if 2 * row.size < n_par:
        raise InputError(f"{row.size} control points give {2 * row.size} equations for {n_par} unknowns")
    options: dict[str, Any] = dict(
        method=method, max_nfev=max_nfev, restarts=restarts, prior_scale=prior_scale, polish=polish,
        staged=staged, random_starts=random_starts, start_spread_px=start_spread_px, seed=seed,
    )
    if column_terms and len(scene0.interior.column_polynomial) < column_terms and stage_columns:
        # staged: the exterior (and focal length) first, then release the spacing terms
        first, rep1 = resect(scene0, row, col, ground, degree=degree, estimate_focal=estimate_focal,
                             column_terms=len(scene0.interior.column_polynomial), **options)
        scene, rep = resect(first, row, col, ground, degree=degree, estimate_focal=estimate_focal,
                            column_terms=column_terms, stage_columns=False, **options)
        return scene, replace(rep, nfev=rep.nfev + rep1.nfev, initial_rmse_px=rep1.initial_rmse_px)
    # canonical order: the result cannot depend on the order in which the points are given
    order = np.lexsort((ground[:, 2], ground[:, 1], ground[:, 0], col, row))
    t = scene0.scanline_time(row[order])
    tau_scale = max(float(np.max(np.abs(t))), 1e-9)

    def problem_of(deg: int) -> _ResectionProblem:
        return _ResectionProblem(scene0, col[order], ground[order], t, tau_scale, degree=deg,
                                 estimate_focal=estimate_focal, column_terms=column_terms, prior_scale=prior_scale)

    problem = problem_of(degree)
    n_obs = 2 * row.size
    p0 = np.zeros(n_par)
    r0 = problem.residuals(p0)
    initial_rmse = float(np.sqrt(np.mean(r0[: row.size] ** 2 + r0[row.size : n_obs] ** 2)))
    solve: dict[str, Any] = dict(method=method, max_nfev=max_nfev, restarts=restarts, polish=polish)

    runs = [_minimise(problem, p0, "initial values", **solve)]
    if staged and degree >= 2:
        prev_problem, prev = problem_of(1), None
        prev = _minimise(prev_problem, np.zeros(prev_problem.n_par), "stage 1", **solve)
        nfev_stages = prev.nfev
        for deg in range(2, degree + 1):
            stage_problem = problem if deg == degree else problem_of(deg)
            start = stage_problem.start_from(prev_problem, prev.x)
            prev = _minimise(stage_problem, start, f"stage {deg}", **solve)
            prev_problem = stage_problem
            nfev_stages += prev.nfev
        runs.append(replace(prev, name=f"staged 1..{degree}", nfev=nfev_stages))
    if random_starts:
        rng = np.random.default_rng(seed)
        scale = problem.effect_scale(p0)
        for k in range(random_starts):
            start = rng.normal(0.0, start_spread_px, n_par) / scale
            runs.append(_minimise(problem, start, f"random {k + 1}", **solve))
    best = min(runs, key=lambda run: run.cost)
    x = best.x

    def rms_of(run: _Run) -> float:
        return float(np.sqrt(2.0 * run.cost / n_obs))

    rms_best = rms_of(best)
    agree = [abs(rms_of(r) - rms_best) <= AGREEMENT_RELATIVE * rms_best + AGREEMENT_FLOOR_PX for r in runs]
    check = _convergence_check(problem, x)
    convergence = {
        "starts": [{"name": r.name, "rmse_px": rms_of(r), "nfev": r.nfev, "status": r.status,
                    "message": r.message, "gauss_newton_steps": r.gauss_newton_steps} for r in runs],
        "best_start": best.name,
        "n_starts": len(runs),
        "n_starts_at_best": int(sum(agree)),
        "start_spread_px": float(max(rms_of(r) for r in runs) - rms_best),
        **check,
    }  # fmt: skip
    ext, interior = problem.unpack(x)
    scene = replace(scene0, exterior=ext, interior=interior)
    drow, dcol = image_residuals(scene, ground, row, col)
    d = np.hypot(drow, dcol)
    report = ResectionReport(
        gcp_row_residual_px=drow,
        gcp_col_residual_px=dcol,
        rmse_px=_rms(d),
        max_px=float(np.nanmax(d)),
        initial_rmse_px=initial_rmse,
        focal_length_m=interior.focal_length_m,
        detector_pitch_m=interior.detector_pitch_m,
        estimate_focal=estimate_focal,
        degree=degree,
        column_terms=column_terms,
        nfev=int(sum(r.nfev for r in runs)),
        success=bool(best.status > 0 and check["converged"]),
        message=best.message,
        convergence=convergence,
    )
    return scene, report
