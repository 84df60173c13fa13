"""One collinearity evaluation (CE: along-track residual, its time derivative, the column) per point:
the reference / fast evaluator :func:`_collinearity_point_py` and the branch-free :func:`_ce_fixed_py`,
written for scalars (compiled by numba) and numpy arrays alike."""

from __future__ import annotations

from typing import Any

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, njit, overload
from explorer.geometry.kernels.params import _C2, _C4, _C6, _C8, _C10, _S3, _S5, _S7, _S9, SMALL_ANGLE


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


_ce_fixed: Any = njit(cache=True, fastmath=False, inline="always")(_ce_fixed_py) if NUMBA_AVAILABLE else None
