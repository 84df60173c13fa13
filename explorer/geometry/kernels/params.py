"""The scene packed into plain arrays for the collinearity kernels: :class:`CollinearityParams`, the
branch-free evaluator's tables (:class:`FixedModel`) and the solver status codes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from explorer._numba import njit

if TYPE_CHECKING:  # typing only: the scene layer sits above geometry
    from explorer.scene import Scene


# Solver status codes (per point).
STATUS_CONVERGED = 0
STATUS_NO_ROOT_IN_WINDOW = 1  # the residual keeps its sign over the whole search window
STATUS_INVALID = 2  # behind the camera (v_z >= 0) or a non-finite residual
STATUS_MAX_ITER = 3  # still iterating after max_iter
STATUS_NAMES = {0: "converged", 1: "no_root_in_window", 2: "behind_camera_or_invalid", 3: "max_iter"}


@njit(cache=True, inline="always")
def store_point(i, status, ok_status, row, col, evaluations, row_out, col_out, status_out, evaluations_out):
    """Write point ``i``'s result in a compiled loop: row and column (NaN unless ``status == ok_status``),
    status code and evaluation count."""
    done = status == ok_status
    row_out[i] = row if done else np.nan
    col_out[i] = col if done else np.nan
    status_out[i] = status
    evaluations_out[i] = evaluations

# Taylor coefficients of sin(d) and cos(d) - 1 for |d| <= SMALL_ANGLE (truncation < 1e-19 relative)
SMALL_ANGLE = 0.0625
_S3, _S5, _S7, _S9 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0
_C2, _C4, _C6, _C8, _C10 = -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0
FIXED_MAX_TERMS = 8  # most jitter sinusoids / distortion / curvature terms the fixed evaluator takes


_A = np.ndarray
#: :meth:`FixedModel.args`: ``P, V, A, AR, sc0, jn, jp, jt, js, jc, jt0, jinv_dt, dn, dist, cn, curv``.
FixedArgs = tuple[_A, _A, _A, _A, _A, tuple, _A, _A, _A, _A, float, float, tuple, _A, tuple, _A]
#: :meth:`CollinearityParams.model_args`: ``pos, dpos, att, datt, jitter, focal, offset, curv, dist, sc0, fast``.
ModelArgs = tuple[_A, _A, _A, _A, _A, float, float, _A, _A, _A, bool]


@dataclass(frozen=True)
class FixedModel:
    """Arrays of the branch-free evaluator :func:`_ce_fixed_py` (see :meth:`CollinearityParams.fixed_model`).

    The counts of jitter sinusoids, distortion and curvature terms travel as tuples ``jn``, ``dn``,
    ``cn`` of length count + 1 (numba's parallel loops reject empty tuples): numba compiles one
    specialisation per combination, with the loops over them unrolled (and absent for a zero
    count), so the loop over points stays vectorisable.
    """

    P: np.ndarray  # (3, 4) position coefficients, zero-padded to degree 3
    V: np.ndarray  # (3, 3) velocity coefficients
    A: np.ndarray  # (3, 4) angle coefficients (column 0 unused: increments from the constant term)
    AR: np.ndarray  # (3, 3) angle-rate coefficients
    sc0: np.ndarray  # (3, 2) sin, cos of the constant angle terms
    jn: tuple  # J + 1 zeros: the jitter count
    jp: np.ndarray  # (J, 5) amplitude, angular frequency, one-hot (omega, phi, kappa)
    jt: np.ndarray  # (K,) table times (integer scanlines)
    js: np.ndarray  # (J, K) sin(w t_k + p)
    jc: np.ndarray  # (J, K) cos(w t_k + p)
    jt0: float
    jinv_dt: float
    dn: tuple  # M + 1 zeros: the distortion term count
    dist: np.ndarray  # (max(M, 1),) k1, k2, ...
    cn: tuple  # L + 1 zeros: the curvature term count
    curv: np.ndarray  # (max(L, 1),) c1, c2, ...

    def args(self) -> FixedArgs:
        """Positional arguments of :func:`_ce_fixed_py` after ``(X, Y, Z, t)`` (``focal, offset`` follow)."""
        return (
            self.P,
            self.V,
            self.A,
            self.AR,
            self.sc0,
            self.jn,
            self.jp,
            self.jt,
            self.js,
            self.jc,
            self.jt0,
            self.jinv_dt,
            self.dn,
            self.dist,
            self.cn,
            self.curv,
        )


@dataclass(frozen=True)
class CollinearityParams:
    """The scene packed into plain arrays for the kernels.

    Attributes
    ----------
    pos, dpos : ndarray, shape (3, D+1), (3, max(D, 1))
        Ascending coefficients of S(t) and dS/dt (metres, m/s, ...).
    att, datt : ndarray, shape (3, Da+1), (3, max(Da, 1))
        Ascending coefficients of the angles and their rates (rad, rad/s, ...).
    jitter : ndarray, shape (J, 4)
        ``(angle index, amplitude rad, angular frequency 2 pi f rad/s, phase rad)`` per sinusoid.
    focal, pitch, principal_column, offset : float
        Interior orientation, metres (principal column in pixels).
    curvature : ndarray, shape (K,)
        Detector line coefficients ``c1, c2, ...``.
    distortion : ndarray, shape (M,)
        Radial distortion ``k1, k2, ...``.
    line_period, reference_row : float
        ``t = (row - reference_row) * line_period``.
    n_rows, n_columns : int
    sc0 : ndarray, shape (3, 2)
        ``sin`` and ``cos`` of the constant terms of omega, phi, kappa (for the fast paths).
    """

    pos: np.ndarray
    dpos: np.ndarray
    att: np.ndarray
    datt: np.ndarray
    jitter: np.ndarray
    focal: float
    pitch: float
    principal_column: float
    offset: float
    curvature: np.ndarray
    distortion: np.ndarray
    line_period: float
    reference_row: float
    n_rows: int
    n_columns: int
    sc0: np.ndarray
    column_polynomial: tuple = ()
    interior: Any = None  # InteriorOrientation (for column_polynomial)

    def to_columns(self, col: np.ndarray) -> np.ndarray:
        """Kernel columns (``y_d / pitch + principal_column``, evenly spaced detectors) -> image columns.

        The identity unless the camera has a non-uniform detector spacing (``column_polynomial``),
        which only changes the column, not the along-track residual; then the measured ``y_d`` is
        recovered and mapped by :meth:`InteriorOrientation.y_to_column`.
        """
        if not self.column_polynomial:
            return col
        return self.interior.y_to_column((col - self.principal_column) * self.pitch)

    @classmethod
    def from_scene(cls, scene: Scene) -> CollinearityParams:
        """Pack a :class:`~explorer.scene.Scene` (its terrain is not needed)."""
        ext, inner = scene.exterior, scene.interior

        def deriv(c: np.ndarray) -> np.ndarray:
            # identical to explorer.geometry.exterior._derivative_coeffs
            d = c.shape[1]
            if d == 1:
                return np.zeros_like(c)
            return np.ascontiguousarray(c[:, 1:] * np.arange(1, d, dtype=np.float64))

        names = ("omega", "phi", "kappa")
        jit = np.array(
            [[names.index(j.angle), j.amplitude_rad, 2.0 * np.pi * j.frequency_hz, j.phase_rad] for j in ext.jitter],
            dtype=np.float64,
        ).reshape(-1, 4)
        return cls(
            pos=np.ascontiguousarray(ext.position_coeffs, dtype=np.float64),
            dpos=deriv(ext.position_coeffs),
            att=np.ascontiguousarray(ext.attitude_coeffs, dtype=np.float64),
            datt=deriv(ext.attitude_coeffs),
            jitter=jit,
            focal=float(inner.focal_length_m),
            pitch=float(inner.detector_pitch_m),
            principal_column=float(inner.principal_column),
            offset=float(inner.along_track_offset_m),
            curvature=np.asarray(inner.line_curvature, dtype=np.float64).reshape(-1),
            distortion=np.asarray(inner.radial_distortion, dtype=np.float64).reshape(-1),
            line_period=float(scene.timing.line_period_s),
            reference_row=float(scene.timing.reference_row),
            n_rows=int(scene.n_rows),
            n_columns=int(scene.n_columns),
            sc0=np.stack([np.sin(ext.attitude_coeffs[:, 0]), np.cos(ext.attitude_coeffs[:, 0])], axis=1),
            column_polynomial=tuple(getattr(inner, "column_polynomial", ())),
            interior=inner,
        )

    def model_args(self, fast: bool = False) -> ModelArgs:
        """Positional arguments of :func:`_collinearity_point_py` after ``(X, Y, Z, t)``."""
        return (
            self.pos,
            self.dpos,
            self.att,
            self.datt,
            self.jitter,
            self.focal,
            self.offset,
            self.curvature,
            self.distortion,
            self.sc0,
            bool(fast),
        )

    def fixed_model(self, window: tuple[float, float]) -> FixedModel | None:
        """Arrays of the branch-free evaluator for rows in ``window``, or None where it does not apply.

        It applies when the position and attitude polynomials have degree <= 3, there are at most
        ``FIXED_MAX_TERMS`` jitter sinusoids (each with ``w * line_period <= SMALL_ANGLE``),
        distortion and curvature terms, and the angle increments from their constant terms stay
        below ``SMALL_ANGLE / 2`` over the window (checked on a dense time grid).  The kernels
        clip the rows they evaluate to the window.
        """
        if (
            self.pos.shape[1] > 4
            or self.att.shape[1] > 4
            or self.jitter.shape[0] > FIXED_MAX_TERMS
            or self.distortion.size > FIXED_MAX_TERMS
            or self.curvature.size > FIXED_MAX_TERMS
        ):
            return None
        if self.jitter.shape[0] and np.max(np.abs(self.jitter[:, 2])) * self.line_period > SMALL_ANGLE:
            return None

        def pad(c: np.ndarray, k: int) -> np.ndarray:
            out = np.zeros((3, k))
            out[:, : c.shape[1]] = c
            return out

        P, V, A, AR = pad(self.pos, 4), pad(self.dpos, 3), pad(self.att, 4), pad(self.datt, 3)
        tt = (np.linspace(window[0], window[1], 8193) - self.reference_row) * self.line_period
        inc = ((A[:, 3:4] * tt + A[:, 2:3]) * tt + A[:, 1:2]) * tt
        if not np.max(np.abs(inc)) <= 0.5 * SMALL_ANGLE:
            return None
        k0 = int(np.floor(window[0])) - 1
        k1 = int(np.ceil(window[1])) + 1
        rows = np.arange(k0, k1 + 1, dtype=np.float64)
        jt = (rows - self.reference_row) * self.line_period  # as LineTiming.scanline_time
        n_jit = self.jitter.shape[0]
        jp = np.zeros((n_jit, 5))
        js = np.zeros((n_jit, rows.size))
        jc = np.ones((n_jit, rows.size))
        for k, (which, amp, w, phase) in enumerate(self.jitter):
            jp[k, :2] = amp, w
            jp[k, 2 + int(which)] = 1.0
            js[k] = np.sin(w * jt + phase)
            jc[k] = np.cos(w * jt + phase)

        def at_least_one(c: np.ndarray) -> np.ndarray:
            return np.ascontiguousarray(c if c.size else np.zeros(1))

        return FixedModel(
            P, V, A, AR,
            self.sc0,
            (0,) * (n_jit + 1),
            jp, jt, js, jc,
            float(jt[0]),
            1.0 / self.line_period,
            (0,) * (self.distortion.size + 1),
            at_least_one(self.distortion),
            (0,) * (self.curvature.size + 1),
            at_least_one(self.curvature),
        )
