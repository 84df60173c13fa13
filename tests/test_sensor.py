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


def test_project_flags_points_off_the_image_and_keeps_their_numbers():
    """project: the exact row/column of a point just off the image edge (not NaN), flagged invalid; on the image
    valid; the line geometry agrees with the scene's own exterior and rays."""
    scene = build_scene("WSU")
    rows = np.array([10.0, scene.n_rows - 1.0, scene.n_rows + 3.0])
    cols = np.array([5.0, 100.0, 50.0])
    ground = scene.image_to_ground(rows, cols, height=100.0)
    p = scene.project(ground)
    np.testing.assert_array_equal(p.valid, [True, True, False])
    np.testing.assert_allclose(p.row, rows, atol=1e-7)
    t = scene.line_time(rows)
    np.testing.assert_allclose(t, scene.scanline_time(rows), rtol=0, atol=0)
    origin, direction = scene.rays(rows, cols)
    np.testing.assert_allclose(scene.perspective_centre(t), origin, rtol=0, atol=1e-9)
    np.testing.assert_allclose(scene.look_direction(rows, cols), direction, rtol=0, atol=1e-15)
    # the look direction is the attitude applied to the camera ray of the detector (straight line, no distortion)
    x, y = scene.interior.detector_focal_plane(cols)
    v = np.stack([x, y, np.full(3, -scene.interior.focal_length_m)], axis=-1)
    d = np.einsum("nij,nj->ni", scene.attitude(t), v)
    np.testing.assert_allclose(d / np.linalg.norm(d, axis=1, keepdims=True), direction, atol=1e-12)


def test_localize_flags_rays_that_miss_a_dem():
    """localize on a DEM: the first hit with flag 0 on it, flag 1 (outside the DEM) for a ray beyond its edge."""
    from explorer.geometry.terrain import GridDEM

    scene = build_scene("WSU")
    fp = scene.footprint()
    x0, x1 = fp[:, 0].min(), fp[:, 0].max()
    y0, y1 = fp[:, 1].min(), fp[:, 1].max()
    # a flat DEM at 120 m over the western half of the footprint only
    dx, dy = (0.5 * (x1 - x0)) / 39, (y1 - y0 + 200.0) / 39
    dem = GridDEM(float(x0), float(y0 - 100.0), dx, dy, np.full((40, 40), 120.0))
    loc = scene.with_terrain(dem).localize(np.full(2, scene.n_rows / 2), np.array([1.0, scene.n_columns - 2.0]))
    inside = loc.valid
    assert inside.sum() == 1
    np.testing.assert_allclose(loc.ground[inside, 2], 120.0, atol=1e-6)
    assert set(loc.flags[~inside].tolist()) <= {1, 3} and np.isnan(loc.ground[~inside]).all()


def test_a_stand_in_in_another_frame_is_asked_through_body_fixed_coordinates():
    """StandIn converts the truth's ENU points into its own frame: the same scene placed in a frame 0.01 degree
    away answers for the same physical points exactly as the scene itself does."""
    from dataclasses import replace

    from explorer.geometry.frames import LocalFrame
    from explorer.sensor import StandIn

    scene = build_scene("WSU")
    f = scene.frame
    other = LocalFrame(f.lat0_deg + 0.01, f.lon0_deg - 0.01, f.h0_m + 5.0, f.body)
    rng = np.random.default_rng(8)
    ground = scene.image_to_ground(rng.uniform(0, scene.n_rows - 1, 50), rng.uniform(0, scene.n_columns - 1, 50),
                                   height=50.0)
    # the stand-in: the scene's geometry moved into the other frame (its exterior shifted/rotated accordingly is
    # not needed: StandIn must hand it the *other frame's* coordinates of the same points, which we check)
    seen = []

    class Probe:
        frame = other

        def ground_to_image(self, g):
            seen.append(g)
            return g[:, 0], g[:, 1]

    StandIn("probe", Probe(), f).ground_to_image(ground)  # type: ignore[arg-type]
    np.testing.assert_allclose(seen[0], other.ecef_to_enu(f.enu_to_ecef(ground)), atol=1e-9)
    assert np.max(np.abs(seen[0] - ground)) > 100.0  # really another frame
    same = StandIn("same", replace(scene), f)
    np.testing.assert_allclose(np.array(same.ground_to_image(ground)), np.array(scene.ground_to_image(ground)))
