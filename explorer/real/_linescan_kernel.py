"""Compiled line geometry of the rigorous line-scan model (:mod:`explorer.real.linescan`).

One collinearity evaluation of :class:`~explorer.real.linescan.RigorousLineScanScene` -- the perspective
centre and attitude interpolated from the ephemeris and attitude tables (Lagrange windows, or slerp), the
optional atmospheric refraction and aberration of light, the rotation into the sensor frame and the
projection onto the focal plane -- as one numba loop over points, instead of a dozen numpy passes over
(N, m) and (N, 3, 3) temporaries per evaluation.  It computes the same formulas in the same order as the
numpy path of ``linescan.py`` (``RigorousLineScanScene.focal_plane_numpy``), which stays the reference:
``tests/real/test_linescan_kernel.py`` holds the two within 1e-9 px on the Pleiades DIMAP and WorldView-1
models and synthetic tables of every option.

The searches of ``methods/_line_geometry.py`` and the bracketing truth (:mod:`explorer.geometry.bracket`)
call :meth:`~explorer.scene.Scene.focal_plane` once per iteration on all unresolved points; with this
kernel that call costs a fraction of a microsecond per point.

Conventions: ``docs/conventions.md`` (frames, rotations, best scanline).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, kernel, prange, serial_twin

__all__ = ["NUMBA_AVAILABLE", "PARALLEL_MIN_POINTS", "ideal_focal_plane", "pack_exterior"]

#: Below this many points the serial variant runs: on the shared 2-core machine the threaded loop took 33 ms for
#: 50,000 points against 9 ms serially (waking and sharing the second thread costs more than it saves).
PARALLEL_MIN_POINTS = 200_000

ATTITUDE_LAGRANGE = 0
ATTITUDE_SLERP = 1


def _search_left(ts: Any, t: float) -> int:
    """``np.searchsorted(ts, t)`` (side "left") for one value: the first index with ``ts[i] >= t``."""
    lo = 0
    hi = ts.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if ts[mid] < t:
            lo = mid + 1
        else:
            hi = mid
    return lo


_search_left_c = kernel(inline="always")(_search_left)


def _lagrange_start(ts: Any, t: float, order: int) -> int:
    """First sample of the Lagrange window of :func:`explorer.real.linescan.lagrange_interpolate` at ``t``."""
    n = ts.shape[0]
    m = min(order, n)
    start = _search_left_c(ts, t) - m // 2
    if start < 0:
        start = 0
    if start > n - m:
        start = n - m
    return start


_lagrange_start_c = kernel(inline="always")(_lagrange_start)


def _lagrange_weight(ts: Any, t: float, start: int, m: int, j: int) -> float:
    """Weight of sample ``start + j`` in the window, the product formed in the order numpy forms it."""
    w = 1.0
    for k in range(m):
        if k != j:
            w *= (t - ts[start + k]) / (ts[start + j] - ts[start + k])
    return w


_lagrange_weight_c = kernel(inline="always")(_lagrange_weight)


def _focal_plane_loop(ground, t, eph_t, eph_p, eph_v, eph_order, att_t, att_q, att_method, att_order,
                      s2b, offset, has_offset, e, origin, focal, aberration, refraction, omega_enu,
                      geo, out_x, out_y):
    """Ideal focal-plane (x, y) (metres, before distortion) of ground points (N, 3) at times (N,)."""
    a_m, b_m, e2 = geo[0], geo[1], geo[2]
    n_refr, scale_h, c_light = geo[3], geo[4], geo[5]
    for i in prange(ground.shape[0]):
        ti = t[i]
        # ---- ephemeris: position minus the frame's origin (ECEF axes) and velocity, interpolated about the
        # tangent line of the window's middle sample (linescan.lagrange_position_from: no 7,000 km round-off)
        s0 = _lagrange_start_c(eph_t, ti, eph_order)
        m = min(eph_order, eph_t.shape[0])
        jm = s0 + m // 2
        tr = eph_t[jm]
        prx = eph_p[jm, 0]
        pry = eph_p[jm, 1]
        prz = eph_p[jm, 2]
        vrx = eph_v[jm, 0]
        vry = eph_v[jm, 1]
        vrz = eph_v[jm, 2]
        px = 0.0
        py = 0.0
        pz = 0.0
        vx = 0.0
        vy = 0.0
        vz = 0.0
        for j in range(m):
            wj = _lagrange_weight_c(eph_t, ti, s0, m, j)
            dtj = eph_t[s0 + j] - tr
            if j == 0:
                px = wj * ((eph_p[s0, 0] - prx) - vrx * dtj)
                py = wj * ((eph_p[s0, 1] - pry) - vry * dtj)
                pz = wj * ((eph_p[s0, 2] - prz) - vrz * dtj)
            else:
                px += wj * ((eph_p[s0 + j, 0] - prx) - vrx * dtj)
                py += wj * ((eph_p[s0 + j, 1] - pry) - vry * dtj)
                pz += wj * ((eph_p[s0 + j, 2] - prz) - vrz * dtj)
            vx += wj * eph_v[s0 + j, 0]
            vy += wj * eph_v[s0 + j, 1]
            vz += wj * eph_v[s0 + j, 2]
        # the window's middle sample (fixed within the window) and the motion from it, kept apart
        dtr = ti - tr
        px = vrx * dtr + px
        py = vry * dtr + py
        pz = vrz * dtr + pz
        fx0 = prx - origin[0]
        fy0 = pry - origin[1]
        fz0 = prz - origin[2]
        # ---- attitude: body -> ECEF quaternion
        if att_method == ATTITUDE_LAGRANGE:
            s1 = _lagrange_start_c(att_t, ti, att_order)
            ma = min(att_order, att_t.shape[0])
            qw = 0.0
            qx = 0.0
            qy = 0.0
            qz = 0.0
            for j in range(ma):
                wj = _lagrange_weight_c(att_t, ti, s1, ma, j)
                qw += wj * att_q[s1 + j, 0]
                qx += wj * att_q[s1 + j, 1]
                qy += wj * att_q[s1 + j, 2]
                qz += wj * att_q[s1 + j, 3]
        else:
            na = att_t.shape[0]
            k = _search_left_c(att_t, ti) - 1
            if k < 0:
                k = 0
            if k > na - 2:
                k = na - 2
            s = (ti - att_t[k]) / (att_t[k + 1] - att_t[k])
            aw, ax, ay, az = att_q[k, 0], att_q[k, 1], att_q[k, 2], att_q[k, 3]
            bw, bx, by, bz = att_q[k + 1, 0], att_q[k + 1, 1], att_q[k + 1, 2], att_q[k + 1, 3]
            dot = aw * bw + ax * bx + ay * by + az * bz
            if dot < 0:
                bw, bx, by, bz = -bw, -bx, -by, -bz
            dot = abs(dot)
            theta = math.acos(min(max(dot, -1.0), 1.0))
            sin_t = math.sin(theta)
            if sin_t < 1e-12:
                w0 = 1.0 - s
                w1 = s
            else:
                w0 = math.sin((1.0 - s) * theta) / sin_t
                w1 = math.sin(s * theta) / sin_t
            qw = w0 * aw + w1 * bw
            qx = w0 * ax + w1 * bx
            qy = w0 * ay + w1 * by
            qz = w0 * az + w1 * bz
        qn = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        qw /= qn
        qx /= qn
        qy /= qn
        qz /= qn
        if att_method == ATTITUDE_LAGRANGE:  # quaternion_to_matrix normalises once more
            qn = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
            qw /= qn
            qx /= qn
            qy /= qn
            qz /= qn
        q00 = 1 - 2 * (qy * qy + qz * qz)
        q01 = 2 * (qx * qy - qz * qw)
        q02 = 2 * (qx * qz + qy * qw)
        q10 = 2 * (qx * qy + qz * qw)
        q11 = 1 - 2 * (qx * qx + qz * qz)
        q12 = 2 * (qy * qz - qx * qw)
        q20 = 2 * (qx * qz - qy * qw)
        q21 = 2 * (qy * qz + qx * qw)
        q22 = 1 - 2 * (qx * qx + qy * qy)
        if has_offset:
            px += q00 * offset[0] + q01 * offset[1] + q02 * offset[2]
            py += q10 * offset[0] + q11 * offset[1] + q12 * offset[2]
            pz += q20 * offset[0] + q21 * offset[1] + q22 * offset[2]
        # ---- perspective centre in ENU: E^T (p - origin), as fixed + moving
        fcx = e[0, 0] * fx0 + e[1, 0] * fy0 + e[2, 0] * fz0
        fcy = e[0, 1] * fx0 + e[1, 1] * fy0 + e[2, 1] * fz0
        fcz = e[0, 2] * fx0 + e[1, 2] * fy0 + e[2, 2] * fz0
        mcx = e[0, 0] * px + e[1, 0] * py + e[2, 0] * pz
        mcy = e[0, 1] * px + e[1, 1] * py + e[2, 1] * pz
        mcz = e[0, 2] * px + e[1, 2] * py + e[2, 2] * pz
        cx = fcx + mcx
        cy = fcy + mcy
        cz = fcz + mcz
        gx = ground[i, 0]
        gy = ground[i, 1]
        gz = ground[i, 2]
        tx = gx
        ty = gy
        tz = gz
        if refraction:
            # geodetic normal and height of the ground point (frames.ecef_to_geodetic)
            ex = origin[0] + e[0, 0] * gx + e[0, 1] * gy + e[0, 2] * gz
            ey = origin[1] + e[1, 0] * gx + e[1, 1] * gy + e[1, 2] * gz
            ez = origin[2] + e[2, 0] * gx + e[2, 1] * gy + e[2, 2] * gz
            lon = math.atan2(ey, ex)
            p = math.hypot(ex, ey)
            ep2 = e2 / (1.0 - e2)
            th = math.atan2(ez * a_m, p * b_m)
            lat = math.atan2(ez + ep2 * b_m * math.sin(th) ** 3, p - e2 * a_m * math.cos(th) ** 3)
            for _ in range(5):
                sl = math.sin(lat)
                nn = a_m / math.sqrt(1.0 - e2 * sl * sl)
                lat = math.atan2(ez + e2 * nn * sl, p)
            sl = math.sin(lat)
            cl = math.cos(lat)
            nn = a_m / math.sqrt(1.0 - e2 * sl * sl)
            h = p * cl + ez * sl - a_m * a_m / nn
            # numpy goes through degrees and back
            lo = math.radians(math.degrees(lon))
            la = math.radians(math.degrees(lat))
            nx = math.cos(la) * math.cos(lo)
            ny = math.cos(la) * math.sin(lo)
            nz = math.sin(la)
            ux = nx * e[0, 0] + ny * e[1, 0] + nz * e[2, 0]
            uy = nx * e[0, 1] + ny * e[1, 1] + nz * e[2, 1]
            uz = nx * e[0, 2] + ny * e[1, 2] + nz * e[2, 2]
            lx = cx - gx
            ly = cy - gy
            lz = cz - gz
            ln = math.sqrt(lx * lx + ly * ly + lz * lz)
            lx /= ln
            ly /= ln
            lz /= ln
            czen = min(max(lx * ux + ly * uy + lz * uz, 1e-6), 1.0)
            tzen = math.sqrt(1.0 - czen * czen) / czen
            shift = n_refr * scale_h * math.exp(-max(h, -500.0) / scale_h) * tzen / czen**2
            ax_ = -(lx - czen * ux)
            ay_ = -(ly - czen * uy)
            az_ = -(lz - czen * uz)
            an = math.sqrt(ax_ * ax_ + ay_ * ay_ + az_ * az_)
            if an > 0:
                ax_ /= an
                ay_ /= an
                az_ /= an
            else:
                ax_ = 0.0
                ay_ = 0.0
                az_ = 0.0
            tx = gx + shift * ax_
            ty = gy + shift * ay_
            tz = gz + shift * az_
        # the line of sight without the round-off of its 700 km length that varies with t
        dx = (tx - fcx) - mcx
        dy = (ty - fcy) - mcy
        dz = (tz - fcz) - mcz
        if aberration:
            rho = math.sqrt(dx * dx + dy * dy + dz * dz)
            # velocity in ENU (v @ E) plus omega x (centre - ground)
            wx = vx * e[0, 0] + vy * e[1, 0] + vz * e[2, 0]
            wy = vx * e[0, 1] + vy * e[1, 1] + vz * e[2, 1]
            wz = vx * e[0, 2] + vy * e[1, 2] + vz * e[2, 2]
            rx = cx - gx
            ry = cy - gy
            rz = cz - gz
            wx += omega_enu[1] * rz - omega_enu[2] * ry
            wy += omega_enu[2] * rx - omega_enu[0] * rz
            wz += omega_enu[0] * ry - omega_enu[1] * rx
            dx = dx / rho + wx / c_light
            dy = dy / rho + wy / c_light
            dz = dz / rho + wz / c_light
        # ---- into the sensor frame: v = R^T d with R = E^T Q S (sensor -> ENU)
        fx = e[0, 0] * dx + e[0, 1] * dy + e[0, 2] * dz  # E d (ECEF)
        fy = e[1, 0] * dx + e[1, 1] * dy + e[1, 2] * dz
        fz = e[2, 0] * dx + e[2, 1] * dy + e[2, 2] * dz
        bx_ = q00 * fx + q10 * fy + q20 * fz  # Q^T (body)
        by_ = q01 * fx + q11 * fy + q21 * fz
        bz_ = q02 * fx + q12 * fy + q22 * fz
        v0 = s2b[0, 0] * bx_ + s2b[1, 0] * by_ + s2b[2, 0] * bz_  # S^T (sensor)
        v1 = s2b[0, 1] * bx_ + s2b[1, 1] * by_ + s2b[2, 1] * bz_
        v2 = s2b[0, 2] * bx_ + s2b[1, 2] * by_ + s2b[2, 2] * bz_
        scale = -focal / v2
        out_x[i] = v0 * scale
        out_y[i] = v1 * scale


_focal_plane_parallel = kernel(parallel=True, nogil=True)(_focal_plane_loop)
_focal_plane_serial = kernel(nogil=True)(serial_twin(_focal_plane_loop))


def pack_exterior(scene: Any, refractivity: float, scale_height_m: float, c_light: float) -> tuple:
    """The arguments of the compiled loop for a :class:`~explorer.real.linescan.RigorousLineScanScene` (its tables,
    frame and options; the constants of its refraction and aberration), after ``ground`` and ``t``."""
    ex = scene.exterior
    eph, att = ex.ephemeris, ex.attitude
    frame = scene.frame
    body = frame.body
    offset = np.ascontiguousarray(ex.centre_offset_body_m, dtype=np.float64)
    return (
        np.ascontiguousarray(eph.time_s, dtype=np.float64), np.ascontiguousarray(eph.position_m, dtype=np.float64),
        np.ascontiguousarray(eph.velocity_m_s, dtype=np.float64), int(eph.order),
        np.ascontiguousarray(att.time_s, dtype=np.float64), np.ascontiguousarray(att.quaternion, dtype=np.float64),
        ATTITUDE_LAGRANGE if att.method == "lagrange" else ATTITUDE_SLERP, int(att.order),
        np.ascontiguousarray(ex.sensor_to_body, dtype=np.float64), offset, bool(np.any(offset)),
        np.ascontiguousarray(frame.enu_to_ecef_rotation, dtype=np.float64),
        np.ascontiguousarray(frame.origin_ecef, dtype=np.float64), float(scene.interior.focal_length_m),
        bool(scene.aberration), bool(scene.refraction), np.ascontiguousarray(scene._omega_enu(), dtype=np.float64),
        np.array([body.a_m, body.b_m, body.e2, refractivity, scale_height_m, c_light], dtype=np.float64),
    )


def _writable(a: np.ndarray) -> np.ndarray:
    """A C-contiguous, writable float64 array (numba compiles read-only arrays as another signature)."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    return a if a.flags.writeable else a.copy()


def ideal_focal_plane(packed: tuple, ground: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ideal focal-plane coordinates (x, y), each (N,) metres, of ground points (N, 3) local ENU metres seen at
    scanline times (N,) seconds, for the model packed by :func:`pack_exterior` (before the lens distortion)."""
    ground = _writable(ground)
    n = ground.shape[0]
    t = np.asarray(t, dtype=np.float64)
    t = _writable(t) if t.shape == (n,) else np.broadcast_to(t, (n,)).copy()
    x = np.empty(n)
    y = np.empty(n)
    if n:
        loop = _focal_plane_parallel if n >= PARALLEL_MIN_POINTS else _focal_plane_serial
        loop(ground, t, *packed, x, y)
    return x, y
