"""The compiled passes of explorer.methods._compiled against their numpy / torch twins: image-footprint
flags, polynomial regression and sigmoid-MLP inference, and the vectorisable exp."""

import numpy as np
import pytest

from explorer.geometry.kernels import NUMBA_AVAILABLE
from explorer.methods._compiled import inside_flags, mlp_predict, polynomial_predict
from explorer.methods._lm import GroundFeatures, SigmoidMLP, TrainedNetwork
from explorer.methods.regression import design_matrix, monomial_exponents
from explorer.points import PointSet

pytestmark = pytest.mark.skipif(not NUMBA_AVAILABLE, reason="the compiled passes need numba")


def _control(n=60, height_span=200.0, seed=0):
    rng = np.random.default_rng(seed)
    ground = np.column_stack([rng.uniform(-5e3, 5e3, n), rng.uniform(-8e3, 8e3, n),
                              100.0 + rng.uniform(0, height_span, n)])
    return PointSet(rng.uniform(0, 4000, n), rng.uniform(0, 4000, n), ground, np.zeros(n))


def _query(n=5000, seed=1):
    """Points inside and up to 30 % outside the control extent, on and off the control heights."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-6.5e3, 6.5e3, n), rng.uniform(-1e4, 1e4, n),
                            100.0 + rng.uniform(-100, 300, n)])


def test_inside_flags_equal_the_scene_rule():
    rng = np.random.default_rng(0)
    row = rng.uniform(-3, 103, 20000)
    col = rng.uniform(-3, 53, 20000)
    row[:6] = [np.nan, np.inf, -np.inf, -0.5, 99.5, 99.5000001]
    col[6:9] = [np.nan, -0.5, 49.5]
    mask = rng.random(20000) < 0.8
    expect = (row >= -0.5) & (row <= 99.5) & (col >= -0.5) & (col <= 49.5)
    np.testing.assert_array_equal(inside_flags(row, col, 100, 50), expect)
    np.testing.assert_array_equal(inside_flags(row, col, 100, 50, mask), expect & mask)
    assert not inside_flags(row[:3], col[:3], 100, 50).any()


@pytest.mark.parametrize("use_height", [True, False])
@pytest.mark.parametrize("degree", [1, 2, 3])
def test_polynomial_predict_equals_the_design_matrix_product(degree, use_height):
    control = _control(height_span=200.0 if use_height else 0.0)
    feats = GroundFeatures(control, use_height, 0.05, 1.0)
    exps = monomial_exponents(feats.n_features, degree)
    coef = np.random.default_rng(3).normal(size=(exps.shape[0], 2)) * 100
    ground = _query()
    if not use_height:  # most points on the control plane (height 100 m), the rest off it
        ground[::4, 2] = 100.0 + np.random.default_rng(2).uniform(-0.5, 0.5, ground[::4].shape[0])
        ground[1::4, 2] = 100.0
        ground[2::4, 2] = 100.0
    values, ok = polynomial_predict(feats, ground, exps, coef)
    f, ok_ref = feats(ground)
    np.testing.assert_array_equal(ok, ok_ref)
    assert 0.2 < ok.mean() < 0.95  # both sides of the domain are exercised
    expect = design_matrix(f, exps) @ coef
    np.testing.assert_allclose(values.T, expect, rtol=1e-13, atol=1e-10)


@pytest.mark.parametrize("hidden", [(10,), (7, 5)])
def test_mlp_predict_equals_the_torch_network(hidden):
    import torch

    control = _control()
    feats = GroundFeatures(control, True, 0.05, 1.0)
    net = SigmoidMLP(3, hidden)
    theta = net.init_params(torch.Generator().manual_seed(5)) * 4.0  # steep: sigmoids near 0 and 1 too
    trained = TrainedNetwork(net, theta, 2000.0, 1500.0, torch.device("cpu"))
    ground = _query()
    values, ok = mlp_predict(feats, ground, trained.theta_numpy, trained.layer_sizes, 1500.0, 2000.0)
    f, ok_ref = feats(ground)
    np.testing.assert_array_equal(ok, ok_ref)
    with torch.no_grad():  # the torch network itself (TrainedNetwork.predict runs numpy on the CPU)
        expected = net.forward(theta, torch.from_numpy(f)).numpy() * 1500.0 + 2000.0
    np.testing.assert_allclose(values, expected, rtol=1e-13, atol=1e-9)


def test_vectorised_exp_is_as_accurate_as_libm():
    from explorer.geometry.kernels import njit
    from explorer.methods._compiled import _exp_block

    @njit
    def run(x):
        e = x.copy()
        _exp_block(e, e.shape[0], np.empty(e.shape[0]))
        return e

    x = np.concatenate([np.linspace(-700, 700, 200001), np.random.default_rng(0).normal(0, 5, 100000)])
    rel = np.abs(run(x) / np.exp(x) - 1.0)
    assert rel.max() < 4.5e-16  # about 2 ulp
    big = run(np.array([-1000.0, 1000.0]))  # clamped to +-708: no overflow to inf or 0
    assert np.all(np.isfinite(big)) and big[0] > 0
