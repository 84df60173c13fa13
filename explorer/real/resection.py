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

import numpy as np
from scipy.optimize import least_squares

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
def project_to_image(
    scene: Scene,
    ground: np.ndarray,
    *,
    row_guess: np.ndarray | None = None,
    margin_fraction: float = 0.25,
    n_bracket: int = 33,
    tol_rows: float = 1e-10,
    max_iter: int = 100,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground -> image for any scene by bracketing the best-scanline condition (Illinois regula falsi).

    :func:`explorer.geometry.bracket.bracket_best_scanline` (the code behind
    :meth:`explorer.scene.Scene.ground_to_image`), independent of the best-scanline methods under study.

    Returns
    -------
    row, col : ndarray, shape (N,)
        Fractional image coordinates (0-based, pixel centre); NaN where no root was bracketed.
    converged : ndarray of bool, shape (N,)
    """
    return bracket_best_scanline(scene, ground, row_guess=row_guess, margin_fraction=margin_fraction,
                                 n_bracket=n_bracket, tol_rows=tol_rows, max_iter=max_iter)


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
        if per_point:
            out["gcp_row_residual_px"] = self.gcp_row_residual_px.tolist()
            out["gcp_col_residual_px"] = self.gcp_col_residual_px.tolist()
            out["check_row_residual_px"] = self.check_row_residual_px.tolist()
            out["check_col_residual_px"] = self.check_col_residual_px.tolist()
        return {k: (v if not isinstance(v, np.floating) else float(v)) for k, v in out.items()}

    def summary(self) -> str:
        """A few human-readable lines."""
        lines = [
            f"MPC space resection (degree {self.degree}, focal {'estimated' if self.estimate_focal else 'fixed'}, "
            f"{self.column_terms} spacing term(s)):"
            f" {self.nfev} evaluations, {'converged' if self.success else 'NOT converged'} ({self.message})",
            f"  focal length {self.focal_length_m:.6f} m, detector pitch {self.detector_pitch_m * 1e6:.4f} um",
            f"  initial RMSE {self.initial_rmse_px:.3g} px (linearised)",
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


# --------------------------------------------------------------------------- resection
def _gauss_newton_polish(fun, x: np.ndarray, n_obs: int, iterations: int) -> np.ndarray:
    """Undamped Gauss-Newton steps with step halving; keeps x when a step does not help."""
    f = fun(x)
    cost = float(f @ f)
    for _ in range(iterations):
        h = 1e-3 * np.maximum(1.0, np.abs(x)) * 1e-3
        jac = np.empty((f.size, x.size))
        for k in range(x.size):
            e = np.zeros_like(x)
            e[k] = h[k]
            jac[:, k] = (fun(x + e) - fun(x - e)) / (2 * h[k])
        scale = np.linalg.norm(jac, axis=0)
        scale[scale == 0] = 1.0
        step = np.linalg.lstsq(jac / scale, -f, rcond=1e-13)[0] / scale
        t = 1.0
        for _ in range(8):
            f_new = fun(x + t * step)
            c_new = float(f_new @ f_new)
            if c_new < cost:
                break
            t *= 0.5
        else:
            break
        x, f, cost = x + t * step, f_new, c_new
    return x


def _pad(coeffs: np.ndarray, degree: int) -> np.ndarray:
    out = np.zeros((3, degree + 1))
    k = min(degree + 1, coeffs.shape[1])
    out[:, :k] = coeffs[:, :k]
    return out


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
    polish: int = 4,
) -> tuple[Scene, ResectionReport]:
    """MPC space resection by Levenberg-Marquardt.

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
        Evaluation budget per run (default: the solver's).
    restarts : int
        The solver is restarted from its solution while the cost drops by more than 1 ppm
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
        Gauss-Newton iterations after Levenberg-Marquardt (central-difference Jacobian, SVD
        least squares on the column-scaled system, step halving): the damped iteration stalls
        in the narrow-field-of-view valley (1e-3 px on an exact model), the undamped one
        finishes it (1e-9 px).

    Returns
    -------
    scene : Scene
        ``scene0`` with the fitted exterior (and focal length).
    report : ResectionReport
        Residuals at the control points (no check points; add them with
        :meth:`ResectionReport.with_check`).
    """
    row = np.asarray(row, dtype=np.float64)
    col = np.asarray(col, dtype=np.float64)
    ground = as_points(ground)
    if not (row.shape == col.shape == ground.shape[:1]):
        raise InputError(f"row {row.shape}, col {col.shape} and ground {ground.shape} disagree")
    if degree < 0:
        raise InputError(f"degree must be >= 0, got {degree}")
    if column_terms < 0:
        raise InputError(f"column_terms must be >= 0, got {column_terms}")
    n_par = 6 * (degree + 1) + int(estimate_focal) + column_terms
    if 2 * row.size < n_par:
        raise InputError(f"{row.size} control points give {2 * row.size} equations for {n_par} unknowns")
    if column_terms and len(scene0.interior.column_polynomial) < column_terms and stage_columns:
        # staged: the exterior (and focal length) first, then release the spacing terms
        first, rep1 = resect(scene0, row, col, ground, degree=degree, estimate_focal=estimate_focal,
                             column_terms=len(scene0.interior.column_polynomial), method=method,
                             max_nfev=max_nfev, restarts=restarts, prior_scale=prior_scale)
        scene, rep = resect(first, row, col, ground, degree=degree, estimate_focal=estimate_focal,
                            column_terms=column_terms, method=method, max_nfev=max_nfev,
                            restarts=restarts, prior_scale=prior_scale, stage_columns=False)
        return scene, replace(rep, nfev=rep.nfev + rep1.nfev, initial_rmse_px=rep1.initial_rmse_px)
    t = scene0.scanline_time(row)
    tau_scale = max(float(np.max(np.abs(t))), 1e-9)
    powers = tau_scale ** np.arange(degree + 1)
    pos0 = _pad(scene0.exterior.position_coeffs, degree) * powers  # coefficients of tau = t / tau_scale
    att0 = _pad(scene0.exterior.attitude_coeffs, degree) * powers
    f0 = scene0.interior.focal_length_m
    pitch = scene0.interior.detector_pitch_m
    # parameter units: 1 m of position, 1 urad of attitude, 1 ppm of focal length,
    # 1 px at the array edge for each spacing term
    pos_unit, att_unit, f_unit = 1.0, 1e-6, 1e-6
    n_pos = 3 * (degree + 1)
    half = max(scene0.interior.principal_column, scene0.n_columns - 1 - scene0.interior.principal_column, 1.0)
    a0 = np.zeros(column_terms)
    k0 = min(column_terms, len(scene0.interior.column_polynomial))
    a0[:k0] = scene0.interior.column_polynomial[:k0]
    a_unit = 1.0 / half ** np.arange(2, column_terms + 2)  # a_k u**k = 1 px at u = half
    i_f = 2 * n_pos
    i_a = i_f + int(estimate_focal)

    def unpack(p: np.ndarray) -> tuple[ExteriorOrientation, InteriorOrientation]:
        pos = (pos0 + pos_unit * p[:n_pos].reshape(3, degree + 1)) / powers
        att = (att0 + att_unit * p[n_pos : 2 * n_pos].reshape(3, degree + 1)) / powers
        ext = ExteriorOrientation(pos, att, [])
        interior = scene0.interior
        if estimate_focal:
            interior = replace(interior, focal_length_m=f0 * (1.0 + f_unit * p[i_f]))
        if column_terms:
            a = a0 + a_unit * p[i_a : i_a + column_terms]
            interior = replace(interior, column_polynomial=tuple(float(v) for v in a))
        return ext, interior

    y_fixed = scene0.interior.column_to_y(col)

    # weak priors: (parameter change) / sigma, in parameter units
    sigma = np.concatenate([
        np.full(n_pos, PRIOR_SIGMA["position_m"] / pos_unit),
        np.full(n_pos, PRIOR_SIGMA["attitude_rad"] / att_unit),
        np.full(int(estimate_focal), PRIOR_SIGMA["focal_relative"] / f_unit),
        np.full(column_terms, PRIOR_SIGMA["column_px"]),
    ]) * prior_scale  # fmt: skip
    n_obs = 2 * row.size

    def residuals(p: np.ndarray) -> np.ndarray:
        ext, interior = unpack(p)
        sc = replace(scene0, exterior=ext, interior=interior)
        x, y = sc.focal_plane(ground, t)
        y_obs = interior.column_to_y(col) if column_terms else y_fixed
        data = np.concatenate([(x - interior.detector_x(y)) / pitch, (y - y_obs) / pitch])
        if prior_scale <= 0:
            return data
        return np.concatenate([data, p / sigma])

    p0 = np.zeros(n_par)
    r0 = residuals(p0)
    initial_rmse = float(np.sqrt(np.mean(r0[: row.size] ** 2 + r0[row.size : n_obs] ** 2)))
    kwargs = {} if max_nfev is None else {"max_nfev": max_nfev}
    # Position, attitude and interior are strongly correlated (narrow field of view): the damped
    # iteration can stop in a long curved valley.  Restarting from the last solution (fresh
    # damping and scaling) continues down the valley; stop when the cost no longer drops.
    nfev = 0
    x = p0
    cost = np.inf
    for _ in range(restarts + 1):
        sol = least_squares(residuals, x, method=method, x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                            **kwargs)
        nfev += int(sol.nfev)
        improved = sol.cost < cost * (1.0 - 1e-6)
        if sol.cost <= cost:
            x, cost, best = sol.x, sol.cost, sol
        if not improved:
            break
    sol = best
    x = _gauss_newton_polish(residuals, sol.x, n_obs, iterations=polish)
    nfev += polish * (2 * n_par + 2)
    ext, interior = unpack(x)
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
        nfev=nfev,
        success=bool(sol.status > 0),
        message=str(sol.message),
    )
    return scene, report
