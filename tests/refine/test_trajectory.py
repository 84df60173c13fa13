"""The original and adjusted trajectory of a refinement against closed forms: a known correction of the MPC
polynomials moves every perspective centre by exactly its offset (plus drift x time) and turns the camera by
the rotation of the corrected angles; the exaggeration multiplies both; an RPC has no trajectory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from explorer.geometry.rotations import rotation_from_opk  # noqa: E402
from explorer.presets import build_scene  # noqa: E402
from explorer.refine.adjust import refine_images  # noqa: E402
from explorer.refine.points_io import PointTable  # noqa: E402
from explorer.refine.torch_scene import adjusted_scene  # noqa: E402
from explorer.refine.trajectory import (  # noqa: E402
    refinement_trajectory,
    rotation_angle,
    trajectory_comparison,
)
from tests.refine.cases import pleiades, simulate_points  # noqa: E402

DRIFT = np.array([5.0, -3.0, 2.0, 1e-5, -2e-5, 3e-5, 0.1, 0.2, -0.1, 1e-6, -1e-6, 2e-6])


def _angles(scene, t):
    return np.stack([np.polynomial.polynomial.polyval(t, c) for c in scene.exterior.attitude_coeffs], axis=1)


def test_known_correction_moves_and_turns_by_its_closed_form():
    scene = build_scene("WSU")
    moved = adjusted_scene(scene, "attitude-drift", DRIFT)
    comp = trajectory_comparison(scene, moved, n=9)
    t = comp.time_s
    np.testing.assert_allclose(comp.rows[[0, -1]], [-0.5, scene.n_rows - 0.5])
    np.testing.assert_allclose(comp.displacement_m, DRIFT[0:3] + DRIFT[6:9] * t[:, None], atol=1e-7)
    ang = _angles(scene, t)
    new = ang + DRIFT[3:6] + DRIFT[9:12] * t[:, None]
    want = rotation_from_opk(new[:, 0], new[:, 1], new[:, 2]) @ np.transpose(
        rotation_from_opk(ang[:, 0], ang[:, 1], ang[:, 2]), (0, 2, 1))
    np.testing.assert_allclose(comp.attitude_change, want, atol=1e-13)


def test_an_omega_offset_turns_by_exactly_that_angle_and_the_exaggeration_multiplies_it():
    scene = build_scene("WSU")
    delta = 3e-6
    comp = trajectory_comparison(scene, adjusted_scene(scene, "attitude", np.array([0, 0, 0, delta, 0, 0.0])), n=5)
    np.testing.assert_allclose(comp.attitude_change_rad, delta, rtol=1e-7)  # R_x(w + d) R_x(w)^T = R_x(d)
    np.testing.assert_allclose(comp.displacement_m, 0.0, atol=1e-9)
    centres, att = comp.exaggerated(1000.0)
    np.testing.assert_allclose(centres, comp.original_centre_m, atol=1e-9)
    change = att @ np.transpose(comp.original_attitude, (0, 2, 1))
    np.testing.assert_allclose(rotation_angle(change), 1000.0 * delta, rtol=1e-7)
    ang = _angles(scene, comp.time_s)
    want = rotation_from_opk(ang[:, 0] + 1000 * delta, ang[:, 1], ang[:, 2])
    np.testing.assert_allclose(att, want, atol=1e-12)
    shift = trajectory_comparison(scene, adjusted_scene(scene, "attitude", np.array([3.0, -4.0, 0, 0, 0, 0])))
    centres, _ = shift.exaggerated(50.0)
    np.testing.assert_allclose(centres - shift.original_centre_m, np.tile([150.0, -200.0, 0.0], (25, 1)), atol=1e-7)
    assert shift.summary()["displacement_m"] == pytest.approx([5.0, 5.0], abs=1e-9)


def test_rotation_angle_small_and_large():
    for a in (1e-12, 1e-6, 0.5, 3.0):
        r = rotation_from_opk(np.array([0.0]), np.array([a]), np.array([0.0]))
        assert rotation_angle(r)[0] == pytest.approx(a, rel=1e-9)


def test_refinement_trajectory_is_the_reports_parameters():
    """The view's trajectory of an adjustment equals the report's parameters (position offsets in metres, the
    corrected angles), and a noise-free adjustment recovers the true offsets."""
    scene = build_scene("WSU")
    true = np.array([20.0, -10.0, 5.0, 1e-5, -1e-5, 2e-5])
    rng = np.random.default_rng(5)
    n = 40
    g = scene.image_to_ground(rng.uniform(0.02, 0.98, n) * scene.n_rows, rng.uniform(0.02, 0.98, n) * scene.n_columns,
                              height=rng.uniform(-300, 300, n))
    row, col = adjusted_scene(scene, "attitude", true).ground_to_image(g)
    lon, lat, h = scene.frame.enu_to_geodetic(g)
    ref = refine_images([scene], model="attitude", control=PointTable([f"g{i}" for i in range(n)], row, col,
                                                                      lon, lat, h), sigma_px=0.3)
    params = {p["name"]: p["value"] for p in ref.report()["parameters"]}
    comp = refinement_trajectory(ref)
    np.testing.assert_allclose(comp.displacement_m, np.tile([params["position_e_m"], params["position_n_m"],
                                                             params["position_u_m"]], (25, 1)), atol=1e-7)
    ang = _angles(scene, comp.time_s)
    d = np.array([params["omega_rad"], params["phi_rad"], params["kappa_rad"]])
    np.testing.assert_allclose(comp.adjusted_attitude, rotation_from_opk(*(ang + d).T), atol=1e-13)
    sigma = np.array([p["sigma"] for p in ref.report()["parameters"]])
    assert np.all(np.abs(ref.parameters - true) <= 3 * sigma + 1e-12)


def test_an_rpc_has_no_trajectory():
    rpc = pleiades()
    ref = refine_images([rpc], model="shift", control=simulate_points(rpc, 8, seed=1), sigma_px=0.3)
    with pytest.raises(ValueError, match="no trajectory"):
        refinement_trajectory(ref)


# ------------------------------------------------- rigorous (DIMAP) and CSM line scanners (explorer.refine.line_adjust)
PHR_2017 = Path(__file__).resolve().parents[1] / "data" / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML"
ORBITAL = Path(__file__).resolve().parents[1] / "data" / "usgscsm" / "orbitalLineScan.json"


@pytest.fixture(scope="module")
def line_scanners():
    from explorer.real.csm_camera import read_isd
    from explorer.real.csm_sensor import csm_scene
    from explorer.sources import load_source

    return {"dimap": load_source("dimap", str(PHR_2017)).scene, "csm": csm_scene(read_isd(ORBITAL))}


@pytest.mark.parametrize("which", ["dimap", "csm"])
def test_line_scanner_offsets_move_and_turn_by_their_closed_form(line_scanners, which):
    """A constant position offset (orbital axes at the middle time) moves every perspective centre by its length
    (the tables' interpolation reproduces a constant); a constant roll turns the camera by exactly that angle,
    whatever frames it is composed with."""
    from explorer.refine.line_adjust import adjusted_sensor, correction_for

    sensor = line_scanners[which]
    corr = correction_for(sensor, "position-attitude")
    moved = trajectory_comparison(sensor, adjusted_sensor(sensor, corr, np.array([30.0, -40.0, 0, 0, 0, 0])), n=9)
    np.testing.assert_allclose(np.linalg.norm(moved.displacement_m, axis=1), 50.0, rtol=1e-9)
    np.testing.assert_allclose(moved.attitude_change_rad, 0.0, atol=1e-12)
    if which == "dimap":  # ECEF tables: the ENU displacement is the orbital axes' combination, rotated to ENU
        want = sensor.frame.enu_to_ecef_rotation.T @ (corr.axes @ np.array([30.0, -40.0, 0.0]))
        np.testing.assert_allclose(moved.displacement_m, np.tile(want, (9, 1)), atol=1e-6)
    turned = trajectory_comparison(sensor, adjusted_sensor(sensor, corr, np.array([0, 0, 0, 2e-5, 0, 0])), n=9)
    np.testing.assert_allclose(turned.attitude_change_rad, 2e-5, rtol=1e-6)
    np.testing.assert_allclose(turned.displacement_m, 0.0, atol=1e-6)


def test_rigorous_refinement_trajectory_is_the_reports_parameters(line_scanners):
    """The trajectory the view draws for an adjusted DIMAP model: the displacement is the report's along / cross /
    radial offsets on the orbital axes (in ENU), the attitude change the angle of the report's roll, pitch, yaw."""
    from explorer.refine.line_adjust import adjusted_sensor, correction_for

    sensor = line_scanners["dimap"]
    corr = correction_for(sensor, "position-attitude")
    truth = adjusted_sensor(sensor, corr, np.array([60.0, -40.0, 20.0, 3e-5, -2e-5, 2e-5]))
    rng = np.random.default_rng(3)
    n = 30
    g = truth.image_to_ground(rng.uniform(0.05, 0.95, n) * sensor.n_rows, rng.uniform(0.05, 0.95, n) * sensor.n_columns,
                              height=rng.uniform(-300, 300, n))
    row, col = truth.ground_to_image(g)
    lon, lat, h = sensor.frame.enu_to_geodetic(g)
    ref = refine_images([sensor], model="position-attitude", sigma_px=0.3,
                        control=PointTable([f"g{i}" for i in range(n)], row + rng.normal(0, 0.3, n),
                                           col + rng.normal(0, 0.3, n), lon, lat, h))
    p = {q["name"]: q["value"] for q in ref.report()["parameters"]}
    comp = refinement_trajectory(ref, n=7)
    offset = np.array([p["along_m"], p["cross_m"], p["radial_m"]])
    want = sensor.frame.enu_to_ecef_rotation.T @ (corr.axes @ offset)
    np.testing.assert_allclose(comp.displacement_m, np.tile(want, (7, 1)), atol=1e-6)
    delta = rotation_from_opk(np.array([p["roll_rad"]]), np.array([p["pitch_rad"]]), np.array([p["yaw_rad"]]))
    np.testing.assert_allclose(comp.attitude_change_rad, rotation_angle(delta)[0], rtol=1e-6)
