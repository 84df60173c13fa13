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
