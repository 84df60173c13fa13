"""MPC space resection against independent truth: preset scenes with exact exterior orientation,
brute-force best scanlines (tests/truth.py), closed-form lines of sight."""

from dataclasses import replace

import numpy as np
import pytest

from explorer.errors import InputError
from explorer.geometry.exterior import ExteriorOrientation
from explorer.geometry.interior import InteriorOrientation
from explorer.points import image_grid
from explorer.presets import build_scene
from explorer.real.resection import mpc_from_lines_of_sight, project_to_image, resect
from explorer.scene import Scene
from tests.truth import brute_force_rows


def _perturbed(scene, seed=0):
    """Initial values: the preset's exterior with metre/microradian-level errors, no rates."""
    rng = np.random.default_rng(seed)
    pos = scene.exterior.position_coeffs.copy()
    att = scene.exterior.attitude_coeffs.copy()
    pos[:, 0] += rng.normal(0, 200.0, 3)
    pos[:, 1] *= 1.0 + rng.normal(0, 1e-3, 3)
    att[:, 0] += rng.normal(0, 2e-4, 3)
    att[:, 1:] = 0.0
    return replace(scene, exterior=ExteriorOrientation(pos, att, []))


@pytest.mark.parametrize("preset", ["WSU", "PMA", "SJB"])
def test_resection_recovers_exact_preset_geometry(preset):
    truth = build_scene(preset)
    gcps = image_grid(truth, 60, layers=3)
    checks = image_grid(truth, 200, layers=2, cell_centred=True)
    scene, report = resect(_perturbed(truth), gcps.row, gcps.col, gcps.ground, degree=2)
    assert report.success
    assert report.initial_rmse_px > 10.0
    # the model is exact for a preset (degree-2 Taylor polynomials): residuals vanish
    assert report.rmse_px < 1e-5 and report.max_px < 1e-4
    row, col, ok = project_to_image(scene, checks.ground)
    assert ok.all()
    assert np.max(np.abs(row - checks.row)) < 1e-4
    assert np.max(np.abs(col - checks.col)) < 1e-4


def test_resection_estimates_focal_length_and_spacing_terms():
    base = build_scene("WSU")
    n = base.n_columns
    half = (n - 1) / 2.0
    true_interior = replace(base.interior, column_polynomial=(-3.0 / half**2,))  # 3 px at the edges
    truth = replace(base, interior=true_interior)
    gcps = image_grid(truth, 80, layers=3)
    start = replace(_perturbed(truth), interior=replace(base.interior,
                                                        focal_length_m=base.interior.focal_length_m * 1.002))
    scene, report = resect(start, gcps.row, gcps.col, gcps.ground, estimate_focal=True, column_terms=1)
    assert report.rmse_px < 1e-4
    assert scene.interior.focal_length_m == pytest.approx(base.interior.focal_length_m, rel=1e-6)
    assert scene.interior.column_polynomial[0] == pytest.approx(-3.0 / half**2, rel=1e-5)


def test_project_to_image_matches_brute_force_truth():
    scene = build_scene("agile", relief_m=300.0, relief_seed=2)
    pts = image_grid(scene, 30, layers=2, cell_centred=True)
    exact = brute_force_rows(scene, pts.ground)
    row, col, ok = project_to_image(scene, pts.ground)
    assert ok.all()
    np.testing.assert_allclose(row, exact, atol=1e-8)
    np.testing.assert_allclose(row, pts.row, atol=1e-8)
    np.testing.assert_allclose(col, pts.col, atol=1e-8)
    # with a guess, and for a point far outside the image: no bracket -> NaN, not converged
    far = pts.ground[:1] + np.array([[0.0, 1e6, 0.0]])
    r2, c2, ok2 = project_to_image(scene, np.vstack([pts.ground[:3], far]), row_guess=np.r_[pts.row[:3], 0.0])
    assert ok2[:3].all() and not ok2[3] and np.isnan(r2[3]) and np.isnan(c2[3])


def test_lines_of_sight_give_the_perspective_centres_in_closed_form():
    scene = build_scene("PMA")
    rows = np.linspace(0, scene.n_rows - 1, 7)
    cols = np.linspace(0, scene.n_columns - 1, 9)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    low = scene.image_to_ground(rr.ravel(), cc.ravel(), height=-200.0).reshape(rr.shape + (3,))
    high = scene.image_to_ground(rr.ravel(), cc.ravel(), height=900.0).reshape(rr.shape + (3,))
    s0, info = mpc_from_lines_of_sight(rows, cols, low, high, n_rows=scene.n_rows, n_columns=scene.n_columns,
                                       frame=scene.frame, degree=2, line_period_s=scene.timing.line_period_s)
    t = scene.scanline_time(rows)
    assert info["centre_rms_m"] < 1e-3
    assert np.max(np.linalg.norm(s0.exterior.position(t) - scene.exterior.position(t), axis=1)) < 0.05
    f_over_pitch = scene.interior.focal_length_m / scene.interior.detector_pitch_m
    assert info["f_over_pitch_px"] == pytest.approx(f_over_pitch, rel=1e-7)
    r_fit = s0.exterior.rotation(t)
    r_true = scene.exterior.rotation(t)
    assert np.max(np.abs(r_fit - r_true)) < 1e-7


def test_resect_refuses_too_few_points_and_bad_shapes():
    scene = build_scene("WSU")
    g = image_grid(scene, 4)
    with pytest.raises(InputError, match="unknowns"):
        resect(scene, g.row[:4], g.col[:4], g.ground[:4], degree=2)
    with pytest.raises(InputError, match="disagree"):
        resect(scene, g.row[:3], g.col, g.ground)


def test_column_polynomial_round_trip_and_backward_compatible_json():
    base = InteriorOrientation(10.0, 1e-5, 4001)
    assert "column_polynomial" not in base.to_dict() and base.is_straight_line
    inner = replace(base, column_polynomial=(-4e-7, 3e-11))
    col = np.linspace(-0.5, 4000.5, 101)
    y = inner.column_to_y(col)
    u = col - 2000.0
    np.testing.assert_allclose(y, 1e-5 * (u - 4e-7 * u**2 + 3e-11 * u**3), rtol=0, atol=1e-15)
    np.testing.assert_allclose(inner.y_to_column(y), col, atol=1e-9)
    back = InteriorOrientation.from_dict(inner.to_dict())
    assert back == inner and not back.is_straight_line and not back.has_uniform_spacing
    # a scene with the new field survives the JSON round trip exactly
    scene = replace(build_scene("WSU"), interior=replace(build_scene("WSU").interior, column_polynomial=(1e-7,)))
    again = Scene.from_dict(scene.to_dict())
    assert again.interior.column_polynomial == (1e-7,)
