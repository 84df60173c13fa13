"""One collinearity evaluation (CE: along-track residual, its time derivative, the column) per point:
the reference / fast evaluator :func:`_collinearity_point_py` and the branch-free :func:`_ce_fixed_py`,
written for scalars (compiled by numba) and numpy arrays alike."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, njit, overload
from explorer.geometry.kernels.params import _C2, _C4, _C6, _C8, _C10, _S3, _S5, _S7, _S9, SMALL_ANGLE


def _inlined_when_compiled(fn: Callable[..., Any] | None = None, *, inline: str = "always") -> Any:
    """Make the plain Python function ``fn`` callable from compiled kernels, where numba inlines it.

    ``fn`` stays the Python function (numpy arrays, and torch tensors in :mod:`explorer.geometry.torch_solver`);
    compiled callers get the same code (numba's ``register_jitable``, under the callers' own
    ``fastmath=False``), so one function serves every evaluator.  ``inline="always"`` inlines it in numba's
    IR; ``"never"`` compiles it on its own and leaves the inlining to LLVM (where numba's IR inliner warns that
    it mis-scoped a loop's variables: a loop inlined twice over, or whose results the caller re-assigns).
    """
    if fn is None:
        return lambda f: _inlined_when_compiled(f, inline=inline)
    if NUMBA_AVAILABLE:
        overload(fn, jit_options={"fastmath": False}, inline=inline, strict=False)(lambda *args: fn)
    return fn


@_inlined_when_compiled
def _sincos_increment(s0, c0, d):
    """``sin(a0 + d), cos(a0 + d)`` from ``s0 = sin a0, c0 = cos a0`` and a small increment ``d`` (rad).

    The addition theorem with Taylor series of ``sin d`` and ``cos d - 1`` (exact to round-off for
    ``|d| <= SMALL_ANGLE``): no ``sin``/``cos`` call, so that compiled loops vectorise.
    """
    d2 = d * d
    sd = d + d * (d2 * (_S3 + d2 * (_S5 + d2 * (_S7 + d2 * _S9))))
    cm1 = d2 * (_C2 + d2 * (_C4 + d2 * (_C6 + d2 * (_C8 + d2 * _C10))))
    return s0 + (s0 * cm1 + c0 * sd), c0 + (c0 * cm1 - s0 * sd)


def _sincos_near(a0, s0, c0, d):
    """``sin(a0 + d), cos(a0 + d)`` from ``s0 = sin a0, c0 = cos a0`` and a small increment ``d``.

    :func:`_sincos_increment` for ``|d| <= SMALL_ANGLE``; larger increments fall back to ``sin``/``cos``
    of ``a0 + d``.  Numpy version (arrays); numba compiles the scalar overload below, which takes the
    same decisions and performs the same operations.
    """
    s, c = _sincos_increment(s0, c0, d)
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
            return _sincos_increment(s0, c0, d)

        return impl

    @overload(_table_index, jit_options={"fastmath": False})
    def _table_index_scalar(x, last):  # pragma: no cover - compiled
        def impl(x, last):
            return min(max(int(np.floor(x)), 0), last)

        return impl


@_inlined_when_compiled
def _focal_plane_and_rate(dx, dy, dz, vx_s, vy_s, vz_s, so, co, sp, cp, sk, ck, om_t, ph_t, ka_t, focal, one_division):
    """Ideal focal-plane coordinates of a point and their time derivatives, from the attitude's sines and cosines.

    Parameters
    ----------
    dx, dy, dz : float or ndarray (N,)
        ``P - S``: ground point minus perspective centre, local ENU metres.
    vx_s, vy_s, vz_s : float or ndarray (N,)
        ``dS/dt``, the perspective centre's velocity, m/s.
    so, co, sp, cp, sk, ck : float or ndarray (N,)
        Sines and cosines of omega, phi, kappa (``R = Rx(omega) Ry(phi) Rz(kappa)``, as
        :func:`explorer.geometry.rotations.rotation_from_opk`).
    om_t, ph_t, ka_t : float or ndarray (N,)
        Angle rates, rad/s.
    focal : float
        Principal distance, metres.
    one_division : bool
        True: one division (``1 / v_z``, then products: the fast evaluators); False: the divisions of
        ``ideal_focal_plane`` (the bitwise reference).

    Returns
    -------
    x, y : ideal focal-plane coordinates, metres
    x_t, y_t : their time derivatives, m/s
    vz : sensor-frame z of the point, metres (negative in front of the camera)
    """
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
    vx = r00 * dx + r10 * dy + r20 * dz
    vy = r01 * dx + r11 * dy + r21 * dz
    vz = r02 * dx + r12 * dy + r22 * dz
    # dv/dt = Rdot^T (P - S) - R^T dS/dt
    vx_t = (q00 * dx + q10 * dy + q20 * dz) - (r00 * vx_s + r10 * vy_s + r20 * vz_s)
    vy_t = (q01 * dx + q11 * dy + q21 * dz) - (r01 * vx_s + r11 * vy_s + r21 * vz_s)
    vz_t = (q02 * dx + q12 * dy + q22 * dz) - (r02 * vx_s + r12 * vy_s + r22 * vz_s)
    if one_division:
        inv_vz = 1.0 / vz
        scale = -focal * inv_vz
        ratio = vz_t * inv_vz
    else:  # as ideal_focal_plane
        scale = -focal / vz
        ratio = vz_t / vz
    x = vx * scale
    y = vy * scale
    return x, y, scale * (vx_t - vx * ratio), scale * (vy_t - vy * ratio), vz


@_inlined_when_compiled
def _power_series(start, u, coef, n_terms):
    """``start + c1 u + c2 u^2 + ...`` and its derivative ``c1 + 2 c2 u + ...`` (the first ``n_terms`` of ``coef``).

    The terms are added to ``start`` one by one, in order: the radial distortion factor (``u = r^2``,
    :meth:`explorer.geometry.interior.InteriorOrientation.distort`) and the curved detector line (``u = y``,
    :meth:`~explorer.geometry.interior.InteriorOrientation.detector_x`).  Scalars or arrays.
    """
    value = start
    slope = 0.0 * u
    power = 1.0 + 0.0 * u
    for m in range(n_terms):
        slope = slope + (m + 1) * coef[m] * power
        power = power * u
        value = value + coef[m] * power
    return value, slope


@_inlined_when_compiled(inline="never")
def _radial_distortion(x, y, x_t, y_t, dist, n_terms):
    """Radial distortion ``r_d = r (1 + k1 r^2 + ...)`` of focal-plane coordinates and their rates
    (:meth:`explorer.geometry.interior.InteriorOrientation.distort`).

    ``dist`` holds ``k1, k2, ...`` (its first ``n_terms`` are used; none: the coordinates unchanged).
    Returns ``xd, yd, xd_t, yd_t`` (metres, m/s).
    """
    xd, yd, xd_t, yd_t = x, y, x_t, y_t
    if n_terms > 0:
        r2 = x * x + y * y
        factor, dfactor = _power_series(1.0 + 0.0 * r2, r2, dist, n_terms)
        r2_t = 2.0 * (x * x_t + y * y_t)
        xd, yd = x * factor, y * factor
        xd_t, yd_t = x_t * factor + x * dfactor * r2_t, y_t * factor + y * dfactor * r2_t
    return xd, yd, xd_t, yd_t


@_inlined_when_compiled(inline="never")
def _horner3(coef, t, lowest):
    """``sum_{j >= lowest} coef[:, j] t^(j - lowest)`` for the three rows of ``coef`` (3, D), by Horner from
    the highest term (ascending coefficients, as ``polyval_ascending``); ``t`` scalar or array."""
    d = coef.shape[1]
    a = coef[0, d - 1] + 0.0 * t
    b = coef[1, d - 1] + 0.0 * t
    c = coef[2, d - 1] + 0.0 * t
    for j in range(d - 2, lowest - 1, -1):
        a = a * t + coef[0, j]
        b = b * t + coef[1, j]
        c = c * t + coef[2, j]
    return a, b, c


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
    sx, sy, sz = _horner3(pos, t, 0)
    vx_s, vy_s, vz_s = _horner3(dpos, t, 0)
    # angles (fast: their increments from the constant terms) and rates
    lowest = 1 if fast else 0
    om, ph, ka = _horner3(att, t, lowest)
    if att.shape[1] - 1 < lowest:  # fast with constant angles: zero increments
        om, ph, ka = 0.0 * t, 0.0 * t, 0.0 * t
    elif fast:
        om, ph, ka = om * t, ph * t, ka * t
    om_t, ph_t, ka_t = _horner3(datt, t, 0)
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
    x, y, x_t, y_t, vz = _focal_plane_and_rate(
        X - sx, Y - sy, Z - sz, vx_s, vy_s, vz_s, so, co, sp, cp, sk, ck, om_t, ph_t, ka_t, focal, fast
    )
    xd, yd, xd_t, yd_t = _radial_distortion(x, y, x_t, y_t, dist, dist.shape[0])
    # detector line (InteriorOrientation.detector_x) and its slope
    xdet, slope = _power_series(offset + 0.0 * yd, yd, curv, curv.shape[0])
    g = xd - xdet
    g_t = xd_t - slope * yd_t
    return g, g_t, yd, yd_t, vz


collinearity_point: Any = njit(cache=True, fastmath=False)(_collinearity_point_py) if NUMBA_AVAILABLE else None


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
            s_j, c_j = _sincos_increment(js[j, k], jc[j, k], w * tau)
            a_s = amp * s_j
            a_c = amp * w * c_j
            d_om = d_om + jp[j, 2] * a_s
            d_ph = d_ph + jp[j, 3] * a_s
            d_ka = d_ka + jp[j, 4] * a_s
            om_t = om_t + jp[j, 2] * a_c
            ph_t = ph_t + jp[j, 3] * a_c
            ka_t = ka_t + jp[j, 4] * a_c
    so, co = _sincos_increment(sc0[0, 0], sc0[0, 1], d_om)
    sp, cp = _sincos_increment(sc0[1, 0], sc0[1, 1], d_ph)
    sk, ck = _sincos_increment(sc0[2, 0], sc0[2, 1], d_ka)
    x, y, x_t, y_t, vz = _focal_plane_and_rate(
        X - sx, Y - sy, Z - sz, vx_s, vy_s, vz_s, so, co, sp, cp, sk, ck, om_t, ph_t, ka_t, focal, True
    )
    xd, yd, xd_t, yd_t = _radial_distortion(x, y, x_t, y_t, dist, len(dn) - 1)
    g = xd - offset
    g_t = xd_t
    if len(cn) > 1:  # curved detector line
        xline, slope = _power_series(0.0 * yd, yd, curv, len(cn) - 1)
        g = g - xline
        g_t = g_t - slope * yd_t
    return g, g_t, yd, yd_t, vz


_ce_fixed: Any = njit(cache=True, fastmath=False, inline="always")(_ce_fixed_py) if NUMBA_AVAILABLE else None


@_inlined_when_compiled
def _ce_either(
    X, Y, Z, t, use_fixed, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, gx
):  # pragma: no cover - compiled
    """One CE in a compiled kernel: :func:`_ce_fixed` where ``use_fixed``, else :func:`collinearity_point`.

    ``P ... fcurv`` are :meth:`FixedModel.args` (a placeholder of its types where the fixed evaluator is not
    used; unpacked by the kernel before its parallel loop, which takes no tuple nested in a tuple), ``gx``
    :meth:`CollinearityParams.model_args` (its ``focal, offset`` serve both evaluators).  Same returns.
    """
    if use_fixed:
        return _ce_fixed(
            X, Y, Z, t, P, V, A, AR, sc0f, jn, jp, jt, js, jc, jt0, jinv_dt, dn, fdist, cn, fcurv, gx[5], gx[6]
        )
    return collinearity_point(X, Y, Z, t, *gx)
