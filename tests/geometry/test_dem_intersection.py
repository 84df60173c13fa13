"""The compiled line-of-sight / DEM kernel against closed forms and a brute-force march.

Synthetic DEMs whose bilinear surface is piecewise planar along the rays (profiles in x only, nodes at
the break lines), so every intersection has a closed form: a tilted plane, a ridge in front of a valley
(hit just below its crest, missed just above), a no-data hole (SRTM void), a ray leaving the DEM, a
60-degree wall, and an upward ray.
"""

from __future__ import annotations

import numpy as np
import pytest

from explorer.geometry.dem_intersection import (
    NO_INTERSECTION,
    NODATA,
    OK,
    OUTSIDE_DEM,
    HeightGrid,
    intersect_rays,
)
from explorer.geometry.terrain import GridDEM


def profile_grid(profile: np.ndarray, ny: int = 40, dx: float = 10.0, peak: float | None = None) -> HeightGrid:
    """Grid of ``profile`` (heights at x = j dx) repeated along y (nodes y = i dx); an optional far peak
    (in the last rows, away from the test rays) raises the DEM maximum so the walk starts high."""
    h = np.tile(np.asarray(profile, float), (ny, 1))
    if peak is not None:
        h[-2:, :] = peak
    return HeightGrid.from_array(h, 0.0, 0.0, dx, dx)


def ray_towards(target: np.ndarray, direction: np.ndarray, back: float = 5000.0) -> tuple[np.ndarray, np.ndarray]:
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    return (np.asarray(target, float) - back * d)[None, :], d[None, :]


def test_tilted_plane_matches_ray_plane_closed_form():
    rng = np.random.default_rng(3)
    nx, ny, d = 60, 50, 5.0
    a, b, c = 0.3, -0.2, 100.0  # h = a x + b y + c: bilinear interpolation of a plane is the plane
    x = np.arange(nx) * d
    y = np.arange(ny) * d
    heights = a * x[None, :] + b * y[:, None] + c
    grid = HeightGrid.from_array(heights, 0.0, 0.0, d, d)
    n = 2000
    xy = rng.uniform([20, 20], [280, 230], (n, 2))
    target = np.column_stack([xy, a * xy[:, 0] + b * xy[:, 1] + c])
    direction = np.column_stack([rng.uniform(-0.4, 0.4, (n, 2)), -np.ones(n)])
    origin = target - rng.uniform(500, 800, n)[:, None] * direction
    points, flags = intersect_rays(origin, direction, grid)
    # closed form: o_z + t d_z = a (o_x + t d_x) + b (o_y + t d_y) + c
    t = (a * origin[:, 0] + b * origin[:, 1] + c - origin[:, 2]) / (direction[:, 2] - a * direction[:, 0]
                                                                  - b * direction[:, 1])
    truth = origin + t[:, None] * direction
    # a ray may leave the grid above the plane before reaching it (then it is flagged, not extrapolated)
    lam_top = (heights.max() - origin[:, 2]) / direction[:, 2]
    top = origin + lam_top[:, None] * direction
    inside = (top[:, 0] > 0) & (top[:, 0] < x[-1]) & (top[:, 1] > 0) & (top[:, 1] < y[-1])
    assert inside.sum() > 1500
    assert np.all(flags[inside] == OK)
    np.testing.assert_allclose(points[inside], truth[inside], atol=1e-8)


def ridge_profile() -> np.ndarray:
    """Flat 0 m, a ridge with crest 100 m at x = 200 (faces of slope 5 over 20 m), flat 0 m behind."""
    x = np.arange(61) * 10.0
    return np.maximum(0.0, 100.0 - 5.0 * np.abs(x - 200.0))


@pytest.mark.parametrize("clearance", [1e-3, -1e-3])
def test_ray_grazing_a_ridge_hits_it_or_lands_in_the_valley_behind(clearance):
    grid = profile_grid(ridge_profile(), peak=300.0)
    slope = 0.5  # travelling +x over the crest at y = 100, 1 mm above or below it
    crest = np.array([200.0, 100.0, 100.0 + clearance])
    origin, direction = ray_towards(crest, [1.0, 0.0, -slope])
    points, flags = intersect_rays(origin, direction, grid)
    assert flags[0] == OK
    if clearance > 0:
        # misses the crest; the back face falls at 5 m/m, faster than the ray: lands on the flat ground behind
        x_hit = 200.0 + (100.0 + clearance) / slope
        np.testing.assert_allclose(points[0], [x_hit, 100.0, 0.0], atol=1e-7)
    else:
        # hits the front face z = 100 - 5 (200 - x) just before the crest
        # 100 + clearance + slope (200 - x) ... ray z at x: 100 + clearance - slope (x - 200)
        x_hit = 200.0 + clearance / (5.0 + slope)
        z_hit = 100.0 - 5.0 * (200.0 - x_hit)
        np.testing.assert_allclose(points[0], [x_hit, 100.0, z_hit], atol=1e-7)
        assert x_hit < 200.0


def test_thin_ridge_is_not_skipped_by_a_steep_descent():
    # a one-cell spike of 60 m in otherwise flat 0 m terrain; a ray clipping its flank must stop there
    profile = np.zeros(61)
    profile[30] = 60.0
    grid = profile_grid(profile, peak=300.0)
    target = np.array([295.0, 100.0, 30.0])  # on the front face z = 6 (x - 290) at x = 295
    origin, direction = ray_towards(target, [1.0, 0.0, -0.3])
    points, flags = intersect_rays(origin, direction, grid)
    assert flags[0] == OK
    np.testing.assert_allclose(points[0], target, atol=1e-7)


def test_sixty_degree_wall():
    slope = np.tan(np.radians(60.0))
    x = np.arange(61) * 10.0
    profile = np.clip((x - 200.0) * slope, 0.0, 10.0 * 8 * slope)  # wall from x = 200 to 280 (138.6 m high)
    grid = profile_grid(profile)
    # a ray travelling +x, 30 degrees below the horizontal, meets the wall face at height 50 m
    target = np.array([200.0 + 50.0 / slope, 100.0, 50.0])
    origin, direction = ray_towards(target, [np.cos(np.radians(30.0)), 0.0, -np.sin(np.radians(30.0))], back=400.0)
    points, flags = intersect_rays(origin, direction, grid)
    assert flags[0] == OK
    np.testing.assert_allclose(points[0], target, atol=1e-7)
    assert abs(points[0, 2] - (points[0, 0] - 200.0) * slope) < 1e-7


def test_nodata_hole_is_flagged_and_a_hit_before_it_is_kept():
    h = np.full((30, 30), 10.0)
    h[14:17, 14:17] = np.nan  # an SRTM void
    h[-1, -1] = 200.0  # raise the maximum (far corner)
    grid = HeightGrid.from_array(h, 0.0, 0.0, 10.0, 10.0)
    # vertical ray into the hole, vertical ray beside it
    origin = np.array([[150.0, 150.0, 1000.0], [50.0, 50.0, 1000.0]])
    direction = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    points, flags = intersect_rays(origin, direction, grid)
    assert flags.tolist() == [NODATA, OK]
    assert np.all(np.isnan(points[0]))
    np.testing.assert_allclose(points[1], [50.0, 50.0, 10.0], atol=1e-9)
    # an oblique ray reaching the surface before the hole: OK; one passing over the hole first: NODATA
    o2, d2 = ray_towards(np.array([100.0, 155.0, 10.0]), [1.0, 0.0, -0.5])
    p2, f2 = intersect_rays(o2, d2, grid)
    assert f2[0] == OK
    np.testing.assert_allclose(p2[0], [100.0, 155.0, 10.0], atol=1e-8)
    o3, d3 = ray_towards(np.array([190.0, 155.0, 10.0]), [1.0, 0.0, -0.5])
    assert intersect_rays(o3, d3, grid)[1][0] == NODATA


def test_ray_leaving_the_dem_and_upward_ray():
    grid = profile_grid(np.zeros(21) + 5.0, ny=21, peak=100.0)  # 200 m x 200 m, 5 m flat, 100 m peak rows
    # descends so slowly that it leaves through x = 200 before reaching 5 m
    origin = np.array([[150.0, 50.0, 100.0], [50.0, 50.0, 300.0], [100.0, 100.0, 300.0]])
    direction = np.array([[1.0, 0.0, -0.1], [0.0, 0.0, 1.0], [-1.0, 0.0, -0.2]])
    points, flags = intersect_rays(origin, direction, grid)
    assert flags[0] == OUTSIDE_DEM
    assert flags[1] == NO_INTERSECTION
    assert flags[2] == OUTSIDE_DEM  # reaches the 100 m level only after leaving through x = 0
    assert np.all(np.isnan(points))


def test_random_relief_against_brute_force_march():
    from explorer.geometry.terrain import synthetic_relief

    dem = synthetic_relief((0.0, 2000.0, 0.0, 2000.0), 300.0, seed=5, cell_m=25.0, correlation_cells=3.0)
    rng = np.random.default_rng(11)
    n = 300
    target = np.column_stack([rng.uniform(300, 1700, (n, 2)), np.zeros(n)])
    direction = np.column_stack([rng.uniform(-0.7, 0.7, (n, 2)), -np.ones(n)])
    origin = target - 2000.0 * direction
    points, flags = intersect_rays(origin, direction, dem.height_grid())
    # brute force: march 0.02 m steps along the ray from the top slab, first sign change, bisection
    lam_top = (dem.max_height + 1 - origin[:, 2]) / direction[:, 2]
    lam_bot = (dem.min_height - 1 - origin[:, 2]) / direction[:, 2]
    steps = np.linspace(0.0, 1.0, 40001)
    for k in range(0, n, 30):
        lam = lam_top[k] + steps * (lam_bot[k] - lam_top[k])
        p = origin[k] + lam[:, None] * direction[k]
        gap = p[:, 2] - dem.height(p[:, 0], p[:, 1])
        if not np.all(np.isfinite(gap)):
            continue
        first = np.argmax(gap <= 0)
        lo, hi = lam[first - 1], lam[first]
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            q = origin[k] + mid * direction[k]
            if q[2] - dem.height(q[:1], q[1:2])[0] > 0:
                lo = mid
            else:
                hi = mid
        truth = origin[k] + hi * direction[k]
        assert flags[k] == OK
        np.testing.assert_allclose(points[k], truth, atol=1e-6)
        assert abs(dem.height(points[k:k + 1, 0], points[k:k + 1, 1])[0] - points[k, 2]) < 1e-8


def test_griddem_nodata_value_and_errors():
    h = np.full((5, 5), 3.0)
    h[2, 2] = -32768.0
    dem = GridDEM(0.0, 0.0, 1.0, 1.0, h, nodata=-32768.0)
    points, flags = intersect_rays(np.array([[2.0, 2.0, 50.0]]), np.array([[0.0, 0.0, -1.0]]), dem.height_grid())
    assert flags[0] == NODATA
    from explorer.errors import InputError

    with pytest.raises(InputError, match="no valid height"):
        HeightGrid.from_array(np.full((3, 3), np.nan), 0, 0, 1, 1)
    with pytest.raises(InputError, match=r"shape \(N, 3\)"):
        intersect_rays(np.zeros((2, 2)), np.zeros((2, 2)), dem.height_grid())
