"""``rfm``: terrain-independent cubic RFM against exact rows/columns of simulated points and brute force.

Why the bounds are so tight: the presets' exterior orientation is a degree-2 polynomial of time
over well under a second of imaging, and the resulting ground -> image map is reproduced by a
cubic rational function to float64 round-off.  Measured on the 5 x 5 x 5-style SCP grid of every
preset except ``agile``: max |row error| 5e-11 px, max |col error| 2e-10 px (the residual is the
least-squares round-off: condition number of the normalised design ~1e5 times 1e-16 times the
image half-size ~3e3 px).  The assertion, 1e-8 px, keeps a 50x margin.  ``agile`` carries 67 Hz
attitude jitter that no cubic follows (measured RMS 1.4 px); with its jitter removed it is back
to 1e-10 px, which is asserted too.
"""

import numpy as np
import pytest

from explorer.methods import create
from explorer.methods.rfm import image_space_grid, rigorous_ground_to_image
from explorer.points import simulate_points
from explorer.presets import build_scene, preset_ids
from tests.truth import brute_force_rows

SMOOTH_PRESETS = [p for p in preset_ids() if p != "agile"]
BOUND_PX = 1e-8


@pytest.mark.parametrize("preset", SMOOTH_PRESETS)
def test_rfm_rows_and_columns_on_independent_3d_check_grid(preset):
    scene = build_scene(preset)
    method = create("rfm", scene)  # 10 x 10 x 5 image-space grid
    check = simulate_points(scene, 25, kind="scp", layers=5)  # 5 x 5 cell centres x 5 heights
    res = method.ground_to_image(check.ground)
    assert res.valid.all()
    assert np.max(np.abs(res.row - check.row)) < BOUND_PX
    assert np.max(np.abs(res.col - check.col)) < BOUND_PX
    assert np.all(res.ce_evaluations == 0)
    assert method.setup_ce == 500


def test_rfm_on_relief_against_brute_force_at_random_points():
    scene = build_scene("WSU", relief_m=800.0, relief_seed=4)
    method = create("rfm", scene)
    rng = np.random.default_rng(11)
    row = rng.uniform(0, scene.n_rows - 1, 40)
    col = rng.uniform(0, scene.n_columns - 1, 40)
    ground = scene.image_to_ground(row, col)  # on the DEM
    exact = brute_force_rows(scene, ground)
    np.testing.assert_allclose(exact, row, atol=1e-9)
    res = method.ground_to_image(ground)
    assert res.valid.all()
    assert np.max(np.abs(res.row - exact)) < BOUND_PX
    assert np.max(np.abs(res.col - col)) < BOUND_PX


def test_ground_grid_variant_counts_its_setup_collinearity_evaluations():
    scene = build_scene("SCB")
    method = create("rfm", scene, grid_space="ground")
    check = simulate_points(scene, 25, kind="scp", layers=5)
    res = method.ground_to_image(check.ground)
    assert np.max(np.abs(res.row - check.row)) < BOUND_PX
    assert np.max(np.abs(res.col - check.col)) < BOUND_PX
    # 500 grid nodes + 9 x 9 x 4 cell-centre checks, each >= 2 bracketing residuals + >= 1 secant + 1 column
    assert method.setup_ce >= 4 * (500 + 324)


def test_rigorous_secant_helper_matches_exact_rows():
    scene = build_scene("PMA")
    row, col, ground = image_space_grid(scene, (4, 4, 3), cell_centred=True)
    r, c, ok, ce = rigorous_ground_to_image(scene, ground)
    assert ok.all()
    assert np.max(np.abs(r - row)) < 1e-8
    assert np.max(np.abs(c - col)) < 1e-8
    assert ce.max() <= 12


def test_agile_jitter_is_not_representable_but_the_smooth_part_is():
    check_scene = build_scene("agile")
    check = simulate_points(check_scene, 25, kind="scp", layers=5)
    res = create("rfm", check_scene).ground_to_image(check.ground)
    rms = np.sqrt(np.mean((res.row - check.row) ** 2))
    assert rms > 0.3  # measured 1.42 px: 67 Hz jitter of 2 microrad on ~0.4 s of imaging
    smooth = build_scene("agile", jitter_amplitude_scale=0.0)
    check = simulate_points(smooth, 25, kind="scp", layers=5)
    res = create("rfm", smooth).ground_to_image(check.ground)
    assert np.max(np.abs(res.row - check.row)) < BOUND_PX


def test_out_of_image_and_out_of_domain_points_are_flagged():
    scene = build_scene("WSU")
    method = create("rfm", scene)
    h = scene.terrain.mean_height
    rows = np.array([-40.0, scene.n_rows + 40.0, 100.0, 100.0, 2000.0])
    cols = np.array([100.0, 100.0, -40.0, scene.n_columns + 40.0, 2000.0])
    ground = scene.image_to_ground(rows, cols, height=h)
    res = method.ground_to_image(ground)
    assert not res.inside[:4].any()
    assert not res.valid[:4].any()
    assert res.valid[4]
    # just outside the image but inside the fitted box: still accurate, only flagged by `inside`
    assert np.max(np.abs(res.row[:4] - rows[:4])) < 1e-6
    far = np.array([[60_000.0, 0.0, h], [0.0, 0.0, h + 5_000.0]])
    res = method.ground_to_image(far)
    assert not res.converged.any()
    assert not res.valid.any()
    assert not res.info["in_domain"].any()


def test_fit_is_a_no_op_and_trace_is_one_step():
    scene = build_scene("SCB")
    method = create("rfm", scene)
    scops = simulate_points(scene, 50)
    before = method.ground_to_image(scops.ground).row
    assert method.fit(scops) is method
    res = method.ground_to_image(scops.ground, trace=True)
    np.testing.assert_array_equal(res.row, before)
    assert len(res.trace) == 1 and res.trace[0].shape == (len(scops),)
    assert method.family == "generalized" and not method.needs_fit
