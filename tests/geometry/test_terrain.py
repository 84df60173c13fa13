import numpy as np
import pytest

from explorer.geometry.terrain import (
    FlatTerrain,
    GridDEM,
    intersect_dem,
    intersect_plane,
    synthetic_relief,
)


def test_bilinear_is_exact_for_bilinear_surfaces():
    x = np.arange(6) * 10.0
    y = np.arange(5) * 20.0
    xx, yy = np.meshgrid(x, y)
    dem = GridDEM(0.0, 0.0, 10.0, 20.0, 3 + 0.2 * xx - 0.1 * yy + 0.001 * xx * yy)
    rng = np.random.default_rng(0)
    px, py = rng.uniform(0, 50, 100), rng.uniform(0, 80, 100)
    np.testing.assert_allclose(dem.height(px, py), 3 + 0.2 * px - 0.1 * py + 0.001 * px * py, atol=1e-12)


def test_outside_and_nodata_give_nan_not_extrapolation():
    h = np.full((4, 4), 10.0)
    h[1, 1] = -9999.0
    dem = GridDEM(0.0, 0.0, 1.0, 1.0, h, nodata=-9999.0)
    assert np.isnan(dem.height(np.array([-0.1]), np.array([1.0])))[0]
    assert np.isnan(dem.height(np.array([1.5]), np.array([1.5])))[0]
    assert dem.height(np.array([2.5]), np.array([2.5]))[0] == 10.0
    assert dem.min_height == dem.max_height == 10.0


def test_synthetic_relief_seeded_and_amplitude():
    a = synthetic_relief((0, 1000, 0, 2000), 300.0, seed=4, base_height_m=100.0)
    b = synthetic_relief((0, 1000, 0, 2000), 300.0, seed=4, base_height_m=100.0)
    c = synthetic_relief((0, 1000, 0, 2000), 300.0, seed=5, base_height_m=100.0)
    np.testing.assert_array_equal(a.heights, b.heights)
    assert not np.array_equal(a.heights, c.heights)
    assert np.isclose(np.abs(a.heights - 100.0).max(), 300.0)


def test_plane_intersection_exact():
    origin = np.array([[0.0, 0.0, 1000.0]])
    d = np.array([[0.6, 0.0, -0.8]])
    np.testing.assert_allclose(intersect_plane(origin, d, 200.0), [[600.0, 0.0, 200.0]])


def test_dem_intersection_does_not_skip_a_thin_ridge():
    # flat ground at 0 m with a 1-cell-wide, 500 m ridge at x = 1000 m: an oblique ray passes
    # above the ridge's foot only briefly; the first hit must be the ridge, not the ground behind
    x = np.arange(0, 3001, 10.0)
    h = np.zeros((3, x.size))
    h[:, 100] = 500.0  # x = 1000 m
    dem = GridDEM(0.0, -10.0, 10.0, 10.0, h)
    origin = np.array([[0.0, 0.0, 1200.0]])
    d = np.array([[1.0, 0.0, -0.8]])
    d /= np.linalg.norm(d)
    hit = intersect_dem(origin, d, dem)[0]
    assert 990.0 < hit[0] < 1010.0
    assert hit[2] == pytest.approx(dem.height(hit[:1], hit[1:2])[0], abs=1e-6)
    # ground truth by dense sampling along the ray
    lam = np.linspace(0, 3000, 3_000_001)
    p = origin + lam[:, None] * d
    first = np.argmax(p[:, 2] - dem.height(p[:, 0], p[:, 1]) <= 0)
    assert abs(lam[first] - np.linalg.norm(hit - origin[0])) < 2e-3


def test_dem_intersection_flags_rays_leaving_the_dem():
    dem = GridDEM(0.0, 0.0, 10.0, 10.0, np.zeros((11, 11)))
    origin = np.array([[50.0, 50.0, 100.0], [500.0, 500.0, 100.0]])
    d = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    out = intersect_dem(origin, d, dem)
    np.testing.assert_allclose(out[0], [50, 50, 0], atol=1e-9)
    assert np.all(np.isnan(out[1]))


def test_flat_terrain_height():
    assert FlatTerrain(12.5).height(np.zeros(3), np.zeros(3)).tolist() == [12.5] * 3
