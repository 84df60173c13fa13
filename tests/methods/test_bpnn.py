"""``bpnn``: Yue et al.'s BP-network image geometry model, checked against exact simulated points.

Truth is the exact rows/columns of simulated SCPs (``simulate_points``) and exact ray/plane
intersections, never the network's own output.  Protocol of the paper's terrain-independent
experiment: train on a 10 x 10 x 5 grid (image grid x 5 height layers), check on a 5 x 5 x 5
grid of cell centres.  Measured (6 hidden sigmoid nodes, LM): WSU check planar RMS 0.024 px
after up to 2000 iterations (the paper, Table 2, 6 nodes: 0.02 px).  With one 600-iteration run
the result depends on the seed (WSU, seeds 0-3: 0.07, 0.62, 0.07, 0.06 px: LM sometimes sits in
a slow valley), so the tests take the best of two 600-iteration runs (measured 0.05-0.1 px).
The asserted bound, 0.5 px, is the paper's "sub-pixel" claim with a margin for the iteration
cap; a value near it would mean training failed.
"""

import numpy as np
import pytest

from explorer.errors import NotFittedError
from explorer.methods import create
from explorer.methods.bpnn import BPNetworkGeometryModel, compare_bpnn_rfm
from explorer.methods.rfm import image_space_grid
from explorer.points import simulate_points
from explorer.presets import build_scene

FAST = dict(max_iter=600, n_restarts=2)  # best of two short LM runs: seconds, not minutes
pytestmark = pytest.mark.filterwarnings("ignore:network training stopped at max_iter")


@pytest.fixture(scope="module")
def wsu():
    return build_scene("WSU")


@pytest.fixture(scope="module")
def fitted_wsu(wsu):
    scops = simulate_points(wsu, 100, layers=5)  # 10 x 10 x 5, edge to edge, 5 heights
    return create("bpnn", wsu, seed=3, **FAST).fit(scops)


def test_not_fitted_errors(wsu):
    with pytest.raises(NotFittedError):
        create("bpnn", wsu).ground_to_image(np.zeros((1, 3)))
    with pytest.raises(NotFittedError):
        BPNetworkGeometryModel().image_to_ground(np.zeros(1), np.zeros(1), np.zeros(1))


@pytest.mark.parametrize("preset", ["WSU", "SCB"])
def test_terrain_independent_check_rmse_is_sub_pixel(preset, wsu, fitted_wsu):
    scene = wsu if preset == "WSU" else build_scene(preset)
    method = fitted_wsu if preset == "WSU" else create("bpnn", scene, seed=3, **FAST).fit(
        simulate_points(scene, 100, layers=5))
    check = simulate_points(scene, 25, kind="scp", layers=5)
    res = method.ground_to_image(check.ground)
    assert res.valid.all()
    row_rmse = np.sqrt(np.mean((res.row - check.row) ** 2))
    col_rmse = np.sqrt(np.mean((res.col - check.col) ** 2))
    assert row_rmse < 0.5 and col_rmse < 0.5
    assert np.all(res.ce_evaluations == 0)
    assert np.all(res.info["iterations"] <= 8)  # Newton on a near-affine map


def test_image_to_ground_matches_exact_rays_at_intermediate_heights(wsu):
    row, col, ground = image_space_grid(wsu, (10, 10, 5))
    net = BPNetworkGeometryModel(6, seed=1, **FAST).fit(row, col, ground[:, 2], ground[:, 0], ground[:, 1])
    cr, cc, cg = image_space_grid(wsu, (5, 5, 5), cell_centred=True)  # heights between the layers
    x, y = net.image_to_ground(cr, cc, cg[:, 2])
    gsd = np.mean(wsu.ground_sample_distance())  # 0.5 m
    planar_px = np.hypot(x - cg[:, 0], y - cg[:, 1]) / gsd
    assert np.sqrt(np.mean(planar_px**2)) < 0.5
    assert net.fit_info["n_parameters"] == 3 * 6 + 6 + 6 * 2 + 2


def test_newton_inversion_recovers_image_coordinates_of_the_network(fitted_wsu, wsu):
    # Inversion property (not accuracy): image_to_ground(ground_to_image(P)) == P for the network.
    net = fitted_wsu.network
    rng = np.random.default_rng(2)
    row = rng.uniform(0, wsu.n_rows - 1, 200)
    col = rng.uniform(0, wsu.n_columns - 1, 200)
    z = rng.uniform(wsu.terrain.mean_height - 400, wsu.terrain.mean_height + 400, 200)
    x, y = net.image_to_ground(row, col, z)
    r, c, conv, its, _ = net.ground_to_image(x, y, z)
    assert conv.all()
    np.testing.assert_allclose(r, row, atol=1e-6)
    np.testing.assert_allclose(c, col, atol=1e-6)


def test_out_of_image_and_out_of_domain_points_are_flagged(fitted_wsu, wsu):
    h = wsu.terrain.mean_height
    rows = np.array([-60.0, wsu.n_rows + 60.0, 500.0, 500.0, 2000.0])
    cols = np.array([500.0, 500.0, -60.0, wsu.n_columns + 60.0, 2000.0])
    ground = wsu.image_to_ground(rows, cols, height=h)
    res = fitted_wsu.ground_to_image(ground, trace=True)
    assert not res.valid[:4].any()
    assert not res.inside[:4].any()
    assert res.valid[4]
    assert len(res.trace) >= 2 and res.trace[0].shape == (5,)
    far = np.array([[0.0, 0.0, h + 3000.0], [80_000.0, 0.0, h]])
    res = fitted_wsu.ground_to_image(far)
    assert not res.valid.any()


def test_single_height_training_refuses_other_heights():
    scene = build_scene("SCB")
    method = create("bpnn", scene, seed=0, max_iter=300).fit(simulate_points(scene, 100))  # one plane
    assert method.fit_info["degenerate_height"]
    row, col = np.array([1000.0]), np.array([700.0])
    on_plane = scene.image_to_ground(row, col)
    above = scene.image_to_ground(row, col, height=scene.terrain.mean_height + 50.0)
    res = method.ground_to_image(np.vstack([on_plane, above]))
    assert res.valid[0] and not res.valid[1]


def test_seeded_reproducibility(wsu):
    row, col, g = image_space_grid(wsu, (6, 6, 3))
    a = BPNetworkGeometryModel(4, seed=5, max_iter=100).fit(row, col, g[:, 2], g[:, 0], g[:, 1])
    b = BPNetworkGeometryModel(4, seed=5, max_iter=100).fit(row, col, g[:, 2], g[:, 0], g[:, 1])
    c = BPNetworkGeometryModel(4, seed=6, max_iter=100).fit(row, col, g[:, 2], g[:, 0], g[:, 1])
    xa, _ = a.image_to_ground(row, col, g[:, 2])
    xb, _ = b.image_to_ground(row, col, g[:, 2])
    xc, _ = c.image_to_ground(row, col, g[:, 2])
    np.testing.assert_array_equal(xa, xb)
    assert np.max(np.abs(xa - xc)) > 0


def test_compare_bpnn_rfm_terrain_independent_table():
    scene = build_scene("SCB")
    tab = compare_bpnn_rfm(scene, hidden_nodes=(6,), max_iter=600, seed=0)
    assert tab["n_train"] == 500 and tab["n_check"] == 125
    row = tab["bpnn"][0]
    for part in ("control", "check", "control_m", "check_m"):
        for axis in ("X", "Y", "planar"):
            for stat in ("max", "rms"):
                assert np.isfinite(row[part][axis][stat])
                assert np.isfinite(tab["rfm"][part][axis][stat])
    assert row["check"]["planar"]["rms"] < 0.5
    # The cubic RFM reproduces this smooth orbit to round-off (see test_rfm.py): far below the network.
    assert tab["rfm"]["check"]["planar"]["max"] < 1e-6
    assert tab["rfm"]["check_image_px"]["row"]["max"] < 1e-6


def test_compare_bpnn_rfm_terrain_dependent_counts():
    scene = build_scene("SCB", relief_m=500.0, relief_seed=2)
    tab = compare_bpnn_rfm(scene, mode="terrain-dependent", hidden_nodes=(4,), max_iter=300, seed=1)
    assert tab["n_train"] == 100 and tab["n_check"] == 22
    assert np.isfinite(tab["bpnn"][0]["check"]["planar"]["rms"])
    assert np.isfinite(tab["rfm"]["check"]["planar"]["rms"])
    with pytest.raises(ValueError):
        compare_bpnn_rfm(scene, mode="nope")


# ------------------------------------------------------------------ seed fragility (the line-of-sight network)
#: Seeds at which Yue's free-Z network failed the contract (row max 18.9 / 0.9 / 5.2 px with 20 / 31 / 23 % of the
#: check points flagged; 1,046 / 1,263 / 1,220 m ground error between the SCOPs' height layers).
FRAGILE_SEEDS = (4, 6, 7)


def contract_scene():
    from tests.methods.cases import scene_for

    return scene_for("WSU", 800.0)


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5, 6, 7])
def test_every_seed_meets_the_declared_exactness_on_the_contract_scene(seed):
    """The contract (seed 0 is tests/methods/test_contract.py) at every other seed: every check point valid, row
    and column within the approximate bar (1 px; measured <= 0.0003 px), and the network between the SCOPs'
    3 height layers a line of sight: its ground error at the check points' own heights is millimetres.  Truth:
    the check points' exact (row, col) and ground from the scene's own projection."""
    from tests.methods.test_contract import BAR_PX, contract_points

    scops, check = contract_points()
    method = create("bpnn", contract_scene(), seed=seed).fit(scops)
    res = method.ground_to_image(check.ground)
    assert res.valid.all(), (seed, 1 - res.valid.mean())
    assert np.max(np.abs(res.row - check.row)) <= BAR_PX["approximate"]
    assert np.max(np.abs(res.col - check.col)) <= BAR_PX["approximate"]
    assert np.max(np.abs(res.row - check.row)) < 0.01  # far inside it: not a near miss of the bar
    x, y = method.network.image_to_ground(check.row, check.col, check.ground[:, 2])
    assert np.max(np.hypot(x - check.ground[:, 0], y - check.ground[:, 1])) < 0.01  # metres, between the layers


@pytest.mark.slow
def test_the_free_z_network_is_what_was_fragile():
    """The cause, shown: Yue et al.'s network literally (``network="free"``, Z a third sigmoid input) fits its 3
    training layers to centimetres at the seeds that failed, yet is hundreds of metres off between them, and the
    method then misses the bar or flags a fifth of the points."""
    from tests.methods.test_contract import BAR_PX, contract_points

    scops, check = contract_points()
    for seed in FRAGILE_SEEDS:
        method = create("bpnn", contract_scene(), seed=seed, network="free").fit(scops)
        assert max(method.fit_info["train_rms"]) < 0.2  # metres, on the 3 layers
        x, y = method.network.image_to_ground(check.row, check.col, check.ground[:, 2])
        assert np.max(np.hypot(x - check.ground[:, 0], y - check.ground[:, 1])) > 100.0  # between the layers
        res = method.ground_to_image(check.ground)
        err = np.abs(res.row - check.row)[res.valid]
        assert res.valid.mean() < 0.9 or np.max(err) > BAR_PX["approximate"], seed


def test_unknown_network_is_refused(wsu):
    with pytest.raises(ValueError, match="line-of-sight"):
        create("bpnn", wsu, network="deep")


def test_scops_on_one_height_are_fitted_by_the_free_network_within_a_pixel_on_the_pleiades_rpc():
    """A real sensor with SCOPs on one height (the Pleiades RPC without a DEM, 100 SCOPs as the explorer draws
    them): there is no space between layers, and the line-of-sight network trained worse there (0.25-1.75 px RMS,
    11 px max over seeds 0-5), so the method fits Yue's network -- the same numbers as ``network="free"``.  Truth:
    the RPC's own projection of the check points (the explorer's sensor_truth); measured 0.06-0.15 px RMS,
    <= 0.43 px max over seeds 0-5."""
    from explorer.app.model import ExplorerModel, Settings
    from explorer.sources import load_source
    from tests.test_explore_export import RPC_PHR

    src = load_source("rpc", str(RPC_PHR))
    s = Settings(preset=src.label, methods=("bpnn",))
    model = ExplorerModel(preview_after_s=None, seed=0, scenes={s.preset: src.scene})
    scops, scps = model.scops(s, 100), model.scps(s).sample(5000, 1)
    assert np.ptp(scops.ground[:, 2]) < 1e-6
    for seed in (0, 1, 5):
        method = create("bpnn", src.scene, seed=seed).fit(scops)
        assert method.fit_info["network_kind"] == "free (SCOPs on one height)"
        res = method.ground_to_image(scps.ground)
        free = create("bpnn", src.scene, seed=seed, network="free").fit(scops).ground_to_image(scps.ground)
        np.testing.assert_array_equal(res.row, free.row)
        assert res.valid.all()
        err = res.row - scps.row
        assert np.sqrt(np.mean(err**2)) < 0.25 and np.max(np.abs(err)) < 1.0, seed
