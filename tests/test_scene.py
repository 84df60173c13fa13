"""The rigorous model against independent truth (brute-force solver, closed forms)."""

import json

import numpy as np
import pytest

from explorer.errors import InputError, SceneFileError
from explorer.geometry.exterior import ExteriorOrientation, Jitter, LineTiming
from explorer.geometry.interior import InteriorOrientation
from explorer.geometry.terrain import FlatTerrain, GridDEM
from explorer.presets import build_scene, preset_ids, preset_spec
from explorer.scene import Scene
from tests.truth import brute_force_rows

ALL_PRESETS = preset_ids()


def _random_image_points(scene, n, seed):
    rng = np.random.default_rng(seed)
    row = rng.uniform(0, scene.n_rows - 1, n)
    col = rng.uniform(0, scene.n_columns - 1, n)
    return row, col


@pytest.mark.parametrize("preset", ALL_PRESETS)
@pytest.mark.parametrize("relief", [0.0, 800.0])
def test_image_ground_image_round_trip(preset, relief):
    scene = build_scene(preset, relief_m=relief, relief_seed=3)
    row, col = _random_image_points(scene, 40, seed=7)
    ground = scene.image_to_ground(row, col)
    assert np.all(np.isfinite(ground))
    if relief:
        dem_h = scene.terrain.height(ground[:, 0], ground[:, 1])
        np.testing.assert_allclose(ground[:, 2], dem_h, atol=1e-6)
    exact = brute_force_rows(scene, ground)
    assert np.max(np.abs(exact - row)) < 1e-9
    col_back = scene.column_at_row(ground, exact)
    assert np.max(np.abs(col_back - col)) < 1e-9


def test_along_track_residual_zero_at_exact_scanline_with_offset_curvature_distortion():
    base = build_scene("WSU")
    pitch = base.interior.detector_pitch_m
    interior = InteriorOrientation(
        base.interior.focal_length_m, pitch, base.n_columns,
        principal_column=1990.3,
        along_track_offset_m=37.2 * pitch,
        line_curvature=(2e-4, 3e-3),
        radial_distortion=(2e-3,),
    )
    scene = Scene("curved", interior, base.exterior, base.timing, base.n_rows, base.terrain, base.frame)
    row, col = _random_image_points(scene, 30, seed=2)
    ground = scene.image_to_ground(row, col)
    exact = brute_force_rows(scene, ground)
    np.testing.assert_allclose(exact, row, atol=1e-9)
    x, y = scene.focal_plane(ground, scene.scanline_time(exact))
    x_det = scene.interior.detector_x(y)
    assert np.max(np.abs(x - x_det)) / pitch < 1e-9
    # the detector line is displaced: x is not zero but the offset (plus curvature)
    assert np.min(np.abs(x)) / pitch > 30


def test_linear_preset_scanline_is_linear_in_ground_coordinates():
    scene = build_scene("linear")
    assert scene.exterior.is_constant_velocity_and_attitude
    rng = np.random.default_rng(5)
    row, col = _random_image_points(scene, 60, seed=1)
    heights = rng.uniform(-300, 300, row.size)
    ground = scene.image_to_ground(row, col, height=heights)
    design = np.column_stack([ground, np.ones(row.size)])
    coef, *_ = np.linalg.lstsq(design[:30], row[:30], rcond=None)
    assert np.max(np.abs(design[30:] @ coef - row[30:])) < 1e-9


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_gsd_matches_table(preset):
    scene = build_scene(preset)
    spec = preset_spec(preset)
    along, across = scene.ground_sample_distance()
    # independent measure: mean spacing of ground points one pixel apart over the central 11 x 11 px
    rc, cc = (scene.n_rows - 1) / 2, (scene.n_columns - 1) / 2
    r = rc + np.arange(-5, 6)
    g_col = scene.image_to_ground(np.full(11, rc), cc + np.arange(-5, 6))
    g_row = scene.image_to_ground(r, np.full(11, cc))
    across2 = np.linalg.norm(np.diff(g_col, axis=0), axis=1).mean()
    along2 = np.linalg.norm(np.diff(g_row, axis=0), axis=1).mean()
    for v in (along, across, along2, across2):
        assert abs(v - spec["gsd_m"]) / spec["gsd_m"] < 0.02


def test_orbit_is_plausible():
    scene = build_scene("WSU")
    s = scene.exterior.position(np.array([0.0]))
    v = scene.exterior.velocity(np.array([0.0]))
    # 770 km altitude within the earth curvature of an 11 deg off-nadir view
    assert 760e3 < s[0, 2] < 780e3
    assert 7.3e3 < np.linalg.norm(v) < 7.6e3


def test_scene_json_round_trip_exact(tmp_path):
    scene = build_scene("agile", relief_m=500.0, relief_seed=9)
    scene.exterior.jitter.append(Jitter("kappa", 1e-6, 13.0, 0.1))
    path = tmp_path / "s.json"
    scene.save(path)
    loaded = Scene.load(path)
    assert loaded.to_dict() == scene.to_dict()
    np.testing.assert_array_equal(loaded.terrain.heights, scene.terrain.heights)
    row, col = _random_image_points(scene, 20, 0)
    np.testing.assert_array_equal(loaded.image_to_ground(row, col), scene.image_to_ground(row, col))


def test_scene_json_round_trip_stored_dem(tmp_path):
    rng = np.random.default_rng(0)
    dem = GridDEM(-5000.0, -5000.0, 100.0, 100.0, rng.normal(50, 10, (101, 101)))
    scene = build_scene("WSU").with_terrain(dem)
    loaded = Scene.from_dict(json.loads(scene.to_json()))
    np.testing.assert_array_equal(loaded.terrain.heights, dem.heights)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.pop("interior"), "interior"),
        (lambda d: d.__setitem__("format", "x"), "not a pushbroom-explorer scene"),
        (lambda d: d["exterior"].__setitem__("position_coeffs", [[1.0, 2.0]]), "position_coeffs"),
        (lambda d: d["terrain"].__setitem__("kind", "lava"), "terrain kind"),
        (lambda d: d["timing"].__setitem__("line_period_s", -1.0), "line_period_s"),
    ],
)
def test_bad_scene_files_raise_clear_errors(tmp_path, mutate, message):
    d = build_scene("WSU").to_dict()
    mutate(d)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(d))
    with pytest.raises(SceneFileError, match=message) as info:
        Scene.load(path)
    assert "bad.json" in str(info.value)


def test_not_json_raises(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text('{"format": "pushbroom-explorer scene", ')
    with pytest.raises(SceneFileError, match="not valid JSON"):
        Scene.load(path)


def test_nan_inputs_raise():
    scene = build_scene("WSU")
    with pytest.raises(InputError, match="row"):
        scene.image_to_ground(np.array([1.0, np.nan]), np.array([1.0, 2.0]))
    with pytest.raises(InputError, match="col"):
        scene.rays(np.array([1.0]), np.array([np.inf]))


def test_finite_check_names_nan_and_inf_and_passes_huge_finite_values():
    from explorer.errors import as_points, check_finite

    with pytest.raises(InputError, match=r"2 NaN/infinite value\(s\); first at index \(1, 0\)"):
        as_points(np.array([[1.0, 2.0, 3.0], [np.nan, 0.0, 0.0], [0.0, -np.inf, 0.0]]))
    with pytest.raises(InputError, match="ground"):
        as_points(np.array([[np.inf, -np.inf, 0.0]]))  # the sum is NaN, not inf
    huge = np.full((4, 3), 1e308)  # the fast path's sum overflows; the values are finite
    assert as_points(huge) is not None and check_finite(huge, "x") is not None


def test_mpc_polynomials_any_degree_and_jitter_derivative():
    pos = np.array([[1.0, 2.0, 0.5, 0.1], [0.0, 1.0, 0.0, 0.0], [700e3, 0.0, -4.0, 0.0]])
    att = np.array([[0.01, 1e-3, 1e-4, 1e-5], [0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 2e-6]])
    ext = ExteriorOrientation(pos, att, [Jitter("phi", 1e-5, 50.0, 0.2)])
    t = np.linspace(-1, 1, 7)
    np.testing.assert_allclose(ext.position(t)[:, 0], 1 + 2 * t + 0.5 * t**2 + 0.1 * t**3)
    h = 1e-6
    num = (ext.angles(t + h) - ext.angles(t - h)) / (2 * h)
    np.testing.assert_allclose(ext.angle_rates(t), num, atol=1e-7)
    vel = (ext.position(t + h) - ext.position(t - h)) / (2 * h)
    np.testing.assert_allclose(ext.velocity(t), vel, rtol=1e-6, atol=1e-6)


def test_timing_row_time_inverse():
    tm = LineTiming(1e-4, 1000.0)
    np.testing.assert_allclose(tm.row_at_time(tm.scanline_time(np.array([0.0, 17.25]))), [0.0, 17.25])


def test_points_outside_flat_plane_direction():
    scene = build_scene("WSU").with_terrain(FlatTerrain(1e7))  # plane above the satellite
    g = scene.image_to_ground(np.array([10.0]), np.array([10.0]))
    assert np.all(np.isnan(g))


def test_geodetic_entry_point_is_project_through_the_frame():
    from explorer.presets import build_scene

    scene = build_scene("WSU")
    ground = scene.image_to_ground(np.array([0.0, 500.0, 3000.0]), np.array([10.0, 400.0, 5000.0]))
    lon, lat, h = scene.frame.enu_to_geodetic(ground)
    geo, enu = scene.project_geodetic(lon, lat, h), scene.project(ground)
    np.testing.assert_allclose(geo.row, enu.row, atol=1e-8)
    np.testing.assert_allclose(geo.col, enu.col, atol=1e-8)
    assert np.array_equal(geo.valid, enu.valid)
