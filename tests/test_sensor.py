"""The sensor interface (explorer/sensor.py) on MPC scenes: conformance, exact projection, time range,
explicit capabilities.  RPC sensors: tests/rpc/test_rpc_sensor.py; rigorous models: tests/real/."""

from __future__ import annotations

import json

import numpy as np
import pytest

from explorer.errors import SceneFileError
from explorer.presets import build_scene
from explorer.real.linescan import RigorousLineScanScene
from explorer.scene import RIGOROUS_SCENE_FORMAT, Scene
from explorer.sensor import PolynomialExteriorSensor, Sensor, has_polynomial_exterior


@pytest.mark.parametrize("preset", ["WSU", "agile"])
def test_scene_ground_to_image_inverts_image_to_ground(preset):
    scene = build_scene(preset, relief_m=0.0)
    rng = np.random.default_rng(3)
    row = rng.uniform(0, scene.n_rows - 1, 200)
    col = rng.uniform(0, scene.n_columns - 1, 200)
    ground = scene.image_to_ground(row, col, height=rng.uniform(-300, 900, 200))
    r, c = scene.ground_to_image(ground)
    assert np.max(np.abs(r - row)) < 1e-7 and np.max(np.abs(c - col)) < 1e-7


def test_scene_ground_to_image_flags_points_off_the_image_by_nan():
    scene = build_scene("WSU")
    far = scene.image_to_ground(np.array([-10.0 * scene.n_rows]), np.array([10.0]), height=0.0)
    r, c = scene.ground_to_image(np.vstack([far, far + 1.0]))
    assert np.all(np.isnan(r)) and np.all(np.isnan(c))


def test_time_range_is_the_first_and_last_scanline_edges():
    scene = build_scene("ISB")
    t0, t1 = scene.time_range()
    lp, r0 = scene.timing.line_period_s, scene.timing.reference_row
    assert t0 == pytest.approx((-0.5 - r0) * lp, rel=1e-15)
    assert t1 == pytest.approx((scene.n_rows - 0.5 - r0) * lp, rel=1e-15)


def test_scenes_implement_the_sensor_protocol_and_declare_capabilities():
    scene = build_scene("WSU")
    assert isinstance(scene, Sensor) and isinstance(scene, PolynomialExteriorSensor)
    assert has_polynomial_exterior(scene)
    assert RigorousLineScanScene.has_polynomial_exterior is False
    assert not has_polynomial_exterior(object())


def test_scene_load_refuses_a_rigorous_file_with_a_pointer_to_load_scene(tmp_path):
    path = tmp_path / "rig.json"
    path.write_text(json.dumps({"format": RIGOROUS_SCENE_FORMAT}))
    with pytest.raises(SceneFileError, match="load_scene"):
        Scene.load(path)
