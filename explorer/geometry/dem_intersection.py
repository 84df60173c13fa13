"""Line of sight against a gridded DEM: the first intersection from the sensor, compiled.

One kernel serves every image-to-ground-on-terrain path of the package: the rigorous scenes (a straight ray
in the local ENU frame against a :class:`~explorer.geometry.terrain.GridDEM`) and the rational function
model (the line of sight between two heights against a lon/lat DEM, see :mod:`explorer.rpc.inverse`).

Algorithm (the choice is documented in ``docs/performance.md#image-to-ground-on-terrain``)
-----------------------------------------------------------------------------------------
The search segment runs from the DEM's highest height down to its lowest height (outside that slab
there can be no intersection).  In grid coordinates ``(u, v, z)`` -- ``u`` the fractional node column,
``v`` the fractional node row, ``z`` the height -- the segment is straight, and over one DEM cell the
bilinear surface restricted to the segment is a quadratic in the segment parameter.  So the segment is
walked cell by cell in the order the sensor sees them (Amanatides & Woo's grid traversal, the walk of
Duvenhage's "Using an implicit min/max kd-tree for doing efficient terrain line of sight calculations",
2009, as in Orekit Rugged), and in each cell whose highest corner is above the segment's lowest point
the quadratic is solved exactly; the smallest root is the first intersection, so a ridge in front of a
valley is hit however thin it is.  A two-level min/max hierarchy (tiles of :data:`TILE` x :data:`TILE`
cells with their maximum height; a tile with a no-data node has +inf) skips the tiles the segment
passes over without entering a cell.

GDAL's RPC transformer instead iterates the height (localise at h, look up the DEM there, repeat):
cheap when it converges, but it can converge to a farther crossing behind a ridge or oscillate on
steep slopes, and it knows nothing of holes it jumps over; the cell walk is exact and its cost is the
number of cells the segment crosses (usually one to three).

The part of the segment outside the DEM's node grid is not searched (the terrain there is unknown): a
line of sight that enters the DEM from outside is walked from where it enters.

Flags (one per point, never a silent wrong point)
-------------------------------------------------
:data:`OK` (0) intersection found; :data:`OUTSIDE_DEM` (1) the segment leaves the DEM's node grid
(or never enters it) before a hit; :data:`NODATA` (2) the walk
reached a cell with a no-data node before a hit; :data:`NO_INTERSECTION` (3) the line never reaches the
terrain (pointing up, or a segment that ends above the surface); :data:`NOT_CONVERGED` (4) an iterative
refinement (RPC) did not converge.  Heights and points are NaN where the flag is not :data:`OK`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from explorer._numba import kernel, prange, serial_twin
from explorer.errors import InputError

__all__ = [
    "FLAG_NAMES",
    "NODATA",
    "NOT_CONVERGED",
    "NO_INTERSECTION",
    "OK",
    "OUTSIDE_DEM",
    "TILE",
    "HeightGrid",
    "heights_at",
    "intersect_rays",
    "intersect_segments",
]

OK = 0
OUTSIDE_DEM = 1
NODATA = 2
NO_INTERSECTION = 3
NOT_CONVERGED = 4
FLAG_NAMES = {OK: "ok", OUTSIDE_DEM: "outside DEM", NODATA: "no-data", NO_INTERSECTION: "no intersection",
              NOT_CONVERGED: "not converged"}

#: Cells per side of a tile of the min/max hierarchy.
TILE = 16

#: Rounds of the max/min pyramid that narrow a segment before its first cell is solved (:func:`_narrow_step`).
NARROW_STEPS = 2

#: Points per chunk of the public wrappers (bounds the temporaries to a few tens of MB).
CHUNK = 1 << 20

#: Below this many rays the loop runs on one thread (waking the second thread costs more on a busy machine).
PARALLEL_MIN_POINTS = 20_000


@dataclass(frozen=True)
class HeightGrid:
    """A regular grid of heights with its tile maxima, in the kernel's layout.

    Node ``(i, j)`` (row ``i``, column ``j``) lies at ``x = x0 + j * dx``, ``y = y0 + i * dy`` in the DEM's
    horizontal coordinates (metres of a local frame, or degrees); ``dx``, ``dy`` may be negative.

    Attributes
    ----------
    heights : ndarray, shape (ny, nx), float64, C-contiguous
        Metres; NaN marks no-data.
    tile_max : ndarray, shape (ceil((ny-1)/TILE), ceil((nx-1)/TILE))
        Highest node of each tile of cells (nodes on the tile's border included); +inf when the tile
        touches a no-data node.
    x0, y0, dx, dy : float
        Node (0, 0) and spacing.
    z_min, z_max : float
        Lowest and highest valid height, metres.
    bound_hi, bound_lo : ndarray, shape (n_bounds,)
        The max/min pyramid (see :func:`bound_pyramid`), all levels one after the other.
    bound_levels : ndarray of int64, shape (n_levels, 3)
        Per level: offset into ``bound_hi``/``bound_lo``, number of block rows, number of block columns.
    """

    heights: np.ndarray
    tile_max: np.ndarray
    x0: float
    y0: float
    dx: float
    dy: float
    z_min: float
    z_max: float
    bound_hi: np.ndarray
    bound_lo: np.ndarray
    bound_levels: np.ndarray

    @classmethod
    def from_array(cls, heights: np.ndarray, x0: float, y0: float, dx: float, dy: float) -> HeightGrid:
        """Grid from heights (NaN = no-data) and the position of node (0, 0) and the spacing."""
        h = np.ascontiguousarray(heights, dtype=np.float64)
        if h.ndim != 2 or min(h.shape) < 2:
            raise InputError(f"DEM heights must be a 2-D grid of at least 2 x 2 nodes, got shape {h.shape}")
        if not (np.isfinite(dx) and np.isfinite(dy) and dx != 0 and dy != 0):
            raise InputError(f"DEM spacing must be finite and non-zero, got dx={dx}, dy={dy}")
        finite = np.isfinite(h)
        if not finite.any():
            raise InputError("DEM has no valid height (every node is no-data)")
        ny, nx = h.shape
        nty, ntx = -(-(ny - 1) // TILE), -(-(nx - 1) // TILE)
        filled = np.where(finite, h, np.inf)
        tile_max = np.empty((nty, ntx))
        for ti in range(nty):
            i0, i1 = ti * TILE, min((ti + 1) * TILE, ny - 1)
            rows = filled[i0:i1 + 1]
            for tj in range(ntx):
                j0, j1 = tj * TILE, min((tj + 1) * TILE, nx - 1)
                tile_max[ti, tj] = rows[:, j0:j1 + 1].max()
        bound_hi, bound_lo, bound_levels = bound_pyramid(h)
        return cls(h, tile_max, float(x0), float(y0), float(dx), float(dy),
                   float(h[finite].min()), float(h[finite].max()), bound_hi, bound_lo, bound_levels)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(tile_max, bound_hi, bound_lo, bound_levels)``: what the compiled loops read besides the heights."""
        return self.tile_max, self.bound_hi, self.bound_lo, self.bound_levels

    def to_grid(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fractional node coordinates (u = column, v = row) of horizontal positions."""
        return (np.asarray(x, np.float64) - self.x0) / self.dx, (np.asarray(y, np.float64) - self.y0) / self.dy


def _block_reduce(a: np.ndarray, fill: float, op) -> np.ndarray:
    """2 x 2 blocks of ``a`` reduced by ``op`` (odd edges padded with ``fill``)."""
    ny, nx = a.shape
    padded = np.full((ny + ny % 2, nx + nx % 2), fill)
    padded[:ny, :nx] = a
    return op(op(padded[0::2, 0::2], padded[0::2, 1::2]), op(padded[1::2, 0::2], padded[1::2, 1::2]))


def _dilate(a: np.ndarray, fill: float, op) -> np.ndarray:
    """Each element reduced by ``op`` with its eight neighbours (outside the array: ``fill``); separable."""
    ny, nx = a.shape
    padded = np.full((ny + 2, nx + 2), fill, dtype=a.dtype)
    padded[1:-1, 1:-1] = a
    rows = op(op(padded[:, :-2], padded[:, 1:-1]), padded[:, 2:])
    return op(op(rows[:-2], rows[1:-1]), rows[2:])


def _float32_bound(a: np.ndarray, upward: bool) -> np.ndarray:
    """``a`` in float32, rounded away from the bound's side (up for maxima, down for minima): still a bound."""
    with np.errstate(over="ignore"):  # beyond float32's range: +-inf, still a bound
        out = a.astype(np.float32)
        wrong = out < a if upward else out > a
        out[wrong] = np.nextafter(out[wrong], np.float32(np.inf if upward else -np.inf))
    return out


def bound_pyramid(heights: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Max/min pyramid of a height grid: bounds of the bilinear surface over any box of cells.

    Level ``k`` has one entry per block of ``2**k x 2**k`` cells: the highest (lowest) node of the block and of
    its eight neighbouring blocks, so that any box of cells at most ``2**k`` cells wide whose middle cell lies
    in the block is bounded by that entry (:func:`_box_bounds_py`).  A no-data node counts as +inf in the
    maxima and -inf in the minima (a box that touches a hole is never declared clear of terrain).  Stored in
    float32 rounded outwards (still bounds): about 5.3 bytes per cell for both pyramids.

    Parameters
    ----------
    heights : ndarray, shape (ny, nx)
        Node heights, metres; NaN = no-data.

    Returns
    -------
    bound_hi, bound_lo : ndarray of float32, shape (n_bounds,)
        All levels, finest first, each C-ordered.
    bound_levels : ndarray of int64, shape (n_levels, 3)
        Offset, rows and columns of each level.
    """
    finite = np.isfinite(heights)
    hi = np.where(finite, heights, np.inf)
    lo = np.where(finite, heights, -np.inf)
    cell_hi = np.maximum(np.maximum(hi[:-1, :-1], hi[:-1, 1:]), np.maximum(hi[1:, :-1], hi[1:, 1:]))
    cell_lo = np.minimum(np.minimum(lo[:-1, :-1], lo[:-1, 1:]), np.minimum(lo[1:, :-1], lo[1:, 1:]))
    his, los, levels = [], [], []
    offset = 0
    while True:
        his.append(_dilate(cell_hi, -np.inf, np.maximum).ravel())
        los.append(_dilate(cell_lo, np.inf, np.minimum).ravel())
        levels.append((offset, cell_hi.shape[0], cell_hi.shape[1]))
        offset += cell_hi.size
        if cell_hi.shape[0] == 1 and cell_hi.shape[1] == 1:
            break
        cell_hi = _block_reduce(cell_hi, -np.inf, np.maximum)
        cell_lo = _block_reduce(cell_lo, np.inf, np.minimum)
    return (_float32_bound(np.concatenate(his), True), _float32_bound(np.concatenate(los), False),
            np.array(levels, dtype=np.int64))


# --------------------------------------------------------------------------------------------- kernel
@kernel(inline="always")
def _patch_quadratic(h00, h01, h10, h11, i, j, ua, va, za, du, dv, dz):
    """``(c0, c1, c2)`` of f(s) = z(s) - h(s) = c0 + c1 s + c2 s^2 along a segment over cell (i, j).

    The segment starts at grid coordinates (ua, va) and height za and moves by (du, dv, dz) per unit of s;
    h is the bilinear patch through the cell's corner heights h00 (i, j), h01 (i, j+1), h10, h11.
    """
    a0 = ua - j
    b0 = va - i
    p = h01 - h00
    q = h10 - h00
    r = h00 - h01 - h10 + h11
    c0 = za - (h00 + p * a0 + q * b0 + r * a0 * b0)
    c1 = dz - (p * du + q * dv + r * (a0 * dv + b0 * du))
    c2 = -r * du * dv
    return c0, c1, c2


@kernel(inline="always")
def _cell_hit(h, i, j, ua, va, za, du, dv, dz, sa, sb):
    """Smallest s in [sa, sb] where the segment meets the bilinear patch of cell (i, j); -1 if none.

    Returns -2.0 when the cell has a no-data corner.
    """
    h00 = h[i, j]
    h01 = h[i, j + 1]
    h10 = h[i + 1, j]
    h11 = h[i + 1, j + 1]
    if math.isnan(h00) or math.isnan(h01) or math.isnan(h10) or math.isnan(h11):
        return -2.0
    z_low = za + dz * sb if dz < 0.0 else za + dz * sa
    if z_low > max(max(h00, h01), max(h10, h11)):
        return -1.0
    c0, c1, c2 = _patch_quadratic(h00, h01, h10, h11, i, j, ua, va, za, du, dv, dz)
    fa = c0 + sa * (c1 + sa * c2)
    if fa <= 0.0:
        return sa
    fb = c0 + sb * (c1 + sb * c2)
    scale = abs(c0) + abs(c1) * max(abs(sa), abs(sb)) + abs(c2) * max(sa * sa, sb * sb)
    if abs(c2) * (sb - sa) * (sb - sa) <= 1e-14 * scale:  # linear over the cell
        if fb > 0.0:
            return -1.0
        s = sa - fa * (sb - sa) / (fb - fa)
    else:
        if fb > 0.0:
            # both ends above: a hit only if the parabola dips below inside (convex, vertex inside)
            if c2 <= 0.0:
                return -1.0
            sv = -c1 / (2.0 * c2)
            if not (sa < sv < sb) or c0 + sv * (c1 + sv * c2) > 0.0:
                return -1.0
        disc = c1 * c1 - 4.0 * c2 * c0
        if disc < 0.0:
            disc = 0.0
        qq = -0.5 * (c1 + math.copysign(math.sqrt(disc), c1))
        r1 = qq / c2
        r2 = c0 / qq if qq != 0.0 else r1
        lo = min(r1, r2)
        hi = max(r1, r2)
        s = lo if (fb > 0.0 or lo >= sa - 1e-9 * (sb - sa)) else hi
    if not (sa <= s <= sb):
        s = min(max(s, sa), sb)
        if fb <= 0.0 and abs(c0 + s * (c1 + s * c2)) > 1e-9 * scale:
            # round-off in the root formula: bisection on the bracket [sa, sb] (f(sa) > 0 >= f(sb))
            lo_s = sa
            hi_s = sb
            for _ in range(200):
                mid = 0.5 * (lo_s + hi_s)
                if mid <= lo_s or mid >= hi_s:
                    break
                if c0 + mid * (c1 + mid * c2) > 0.0:
                    lo_s = mid
                else:
                    hi_s = mid
            s = hi_s
    # one Newton polish on the exact quadratic (round-off of the root formula)
    fs = c0 + s * (c1 + s * c2)
    ds = c1 + 2.0 * c2 * s
    if ds != 0.0:
        s2 = s - fs / ds
        if sa <= s2 <= sb:
            s = s2
    return s


@kernel(inline="always")
def exit_param(a, d, index, size):
    """Segment parameter where the coordinate ``a + d s`` leaves interval ``index`` of width ``size``.

    The interval is ``[index * size, (index + 1) * size]``; moving up (``d > 0``) it is left at its upper
    edge, moving down at its lower edge; ``inf`` when the coordinate does not move.  Branch-free selects.
    """
    edge = (index + 1.0) * size if d > 0.0 else index * 1.0 * size
    return (edge - a) / d if d != 0.0 else math.inf


@kernel()
def _walk(h, tile_max, ua, va, za, du, dv, dz, s0, s1):
    """First hit of the segment between parameters s0 and s1 (inside the node box): ``(s, flag)``, flag -1: none.

    Tiles of :data:`TILE` cells whose highest node is below the segment are skipped; in the others the cells
    are walked in order (Amanatides & Woo) and solved exactly (:func:`_cell_hit`).
    """
    ny = h.shape[0]
    nx = h.shape[1]
    tile = TILE
    nty = tile_max.shape[0]
    ntx = tile_max.shape[1]
    step_u = 1 if du > 0.0 else -1
    step_v = 1 if dv > 0.0 else -1
    u0 = min(max(ua + du * s0, 0.0), nx - 1.0)
    v0 = min(max(va + dv * s0, 0.0), ny - 1.0)
    if du >= 0.0:
        tj = int(math.floor(u0 / tile))
    else:
        tj = int(math.ceil(u0 / tile)) - 1
    if dv >= 0.0:
        ti = int(math.floor(v0 / tile))
    else:
        ti = int(math.ceil(v0 / tile)) - 1
    tj = min(max(tj, 0), ntx - 1)
    ti = min(max(ti, 0), nty - 1)
    s_cur = s0
    for _ in range(nty + ntx + 4):
        su = exit_param(ua, du, tj, tile)  # exit of tile (ti, tj)
        sv = exit_param(va, dv, ti, tile)
        s_exit = min(min(su, sv), s1)
        if s_exit < s_cur:
            s_exit = s_cur
        z_low = za + dz * s_exit
        if tile_max[ti, tj] >= z_low:
            # fine walk over the cells of this tile between s_cur and s_exit
            um = ua + du * s_cur
            vm = va + dv * s_cur
            if du >= 0.0:
                j = int(math.floor(um))
            else:
                j = int(math.ceil(um)) - 1
            if dv >= 0.0:
                i = int(math.floor(vm))
            else:
                i = int(math.ceil(vm)) - 1
            j = min(max(j, max(tj * tile, 0)), min((tj + 1) * tile, nx - 1) - 1)
            i = min(max(i, max(ti * tile, 0)), min((ti + 1) * tile, ny - 1) - 1)
            c_cur = s_cur
            for _k in range(2 * tile + 4):
                cu = exit_param(ua, du, j, 1)  # exit of cell (i, j)
                cv = exit_param(va, dv, i, 1)
                c_exit = min(min(cu, cv), s_exit)
                if c_exit < c_cur:
                    c_exit = c_cur
                s_hit = _cell_hit(h, i, j, ua, va, za, du, dv, dz, c_cur, c_exit)
                if s_hit == -2.0:
                    return math.nan, NODATA
                if s_hit >= 0.0:
                    return s_hit, OK
                if c_exit >= s_exit:
                    break
                if cu < cv:
                    j += step_u
                    if j < tj * tile or j >= min((tj + 1) * tile, nx - 1):
                        break
                else:
                    i += step_v
                    if i < ti * tile or i >= min((ti + 1) * tile, ny - 1):
                        break
                c_cur = c_exit
        if s_exit >= s1:
            break
        if su < sv:
            tj += step_u
            if tj < 0 or tj >= ntx:
                break
        else:
            ti += step_v
            if ti < 0 or ti >= nty:
                break
        s_cur = s_exit

    return math.nan, -1


@kernel(inline="always")
def _box_cells(ncu, ncv, ua, va, du, dv, sa, sb):
    """Cells [cu_lo, cu_hi] x [cv_lo, cv_hi] under the segment's part [sa, sb] (clamped to the grid)."""
    u_a = ua + du * sa
    u_b = ua + du * sb
    v_a = va + dv * sa
    v_b = va + dv * sb
    cu_lo = min(max(int(math.floor(min(u_a, u_b))), 0), ncu - 1)
    cu_hi = min(max(int(math.floor(max(u_a, u_b))), 0), ncu - 1)
    cv_lo = min(max(int(math.floor(min(v_a, v_b))), 0), ncv - 1)
    cv_hi = min(max(int(math.floor(max(v_a, v_b))), 0), ncv - 1)
    return cu_lo, cu_hi, cv_lo, cv_hi


@kernel(inline="always")
def _level_for_width(levels, width):
    """Finest pyramid level whose blocks are at least ``width`` cells wide (the top level at most)."""
    k = 0
    while (1 << k) < width and k < levels.shape[0] - 1:
        k += 1
    return k


@kernel(inline="always")
def _narrow_step(bound_hi, bound_lo, levels, k, ncu, ncv, ua, va, za, du, dv, dz, sa, sb):
    """One round of narrowing the part [sa, sb] of a segment that holds its first hit: ``(sa, sb)``.

    The segment (inside the node grid, ``dz < 0``) starts at (ua, va, za) and moves by (du, dv, dz) per unit
    of s.  The box of cells under [sa, sb] is bounded by level ``k`` of the pyramid (``2**k`` at least its
    width, :func:`_level_for_width`).  No hit can lie above the box's highest node (``sa`` moves down to
    it); and where the segment is below the box's lowest node it has already crossed the surface (``sb``
    moves up to it).  A hole counts as +inf in the maxima and -inf in the minima, so a segment over a hole
    is not narrowed past it.  Branch-free, and ``k`` the same for a whole loop, so that it vectorises.
    """
    cu_lo, cu_hi, cv_lo, cv_hi = _box_cells(ncu, ncv, ua, va, du, dv, sa, sb)
    idx = levels[k, 0] + (((cv_lo + cv_hi) // 2) >> k) * levels[k, 2] + (((cu_lo + cu_hi) // 2) >> k)
    na = (bound_hi[idx] - za) / dz
    nb = (bound_lo[idx] - za) / dz
    na = na if na > sa else sa
    nb = nb if nb < sb else sb
    na = na if na < sb else sb
    nb = nb if nb > na else na
    return na, nb


@kernel()
def _first_hit(h, tile_max, ua, va, za, ub, vb, zb):
    """First intersection of the segment (ua, va, za) -> (ub, vb, zb) (grid coordinates) with the DEM.

    Returns ``(s, flag)``: the segment parameter in [0, 1] of the hit (NaN when the flag is not OK).
    """
    ny = h.shape[0]
    nx = h.shape[1]
    du = ub - ua
    dv = vb - va
    dz = zb - za
    if not (dz < 0.0):
        return math.nan, NO_INTERSECTION
    if not (math.isfinite(ua) and math.isfinite(va) and math.isfinite(ub) and math.isfinite(vb)):
        return math.nan, OUTSIDE_DEM
    # clip to the node box [0, nx-1] x [0, ny-1]
    s0 = 0.0
    s1 = 1.0
    eps = 1e-12
    for axis in range(2):
        a = ua if axis == 0 else va
        d = du if axis == 0 else dv
        top = (nx - 1.0) if axis == 0 else (ny - 1.0)
        if d == 0.0:
            if a < -eps or a > top + eps:
                return math.nan, OUTSIDE_DEM
        else:
            t_lo = (0.0 - a) / d
            t_hi = (top - a) / d
            if t_lo > t_hi:
                t_lo, t_hi = t_hi, t_lo
            s0 = max(s0, t_lo)
            s1 = min(s1, t_hi)
    if s1 < s0:
        return math.nan, OUTSIDE_DEM
    if s0 < 1e-12:
        s0 = 0.0
    leaves = s1 < 1.0 - 1e-12
    # fast path: the whole segment inside the grid and inside one cell (coarse DEMs, short segments)
    if s0 == 0.0 and not leaves:
        j = min(int(ua), nx - 2)
        i = min(int(va), ny - 2)
        if j == min(int(ub), nx - 2) and i == min(int(vb), ny - 2):
            s_hit = _cell_hit(h, i, j, ua, va, za, du, dv, dz, 0.0, 1.0)
            if s_hit == -2.0:
                return math.nan, NODATA
            if s_hit >= 0.0:
                return s_hit, OK
            return math.nan, NO_INTERSECTION
    s, fl = _walk(h, tile_max, ua, va, za, du, dv, dz, s0, s1)
    if fl != -1:
        return s, fl
    if leaves:
        return math.nan, OUTSIDE_DEM
    return math.nan, NO_INTERSECTION


@kernel(parallel=True)
def _segments_loop(h, tile_max, ua, va, za, ub, vb, zb, s_out, flag_out):
    for k in prange(ua.shape[0]):
        s, f = _first_hit(h, tile_max, ua[k], va[k], za[k], ub[k], vb[k], zb[k])
        s_out[k] = s
        flag_out[k] = f


@kernel(parallel=True)
def _rays_loop(h, tile_max, x0, y0, dx, dy, z_top, z_bot, origin, direction, out, flag_out):
    """ENU rays against the grid: segment from height z_top down to z_bot (or from the origin if lower)."""
    for k in prange(origin.shape[0]):
        ox = origin[k, 0]
        oy = origin[k, 1]
        oz = origin[k, 2]
        ddx = direction[k, 0]
        ddy = direction[k, 1]
        ddz = direction[k, 2]
        if not (ddz < 0.0) or not (oz > z_bot):
            out[k, 0] = math.nan
            out[k, 1] = math.nan
            out[k, 2] = math.nan
            flag_out[k] = NO_INTERSECTION
            continue
        lam_a = (z_top - oz) / ddz
        if lam_a < 0.0:
            lam_a = 0.0
        lam_b = (z_bot - oz) / ddz
        ua = (ox + lam_a * ddx - x0) / dx
        va = (oy + lam_a * ddy - y0) / dy
        ub = (ox + lam_b * ddx - x0) / dx
        vb = (oy + lam_b * ddy - y0) / dy
        za = oz + lam_a * ddz
        zb = oz + lam_b * ddz
        s, f = _first_hit(h, tile_max, ua, va, za, ub, vb, zb)
        flag_out[k] = f
        if f == OK:
            lam = lam_a + s * (lam_b - lam_a)
            out[k, 0] = ox + lam * ddx
            out[k, 1] = oy + lam * ddy
            out[k, 2] = oz + lam * ddz
        else:
            out[k, 0] = math.nan
            out[k, 1] = math.nan
            out[k, 2] = math.nan


@kernel(inline="always")
def bilinear(h, u, v):
    """Bilinear height at fractional node (u, v) with the cell's partial derivatives; flag for holes.

    Returns ``(z, dz_du, dz_dv, flag)``.
    """
    ny = h.shape[0]
    nx = h.shape[1]
    if not (u >= 0.0 and u <= nx - 1.0 and v >= 0.0 and v <= ny - 1.0):
        return math.nan, 0.0, 0.0, OUTSIDE_DEM
    j = min(int(u), nx - 2)
    i = min(int(v), ny - 2)
    a = u - j
    b = v - i
    h00 = h[i, j]
    h01 = h[i, j + 1]
    h10 = h[i + 1, j]
    h11 = h[i + 1, j + 1]
    if math.isnan(h00) or math.isnan(h01) or math.isnan(h10) or math.isnan(h11):
        return math.nan, 0.0, 0.0, NODATA
    p = h01 - h00
    q = h10 - h00
    r = h00 - h01 - h10 + h11
    return h00 + p * a + q * b + r * a * b, p + r * b, q + r * a, OK


# the same loop without threads, for small calls (waking the second thread costs more than it takes)
_rays_loop_serial = kernel(parallel=False)(serial_twin(getattr(_rays_loop, "py_func", _rays_loop)))

first_hit = _first_hit
box_cells = _box_cells
level_for_width = _level_for_width
narrow_step = _narrow_step
cell_hit = _cell_hit
patch_quadratic = _patch_quadratic


@kernel(parallel=True)
def _heights_loop(h, x0, y0, dx, dy, x, y, out):
    for k in prange(x.shape[0]):
        z, _du, _dv, flag = bilinear(h, (x[k] - x0) / dx, (y[k] - y0) / dy)
        out[k] = z if flag == OK else math.nan


def heights_at(grid: HeightGrid, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear heights (N,) at horizontal positions (N,) (compiled); NaN outside the grid or next to no-data.

    Parameters
    ----------
    grid : HeightGrid
    x, y : ndarray, shape (N,)
        Same horizontal coordinates as the grid (metres of a local frame, or degrees).

    Returns
    -------
    ndarray, shape (N,)
        Metres.
    """
    x = np.ascontiguousarray(np.ravel(x), dtype=np.float64)
    y = np.ascontiguousarray(np.ravel(y), dtype=np.float64)
    out = np.empty(x.shape[0])
    for start in range(0, x.shape[0], CHUNK):
        sl = slice(start, min(start + CHUNK, x.shape[0]))
        _heights_loop(grid.heights, grid.x0, grid.y0, grid.dx, grid.dy, x[sl], y[sl], out[sl])
    return out


def intersect_segments(
    grid: HeightGrid, ua: np.ndarray, va: np.ndarray, za: np.ndarray, ub: np.ndarray, vb: np.ndarray,
    zb: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """First intersection of straight segments in grid coordinates with the DEM surface.

    Parameters
    ----------
    grid : HeightGrid
    ua, va, za : ndarray, shape (N,)
        Start of each segment (the end nearer the sensor): fractional node column, row and height (metres).
    ub, vb, zb : ndarray, shape (N,)
        End of each segment; ``zb < za``.

    Returns
    -------
    s : ndarray, shape (N,)
        Segment parameter of the hit in [0, 1] (point = start + s (end - start)); NaN unless the flag is OK.
    flag : ndarray of int8, shape (N,)
        :data:`OK`, :data:`OUTSIDE_DEM`, :data:`NODATA` or :data:`NO_INTERSECTION`.
    """
    arrays = [np.ascontiguousarray(np.ravel(a), dtype=np.float64) for a in (ua, va, za, ub, vb, zb)]
    n = arrays[0].shape[0]
    if any(a.shape[0] != n for a in arrays):
        raise InputError("segment coordinate arrays must all have the same length")
    s = np.empty(n)
    flag = np.empty(n, np.int8)
    for start in range(0, n, CHUNK):
        sl = slice(start, min(start + CHUNK, n))
        _segments_loop(grid.heights, grid.tile_max, *(a[sl] for a in arrays), s[sl], flag[sl])
    return s, flag


def intersect_rays(origin: np.ndarray, direction: np.ndarray, grid: HeightGrid) -> tuple[np.ndarray, np.ndarray]:
    """First intersection of rays (local ENU, metres) with a DEM grid in the same frame.

    Parameters
    ----------
    origin : ndarray, shape (N, 3)
        Ray origins (perspective centres), metres.
    direction : ndarray, shape (N, 3)
        Directions (any length, pointing down: ``direction[:, 2] < 0``).
    grid : HeightGrid
        Heights are the ``up`` coordinate; ``x`` east, ``y`` north.

    Returns
    -------
    points : ndarray, shape (N, 3)
        Intersections, metres; NaN rows where the flag is not :data:`OK`.
    flag : ndarray of int8, shape (N,)
    """
    origin = np.ascontiguousarray(origin, dtype=np.float64)
    direction = np.ascontiguousarray(direction, dtype=np.float64)
    if origin.ndim != 2 or origin.shape[1] != 3 or direction.shape != origin.shape:
        raise InputError(f"origin and direction must both have shape (N, 3), got {origin.shape} and {direction.shape}")
    n = origin.shape[0]
    out = np.empty((n, 3))
    flag = np.empty(n, np.int8)
    # the slab [z_min, z_max] widened by a hair so a hit on the highest/lowest node is inside the segment
    pad = 1e-9 * max(1.0, abs(grid.z_max), abs(grid.z_min))
    z_top, z_bot = grid.z_max + pad, grid.z_min - pad
    for start in range(0, n, CHUNK):
        sl = slice(start, min(start + CHUNK, n))
        kernel = _rays_loop if sl.stop - sl.start >= PARALLEL_MIN_POINTS else _rays_loop_serial
        kernel(grid.heights, grid.tile_max, grid.x0, grid.y0, grid.dx, grid.dy, z_top, z_bot,
                   origin[sl], direction[sl], out[sl], flag[sl])
    return out, flag
