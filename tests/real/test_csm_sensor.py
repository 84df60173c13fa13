"""The CSM camera as a Sensor (explorer.real.csm_sensor): against a camera with a closed-form answer built here,
and against the camera itself on the real usgscsm ISDs (tests/data/usgscsm, PROVENANCE there)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from explorer.geometry.frames import MARS
from explorer.methods import create
from explorer.points import simulate_points
from explorer.real.csm_camera import camera_from_isd, read_isd
from explorer.real.csm_sensor import CsmScene, csm_scene
from explorer.scene import Scene
from explorer.sensor import LineGeometrySensor, Sensor

DATA = Path(__file__).resolve().parents[1] / "data" / "usgscsm"

# a camera in a straight, uniform flight with a constant attitude over a sphere: closed-form ground to image
R, H, V = 3396190.0, 300e3, 3400.0  # sphere radius, altitude, speed (m, m, m/s)
F_MM, P_MM, N_S, N_L, DT = 350.0, 0.007, 2000, 3000, 1e-3
M = np.column_stack([(0, 1, 0), (0, 0, 1), (1, 0, 0)]).astype(float)  # camera -> body: x along track, z up


def closed_form_isd(theta: float = 0.0) -> dict:
    """The ISD of that camera; ``theta`` rotates the detector in the focal plane (focal2pixel)."""
    times = np.linspace(-2.0, 2.0, 41)
    pos = np.column_stack([np.full(times.size, R + H), V * times, np.zeros(times.size)])
    q = Rotation.from_matrix(M.T).as_quat()  # body -> camera, (x, y, z, w)
    c, s = np.cos(theta), np.sin(theta)
    return {
        "name_model": "USGS_ASTRO_LINE_SCANNER_SENSOR_MODEL", "center_ephemeris_time": 0.0,
        "line_scan_rate": [[0.5, -0.5 * N_L * DT, DT]], "detector_sample_summing": 1, "detector_line_summing": 1,
        "focal2pixel_lines": [0.0, c / P_MM, -s / P_MM], "focal2pixel_samples": [0.0, s / P_MM, c / P_MM],
        "focal_length_model": {"focal_length": F_MM}, "image_lines": N_L, "image_samples": N_S,
        "detector_center": {"line": 0.0, "sample": N_S / 2}, "starting_detector_line": 0,
        "starting_detector_sample": 0, "optical_distortion": {"radial": {"coefficients": [0.0, 0.0, 0.0]}},
        "radii": {"semimajor": R, "semiminor": R, "unit": "m"},
        "instrument_position": {"unit": "m", "positions": pos.tolist(), "velocities": [[0, V, 0]] * times.size,
                                "ephemeris_times": times.tolist(), "reference_frame": 10014},
        "instrument_pointing": {"quaternions": [[q[3], q[0], q[1], q[2]]] * times.size,
                                "ephemeris_times": times.tolist()},
        "body_rotation": {"quaternions": [[1, 0, 0, 0]] * times.size, "ephemeris_times": times.tolist(),
                          "time_dependent_frames": [10014]},
    }


def closed_form_image(xyz: np.ndarray, theta: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(row, col) of body-fixed points: the detector line x cos(theta) - y sin(theta) = 0 in the focal plane
    (x = f v_x / v_z, v = M^T (P - C(t)), C(t) = (R + H, V t, 0)) is crossed at t = (P_y - P_z tan(theta)) / V;
    line = t / DT + N_L / 2 (line_scan_rate); sample = (x sin + y cos) / pitch + N_S / 2."""
    px, py, pz = xyz.T
    t = (py - pz * np.tan(theta)) / V
    vz = px - (R + H)
    x = F_MM * (py - V * t) / vz
    y = F_MM * pz / vz
    line = t / DT + N_L / 2
    sample = (x * np.sin(theta) + y * np.cos(theta)) / P_MM + N_S / 2
    return line - 0.5, sample - 0.5


@pytest.fixture(scope="module", params=[0.0, 0.3])
def closed(request):
    theta = request.param
    return theta, csm_scene(camera_from_isd(closed_form_isd(theta), interpolation="tables"))


def test_every_sensor_declares_its_capabilities(closed):
    from explorer.presets import build_scene
    from explorer.rpc.sensor import RPCSensor

    _, scene = closed
    assert isinstance(scene, Sensor) and isinstance(scene, LineGeometrySensor) and isinstance(scene, Scene)
    assert type(scene).has_line_geometry and not type(scene).has_polynomial_exterior
    mpc = build_scene("WSU")
    assert isinstance(mpc, Sensor) and type(mpc).has_line_geometry
    assert RPCSensor.has_line_geometry is False and not hasattr(RPCSensor, "line_time")


def test_closed_form_ground_to_image_and_back(closed):
    theta, scene = closed
    rng = np.random.default_rng(4)
    n = 500
    row, col = rng.uniform(-0.5, N_L - 0.5, n), rng.uniform(-0.5, N_S - 0.5, n)
    ground = scene.image_to_ground(row, col, height=rng.uniform(-2000, 2000, n))
    xyz = scene.to_body_fixed(ground)
    r_true, c_true = closed_form_image(xyz, theta)
    np.testing.assert_allclose(r_true, row, atol=1e-7)  # image -> ground is the camera's ray
    np.testing.assert_allclose(c_true, col, atol=1e-7)
    proj = scene.project(ground)
    assert proj.valid.all()
    np.testing.assert_allclose(proj.row, r_true, atol=1e-7)
    np.testing.assert_allclose(proj.col, c_true, atol=1e-7)
    assert scene.body.a_m == R and scene.frame.body is scene.body
    # off the image: solved but flagged
    far = scene.image_to_ground(np.array([N_L + 40.0]), np.array([10.0]), height=0.0)
    assert not scene.project(far).valid[0]


def test_closed_form_line_geometry(closed):
    theta, scene = closed
    rows = np.array([0.0, 1234.5, N_L - 1.0])
    t = scene.line_time(rows)
    np.testing.assert_allclose(t, (rows + 0.5) * DT - 0.5 * N_L * DT, atol=1e-12)
    np.testing.assert_allclose(scene.time_range(), (-0.5 * N_L * DT, 0.5 * N_L * DT), atol=1e-12)
    centre_bf = scene.to_body_fixed(scene.perspective_centre(t))
    np.testing.assert_allclose(centre_bf, np.column_stack([np.full(3, R + H), V * t, np.zeros(3)]), atol=1e-6)
    # the look direction of the detector centre (sample N_S / 2 -> col N_S / 2 - 0.5 for theta = 0): nadir
    look = scene.look_direction(rows, np.full(3, N_S / 2 - 0.5))
    look_bf = look @ scene.frame.enu_to_ecef_rotation.T
    if theta == 0.0:
        np.testing.assert_allclose(look_bf, np.tile([-1.0, 0.0, 0.0], (3, 1)), atol=1e-12)
    # the attitude maps the project's camera -z axis to the boresight, whatever the detector rotation
    boresight = np.einsum("nij,j->ni", scene.attitude(t), [0.0, 0.0, -1.0]) @ scene.frame.enu_to_ecef_rotation.T
    np.testing.assert_allclose(boresight, np.tile([-1.0, 0.0, 0.0], (3, 1)), atol=1e-9)


@pytest.mark.parametrize("name", ["exact", "csm-secant", "nr", "cpp", "bws-interp", "hybrid"])
def test_search_methods_on_the_closed_form_camera(closed, name):
    theta, scene = closed
    rng = np.random.default_rng(5)
    n = 300
    row, col = rng.uniform(0, N_L - 1, n), rng.uniform(0, N_S - 1, n)
    ground = scene.image_to_ground(row, col, height=rng.uniform(-1000, 1000, n))
    r_true, c_true = closed_form_image(scene.to_body_fixed(ground), theta)
    res = create(name, scene).ground_to_image(ground)
    assert res.valid.all()
    tol = 1e-6 if name in ("exact", "csm-secant", "nr", "cpp") else 1e-3  # interpolating searches: their own error
    assert np.max(np.abs(res.row - r_true)) < tol and np.max(np.abs(res.col - c_true)) < tol


@pytest.mark.parametrize("isd", ["ctxLineScan.json", "orbitalLineScan.json", "constVelocityLineScan.json"])
def test_real_isd_truth_is_the_camera(isd):
    """SCPs are simulated by the camera's own rays, and exact / csm-secant agree with the camera's own
    ground_to_image (usgscsm's model) to 1e-6 px at them."""
    cam = read_isd(DATA / isd)
    scene = csm_scene(cam)
    assert isinstance(scene, CsmScene)
    if isd == "ctxLineScan.json":
        assert scene.body == MARS
    scps = simulate_points(scene, 400, kind="scp", layers=2, seed=1)
    xyz = scene.to_body_fixed(scps.ground)
    truth = cam.ground_to_image(xyz)
    assert truth.valid.all()
    np.testing.assert_allclose(truth.line - 0.5, scps.row, atol=1e-7)
    np.testing.assert_allclose(truth.sample - 0.5, scps.col, atol=1e-7)
    for name in ("exact", "csm-secant"):
        res = create(name, scene).ground_to_image(scps.ground)
        assert res.valid.all()
        assert np.max(np.abs(res.row - (truth.line - 0.5))) < 1e-6, name
        assert np.max(np.abs(res.col - (truth.sample - 0.5))) < 1e-6, name


def test_simulate_reads_an_isd_through_the_one_loader(tmp_path):
    """``pushbroom simulate --isd``: the same path from file to sensor as explore and bench; the points are
    the camera's (its own ground_to_image gives their rows), and preset perturbations are refused on a file."""
    from explorer.cli import main
    from explorer.errors import InputError
    from explorer.points import PointSet

    out = tmp_path / "p.npz"
    assert main(["simulate", "--isd", str(DATA / "orbitalLineScan.json"), "--n", "20", "--out", str(out)]) == 0
    pts = PointSet.load_npz(out)
    cam = read_isd(DATA / "orbitalLineScan.json")
    truth = cam.ground_to_image(csm_scene(cam).to_body_fixed(pts.ground))
    np.testing.assert_allclose(truth.line - 0.5, pts.row, atol=1e-7)
    from explorer.commands.simulate import scene_from_args

    args = __import__("argparse").Namespace(preset=None, scene=None, isd=str(DATA / "orbitalLineScan.json"),
                                            relief=5.0, relief_seed=0, attitude_rate_scale=1.0, jitter_scale=1.0)
    with pytest.raises(InputError, match="--relief"):
        scene_from_args(args)
