"""The compiled Levenberg-Marquardt trainer of one-hidden-layer networks (explorer/methods/_lm_compiled.py, the
trainer of bpnn and nn-rfm) against the torch trainer it replaces (explorer.methods._lm.lm_minimise with the
networks' back-propagated Jacobians, checked against autograd in test_lm_jacobian.py): the same epochs, the same
stop reason and the same weights to round-off over short trainings, for every network kind and option it serves;
the same bits run to run; networks it does not serve still train (by torch)."""

from __future__ import annotations

import numpy as np
import pytest

from explorer.methods import _lm_compiled, bpnn
from tests.methods.cases import caller_at_two_blas_threads, scene_for

pytestmark = pytest.mark.skipif(not _lm_compiled.NUMBA_AVAILABLE, reason="numba is not installed")


@pytest.fixture(scope="module")
def data():
    from explorer.points import simulate_points

    scops = simulate_points(scene_for("WSU", 800.0), 120, kind="scop", layers=3)
    g = scops.ground
    return scops.row, scops.col, g[:, 2], g[:, 0], g[:, 1]


def _both(monkeypatch, make, fit):
    out = []
    for compiled in (False, True):
        monkeypatch.setattr(bpnn.MLPRegressor, "compiled_training", compiled)
        net = make()
        calls = []
        original = net._levenberg_marquardt_compiled
        net._levenberg_marquardt_compiled = lambda *a, _o=original, _c=calls: _c.append(1) or _o(*a)
        fit(net)
        assert bool(calls) is compiled  # the path under test was the one taken
        out.append(net)
    return out


CASES = {
    "line-of-sight (bpnn, nn-rfm)": dict(cls=bpnn.LineOfSightNetwork, hidden=6, opts={}),
    "free, Yue's network": dict(cls=bpnn.BPNetworkGeometryModel, hidden=5, opts={}),
    "line-of-sight, validation split": dict(cls=bpnn.LineOfSightNetwork, hidden=7, opts={"validation_fraction": 0.2}),
    "free, tanh, weight decay": dict(cls=bpnn.BPNetworkGeometryModel, hidden=4,
                                     opts={"activation": "tanh", "weight_decay": 1e-6}),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_compiled_training_equals_the_torch_trainer(data, monkeypatch, case):
    c = CASES[case]
    torch_net, numba_net = _both(monkeypatch, lambda: c["cls"](c["hidden"], max_iter=30, seed=3, **c["opts"]),
                                 lambda net: net.fit(*data))
    a, b = torch_net.fit_info, numba_net.fit_info
    assert a["iterations"] == b["iterations"] and a["stop"] == b["stop"]
    assert a["iterations"] >= 10
    np.testing.assert_allclose(numba_net._theta, torch_net._theta, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(b["train_rms"], a["train_rms"], rtol=1e-8)
    np.testing.assert_allclose(b["window_decrease"], a["window_decrease"], rtol=1e-8, atol=1e-12)
    x = np.column_stack(data[:3])
    np.testing.assert_allclose(numba_net.predict(x), torch_net.predict(x), rtol=0, atol=1e-6)  # metres
    if "validation_rms" in a:
        np.testing.assert_allclose(b["validation_rms"], a["validation_rms"], rtol=1e-8)


@pytest.mark.parametrize(("opts", "stop"), [({"tol": 0.5, "window": 3}, "plateau"),
                                            ({"validation_fraction": 0.2, "max_fail": 1}, "validation")])
def test_the_stopping_rules_stop_at_the_same_epoch(data, monkeypatch, opts, stop):
    torch_net, numba_net = _both(monkeypatch, lambda: bpnn.LineOfSightNetwork(6, max_iter=400, seed=1, **opts),
                                 lambda net: net.fit(*data))
    assert torch_net.fit_info["stop"] == numba_net.fit_info["stop"] == stop
    assert torch_net.fit_info["iterations"] == numba_net.fit_info["iterations"] < 400
    np.testing.assert_allclose(numba_net._theta, torch_net._theta, rtol=1e-8, atol=1e-10)


def test_three_outputs_of_the_surface_network(monkeypatch):
    """nn-rfm's surface variant: (row, col) -> (X, Y, Z), an MLPRegressor with three outputs."""
    rng = np.random.default_rng(4)
    rc = rng.uniform(0, 1000, (80, 2))
    xyz = np.column_stack([2 * rc[:, 0] + 0.01 * rc[:, 1] ** 1.5, 3 * rc[:, 1], 50 * np.sin(rc[:, 0] / 300)])
    torch_net, numba_net = _both(monkeypatch, lambda: bpnn.MLPRegressor(5, max_iter=25, seed=2),
                                 lambda net: net.fit_arrays(rc, xyz))
    assert torch_net.fit_info["iterations"] == numba_net.fit_info["iterations"] >= 10
    np.testing.assert_allclose(numba_net._theta, torch_net._theta, rtol=1e-9, atol=1e-11)


def test_same_bits_run_to_run_and_several_layers_train_by_torch(data):
    one, two = (bpnn.LineOfSightNetwork(6, max_iter=300, seed=5).fit(*data) for _ in range(2))
    assert one.fit_info["iterations"] == two.fit_info["iterations"] > 100
    assert np.array_equal(one._theta, two._theta)
    deep = bpnn.BPNetworkGeometryModel((4, 3), max_iter=40, seed=0)
    deep._levenberg_marquardt_compiled = None  # not the compiled trainer: it serves one hidden layer only
    deep.fit(*data)
    assert deep.fit_info["iterations"] > 0 and np.isfinite(deep.fit_info["train_rms"]).all()


def test_the_compiled_training_runs_on_one_blas_thread(data, monkeypatch):
    """Its J_o^T J_o products go to OpenBLAS (numba's np.dot): on OpenBLAS's threads they cost 25x on a busy machine
    (measured 5.2 ms against 0.2 ms per epoch at 1,000 points, load 6), and a network trained outside a method's fit
    (compare_bpnn_rfm, fit_nn_rfm) has no other guard."""
    from explorer import _threads

    if _threads.blas_thread_count() is None:
        pytest.skip("no OpenBLAS found in this process")
    seen = []
    original = bpnn.lm_one_hidden

    def spy(*args):
        seen.append(_threads.blas_thread_count())
        return original(*args)

    monkeypatch.setattr(bpnn, "lm_one_hidden", spy)
    with caller_at_two_blas_threads():
        bpnn.LineOfSightNetwork(6, max_iter=5, seed=0).fit(*data)
        assert _threads.blas_thread_count() == 2  # restored
    assert seen == [1]


def test_the_damped_step_solves_by_cholesky_and_falls_back_to_least_squares():
    """Its Cholesky solve against numpy's dense solve (positive definite), and a matrix Cholesky cannot factor (a
    weight no error depends on: a zero row and column of J^T J, no damping) solved by least squares (numpy's
    minimum-norm solution), as torch's trainer does, instead of a division by a zero pivot."""
    rng = np.random.default_rng(0)
    jac = rng.normal(size=(60, 12))
    product, rhs = jac.T @ jac, rng.normal(size=12)
    np.testing.assert_allclose(_lm_compiled._damped_step(product, rhs, 1e-3),
                               np.linalg.solve(product + 1e-3 * np.eye(12), rhs), rtol=1e-10)
    jac[:, 5] = 0.0
    product = jac.T @ jac
    rhs = jac.T @ rng.normal(size=60)
    step = _lm_compiled._damped_step(product, rhs, 0.0)
    assert np.isfinite(step).all() and abs(step[5]) < 1e-12  # a zero pivot would give inf / NaN
    np.testing.assert_allclose(step, np.linalg.lstsq(product, rhs, rcond=None)[0], rtol=1e-8, atol=1e-12)
