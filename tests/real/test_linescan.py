"""Rigorous line-scan machinery against closed forms: quaternions (scipy's Rotation), Lagrange
interpolation of polynomials and of a circular orbit, constant-rate attitude, aberration and
refraction magnitudes, scene consistency (image -> ground -> image) and JSON round trips."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from explorer.geometry.frames import LocalFrame
from explorer.geometry.rotations import rotation_from_opk
from explorer.real.linescan import (
    C_LIGHT,
    AttitudeTable,
    lagrange_interpolate,
    load_scene,
    matrix_to_quaternion,
    quaternion_to_matrix,
    slerp,
)
from explorer.real.resection import project_to_image
from explorer.real.worldview import rigorous_scene_from_dg
from explorer.scene import Scene

from .conftest import WV1


def test_quaternions_match_scipy():
    rng = np.random.default_rng(0)
    q_xyzw = Rotation.random(50, random_state=1).as_quat()
    q = np.column_stack([q_xyzw[:, 3], q_xyzw[:, :3]])
    np.testing.assert_allclose(quaternion_to_matrix(q), Rotation.from_quat(q_xyzw).as_matrix(), atol=1e-14)
    back = matrix_to_quaternion(quaternion_to_matrix(q))
    same = np.where(np.sum(back * q, axis=1, keepdims=True) < 0, -back, back)
    np.testing.assert_allclose(same, q, atol=1e-13)
    # slerp halfway between two rotations about z is the rotation by the mean angle
    a, b = rng.uniform(-1, 1, 2)
    qa = np.array([[np.cos(a / 2), 0, 0, np.sin(a / 2)]])
    qb = np.array([[np.cos(b / 2), 0, 0, np.sin(b / 2)]])
    mid = slerp(qa, qb, np.array([0.5]))
    np.testing.assert_allclose(mid[0], [np.cos((a + b) / 4), 0, 0, np.sin((a + b) / 4)], atol=1e-14)


def test_lagrange_is_exact_for_polynomials_and_accurate_on_a_circular_orbit():
    ts = np.linspace(-120.0, 150.0, 10)  # the Pleiades sampling: 30 s
    t = np.linspace(-2.0, 2.0, 7)
    cubic = np.stack([1 + ts - 3e-3 * ts**3, 2 * ts**2], axis=1)
    np.testing.assert_allclose(lagrange_interpolate(ts, cubic, t, order=8),
                               np.stack([1 + t - 3e-3 * t**3, 2 * t**2], axis=1), atol=1e-9)
    r, w = 7.07e6, 2 * np.pi / 5900.0  # circular orbit, closed form
    orbit = np.stack([r * np.cos(w * ts), r * np.sin(w * ts), 0 * ts], axis=1)
    exact = np.stack([r * np.cos(w * t), r * np.sin(w * t), 0 * t], axis=1)
    assert np.max(np.abs(lagrange_interpolate(ts, orbit, t, order=8) - exact)) < 1e-4  # metres


@pytest.mark.parametrize("method", ["lagrange", "slerp"])
def test_constant_rate_attitude_is_interpolated_exactly(method):
    axis = np.array([0.3, -0.5, 0.81])
    axis /= np.linalg.norm(axis)
    rate = 0.0147  # rad/s, the Pleiades 2017 scan
    ts = np.arange(-2.0, 2.01, 0.125)
    q = np.column_stack([np.cos(rate * ts / 2), np.sin(rate * ts / 2)[:, None] * axis])
    table = AttitudeTable(ts, -q if method == "slerp" else q, method=method)  # sign-free
    t = np.array([-1.93, -0.3, 0.0625, 1.7])
    expected = Rotation.from_rotvec(rate * t[:, None] * axis).as_matrix()
    tol = 1e-15 if method == "slerp" else 1e-9
    assert np.max(np.abs(table.rotation(t) - expected)) < tol


@pytest.fixture(scope="module")
def wv1():
    return rigorous_scene_from_dg(WV1)


def test_rigorous_scene_is_self_consistent(wv1):
    rng = np.random.default_rng(4)
    row = rng.uniform(0, wv1.n_rows - 1, 60)
    col = rng.uniform(0, wv1.n_columns - 1, 60)
    h = rng.uniform(-400, 600, 60)
    ground = wv1.image_to_ground(row, col, height=h)
    np.testing.assert_allclose(ground[:, 2], h, atol=1e-6)
    r, c, ok = project_to_image(wv1, ground)
    assert ok.all()
    assert np.max(np.abs(r - row)) < 1e-6 and np.max(np.abs(c - col)) < 1e-6
    # the exterior's angles reproduce its rotation (docs/conventions.md#rotations)
    t = wv1.scanline_time(row[:5])
    a = wv1.exterior.angles(t)
    np.testing.assert_allclose(rotation_from_opk(a[:, 0], a[:, 1], a[:, 2]), wv1.exterior.rotation(t), atol=1e-12)
    rates = wv1.exterior.angle_rates(t)
    fd = (wv1.exterior.angles(t + 0.01) - wv1.exterior.angles(t - 0.01)) / 0.02
    np.testing.assert_allclose(rates, fd, atol=1e-7)


def test_aberration_and_refraction_magnitudes(wv1):
    row, col = np.array([wv1.n_rows / 2.0]), np.array([wv1.n_columns / 2.0])
    both = wv1.image_to_ground(row, col, height=0.0)[0]
    wv1.aberration = False
    no_ab = wv1.image_to_ground(row, col, height=0.0)[0]
    wv1.refraction = False
    plain = wv1.image_to_ground(row, col, height=0.0)[0]
    wv1.aberration = wv1.refraction = True
    t = wv1.scanline_time(row)
    s, v = wv1.exterior.position(t)[0], wv1.exterior.velocity(t)[0]
    los = (plain - s) / np.linalg.norm(plain - s)
    rho = np.linalg.norm(plain - s)
    # first order: the ray turns by |v_perp| / c; on the ground that is rho |v_perp| / c / cos(incidence)-ish
    v_perp = np.linalg.norm(v - (v @ los) * los)
    shift_ab = np.linalg.norm(both - no_ab)
    assert rho * v_perp / C_LIGHT == pytest.approx(shift_ab, rel=0.25)  # ~12 m for 0.5 m pixels
    cz = -los[2]
    tz = np.sqrt(1 - cz**2) / cz
    shift_ref = np.linalg.norm(no_ab - plain)
    assert shift_ref == pytest.approx(2.77e-4 * 8000.0 * tz / cz**2, rel=0.02)  # 1.2 m at 25 deg


def test_rigorous_scene_json_round_trip(wv1, tmp_path):
    path = tmp_path / "wv1.json"
    wv1.save(path)
    again = load_scene(path)
    assert type(again) is type(wv1) and again.aberration and again.refraction
    rows = np.array([0.0, 13000.3, wv1.n_rows - 1.0])
    cols = np.array([0.0, 17000.7, wv1.n_columns - 1.0])
    np.testing.assert_allclose(again.image_to_ground(rows, cols, height=50.0),
                               wv1.image_to_ground(rows, cols, height=50.0), atol=1e-9)
    # an MPC scene file still loads through the same function
    mpc = Scene(wv1.name, wv1.interior, __import__("explorer.presets", fromlist=["x"]).build_scene("WSU").exterior,
                wv1.timing, wv1.n_rows, wv1.terrain, LocalFrame(0.0, 0.0))
    mpc.save(tmp_path / "mpc.json")
    assert type(load_scene(tmp_path / "mpc.json")) is Scene


@pytest.fixture(scope="module")
def phr():
    from explorer.real.dimap import rigorous_scene_from_dimap

    from .conftest import PHR_2018

    return rigorous_scene_from_dimap(PHR_2018, n_gcps=60, n_check=0)[0]


@pytest.mark.parametrize(
    ("which", "name"),
    [("wv1", "bws-interp"), ("wv1", "hybrid"), ("phr", "bws-interp"), ("phr", "hybrid"), ("phr", "cpp"),
     ("wv1", "exact"), ("phr", "exact"), ("wv1", "csm-secant"), ("phr", "csm-secant"), ("wv1", "nr"),
     ("phr", "nr"), ("wv1", "cpp"), ("wv1", "gdp")],
)
def test_registered_methods_run_unchanged_on_rigorous_scenes(request, which, name):
    """Every search method is exact on a rigorous scene's own residual (aberration and refraction included):
    ``exact`` and ``csm-secant`` through their line-geometry solvers, ``nr`` with the central difference of the
    scene's residual, ``cpp`` with its refinement on it (its planes alone miss the corrections)."""
    from explorer.methods.base import available, create

    if name not in available():
        pytest.skip(f"method {name} not registered")
    scene = request.getfixturevalue(which)
    rng = np.random.default_rng(9)
    row = rng.uniform(0, scene.n_rows - 1, 40)
    col = rng.uniform(0, scene.n_columns - 1, 40)
    ground = scene.image_to_ground(row, col, height=rng.uniform(-300, 500, 40) + scene.terrain.mean_height)
    result = create(name, scene).ground_to_image(ground)
    assert result.valid.all()
    assert np.max(np.abs(result.row - row)) < 1e-6 and np.max(np.abs(result.col - col)) < 1e-6
