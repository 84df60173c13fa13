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


class TiltedPlane:
    """A terrain the package does not know: ``Z = z0 + gx X + gy Y``, implementing the Terrain protocol with
    its own closed-form first hit (a ray meets a plane once)."""

    def __init__(self, z0: float, gx: float, gy: float) -> None:
        self.z0, self.gx, self.gy = z0, gx, gy
        self.min_height, self.max_height, self.mean_height = z0 - 500.0, z0 + 500.0, z0

    def height(self, x, y):
        return self.z0 + self.gx * np.asarray(x) + self.gy * np.asarray(y)

    def intersect(self, origin, direction):
        # (o + t d).z = z0 + gx (o + t d).x + gy (o + t d).y  ->  t
        num = self.z0 + self.gx * origin[:, 0] + self.gy * origin[:, 1] - origin[:, 2]
        den = direction[:, 2] - self.gx * direction[:, 0] - self.gy * direction[:, 1]
        t = num / den
        points = origin + t[:, None] * direction
        ok = t > 0
        return np.where(ok[:, None], points, np.nan), np.where(ok, 0, 3).astype(np.int8)

    def to_dict(self):
        return {"kind": "tilted", "z0": self.z0, "gx": self.gx, "gy": self.gy}


def test_flat_and_grid_terrains_implement_the_terrain_interface():
    from explorer.geometry.terrain import Terrain

    assert isinstance(FlatTerrain(3.0), Terrain)
    assert isinstance(synthetic_relief((0, 100, 0, 100), 10.0, seed=1), Terrain)
    assert isinstance(TiltedPlane(0.0, 0.01, 0.0), Terrain)
    origin = np.array([[0.0, 0.0, 1000.0], [5.0, 5.0, 1000.0]])
    direction = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]])  # the second points up: no hit
    points, flags = FlatTerrain(200.0).intersect(origin, direction)
    np.testing.assert_allclose(points[0], [0.0, 0.0, 200.0])
    assert flags.tolist() == [0, 3] and np.isnan(points[1]).all()


@pytest.mark.parametrize("kind", ["scene", "rigorous"])
def test_a_new_terrain_needs_no_change_in_the_sensors(kind):
    """Scenes and rigorous models intersect any Terrain through its ``intersect``: image to ground on a tilted
    plane lands on the plane (its closed form) and ground to image (bracketing) returns the pixel."""
    from explorer.presets import build_scene

    if kind == "scene":
        scene = build_scene("SCB")
    else:
        from explorer.real.worldview import rigorous_scene_from_dg
        from tests.real.conftest import WV1

        scene = rigorous_scene_from_dg(WV1)
    plane = TiltedPlane(scene.terrain.mean_height, 0.02, -0.01)
    tilted = scene.with_terrain(plane)
    rng = np.random.default_rng(3)
    row = rng.uniform(0, scene.n_rows - 1, 50)
    col = rng.uniform(0, scene.n_columns - 1, 50)
    ground, flags = tilted.image_to_ground(row, col, return_flags=True)
    assert (flags == 0).all()
    np.testing.assert_allclose(ground[:, 2], plane.height(ground[:, 0], ground[:, 1]), atol=1e-6)
    r, c = tilted.ground_to_image(ground)
    assert np.max(np.hypot(r - row, c - col)) < 1e-5
    flat = scene.image_to_ground(row, col)  # the slope moved the points: the plane was really used
    assert np.max(np.abs(ground[:, 2] - flat[:, 2])) > 10.0
