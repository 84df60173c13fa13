"""Fast, exact image-to-ground for rational function models: at a height, and on a DEM.

At a height
-----------
A cubic polynomial (the 20 RPC00B monomials, no denominator) of the normalised column, row and height
is fitted by least squares to the normalised longitude and latitude of a grid of ground points
projected by the forward RPC (:func:`fit_inverse_polynomial`; fitted once per model and height range,
on the model's own projection -- the file's inverse model, when there is one, is not needed).  It gives a
first guess within about 1e-4 to 1e-2 pixels and, through its derivatives, the inverse Jacobian
``d(lon, lat) / d(col, row)``.  Each iteration then evaluates the forward RPC once and moves the point by
that inverse Jacobian times the pixel residual (a chord Newton iteration: linear convergence with the
relative error of the fitted Jacobian as rate, about 1e-4, so two or three evaluations reach 1e-9 px);
when an iteration does not shrink the residual fourfold the exact Jacobian of the forward RPC is used
instead (Newton).  Converged means a *measured* residual below ``tol_px`` (1e-9 px by default).

On a DEM
--------
The line of sight of a pixel between the DEM's highest and lowest heights is the polynomial's curve
between those heights; its chord is narrowed with the DEM's max/min pyramid and its first cells are solved
in lockstep over a block of points (:func:`_cell_step`); what they do not settle is walked by the
compiled kernel of :mod:`explorer.geometry.dem_intersection` (first intersection, exact per bilinear cell).
From that hit the point is refined on the *exact* RPC line of sight and the bilinear DEM together: each
iteration one forward RPC evaluation (pixel correction as above) and one bilinear lookup (height correction
along the line of sight, Newton on ``h - dem(lon(h), lat(h))``), until the pixel residual is below
``tol_px`` and the height residual below ``tol_m``.  Every point carries a flag
(:data:`~explorer.geometry.dem_intersection.OK`, ``OUTSIDE_DEM``, ``NODATA``, ``NO_INTERSECTION``,
``NOT_CONVERGED``); lon/lat/h are NaN unless OK.  The loops are serial, released from the GIL and run on
block-aligned parts of the points by :func:`explorer._threads.run_in_parts` (the same bits on any number of
threads).  Design and measurements: ``docs/performance.md#image-to-ground-on-terrain``.

Ground coordinates: longitude/latitude in degrees, heights in metres above the ellipsoid; pixels
0-based, integer = pixel centre (``docs/conventions.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, kernel
from explorer._threads import run_in_parts
from explorer.errors import InputError
from explorer.geometry import dem_intersection as _dem
from explorer.geometry.dem_intersection import NARROW_STEPS, NOT_CONVERGED, OK, HeightGrid
from explorer.rpc._kernels import horner_rpc00b

if TYPE_CHECKING:
    from explorer.rpc.model import RationalFunctionModel

__all__ = ["RPCInverse", "fit_inverse_polynomial"]

#: Fewest points a thread is given (:func:`explorer._threads.run_in_parts`): handing a part to the second
#: thread costs tens of microseconds, 10,000 pixels about 0.7 ms of work.
PARALLEL_MIN_POINTS = 10_000


def _monomials(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    one = np.ones_like(x)
    return np.stack([one, x, y, z, x * y, x * z, y * z, x * x, y * y, z * z, x * y * z, x**3, x * y * y,
                     x * z * z, x * x * y, y**3, y * z * z, x * x * z, y * y * z, z**3], axis=1)


def fit_inverse_polynomial(
    rpc: RationalFunctionModel, h_min: float, h_max: float, *, n_plane: int = 21, n_heights: int = 7
) -> tuple[np.ndarray, float]:
    """Least-squares cubic ``(x, y) = P(col_n, row_n, z_n)`` of the model's normalised coordinates.

    Parameters
    ----------
    rpc : RationalFunctionModel
    h_min, h_max : float
        Height range (metres) the polynomial must serve.
    n_plane, n_heights : int
        Ground grid: ``n_plane x n_plane`` points over the normalisation box at each of ``n_heights``.

    Returns
    -------
    coefficients : ndarray, shape (2, 20)
        Rows: normalised longitude, latitude; RPC00B monomial order of (col_n, row_n, z_n).
    error_px : float
        Largest pixel error of the polynomial's ground point (re-projected) on a validation grid
        offset from the fitting grid.
    """
    def grid(n_p: int, n_h: int, shift: float) -> tuple[np.ndarray, ...]:
        t = np.linspace(-1.0, 1.0, n_p) + shift
        zs = (np.linspace(h_min, h_max, n_h) - rpc.height_offset) / rpc.height_scale
        xg, yg, zg = np.meshgrid(t, t, zs, indexing="ij")
        x, y, z = xg.ravel(), yg.ravel(), zg.ravel()
        rn, cn = rpc.normalized_projection(x, y, z)
        ok = np.isfinite(rn) & np.isfinite(cn) & (np.abs(rn) < 1.5) & (np.abs(cn) < 1.5)
        return x[ok], y[ok], z[ok], rn[ok], cn[ok]

    x, y, z, rn, cn = grid(n_plane, n_heights, 0.0)
    if x.size < 60:
        raise InputError(f"RPC {rpc.source_path or ''}: too few ground points project into the image to fit "
                         "an inverse (normalisation box and image do not overlap)")
    a = _monomials(cn, rn, z)
    coefficients = np.empty((2, 20))
    for k, target in enumerate((x, y)):
        coefficients[k], *_ = np.linalg.lstsq(a, target, rcond=None)
    half = 1.0 / (n_plane - 1)
    xv, yv, zv, rv, cv = grid(n_plane - 1, n_heights, half * 0.5)
    keep = (np.abs(xv) <= 1) & (np.abs(yv) <= 1)
    av = _monomials(cv[keep], rv[keep], zv[keep])
    xp, yp = av @ coefficients[0], av @ coefficients[1]
    r2, c2 = rpc.normalized_projection(xp, yp, zv[keep])
    error = np.hypot((r2 - rv[keep]) * rpc.row_scale, (c2 - cv[keep]) * rpc.col_scale)
    return coefficients, float(np.max(error)) if error.size else math.inf


# ------------------------------------------------------------------------------------------ kernels
@kernel(inline="always")
def _poly_grad(c, x, y, z):
    """Value and d/dx, d/dy, d/dz of an RPC00B cubic (x = first variable)."""
    value = _horner(c, x, y, z)
    d_dx = (c[1] + y * (c[4] + c[10] * z + c[12] * y) + z * (c[5] + c[13] * z)
            + 2.0 * x * (c[7] + c[14] * y + c[17] * z) + 3.0 * c[11] * x * x)
    d_dy = (c[2] + z * (c[6] + c[16] * z) + 2.0 * y * (c[8] + c[18] * z) + 3.0 * c[15] * y * y
            + x * (c[4] + c[10] * z + 2.0 * c[12] * y) + c[14] * x * x)
    d_dz = (c[3] + c[5] * x + c[6] * y + 2.0 * c[9] * z + c[10] * x * y + 2.0 * c[13] * x * z
            + 2.0 * c[16] * y * z + c[17] * x * x + c[18] * y * y + 3.0 * c[19] * z * z)
    return value, d_dx, d_dy, d_dz


@kernel(inline="always")
def _forward(fw0, fw1, fw2, fw3, x, y, z):
    """Normalised (row, col) of normalised ground (x, y, z): row_num, row_den, col_num, col_den."""
    return _horner(fw0, x, y, z) / _horner(fw1, x, y, z), _horner(fw2, x, y, z) / _horner(fw3, x, y, z)


@kernel()
def _exact_inverse_jacobian(fw0, fw1, fw2, fw3, x, y, z):
    """Inverse of d(row_n, col_n)/d(x, y) at (x, y, z): returns (dx/dr, dx/dc, dy/dr, dy/dc)."""
    rn, rn_x, rn_y, _ = _poly_grad(fw0, x, y, z)
    rd, rd_x, rd_y, _ = _poly_grad(fw1, x, y, z)
    cn, cn_x, cn_y, _ = _poly_grad(fw2, x, y, z)
    cd, cd_x, cd_y, _ = _poly_grad(fw3, x, y, z)
    r_x = (rn_x * rd - rn * rd_x) / (rd * rd)
    r_y = (rn_y * rd - rn * rd_y) / (rd * rd)
    c_x = (cn_x * cd - cn * cd_x) / (cd * cd)
    c_y = (cn_y * cd - cn * cd_y) / (cd * cd)
    det = r_x * c_y - r_y * c_x
    return c_y / det, -r_y / det, -c_x / det, r_x / det


@kernel(inline="always")
def _inverse_guess(iv0, iv1, cn, rn, zn):
    """Polynomial guess (x, y), its inverse Jacobian and line-of-sight slope in normalised units.

    Returns ``x, y, dx_dr, dx_dc, dy_dr, dy_dc, dx_dz, dy_dz``.
    """
    x, x_c, x_r, x_z = _poly_grad(iv0, cn, rn, zn)
    y, y_c, y_r, y_z = _poly_grad(iv1, cn, rn, zn)
    return x, y, x_r, x_c, y_r, y_c, x_z, y_z


@kernel(inline="always")
def _correction_cell(corr, cg, cn, rn, zn):
    """Cell of the polynomial's residual grid and the interpolation weights: ``(cell, a, b, w)``.

    ``cell`` is the flat index ``(l * n_r + i) * n_c + j`` of the cell of (col_n, row_n) in height interval
    ``l`` (clamped: outside the grid the nearest cell is used), ``a``, ``b`` the fractions within it, ``w``
    the fraction of the height within the interval.  No memory access, so that a loop over points vectorises.
    """
    n_l = corr.shape[0]
    n_r = corr.shape[1]
    n_c = corr.shape[2]
    fu = (cn - cg[0]) / cg[3]
    fv = (rn - cg[1]) / cg[4]
    fw = (zn - cg[2]) / cg[5]
    fu = fu if fu >= 0.0 else 0.0
    fu = fu if fu <= n_c else float(n_c)
    fv = fv if fv >= 0.0 else 0.0
    fv = fv if fv <= n_r else float(n_r)
    j = min(int(fu), n_c - 1)
    i = min(int(fv), n_r - 1)
    layer = min(int(fw if fw >= 0.0 else 0.0), n_l - 1)
    return (layer * n_r + i) * n_c + j, fu - j, fv - i, fw - layer


@kernel(inline="always")
def _correction_at(cells, cell, a, b, w):
    """Residual of the fitted polynomial: bilinear in (col_n, row_n) over ``cells[cell]``, linear in height.

    ``cells`` has shape (n_cells, 16): per cell (of one height interval), for the longitude then the latitude,
    for the lower then the upper height, the corners (0, 0), (0, 1), (1, 0), (1, 1) -- contiguous, so one cell
    is two cache lines.
    """
    c = cells[cell]
    w00 = (1.0 - a) * (1.0 - b)
    w01 = a * (1.0 - b)
    w10 = (1.0 - a) * b
    w11 = a * b
    lon_lo = w00 * c[0] + w01 * c[1] + w10 * c[2] + w11 * c[3]
    lon_hi = w00 * c[4] + w01 * c[5] + w10 * c[6] + w11 * c[7]
    lat_lo = w00 * c[8] + w01 * c[9] + w10 * c[10] + w11 * c[11]
    lat_hi = w00 * c[12] + w01 * c[13] + w10 * c[14] + w11 * c[15]
    return lon_lo + w * (lon_hi - lon_lo), lat_lo + w * (lat_hi - lat_lo)


@kernel(inline="always")
def _correction(corr, cg, cn, rn, zn):
    """Residual of the fitted polynomial at (col_n, row_n, z_n), interpolated in its grid.

    ``corr`` has shape (n_layers - 1, n_r - 1, n_c - 1, 16) (see :func:`_correction_at`); ``cg`` = (c0, r0,
    z0, dc, dr, dz).  The compiled loops split this into a vectorised pass (:func:`_correction_cell`) and the gathers.
    """
    cell, a, b, w = _correction_cell(corr, cg, cn, rn, zn)
    return _correction_at(corr.reshape(corr.shape[0] * corr.shape[1] * corr.shape[2], 16), cell, a, b, w)


def _correction_cells(residual: np.ndarray) -> np.ndarray:
    """(2, n_z, n_r, n_c) node residuals (component, height layer) -> (n_z - 1, n_r - 1, n_c - 1, 16) blocks."""
    n_z, n_r, n_c = residual.shape[1:]
    cells = np.empty((n_z - 1, n_r - 1, n_c - 1, 16))
    for interval in range(n_z - 1):
        for comp in range(2):
            for upper in range(2):
                grid = residual[comp, interval + upper]
                base = 8 * comp + 4 * upper
                cells[interval, :, :, base] = grid[:-1, :-1]
                cells[interval, :, :, base + 1] = grid[:-1, 1:]
                cells[interval, :, :, base + 2] = grid[1:, :-1]
                cells[interval, :, :, base + 3] = grid[1:, 1:]
    return np.ascontiguousarray(cells)


#: Points per block of the compiled loops: each block runs branch-free passes over its points (which LLVM
#: vectorises), then the scalar walk and the scalar fallback for the few points the passes did not settle.
BLOCK = 512

#: Cells of a narrowed line of sight solved in lockstep over a block before the scalar walk takes the rest.
CELL_STEPS = 3

#: Nodes per side of the correction grid of the fitted polynomial.
CORRECTION_NODES = 65

#: Height layers of the correction grid (linear between neighbouring layers): the residual of the cubic is
#: curved in height (two layers left 1e-3 px on the Pleiades 2017 model, and a third pass for half its points).
CORRECTION_LAYERS = 5

#: At most this many vectorised passes (forward RPC, verification, a chord step for the points not yet
#: converged); the passes stop as soon as at most an eighth of a block is left, which the scalar loop finishes.
MAX_PASSES = 4


@kernel(inline="always")
def _start(iv0, iv1, corr, cg, cn, rn, zn):
    """Polynomial guess plus its interpolated residual: ``x, y, dx_dr, dx_dc, dy_dr, dy_dc, dx_dz, dy_dz``."""
    x, y, m_xr, m_xc, m_yr, m_yc, x_z, y_z = _inverse_guess(iv0, iv1, cn, rn, zn)
    cx, cy = _correction(corr, cg, cn, rn, zn)
    return x + cx, y + cy, m_xr, m_xc, m_yr, m_yc, x_z, y_z


@kernel(inline="always")
def _pixel_residual(fw0, fw1, fw2, fw3, x, y, zn, rn, cn, row_sc, col_sc):
    """Normalised residual (row, col) of ground (x, y, zn) against pixel (rn, cn), and its size in pixels."""
    rr, cc = _forward(fw0, fw1, fw2, fw3, x, y, zn)
    er = rn - rr
    ec = cn - cc
    return er, ec, math.sqrt((er * row_sc) ** 2 + (ec * col_sc) ** 2)  # not hypot: a libm call, not vectorised


@kernel()
def _refine_at_height(fw0, fw1, fw2, fw3, norm, rn, cn, zn, x, y, m_xr, m_xc, m_yr, m_yc, tol_px, max_iter):
    """Scalar refinement of one point at a fixed normalised height from (x, y): ``(x, y, converged)``.

    Chord steps with the given inverse Jacobian; when a step does not shrink the residual fourfold, the exact
    inverse Jacobian of the forward RPC (Newton).
    """
    prev = math.inf
    for _it in range(max_iter):
        er, ec, err = _pixel_residual(fw0, fw1, fw2, fw3, x, y, zn, rn, cn, norm[7], norm[9])
        if not (err < 1e300):
            return x, y, False
        if err <= tol_px:
            return x, y, True
        if err > 0.25 * prev:  # the fitted Jacobian does not contract here: exact Newton
            m_xr, m_xc, m_yr, m_yc = _exact_inverse_jacobian(fw0, fw1, fw2, fw3, x, y, zn)
        prev = err
        x += m_xr * er + m_xc * ec
        y += m_yr * er + m_yc * ec
    return x, y, False


@kernel(inline="always")
def _block_scratch(b, n, rows):
    """Block ``b`` of ``n`` points: its first point, its size, ``rows`` rows of float scratch and a cell index row."""
    i0 = b * BLOCK
    m = min(n, i0 + BLOCK) - i0
    return i0, m, np.empty((rows, m)), np.empty(m, np.int64)


@kernel(nogil=True)
def _localize_blocks(fw0, fw1, fw2, fw3, iv0, iv1, corr, cg, norm, row, col, h, tol_px, max_iter, lon_out, lat_out,
                        flag_out):
    lon_off, lon_sc, lat_off, lat_sc, h_off, h_sc, row_off, row_sc, col_off, col_sc = norm
    tol2 = tol_px * tol_px
    cells = corr.reshape(corr.shape[0] * corr.shape[1] * corr.shape[2], 16)
    n = row.shape[0]
    n_blocks = (n + BLOCK - 1) // BLOCK
    for b in range(n_blocks):
        i0, m, sc, cell = _block_scratch(b, n, 7)
        x = lon_out[i0:i0 + m]
        y = lat_out[i0:i0 + m]
        for k in range(m):  # the polynomial's guess, inverse Jacobian and residual cell (vectorised)
            rn = (row[i0 + k] - row_off) / row_sc
            cn = (col[i0 + k] - col_off) / col_sc
            zn = (h[i0 + k] - h_off) / h_sc
            x[k], y[k], sc[0, k], sc[1, k], sc[2, k], sc[3, k], _e, _f = _inverse_guess(iv0, iv1, cn, rn, zn)
            cell[k], sc[4, k], sc[5, k], sc[6, k] = _correction_cell(corr, cg, cn, rn, zn)
        for k in range(m):  # the polynomial's residual (gathers: a loop of its own)
            cx, cy = _correction_at(cells, cell[k], sc[4, k], sc[5, k], sc[6, k])
            x[k] += cx
            y[k] += cy
        for _p in range(MAX_PASSES):  # measure, keep the converged, a chord step for the others
            n_open = 0
            for k in range(m):  # the forward RPC and the verification (vectorised; an integer count)
                rr, cc = _forward(fw0, fw1, fw2, fw3, x[k], y[k], (h[i0 + k] - h_off) / h_sc)
                er = (row[i0 + k] - row_off) / row_sc - rr
                ec = (col[i0 + k] - col_off) / col_sc - cc
                good = (er * row_sc) ** 2 + (ec * col_sc) ** 2 <= tol2
                sc[4, k] = 0.0 if good else 1.0
                sc[5, k] = er
                sc[6, k] = ec
                n_open += 0 if good else 1
            if 8 * n_open <= m:
                break
            for k in range(m):  # the chord step (vectorised)
                step = sc[4, k] != 0.0
                x[k] += sc[0, k] * sc[5, k] + sc[1, k] * sc[6, k] if step else 0.0
                y[k] += sc[2, k] * sc[5, k] + sc[3, k] * sc[6, k] if step else 0.0
        for k in range(m):  # scalar loop for the points the passes left, then degrees
            flag_out[i0 + k] = OK
            if sc[4, k] != 0.0:
                rn = (row[i0 + k] - row_off) / row_sc
                cn = (col[i0 + k] - col_off) / col_sc
                zn = (h[i0 + k] - h_off) / h_sc
                xs, ys, conv = _refine_at_height(fw0, fw1, fw2, fw3, norm, rn, cn, zn, x[k], y[k], sc[0, k],
                                                 sc[1, k], sc[2, k], sc[3, k], tol_px, max_iter)
                if not conv and not (math.isfinite(x[k]) and math.isfinite(y[k])):  # lost: again from the guess
                    xg, yg, a, bb, c, d, _e, _f = _start(iv0, iv1, corr, cg, cn, rn, zn)
                    xs, ys, conv = _refine_at_height(fw0, fw1, fw2, fw3, norm, rn, cn, zn, xg, yg, a, bb, c, d,
                                                     tol_px, max_iter)
                x[k] = xs if conv else math.nan
                y[k] = ys if conv else math.nan
                flag_out[i0 + k] = OK if conv else NOT_CONVERGED
            x[k] = x[k] * lon_sc + lon_off
            y[k] = y[k] * lat_sc + lat_off


@kernel(inline="always")
def _cell_step(h00, h01, h10, h11, j, i, ua, va, za, du, dv, dz, sa, sb, top_j, top_i):
    """One cell of a narrowed segment: ``(s, flag, s_next, j_next, i_next)`` (all floats; flag 0.0 is OK).

    The segment (grid coordinates, parameter s) starts at (ua, va, za) and moves by (du, dv, dz) per unit of
    s; the part [sa, sb] holds its first hit (:func:`explorer.geometry.dem_intersection.narrow_step`) and
    enters cell (i, j) (corner heights h00 (i, j), h01 (i, j+1), h10, h11) at sa.  Over the cell the
    bilinear patch along the segment is a quadratic f(s) = z(s) - h(s).  f(sa) <= 0: a hit at sa (flag OK);
    f(sa) > 0 >= f(se) at the cell's exit se: exactly one root there, approached by the secant and one Newton
    step (flag OK; no square root, the refinement that follows is exact); a no-data corner, or a dip below
    the surface and back up inside the cell, or the end sb reached: flag -1 (the exact walk decides);
    otherwise flag -2 and the next cell, entered at ``s_next``.  Branch-free, so that a loop over points
    vectorises.
    """
    cu = _exit_param(ua, du, j, 1.0)
    cv = _exit_param(va, dv, i, 1.0)
    se = min(min(cu, cv), sb)
    se = se if se > sa else sa
    c0, c1, c2 = _patch_quadratic(h00, h01, h10, h11, i, j, ua, va, za, du, dv, dz)
    fa = c0 + sa * (c1 + sa * c2)
    fe = c0 + se * (c1 + se * c2)
    s = sa + (se - sa) * fa / (fa - fe)
    ds = c1 + 2.0 * c2 * s
    s2 = s - (c0 + s * (c1 + s * c2)) / ds
    s = s2 if (s2 >= sa) & (s2 <= se) else s
    s = s if fa > 0.0 else sa
    sv = -c1 / (2.0 * c2)
    dip = (c2 > 0.0) & (sv > sa) & (sv < se) & (c0 + sv * (c1 + sv * c2) <= 0.0)
    hole = math.isnan(h00) | math.isnan(h01) | math.isnan(h10) | math.isnan(h11)
    hit = (fa <= 0.0) | (fe <= 0.0)
    flag = -1.0 if hole | (dip & ~hit) | (~hit & (se >= sb)) else (0.0 if hit else -2.0)
    step_u = cu < cv
    j_next = j + (1.0 if du > 0.0 else -1.0) if step_u else j
    i_next = i if step_u else i + (1.0 if dv > 0.0 else -1.0)
    j_next = min(max(j_next, 0.0), top_j)
    i_next = min(max(i_next, 0.0), top_i)
    return s, flag, se, j_next, i_next


@kernel(inline="always")
def _clamp_index(u, top):
    """Cell index of fractional node coordinate u, clamped to [0, top] (NaN -> 0); branch-free selects."""
    uc = u if u >= 0.0 else 0.0
    uc = uc if uc <= top else top
    return int(uc)


@kernel()
def _refine_on_dem(fw0, fw1, fw2, fw3, norm, hgt, ux, u0, vy, v0, rn, cn, x, y, zn, m_xr, m_xc, m_yr, m_yc, x_z,
                      y_z, tol_px, tol_m, max_iter):
    """Scalar refinement of one point on the line of sight and the DEM from (x, y, zn): ``(x, y, zn, flag)``.

    Each iteration: the pixel step of :func:`_refine_at_height` and a Newton step on the height along the
    line of sight (slopes ``x_z``, ``y_z``) against the bilinear DEM.
    """
    h_off = norm[4]
    h_sc = norm[5]
    prev = math.inf
    for _it in range(max_iter):
        er, ec, err = _pixel_residual(fw0, fw1, fw2, fw3, x, y, zn, rn, cn, norm[7], norm[9])
        hd, hu, hv, fl = _bilinear(hgt, ux * x + u0, vy * y + v0)
        if fl != OK:
            return x, y, zn, fl
        g = zn * h_sc + h_off - hd
        if not (err < 1e300) or not (abs(g) < 1e300):
            return x, y, zn, NOT_CONVERGED
        if err <= tol_px and abs(g) <= tol_m:
            return x, y, zn, OK
        if err > 0.25 * prev and err > tol_px:
            m_xr, m_xc, m_yr, m_yc = _exact_inverse_jacobian(fw0, fw1, fw2, fw3, x, y, zn)
        prev = err
        dx = m_xr * er + m_xc * ec
        dy = m_yr * er + m_yc * ec
        x += dx
        y += dy
        g -= hu * ux * dx + hv * vy * dy
        slope = h_sc - (hu * ux * x_z + hv * vy * y_z)
        if slope == 0.0:
            return x, y, zn, NOT_CONVERGED
        dz = -g / slope
        zn += dz
        x += x_z * dz
        y += y_z * dz
    return x, y, zn, NOT_CONVERGED


@kernel(nogil=True)
def _dem_blocks(fw0, fw1, fw2, fw3, iv0, iv1, corr, cg, norm, hgt, bounds, gx0, gy0, gdx, gdy, z_top, z_bot,
                   row, col, tol_px, tol_m, max_iter, lon_out, lat_out, h_out, flag_out):
    lon_off, lon_sc, lat_off, lat_sc, h_off, h_sc, row_off, row_sc, col_off, col_sc = norm
    zn_top = (z_top - h_off) / h_sc
    zn_bot = (z_bot - h_off) / h_sc
    # grid coordinates of normalised ground: u = ux * x + u0, v = vy * y + v0
    ux = lon_sc / gdx
    u0 = (lon_off - gx0) / gdx
    vy = lat_sc / gdy
    v0 = (lat_off - gy0) / gdy
    top_j = hgt.shape[1] - 2.0
    top_i = hgt.shape[0] - 2.0
    zn_mid = 0.5 * (zn_top + zn_bot)
    tol2 = tol_px * tol_px
    tile_max, bound_hi, bound_lo, levels = bounds
    n_cu = hgt.shape[1] - 1
    n_cv = hgt.shape[0] - 1
    dz_chord = z_bot - z_top
    cells = corr.reshape(corr.shape[0] * corr.shape[1] * corr.shape[2], 16)
    n = row.shape[0]
    n_blocks = (n + BLOCK - 1) // BLOCK
    for b in range(n_blocks):
        i0, m, sc, cell = _block_scratch(b, n, 16)
        x, y, zn = lon_out[i0:i0 + m], lat_out[i0:i0 + m], h_out[i0:i0 + m]
        for k in range(m):  # the chord: the polynomial's line of sight at the top and bottom heights (vectorised)
            rn = (row[i0 + k] - row_off) / row_sc
            cn = (col[i0 + k] - col_off) / col_sc
            sc[10, k] = ux * _horner(iv0, cn, rn, zn_top) + u0
            sc[11, k] = vy * _horner(iv1, cn, rn, zn_top) + v0
            sc[12, k] = ux * _horner(iv0, cn, rn, zn_bot) + u0
            sc[13, k] = vy * _horner(iv1, cn, rn, zn_bot) + v0
        for k in range(m):  # which chords lie inside the DEM (vectorised)
            ua = sc[10, k]
            va = sc[11, k]
            ub = sc[12, k]
            vb = sc[13, k]
            inside = (ua >= 0.0) & (va >= 0.0) & (ub >= 0.0) & (vb >= 0.0) & (ua <= top_j + 1.0) \
                & (ub <= top_j + 1.0) & (va <= top_i + 1.0) & (vb <= top_i + 1.0)
            sc[6, k] = 1.0 if inside else 0.0
            sc[8, k] = 0.0
            sc[9, k] = 1.0
        for _step in range(NARROW_STEPS):  # narrow them with the max/min pyramid, one level per block
            width = 0
            for k in range(m):  # (vectorised: an integer maximum)
                cu_lo, cu_hi, cv_lo, cv_hi = _box_cells(n_cu, n_cv, sc[10, k], sc[11, k], sc[12, k] - sc[10, k],
                                                        sc[13, k] - sc[11, k], sc[8, k], sc[9, k])
                width = max(width, max(cu_hi - cu_lo, cv_hi - cv_lo))
            if 2 * width + 1 <= CELL_STEPS:  # the lockstep cells cover every chord of the block: nothing to gain
                break
            level = _level_for_width(levels, width)
            for k in range(m):  # (vectorised; gathers)
                sc[8, k], sc[9, k] = _narrow_step(bound_hi, bound_lo, levels, level, n_cu, n_cv, sc[10, k], sc[11, k],
                                                  z_top, sc[12, k] - sc[10, k], sc[13, k] - sc[11, k], dz_chord,
                                                  sc[8, k], sc[9, k])
        for k in range(m):  # the cell the narrowed chord starts in (vectorised); -2: still stepping
            du = sc[12, k] - sc[10, k]
            dv = sc[13, k] - sc[11, k]
            u = sc[10, k] + du * sc[8, k]
            v = sc[11, k] + dv * sc[8, k]
            sc[4, k] = _clamp_index(math.floor(u) if du >= 0.0 else math.ceil(u) - 1.0, top_j)
            sc[5, k] = _clamp_index(math.floor(v) if dv >= 0.0 else math.ceil(v) - 1.0, top_i)
            sc[14, k] = -2.0 if sc[6, k] != 0.0 else -1.0
        for _cell in range(CELL_STEPS):  # cell by cell in lockstep over the points
            for k in range(m):  # the cell's corners (gathers)
                i = int(sc[5, k])
                j = int(sc[4, k])
                sc[0, k] = hgt[i, j]
                sc[1, k] = hgt[i, j + 1]
                sc[2, k] = hgt[i + 1, j]
                sc[3, k] = hgt[i + 1, j + 1]
            n_pending = 0
            for k in range(m):  # the hit in it, or on to the next cell (vectorised; an integer count)
                s, fl, s_next, j_next, i_next = _cell_step(sc[0, k], sc[1, k], sc[2, k], sc[3, k], sc[4, k],
                                                           sc[5, k], sc[10, k], sc[11, k], z_top,
                                                           sc[12, k] - sc[10, k], sc[13, k] - sc[11, k], dz_chord,
                                                           sc[8, k], sc[9, k], top_j, top_i)
                pending = sc[14, k] == -2.0
                sc[7, k] = s if pending else sc[7, k]
                sc[14, k] = fl if pending else sc[14, k]
                n_pending += 1 if pending & (fl == -2.0) else 0
                sc[8, k] = s_next
                sc[4, k] = j_next
                sc[5, k] = i_next
            if n_pending == 0:
                break
        for k in range(m):  # still stepping: the walk decides
            flag_out[i0 + k] = -1 if sc[14, k] == -2.0 else int(sc[14, k])
        for k in range(m):  # the walk for the others (scalar), then the hit's height
            fl = flag_out[i0 + k]
            s = sc[7, k]
            if fl == -1:
                s, fl = _first_hit(hgt, tile_max, sc[10, k], sc[11, k], z_top, sc[12, k], sc[13, k], z_bot)
                flag_out[i0 + k] = fl
            zn[k] = zn_top + s * (zn_bot - zn_top) if fl == OK else zn_mid
        for k in range(m):  # start on the line of sight at the hit height (vectorised)
            rn = (row[i0 + k] - row_off) / row_sc
            cn = (col[i0 + k] - col_off) / col_sc
            x[k], y[k], sc[0, k], sc[1, k], sc[2, k], sc[3, k], sc[4, k], sc[5, k] = _inverse_guess(iv0, iv1, cn, rn,
                                                                                                 zn[k])
            sc[6, k] = zn[k]
            cell[k], sc[8, k], sc[9, k], sc[10, k] = _correction_cell(corr, cg, cn, rn, zn[k])
        for k in range(m):  # the polynomial's residual (gathers: a loop of its own)
            cx, cy = _correction_at(cells, cell[k], sc[8, k], sc[9, k], sc[10, k])
            x[k] += cx
            y[k] += cy
        for _p in range(MAX_PASSES):  # measure, keep the converged, a pixel + height step for the others
            for k in range(m):  # the forward RPC alone (vectorised; no gathers in this loop)
                rr, cc = _forward(fw0, fw1, fw2, fw3, x[k], y[k], zn[k])
                sc[8, k] = (row[i0 + k] - row_off) / row_sc - rr
                sc[9, k] = (col[i0 + k] - col_off) / col_sc - cc
            for k in range(m):  # the DEM cell under the point (gathers): its corner height and bilinear terms
                u = ux * x[k] + u0
                v = vy * y[k] + v0
                j = _clamp_index(u, top_j)
                i = _clamp_index(v, top_i)
                h00 = hgt[i, j]
                sc[10, k] = h00
                sc[11, k] = hgt[i, j + 1] - h00
                sc[12, k] = hgt[i + 1, j] - h00
                sc[13, k] = hgt[i + 1, j + 1] - hgt[i + 1, j] - sc[11, k]
                sc[14, k] = u - j
                sc[15, k] = v - i
            if _p > 0:  # (the guess itself is never within 1e-9 px: not measured)
                n_open = 0
                for k in range(m):  # verification (vectorised; an integer count, which LLVM may reorder)
                    a = sc[14, k]
                    bb = sc[15, k]
                    g = zn[k] * h_sc + h_off - (sc[10, k] + sc[11, k] * a + sc[12, k] * bb + sc[13, k] * a * bb)
                    u = ux * x[k] + u0
                    v = vy * y[k] + v0
                    inside = (u >= 0.0) & (u <= top_j + 1.0) & (v >= 0.0) & (v <= top_i + 1.0)
                    good = ((sc[8, k] * row_sc) ** 2 + (sc[9, k] * col_sc) ** 2 <= tol2) & (abs(g) <= tol_m) & inside
                    sc[7, k] = 0.0 if good else 1.0
                    n_open += 1 if (not good) & (flag_out[i0 + k] == OK) else 0
                if 8 * n_open <= m:
                    break
            for k in range(m):  # a pixel + height step for the points not yet converged (vectorised)
                er = sc[8, k]
                ec = sc[9, k]
                a = sc[14, k]
                bb = sc[15, k]
                p = sc[11, k]
                q = sc[12, k]
                r = sc[13, k]
                g = zn[k] * h_sc + h_off - (sc[10, k] + p * a + q * bb + r * a * bb)
                hu = p + r * bb
                hv = q + r * a
                dx = sc[0, k] * er + sc[1, k] * ec
                dy = sc[2, k] * er + sc[3, k] * ec
                g -= hu * ux * dx + hv * vy * dy
                dz = -g / (h_sc - (hu * ux * sc[4, k] + hv * vy * sc[5, k]))
                step = (_p == 0) | (sc[7, k] != 0.0)
                x[k] += dx + sc[4, k] * dz if step else 0.0
                y[k] += dy + sc[5, k] * dz if step else 0.0
                zn[k] += dz if step else 0.0
        for k in range(m):  # scalar loop for the points the passes left, then units
            if flag_out[i0 + k] == OK and sc[7, k] != 0.0:
                rn = (row[i0 + k] - row_off) / row_sc
                cn = (col[i0 + k] - col_off) / col_sc
                xs, ys, zs, fl = _refine_on_dem(fw0, fw1, fw2, fw3, norm, hgt, ux, u0, vy, v0, rn, cn, x[k], y[k],
                                                zn[k], sc[0, k], sc[1, k], sc[2, k], sc[3, k], sc[4, k], sc[5, k],
                                                tol_px, tol_m, max_iter)
                if fl != OK:  # again from the polynomial at the walk's height
                    xg, yg, a, bb, c, d, e, f = _start(iv0, iv1, corr, cg, cn, rn, sc[6, k])
                    xs, ys, zs, fl = _refine_on_dem(fw0, fw1, fw2, fw3, norm, hgt, ux, u0, vy, v0, rn, cn, xg, yg,
                                                    sc[6, k], a, bb, c, d, e, f, tol_px, tol_m, max_iter)
                x[k] = xs
                y[k] = ys
                zn[k] = zs
                flag_out[i0 + k] = fl
            if flag_out[i0 + k] == OK:
                x[k] = x[k] * lon_sc + lon_off
                y[k] = y[k] * lat_sc + lat_off
                zn[k] = zn[k] * h_sc + h_off
            else:
                x[k] = math.nan
                y[k] = math.nan
                zn[k] = math.nan


if NUMBA_AVAILABLE:
    from explorer.rpc._kernels import _horner  # compiled cubic (same operations as the numpy path)
else:  # pragma: no cover - numba missing: interpreted (slow, same operations)
    _horner = horner_rpc00b
_first_hit = _dem.first_hit
_exit_param = _dem.exit_param
_box_cells = _dem.box_cells
_level_for_width = _dem.level_for_width
_narrow_step = _dem.narrow_step
_bilinear = _dem.bilinear
_cell_hit = _dem.cell_hit
_patch_quadratic = _dem.patch_quadratic


def _tuples(array: np.ndarray) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in array)


@dataclass(frozen=True)
class RPCInverse:
    """The fitted inverse of one model over one height range, and the compiled loops that use it.

    Build with :meth:`for_model` (cached on the model per height range).

    Attributes
    ----------
    forward : tuple of 4 tuples of 20 float
        row_num, row_den, col_num, col_den (tuples: constants in registers in the compiled loops).
    inverse : tuple of 2 tuples of 20 float
        Fitted polynomial (see :func:`fit_inverse_polynomial`).
    norm : tuple of 10 float
        lon_off, lon_scale, lat_off, lat_scale, h_off, h_scale, row_off, row_scale, col_off, col_scale.
    h_min, h_max : float
        Height range of the fit, metres.
    guess_error_px : float
        The polynomial's largest error on the validation grid, pixels (before the correction grid).
    correction : ndarray, shape (CORRECTION_LAYERS - 1, n_r - 1, n_c - 1, 16)
        The polynomial's residual (normalised lon, lat; exact inverse minus polynomial) at the nodes of a
        regular grid of normalised column and row at CORRECTION_LAYERS heights, stored per cell
        (see :func:`_correction`), interpolated and added to the guess.
    correction_grid : tuple of 6 float
        c0, r0, z0 (first node) and dc, dr, dz (spacing) of that grid, normalised units.
    """

    forward: tuple
    inverse: tuple
    norm: tuple[float, ...]
    h_min: float
    h_max: float
    guess_error_px: float
    correction: np.ndarray
    correction_grid: tuple[float, ...]

    @classmethod
    def for_model(cls, rpc: RationalFunctionModel, h_min: float | None = None,
                  h_max: float | None = None) -> RPCInverse:
        """Fit (or reuse) the inverse of ``rpc`` over ``[h_min, h_max]`` (default: the model's height range)."""
        lo, hi = rpc.height_range()
        h_min = lo if h_min is None else float(h_min)
        h_max = hi if h_max is None else float(h_max)
        if not (np.isfinite(h_min) and np.isfinite(h_max) and h_max >= h_min):
            raise InputError(f"height range must be finite with h_max >= h_min, got [{h_min}, {h_max}]")
        if h_max - h_min < 1.0:
            mid = 0.5 * (h_min + h_max)
            h_min, h_max = mid - 0.5, mid + 0.5
        cache = rpc.__dict__.setdefault("_inverse_cache", {})
        key = (round(h_min, 3), round(h_max, 3))
        if key not in cache:
            coefficients, error = fit_inverse_polynomial(rpc, h_min, h_max)
            forward = np.stack([rpc.row_num, rpc.row_den, rpc.col_num, rpc.col_den])
            norm = (rpc.lon_offset, rpc.lon_scale, rpc.lat_offset, rpc.lat_scale, rpc.height_offset,
                    rpc.height_scale, rpc.row_offset, rpc.row_scale, rpc.col_offset, rpc.col_scale)
            if len(cache) > 8:
                cache.clear()
            # the correction grid over the image (normalised, 2% margin) and the height range
            if rpc.image_size is not None:
                rows, cols = rpc.image_size
                r_ends = (np.array([-0.5, rows - 0.5]) - rpc.row_offset) / rpc.row_scale
                c_ends = (np.array([-0.5, cols - 0.5]) - rpc.col_offset) / rpc.col_scale
            else:
                r_ends = c_ends = np.array([-1.0, 1.0])
            n_grid, n_z = CORRECTION_NODES, CORRECTION_LAYERS
            r_lo, r_hi = r_ends.min() - 0.02 * np.ptp(r_ends), r_ends.max() + 0.02 * np.ptp(r_ends)
            c_lo, c_hi = c_ends.min() - 0.02 * np.ptp(c_ends), c_ends.max() + 0.02 * np.ptp(c_ends)
            z_lo, z_hi = ((np.array([h_min, h_max]) - rpc.height_offset) / rpc.height_scale)
            z_lo, z_hi = min(z_lo, z_hi), max(z_lo, z_hi)
            steps = ((c_hi - c_lo) / (n_grid - 1), (r_hi - r_lo) / (n_grid - 1), (z_hi - z_lo) / (n_z - 1))
            grid = tuple(float(v) for v in (c_lo, r_lo, z_lo, *steps))
            first = cls(_tuples(forward), _tuples(coefficients), tuple(float(v) for v in norm), h_min, h_max, error,
                        np.zeros((n_z - 1, n_grid - 1, n_grid - 1, 16)), grid)
            zz, rr, cc = np.meshgrid(np.linspace(z_lo, z_hi, n_z), np.linspace(r_lo, r_hi, n_grid),
                                     np.linspace(c_lo, c_hi, n_grid), indexing="ij")
            lon, lat, flags = first.localize(rr.ravel() * rpc.row_scale + rpc.row_offset,
                                             cc.ravel() * rpc.col_scale + rpc.col_offset,
                                             zz.ravel() * rpc.height_scale + rpc.height_offset)
            a = _monomials(cc.ravel(), rr.ravel(), zz.ravel())
            residual = np.stack([(lon - rpc.lon_offset) / rpc.lon_scale - a @ coefficients[0],
                                 (lat - rpc.lat_offset) / rpc.lat_scale - a @ coefficients[1]])
            residual[~np.isfinite(residual)] = 0.0
            cache[key] = cls(first.forward, first.inverse, first.norm, h_min, h_max, error,
                             _correction_cells(residual.reshape(2, n_z, n_grid, n_grid)), grid)
        return cache[key]

    def localize(self, row: np.ndarray, col: np.ndarray, h: np.ndarray, *, tol_px: float = 1e-9,
                 max_iter: int = 30) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Image to ground at heights.

        Parameters
        ----------
        row, col : array_like, shape (N,)
            0-based pixel-centre image coordinates (broadcastable).
        h : array_like, shape (N,)
            Heights, metres above the ellipsoid.
        tol_px : float
            A point is converged when its measured re-projection residual is at most this (pixels).

        Returns
        -------
        lon, lat : ndarray, shape (N,)
            Degrees; NaN unless converged.
        flag : ndarray of int8, shape (N,)
            :data:`OK` or :data:`NOT_CONVERGED`.
        """
        row, col, h = (np.ascontiguousarray(np.ravel(a), dtype=np.float64) for a in np.broadcast_arrays(row, col, h))
        n = row.shape[0]
        lon, lat, flag = np.empty(n), np.empty(n), np.empty(n, np.int8)

        def run(sl: slice) -> None:
            _localize_blocks(*self.forward, *self.inverse, self.correction, self.correction_grid, self.norm, row[sl],
                             col[sl], h[sl], float(tol_px), int(max_iter), lon[sl], lat[sl], flag[sl])

        run_in_parts(run, n, align=BLOCK, min_points=PARALLEL_MIN_POINTS)
        return lon, lat, flag

    def on_dem(self, row: np.ndarray, col: np.ndarray, grid: HeightGrid, *, tol_px: float = 1e-9,
               tol_m: float = 1e-6, max_iter: int = 30) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """First intersection of each pixel's line of sight with ``grid``.

        Parameters
        ----------
        row, col : array_like, shape (N,)
            0-based pixel-centre image coordinates (broadcastable).
        grid : HeightGrid
            Longitude/latitude grid (degrees), heights above the ellipsoid (metres).
        tol_px, tol_m : float
            Converged when the measured re-projection residual is at most ``tol_px`` pixels and the point is
            within ``tol_m`` metres of the DEM surface.

        Returns
        -------
        lon, lat, h : ndarray, shape (N,)
            Degrees, degrees, metres; NaN unless the flag is OK.
        flag : ndarray of int8, shape (N,)
            See :mod:`explorer.geometry.dem_intersection`.
        """
        row, col = (np.ascontiguousarray(np.ravel(a), dtype=np.float64) for a in np.broadcast_arrays(row, col))
        n = row.shape[0]
        lon, lat, h, flag = np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.int8)
        pad = 1e-6 * max(1.0, abs(grid.z_max), abs(grid.z_min))
        z_top, z_bot = grid.z_max + pad, grid.z_min - pad

        def run(sl: slice) -> None:
            _dem_blocks(*self.forward, *self.inverse, self.correction, self.correction_grid, self.norm, grid.heights,
                        grid.bounds, grid.x0, grid.y0, grid.dx, grid.dy, z_top, z_bot, row[sl], col[sl],
                        float(tol_px), float(tol_m), int(max_iter), lon[sl], lat[sl], h[sl], flag[sl])

        run_in_parts(run, n, align=BLOCK, min_points=PARALLEL_MIN_POINTS)
        return lon, lat, h, flag
