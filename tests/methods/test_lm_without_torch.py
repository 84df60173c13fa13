"""``mlp`` and ``ann`` trained and evaluated without torch (explorer.methods._lm.fit_network's compiled path:
TorchUniform first weights, explorer.methods._lm_compiled.train_one_hidden, numpy prediction) against the torch
trainer it replaces (explorer.methods._lm.levenberg_marquardt, whose back-propagated Jacobian is checked against
autograd in test_lm_jacobian.py): the same first weights bit for bit, the same epochs, stop reason and weights to
round-off over short trainings -- in the J^T J form and in the dual J J^T form (fewer errors than weights) --, the
same rows from mlp and ann fitted both ways on a preset and on the Pleiades DIMAP with its DEM, the same bits run
to run, several hidden layers still by torch, and a process that fits and evaluates both methods never imports
torch."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from explorer.methods import _lm, _lm_compiled
from explorer.methods._torch_uniform import TorchUniform

pytestmark = pytest.mark.skipif(not _lm_compiled.NUMBA_AVAILABLE, reason="numba is not installed")

torch = pytest.importorskip("torch")


@pytest.mark.parametrize("n_inputs", [1, 2, 3])
@pytest.mark.parametrize("hidden", [(5,), (10,), (30,), (4, 3)])
@pytest.mark.parametrize("seed", [0, 7, 2**40 + 3])
def test_first_weights_equal_torchs_bit_for_bit(n_inputs, hidden, seed):
    net = _lm.SigmoidMLP(n_inputs, hidden)
    expected = net.init_params(torch.Generator().manual_seed(seed)).numpy()
    np.testing.assert_array_equal(net.init_params_numpy(TorchUniform(seed)), expected)


def _problem(n, n_inputs, seed, kind="smooth"):
    """Normalised inputs and targets of an mlp-like problem: a smooth non-linear function (what remains of a row
    after its affine trend), scaled to [-1, 1], split 70/30 as fit_network splits."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (n, n_inputs))
    y = np.sin(1.3 * x[:, 0]) * np.cos(0.7 * x[:, -1]) + 0.3 * x[:, 0] ** 2
    if kind == "noisy":
        y = y + 0.05 * rng.normal(size=n)
    y = (y - (y.max() + y.min()) / 2) / ((y.max() - y.min()) / 2)
    tr, va = _lm.split_train_validation(n, 0.7, seed)
    return x[tr], y[tr], x[va], y[va]


def _both(net, seed, data, **options):
    theta0 = net.init_params(torch.Generator().manual_seed(seed))
    ref = _lm.levenberg_marquardt(net, theta0, *data, **options)
    got = _lm.levenberg_marquardt_compiled(net, theta0.numpy(), *data, **options)
    return ref, got


def _reordering_spread(net, seed, data, **options):
    """The torch trainer's own round-off: the largest weight difference (P,) between its training and its trainings
    on the same points in three other orders (the same problem, sums in another order -- as the compiled trainer's
    sums are).  An ill-conditioned early step amplifies it: measured up to 1.9e-9 on weights of order 1."""
    xt, yt, xv, yv = data
    ref = _lm.levenberg_marquardt(net, net.init_params(torch.Generator().manual_seed(seed)), *data, **options)
    spread = np.zeros(net.n_params)
    for k in range(3):
        p = np.random.default_rng(k).permutation(yt.size)
        other = _lm.levenberg_marquardt(net, net.init_params(torch.Generator().manual_seed(seed)), xt[p], yt[p], xv,
                                        yv, **options)
        assert other.epochs == ref.epochs
        spread = np.maximum(spread, np.abs(other.theta.numpy() - ref.theta.numpy()))
    return spread


def _assert_same(ref, got, rtol=1e-9, atol=1e-11, spread=None):
    """The same epochs, stop and weights to ``rtol`` / ``atol`` -- or within three times the torch trainer's own
    spread under reordering (``spread``, :func:`_reordering_spread`), whichever is larger."""
    assert (got.epochs, got.best_epoch, got.stop_reason, got.iterations, got.converged) == (
        ref.epochs, ref.best_epoch, ref.stop_reason, ref.iterations, ref.converged)
    assert isinstance(got.theta, np.ndarray)
    r = ref.theta.numpy()
    tol = rtol * np.abs(r) + atol
    if spread is not None:
        tol = np.maximum(tol, 3.0 * spread)
    assert np.all(np.abs(got.theta - r) <= tol), np.max(np.abs(got.theta - r) / tol)
    np.testing.assert_allclose(got.train_mse, ref.train_mse, rtol=1e-8, atol=1e-20)
    np.testing.assert_allclose(got.val_mse, ref.val_mse, rtol=1e-8, atol=1e-20)
    np.testing.assert_allclose(got.final_objective, ref.final_objective, rtol=1e-8, atol=1e-20)
    for key in ("objective", "validation", "mu"):
        np.testing.assert_allclose(got.history[key], ref.history[key], rtol=1e-8, atol=1e-20, err_msg=key)


# (points, inputs, hidden, options): the J^T J form (more errors than weights) and the dual form (fewer)
# (points, inputs, hidden, options, epochs at least): the J^T J form (more errors than weights) and the dual form
# (fewer: the network interpolates the training points, here down to the gradient test in 15 and 7 epochs)
CASES = {
    "primal, 2 inputs, 10 neurons": (140, 2, 10, {"max_epochs": 25}, 25),
    "primal, 3 inputs, 5 neurons, noisy": (300, 3, 5, {"max_epochs": 30}, 17),  # stopped by validation
    "dual, 2 inputs, 10 neurons (20 SCOPs: 14 errors, 41 weights)": (20, 2, 10, {"max_epochs": 25, "max_fail": 100},
                                                                      15),
    "dual, 3 inputs, 30 neurons (60 SCOPs: 42 errors, 151 weights)": (60, 3, 30, {"max_epochs": 20, "max_fail": 100},
                                                                       7),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_compiled_training_equals_the_torch_trainer(case):
    n, n_inputs, hidden, options, epochs = CASES[case]
    net = _lm.SigmoidMLP(n_inputs, (hidden,))
    data = _problem(n, n_inputs, seed=n, kind="noisy" if "noisy" in case else "smooth")
    assert (net.n_params > data[0].shape[0]) is case.startswith("dual")
    ref, got = _both(net, 3, data, **options)
    assert got.epochs == epochs
    if case.startswith("dual"):
        assert got.stop_reason == "min_grad"
    _assert_same(ref, got, spread=_reordering_spread(net, 3, data, **options))


@pytest.mark.parametrize(("options", "stop"), [
    ({"goal": 2.4e-3, "max_fail": 1000}, "goal"),  # reached at epoch 18
    ({"max_fail": 1}, "validation"),
    ({"min_grad": 1e-2}, "min_grad"),
    ({"mu_max": 1e-2}, "mu_max"),
])
def test_the_stopping_rules_stop_at_the_same_epoch(options, stop):
    net = _lm.SigmoidMLP(2, (6,))
    ref, got = _both(net, 1, _problem(120, 2, seed=4, kind="noisy"), max_epochs=400, **options)
    assert ref.stop_reason == stop
    _assert_same(ref, got, rtol=1e-8, atol=1e-10)


def test_without_a_validation_set_the_last_weights_are_kept():
    net = _lm.SigmoidMLP(2, (6,))
    xt, yt, _, _ = _problem(90, 2, seed=6, kind="noisy")
    ref, got = _both(net, 5, (xt, yt, np.empty((0, 2)), np.empty(0)), max_epochs=20)
    assert got.stop_reason == "max_epochs" and got.best_epoch == got.epochs == 20 and np.isnan(got.val_mse)
    assert np.isnan(got.history["validation"]).all()
    _assert_same(ref, got)


def test_the_initial_validation_error_counts():
    """Validation targets equal to the first weights' outputs: the start's validation error (0) is the best, every
    later one is worse, so training stops after max_fail epochs and keeps the first weights (the torch trainer's
    ``count_initial_validation=True``)."""
    net = _lm.SigmoidMLP(2, (5,))
    theta0 = net.init_params_numpy(TorchUniform(2))
    xt, yt, xv, _ = _problem(80, 2, seed=9)
    yv = net.forward_numpy(theta0, xv)  # the start predicts the validation set exactly
    ref, got = _both(net, 2, (xt, yt, xv, yv), max_epochs=50, max_fail=4)
    assert ref.stop_reason == got.stop_reason == "validation" and got.best_epoch == 0 and got.epochs == 4
    np.testing.assert_array_equal(got.theta, theta0)
    _assert_same(ref, got)


def test_the_prediction_in_numpy_equals_torchs():
    net = _lm.SigmoidMLP(3, (12,))
    theta = net.init_params(torch.Generator().manual_seed(5)) * 8.0  # steep: sigmoids near 0 and 1 too
    x = np.random.default_rng(0).uniform(-3, 3, (5000, 3))
    with torch.no_grad():
        expected = net.forward(theta, torch.from_numpy(x)).numpy()
    trained = _lm.TrainedNetwork(net, theta.numpy(), 10.0, 3.0, "cpu")
    np.testing.assert_allclose(trained.predict(x), expected * 3.0 + 10.0, rtol=1e-13, atol=1e-12)
    assert trained.on_cpu and trained.layer_sizes == (3, 12, 1)


def _fit_both_ways(monkeypatch, method, scene, scops):
    from explorer.methods import create

    out = []
    for compiled in (False, True):
        monkeypatch.setattr(_lm, "compiled_training_applies", lambda net, device, _c=compiled: _c)
        m = create(method, scene).fit(scops)
        assert isinstance(m.network.theta, np.ndarray) is compiled  # the path under test was the one taken
        out.append(m)
    return out


def _assert_same_method(ref, got, ground, row_atol):
    a, b = ref.fit_info, got.fit_info
    assert (a["epochs"], a["best_epoch"], a["stop_reason"]) == (b["epochs"], b["best_epoch"], b["stop_reason"])
    np.testing.assert_allclose(b["val_rmse_px"], a["val_rmse_px"], rtol=1e-6)
    ra, rb = ref.ground_to_image(ground), got.ground_to_image(ground)
    np.testing.assert_array_equal(ra.converged, rb.converged)
    np.testing.assert_allclose(rb.row, ra.row, rtol=0, atol=row_atol)
    np.testing.assert_allclose(rb.col, ra.col, rtol=0, atol=row_atol)


@pytest.mark.parametrize("method", ["mlp", "ann"])
def test_mlp_and_ann_give_the_same_rows_both_ways_on_a_preset(monkeypatch, method):
    from explorer.points import simulate_points
    from tests.methods.cases import scene_for, scps_for

    scene = scene_for("WSU", 800.0)  # relief: three inputs for mlp
    scops = simulate_points(scene, 100, kind="scop", layers=3)
    ref, got = _fit_both_ways(monkeypatch, method, scene, scops)
    assert ref.fit_info["epochs"] >= 5
    _assert_same_method(ref, got, scps_for("WSU", 800.0, n=3000).ground, row_atol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("density", [20, 100])
def test_mlp_and_ann_give_the_same_rows_both_ways_on_the_dimap(monkeypatch, density):
    """The Pleiades DIMAP (rigorous model on its DEM), the export's source: 20 SCOPs train mlp in the dual form
    (14 errors, 41 weights), 100 in the J^T J form."""
    from explorer.points import simulate_points
    from explorer.sources import load_source
    from tests.real.conftest import DEM_DIR, RPC_DIR

    src = load_source("dimap", str(RPC_DIR / "PHRDIMAP_P1BP--2017030824934340CP.XML"),
                      dem=str(DEM_DIR / "MNT_P1BP--2017030824934340CP.tif"), dem_datum="egm96")
    scops = simulate_points(src.scene, density, kind="scop")
    check = simulate_points(src.scene, 5000, kind="scp")
    for method in ("mlp", "ann"):
        ref, got = _fit_both_ways(monkeypatch, method, src.scene, scops)
        _assert_same_method(ref, got, check.ground, row_atol=1e-6)


def test_same_bits_run_to_run_and_several_layers_train_by_torch():
    x = np.random.default_rng(1).uniform(-1, 1, (150, 2))
    y = np.sin(2 * x[:, 0]) + x[:, 1] ** 3
    one, two = (_lm.fit_network(x, y, (8,), name="t", seed=4, max_epochs=200) for _ in range(2))
    assert one[1] == two[1] and one[1]["epochs"] > 20
    assert np.array_equal(one[0].theta, two[0].theta)
    assert isinstance(one[0].theta, np.ndarray) and one[0].device == "cpu"
    deep, info = _lm.fit_network(x, y, (4, 3), name="t", seed=4, max_epochs=30)
    assert isinstance(deep.theta, torch.Tensor) and info["epochs"] > 0 and np.isfinite(info["train_rmse"])
    np.testing.assert_allclose(deep.predict(x[:5]), deep.predict(x)[:5], rtol=0, atol=0)
    assert not _lm.compiled_training_applies(_lm.SigmoidMLP(2, (8,)), "cuda")
    assert _lm.compiled_training_applies(_lm.SigmoidMLP(2, (8,)), torch.device("cpu"))


def test_fitting_and_evaluating_mlp_and_ann_does_not_import_torch():
    code = (
        "import sys\n"
        "from explorer.methods import create\n"
        "from explorer.points import simulate_points\n"
        "from explorer.presets import build_scene\n"
        "scene = build_scene('WSU', relief_m=300.0, relief_seed=3)\n"
        "scops = simulate_points(scene, 60, kind='scop', layers=3)\n"
        "check = simulate_points(scene, 500, kind='scp')\n"
        "for name in ('mlp', 'ann'):\n"
        "    m = create(name, scene).fit(scops)\n"
        "    r = m.ground_to_image(check.ground)\n"
        "    assert r.converged.mean() > 0.5, name\n"
        "    assert m.fit_info['epochs'] > 0, name\n"
        "assert 'torch' not in sys.modules, sorted(k for k in sys.modules if k.startswith('torch'))[:5]\n"
        "print('ok')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and done.stdout.strip().endswith("ok"), done.stderr[-2000:]


def _network(theta, x, feats, n_hidden, n_out, tanh):
    """The hidden activations (N, H) and outputs (N, O) of the compiled trainer's network (explorer/methods/
    _lm_compiled.py's module docstring: its parameter layout) in numpy."""
    n_in, n_feat = x.shape[1], feats.shape[1]
    s = n_hidden * n_in + n_hidden
    w1, b1 = theta[:n_hidden * n_in].reshape(n_hidden, n_in), theta[n_hidden * n_in:s]
    w2 = theta[s:s + n_out * n_hidden].reshape(n_out, n_hidden)
    b2 = theta[s + n_out * n_hidden:s + n_out * n_hidden + n_out]
    lin = theta[s + n_out * n_hidden + n_out:].reshape(n_out, n_feat)
    z = x @ w1.T + b1
    h = np.tanh(z) if tanh else 1.0 / (1.0 + np.exp(-z))
    return h, h @ w2.T + b2 + feats @ lin.T


@pytest.mark.parametrize(("n_out", "n_feat", "lam"), [(2, 2, 0.0), (1, 0, 0.0), (3, 1, 0.25)])
@pytest.mark.parametrize("tanh", [False, True])
def test_the_full_jacobian_of_the_dual_form(tanh, n_out, n_feat, lam):
    """The dual form's Jacobian (every output, the line-of-sight network's linear terms too) against central
    differences of the network's outputs, and its J^T J / J^T e - lam theta against the normal equations bpnn, mlp
    and ann train with (built from one product of the columns the outputs share; tests/methods/test_lm_compiled.py
    checks the trainings against torch): one, two and three outputs, with and without linear terms and weight
    decay."""
    rng = np.random.default_rng(3)
    n, n_in, n_hidden = 9, 3, 4
    x, feats = rng.uniform(-1, 1, (n, n_in)), rng.uniform(-1, 1, (n, n_feat))
    theta = rng.normal(size=n_hidden * n_in + n_hidden + n_out * (n_hidden + 1 + n_feat))
    err = rng.normal(size=(n, n_out))
    h = _network(theta, x, feats, n_hidden, n_out, tanh)[0]
    jac = _lm_compiled._jacobian(theta, x, feats, h, tanh, n_out)
    assert jac.shape == (n * n_out, theta.size)
    step = 1e-6
    numeric = np.empty_like(jac)
    for c in range(theta.size):
        d = np.zeros(theta.size)
        d[c] = step
        up = _network(theta + d, x, feats, n_hidden, n_out, tanh)[1]
        down = _network(theta - d, x, feats, n_hidden, n_out, tanh)[1]
        numeric[:, c] = ((up - down) / (2 * step)).reshape(-1)  # row k * n_out + o, as the errors are flattened
    np.testing.assert_allclose(jac, numeric, rtol=1e-7, atol=1e-9)
    work = _lm_compiled._normal_work(x, feats, n_hidden, n_out)
    work[:] = np.nan  # scratch: nothing of it may be read before it is written
    product, rhs = _lm_compiled._normal_equations(theta, x, feats, err, h, tanh, lam, work)
    np.testing.assert_allclose(jac.T @ jac, product, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(jac.T @ err.reshape(-1) - lam * theta, rhs, rtol=1e-12, atol=1e-12)
