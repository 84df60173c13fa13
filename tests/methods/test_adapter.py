"""MethodSensor: a best-scanline method behind the Sensor interface (explorer/methods/adapter.py).

Truth: the scene's own ground to image by bracketing the along-track residual (geometry/bracket.py, independent
of the methods) and the simulated SCPs' image positions (the scene's own image to ground)."""

import numpy as np
import pytest

from explorer.errors import InputError
from explorer.methods.adapter import SCOP_LAYERS, MethodSensor
from explorer.points import simulate_points
from explorer.presets import build_scene
from explorer.sensor import Sensor


@pytest.fixture(scope="module")
def wsu():
    scene = build_scene("WSU")
    return scene, simulate_points(scene, 400, kind="scp")


def test_exact_behind_the_sensor_interface_is_the_scenes_ground_to_image(wsu):
    scene, pts = wsu
    sensor = MethodSensor.create(scene, "exact")
    assert isinstance(sensor, Sensor)
    assert (sensor.n_rows, sensor.n_columns) == (scene.n_rows, scene.n_columns)
    row, col = sensor.ground_to_image(pts.ground)
    r_ref, c_ref = scene.ground_to_image(pts.ground)
    assert np.max(np.hypot(row - r_ref, col - c_ref)) < 1e-6
    assert np.max(np.hypot(row - pts.row, col - pts.col)) < 1e-6
    # image to ground is the scene's own
    np.testing.assert_array_equal(sensor.image_to_ground(pts.row, pts.col), scene.image_to_ground(pts.row, pts.col))


def test_a_point_off_the_image_is_nan_never_extrapolated(wsu):
    scene, _ = wsu
    sensor = MethodSensor.create(scene, "exact")
    far = scene.footprint()[2] + np.array([5_000.0, 5_000.0, 0.0])  # beyond the last corner
    row, col = sensor.ground_to_image(far[None, :])
    assert np.isnan(row[0]) and np.isnan(col[0])


def test_a_learned_method_is_fitted_on_scops_from_the_scene(wsu):
    scene, pts = wsu
    sensor = MethodSensor.create(scene, "lrm", height_range=(-100.0, 100.0), scops=50)
    control = MethodSensor.control_points(scene, 50, (-100.0, 100.0))
    assert control.grid_shape[2] == SCOP_LAYERS
    assert set(np.round(control.ground[:, 2], 6)) == {-100.0, 0.0, 100.0}
    row, col = sensor.ground_to_image(pts.ground)
    err = np.hypot(row - pts.row, col - pts.col)
    assert np.all(np.isfinite(err))
    # an affine model of a pushbroom scene: small but not exact (measured 0.038 px on WSU)
    assert 1e-4 < np.max(err) < 0.2


def test_too_few_scops_are_refused(wsu):
    scene, _ = wsu
    with pytest.raises(InputError, match="SCOPs"):
        MethodSensor.create(scene, "lrm", scops=2)
