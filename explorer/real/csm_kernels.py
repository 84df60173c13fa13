"""Compiled kernels of the USGS CSM line-scan camera (:mod:`explorer.real.csm`).

Scalar functions compiled with numba (``explorer._numba``) and the ``prange`` loops over points
that call them.  Every formula follows the conventions of usgscsm's ``UsgsAstroLsSensorModel``
(USGS Astrogeology, the Community Sensor Model plug-in for planetary pushbroom cameras), restated
here from its documented behaviour; ``docs/conventions.md#usgs-csm-line-scan-isds`` has the
mapping to this project's pixels.

* line -> time: ``t = t_k + dt_k (line - line_k + 0.5)`` with ``k`` the last table entry whose
  ``line_k <= line`` (the ISD's ``line_scan_rate``, times relative to ``center_ephemeris_time``);
* positions: Lagrange interpolation over a window centred on the time's table interval, of the
  stated order, reduced near the table ends as usgscsm's ``lagrangeInterp`` does (8 / 6 / 4 / 2
  samples), on the table's own (not necessarily uniform) times;
* rotations: quaternions ``(w, x, y, z)`` per table, interpolated by slerp between neighbours
  (mode 0) or by the same Lagrange window on the components, renormalised (mode 1);
* optical distortion: :func:`remove_distortion` (distorted -> undistorted focal plane) and
  :func:`apply_distortion` (its inverse), closed form in the direction each model states it and
  solved by Newton's method (finite-difference Jacobian, to 1e-14 mm) in the other.
"""

from __future__ import annotations

import numpy as np

from explorer._numba import njit, prange
from explorer.geometry.kernels.params import store_point

# distortion model codes
DIST_NONE = 0
DIST_RADIAL = 1
DIST_TRANSVERSE = 2
DIST_KAGUYALISM = 3
DIST_DAWNFC = 4
DIST_LROLROCNAC = 5
DIST_CAHVOR = 6
DIST_LUNARORBITER = 7
DIST_RADTAN = 8
DIST_KPLOSHADOWCAM = 9
DIST_LEGENDRE = 10
DIST_THEMISIR = 11

STATUS_OK = 0
STATUS_BEHIND = 1  # the ground point is behind the camera (or a non-finite evaluation)
STATUS_NO_ROOT = 2  # the detector-line residual keeps its sign over the search window
STATUS_MAX_ITER = 3
STATUS_MISS = 4  # image -> ground: the ray misses the (inflated) ellipsoid

NEWTON_TOL_MM = 1e-14
DIST_MAX_ITER = 60


# --------------------------------------------------------------------------- tables
@njit(cache=True)
def interval_index(times, t):
    """Index ``i`` of the table interval ``[times[i], times[i+1])`` holding ``t`` (clamped).

    A guess from the mean spacing, corrected by walking (a step or two on nearly even tables such as
    usgscsm's resampled ones; a binary search beyond that)."""
    n = times.shape[0]
    if n < 2:
        return 0
    t0 = times[0]
    span = times[n - 1] - t0
    g = (t - t0) / span * (n - 1)
    if not (g >= 0.0):  # also NaN
        return 0
    if g >= n - 2:
        i = n - 2
    else:
        i = int(g)
    for _ in range(3):
        if t < times[i] and i > 0:
            i -= 1
        elif i < n - 2 and t >= times[i + 1]:
            i += 1
        else:
            return i
    if t < times[i] and i > 0 or i < n - 2 and t >= times[i + 1]:
        i = np.searchsorted(times, t, side="right") - 1
        if i < 0:
            i = 0
        if i > n - 2:
            i = n - 2
    return i


@njit(cache=True)
def lagrange_window(n, index, max_order):
    """usgscsm's window: (first sample, number of samples) around table interval ``index``."""
    if index >= 3 and index < n - 4:
        order = 8
    elif index >= 2 and index < n - 3:
        order = 6
    elif index >= 1 and index < n - 2:
        order = 4
    else:
        order = 2
    if order > max_order:
        order = max_order
    if order > n:
        order = n
    first = index - order // 2 + 1
    if first < 0:
        first = 0
    if first + order > n:
        first = n - order
    return first, order


@njit(cache=True)
def lagrange_eval(times, values, t, max_order, out):
    """Lagrange interpolation of ``values`` (n, k) at ``t`` into ``out`` (k,)."""
    n = times.shape[0]
    k = values.shape[1]
    for j in range(k):
        out[j] = 0.0
    if n == 1:
        for j in range(k):
            out[j] = values[0, j]
        return
    first, order = lagrange_window(n, interval_index(times, t), max_order)
    for a in range(first, first + order):
        w = 1.0
        for b in range(first, first + order):
            if b != a:
                w *= (t - times[b]) / (times[a] - times[b])
        for j in range(k):
            out[j] += w * values[a, j]


@njit(cache=True)
def window_tables(times, max_order):
    """Per table interval: usgscsm's Lagrange window ``(first, order)`` and the inverse denominators
    ``1 / prod_{b != a} (t_a - t_b)`` of its weights (so that evaluations need no division)."""
    n = times.shape[0]
    m = max(n - 1, 1)
    win = np.zeros((m, 2), np.int64)
    den = np.zeros((m, 8))
    if n < 2:
        win[0, 1] = 1
        den[0, 0] = 1.0
        return win, den
    for i in range(n - 1):
        first, order = lagrange_window(n, i, max_order)
        win[i, 0], win[i, 1] = first, order
        for a in range(order):
            d = 1.0
            for b in range(order):
                if b != a:
                    d *= times[first + a] - times[first + b]
            den[i, a] = 1.0 / d
    return win, den


@njit(cache=True, inline="always")
def _running_products(a, b, c, d, e, f, g):
    """``a, ab, abc, ..., abcdefg``, multiplied left to right."""
    ab = a * b
    abc = ab * c
    abcd = abc * d
    abcde = abcd * e
    abcdef = abcde * f
    return a, ab, abc, abcd, abcde, abcdef, abcdef * g


@njit(cache=True)
def _weights8(times, first, den, i, t):
    """The 8 Lagrange weights of window ``first`` (``den[i]`` their inverse denominators) at ``t``:
    prefix / suffix products of ``t - t_b``, branch-free (the usgscsm window of order 8)."""
    d0, d1, d2, d3 = t - times[first], t - times[first + 1], t - times[first + 2], t - times[first + 3]
    d4, d5, d6, d7 = t - times[first + 4], t - times[first + 5], t - times[first + 6], t - times[first + 7]
    p1, p2, p3, p4, p5, p6, p7 = _running_products(d0, d1, d2, d3, d4, d5, d6)  # prefixes d0 ... d_{a-1}
    s6, s5, s4, s3, s2, s1, s0 = _running_products(d7, d6, d5, d4, d3, d2, d1)  # suffixes d_{a+1} ... d7
    return (den[i, 0] * s0, den[i, 1] * p1 * s1, den[i, 2] * p2 * s2, den[i, 3] * p3 * s3, den[i, 4] * p4 * s4,
            den[i, 5] * p5 * s5, den[i, 6] * p6 * s6, den[i, 7] * p7)


@njit(cache=True, inline="always")
def _lagrange_rows(times, values, win, den, t):
    """Lagrange interpolation of the rows of ``values`` (n, 3) or (n, 4) at ``t`` with precomputed windows
    (allocation-free): the four column sums, the fourth 0.0 for three columns."""
    four = values.shape[1] > 3
    if times.shape[0] == 1:
        return values[0, 0], values[0, 1], values[0, 2], values[0, 3] if four else 0.0
    i = interval_index(times, t)
    first, order = win[i, 0], win[i, 1]
    o0 = o1 = o2 = o3 = 0.0
    if order == 8:
        ww = _weights8(times, first, den, i, t)
    for a in range(order):
        if order == 8:
            w = ww[a]
        else:
            w = den[i, a]
            for b in range(order):
                if b != a:
                    w *= t - times[first + b]
        o0 += w * values[first + a, 0]
        o1 += w * values[first + a, 1]
        o2 += w * values[first + a, 2]
        if four:
            o3 += w * values[first + a, 3]
    return o0, o1, o2, o3


@njit(cache=True)
def _lagrange3(times, values, win, den, t):
    """Lagrange interpolation of ``values`` (n, 3) at ``t`` with precomputed windows (allocation-free)."""
    o0, o1, o2, _ = _lagrange_rows(times, values, win, den, t)
    return o0, o1, o2


@njit(cache=True)
def _quat(times, quats, win, den, t, mode):
    """Interpolated unit quaternion ``(w, x, y, z)`` at ``t`` (allocation-free, see :func:`quaternion_at`)."""
    if mode == 1 or times.shape[0] == 1:
        q0, q1, q2, q3 = _lagrange_rows(times, quats, win, den, t)
    else:
        i = interval_index(times, t)
        s = (t - times[i]) / (times[i + 1] - times[i])
        dot = quats[i, 0] * quats[i + 1, 0] + quats[i, 1] * quats[i + 1, 1] + quats[i, 2] * quats[i + 1, 2] \
            + quats[i, 3] * quats[i + 1, 3]
        if dot > 1.0:
            dot = 1.0
        theta = np.arccos(dot)
        st = np.sin(theta)
        if st < 1e-12:
            w0 = 1.0 - s
            w1 = s
        else:
            w0 = np.sin((1.0 - s) * theta) / st
            w1 = np.sin(s * theta) / st
        q0 = w0 * quats[i, 0] + w1 * quats[i + 1, 0]
        q1 = w0 * quats[i, 1] + w1 * quats[i + 1, 1]
        q2 = w0 * quats[i, 2] + w1 * quats[i + 1, 2]
        q3 = w0 * quats[i, 3] + w1 * quats[i + 1, 3]
    nrm = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    return q0 / nrm, q1 / nrm, q2 / nrm, q3 / nrm


@njit(cache=True)
def quaternion_at(times, quats, t, mode, max_order, q):
    """Interpolated unit quaternion ``(w, x, y, z)`` at ``t`` into ``q`` (4,).

    ``mode`` 0: slerp between the two samples around ``t`` (linear extrapolation of the angle
    beyond the table); 1: Lagrange on the components (usgscsm), renormalised.  (The Lagrange windows
    are built per call: for many times use the kernels with :func:`window_tables` built once.)
    """
    if mode == 1:
        win, den = window_tables(times, max_order)
    else:  # slerp needs no window
        win, den = np.zeros((1, 2), np.int64), np.zeros((1, 8))
    q[0], q[1], q[2], q[3] = _quat(times, quats, win, den, t, mode)


@njit(cache=True)
def _qmat(w, x, y, z):
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w),
            2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w),
            2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y))


@njit(cache=True)
def quaternion_matrix(q, r):
    """Active rotation matrix ``r`` (3, 3) of the unit quaternion ``q = (w, x, y, z)``."""
    m = _qmat(q[0], q[1], q[2], q[3])
    for k in range(9):
        r[k // 3, k % 3] = m[k]


@njit(cache=True)
def line_time(line, rate_lines, rate_times, rate_periods):
    """CSM image time of a (fractional) line: ``t_k + dt_k (line - line_k + 0.5)``."""
    k = np.searchsorted(rate_lines, line, side="right") - 1
    if k < 0:
        k = 0
    return rate_times[k] + rate_periods[k] * (line - rate_lines[k] + 0.5)


# --------------------------------------------------------------------------- exterior
@njit(cache=True)
def _const_times(c, m):
    """``c @ m`` for a 3 x 3 array ``c`` and a 9-tuple ``m`` (row-major), as a 9-tuple."""
    return (c[0, 0] * m[0] + c[0, 1] * m[3] + c[0, 2] * m[6], c[0, 0] * m[1] + c[0, 1] * m[4] + c[0, 2] * m[7],
            c[0, 0] * m[2] + c[0, 1] * m[5] + c[0, 2] * m[8], c[1, 0] * m[0] + c[1, 1] * m[3] + c[1, 2] * m[6],
            c[1, 0] * m[1] + c[1, 1] * m[4] + c[1, 2] * m[7], c[1, 0] * m[2] + c[1, 1] * m[5] + c[1, 2] * m[8],
            c[2, 0] * m[0] + c[2, 1] * m[3] + c[2, 2] * m[6], c[2, 0] * m[1] + c[2, 1] * m[4] + c[2, 2] * m[7],
            c[2, 0] * m[2] + c[2, 1] * m[5] + c[2, 2] * m[8])


@njit(cache=True, inline="always")  # inlined: the tables' tuple is not copied per call (-15 % CPU per point)
def _exterior(t, ext):
    """Allocation-free exterior: centre ``(s0, s1, s2)`` and camera -> body rotation (row-major 9-tuple).

    ``ext`` = ``(pos_t, pos - pos_ref, pos_ref, pos_win, pos_den, qp_t, qp, qp_win, qp_den, cp, qb_t, qb,
    qb_win, qb_den, cb, att_mode, rotate_position, simple)`` (:meth:`explorer.real.csm.CsmCamera._exterior_args`;
    ``simple``: identity body and constant rotations, positions body-fixed):
    the positions are interpolated as offsets from a reference point (the weights sum to one), which keeps
    the round-off of the weighted sum at the offsets' scale instead of the body radius.
    """
    pos_t, pos, pos_ref, pos_win, pos_den, qp_t, qp, qp_win, qp_den, cp, qb_t, qb, qb_win, qb_den, cb, att_mode, \
        rotate_position, simple = ext
    p0, p1, p2 = _lagrange3(pos_t, pos, pos_win, pos_den, t)
    p0, p1, p2 = p0 + pos_ref[0], p1 + pos_ref[1], p2 + pos_ref[2]
    w, x, y, z = _quat(qp_t, qp, qp_win, qp_den, t, att_mode)
    if simple:  # identity body rotation and constant rotations (usgscsm state): M = P^T
        pm = _qmat(w, x, y, z)
        m = (pm[0], pm[3], pm[6], pm[1], pm[4], pm[7], pm[2], pm[5], pm[8])
        return p0, p1, p2, m
    pm = _const_times(cp, _qmat(w, x, y, z))
    w, x, y, z = _quat(qb_t, qb, qb_win, qb_den, t, att_mode)
    b = _const_times(cb, _qmat(w, x, y, z))
    m = (b[0] * pm[0] + b[1] * pm[1] + b[2] * pm[2], b[0] * pm[3] + b[1] * pm[4] + b[2] * pm[5],
         b[0] * pm[6] + b[1] * pm[7] + b[2] * pm[8], b[3] * pm[0] + b[4] * pm[1] + b[5] * pm[2],
         b[3] * pm[3] + b[4] * pm[4] + b[5] * pm[5], b[3] * pm[6] + b[4] * pm[7] + b[5] * pm[8],
         b[6] * pm[0] + b[7] * pm[1] + b[8] * pm[2], b[6] * pm[3] + b[7] * pm[4] + b[8] * pm[5],
         b[6] * pm[6] + b[7] * pm[7] + b[8] * pm[8])
    if rotate_position:
        return (b[0] * p0 + b[1] * p1 + b[2] * p2, b[3] * p0 + b[4] * p1 + b[5] * p2,
                b[6] * p0 + b[7] * p1 + b[8] * p2, m)
    return p0, p1, p2, m


@njit(cache=True)
def exterior_at(t, ext, s_out, m_out):
    """Perspective centre ``s_out`` (3,) body-fixed metres and camera -> body rotation ``m_out`` (3, 3).

    ``M = B(t) P(t)^T`` with ``P = C_p Q(qp(t))`` the J2000 -> sensor rotation and
    ``B = C_b Q(qb(t))`` the J2000 -> body rotation; positions given in J2000
    (``rotate_position``) are rotated by ``B(t)``.
    """
    s0, s1, s2, m = _exterior(t, ext)
    s_out[0], s_out[1], s_out[2] = s0, s1, s2
    for k in range(9):
        m_out[k // 3, k % 3] = m[k]


# --------------------------------------------------------------------------- distortion
@njit(cache=True)
def _closed_form(model, c, x, y):
    """The direction of each model that has a closed form (see :func:`closed_form_is_removal`)."""
    if model == DIST_RADIAL:
        rr = x * x + y * y
        dr = c[0] + rr * (c[1] + rr * c[2])
        return x * (1.0 - dr), y * (1.0 - dr)
    if model == DIST_TRANSVERSE:
        f1, f2, f3, f4 = x, y, x * x, x * y
        f5, f6, f7, f8, f9 = y * y, x * x * x, x * x * y, x * y * y, y * y * y
        ox = c[0] + c[1] * f1 + c[2] * f2 + c[3] * f3 + c[4] * f4 + c[5] * f5 + c[6] * f6 + c[7] * f7 \
            + c[8] * f8 + c[9] * f9
        oy = c[10] + c[11] * f1 + c[12] * f2 + c[13] * f3 + c[14] * f4 + c[15] * f5 + c[16] * f6 \
            + c[17] * f7 + c[18] * f8 + c[19] * f9
        return ox, oy
    if model == DIST_KAGUYALISM:
        r2 = x * x + y * y
        r = np.sqrt(r2)
        r3 = r2 * r
        dx = c[1] + c[2] * r + c[3] * r2 + c[4] * r3
        dy = c[6] + c[7] * r + c[8] * r2 + c[9] * r3
        return x + dx + c[0], y + dy + c[5]
    if model == DIST_DAWNFC:
        r2 = x * x + y * y
        return x * (1.0 + c[0] * r2), y * (1.0 + c[0] * r2)
    if model == DIST_LROLROCNAC:
        return x, y / (1.0 + c[0] * y * y)
    if model == DIST_CAHVOR:  # usgscsm: radial about the offset (c[3], c[4])
        sx, sy = x - c[3], y - c[4]
        rr = sx * sx + sy * sy
        dr = c[0] + rr * (c[1] + rr * c[2])
        return sx * (1.0 - dr) + c[3], sy * (1.0 - dr) + c[4]
    if model == DIST_LUNARORBITER:  # ISIS LoHighDistortionMap::SetFocalPlane: perspective, then radial about (x0, y0)
        pf = 1.0 + c[0] * x + c[1] * y
        pcx, pcy = x * pf, y * pf
        sx, sy = pcx - c[2], pcy - c[3]
        rr = sx * sx + sy * sy
        dr = c[4] + c[5] * rr
        return pcx - dr * sx, pcy - dr * sy
    if model == DIST_RADTAN:  # usgscsm / OpenCV on coordinates normalised by the focal length c[5]
        f = c[5]
        u, v = x / f, y / f
        rr = u * u + v * v
        radial = 1.0 + rr * (c[0] + rr * (c[1] + rr * c[4]))
        du = u * radial + 2.0 * c[2] * u * v + c[3] * (rr + 2.0 * u * u)
        dv = v * radial + c[2] * (rr + 2.0 * v * v) + 2.0 * c[3] * u * v
        return du * f, dv * f
    if model == DIST_KPLOSHADOWCAM:  # usgscsm: y only, uy = dy (1 + k dy^2)
        return x, y * (1.0 + c[0] * y * y)
    if model == DIST_LEGENDRE:  # ISIS NewHorizonsMvicTdiCameraDistortionMap::SetFocalPlane (x only, y scaled 0)
        half = c[0]
        s = -x / half
        s2 = s * s
        p0, p1, p2 = 1.0, s, 0.5 * (3.0 * s2 - 1.0)
        p3 = 0.5 * s * (5.0 * s2 - 3.0)
        p4 = (35.0 * s2 * s2 - 30.0 * s2 + 3.0) / 8.0
        p5 = s * (63.0 * s2 * s2 - 70.0 * s2 + 15.0) / 8.0
        q0, q2, q4 = 1.0, -0.5, 0.375  # P_n(0); P_1, P_3, P_5 vanish at 0
        # terms (i, j) of P_i(x) P_j(y): (0,1) (1,0) (0,2) (1,1) (2,0) (0,3) (1,2) (2,1) (3,0) (0,4) (1,3) (2,2)
        # (3,1) (4,0) (0,5) (1,4) (2,3) (3,2) (4,1) (5,0); coefficients c[1 + k]
        d = c[2] * p1 * q0 + c[3] * p0 * q2 + c[5] * p2 * q0 + c[7] * p1 * q2 + c[9] * p3 * q0 \
            + c[10] * p0 * q4 + c[12] * p2 * q2 + c[14] * p4 * q0 + c[16] * p1 * q4 + c[18] * p3 * q2 \
            + c[20] * p5 * q0
        return -(s + d) * half, y
    if model == DIST_THEMISIR:  # ISIS ThemisIrDistortionMap::SetFocalPlane
        rad = (1.0 + c[1]) * (1.0 + c[1]) + 4.0 * c[2] * y
        if rad < 0.0:
            return np.nan, np.nan
        return x / c[0], 2.0 * y / (1.0 + c[1] + np.sqrt(rad))
    return x, y


@njit(cache=True)
def closed_form_is_removal(model):
    """True where the closed form maps distorted -> undistorted (all but transverse, Dawn FC and radtan)."""
    return not (model == DIST_TRANSVERSE or model == DIST_DAWNFC or model == DIST_RADTAN)


@njit(cache=True)
def _solve_closed_form(model, c, tx, ty):
    """Solve ``closed_form(x, y) = (tx, ty)`` by Newton (finite-difference Jacobian)."""
    x, y = tx, ty
    ok = False
    for _ in range(DIST_MAX_ITER):
        fx, fy = _closed_form(model, c, x, y)
        ex, ey = fx - tx, fy - ty
        h = 1e-7 * (abs(x) + abs(y) + 1e-3)
        ax, ay = _closed_form(model, c, x + h, y)
        bx, by = _closed_form(model, c, x, y + h)
        j00, j10 = (ax - fx) / h, (ay - fy) / h
        j01, j11 = (bx - fx) / h, (by - fy) / h
        det = j00 * j11 - j01 * j10
        if det == 0.0 or not np.isfinite(det):
            break
        dx = (j11 * ex - j01 * ey) / det
        dy = (j00 * ey - j10 * ex) / det
        x -= dx
        y -= dy
        if abs(dx) + abs(dy) <= NEWTON_TOL_MM * (1.0 + abs(x) + abs(y)):
            ok = True
            break
    if not ok:
        return np.nan, np.nan
    return x, y


@njit(cache=True)
def remove_distortion(model, c, x, y):
    """Distorted -> undistorted focal-plane coordinates (mm)."""
    if model == DIST_NONE:
        return x, y
    if closed_form_is_removal(model):
        return _closed_form(model, c, x, y)
    return _solve_closed_form(model, c, x, y)


@njit(cache=True)
def _apply_radial(c, x, y):
    """Inverse of usgscsm's radial removal ``u = d (1 - D(|d|^2))``: Newton on the distorted radius."""
    ru = np.sqrt(x * x + y * y)
    if ru == 0.0:
        return x, y
    r = ru
    for _ in range(DIST_MAX_ITER):
        rr = r * r
        dd = c[0] + rr * (c[1] + rr * c[2])
        f = r * (1.0 - dd) - ru
        fp = 1.0 - dd - 2.0 * rr * (c[1] + 2.0 * rr * c[2])
        step = f / fp
        r -= step
        if abs(step) <= NEWTON_TOL_MM * (1.0 + r):
            rr = r * r
            dd = c[0] + rr * (c[1] + rr * c[2])
            return x / (1.0 - dd), y / (1.0 - dd)
    return np.nan, np.nan


@njit(cache=True)
def apply_distortion(model, c, x, y):
    """Undistorted -> distorted focal-plane coordinates (mm)."""
    if model == DIST_NONE:
        return x, y
    if model == DIST_RADIAL:
        return _apply_radial(c, x, y)
    if closed_form_is_removal(model):
        return _solve_closed_form(model, c, x, y)
    return _closed_form(model, c, x, y)


@njit(parallel=True, cache=True)
def distortion_many(model, c, x, y, remove, ox, oy):
    """Vectorised :func:`remove_distortion` (``remove``) or :func:`apply_distortion`."""
    for i in prange(x.shape[0]):
        if remove:
            ox[i], oy[i] = remove_distortion(model, c, x[i], y[i])
        else:
            ox[i], oy[i] = apply_distortion(model, c, x[i], y[i])


# --------------------------------------------------------------------------- camera
# ``cam``: float64 array of the scalar camera constants, see explorer.real.csm.CsmCamera._cam
C_FOCAL, C_LINE_ORIGIN, C_SAMPLE_ORIGIN, C_START_LINE, C_START_SAMPLE = 0, 1, 2, 3, 4
C_LINE_SUM, C_SAMPLE_SUM, C_TL0, C_TL1, C_TL2, C_TS0, C_TS1, C_TS2 = 5, 6, 7, 8, 9, 10, 11, 12
C_A, C_B, C_N_LINES, C_N_SAMPLES, C_SLOPE, C_LOOK, C_CURV = 13, 14, 15, 16, 17, 18, 19
N_CAM = 20


@njit(cache=True, inline="always")
def detector_residual(X, Y, Z, line, cam, rl, rt, rp, ext, dmodel, dc):
    """Detector-line residual (image lines) and sample of a ground point seen at ``line``.

    Returns ``(residual, sample, ok)``: the residual is usgscsm's ``calcDetectorLineErr`` (zero
    at the best line); ``ok`` is False behind the camera or for a non-finite evaluation.
    """
    t = line_time(line, rl, rt, rp)
    s0, s1, s2, m = _exterior(t, ext)
    sg = cam[C_LOOK]
    dx, dy, dz = sg * (X - s0), sg * (Y - s1), sg * (Z - s2)
    vx = m[0] * dx + m[3] * dy + m[6] * dz
    vy = m[1] * dx + m[4] * dy + m[7] * dz
    vz = m[2] * dx + m[5] * dy + m[8] * dz
    if not vz < 0.0:  # the camera looks along C_LOOK * (-x, -y, -f)
        return np.nan, np.nan, False
    f = cam[C_FOCAL]
    xu = f * vx / vz
    yu = f * vy / vz
    xd, yd = apply_distortion(dmodel, dc, xu, yu)
    det_line = cam[C_TL0] + cam[C_TL1] * xd + cam[C_TL2] * yd + cam[C_LINE_ORIGIN] - cam[C_START_LINE]
    det_sample = cam[C_TS0] + cam[C_TS1] * xd + cam[C_TS2] * yd + cam[C_SAMPLE_ORIGIN] - cam[C_START_SAMPLE]
    res = det_line / cam[C_LINE_SUM]
    sample = det_sample / cam[C_SAMPLE_SUM]
    ok = np.isfinite(res) and np.isfinite(sample)
    return res, sample, ok


@njit(cache=True)
def seed_polynomial(X, Y, Z, mean, inv_scale, coef):
    """The camera's seed polynomial ``line(X, Y, Z)`` (quadratic: 10 terms, cubic: 20) in normalised coordinates."""
    x = (X - mean[0]) * inv_scale[0]
    y = (Y - mean[1]) * inv_scale[1]
    z = (Z - mean[2]) * inv_scale[2]
    v = coef[0] + coef[1] * x + coef[2] * y + coef[3] * z + coef[4] * x * x + coef[5] * y * y + coef[6] * z * z \
        + coef[7] * x * y + coef[8] * x * z + coef[9] * y * z
    if coef.shape[0] == 20:
        v += coef[10] * x * x * x + coef[11] * y * y * y + coef[12] * z * z * z + coef[13] * x * x * y \
            + coef[14] * x * x * z + coef[15] * y * y * x + coef[16] * y * y * z + coef[17] * z * z * x \
            + coef[18] * z * z * y + coef[19] * x * y * z
    return v


@njit(parallel=True, cache=True)
def ground_to_image_nb(ground, seed, window_lo, window_hi, tol, max_iter, cam, rl, rt, rp, ext, dmodel, dc,
                       line_out, sample_out, status_out, evals_out):
    """Best line per ground point: safeguarded secant on the detector-line residual.

    ``seed`` = ``(mean (3,), 1 / scale (3,), line coefficients, sample coefficients (10 or 20,),
    correction table (K, 3), first node, 1 / node step, middle sample, 2 / samples)``: the polynomial
    :func:`seed_polynomial` plus its tabulated error (:meth:`explorer.real.csm.CsmCamera._correction_table`).

    From the seed (clipped to the window), a Newton step with the camera's typical slope
    ``d residual / d line`` (``cam[C_SLOPE]``), then secant steps; once two residuals differ in
    sign the root is bracketed, the bracket shrinks with every evaluation and a step leaving it
    is replaced by bisection.  Stops when the step is at most ``tol`` lines and returns the last
    iterate plus that step (the sample is the last evaluation's: it moves by less than ``tol``
    times ``d sample / d line``).  A step pushed against a window end twice means no root.
    """
    curv = cam[C_CURV]
    mean, inv_scale, coef, scoef, table, node0, inv_step, s_mid, s_inv_half = seed
    n_nodes = table.shape[0]
    for i in prange(ground.shape[0]):
        X, Y, Z = ground[i, 0], ground[i, 1], ground[i, 2]
        x0 = seed_polynomial(X, Y, Z, mean, inv_scale, coef)
        if n_nodes > 1:
            # tabulated error of the polynomial: linear in its line, quadratic in the sample
            j = (x0 - node0) * inv_step
            if j >= 0.0 and j < n_nodes - 1:
                k = int(j)
                fr = j - k
                u = (seed_polynomial(X, Y, Z, mean, inv_scale, scoef) - s_mid) * s_inv_half
                u = min(max(u, -1.0), 1.0)
                l0, l1, l2 = 0.5 * u * (u - 1.0), 1.0 - u * u, 0.5 * u * (u + 1.0)
                e0 = (1.0 - fr) * table[k, 0] + fr * table[k + 1, 0]
                e1 = (1.0 - fr) * table[k, 1] + fr * table[k + 1, 1]
                e2 = (1.0 - fr) * table[k, 2] + fr * table[k + 1, 2]
                x0 += l0 * e0 + l1 * e1 + l2 * e2
        x0 = min(max(x0, window_lo), window_hi)
        f0, s0, ok = detector_residual(X, Y, Z, x0, cam, rl, rt, rp, ext, dmodel, dc)
        n_eval = 1
        status = STATUS_MAX_ITER
        line = np.nan
        sample = np.nan
        if not ok:
            status = STATUS_BEHIND
        else:
            slope = cam[C_SLOPE]
            bracket = False
            a, fa, b = window_lo, 0.0, window_hi
            x1 = min(max(x0 - f0 / slope, window_lo), window_hi)
            if x1 == x0:
                x1 = min(max(x0 + (1.0 if -f0 / slope > 0 else -1.0) * 1e-3, window_lo), window_hi)
            for _ in range(max_iter):
                f1, s1, ok = detector_residual(X, Y, Z, x1, cam, rl, rt, rp, ext, dmodel, dc)
                n_eval += 1
                if not ok:
                    status = STATUS_BEHIND
                    break
                if abs(f1 / slope) <= 0.01 * tol:  # at the residual's floor: x1 is the root
                    line, sample, status = x1, s1, STATUS_OK
                    break
                if not bracket and ((f0 < 0.0) != (f1 < 0.0)):
                    bracket = True
                    if x0 < x1:
                        a, fa, b = x0, f0, x1
                    else:
                        a, fa, b = x1, f1, x0
                elif bracket and a < x1 < b:
                    if (f1 < 0.0) == (fa < 0.0):
                        a, fa = x1, f1
                    else:
                        b = x1
                denom = f1 - f0
                step = -f1 * (x1 - x0) / denom if denom != 0.0 else -f1 / slope
                x2 = x1 + step
                bisected = False
                if bracket and not (a < x2 < b):
                    x2 = 0.5 * (a + b)
                    step = x2 - x1
                    bisected = True
                # the secant point's error is about C |x1 - r| |x0 - r| ~ C |step| |x1 - x0| (C: the residual's
                # curvature constant measured at setup); accept once that (or the step itself) is below tol
                if abs(step) <= tol or (not bisected and curv * abs(step) * abs(x1 - x0) <= tol):
                    ds = (s1 - s0) / (x1 - x0) if x1 != x0 else 0.0
                    line, sample, status = x2, s1 + ds * step, STATUS_OK
                    break
                x2c = min(max(x2, window_lo), window_hi)
                if x2c == x1:  # pushed against a window end: the residual keeps its sign over the window
                    status = STATUS_NO_ROOT
                    break
                x0, f0, s0 = x1, f1, s1
                x1 = x2c
        store_point(i, status, STATUS_OK, line, sample, n_eval, line_out, sample_out, status_out, evals_out)


@njit(parallel=True, cache=True)
def image_to_ground_nb(line, sample, height, cam, rl, rt, rp, ext, dmodel, dc, ground_out, status_out, centre_out,
                       look_out):
    """Lines of sight of image points intersected with the ellipsoid inflated by ``height``.

    The ellipsoid has semi-axes ``(a + h, a + h, b + h)`` as in usgscsm's ``losEllipsoidIntersect``;
    the nearest intersection in front of the camera is returned; a ray that misses is NaN with
    ``STATUS_MISS`` (usgscsm would return the point of the ray closest to the surface instead).
    """
    for i in prange(line.shape[0]):
        t = line_time(line[i], rl, rt, rp)
        s = np.empty(3)
        m = np.empty((3, 3))
        exterior_at(t, ext, s, m)
        det_sample = sample[i] * cam[C_SAMPLE_SUM] + cam[C_START_SAMPLE]
        det_line = cam[C_START_LINE]  # the detector line: usgscsm passes line 0 to the focal-plane mapping
        t1 = det_line - cam[C_LINE_ORIGIN] - cam[C_TL0]
        t2 = det_sample - cam[C_SAMPLE_ORIGIN] - cam[C_TS0]
        m11, m12, m21, m22 = cam[C_TL1], cam[C_TL2], cam[C_TS1], cam[C_TS2]
        det = m11 * m22 - m12 * m21
        xd = (m22 * t1 - m12 * t2) / det
        yd = (-m21 * t1 + m11 * t2) / det
        xu, yu = remove_distortion(dmodel, dc, xd, yd)
        cx, cy, cz = -xu, -yu, -cam[C_FOCAL]
        nrm = cam[C_LOOK] / np.sqrt(cx * cx + cy * cy + cz * cz)
        cx, cy, cz = cx * nrm, cy * nrm, cz * nrm
        lx = m[0, 0] * cx + m[0, 1] * cy + m[0, 2] * cz
        ly = m[1, 0] * cx + m[1, 1] * cy + m[1, 2] * cz
        lz = m[2, 0] * cx + m[2, 1] * cy + m[2, 2] * cz
        centre_out[i, 0], centre_out[i, 1], centre_out[i, 2] = s[0], s[1], s[2]
        look_out[i, 0], look_out[i, 1], look_out[i, 2] = lx, ly, lz
        ap = cam[C_A] + height[i]
        bp = cam[C_B] + height[i]
        k = ap * ap / (bp * bp)
        qa = lx * lx + ly * ly + k * lz * lz
        qb2 = lx * s[0] + ly * s[1] + k * lz * s[2]  # half of usgscsm's bt
        qc = s[0] * s[0] + s[1] * s[1] + k * s[2] * s[2] - ap * ap
        disc = qb2 * qb2 - qa * qc
        scale = np.nan
        if disc >= 0.0 and np.isfinite(disc):
            sq = np.sqrt(disc)
            # numerically stable roots of qa s^2 + 2 qb2 s + qc = 0
            if qb2 >= 0.0:
                r1 = (-qb2 - sq) / qa
                r2 = qc / (qa * r1) if r1 != 0.0 else np.nan
            else:
                r2 = (-qb2 + sq) / qa
                r1 = qc / (qa * r2) if r2 != 0.0 else np.nan
            lo_r, hi_r = min(r1, r2), max(r1, r2)
            if lo_r > 0.0:
                scale = lo_r
            elif hi_r > 0.0:
                scale = hi_r
        if np.isfinite(scale):
            ground_out[i, 0] = s[0] + scale * lx
            ground_out[i, 1] = s[1] + scale * ly
            ground_out[i, 2] = s[2] + scale * lz
            status_out[i] = STATUS_OK
        else:
            ground_out[i, 0] = np.nan
            ground_out[i, 1] = np.nan
            ground_out[i, 2] = np.nan
            status_out[i] = STATUS_MISS


@njit(parallel=True, cache=True)
def exterior_many(times, ext,
                  centre_out, rot_out):
    """Perspective centres (N, 3) and camera -> body rotations (N, 3, 3) at times (N,)."""
    for i in prange(times.shape[0]):
        s = np.empty(3)
        m = np.empty((3, 3))
        exterior_at(times[i], ext,
                    s, m)
        for a in range(3):
            centre_out[i, a] = s[a]
            for b in range(3):
                rot_out[i, a, b] = m[a, b]


@njit(parallel=True, cache=True)
def residual_many(ground, lines, cam, rl, rt, rp, ext, dmodel, dc, res_out, sample_out):
    """:func:`detector_residual` for many (point, line) pairs (NaN where invalid)."""
    for i in prange(ground.shape[0]):
        r, s, ok = detector_residual(ground[i, 0], ground[i, 1], ground[i, 2], lines[i], cam, rl, rt, rp, ext,
                                     dmodel, dc)
        res_out[i] = r if ok else np.nan
        sample_out[i] = s if ok else np.nan


@njit(cache=True)
def geodetic_to_body_fixed_nb(lon_deg, lat_deg, h, a, e2, out):
    """Planetodetic (lon, lat degrees, height above the ellipsoid metres; each (N,)) -> body-fixed metres into
    ``out`` (N, 3) on the ellipsoid of semi-major axis ``a`` and squared eccentricity ``e2``: the formulas of
    :func:`explorer.geometry.frames.geodetic_to_ecef` in one loop (the camera's geodetic entry, at the cost of
    four libm calls a point instead of numpy's separate passes; equal to it within an ulp)."""
    d = np.pi / 180.0
    for i in range(lon_deg.shape[0]):
        la = lat_deg[i] * d
        lo = lon_deg[i] * d
        sl = np.sin(la)
        cl = np.cos(la)
        n = a / np.sqrt(1.0 - e2 * sl * sl)
        r = (n + h[i]) * cl
        out[i, 0] = r * np.cos(lo)
        out[i, 1] = r * np.sin(lo)
        out[i, 2] = (n * (1.0 - e2) + h[i]) * sl
