"""CSM ISD -> project Scene: fit size against the CSM camera, methods on the scene, JSON round trip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from explorer.methods import create
from explorer.real.csm import body_fixed_to_enu, enu_to_body_fixed, read_isd, scene_from_isd
from explorer.scene import Scene

DATA = Path(__file__).resolve().parents[1] / "data" / "usgscsm"


@pytest.fixture(scope="module")
def ctx_scene():
    return scene_from_isd(DATA / "ctxLineScan.json", n_check=500)


def test_orbital_scene_fits_the_camera():
    scene = scene_from_isd(DATA / "orbitalLineScan.json", n_check=500)
    fit = scene.metadata["csm_fit"]
    assert fit["row_max_px"] < 0.05 and fit["col_max_px"] < 0.05
    # the frame helpers invert each other
    cam = read_isd(DATA / "orbitalLineScan.json")
    g = cam.image_to_ground([8.0], [8.0], 0.0).ground
    np.testing.assert_allclose(enu_to_body_fixed(scene, body_fixed_to_enu(scene, g)), g, rtol=0, atol=1e-6)


def test_ctx_scene_fit_reported(ctx_scene):
    fit = ctx_scene.metadata["csm_fit"]
    # the MPC polynomials cannot follow CTX's sampled attitude exactly: sub-pixel, measured and reported
    assert fit["row_max_px"] < 1.0 and fit["col_max_px"] < 1.0
    assert ctx_scene.shape == (11264, 5000)


@pytest.mark.parametrize("method", ["exact", "csm-secant"])
def test_exact_methods_on_ctx_scene(ctx_scene, method):
    rng = np.random.default_rng(0)
    rows = rng.uniform(0, ctx_scene.n_rows - 1, 3000)
    cols = rng.uniform(0, ctx_scene.n_columns - 1, 3000)
    ground = ctx_scene.image_to_ground(rows, cols, height=rng.uniform(-500, 500, 3000))
    res = create(method, ctx_scene).ground_to_image(ground)
    assert res.valid.all()
    assert np.max(np.abs(res.row - rows)) <= 1e-6
    assert np.max(np.abs(res.col - cols)) <= 1e-6


def test_ctx_scene_json_round_trip(ctx_scene, tmp_path):
    p = tmp_path / "ctx.json"
    ctx_scene.save(p)
    back = Scene.load(p)
    rows, cols = np.array([10.0, 5000.0]), np.array([20.0, 4000.0])
    np.testing.assert_array_equal(back.image_to_ground(rows, cols, height=0.0),
                                  ctx_scene.image_to_ground(rows, cols, height=0.0))
    assert back.metadata["csm"]["semi_major_m"] == 3396190.0


def test_ctx_harmonics_follow_the_attitude():
    """Attitude sinusoids fitted to what the polynomials leave bring the CTX scene closer to the CSM camera,
    and the exact methods stay exact on the scene (general evaluator: more than 8 jitter terms)."""
    scene = scene_from_isd(DATA / "ctxLineScan.json", harmonics=20, n_check=500)
    plain = scene_from_isd(DATA / "ctxLineScan.json", n_check=500)
    assert scene.metadata["csm_fit"]["row_max_px"] < 0.5 * plain.metadata["csm_fit"]["row_max_px"]
    assert scene.metadata["csm_fit"]["col_max_px"] < 0.5 * plain.metadata["csm_fit"]["col_max_px"]
    rng = np.random.default_rng(1)
    rows = rng.uniform(0, scene.n_rows - 1, 2000)
    cols = rng.uniform(0, scene.n_columns - 1, 2000)
    ground = scene.image_to_ground(rows, cols, height=0.0)
    res = create("exact", scene).ground_to_image(ground)
    assert res.valid.all() and np.max(np.abs(res.row - rows)) <= 1e-6 and np.max(np.abs(res.col - cols)) <= 1e-6


@pytest.mark.parametrize("turn_deg", [90.0, 30.0, 200.0])
def test_scene_of_a_turned_detector_is_the_camera(turn_deg):
    """A fly-by whose detector runs along the focal plane's x axis (or at any angle, the focal2pixel matrix
    turned with the camera): the MPC scene represents it exactly (straight flight, constant attitude), so its
    fit against the CSM camera is at round-off, as for the unturned detector."""
    from explorer.real.csm import camera_from_isd, scene_from_camera
    from tests.real.test_csm import flyby_isd

    scene = scene_from_camera(camera_from_isd(flyby_isd(detector_rotation_deg=turn_deg), source="turned"),
                              n_check=500)
    fit = scene.metadata["csm_fit"]
    assert fit["n"] == 500 and fit["row_max_px"] < 1e-8 and fit["col_max_px"] < 1e-8
