"""``exact``: seeded, safeguarded Newton against the exact rows of simulated points and brute force."""

import numpy as np
import pytest

from explorer.evaluate import evaluate_method
from explorer.geometry.exterior import Jitter
from explorer.geometry.kernels import NUMBA_AVAILABLE, STATUS_INVALID, STATUS_NO_ROOT_IN_WINDOW
from explorer.methods import available, create
from explorer.points import simulate_points
from explorer.presets import build_scene, preset_ids
from tests.truth import brute_force_rows

ALL_PRESETS = preset_ids()


def _check_exact(method, check, rmse_max=1e-8, drmax_max=1e-7):
    ev = evaluate_method(method, check)
    res = method.ground_to_image(check.ground)
    assert ev.valid_frac == 1.0
    assert ev.rmse_px <= rmse_max
    assert ev.dr_max_px <= drmax_max
    assert ev.col_rmse_px <= rmse_max
    assert np.max(np.abs(res.col - check.col)) <= drmax_max
    return ev, res


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_exact_rows_on_every_preset(preset):
    scene = build_scene(preset)
    check = simulate_points(scene, 3000, kind="scp")
    ev, res = _check_exact(create("exact", scene), check)
    assert res.ce_evaluations.min() >= 1
    assert ev.ce_evals_per_point <= 3.0


def test_jitter_seed_correction_reaches_one_evaluation_on_agile():
    """agile's 41/67 Hz jitter moves the row by ~4.6 rows and differently across the columns: the seed's
    correction table (3 columns, 0.25-row nodes over the polynomial's row) brings the seed within Newton's
    acceptance step of the exact row, so almost every point costs one CE (it cost two before)."""
    scene = build_scene("agile")
    m = create("exact", scene)
    check = simulate_points(scene, 20000, kind="scp", seed=5)
    assert m.seed_correction_max_rows > 1.0 and m.seed.correction.shape[1] == 3
    seed_err = np.abs(m.seed.rows(check.ground) - check.row)
    poly_err = np.abs(type(m.seed)(m.seed.mean, m.seed.scale, m.seed.coef).rows(check.ground) - check.row)
    assert poly_err.max() > 1.0  # the polynomial alone is rows away
    assert np.mean(seed_err <= m.accept_step) > 0.99
    assert m.first_evaluations == 1
    ev, res = _check_exact(m, check)
    assert ev.ce_evals_per_point < 1.02


@pytest.mark.parametrize("preset", ["PMA", "agile"])
def test_exact_rows_with_relief(preset):
    scene = build_scene(preset, relief_m=1000.0, relief_seed=4)
    check = simulate_points(scene, 3000, kind="scp")
    assert np.ptp(check.ground[:, 2]) > 500.0
    _check_exact(create("exact", scene), check)


def test_exact_rows_on_a_3d_grid_of_heights():
    scene = build_scene("WSA")
    check = simulate_points(scene, 1000, kind="scp", layers=5)
    _check_exact(create("exact", scene), check)


@pytest.mark.slow  # brute-force truth on a strong-rate, jittered scene (about 20 s)
@pytest.mark.parametrize(
    "kwargs",
    [
        {"attitude_rate_scale": 3.0, "jitter_amplitude_scale": 10.0},
        {"attitude_rate_scale": 1.0, "jitter_amplitude_scale": 1.0,
         "extra_jitter": [Jitter("kappa", 2e-5, 150.0, 0.2), Jitter("omega", 1e-5, 9.0, 2.0)]},
    ],
)
def test_exact_under_strong_rates_and_jitter_matches_brute_force(kwargs):
    scene = build_scene("agile", **kwargs)
    rng = np.random.default_rng(3)
    row = rng.uniform(-0.4, scene.n_rows - 0.6, 300)
    col = rng.uniform(0, scene.n_columns - 1, 300)
    ground = scene.image_to_ground(row, col, height=rng.uniform(-300, 900, 300))
    truth = brute_force_rows(scene, ground)
    res = create("exact", scene).ground_to_image(ground)
    assert res.converged.all()
    assert np.max(np.abs(res.row - truth)) <= 1e-7
    assert np.max(np.abs(res.row - row)) <= 1e-7


@pytest.mark.parametrize("preset", ["WSU", pytest.param("agile", marks=pytest.mark.slow)])
def test_points_off_the_image_are_flagged_never_clipped(preset):
    scene = build_scene(preset)
    n = scene.n_rows
    method = create("exact", scene)  # search window: image +- 50 rows
    # (row, col) of ground points at the mean height
    rows = np.array([-0.3, n - 0.7, -3.0, n + 2.0, -40.0, n + 45.0, 700.0, -80.0, n + 400.0])
    cols = np.array([10.0, 20.0, 30.0, 40.0, 50.0, 60.0, scene.n_columns + 25.0, 70.0, 80.0])
    ground = scene.image_to_ground(rows, cols, height=scene.terrain.mean_height)
    far = np.array([[2e6, 2e6, 0.0], [-6e5, 0.0, 0.0]])
    above = scene.exterior.position(np.zeros(1)) + np.array([[0.0, 0.0, 1e5]])
    ground = np.vstack([ground, far, above])
    res = method.ground_to_image(ground)
    truth = brute_force_rows(scene, ground[:7], margin=60)
    # roots within the window: found exactly, flagged outside unless on the image
    np.testing.assert_allclose(res.row[:7], truth, atol=1e-7)
    np.testing.assert_allclose(res.row[:7], rows[:7], atol=1e-7)
    assert res.converged[:7].all()
    assert res.inside[:2].all() and not res.inside[2:7].any()
    # beyond the window, far away, above the satellite: not converged, no row
    assert not res.converged[7:].any()
    assert np.isnan(res.row[7:]).all() and not res.valid[7:].any()
    status = res.info["status"]
    assert (status[7:9] == STATUS_NO_ROOT_IN_WINDOW).all()
    # a point 2800 km away may also be behind the camera plane of a tilted view
    assert np.isin(status[9:11], [STATUS_NO_ROOT_IN_WINDOW, STATUS_INVALID]).all()
    assert status[11] == STATUS_INVALID
    assert res.ce_evaluations[7:].max() <= 4


def test_numpy_backend_gives_the_same_rows_counts_and_trace():
    if not NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    scene = build_scene("agile")
    check = simulate_points(scene, 2000, kind="scp")
    extra = scene.image_to_ground(np.array([-20.0, scene.n_rows + 80.0]), np.array([3.0, 4.0]))
    ground = np.vstack([check.ground, extra])
    a = create("exact", scene).ground_to_image(ground, trace=True)
    b = create("exact", scene, backend="numpy").ground_to_image(ground, trace=True)
    np.testing.assert_allclose(a.row, b.row, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.col, b.col, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(a.ce_evaluations, b.ce_evaluations)
    np.testing.assert_array_equal(a.converged, b.converged)
    assert len(a.trace) == len(b.trace) == a.ce_evaluations.max()
    for x, y in zip(a.trace, b.trace, strict=True):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-9)


def test_trace_lists_the_rows_evaluated():
    scene = build_scene("agile")
    check = simulate_points(scene, 500, kind="scp")
    res = create("exact", scene).ground_to_image(check.ground, trace=True)
    assert len(res.trace) == res.ce_evaluations.max()
    visited = np.sum([np.isfinite(r) for r in res.trace], axis=0)
    np.testing.assert_array_equal(visited, res.ce_evaluations)
    # the last row visited is within one Newton step (accept_step) of the returned row
    last = np.array([res.trace[k - 1][i] for i, k in enumerate(res.ce_evaluations)])
    assert np.max(np.abs(last - res.row)) <= create("exact", scene).accept_step + 1e-12


def test_setup_cost_and_parameters():
    scene = build_scene("WSU")
    m = create("exact", scene)
    assert "exact" in available()
    assert m.setup_ce >= 75
    assert m.accept_step > 0 and m.orient in (-1.0, 1.0)
    with pytest.raises(ValueError, match="device"):
        create("exact", scene, device="tpu")
    with pytest.raises(ValueError, match="backend"):
        create("exact", scene, backend="fortran")
    with pytest.raises(ValueError, match="seed_degree"):
        create("exact", scene, seed_degree=5)
    assert create("exact", scene, device="cpu").device == "cpu"


def test_torch_backend_equals_the_compiled_path_and_cuda_is_checked():
    """The torch path (device 'cpu' here; 'cuda' where a GPU exists) through the method interface."""
    torch = pytest.importorskip("torch")
    scene = build_scene("agile", relief_m=600.0, relief_seed=2)
    check = simulate_points(scene, 5000, kind="scp", seed=3)
    ref = create("exact", scene).ground_to_image(check.ground)
    tor = create("exact", scene, backend="torch").ground_to_image(check.ground)
    assert np.max(np.abs(tor.row - ref.row)) < 1e-9 and np.max(np.abs(tor.col - ref.col)) < 1e-9
    np.testing.assert_array_equal(tor.ce_evaluations, ref.ce_evaluations)
    np.testing.assert_array_equal(tor.valid, ref.valid)
    assert np.max(np.abs(tor.row - check.row)) < 1e-7
    if torch.cuda.is_available():
        gpu = create("exact", scene, device="cuda").ground_to_image(check.ground)
        assert np.max(np.abs(gpu.row - ref.row)) < 1e-6 and np.max(np.abs(gpu.col - ref.col)) < 1e-6
    else:
        with pytest.raises(ValueError, match="no CUDA device"):
            create("exact", scene, device="cuda")
