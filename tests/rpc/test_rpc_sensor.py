"""RPCSensor: an RPC behind the Sensor interface, in local ENU metres."""

from __future__ import annotations

import numpy as np
import pytest

from explorer.errors import InputError
from explorer.geometry.frames import LocalFrame
from explorer.rpc import read_rpc
from explorer.rpc.sensor import RPCSensor
from explorer.sensor import Sensor
from tests.rpc.conftest import RPC_DIR


@pytest.fixture(scope="module")
def sensor():
    rpc = read_rpc(RPC_DIR / "rpc_WV2.xml")
    return RPCSensor(rpc, LocalFrame(float(rpc.lat_offset), float(rpc.lon_offset), 50.0), name="wv2")


def test_is_a_sensor(sensor):
    assert isinstance(sensor, Sensor)
    assert (sensor.n_rows, sensor.n_columns) == tuple(sensor.rpc.image_size)


def test_image_to_ground_lies_on_the_local_plane_and_projects_back(sensor):
    row, col, z = np.random.default_rng(0).uniform([0, 0, -100.0], [sensor.n_rows - 1, sensor.n_columns - 1, 400.0],
                                                   (100, 3)).T
    ground = sensor.image_to_ground(row, col, height=z)
    assert np.max(np.abs(ground[:, 2] - z)) < 1e-6  # on the local plane, not the ellipsoidal height
    lon, lat, h = sensor.frame.enu_to_geodetic(ground)
    r_rpc, c_rpc = sensor.rpc.projection(lon, lat, h)  # the RPC itself is the truth
    assert np.max(np.abs(r_rpc - row)) < 1e-6 and np.max(np.abs(c_rpc - col)) < 1e-6
    r, c = sensor.ground_to_image(ground)
    assert np.array_equal(r, r_rpc) and np.array_equal(c, c_rpc)


def test_footprint_corners_are_the_image_corners(sensor):
    corners = sensor.footprint(100.0)
    r, c = sensor.ground_to_image(corners)
    r1, c1 = sensor.n_rows - 0.5, sensor.n_columns - 0.5
    assert np.allclose(r, [-0.5, -0.5, r1, r1], atol=1e-6) and np.allclose(c, [-0.5, c1, c1, -0.5], atol=1e-6)


def test_time_range_needs_a_line_period(sensor):
    with pytest.raises(InputError, match="line_period_s"):
        sensor.time_range()
    timed = RPCSensor(sensor.rpc, sensor.frame, line_period_s=1e-4)
    assert timed.time_range() == (-0.5e-4, (sensor.n_rows - 0.5) * 1e-4)


def test_bad_ground_is_refused(sensor):
    with pytest.raises(InputError):
        sensor.ground_to_image(np.array([[0.0, np.nan, 0.0]]))


def test_default_terrain_is_the_plane_of_the_height_offset(sensor):
    row, col = np.array([10.0, 5000.0]), np.array([20.0, 3000.0])
    on_terrain = sensor.image_to_ground(row, col)
    assert np.array_equal(on_terrain, sensor.image_to_ground(row, col, height=sensor.mean_height))
    assert sensor.terrain.mean_height == sensor.mean_height


def test_localisation_on_a_dem_is_the_rpc_at_the_first_hit():
    """On a DEM: every point is a pair of the RPC itself (projects back to its pixel to 1e-6 px) and lies on the
    DEM (its height is the DEM's there, to the mm of the straight chord against the RPC's line of sight); a
    pixel whose line of sight leaves the DEM is flagged, never given a height."""
    from explorer.geometry.terrain import GridDEM

    rpc = read_rpc(RPC_DIR / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML")
    flat = RPCSensor(rpc)
    corners = np.vstack([flat.footprint(flat.mean_height - 300), flat.footprint(flat.mean_height + 300)])
    x = np.linspace(corners[:, 0].min() - 500, corners[:, 0].max() + 500, 300)
    y = np.linspace(corners[:, 1].min() - 500, corners[:, 1].max() + 500, 200)
    heights = flat.mean_height + 250.0 * np.sin(x[None, :] / 1500.0) * np.cos(y[:, None] / 900.0)
    heights[:40, :40] = np.nan  # a void in one corner
    dem = GridDEM(float(x[0]), float(y[0]), float(x[1] - x[0]), float(y[1] - y[0]), heights)
    s = flat.with_terrain(dem)
    rng = np.random.default_rng(3)
    row, col = rng.uniform(0, s.n_rows - 1, 2000), rng.uniform(0, s.n_columns - 1, 2000)
    loc = s.localize(row, col)
    ok = loc.valid
    assert 0.9 < ok.mean() < 1.0 and set(np.unique(loc.flags[~ok])) <= {1, 2, 3}
    assert np.isnan(loc.ground[~ok]).all()
    r, c = rpc.projection(*s.frame.enu_to_geodetic(loc.ground[ok]))
    assert np.max(np.abs(r - row[ok])) < 1e-6 and np.max(np.abs(c - col[ok])) < 1e-6
    assert np.max(np.abs(dem.height(loc.ground[ok, 0], loc.ground[ok, 1]) - loc.ground[ok, 2])) < 0.01
    # the first hit: no point of the line of sight above it is under the DEM (brute force along the line)
    i = np.flatnonzero(ok)[:50]
    for dz in np.linspace(1.0, 260.0, 40):
        above = s.image_to_ground(row[i], col[i], height=loc.ground[i, 2] + dz)
        h_dem = dem.height(above[:, 0], above[:, 1])
        assert np.all(~np.isfinite(h_dem) | (above[:, 2] >= h_dem - 0.01))
    assert np.array_equal(s.image_to_ground(row, col), loc.ground, equal_nan=True)


def test_shape_and_ground_sample_distance(sensor):
    assert sensor.shape == (sensor.n_rows, sensor.n_columns)
    gsd = sensor.ground_sample_distance()
    rc, cc = (sensor.n_rows - 1) / 2, (sensor.n_columns - 1) / 2
    g = sensor.image_to_ground(np.array([rc, rc + 1, rc]), np.array([cc, cc, cc + 1]), height=sensor.mean_height)
    assert gsd == pytest.approx((np.linalg.norm(g[1] - g[0]), np.linalg.norm(g[2] - g[0])), rel=1e-3)


def test_geodetic_entry_is_the_rpc_with_its_flags(sensor):
    """``project_geodetic``: the RPC's own projection of (lon, lat, h) and the flags ``project`` gives for the same
    points through the local frame (RPC validity and on the image), points off the image flagged."""
    rng = np.random.default_rng(4)
    row = rng.uniform(-300, sensor.n_rows + 300, 3000)
    col = rng.uniform(-300, sensor.n_columns + 300, 3000)
    ground = sensor.image_to_ground(row, col, height=rng.uniform(0.0, 300.0, 3000))
    ground = ground[np.isfinite(ground[:, 0])]
    lon, lat, h = sensor.frame.enu_to_geodetic(ground)
    geo = sensor.project_geodetic(lon, lat, h)
    r_rpc, c_rpc = sensor.rpc.projection(lon, lat, h)
    assert np.array_equal(geo.row, r_rpc) and np.array_equal(geo.col, c_rpc)
    enu = sensor.project(ground)
    assert np.array_equal(geo.valid, enu.valid) and 0.5 < geo.valid.mean() < 1.0
    on_image = (r_rpc >= -0.5) & (r_rpc <= sensor.n_rows - 0.5) & (c_rpc >= -0.5) & (c_rpc <= sensor.n_columns - 0.5)
    assert not np.any(geo.valid & ~on_image)


def test_and_inside_image_matches_the_definition():
    from explorer.rpc._kernels import and_inside_image
    from explorer.sensor import inside_image

    rng = np.random.default_rng(1)
    row, col = rng.uniform(-2, 12, 5000), rng.uniform(-2, 22, 5000)
    row[[0, 1, 2, 3]] = [-0.5, 9.5, np.nan, -0.5000001]
    valid = rng.uniform(size=5000) < 0.8
    expected = valid & inside_image(row, col, 10, 20)
    and_inside_image(row, col, valid, 10, 20)
    assert np.array_equal(valid, expected) and valid[0] == expected[0] and not valid[2] and not valid[3]
