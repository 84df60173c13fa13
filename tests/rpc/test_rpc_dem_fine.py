"""RPC image to ground on a fine, rough DEM: the narrowed, cell-stepped search against a brute-force march.

The compiled kernel narrows each line of sight with the DEM's max/min pyramid and solves its cells in lockstep
over the points (:mod:`explorer.rpc.inverse`); on the coarse Pleiades DEM of ``test_rpc_dem.py`` nearly every
line of sight stays in one cell, so that path is exercised here on a seeded 3-arcsecond fractal terrain of
1,700 m relief with a cliff of about 60 degrees and an SRTM-like void.

Truth: the exact line of sight (the RPC inverse at 1,200 heights between the DEM's highest and lowest node,
each converged to 1e-9 px) against the DEM's own numpy bilinear heights: the first sampled level at or below
the surface, then bisection on the height -- or no-data where the march meets the void first.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from explorer.geometry.dem_intersection import NODATA, OK, HeightGrid
from explorer.geometry.terrain import mountain_heights
from explorer.rpc import read_rpc
from explorer.rpc.inverse import RPCInverse

DATA = Path(__file__).resolve().parents[1] / "data" / "rpc"
PHR_2018 = DATA / "PHRDIMAP_P1BP--2018122638935449CP.XML"
ARCSEC = 1.0 / 3600.0


def rough_grid(rpc, spacing_arcsec: float = 3.0, seed: int = 3) -> HeightGrid:
    """Fractal terrain (amplitude ~ 1/k^2), a mountain, a 60-degree cliff, a thin ridge, a 20 x 40-node void."""
    d = spacing_arcsec * ARCSEC
    lon0, lat0 = rpc.lon_offset - rpc.lon_scale - 0.02, rpc.lat_offset - rpc.lat_scale - 0.02
    nx = int(np.ceil((2 * rpc.lon_scale + 0.04) / d)) + 1
    ny = int(np.ceil((2 * rpc.lat_scale + 0.04) / d)) + 1
    z = mountain_heights((ny, nx), 200.0, 1900.0, seed)
    # a cliff: 150 m over one 90 m cell (about 60 degrees) along a column band
    z[:, int(0.6 * nx):] += 150.0
    # a thin ridge: one row of nodes 900 m up (flanks of 84 degrees, steeper than the lines of sight)
    z[int(0.7 * ny), :] += 900.0
    z[ny // 3: ny // 3 + 20, nx // 3: nx // 3 + 40] = np.nan
    return HeightGrid.from_array(z, lon0, lat0, d, d)


def brute_force(inverse: RPCInverse, grid: HeightGrid, row, col, n_levels: int = 1200):
    """First crossing of each exact line of sight with the bilinear DEM by march + bisection: (h, flag, g).

    ``g`` (levels, n) is terrain minus height along each line of sight at the sampled levels.
    """
    z_top, z_bot = grid.z_max + 1e-6, grid.z_min - 1e-6
    levels = np.linspace(z_top, z_bot, n_levels)
    n = row.size

    def dem_minus(h):  # (n,) terrain - height at the exact ground point of each pixel at height h
        lon, lat, flags = inverse.localize(row, col, h)
        assert np.all(flags == OK)
        u, v = grid.to_grid(lon, lat)
        j = np.clip(np.floor(u).astype(int), 0, grid.heights.shape[1] - 2)
        i = np.clip(np.floor(v).astype(int), 0, grid.heights.shape[0] - 2)
        a, b = u - j, v - i
        hh = grid.heights
        terrain = (hh[i, j] * (1 - a) * (1 - b) + hh[i, j + 1] * a * (1 - b) + hh[i + 1, j] * (1 - a) * b
                   + hh[i + 1, j + 1] * a * b)
        return terrain - h

    g = np.stack([dem_minus(np.full(n, z)) for z in levels])  # (levels, n)
    below = (g >= 0.0) | np.isnan(g)
    first = np.argmax(below, axis=0)
    assert below.any(axis=0).all()
    void_first = np.isnan(g[first, np.arange(n)])
    hi, lo = levels[first - 1], levels[first]
    for _ in range(45):
        mid = 0.5 * (hi + lo)
        under = dem_minus(mid) >= 0.0
        lo = np.where(under, mid, lo)
        hi = np.where(under, hi, mid)
    return 0.5 * (hi + lo), np.where(void_first, NODATA, OK), g


@pytest.fixture(scope="module")
def rough():
    """The Pleiades 2018 RPC, the rough grid and the RPC's inverse over the grid's heights."""
    rpc = read_rpc(PHR_2018)
    grid = rough_grid(rpc)
    return rpc, grid, RPCInverse.for_model(rpc, grid.z_min - 1.0, grid.z_max + 1.0)


def random_pixels(rpc, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    rows, cols = rpc.image_size
    return rng.uniform(0, rows - 1, n), rng.uniform(0, cols - 1, n)


def test_rough_dem_first_hit_matches_brute_force_march(rough):
    rpc, grid, inverse = rough
    row, col = random_pixels(rpc, 5000, 11)
    # and pixels whose lines of sight meet the void and the cliff
    lon_void = grid.x0 + grid.dx * (grid.heights.shape[1] // 3 + 20)
    lat_void = grid.y0 + grid.dy * (grid.heights.shape[0] // 3 + 10)
    lon_cliff = grid.x0 + grid.dx * int(0.6 * grid.heights.shape[1])
    lat_ridge = grid.y0 + grid.dy * int(0.7 * grid.heights.shape[0])
    extra_lon = np.concatenate([lon_void + np.linspace(-0.002, 0.002, 40), np.full(60, lon_cliff),
                                np.repeat(np.linspace(lon_void, lon_cliff, 20), 50)])
    extra_lat = np.concatenate([np.full(40, lat_void), lat_void + np.linspace(-0.05, 0.05, 60),
                                np.tile(lat_ridge + np.linspace(-0.0012, 0.0012, 50), 20)])
    r_extra, c_extra = rpc.projection(extra_lon, extra_lat, np.full(extra_lon.size, 1000.0))
    row, col = np.concatenate([row, r_extra]), np.concatenate([col, c_extra])

    lon, lat, h, flags = inverse.on_dem(row, col, grid)
    h_true, flag_true, march_g = brute_force(inverse, grid, row, col)
    assert np.array_equal(flags, flag_true), np.flatnonzero(flags != flag_true)
    assert (flags == NODATA).sum() >= 20 and (flags == OK).sum() >= 5000
    # lines of sight that cross the surface more than once (the ridge in front): the first crossing is kept
    crossings = (np.diff(np.sign(march_g), axis=0) != 0).sum(axis=0)
    assert (crossings[flags == OK] >= 3).sum() >= 40
    ok = flags == OK
    assert np.max(np.abs(h[ok] - h_true[ok])) < 1e-4
    r2, c2 = rpc.projection(lon[ok], lat[ok], h[ok], backend="numpy")
    assert np.max(np.hypot(r2 - row[ok], c2 - col[ok])) < 1e-6


def test_pyramid_bounds_every_box_of_cells():
    """Brute force: the entry chosen for a box bounds the min/max of all nodes of the box's cells."""
    from explorer.geometry.dem_intersection import level_for_width

    rng = np.random.default_rng(5)
    heights = rng.normal(size=(37, 53)).cumsum(axis=0).cumsum(axis=1)
    heights[10:13, 20:22] = np.nan
    grid = HeightGrid.from_array(heights, 0.0, 0.0, 1.0, 1.0)
    hi_nodes = np.where(np.isfinite(heights), heights, np.inf)
    lo_nodes = np.where(np.isfinite(heights), heights, -np.inf)
    levels = grid.bound_levels
    for _ in range(3000):
        cu_lo, cv_lo = rng.integers(0, 52), rng.integers(0, 36)
        cu_hi, cv_hi = rng.integers(cu_lo, min(52, cu_lo + 20)), rng.integers(cv_lo, min(36, cv_lo + 20))
        k = level_for_width(levels, max(cu_hi - cu_lo, cv_hi - cv_lo))
        idx = levels[k, 0] + ((cv_lo + cv_hi) // 2 >> k) * levels[k, 2] + ((cu_lo + cu_hi) // 2 >> k)
        assert grid.bound_hi[idx] >= hi_nodes[cv_lo:cv_hi + 2, cu_lo:cu_hi + 2].max()
        assert grid.bound_lo[idx] <= lo_nodes[cv_lo:cv_hi + 2, cu_lo:cu_hi + 2].min()


def test_same_bits_on_one_and_two_threads(monkeypatch, rough):
    """The points are split at block boundaries, so the thread count cannot change a result."""
    from explorer import _threads

    rpc, grid, inverse = rough
    row, col = random_pixels(rpc, 60_000, 4)
    results = {}
    for threads in (1, 2, 3):
        monkeypatch.setattr(_threads, "n_threads", lambda threads=threads: threads)
        results[threads] = inverse.on_dem(row, col, grid)
        results[threads, "h"] = inverse.localize(row, col, np.full(row.size, 900.0))
    for threads in (2, 3):
        for a, b in zip(results[1], results[threads], strict=True):
            assert np.array_equal(a, b, equal_nan=True)
        for a, b in zip(results[1, "h"], results[threads, "h"], strict=True):
            assert np.array_equal(a, b, equal_nan=True)
