"""mpc_scene_from_sensor: an MPC scene fitted through the Sensor interface, checked against the sensor."""

from __future__ import annotations

import numpy as np

from explorer.geometry.frames import LocalFrame
from explorer.real.mpc_fit import mpc_scene_from_sensor
from explorer.rpc import read_rpc
from explorer.rpc.sensor import RPCSensor
from tests.rpc.conftest import RPC_DIR


def test_an_mpc_scene_fitted_to_an_rpc_sensor_reproduces_the_rpc():
    rpc = read_rpc(RPC_DIR / "rpc_PLEIADES.xml")
    sensor = RPCSensor(rpc, LocalFrame(float(rpc.lat_offset), float(rpc.lon_offset), 0.0), line_period_s=1e-4)
    lo, hi = rpc.height_range(0.5)
    scene, report = mpc_scene_from_sensor(sensor, height_range=(lo, hi), degree=3, n=60, layers=3, n_check=100)
    assert (scene.n_rows, scene.n_columns) == (sensor.n_rows, sensor.n_columns)
    assert np.allclose(scene.time_range(), sensor.time_range(), rtol=1e-12, atol=1e-15)
    # independent check: points the RPC localises at random heights, projected by the fitted scene
    rng = np.random.default_rng(5)
    row = rng.uniform(0, sensor.n_rows - 1, 50)
    col = rng.uniform(0, sensor.n_columns - 1, 50)
    ground = sensor.image_to_ground(row, col, height=rng.uniform(lo, hi, 50))
    r, c = scene.ground_to_image(ground)
    err = np.hypot(r - row, c - col)
    assert np.max(err) < 0.01, np.max(err)  # from_rpc reaches 0.0008 px RMS on this file (degree 3)
    assert report.check_rmse_px < 0.01 and scene.metadata["mpc_fit"]["n_check"] == report.n_check
