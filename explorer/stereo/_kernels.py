"""Compiled per-point kernels of the stereo package (numba through :func:`explorer._numba.kernel`).

* :func:`closest_approach` -- two families of straight lines, the midpoint and distance of their closest
  approach and the sine of their angle (``prange`` over points).
* :func:`solve_normal_3` -- one Gauss-Newton step ``(J^T J)^-1 J^T e`` of 4 residuals in 3 unknowns per point.
* :func:`rpc_pair_triangulate` -- the whole triangulation of an RPC pair per point: exact localisation of each
  pixel at two heights (Newton on the RPC00B projection), the rays' closest approach in WGS84 ECEF, Gauss-Newton on
  (lon, lat, h) with the analytic Jacobian of both projections until the reprojection is exact, and the distance
  of the two lines of sight (their tangents at the solution's height).
* :func:`rpc_localise` -- exact RPC localisation (image + ellipsoidal height -> lon, lat) per point.

Without numba the same functions run interpreted (slowly): :func:`explorer._numba.kernel`.
"""

from __future__ import annotations

import math

import numpy as np

from explorer._numba import kernel, prange, serial_twin

_A = 6378137.0
_F = 1.0 / 298.257223563
_E2 = _F * (2.0 - _F)
_B = _A * (1.0 - _F)

# flag bits (explorer.stereo.triangulation documents them)
OUTSIDE_LEFT = 1
OUTSIDE_RIGHT = 2
PARALLEL = 4
BEHIND = 8
NOT_CONVERGED = 16
OUTSIDE_DOMAIN = 32


@kernel()
def _poly(c, x, y, z):
    """RPC00B cubic (file order) and its gradient in (x = L, y = P, z = H)."""
    v = (c[0] + c[1] * x + c[2] * y + c[3] * z + c[4] * x * y + c[5] * x * z + c[6] * y * z + c[7] * x * x
         + c[8] * y * y + c[9] * z * z + c[10] * x * y * z + c[11] * x * x * x + c[12] * x * y * y
         + c[13] * x * z * z + c[14] * x * x * y + c[15] * y * y * y + c[16] * y * z * z + c[17] * x * x * z
         + c[18] * y * y * z + c[19] * z * z * z)
    dx = (c[1] + c[4] * y + c[5] * z + 2.0 * c[7] * x + c[10] * y * z + 3.0 * c[11] * x * x + c[12] * y * y
          + c[13] * z * z + 2.0 * c[14] * x * y + 2.0 * c[17] * x * z)
    dy = (c[2] + c[4] * x + c[6] * z + 2.0 * c[8] * y + c[10] * x * z + 2.0 * c[12] * x * y + c[14] * x * x
          + 3.0 * c[15] * y * y + c[16] * z * z + 2.0 * c[18] * y * z)
    dz = (c[3] + c[5] * x + c[6] * y + 2.0 * c[9] * z + c[10] * x * y + 2.0 * c[13] * x * z + 2.0 * c[16] * y * z
          + c[17] * x * x + c[18] * y * y + 3.0 * c[19] * z * z)
    return v, dx, dy, dz


@kernel()
def _project_grad(coef, norm, lon, lat, h):
    """(row, col) of (lon, lat, h) and their derivatives per degree (lon, lat) and per metre (h).

    ``coef`` (4, 20): row_num, row_den, col_num, col_den; ``norm`` (10,): lon_off, lon_scale, lat_off, lat_scale,
    h_off, h_scale, row_off, row_scale, col_off, col_scale.
    """
    x = (lon - norm[0]) / norm[1]
    y = (lat - norm[2]) / norm[3]
    z = (h - norm[4]) / norm[5]
    rn, rnx, rny, rnz = _poly(coef[0], x, y, z)
    rd, rdx, rdy, rdz = _poly(coef[1], x, y, z)
    cn, cnx, cny, cnz = _poly(coef[2], x, y, z)
    cd, cdx, cdy, cdz = _poly(coef[3], x, y, z)
    rs = norm[7]
    cs = norm[9]
    row = rn / rd * rs + norm[6]
    col = cn / cd * cs + norm[8]
    r2 = rd * rd
    c2 = cd * cd
    r_lon = (rnx * rd - rn * rdx) / r2 * rs / norm[1]
    r_lat = (rny * rd - rn * rdy) / r2 * rs / norm[3]
    r_h = (rnz * rd - rn * rdz) / r2 * rs / norm[5]
    c_lon = (cnx * cd - cn * cdx) / c2 * cs / norm[1]
    c_lat = (cny * cd - cn * cdy) / c2 * cs / norm[3]
    c_h = (cnz * cd - cn * cdz) / c2 * cs / norm[5]
    return row, col, r_lon, r_lat, r_h, c_lon, c_lat, c_h


@kernel()
def _localise(coef, norm, row, col, h, lon0, lat0, max_iter):
    """Exact localisation of one pixel at ellipsoidal height ``h``: Newton on (lon, lat) from (lon0, lat0).

    Returns (lon, lat, ok); ok when the last step is below 1e-13 of the lon/lat scale and the pixel residual
    below 1e-7 px.
    """
    lon = lon0
    lat = lat0
    tol_lon = 1e-13 * abs(norm[1])
    tol_lat = 1e-13 * abs(norm[3])
    for _ in range(max_iter):
        r, c, r_lon, r_lat, _r_h, c_lon, c_lat, _c_h = _project_grad(coef, norm, lon, lat, h)
        er = row - r
        ec = col - c
        det = r_lon * c_lat - r_lat * c_lon
        if det == 0.0 or not math.isfinite(det):
            return math.nan, math.nan, False
        dlon = (c_lat * er - r_lat * ec) / det
        dlat = (-c_lon * er + r_lon * ec) / det
        lon += dlon
        lat += dlat
        if not (math.isfinite(lon) and math.isfinite(lat)):
            return math.nan, math.nan, False
        if abs(dlon) <= tol_lon and abs(dlat) <= tol_lat:
            r, c, _a, _b, _c, _d, _e, _f = _project_grad(coef, norm, lon, lat, h)
            if abs(r - row) <= 1e-7 and abs(c - col) <= 1e-7:
                return lon, lat, True
            return lon, lat, False
    return lon, lat, False


@kernel()
def _to_ecef(lon_deg, lat_deg, h):
    lon = math.radians(lon_deg)
    lat = math.radians(lat_deg)
    sl = math.sin(lat)
    cl = math.cos(lat)
    n = _A / math.sqrt(1.0 - _E2 * sl * sl)
    return (n + h) * cl * math.cos(lon), (n + h) * cl * math.sin(lon), (n * (1.0 - _E2) + h) * sl


@kernel()
def _to_geodetic(x, y, z):
    """WGS84 ECEF -> (lon_deg, lat_deg, h): the operations of :func:`explorer.geometry.frames.ecef_to_geodetic`."""
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    ep2 = _E2 / (1.0 - _E2)
    theta = math.atan2(z * _A, p * _B)
    lat = math.atan2(z + ep2 * _B * math.sin(theta) ** 3, p - _E2 * _A * math.cos(theta) ** 3)
    for _ in range(5):
        sl = math.sin(lat)
        n = _A / math.sqrt(1.0 - _E2 * sl * sl)
        lat = math.atan2(z + _E2 * n * sl, p)
    sl = math.sin(lat)
    cl = math.cos(lat)
    n = _A / math.sqrt(1.0 - _E2 * sl * sl)
    h = p * cl + z * sl - _A * _A / n
    return math.degrees(lon), math.degrees(lat), h


@kernel()
def _closest(px, py, pz, ux, uy, uz, qx, qy, qz, vx, vy, vz):
    """Closest approach of lines p + s u and q + t v: (mid x, y, z, distance, sin^2 of the angle, s, t)."""
    wx = px - qx
    wy = py - qy
    wz = pz - qz
    a = ux * ux + uy * uy + uz * uz
    b = ux * vx + uy * vy + uz * vz
    c = vx * vx + vy * vy + vz * vz
    d = ux * wx + uy * wy + uz * wz
    e = vx * wx + vy * wy + vz * wz
    den = a * c - b * b
    sin2 = den / (a * c) if a * c > 0.0 else 0.0
    if den <= 0.0:
        return math.nan, math.nan, math.nan, math.nan, 0.0, math.nan, math.nan
    s = (b * e - c * d) / den
    t = (a * e - b * d) / den
    ax = px + s * ux
    ay = py + s * uy
    az = pz + s * uz
    bx = qx + t * vx
    by = qy + t * vy
    bz = qz + t * vz
    dist = math.sqrt((ax - bx) ** 2 + (ay - by) ** 2 + (az - bz) ** 2)
    return 0.5 * (ax + bx), 0.5 * (ay + by), 0.5 * (az + bz), dist, sin2, s, t


def _closest_approach_py(p, u, q, v):
    """Lines ``p + s u`` and ``q + t v`` (each (N, 3)) -> midpoint (N, 3), distance (N,), sin^2 angle (N,),
    s (N,), t (N,)."""
    n = p.shape[0]
    mid = np.empty((n, 3))
    dist = np.empty(n)
    sin2 = np.empty(n)
    s = np.empty(n)
    t = np.empty(n)
    for i in prange(n):
        mx, my, mz, d, s2, si, ti = _closest(p[i, 0], p[i, 1], p[i, 2], u[i, 0], u[i, 1], u[i, 2],
                                             q[i, 0], q[i, 1], q[i, 2], v[i, 0], v[i, 1], v[i, 2])
        mid[i, 0] = mx
        mid[i, 1] = my
        mid[i, 2] = mz
        dist[i] = d
        sin2[i] = s2
        s[i] = si
        t[i] = ti
    return mid, dist, sin2, s, t


@kernel()
def _solve3(a00, a01, a02, a11, a12, a22, b0, b1, b2):
    """Solve the symmetric 3 x 3 system by Cramer's rule (NaN when singular)."""
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    if det == 0.0 or not math.isfinite(det):
        return math.nan, math.nan, math.nan
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    x0 = (c00 * b0 + c01 * b1 + c02 * b2) / det
    x1 = (c01 * b0 + c11 * b1 + c12 * b2) / det
    x2 = (c02 * b0 + c12 * b1 + c22 * b2) / det
    return x0, x1, x2


def _solve_normal_3_py(jac, res):
    """Gauss-Newton steps: ``jac`` (N, 4, 3), ``res`` (N, 4) -> the least-squares step (N, 3) of each point."""
    n = jac.shape[0]
    out = np.empty((n, 3))
    for i in prange(n):
        a00 = 0.0
        a01 = 0.0
        a02 = 0.0
        a11 = 0.0
        a12 = 0.0
        a22 = 0.0
        b0 = 0.0
        b1 = 0.0
        b2 = 0.0
        for k in range(jac.shape[1]):
            j0 = jac[i, k, 0]
            j1 = jac[i, k, 1]
            j2 = jac[i, k, 2]
            e = res[i, k]
            a00 += j0 * j0
            a01 += j0 * j1
            a02 += j0 * j2
            a11 += j1 * j1
            a12 += j1 * j2
            a22 += j2 * j2
            b0 += j0 * e
            b1 += j1 * e
            b2 += j2 * e
        out[i, 0], out[i, 1], out[i, 2] = _solve3(a00, a01, a02, a11, a12, a22, b0, b1, b2)
    return out


def _rpc_localise_py(coef, norm, row, col, h, max_iter):
    """Exact localisation of pixels (N,) at ellipsoidal heights (N,) -> lon (N,), lat (N,), ok (N,)."""
    n = row.shape[0]
    lon = np.empty(n)
    lat = np.empty(n)
    ok = np.empty(n, dtype=np.bool_)
    for i in prange(n):
        lo, la, good = _localise(coef, norm, row[i], col[i], h[i], norm[0], norm[2], max_iter)
        lon[i] = lo if good else math.nan
        lat[i] = la if good else math.nan
        ok[i] = good
    return lon, lat, ok


@kernel()
def _ray_ecef(coef, norm, row, col, h0, h1, lon0, lat0, max_iter):
    """Points of one pixel's line of sight at heights h0 and h1, ECEF; ok flag."""
    lo0, la0, ok0 = _localise(coef, norm, row, col, h0, lon0, lat0, max_iter)
    lo1, la1, ok1 = _localise(coef, norm, row, col, h1, lo0 if ok0 else lon0, la0 if ok0 else lat0, max_iter)
    x0, y0, z0 = _to_ecef(lo0, la0, h0)
    x1, y1, z1 = _to_ecef(lo1, la1, h1)
    return x0, y0, z0, x1 - x0, y1 - y0, z1 - z0, ok0 and ok1


def _rpc_pair_triangulate_py(coef_l, norm_l, coef_r, norm_r, lrow, lcol, rrow, rcol, h0, h1, min_sin2, max_iter,
                         tol_m, tangent_dh, out_geo, out_ecef, out_ray, out_rep, out_flags):
    """Triangulate matches of an RPC pair (see the module docstring); outputs are filled in place.

    ``out_geo`` (N, 3) lon, lat, h; ``out_ecef`` (N, 3); ``out_ray`` (N,) distance of the lines of sight, m;
    ``out_rep`` (N, 2) reprojection error per image, px; ``out_flags`` (N,) uint8 bits (``NOT_CONVERGED``,
    ``PARALLEL``; the caller adds the image and domain bits).
    """
    n = lrow.shape[0]
    for i in prange(n):
        flags = 0
        pxl, pyl, pzl, uxl, uyl, uzl, okl = _ray_ecef(coef_l, norm_l, lrow[i], lcol[i], h0, h1, norm_l[0], norm_l[2],
                                                      max_iter)
        pxr, pyr, pzr, uxr, uyr, uzr, okr = _ray_ecef(coef_r, norm_r, rrow[i], rcol[i], h0, h1, norm_r[0], norm_r[2],
                                                      max_iter)
        if not (okl and okr):
            out_flags[i] = NOT_CONVERGED
            for k in range(3):
                out_geo[i, k] = math.nan
                out_ecef[i, k] = math.nan
            out_ray[i] = math.nan
            out_rep[i, 0] = math.nan
            out_rep[i, 1] = math.nan
            continue
        mx, my, mz, _d, sin2, _s, _t = _closest(pxl, pyl, pzl, uxl, uyl, uzl, pxr, pyr, pzr, uxr, uyr, uzr)
        if not (sin2 >= min_sin2) or not math.isfinite(mx):
            out_flags[i] = PARALLEL
            for k in range(3):
                out_geo[i, k] = math.nan
                out_ecef[i, k] = math.nan
            out_ray[i] = math.nan
            out_rep[i, 0] = math.nan
            out_rep[i, 1] = math.nan
            continue
        lon, lat, h = _to_geodetic(mx, my, mz)
        converged = False
        for _ in range(max_iter):
            rl, cl, rl_lo, rl_la, rl_h, cl_lo, cl_la, cl_h = _project_grad(coef_l, norm_l, lon, lat, h)
            rr, cr, rr_lo, rr_la, rr_h, cr_lo, cr_la, cr_h = _project_grad(coef_r, norm_r, lon, lat, h)
            # metres east / north per degree at the current point
            sl = math.sin(math.radians(lat))
            w = math.sqrt(1.0 - _E2 * sl * sl)
            m_lon = math.radians(1.0) * (_A / w + h) * math.cos(math.radians(lat))
            m_lat = math.radians(1.0) * (_A * (1.0 - _E2) / (w * w * w) + h)
            e0 = lrow[i] - rl
            e1 = lcol[i] - cl
            e2 = rrow[i] - rr
            e3 = rcol[i] - cr
            j00 = rl_lo / m_lon
            j01 = rl_la / m_lat
            j10 = cl_lo / m_lon
            j11 = cl_la / m_lat
            j20 = rr_lo / m_lon
            j21 = rr_la / m_lat
            j30 = cr_lo / m_lon
            j31 = cr_la / m_lat
            de, dn, du = _solve3(
                j00 * j00 + j10 * j10 + j20 * j20 + j30 * j30,
                j00 * j01 + j10 * j11 + j20 * j21 + j30 * j31,
                j00 * rl_h + j10 * cl_h + j20 * rr_h + j30 * cr_h,
                j01 * j01 + j11 * j11 + j21 * j21 + j31 * j31,
                j01 * rl_h + j11 * cl_h + j21 * rr_h + j31 * cr_h,
                rl_h * rl_h + cl_h * cl_h + rr_h * rr_h + cr_h * cr_h,
                j00 * e0 + j10 * e1 + j20 * e2 + j30 * e3,
                j01 * e0 + j11 * e1 + j21 * e2 + j31 * e3,
                rl_h * e0 + cl_h * e1 + rr_h * e2 + cr_h * e3,
            )
            if not (math.isfinite(de) and math.isfinite(dn) and math.isfinite(du)):
                break
            lon += de / m_lon
            lat += dn / m_lat
            h += du
            if math.sqrt(de * de + dn * dn + du * du) <= tol_m:
                converged = True
                break
        if not converged:
            flags |= NOT_CONVERGED
        rl, cl, _a, _b, _c, _d2, _e, _f = _project_grad(coef_l, norm_l, lon, lat, h)
        rr, cr, _a, _b, _c, _d2, _e, _f = _project_grad(coef_r, norm_r, lon, lat, h)
        out_rep[i, 0] = math.hypot(rl - lrow[i], cl - lcol[i])
        out_rep[i, 1] = math.hypot(rr - rrow[i], cr - rcol[i])
        x, y, z = _to_ecef(lon, lat, h)
        out_geo[i, 0] = lon
        out_geo[i, 1] = lat
        out_geo[i, 2] = h
        out_ecef[i, 0] = x
        out_ecef[i, 1] = y
        out_ecef[i, 2] = z
        # the lines of sight near the solution: tangents through their points at h and h + tangent_dh
        pxl, pyl, pzl, uxl, uyl, uzl, okl = _ray_ecef(coef_l, norm_l, lrow[i], lcol[i], h, h + tangent_dh, lon, lat,
                                                      max_iter)
        pxr, pyr, pzr, uxr, uyr, uzr, okr = _ray_ecef(coef_r, norm_r, rrow[i], rcol[i], h, h + tangent_dh, lon, lat,
                                                      max_iter)
        if okl and okr:
            _mx, _my, _mz, dist, _s2, _s, _t = _closest(pxl, pyl, pzl, uxl, uyl, uzl, pxr, pyr, pzr, uxr, uyr, uzr)
            out_ray[i] = dist
        else:
            out_ray[i] = math.nan
            flags |= NOT_CONVERGED
        out_flags[i] = flags


#: Below this many points the serial variant of a kernel runs: waking the second thread of a ``prange`` loop
#: costs milliseconds on a busy 2-core machine (explorer.rpc._kernels.PARALLEL_MIN_POINTS measured it).
PARALLEL_MIN_POINTS = 100_000


def _pick(fn):
    """A dispatcher running ``fn`` compiled with ``prange`` (large inputs) or serially (small ones), by the length
    of its first array argument (the package's numba cache keeps one entry per variant, ``serial_twin``)."""
    parallel = kernel(parallel=True)(fn)
    serial = kernel()(serial_twin(fn))

    def run(first, *args):
        return (parallel if first.shape[0] >= PARALLEL_MIN_POINTS else serial)(first, *args)

    run.__name__ = fn.__name__.removeprefix("_").removesuffix("_py")
    run.__doc__ = fn.__doc__
    return run, parallel, serial


closest_approach, _closest_approach_parallel, _closest_approach_serial = _pick(_closest_approach_py)
solve_normal_3, _solve_normal_3_parallel, _solve_normal_3_serial = _pick(_solve_normal_3_py)


def _by_size(parallel, serial, n):
    return parallel if n >= PARALLEL_MIN_POINTS else serial


_rpc_localise_parallel = kernel(parallel=True)(_rpc_localise_py)
_rpc_localise_serial = kernel()(serial_twin(_rpc_localise_py))
_rpc_pair_parallel = kernel(parallel=True)(_rpc_pair_triangulate_py)
_rpc_pair_serial = kernel()(serial_twin(_rpc_pair_triangulate_py))
#: (parallel, serial) variants of each kernel above: the same argument types, two cache entries.
TWINS = ((_closest_approach_parallel, _closest_approach_serial), (_solve_normal_3_parallel, _solve_normal_3_serial),
         (_rpc_localise_parallel, _rpc_localise_serial), (_rpc_pair_parallel, _rpc_pair_serial))


def rpc_localise(coef, norm, row, col, h, max_iter):
    """Exact localisation of pixels (N,) at ellipsoidal heights (N,) -> lon (N,), lat (N,), ok (N,)."""
    return _by_size(_rpc_localise_parallel, _rpc_localise_serial, row.shape[0])(coef, norm, row, col, h, max_iter)


def rpc_pair_triangulate(coef_l, norm_l, coef_r, norm_r, lrow, *args):
    """Triangulate matches of an RPC pair (:func:`_rpc_pair_triangulate_py`), parallel from
    :data:`PARALLEL_MIN_POINTS` matches."""
    return _by_size(_rpc_pair_parallel, _rpc_pair_serial, lrow.shape[0])(coef_l, norm_l, coef_r, norm_r, lrow, *args)
