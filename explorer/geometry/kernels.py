"""Fast collinearity kernels: the along-track residual, its analytic time derivative and the
image column for millions of points, plus the compiled per-point root finders used by the
``exact`` and ``csm-secant`` methods.

The residual is the best-scanline condition of ``docs/conventions.md#best-scanline``
(Ahooei Nezhad et al. 2024, Remote Sensing 16:2787, eqs. 1-2; the MPC model of the same paper):

    v = R(t)^T (P - S(t)),   x = -f v_x / v_z,   y = -f v_y / v_z,
    (x_d, y_d) = (x, y) * F(r^2),   F = 1 + k1 r^2 + k2 r^4 + ...,   r^2 = x^2 + y^2,
    g(t) = x_d - x_det(y_d),   x_det(y) = offset + c1 y + c2 y^2 + ...

with ``S(t)`` and the angles ``(omega, phi, kappa)(t)`` ascending polynomials of any degree plus
jitter sinusoids ``A sin(w t + p)`` and ``R = R_x(omega) R_y(phi) R_z(kappa)``
(``docs/conventions.md#rotations``).  Its time derivative is analytic:

    dv/dt = (dR/dt)^T (P - S) - R^T dS/dt,
    dR/dt = dR/domega omega' + dR/dphi phi' + dR/dkappa kappa'   (chain rule on the closed form),
    dx/dt = (-f / v_z) (v_x' - v_x v_z' / v_z)   (same for y),
    d(r^2)/dt = 2 (x x' + y y'),   x_d' = x' F + x F'(r^2) (r^2)',
    g' = x_d' - x_det'(y_d) y_d',

with ``dS/dt`` the velocity polynomial and the angle rates including the jitter terms
``A w cos(w t + p)``.

Three evaluators of one collinearity evaluation (CE: residual, derivative, column):

* :func:`_collinearity_point_py` with ``fast=False`` -- the reference: the same floating-point
  operations in the same order as :meth:`explorer.scene.Scene.along_track_residual` (bit for bit);
* the same function with ``fast=True`` -- the angle sines by the addition theorem around the
  constant terms with Taylor series of the small increment (:func:`_sincos_near`), one division;
* :func:`_ce_fixed_py` -- branch- and loop-free: polynomials zero-padded to degree 3, up to
  ``JITTER_MAX`` jitter sinusoids from per-scanline tables of ``sin``/``cos`` plus the addition
  theorem, distortion and detector curvature zero-padded to 3 terms.  LLVM vectorises the loop
  over points (AVX2) around it.  It applies when the scene fits (:meth:`CollinearityParams.fixed_model`).

All of them are written with operations valid on scalars and on numpy arrays alike: numba compiles
them for the per-point kernels, and the pure-numpy fallback (numba missing, or
``EXPLORER_DISABLE_NUMBA=1``) calls the very same code on arrays, so both backends perform the same
operations and agree bit for bit (given the same libm).  ``fast`` results differ from the reference
by round-off only (about ``eps |S - P| / GSD``, 1e-10 px), the floor of the model itself.

The solvers (:func:`solve_exact`, :func:`solve_secant`) run the per-point iterations inside
compiled ``prange``-parallel loops (no per-point Python); the numpy fallbacks run the same
algorithms vectorised over points, one Python step per iteration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, njit, numba, overload, prange  # noqa: F401 - re-exported
from explorer.scene import Scene

# Solver status codes (per point).
STATUS_CONVERGED = 0
STATUS_NO_ROOT_IN_WINDOW = 1  # the residual keeps its sign over the whole search window
STATUS_INVALID = 2  # behind the camera (v_z >= 0) or a non-finite residual
STATUS_MAX_ITER = 3  # still iterating after max_iter
STATUS_NAMES = {0: "converged", 1: "no_root_in_window", 2: "behind_camera_or_invalid", 3: "max_iter"}

# Taylor coefficients of sin(d) and cos(d) - 1 for |d| <= SMALL_ANGLE (truncation < 1e-19 relative)
SMALL_ANGLE = 0.0625
_S3, _S5, _S7, _S9 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0
_C2, _C4, _C6, _C8, _C10 = -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0
FIXED_MAX_TERMS = 8  # most jitter sinusoids / distortion / curvature terms the fixed evaluator takes


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

    def args(self) -> tuple:
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
    interior: object = None

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

    def model_args(self, fast: bool = False) -> tuple:
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
            P,
            V,
            A,
            AR,
            self.sc0,
            (0,) * (n_jit + 1),
            jp,
            jt,
            js,
            jc,
            float(jt[0]),
            1.0 / self.line_period,
            (0,) * (self.distortion.size + 1),
            at_least_one(self.distortion),
            (0,) * (self.curvature.size + 1),
            at_least_one(self.curvature),
        )


def _sincos_near(a0, s0, c0, d):
    """``sin(a0 + d), cos(a0 + d)`` from ``s0 = sin a0, c0 = cos a0`` and a small increment ``d``.

    The addition theorem with Taylor series of ``sin d`` and ``cos d - 1`` (exact to round-off for
    ``|d| <= SMALL_ANGLE``); larger increments fall back to ``sin``/``cos`` of ``a0 + d``.  Numpy
    version (arrays); numba compiles the scalar overload below, which takes the same decisions and
    performs the same operations.
    """
    d2 = d * d
    sd = d + d * (d2 * (_S3 + d2 * (_S5 + d2 * (_S7 + d2 * _S9))))
    cm1 = d2 * (_C2 + d2 * (_C4 + d2 * (_C6 + d2 * (_C8 + d2 * _C10))))
    s = s0 + (s0 * cm1 + c0 * sd)
    c = c0 + (c0 * cm1 - s0 * sd)
    big = np.abs(d) > SMALL_ANGLE
    if np.any(big):
        a = a0 + d
        s = np.where(big, np.sin(a), s)
        c = np.where(big, np.cos(a), c)
    return s, c


def _table_index(x, last):
    """``floor(x)`` clamped to ``[0, last]`` as an integer index (arrays; scalar overload below)."""
    return np.clip(np.floor(x), 0, last).astype(np.int64)


if NUMBA_AVAILABLE:

    @overload(_sincos_near, jit_options={"fastmath": False})
    def _sincos_near_scalar(a0, s0, c0, d):  # pragma: no cover - compiled
        def impl(a0, s0, c0, d):
            if abs(d) > SMALL_ANGLE:
                a = a0 + d
                return np.sin(a), np.cos(a)
            d2 = d * d
            sd = d + d * (d2 * (_S3 + d2 * (_S5 + d2 * (_S7 + d2 * _S9))))
            cm1 = d2 * (_C2 + d2 * (_C4 + d2 * (_C6 + d2 * (_C8 + d2 * _C10))))
            return s0 + (s0 * cm1 + c0 * sd), c0 + (c0 * cm1 - s0 * sd)

        return impl

    @overload(_table_index, jit_options={"fastmath": False})
    def _table_index_scalar(x, last):  # pragma: no cover - compiled
        def impl(x, last):
            return min(max(int(np.floor(x)), 0), last)

        return impl


def _collinearity_point_py(X, Y, Z, t, pos, dpos, att, datt, jit, focal, offset, curv, dist, sc0, fast):
    """Residual, its time derivative and the measured across-track coordinate at time ``t``.

    Valid for scalars (compiled by numba) and for numpy arrays of equal shape (the fallback).

    Parameters
    ----------
    X, Y, Z : float or ndarray (N,)
        Ground point, local ENU metres.
    t : float or ndarray (N,)
        Scanline time, seconds.
    pos, dpos, att, datt, jit, focal, offset, curv, dist, sc0
        See :class:`CollinearityParams`.
    fast : bool
        False: the angles are evaluated and their sines taken exactly as
        :meth:`Scene.along_track_residual` does (bitwise the same residual).  True: the sines come
        from the addition theorem around the constant terms ``a0`` (``sc0``) with Taylor series
        of the increment (:func:`_sincos_near`) and one division: cheaper, equal to round-off.

    Returns
    -------
    g : along-track residual ``x_d - x_det(y_d)``, metres
    g_t : dg/dt, m/s
    yd : measured across-track focal-plane coordinate, metres
    yd_t : d yd / dt, m/s
    vz : sensor-frame z of the point, metres (negative in front of the camera)
    """
    # perspective centre and velocity (Horner, ascending coefficients, as polyval_ascending)
    d_pos = pos.shape[1]
    sx = pos[0, d_pos - 1] + 0.0 * t
    sy = pos[1, d_pos - 1] + 0.0 * t
    sz = pos[2, d_pos - 1] + 0.0 * t
    for j in range(d_pos - 2, -1, -1):
        sx = sx * t + pos[0, j]
        sy = sy * t + pos[1, j]
        sz = sz * t + pos[2, j]
    d_vel = dpos.shape[1]
    vx_s = dpos[0, d_vel - 1] + 0.0 * t
    vy_s = dpos[1, d_vel - 1] + 0.0 * t
    vz_s = dpos[2, d_vel - 1] + 0.0 * t
    for j in range(d_vel - 2, -1, -1):
        vx_s = vx_s * t + dpos[0, j]
        vy_s = vy_s * t + dpos[1, j]
        vz_s = vz_s * t + dpos[2, j]
    # angles (fast: their increments from the constant terms) and rates
    d_att = att.shape[1]
    lowest = 1 if fast else 0
    om = att[0, d_att - 1] + 0.0 * t
    ph = att[1, d_att - 1] + 0.0 * t
    ka = att[2, d_att - 1] + 0.0 * t
    if d_att - 1 < lowest:  # fast with constant angles: zero increments
        om = 0.0 * t
        ph = 0.0 * t
        ka = 0.0 * t
    for j in range(d_att - 2, lowest - 1, -1):
        om = om * t + att[0, j]
        ph = ph * t + att[1, j]
        ka = ka * t + att[2, j]
    if fast and d_att > 1:
        om = om * t
        ph = ph * t
        ka = ka * t
    d_rate = datt.shape[1]
    om_t = datt[0, d_rate - 1] + 0.0 * t
    ph_t = datt[1, d_rate - 1] + 0.0 * t
    ka_t = datt[2, d_rate - 1] + 0.0 * t
    for j in range(d_rate - 2, -1, -1):
        om_t = om_t * t + datt[0, j]
        ph_t = ph_t * t + datt[1, j]
        ka_t = ka_t * t + datt[2, j]
    for k in range(jit.shape[0]):
        which = int(jit[k, 0])
        amp = jit[k, 1]
        w = jit[k, 2]
        arg = w * t + jit[k, 3]
        s_j = amp * np.sin(arg)
        c_j = amp * w * np.cos(arg)
        if which == 0:
            om = om + s_j
            om_t = om_t + c_j
        elif which == 1:
            ph = ph + s_j
            ph_t = ph_t + c_j
        else:
            ka = ka + s_j
            ka_t = ka_t + c_j
    if fast:
        so, co = _sincos_near(att[0, 0], sc0[0, 0], sc0[0, 1], om)
        sp, cp = _sincos_near(att[1, 0], sc0[1, 0], sc0[1, 1], ph)
        sk, ck = _sincos_near(att[2, 0], sc0[2, 0], sc0[2, 1], ka)
    else:
        so = np.sin(om)
        co = np.cos(om)
        sp = np.sin(ph)
        cp = np.cos(ph)
        sk = np.sin(ka)
        ck = np.cos(ka)
    # R = Rx(omega) Ry(phi) Rz(kappa), as explorer.geometry.rotations.rotation_from_opk
    r00 = cp * ck
    r01 = -cp * sk
    r02 = sp
    r10 = co * sk + so * sp * ck
    r11 = co * ck - so * sp * sk
    r12 = -so * cp
    r20 = so * sk - co * sp * ck
    r21 = so * ck + co * sp * sk
    r22 = co * cp
    # dR/dt = dR/domega omega' + dR/dphi phi' + dR/dkappa kappa'
    # dR/domega: row 0 -> 0, row 1 -> -row 2, row 2 -> row 1
    # dR/dphi: Rx(omega) dRy(phi) Rz(kappa)
    # dR/dkappa: R @ [[0,-1,0],[1,0,0],[0,0,0]] -> column 0 -> column 1, column 1 -> -column 0
    spck = sp * ck
    spsk = sp * sk
    q00 = -spck * ph_t + r01 * ka_t
    q01 = spsk * ph_t - r00 * ka_t
    q02 = cp * ph_t
    q10 = -r20 * om_t + so * cp * ck * ph_t + r11 * ka_t
    q11 = -r21 * om_t - so * cp * sk * ph_t - r10 * ka_t
    q12 = -r22 * om_t + so * sp * ph_t
    q20 = r10 * om_t - co * cp * ck * ph_t + r21 * ka_t
    q21 = r11 * om_t + co * cp * sk * ph_t - r20 * ka_t
    q22 = r12 * om_t - co * sp * ph_t
    # v = R^T (P - S)  (sum over the first index, in order, as the numpy einsum)
    dx = X - sx
    dy = Y - sy
    dz = Z - sz
    vx = r00 * dx + r10 * dy + r20 * dz
    vy = r01 * dx + r11 * dy + r21 * dz
    vz = r02 * dx + r12 * dy + r22 * dz
    # dv/dt = Rdot^T (P - S) - R^T dS/dt
    vx_t = (q00 * dx + q10 * dy + q20 * dz) - (r00 * vx_s + r10 * vy_s + r20 * vz_s)
    vy_t = (q01 * dx + q11 * dy + q21 * dz) - (r01 * vx_s + r11 * vy_s + r21 * vz_s)
    vz_t = (q02 * dx + q12 * dy + q22 * dz) - (r02 * vx_s + r12 * vy_s + r22 * vz_s)
    if fast:  # one division
        inv_vz = 1.0 / vz
        scale = -focal * inv_vz
        ratio = vz_t * inv_vz
    else:  # as ideal_focal_plane
        scale = -focal / vz
        ratio = vz_t / vz
    x = vx * scale
    y = vy * scale
    x_t = scale * (vx_t - vx * ratio)
    y_t = scale * (vy_t - vy * ratio)
    # radial distortion (explorer.geometry.interior.InteriorOrientation.distort)
    if dist.shape[0] > 0:
        r2 = x * x + y * y
        factor = 1.0 + 0.0 * r2
        power = 1.0 + 0.0 * r2
        dfactor = 0.0 * r2
        dpower = 1.0 + 0.0 * r2
        for m in range(dist.shape[0]):
            power = power * r2
            factor = factor + dist[m] * power
            dfactor = dfactor + (m + 1) * dist[m] * dpower
            dpower = dpower * r2
        r2_t = 2.0 * (x * x_t + y * y_t)
        xd = x * factor
        yd = y * factor
        xd_t = x_t * factor + x * dfactor * r2_t
        yd_t = y_t * factor + y * dfactor * r2_t
    else:
        xd = x
        yd = y
        xd_t = x_t
        yd_t = y_t
    # detector line (InteriorOrientation.detector_x) and its slope
    xdet = offset + 0.0 * yd
    slope = 0.0 * yd
    power = 1.0 + 0.0 * yd
    for m in range(curv.shape[0]):
        slope = slope + (m + 1) * curv[m] * power
        power = power * yd
        xdet = xdet + curv[m] * power
    g = xd - xdet
    g_t = xd_t - slope * yd_t
    return g, g_t, yd, yd_t, vz


collinearity_point = njit(cache=True, fastmath=False)(_collinearity_point_py) if NUMBA_AVAILABLE else None


def _ce_fixed_py(X, Y, Z, t, P, V, A, AR, sc0, jn, jp, jt, js, jc, jt0, jinv_dt, dn, dist, cn, curv, focal, offset):
    """One CE, branch- and loop-free (see the module docstring and :meth:`CollinearityParams.fixed_model`).

    Same returns as :func:`_collinearity_point_py`; equal to it to round-off for the scenes the
    fixed model applies to, for ``t`` within the model's window.  Scalars (compiled) or arrays.
    """
    sx = ((P[0, 3] * t + P[0, 2]) * t + P[0, 1]) * t + P[0, 0]
    sy = ((P[1, 3] * t + P[1, 2]) * t + P[1, 1]) * t + P[1, 0]
    sz = ((P[2, 3] * t + P[2, 2]) * t + P[2, 1]) * t + P[2, 0]
    vx_s = (V[0, 2] * t + V[0, 1]) * t + V[0, 0]
    vy_s = (V[1, 2] * t + V[1, 1]) * t + V[1, 0]
    vz_s = (V[2, 2] * t + V[2, 1]) * t + V[2, 0]
    d_om = ((A[0, 3] * t + A[0, 2]) * t + A[0, 1]) * t
    d_ph = ((A[1, 3] * t + A[1, 2]) * t + A[1, 1]) * t
    d_ka = ((A[2, 3] * t + A[2, 2]) * t + A[2, 1]) * t
    om_t = (AR[0, 2] * t + AR[0, 1]) * t + AR[0, 0]
    ph_t = (AR[1, 2] * t + AR[1, 1]) * t + AR[1, 0]
    ka_t = (AR[2, 2] * t + AR[2, 1]) * t + AR[2, 0]
    if len(jn) > 1:  # jitter: sin/cos at the nearest tabulated scanline, moved by the addition theorem
        k = _table_index((t - jt0) * jinv_dt + 0.5, jt.shape[0] - 1)
        tau = t - jt[k]
        for j in range(len(jn) - 1):
            amp = jp[j, 0]
            w = jp[j, 1]
            e = w * tau
            q = e * e
            se = e + e * (q * (_S3 + q * (_S5 + q * (_S7 + q * _S9))))
            ce = q * (_C2 + q * (_C4 + q * (_C6 + q * (_C8 + q * _C10))))
            s0 = js[j, k]
            c0 = jc[j, k]
            a_s = amp * (s0 + (s0 * ce + c0 * se))
            a_c = amp * w * (c0 + (c0 * ce - s0 * se))
            d_om = d_om + jp[j, 2] * a_s
            d_ph = d_ph + jp[j, 3] * a_s
            d_ka = d_ka + jp[j, 4] * a_s
            om_t = om_t + jp[j, 2] * a_c
            ph_t = ph_t + jp[j, 3] * a_c
            ka_t = ka_t + jp[j, 4] * a_c
    q = d_om * d_om
    sd = d_om + d_om * (q * (_S3 + q * (_S5 + q * (_S7 + q * _S9))))
    cm1 = q * (_C2 + q * (_C4 + q * (_C6 + q * (_C8 + q * _C10))))
    so = sc0[0, 0] + (sc0[0, 0] * cm1 + sc0[0, 1] * sd)
    co = sc0[0, 1] + (sc0[0, 1] * cm1 - sc0[0, 0] * sd)
    q = d_ph * d_ph
    sd = d_ph + d_ph * (q * (_S3 + q * (_S5 + q * (_S7 + q * _S9))))
    cm1 = q * (_C2 + q * (_C4 + q * (_C6 + q * (_C8 + q * _C10))))
    sp = sc0[1, 0] + (sc0[1, 0] * cm1 + sc0[1, 1] * sd)
    cp = sc0[1, 1] + (sc0[1, 1] * cm1 - sc0[1, 0] * sd)
    q = d_ka * d_ka
    sd = d_ka + d_ka * (q * (_S3 + q * (_S5 + q * (_S7 + q * _S9))))
    cm1 = q * (_C2 + q * (_C4 + q * (_C6 + q * (_C8 + q * _C10))))
    sk = sc0[2, 0] + (sc0[2, 0] * cm1 + sc0[2, 1] * sd)
    ck = sc0[2, 1] + (sc0[2, 1] * cm1 - sc0[2, 0] * sd)
    r00 = cp * ck
    r01 = -cp * sk
    r02 = sp
    r10 = co * sk + so * sp * ck
    r11 = co * ck - so * sp * sk
    r12 = -so * cp
    r20 = so * sk - co * sp * ck
    r21 = so * ck + co * sp * sk
    r22 = co * cp
    spck = sp * ck
    spsk = sp * sk
    q00 = -spck * ph_t + r01 * ka_t
    q01 = spsk * ph_t - r00 * ka_t
    q02 = cp * ph_t
    q10 = -r20 * om_t + so * cp * ck * ph_t + r11 * ka_t
    q11 = -r21 * om_t - so * cp * sk * ph_t - r10 * ka_t
    q12 = -r22 * om_t + so * sp * ph_t
    q20 = r10 * om_t - co * cp * ck * ph_t + r21 * ka_t
    q21 = r11 * om_t + co * cp * sk * ph_t - r20 * ka_t
    q22 = r12 * om_t - co * sp * ph_t
    dx = X - sx
    dy = Y - sy
    dz = Z - sz
    vx = r00 * dx + r10 * dy + r20 * dz
    vy = r01 * dx + r11 * dy + r21 * dz
    vz = r02 * dx + r12 * dy + r22 * dz
    vx_t = (q00 * dx + q10 * dy + q20 * dz) - (r00 * vx_s + r10 * vy_s + r20 * vz_s)
    vy_t = (q01 * dx + q11 * dy + q21 * dz) - (r01 * vx_s + r11 * vy_s + r21 * vz_s)
    vz_t = (q02 * dx + q12 * dy + q22 * dz) - (r02 * vx_s + r12 * vy_s + r22 * vz_s)
    inv_vz = 1.0 / vz
    scale = -focal * inv_vz
    ratio = vz_t * inv_vz
    x = vx * scale
    y = vy * scale
    x_t = scale * (vx_t - vx * ratio)
    y_t = scale * (vy_t - vy * ratio)
    xd = x
    yd = y
    xd_t = x_t
    yd_t = y_t
    if len(dn) > 1:  # radial distortion
        r2 = x * x + y * y
        factor = 1.0 + 0.0 * r2
        dfactor = 0.0 * r2
        power = 1.0 + 0.0 * r2
        for m in range(len(dn) - 1):
            dfactor = dfactor + (m + 1) * dist[m] * power
            power = power * r2
            factor = factor + dist[m] * power
        r2_t = 2.0 * (x * x_t + y * y_t)
        xd = x * factor
        yd = y * factor
        xd_t = x_t * factor + x * dfactor * r2_t
        yd_t = y_t * factor + y * dfactor * r2_t
    g = xd - offset
    g_t = xd_t
    if len(cn) > 1:  # curved detector line
        slope = 0.0 * yd
        power = 1.0 + 0.0 * yd
        xline = 0.0 * yd
        for m in range(len(cn) - 1):
            slope = slope + (m + 1) * curv[m] * power
            power = power * yd
            xline = xline + curv[m] * power
        g = g - xline
        g_t = g_t - slope * yd_t
    return g, g_t, yd, yd_t, vz


_ce_fixed = njit(cache=True, fastmath=False, inline="always")(_ce_fixed_py) if NUMBA_AVAILABLE else None


# --------------------------------------------------------------------------- residual kernel
@njit(parallel=True, fastmath=False, cache=True)
def _residual_nb(
    ground, t, pos, dpos, att, datt, jit, focal, offset, curv, dist, sc0, fast, pitch, pc, g_out, gt_out, col_out
):  # pragma: no cover - compiled
    for i in prange(ground.shape[0]):
        g, gt, yd, ydt, vz = collinearity_point(
            ground[i, 0],
            ground[i, 1],
            ground[i, 2],
            t[i],
            pos,
            dpos,
            att,
            datt,
            jit,
            focal,
            offset,
            curv,
            dist,
            sc0,
            fast,
        )
        g_out[i] = g
        gt_out[i] = gt
        col_out[i] = yd / pitch + pc


@njit(parallel=True, fastmath=False, cache=True)
def _residual_fixed_nb(ground, t_all, fx, focal, offset, pitch, pc, g_out, gt_out, col_out):  # pragma: no cover
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    for i in prange(ground.shape[0]):
        X = ground[i, 0]
        Y = ground[i, 1]
        Z = ground[i, 2]
        t = t_all[i]
        g, gt, yd, ydt, vz = _ce_fixed(
            X, Y, Z, t, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, focal, offset
        )
        g_out[i] = g
        gt_out[i] = gt
        col_out[i] = yd / pitch + pc


def _use_numba(backend: str) -> bool:
    if backend not in ("auto", "numba", "numpy"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'numpy', got {backend!r}")
    if backend == "numba" and not NUMBA_AVAILABLE:
        raise RuntimeError("backend='numba' requested but numba is not available")
    return NUMBA_AVAILABLE and backend != "numpy"


def _params(scene_or_params: Scene | CollinearityParams) -> CollinearityParams:
    if isinstance(scene_or_params, CollinearityParams):
        return scene_or_params
    return CollinearityParams.from_scene(scene_or_params)


def residual_and_rate(
    scene: Scene | CollinearityParams,
    ground: np.ndarray,
    t: np.ndarray,
    *,
    backend: str = "auto",
    evaluator: str = "reference",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along-track residual, its time derivative and the column: one collinearity evaluation.

    Parameters
    ----------
    scene : Scene or CollinearityParams
    ground : ndarray, shape (N, 3)
        Local ENU metres.
    t : ndarray, shape (N,) or scalar
        Scanline times, seconds.
    backend : {"auto", "numba", "numpy"}
        "auto" uses numba when available.
    evaluator : {"reference", "fast", "fixed"}
        "reference" reproduces :meth:`Scene.along_track_residual` bit for bit; "fast" uses the
        addition-theorem sines; "fixed" the branch-free evaluator the solvers use (times must lie
        within the image +-64 rows; raises ValueError where the scene does not fit it).

    Returns
    -------
    g : ndarray, shape (N,)
        ``x_d - x_det(y_d)`` metres (as :meth:`Scene.along_track_residual`; divide by the pitch for
        pixels).
    g_t : ndarray, shape (N,)
        ``dg/dt``, metres per second (analytic).
    col : ndarray, shape (N,)
        Image column at time ``t``.
    """
    if evaluator not in ("reference", "fast", "fixed"):
        raise ValueError(f"evaluator must be 'reference', 'fast' or 'fixed', got {evaluator!r}")
    p = _params(scene)
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    t = np.ascontiguousarray(np.broadcast_to(np.asarray(t, dtype=np.float64), ground.shape[:1]))
    n = ground.shape[0]
    if evaluator == "fixed":
        fm = p.fixed_model((-64.5, p.n_rows + 63.5))
        if fm is None:
            raise ValueError("the fixed evaluator does not apply to this scene (see CollinearityParams.fixed_model)")
        if _use_numba(backend):
            g, gt, col = np.empty(n), np.empty(n), np.empty(n)
            _residual_fixed_nb(ground, t, fm.args(), p.focal, p.offset, p.pitch, p.principal_column, g, gt, col)
            return g, gt, p.to_columns(col)
        g, gt, yd, _, _ = _ce_fixed_py(ground[:, 0], ground[:, 1], ground[:, 2], t, *fm.args(), p.focal, p.offset)
        return g, gt, p.to_columns(yd / p.pitch + p.principal_column)
    fast = evaluator == "fast"
    if _use_numba(backend):
        g, gt, col = np.empty(n), np.empty(n), np.empty(n)
        _residual_nb(ground, t, *p.model_args(fast), p.pitch, p.principal_column, g, gt, col)
        return g, gt, p.to_columns(col)
    g, gt, yd, _, _ = _collinearity_point_py(ground[:, 0], ground[:, 1], ground[:, 2], t, *p.model_args(fast))
    return g, gt, p.to_columns(yd / p.pitch + p.principal_column)


# --------------------------------------------------------------------------- column at given rows
COLUMN_WINDOW_MARGIN = 64.0  # rows beyond the image where the column kernel uses the fixed evaluator


@njit(parallel=True, fastmath=False, cache=True)
def _column_fixed_nb(ground, rows, fx, focal, offset, pitch, pc, line_period, ref_row, r_lo, r_hi, col_out):
    # pragma: no cover - compiled
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    n_out = 0
    for i in prange(ground.shape[0]):
        r = rows[i]
        inside = (r >= r_lo) & (r <= r_hi)  # False for NaN
        rr = r if inside else r_lo
        _, _, yd, _, _ = _ce_fixed(
            ground[i, 0], ground[i, 1], ground[i, 2], (rr - ref_row) * line_period, P, V, A, AR, sc0f, jn, jp, jt,
            js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, focal, offset,
        )
        col_out[i] = yd / pitch + pc if inside else np.nan
        n_out += 0 if inside or not np.isfinite(r) else 1
    return n_out


def collinearity_params_or_none(scene: Scene) -> CollinearityParams | None:
    """:meth:`CollinearityParams.from_scene`, or None where the compiled kernels do not apply (numba
    missing or disabled, or a scene without MPC polynomials such as a rigorous line-scan model)."""
    if not NUMBA_AVAILABLE:
        return None
    try:
        return CollinearityParams.from_scene(scene)
    except AttributeError:
        return None


def columns_at_rows(params: CollinearityParams, ground: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Image columns of ground points at given (fractional) rows: one CE per finite row, compiled.

    The column of the learned methods, which predict the row only (``docs/conventions.md``).  Rows
    within the image +-``COLUMN_WINDOW_MARGIN`` use the branch-free evaluator (vectorised), others the
    reference evaluator; equal to :meth:`explorer.scene.Scene.column_at_row` to round-off.

    Parameters
    ----------
    params : CollinearityParams
    ground : ndarray, shape (N, 3)
        Local ENU metres.
    rows : ndarray, shape (N,)
        Rows (NaN gives NaN).

    Returns
    -------
    ndarray, shape (N,)
    """
    p = params
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    rows = np.ascontiguousarray(rows, dtype=np.float64)
    window = (-0.5 - COLUMN_WINDOW_MARGIN, p.n_rows - 0.5 + COLUMN_WINDOW_MARGIN)
    fm = p.fixed_model(window) if NUMBA_AVAILABLE else None
    t = (rows - p.reference_row) * p.line_period
    if fm is None:
        return residual_and_rate(p, ground, t)[2]
    col = np.empty(rows.shape[0])
    n_out = _column_fixed_nb(
        ground, rows, fm.args(), p.focal, p.offset, p.pitch, p.principal_column, p.line_period, p.reference_row,
        window[0], window[1], col,
    )
    col = p.to_columns(col)
    if n_out:  # rows far off the image: the reference evaluator
        far = np.flatnonzero(np.isfinite(rows) & ~((rows >= window[0]) & (rows <= window[1])))
        col[far] = residual_and_rate(p, ground[far], t[far])[2]
    return col


# --------------------------------------------------------------------------- seeds
SEED_TERMS = 20  # cubic seed polynomial; lower degrees are zero-padded


def _seed_row_py(X, Y, Z, mean, inv_scale, coef):
    """Polynomial seed row in normalised ``(X - mean) * inv_scale``: ``coef`` (20,) multiplies the
    monomials of :func:`seed_features` (degree 3; lower degrees zero-padded), nested Horner-style.

    Scalars (compiled) or arrays (the numpy fallback), same operations.
    """
    u = (X - mean[0]) * inv_scale[0]
    v = (Y - mean[1]) * inv_scale[1]
    w = (Z - mean[2]) * inv_scale[2]
    c = coef
    ru = (
        c[1]
        + u * (c[4] + u * c[10] + v * c[11] + w * c[12])
        + v * (c[5] + v * c[13] + w * c[14])
        + w * (c[6] + w * c[15])
    )
    rv = c[2] + v * (c[7] + v * c[16] + w * c[17]) + w * (c[8] + w * c[18])
    rw = c[3] + w * (c[9] + w * c[19])
    return c[0] + (u * ru + (v * rv + w * rw))


_seed_row = njit(cache=True, fastmath=False, inline="always")(_seed_row_py) if NUMBA_AVAILABLE else None


def _seed_full_py(X, Y, Z, mean, inv_scale, coef, cs, c_r0, c_inv, H, ccoef, c_mid, c_inv_half):
    """Seed row: the polynomial plus, when ``len(cs) > 1``, a correction ``H`` (K, 3) tabulated over
    the polynomial's rows at three columns (linear interpolation in the row, quadratic Lagrange in the
    column given by the column polynomial ``ccoef``; see :class:`SeedModel`).  Scalars or arrays."""
    r = _seed_row_py(X, Y, Z, mean, inv_scale, coef)
    if len(cs) > 1:
        x = (r - c_r0) * c_inv
        k = _table_index(x, H.shape[0] - 2)
        f = x - k
        u = (_seed_row_py(X, Y, Z, mean, inv_scale, ccoef) - c_mid) * c_inv_half
        h0 = H[k, 0] + f * (H[k + 1, 0] - H[k, 0])
        h1 = H[k, 1] + f * (H[k + 1, 1] - H[k, 1])
        h2 = H[k, 2] + f * (H[k + 1, 2] - H[k, 2])
        r = r + (h1 + u * (0.5 * (h2 - h0) + u * (0.5 * (h0 + h2) - h1)))
    return r


if NUMBA_AVAILABLE:

    @njit(cache=True, fastmath=False, inline="always")
    def _seed_full(X, Y, Z, mean, inv_scale, coef, cs, c_r0, c_inv, H, ccoef, c_mid, c_inv_half):
        # pragma: no cover - compiled (same operations as _seed_full_py)
        r = _seed_row(X, Y, Z, mean, inv_scale, coef)
        if len(cs) > 1:
            x = (r - c_r0) * c_inv
            k = _table_index(x, H.shape[0] - 2)
            f = x - k
            u = (_seed_row(X, Y, Z, mean, inv_scale, ccoef) - c_mid) * c_inv_half
            h0 = H[k, 0] + f * (H[k + 1, 0] - H[k, 0])
            h1 = H[k, 1] + f * (H[k + 1, 1] - H[k, 1])
            h2 = H[k, 2] + f * (H[k + 1, 2] - H[k, 2])
            r = r + (h1 + u * (0.5 * (h2 - h0) + u * (0.5 * (h0 + h2) - h1)))
        return r


@dataclass(frozen=True)
class SeedModel:
    """The seed of :func:`solve_exact`: a polynomial ``row(X, Y, Z)`` in normalised coordinates plus an
    optional correction tabulated over rows (for time-only disturbances such as attitude jitter,
    which no low-degree polynomial of the ground coordinates follows).

    Attributes
    ----------
    mean, scale : ndarray, shape (3,)
        Normalisation ``(P - mean) / scale``.
    coef : ndarray, shape (4|10|20,)
        Coefficients over :func:`seed_features`.
    correction : ndarray, shape (K, 3) or (K,), or None
        Row correction at polynomial rows ``correction_row0 + k * correction_step`` and at the
        columns ``column_mid - column_half``, ``column_mid``, ``column_mid + column_half`` (one
        column: the same correction everywhere), added to the polynomial: linear interpolation at
        the polynomial's row, quadratic Lagrange interpolation at the column polynomial's column.
    correction_row0, correction_step : float
    column_coef : ndarray, shape (4|10|20,) or None
        Polynomial ``col(X, Y, Z)`` over :func:`seed_features` (needed with a 3-column correction).
    column_mid, column_half : float
    """

    mean: np.ndarray
    scale: np.ndarray
    coef: np.ndarray
    correction: np.ndarray | None = None
    correction_row0: float = 0.0
    correction_step: float = 1.0
    column_coef: np.ndarray | None = None
    column_mid: float = 0.0
    column_half: float = 1.0

    def args(self) -> tuple:
        """``(mean, inv_scale, coef (20,), cs, c_r0, c_inv, H (K, 3), ccoef (20,), c_mid, c_inv_half)``."""

        def pad(c: np.ndarray | None) -> np.ndarray:
            c = np.zeros(0) if c is None else np.asarray(c, dtype=np.float64)
            return np.concatenate([c, np.zeros(SEED_TERMS - len(c))])

        if self.correction is None:
            cs, H = (0,), np.zeros((2, 3))
        else:
            H = np.asarray(self.correction, dtype=np.float64)
            H = np.ascontiguousarray(np.repeat(H[:, None], 3, axis=1) if H.ndim == 1 else H)
            if H.shape[1] != 3 or H.shape[0] < 2:
                raise ValueError(f"seed correction must have shape (K >= 2, 3) or (K,), got {H.shape}")
            if not np.allclose(H[:, 0], H[:, 1]) and self.column_coef is None:
                raise ValueError("a seed correction that varies with the column needs column_coef")
            cs = (0, 0)
        return (
            np.asarray(self.mean, dtype=np.float64),
            1.0 / np.asarray(self.scale, dtype=np.float64),
            pad(self.coef),
            cs,
            float(self.correction_row0),
            1.0 / float(self.correction_step),
            H,
            pad(self.column_coef),
            float(self.column_mid),
            1.0 / float(self.column_half),
        )

    def rows(self, ground: np.ndarray) -> np.ndarray:
        """Seed rows (N,) of ground points (N, 3) (numpy; the kernels compute the same)."""
        return _seed_full_py(ground[:, 0], ground[:, 1], ground[:, 2], *self.args())


def seed_features(uvw: np.ndarray, degree: int) -> np.ndarray:
    """Monomials of normalised coordinates (N, 3) in the order :func:`_seed_row_py` uses: (N, 4|10|20)."""
    if degree not in (1, 2, 3):
        raise ValueError(f"seed degree must be 1, 2 or 3, got {degree}")
    u, v, w = uvw[:, 0], uvw[:, 1], uvw[:, 2]
    cols = [np.ones_like(u), u, v, w]
    if degree >= 2:
        cols += [u * u, u * v, u * w, v * v, v * w, w * w]
    if degree >= 3:
        cols += [
            u * u * u,
            u * u * v,
            u * u * w,
            u * v * v,
            u * v * w,
            u * w * w,
            v * v * v,
            v * v * w,
            v * w * w,
            w * w * w,
        ]
    return np.stack(cols, axis=1)


# --------------------------------------------------------------------------- exact: vectorised Newton passes
_RUNNING, _ACCEPTED, _TO_GENERAL, _NO_ROOT = 0, 1, 2, 3


@njit(cache=True, fastmath=False, inline="always")
def _newton_update(
    i, rr, g, gt, yd, ydt, vz, line_period, pitch, pc, w_lo, w_hi, orient, accept_step, r, row_out, col_out, state
):  # pragma: no cover - compiled
    gr = gt * line_period
    delta = -g / gr
    rn = rr + delta
    good = (vz < 0.0) & (orient * gr > 0.0) & (abs(delta) < np.inf)
    outward = ((rr >= w_hi) & (delta > 0.0)) | ((rr <= w_lo) & (delta < 0.0))
    acc = good & (abs(delta) <= accept_step)
    row_out[i] = rn
    col_out[i] = (yd + ydt * line_period * delta) / pitch + pc
    r[i] = rn if good else rr
    state[i] = _ACCEPTED if acc else (_NO_ROOT if (good & outward) else (_RUNNING if good else _TO_GENERAL))


def _newton_update_np(rr, g, gt, yd, ydt, vz, line_period, pitch, pc, w_lo, w_hi, orient, accept_step):
    """Numpy twin of :func:`_newton_update` (same operations): (row, col, next r, state)."""
    gr = gt * line_period
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = -g / gr
    rn = rr + delta
    good = (vz < 0.0) & (orient * gr > 0.0) & (np.abs(delta) < np.inf)
    outward = ((rr >= w_hi) & (delta > 0.0)) | ((rr <= w_lo) & (delta < 0.0))
    acc = good & (np.abs(delta) <= accept_step)
    state = np.where(acc, _ACCEPTED, np.where(good & outward, _NO_ROOT, np.where(good, _RUNNING, _TO_GENERAL)))
    return rn, (yd + ydt * line_period * delta) / pitch + pc, np.where(good, rn, rr), state.astype(np.int8)


@njit(parallel=True, fastmath=False, cache=True)
def _newton_first_nb(
    ground,
    sx,
    fx,
    focal,
    offset,
    pitch,
    pc,
    line_period,
    ref_row,
    w_lo,
    w_hi,
    orient,
    accept_step,
    steps,
    r,
    row_out,
    col_out,
    state,
    ce,
    trace,
):  # pragma: no cover - compiled
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    mean, inv_scale, coef, cs, c_r0, c_inv, H, ccoef, c_mid, c_inv_half = sx
    n_trace = trace.shape[0]
    for i in prange(ground.shape[0]):
        X = ground[i, 0]
        Y = ground[i, 1]
        Z = ground[i, 2]
        rr = min(max(_seed_full(X, Y, Z, mean, inv_scale, coef, cs, c_r0, c_inv, H, ccoef, c_mid, c_inv_half), w_lo),
                 w_hi)
        for s in range(len(steps)):  # 1 or 2 unconditional Newton evaluations (unrolled)
            if s > 0:
                rr = min(max(r[i], w_lo), w_hi)
            if n_trace > s:
                trace[s, i] = rr
            t = (rr - ref_row) * line_period
            g, gt, yd, ydt, vz = _ce_fixed(
                X, Y, Z, t, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, focal, offset
            )
            _newton_update(
                i,
                rr,
                g,
                gt,
                yd,
                ydt,
                vz,
                line_period,
                pitch,
                pc,
                w_lo,
                w_hi,
                orient,
                accept_step,
                r,
                row_out,
                col_out,
                state,
            )
        ce[i] = len(steps)


@njit(parallel=True, fastmath=False, cache=True)
def _newton_next_nb(
    ground,
    idx,
    fx,
    focal,
    offset,
    pitch,
    pc,
    line_period,
    ref_row,
    w_lo,
    w_hi,
    orient,
    accept_step,
    k,
    r,
    row_out,
    col_out,
    state,
    ce,
    trace,
):  # pragma: no cover - compiled
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    n_trace = trace.shape[0]
    for j in prange(idx.shape[0]):
        i = idx[j]
        rr = min(max(r[i], w_lo), w_hi)
        if n_trace > k:
            trace[k, i] = rr
        t = (rr - ref_row) * line_period
        X = ground[i, 0]
        Y = ground[i, 1]
        Z = ground[i, 2]
        g, gt, yd, ydt, vz = _ce_fixed(
            X, Y, Z, t, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, focal, offset
        )
        _newton_update(
            i,
            rr,
            g,
            gt,
            yd,
            ydt,
            vz,
            line_period,
            pitch,
            pc,
            w_lo,
            w_hi,
            orient,
            accept_step,
            r,
            row_out,
            col_out,
            state,
        )
        ce[i] = k + 1


# --------------------------------------------------------------------------- exact: safeguarded iteration
@njit(parallel=True, fastmath=False, cache=True)
def _solve_exact_nb(
    ground,
    start,
    gx,
    fx,
    use_fixed,
    focal,
    offset,
    pitch,
    pc,
    line_period,
    ref_row,
    w_lo,
    w_hi,
    orient,
    tol,
    accept_step,
    max_iter,
    row_out,
    col_out,
    status_out,
    ce_out,
    trace,
):  # pragma: no cover - compiled
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    pos, dpos, att, datt, jit, _, _, curv, dist, sc0, fast = gx
    n = ground.shape[0]
    n_trace = trace.shape[0]
    for i in prange(n):
        X = ground[i, 0]
        Y = ground[i, 1]
        Z = ground[i, 2]
        r = start[i]
        if not (r >= w_lo):  # also catches NaN
            r = w_lo if r < w_lo else 0.5 * (w_lo + w_hi)
        if r > w_hi:
            r = w_hi
        lo = w_lo
        hi = w_hi
        lo_eval = False
        hi_eval = False
        prev_abs = np.inf
        last_newton = False
        status = STATUS_MAX_ITER
        row = np.nan
        col = np.nan
        ce = 0
        for it in range(max_iter):
            if it < n_trace:
                trace[it, i] = r
            t = (r - ref_row) * line_period
            if use_fixed:
                g, gt, yd, ydt, vz = _ce_fixed(
                    X, Y, Z, t, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, focal, offset
                )
            else:
                g, gt, yd, ydt, vz = collinearity_point(
                    X, Y, Z, t, pos, dpos, att, datt, jit, focal, offset, curv, dist, sc0, fast
                )
            ce += 1
            if not (vz < 0.0) or not np.isfinite(g) or not np.isfinite(gt):
                status = STATUS_INVALID
                break
            gr = gt * line_period
            ydr = ydt * line_period
            sg = orient * g
            if sg == 0.0:
                row = r
                col = yd / pitch + pc
                status = STATUS_CONVERGED
                break
            if sg > 0.0:  # the root lies below r
                hi = r
                hi_eval = True
                if r <= w_lo:
                    status = STATUS_NO_ROOT_IN_WINDOW
                    break
            else:
                lo = r
                lo_eval = True
                if r >= w_hi:
                    status = STATUS_NO_ROOT_IN_WINDOW
                    break
            newton_ok = orient * gr > 0.0
            rn = r
            if newton_ok:
                delta = -g / gr
                if abs(delta) <= accept_step:
                    row = r + delta
                    col = (yd + ydr * delta) / pitch + pc
                    status = STATUS_CONVERGED
                    break
                rn = r + delta
                if last_newton and abs(g) > 0.5 * prev_abs:
                    newton_ok = False
            if newton_ok and lo < rn < hi:
                last_newton = True
            else:
                last_newton = False
                if newton_ok and rn <= lo and not lo_eval:
                    rn = w_lo
                elif newton_ok and rn >= hi and not hi_eval:
                    rn = w_hi
                else:
                    rn = 0.5 * (lo + hi)
                    if lo_eval and hi_eval and hi - lo <= tol + 1e-15 * abs(hi):
                        row = rn
                        col = (yd + ydr * (rn - r)) / pitch + pc
                        status = STATUS_CONVERGED
                        break
            prev_abs = abs(g)
            r = rn
        if status != STATUS_CONVERGED:
            row = np.nan
            col = np.nan
        row_out[i] = row
        col_out[i] = col
        status_out[i] = status
        ce_out[i] = ce


def _evaluate_np(ground, t, p: CollinearityParams, fm: FixedModel | None, fast: bool):
    """One CE on arrays with the evaluator the solvers use (fixed model if given, else general)."""
    if fm is not None:
        return _ce_fixed_py(ground[:, 0], ground[:, 1], ground[:, 2], t, *fm.args(), p.focal, p.offset)
    return _collinearity_point_py(ground[:, 0], ground[:, 1], ground[:, 2], t, *p.model_args(fast))


def _solve_exact_np(
    ground,
    start,
    p: CollinearityParams,
    fm: FixedModel | None,
    fast: bool,
    w_lo,
    w_hi,
    orient,
    tol,
    accept_step,
    max_iter,
    trace_rows,
):
    """Vectorised numpy twin of :func:`_solve_exact_nb` (same algorithm, same decisions)."""
    n = ground.shape[0]
    r = np.asarray(start, dtype=np.float64).copy()
    r = np.where(np.isnan(r), 0.5 * (w_lo + w_hi), np.clip(r, w_lo, w_hi))
    lo = np.full(n, w_lo)
    hi = np.full(n, w_hi)
    lo_eval = np.zeros(n, bool)
    hi_eval = np.zeros(n, bool)
    prev_abs = np.full(n, np.inf)
    last_newton = np.zeros(n, bool)
    status = np.full(n, STATUS_MAX_ITER, np.int8)
    row = np.full(n, np.nan)
    col = np.full(n, np.nan)
    ce = np.zeros(n, np.int64)
    active = np.arange(n)
    dt = p.line_period
    pc = p.principal_column
    for it in range(max_iter):
        if active.size == 0:
            break
        ra = r[active]
        if it < trace_rows.shape[0]:
            trace_rows[it, active] = ra
        t = (ra - p.reference_row) * dt
        with np.errstate(divide="ignore", invalid="ignore"):
            g, gt, yd, ydt, vz = _evaluate_np(ground[active], t, p, fm, fast)
        ce[active] += 1
        gr = gt * dt
        ydr = ydt * dt
        m = active.size
        done = np.zeros(m, bool)
        new_status = np.full(m, STATUS_MAX_ITER, np.int8)
        new_row = np.full(m, np.nan)
        new_col = np.full(m, np.nan)

        def finish(mask, st, rr=None, cc=None, done=done, new_status=new_status, new_row=new_row, new_col=new_col):
            mask = mask & ~done
            new_status[mask] = st
            if rr is not None:
                new_row[mask] = rr[mask]
                new_col[mask] = cc[mask]
            done[mask] = True

        finish(~(vz < 0.0) | ~np.isfinite(g) | ~np.isfinite(gt), STATUS_INVALID)
        sg = orient * g
        finish(sg == 0.0, STATUS_CONVERGED, ra, yd / p.pitch + pc)
        above = (sg > 0.0) & ~done
        below = (sg < 0.0) & ~done
        hi_a = np.where(above, ra, hi[active])
        lo_a = np.where(below, ra, lo[active])
        hie = hi_eval[active] | above
        loe = lo_eval[active] | below
        finish(above & (ra <= w_lo), STATUS_NO_ROOT_IN_WINDOW)
        finish(below & (ra >= w_hi), STATUS_NO_ROOT_IN_WINDOW)
        newton_ok = (orient * gr > 0.0) & ~done
        with np.errstate(divide="ignore", invalid="ignore"):
            delta = np.where(newton_ok, -g / gr, 0.0)
        finish(
            newton_ok & (np.abs(delta) <= accept_step), STATUS_CONVERGED, ra + delta, (yd + ydr * delta) / p.pitch + pc
        )
        rn = np.where(newton_ok, ra + delta, ra)
        newton_ok &= ~done & ~(last_newton[active] & (np.abs(g) > 0.5 * prev_abs[active]))
        take = newton_ok & (lo_a < rn) & (rn < hi_a)
        probe_lo = ~take & newton_ok & (rn <= lo_a) & ~loe
        probe_hi = ~take & newton_ok & (rn >= hi_a) & ~hie & ~probe_lo
        bis = ~take & ~probe_lo & ~probe_hi
        mid = 0.5 * (lo_a + hi_a)
        rn = np.where(probe_lo, w_lo, np.where(probe_hi, w_hi, np.where(bis, mid, rn)))
        tiny = bis & loe & hie & (hi_a - lo_a <= tol + 1e-15 * np.abs(hi_a))
        finish(tiny, STATUS_CONVERGED, mid, (yd + ydr * (mid - ra)) / p.pitch + pc)
        lo[active] = lo_a
        hi[active] = hi_a
        lo_eval[active] = loe
        hi_eval[active] = hie
        last_newton[active] = take
        prev_abs[active] = np.abs(g)
        r[active] = rn
        fin = active[done]
        status[fin] = new_status[done]
        row[fin] = new_row[done]
        col[fin] = new_col[done]
        active = active[~done]
    return row, col, status, ce


def _dummy_fixed() -> FixedModel:
    """A placeholder of the right types for kernels told not to use the fixed evaluator."""
    z = np.zeros(1)
    return FixedModel(
        np.zeros((3, 4)),
        np.zeros((3, 3)),
        np.zeros((3, 4)),
        np.zeros((3, 3)),
        np.zeros((3, 2)),
        (0,),
        np.zeros((0, 5)),
        z,
        np.zeros((0, 1)),
        np.zeros((0, 1)),
        0.0,
        1.0,
        (0,),
        z,
        (0,),
        z,
    )


def solve_exact(
    params: CollinearityParams,
    ground: np.ndarray,
    seed: SeedModel,
    *,
    window: tuple[float, float],
    orient: float,
    tol: float,
    accept_step: float,
    max_iter: int,
    max_fast_passes: int = 8,
    first_evaluations: int = 1,
    trace: bool = False,
    backend: str = "auto",
    fast: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[np.ndarray] | None]:
    """Seeded Newton on the along-track residual with a safeguarded fallback, per point.

    Where the scene fits the branch-free evaluator (:meth:`CollinearityParams.fixed_model`) and
    ``fast`` is set, up to ``max_fast_passes`` plain Newton passes run first, each one compiled
    loop over the points still unresolved (vectorised by LLVM): pass 1 starts from the
    window-clipped seed; a point is accepted when its Newton step is at most ``accept_step`` rows
    (the step is applied), declared rootless when it sits on a window end and the step points
    outward (the residual is monotone), and handed to the safeguarded iteration when the
    evaluation is unusable (behind the camera, derivative of the wrong sign).  The safeguarded
    iteration (per-point bracket, bisection, window probes) finishes every point left, starting
    from its last iterate.

    Parameters
    ----------
    params : CollinearityParams
    ground : ndarray, shape (N, 3)
    seed : SeedModel
        Polynomial row seed (plus optional row correction table).
    window : (float, float)
        Search window in rows; roots outside it are reported as ``STATUS_NO_ROOT_IN_WINDOW``.
    orient : float
        +1 if the residual increases with the row, -1 otherwise (a property of the scene).
    tol : float
        Target row error (also the bisection bracket width that counts as converged).
    accept_step : float
        Newton steps below this many rows are accepted (with the step applied); chosen so that
        the quadratic error of the step is below ``tol``.
    max_iter : int
        Evaluations per point in the safeguarded iteration.
    max_fast_passes : int
        Plain Newton evaluations per point before the safeguarded iteration takes over.
    first_evaluations : {1, 2}
        Newton evaluations every point gets in the first compiled pass, unconditionally (2 when
        the seed is known to be too coarse for one: it saves a pass over the points).
    trace : bool
        Return the rows visited per evaluation (NaN once a point has finished).
    backend : {"auto", "numba", "numpy"}
    fast : bool
        Fast evaluators (default; equal to the reference to round-off) or the bitwise reference
        evaluator (safeguarded iteration only).

    Returns
    -------
    row, col : ndarray, shape (N,)
        NaN where not converged.
    status : ndarray of int8, shape (N,)
    ce : ndarray of int64, shape (N,)
        Collinearity evaluations per point (each gives residual, derivative and column).
    trace : list of ndarray (N,) or None
    """
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    sx = seed.args()
    n = ground.shape[0]
    w_lo, w_hi = float(window[0]), float(window[1])
    orient, tol, accept_step = float(orient), float(tol), float(accept_step)
    p = params
    use_nb = _use_numba(backend)
    fm = p.fixed_model(window) if fast else None
    dt, ref, pitch, pc = p.line_period, p.reference_row, p.pitch, p.principal_column
    n_trace = (max_fast_passes + max_iter) if trace else 0
    trace_rows = np.full((n_trace, n), np.nan)
    row = np.empty(n)  # every entry is written below
    col = np.empty(n)
    status = np.zeros(n, np.int8)  # STATUS_CONVERGED
    first = int(first_evaluations)
    if first not in (1, 2):
        raise ValueError(f"first_evaluations must be 1 or 2, got {first_evaluations}")
    if fm is not None and max_fast_passes >= first:
        r = np.empty(n)
        state = np.empty(n, np.int8)
        if use_nb:
            ce = np.empty(n, np.int64)
            _newton_first_nb(
                ground,
                sx,
                fm.args(),
                p.focal,
                p.offset,
                pitch,
                pc,
                dt,
                ref,
                w_lo,
                w_hi,
                orient,
                accept_step,
                (0,) * first,
                r,
                row,
                col,
                state,
                ce,
                trace_rows,
            )
        else:
            ce = np.full(n, first, np.int64)
            rr = np.minimum(np.maximum(seed.rows(ground), w_lo), w_hi)
            for step in range(first):
                if step > 0:
                    rr = np.minimum(np.maximum(r, w_lo), w_hi)
                if trace:
                    trace_rows[step] = rr
                with np.errstate(divide="ignore", invalid="ignore"):
                    g, gt, yd, ydt, vz = _ce_fixed_py(
                        ground[:, 0], ground[:, 1], ground[:, 2], (rr - ref) * dt, *fm.args(), p.focal, p.offset
                    )
                row, col, r, state = _newton_update_np(
                    rr, g, gt, yd, ydt, vz, dt, pitch, pc, w_lo, w_hi, orient, accept_step
                )
        pending = np.flatnonzero(state != _ACCEPTED)  # usually empty or small; one pass over int8
        idx = pending[state[pending] == _RUNNING]
        k = first
        while idx.size and k < max_fast_passes:
            if use_nb:
                _newton_next_nb(
                    ground,
                    idx,
                    fm.args(),
                    p.focal,
                    p.offset,
                    pitch,
                    pc,
                    dt,
                    ref,
                    w_lo,
                    w_hi,
                    orient,
                    accept_step,
                    k,
                    r,
                    row,
                    col,
                    state,
                    ce,
                    trace_rows,
                )
            else:
                rr = np.minimum(np.maximum(r[idx], w_lo), w_hi)
                if trace:
                    trace_rows[k, idx] = rr
                with np.errstate(divide="ignore", invalid="ignore"):
                    g, gt, yd, ydt, vz = _ce_fixed_py(
                        ground[idx, 0], ground[idx, 1], ground[idx, 2], (rr - ref) * dt, *fm.args(), p.focal, p.offset
                    )
                row[idx], col[idx], r[idx], state[idx] = _newton_update_np(
                    rr, g, gt, yd, ydt, vz, dt, pitch, pc, w_lo, w_hi, orient, accept_step
                )
                ce[idx] = k + 1
            k += 1
            idx = idx[state[idx] == _RUNNING]
        final = state[pending]
        no_root = pending[final == _NO_ROOT]
        status[no_root] = STATUS_NO_ROOT_IN_WINDOW
        row[no_root] = np.nan
        col[no_root] = np.nan
        rest = pending[(final == _RUNNING) | (final == _TO_GENERAL)]
        start = r[rest]
    else:
        ce = np.zeros(n, np.int64)
        rest = np.arange(n)
        start = seed.rows(ground)
    if rest.size:
        sub = ground[rest]
        offsets = ce[rest]
        sub_trace = np.full((max_iter if trace else 0, rest.size), np.nan)
        if use_nb:
            f = fm if fm is not None else _dummy_fixed()
            r2, c2 = np.empty(rest.size), np.empty(rest.size)
            s2 = np.empty(rest.size, np.int8)
            ce2 = np.empty(rest.size, np.int64)
            _solve_exact_nb(
                sub,
                np.ascontiguousarray(start),
                p.model_args(fast),
                f.args(),
                fm is not None,
                p.focal,
                p.offset,
                pitch,
                pc,
                dt,
                ref,
                w_lo,
                w_hi,
                orient,
                tol,
                accept_step,
                int(max_iter),
                r2,
                c2,
                s2,
                ce2,
                sub_trace,
            )
        else:
            r2, c2, s2, ce2 = _solve_exact_np(
                sub, start, p, fm, fast, w_lo, w_hi, orient, tol, accept_step, int(max_iter), sub_trace
            )
        row[rest] = r2
        col[rest] = c2
        status[rest] = s2
        ce[rest] += ce2
        if trace:
            for off in np.unique(offsets):
                sel = offsets == off
                trace_rows[off : off + max_iter, rest[sel]] = sub_trace[:, sel][: n_trace - off]
    out_trace = None
    if trace:
        used = int(ce.max()) if n else 0
        out_trace = [trace_rows[k].copy() for k in range(used)]
    return row, p.to_columns(col), status, ce, out_trace


# --------------------------------------------------------------------------- usgscsm secant solver
@njit(parallel=True, fastmath=False, cache=True)
def _solve_secant_nb(
    ground,
    proj,
    gx,
    fx,
    use_fixed,
    f_lo,
    f_hi,
    focal,
    offset,
    pitch,
    pc,
    line_period,
    ref_row,
    r_min,
    r_max,
    precision,
    first_step,
    max_count,
    row_out,
    col_out,
    ok_out,
    ce_out,
    trace,
):  # pragma: no cover - compiled
    P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv = fx  # unpacked outside prange
    pos, dpos, att, datt, jit, _, _, curv, dist, sc0, fast = gx
    n = ground.shape[0]
    n_trace = trace.shape[0]
    for i in prange(n):
        X = ground[i, 0]
        Y = ground[i, 1]
        Z = ground[i, 2]
        # projective approximation (usgscsm computeProjectiveApproximation), clamped to the image
        u = (X - proj[8]) / proj[11]
        v = (Y - proj[9]) / proj[12]
        w = (Z - proj[10]) / proj[13]
        den = 1.0 + proj[4] * u + proj[5] * v + proj[6] * w
        approx = (proj[0] + proj[1] * u + proj[2] * v + proj[3] * w) / den
        if den == 0.0 or not np.isfinite(approx):
            approx = 0.5 * (r_min + r_max)
        if approx < r_min:
            approx = r_min
        if approx > r_max:
            approx = r_max
        # usgscsm: e0 = e(0); e1 = e(0.1); while |e1| > precision and ++count < max_count:
        #   if e1 == e0 break; t2 = t1 - e1 (t1 - t0) / (e1 - e0); shift.  Then the column at t1.
        # Written with one evaluation site (phase 0, 1: the probes; 2: secant steps; 3: column).
        t0 = 0.0
        t1 = 0.0
        e0 = 0.0
        e1 = 0.0
        ts = 0.0
        phase = 0
        count = 0
        ce = 0
        valid = True
        col = np.nan
        while True:
            rowq = approx + ts
            t = (rowq - ref_row) * line_period
            if use_fixed and f_lo <= rowq <= f_hi:
                e, _, yd, _, vz = _ce_fixed(
                    X,
                    Y,
                    Z,
                    t,
                    P,
                    V,
                    A,
                    AR,
                    sc0f,
                    jn,
                    jp,
                    jt,
                    js,
                    jc,
                    jt0,
                    jinv_dt,
                    dn,
                    fdist,
                    cn,
                    fcurv,
                    focal,
                    offset,
                )
            else:
                e, _, yd, _, vz = collinearity_point(
                    X, Y, Z, t, pos, dpos, att, datt, jit, focal, offset, curv, dist, sc0, fast
                )
            ce += 1
            valid = valid and vz < 0.0
            if phase == 3:
                col = yd / pitch + pc
                break
            if ce - 1 < n_trace:
                trace[ce - 1, i] = rowq
            e = e / pitch
            if phase == 0:
                t0 = ts
                e0 = e
                ts = first_step
                phase = 1
                continue
            if phase == 1:
                t1 = ts
                e1 = e
                phase = 2
            else:
                t0 = t1
                e0 = e1
                t1 = ts
                e1 = e
            if abs(e1) > precision:
                count += 1
                if count < max_count and e1 != e0:
                    ts = t1 - e1 * (t1 - t0) / (e1 - e0)
                    continue
            ts = t1
            phase = 3
        row = approx + t1
        row_out[i] = row
        col_out[i] = col
        ok_out[i] = valid and (abs(e1) <= precision) and np.isfinite(row)
        ce_out[i] = ce


def _line_error_np(ground, row, p: CollinearityParams, fm: FixedModel | None, f_lo, f_hi, fast):
    """Numpy twin of :func:`_line_error` on arrays (same evaluator choice per point)."""
    t = (row - p.reference_row) * p.line_period
    out = [np.empty(row.shape) for _ in range(5)]
    in_fixed = (f_lo <= row) & (row <= f_hi) if fm is not None else np.zeros(row.shape, bool)
    for mask, fixed in ((in_fixed, True), (~in_fixed, False)):
        if not mask.any():
            continue
        if fixed:
            res = _ce_fixed_py(
                ground[mask, 0], ground[mask, 1], ground[mask, 2], t[mask], *fm.args(), p.focal, p.offset
            )
        else:
            res = _collinearity_point_py(
                ground[mask, 0], ground[mask, 1], ground[mask, 2], t[mask], *p.model_args(fast)
            )
        for o, v in zip(out, res, strict=True):
            o[mask] = v
    return out


def _solve_secant_np(
    ground,
    proj,
    p: CollinearityParams,
    fm,
    f_lo,
    f_hi,
    fast,
    r_min,
    r_max,
    precision,
    first_step,
    max_count,
    trace_rows,
):
    """Vectorised numpy twin of :func:`_solve_secant_nb` (same iteration, same decisions)."""
    n = ground.shape[0]
    u = (ground[:, 0] - proj[8]) / proj[11]
    v = (ground[:, 1] - proj[9]) / proj[12]
    w = (ground[:, 2] - proj[10]) / proj[13]
    den = 1.0 + proj[4] * u + proj[5] * v + proj[6] * w
    with np.errstate(divide="ignore", invalid="ignore"):
        approx = (proj[0] + proj[1] * u + proj[2] * v + proj[3] * w) / den
    approx = np.where((den == 0.0) | ~np.isfinite(approx), 0.5 * (r_min + r_max), approx)
    approx = np.clip(approx, r_min, r_max)

    def err(idx, t_off):
        with np.errstate(divide="ignore", invalid="ignore"):
            e, _, yd, _, vz = _line_error_np(ground[idx], approx[idx] + t_off, p, fm, f_lo, f_hi, fast)
        return e / p.pitch, yd, vz

    everything = np.arange(n)
    t0 = np.zeros(n)
    e0, _, vz0 = err(everything, t0)
    t1 = np.full(n, first_step)
    e1, _, vz1 = err(everything, t1)
    ce = np.full(n, 2, np.int64)
    valid = (vz0 < 0.0) & (vz1 < 0.0)
    if trace_rows.shape[0] > 0:
        trace_rows[0] = approx + t0
    if trace_rows.shape[0] > 1:
        trace_rows[1] = approx + t1
    count = np.zeros(n, np.int64)
    active = everything[np.abs(e1) > precision]
    while active.size:
        count[active] += 1
        keep = (count[active] < max_count) & (e1[active] != e0[active])
        active = active[keep]
        if active.size == 0:
            break
        a0, a1, f0, f1 = t0[active], t1[active], e0[active], e1[active]
        t2 = a1 - f1 * (a1 - a0) / (f1 - f0)
        e2, _, vz2 = err(active, t2)
        ce[active] += 1
        valid[active] &= vz2 < 0.0
        k = ce[active] - 1
        tr = k < trace_rows.shape[0]
        trace_rows[k[tr], active[tr]] = approx[active[tr]] + t2[tr]
        t0[active], e0[active] = a1, f1
        t1[active], e1[active] = t2, e2
        active = active[np.abs(e2) > precision]
    row = approx + t1
    _, yd, vz_f = err(everything, t1)
    ce += 1
    col = yd / p.pitch + p.principal_column
    ok = valid & (vz_f < 0.0) & (np.abs(e1) <= precision) & np.isfinite(row)
    return row, col, ok, ce


FIXED_MARGIN_ROWS = 64.0  # the secant's fixed evaluator covers the image +- this many rows


def solve_secant(
    params: CollinearityParams,
    ground: np.ndarray,
    proj: np.ndarray,
    *,
    precision: float,
    first_step: float = 0.1,
    max_count: int = 15,
    trace: bool = False,
    backend: str = "auto",
    fast: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[np.ndarray] | None]:
    """The usgscsm line-scan ``groundToImage`` secant iteration, per point.

    Parameters
    ----------
    params : CollinearityParams
    ground : ndarray, shape (N, 3)
    proj : ndarray, shape (14,)
        ``(a0..a3, b1..b3, unused, mean x, y, z, scale x, y, z)``: projective line seed
        ``(a0 + a.u) / (1 + b.u)`` in normalised ground coordinates ``u``.
    precision : float
        Stop when the detector-line residual ``|x_d - x_det| / pitch`` is at most this (pixels).
    first_step : float
        Second probe, rows after the seed (usgscsm: 0.1).
    max_count : int
        usgscsm's iteration limit (15).
    trace : bool
    backend : {"auto", "numba", "numpy"}
    fast : bool
        Fast evaluators (default; the fixed one inside the image +-64 rows where the scene fits,
        else the general fast one), equal to the reference to round-off; False: the reference.

    Returns
    -------
    row, col : ndarray (N,)
    ok : ndarray of bool (N,)
        Residual precision met (usgscsm would warn PRECISION_NOT_MET otherwise), in front of the camera.
    ce : ndarray of int64 (N,)
        Collinearity evaluations per point, the final column evaluation included.
    trace : list of ndarray (N,) or None
    """
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    proj = np.ascontiguousarray(proj, dtype=np.float64)
    p = params
    n = ground.shape[0]
    r_min, r_max = -0.5, p.n_rows - 0.5
    f_lo, f_hi = r_min - FIXED_MARGIN_ROWS, r_max + FIXED_MARGIN_ROWS
    fm = p.fixed_model((f_lo, f_hi)) if fast else None
    trace_rows = np.full((max_count + 2 if trace else 0, n), np.nan)
    if _use_numba(backend):
        f = fm if fm is not None else _dummy_fixed()
        row, col = np.empty(n), np.empty(n)
        ok = np.empty(n, np.bool_)
        ce = np.empty(n, np.int64)
        _solve_secant_nb(
            ground,
            proj,
            p.model_args(fast),
            f.args(),
            fm is not None,
            f_lo,
            f_hi,
            p.focal,
            p.offset,
            p.pitch,
            p.principal_column,
            p.line_period,
            p.reference_row,
            r_min,
            r_max,
            float(precision),
            float(first_step),
            int(max_count),
            row,
            col,
            ok,
            ce,
            trace_rows,
        )
    else:
        row, col, ok, ce = _solve_secant_np(
            ground,
            proj,
            p,
            fm,
            f_lo,
            f_hi,
            fast,
            r_min,
            r_max,
            float(precision),
            float(first_step),
            int(max_count),
            trace_rows,
        )
    out_trace = None
    if trace:
        used = int((ce - 1).max()) if n else 0
        out_trace = [trace_rows[k].copy() for k in range(used)]
    return row, params.to_columns(col), ok, ce, out_trace


def set_threads(n: int | None) -> int:
    """Set numba's thread count (``None``: leave it); returns the count in use (1 without numba)."""
    if not NUMBA_AVAILABLE:
        return 1
    if n is not None:
        numba.set_num_threads(int(n))
    return int(numba.get_num_threads())


__all__ = [
    "NUMBA_AVAILABLE",
    "CollinearityParams",
    "FixedModel",
    "SeedModel",
    "residual_and_rate",
    "solve_exact",
    "solve_secant",
    "seed_features",
    "set_threads",
    "STATUS_NAMES",
    "STATUS_CONVERGED",
    "STATUS_NO_ROOT_IN_WINDOW",
    "STATUS_INVALID",
    "STATUS_MAX_ITER",
]
