"""``nn-rfm``: Habib et al.'s hybrid network + RFM, against exact simulated points.

Truth: exact rows/columns of simulated SCPs and exact ray/terrain intersections.  Measured with
the defaults (7 sigmoid nodes, 12 x 12 x 5 synthetic grid, Tikhonov 1e-5):

* fitted on exact SCOPs (a regular grid on the terrain, 400 points) the final RFM reproduces
  SCP rows/cols to 0.13 / 0.10 px RMS on QII with 300 m relief (the network's own accuracy)
  and 0.003 px on flat SCB; the bounds below (0.5 px, 0.05 px) keep a 4x margin or more;
* on 572 irregular GCPs with 0.5 px / 0.3 m noise (QII, 300 m relief, 500 check points) the
  hybrid beats the direct cubic RFM in all of seeds 0-4 (see ``compare_nn_rfm``'s notes); the
  test uses seed 1 (direct 0.39 m with 2 failed check points, hybrid 0.18 m).  With only the
  paper's 9 check points the direct RFM is as good or better in all five seeds: its failures
  are local poles that 9 random points rarely hit, so 500 check points are used here.
"""

import numpy as np
import pytest

from explorer.errors import NotFittedError
from explorer.methods import create
from explorer.methods.nn_rfm import compare_nn_rfm, irregular_gcps
from explorer.points import simulate_points
from explorer.presets import build_scene

pytestmark = pytest.mark.filterwarnings("ignore:network training stopped at max_iter")


@pytest.fixture(scope="module")
def qii():
    return build_scene("QII", relief_m=300.0, relief_seed=1)


@pytest.fixture(scope="module")
def fitted_qii(qii):
    return create("nn-rfm", qii, seed=0).fit(simulate_points(qii, 400))


def test_not_fitted_error(qii):
    with pytest.raises(NotFittedError):
        create("nn-rfm", qii).ground_to_image(np.zeros((1, 3)))


def test_scanline_accuracy_on_relief_from_exact_scops(fitted_qii, qii):
    check = simulate_points(qii, 400, kind="scp")  # cell-centred grid on the DEM
    res = fitted_qii.ground_to_image(check.ground)
    assert res.valid.all()
    assert np.sqrt(np.mean((res.row - check.row) ** 2)) < 0.5
    assert np.sqrt(np.mean((res.col - check.col) ** 2)) < 0.5
    assert np.all(res.ce_evaluations == 0)
    assert fitted_qii.fit_info["n_synthetic"] == 720


def test_flat_scene_single_layer_and_height_domain():
    scene = build_scene("SCB")
    method = create("nn-rfm", scene, seed=0, max_iter=400).fit(simulate_points(scene, 200))
    assert len(method.fit_info["synthetic_heights_m"]) == 1
    check = simulate_points(scene, 200, kind="scp")
    res = method.ground_to_image(check.ground)
    assert res.valid.all()
    assert np.sqrt(np.mean((res.row - check.row) ** 2)) < 0.05
    above = scene.image_to_ground(np.array([1000.0]), np.array([700.0]), height=scene.terrain.mean_height + 30.0)
    assert not method.ground_to_image(above).valid[0]


def test_out_of_image_points_are_flagged(fitted_qii, qii):
    rows = np.array([-80.0, qii.n_rows + 80.0, 3000.0, 3000.0])
    cols = np.array([3000.0, 3000.0, -80.0, qii.n_columns + 80.0])
    ground = qii.image_to_ground(rows, cols, height=qii.terrain.mean_height)
    res = fitted_qii.ground_to_image(ground, trace=True)
    assert not res.valid.any()
    assert not res.inside.any()
    assert len(res.trace) == 1
    far = np.array([[90_000.0, 0.0, qii.terrain.mean_height]])
    assert not fitted_qii.ground_to_image(far).valid[0]


def test_irregular_gcps_are_exact_before_noise_and_noise_has_the_requested_sigma(qii):
    exact, noisy = irregular_gcps(qii, 572, noise_px=0.5, noise_m=0.3, seed=3)
    assert len(exact) == 572
    # exact points lie on the DEM, at the ray of their image coordinates
    np.testing.assert_allclose(exact.ground[:, 2], qii.terrain.height(exact.ground[:, 0], exact.ground[:, 1]),
                               atol=1e-6)
    again = qii.image_to_ground(exact.row, exact.col)
    np.testing.assert_allclose(again, exact.ground, atol=1e-6)
    # sample std of 572 normals is within ~6 % of sigma (1 sigma of the estimate is 3 %)
    assert np.std(noisy.row - exact.row) == pytest.approx(0.5, rel=0.1)
    assert np.std(noisy.ground - exact.ground) == pytest.approx(0.3, rel=0.1)


def test_compare_hybrid_beats_direct_rfm_on_irregular_noisy_gcps(qii):
    tab = compare_nn_rfm(qii, n_checks=500, noise_px=0.5, noise_m=0.3, seed=1)
    for key in ("rfm", "nn_rfm", "nn"):
        for stat in ("rms_x", "rms_y", "rms_total", "mean_x", "mean_y"):
            assert np.isfinite(tab[key][stat])
    assert tab["n_gcps"] == 572 and tab["n_checks"] == 500
    assert tab["nn_rfm"]["n_failed"] == 0
    assert tab["nn_rfm"]["rms_total"] < tab["rfm"]["rms_total"]
    # and in image space (no inversion involved): the RFM poles show up as large errors
    assert tab["nn_rfm"]["image_max_px"] < tab["rfm"]["image_max_px"]
    assert tab["paper"]["nn_rfm"]["rms_x"] == 0.851


def test_compare_nine_check_points_like_the_paper_returns_finite_numbers(qii):
    tab = compare_nn_rfm(qii, n_gcps=150, n_checks=9, seed=2, max_iter=300)
    assert tab["n_checks"] == 9 and len(tab["rfm"]["err_x"]) == 9
    assert np.isfinite(tab["nn_rfm"]["rms_total"]) and np.isfinite(tab["rfm"]["rms_total"])


def test_seeded_reproducibility():
    scene = build_scene("SCB", relief_m=200.0, relief_seed=5)
    scops = simulate_points(scene, 120)
    ground = simulate_points(scene, 50, kind="scp").ground
    a = create("nn-rfm", scene, seed=4, max_iter=200).fit(scops).ground_to_image(ground)
    b = create("nn-rfm", scene, seed=4, max_iter=200).fit(scops).ground_to_image(ground)
    c = create("nn-rfm", scene, seed=5, max_iter=200).fit(scops).ground_to_image(ground)
    np.testing.assert_array_equal(a.row, b.row)
    assert np.max(np.abs(a.row - c.row)) > 0


def test_surface_variant_on_flat_terrain():
    scene = build_scene("SCB")
    method = create("nn-rfm", scene, synthetic="surface", seed=0, max_iter=400).fit(simulate_points(scene, 200))
    check = simulate_points(scene, 200, kind="scp")
    res = method.ground_to_image(check.ground)
    assert res.valid.all()
    assert np.sqrt(np.mean((res.row - check.row) ** 2)) < 0.1
    assert np.sqrt(np.mean((res.col - check.col) ** 2)) < 0.1
    with pytest.raises(ValueError):
        create("nn-rfm", scene, synthetic="surface", grid=(10, 10, 3)).fit(simulate_points(scene, 50))


#: The contract scene (tests/methods/test_contract.py: WSU, 800 m relief, 200 SCOPs on 3 height layers, 500
#: check points on the terrain), where Yue et al.'s free-Z network made nn-rfm seed-fragile.
FRAGILE_SEEDS = (1, 2)  # the free network: 111 px and 2,381 px at these seeds (measured)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4, 5])
def test_line_of_sight_network_meets_the_sub_pixel_bar_at_every_seed(seed):
    """The seed fragility is gone: every seed is sub-pixel on the contract scene (the approximate bar, 1 px;
    measured 0.0004-0.0012 px over seeds 0-7), and the network between the training heights is a line of sight:
    its ground error at the check points' own heights is centimetres (it was 1.6 / 440 / 446 m for seeds 0-2)."""
    from tests.methods.test_contract import BAR_PX, contract_points

    scops, check = contract_points()
    method = create("nn-rfm", scops_scene(), seed=seed).fit(scops)
    res = method.ground_to_image(check.ground)
    assert res.valid.all()
    assert np.max(np.abs(res.row - check.row)) <= BAR_PX["approximate"]
    assert np.max(np.abs(res.col - check.col)) <= BAR_PX["approximate"]
    x, y = method.network.image_to_ground(check.row, check.col, check.ground[:, 2])
    assert np.max(np.hypot(x - check.ground[:, 0], y - check.ground[:, 1])) < 0.5  # metres (GSD 0.5 m)


@pytest.mark.slow
def test_the_free_z_network_is_what_was_fragile():
    """The cause, shown: the chain as it was (Yue et al.'s free-Z network, ``network="free"``, 15 % held out)
    misses the bar by orders of magnitude at the seeds that failed, while fitting its 3 training layers to
    centimetres."""
    from tests.methods.test_contract import contract_points

    scops, check = contract_points()
    for seed in FRAGILE_SEEDS:
        method = create("nn-rfm", scops_scene(), seed=seed, network="free", validation_fraction=0.15).fit(scops)
        assert max(method.fit_info["network"]["train_rms"]) < 0.05  # metres, on the 3 layers
        x, y = method.network.image_to_ground(check.row, check.col, check.ground[:, 2])
        assert np.max(np.hypot(x - check.ground[:, 0], y - check.ground[:, 1])) > 100.0  # between the layers
        res = method.ground_to_image(check.ground)
        assert np.nanmax(np.abs(res.row - check.row)) > 10.0


def test_line_of_sight_network_is_affine_in_height_at_an_image_point():
    """(X, Y) at a fixed (row, col) is exactly affine in Z (a straight line of sight), whatever the weights."""
    from explorer.methods.nn_rfm import LineOfSightNetwork

    scene = build_scene("WSU", relief_m=400.0)
    scops = simulate_points(scene, 100, layers=3)
    net = LineOfSightNetwork(5, max_iter=30, seed=3).fit(scops.row, scops.col, scops.ground[:, 2],
                                                         scops.ground[:, 0], scops.ground[:, 1])
    z = np.linspace(-800.0, 1500.0, 7)
    x, y = net.image_to_ground(np.full(7, 1234.5), np.full(7, 987.0), z)
    for v in (x, y):
        second = np.diff(v, 2)  # second differences of an affine function vanish
        assert np.max(np.abs(second)) < 1e-9 * max(1.0, np.max(np.abs(v)))
    # and the hand-written Jacobian is the derivative of the forward pass (central differences)
    import torch

    theta = torch.tensor(net._theta)  # the torch trainer's Jacobian, on torch tensors
    u = torch.tensor(net._normalise_inputs(np.column_stack([scops.row[:5], scops.col[:5], scops.ground[:5, 2]])))
    jac = net._jacobian(theta, u)
    h = 1e-6
    for k in (0, 7, theta.numel() - 1):
        e = torch.zeros_like(theta)
        e[k] = h
        fd = (net._forward(theta + e, u) - net._forward(theta - e, u)).reshape(-1) / (2 * h)
        np.testing.assert_allclose(jac[:, k].numpy(), fd.numpy(), rtol=1e-6, atol=1e-8)


def scops_scene():
    from tests.methods.cases import scene_for

    return scene_for("WSU", 800.0)


@pytest.mark.slow
def test_every_seed_is_sub_pixel_on_the_pleiades_dimap_with_its_dem():
    """A real sensor: the rigorous Pleiades DIMAP model on its DEM (tests/data/rpc, assets/dem), 100 SCOPs on the
    terrain as the explorer draws them, the check points' exact rows by the model's own ground to image.  Every
    seed is sub-pixel (measured 0.02-0.05 px RMS, <= 0.23 px max over seeds 0-5); before, 1.26 px RMS at seed 0,
    and an intermediate free-slope network reached 570 px at seed 3."""
    from explorer.app.model import ExplorerModel, Settings
    from explorer.sources import load_source
    from tests.real.conftest import DEM_DIR, PHR_2017

    src = load_source("dimap", str(PHR_2017), dem=str(DEM_DIR / "MNT_P1BP--2017030824934340CP.tif"))
    s = Settings(preset=src.label, scop_density=100, scp_count=5000, methods=("nn-rfm",))
    model = ExplorerModel(preview_after_s=None, seed=0, scenes={s.preset: src.scene})
    scops, scps = model.scops(s), model.scps(s)
    assert len(scops) == 100
    for seed in (0, 1, 2, 3):
        res = create("nn-rfm", src.scene, seed=seed).fit(scops).ground_to_image(scps.ground)
        # flagged, not extrapolated: the few check points beyond the SCOPs' height range (+5 %) of the RFM box
        assert res.valid.mean() > 0.99 and np.array_equal(res.valid, res.info["in_domain"] & res.inside), seed
        err = np.abs(res.row - scps.row)[res.valid]
        assert np.sqrt(np.mean(err**2)) < 0.25 and np.max(err) < 1.0, (seed, np.sqrt(np.mean(err**2)), np.max(err))
