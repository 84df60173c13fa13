"""``csm-secant`` (usgscsm groundToImage) against the exact rows of simulated points and brute force."""

import numpy as np
import pytest

from explorer.evaluate import evaluate_method
from explorer.geometry.kernels import NUMBA_AVAILABLE
from explorer.methods import available, create
from explorer.methods.csm_secant import fit_projective_line
from explorer.points import simulate_points
from explorer.presets import build_scene, preset_ids

ALL_PRESETS = preset_ids()


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_rows_within_1e6_px_on_every_preset(preset):
    scene = build_scene(preset)
    check = simulate_points(scene, 3000, kind="scp")
    method = create("csm-secant", scene)
    ev = evaluate_method(method, check)
    assert ev.valid_frac == 1.0
    assert ev.rmse_px <= 1e-6 and ev.dr_max_px <= 1e-6
    assert ev.col_rmse_px <= 1e-6
    res = method.ground_to_image(check.ground)
    # two probes, at least one secant step unless a probe already meets the precision, one column
    assert res.ce_evaluations.min() >= 3
    assert res.ce_evaluations.max() <= 2 + 14 + 1


@pytest.mark.parametrize("preset", ["SAN", "agile"])
def test_rows_with_relief(preset):
    scene = build_scene(preset, relief_m=1000.0, relief_seed=2)
    check = simulate_points(scene, 2000, kind="scp")
    ev = evaluate_method(create("csm-secant", scene), check)
    assert ev.valid_frac == 1.0 and ev.dr_max_px <= 1e-6


def test_projective_seed_reproduces_its_fitting_grid_on_a_straight_orbit():
    # on the 'linear' preset (straight orbit, constant attitude) the line is exactly projective
    # in the ground coordinates for a straight detector: the 18 fit points are reproduced
    scene = build_scene("linear")
    proj, n = fit_projective_line(scene)
    assert n == 18
    rows = np.array([-0.5, (scene.n_rows - 1) / 2, scene.n_rows - 0.5])
    ground = scene.image_to_ground(rows, np.array([3.0, 500.0, 1900.0]), height=40.0)
    u = (ground - proj[8:11]) / proj[11:14]
    line = (proj[0] + u @ proj[1:4]) / (1.0 + u @ proj[4:7])
    np.testing.assert_allclose(line, rows, atol=1e-6)


def test_flags_points_it_cannot_solve():
    scene = build_scene("WSU")
    sat = scene.exterior.position(np.zeros(1))
    ground = np.vstack([sat + np.array([[0.0, 0.0, 2e5]]), sat + np.array([[3e3, -2e3, 5e4]])])
    res = create("csm-secant", scene).ground_to_image(ground)
    assert not res.converged.any() and not res.valid.any()
    assert np.isnan(res.row).all()
    # a precision not reached within the iteration limit is reported, not hidden: with no secant
    # step allowed (max_count=1) only the two probes are made, 0.1 rows apart
    check = simulate_points(scene, 200, kind="scp")
    res = create("csm-secant", scene, max_count=1).ground_to_image(check.ground)
    assert res.info["precision_not_met"] == np.count_nonzero(~res.converged) >= 190
    assert np.isnan(res.row[~res.converged]).all()
    assert np.nanmax(np.abs(res.info["row_estimate"] - check.row)) < 0.2


def test_points_off_the_image_are_flagged():
    scene = build_scene("WSU")
    rows = np.array([-30.0, scene.n_rows + 12.0, 1000.0])
    cols = np.array([100.0, 200.0, scene.n_columns + 40.0])
    ground = scene.image_to_ground(rows, cols, height=scene.terrain.mean_height)
    res = create("csm-secant", scene).ground_to_image(ground)
    assert not res.inside.any() and not res.valid.any()
    np.testing.assert_allclose(res.row, rows, atol=1e-6)


def test_numpy_backend_gives_the_same_result():
    if not NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    scene = build_scene("agile")
    check = simulate_points(scene, 1500, kind="scp")
    a = create("csm-secant", scene).ground_to_image(check.ground, trace=True)
    b = create("csm-secant", scene, backend="numpy").ground_to_image(check.ground, trace=True)
    np.testing.assert_allclose(a.row, b.row, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(a.ce_evaluations, b.ce_evaluations)
    assert len(a.trace) == len(b.trace) == a.ce_evaluations.max() - 1
    for x, y in zip(a.trace, b.trace, strict=True):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9)


def test_device_and_registry():
    scene = build_scene("WSU")
    assert "csm-secant" in available()
    assert create("csm-secant", scene, device="cpu").setup_ce == 18
    with pytest.raises(ValueError, match="device='cpu'"):
        create("csm-secant", scene, device="cuda")
