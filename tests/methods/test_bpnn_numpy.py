"""bpnn's and nn-rfm's networks (explorer.methods.bpnn.MLPRegressor and its subclasses) hold numpy weights and start,
fit their output layer, predict and differentiate without torch where the compiled trainer applies; checked against
torch, the independent truth and the path they replace (the torch generator's draws, torch's gelsd least squares,
torch's forward pass and autograd), reimplemented here from the code before the change:

* each restart's random start bit for bit equal to ``torch.rand`` on ``torch.Generator().manual_seed(seed)``;
* the least-squares output layer (and nn-rfm's linear terms) equal to ``torch.linalg.lstsq(driver="gelsd")``'s to
  round-off;
* a whole training from the torch start (the path before) equal to one from the numpy start to round-off, and the
  bpnn and nn-rfm methods' answers from either start equal to 1e-8 px;
* ``predict`` equal to torch's forward pass and ``predict_with_jacobian`` to torch autograd's, one and two hidden
  layers, sigmoid and tanh, the line-of-sight network's linear terms;
* the same bits run to run, and in a fresh process fitting and evaluating bpnn and nn-rfm (a refused fit
  included) never imports torch.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from explorer.methods import _lm_compiled, bpnn
from explorer.methods._torch_uniform import TorchUniform
from tests.methods.cases import scene_for

torch = pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def data():
    from explorer.points import simulate_points

    scops = simulate_points(scene_for("WSU", 800.0), 120, kind="scop", layers=3)
    g = scops.ground
    return scops.row, scops.col, g[:, 2], g[:, 0], g[:, 1]


# ------------------------------------------------------------------ the torch path before the change
def torch_act(net, z):
    return torch.sigmoid(z) if net.activation == "sigmoid" else torch.tanh(z)


def torch_init_theta(net, gen):
    """``MLPRegressor._init_theta`` before: torch.rand on the seeded generator (nn-rfm's linear terms zero)."""
    parts = []
    last = len(net._shapes) - 1
    for layer, (o, i) in enumerate(net._shapes):
        a = np.sqrt(6.0 / (o + i)) * (4.0 if (net.activation == "sigmoid" and layer < last) else 1.0)
        parts.append((torch.rand(o * i, generator=gen, dtype=torch.float64) * 2 - 1) * a)
        if layer < last:
            parts.append(torch.rand(o, generator=gen, dtype=torch.float64) * 2 - 1)
        else:
            parts.append(torch.zeros(o, dtype=torch.float64))
    if isinstance(net, bpnn.LineOfSightNetwork):
        parts.append(torch.zeros(int(np.prod(net._linear_shape)), dtype=torch.float64))
    return torch.cat(parts)


def torch_hidden(net, theta, u):
    """The last hidden layer's activations of the network before (the line-of-sight network's on (row, col))."""
    h = u[:, :-1] if isinstance(net, bpnn.LineOfSightNetwork) else u
    pos = 0
    for o, i in net._shapes[:-1]:
        w, b = theta[pos:pos + o * i].reshape(o, i), theta[pos + o * i:pos + o * i + o]
        h = torch_act(net, h @ w.T + b)
        pos += o * i + o
    return h, pos


def torch_init_output_layer(net, theta, u, t):
    """``_init_output_layer`` before: torch's gelsd least squares for the output layer (and the linear terms)."""
    h, start = torch_hidden(net, theta, u)
    parts = [h, torch.ones((h.shape[0], 1), dtype=torch.float64)]
    if isinstance(net, bpnn.LineOfSightNetwork):
        parts.append(net._linear_features(u))
    sol = torch.linalg.lstsq(torch.cat(parts, dim=1), t, driver="gelsd").solution
    nh = h.shape[1]
    o, i = net._shapes[-1]
    theta = theta.clone()
    theta[start:start + o * i] = sol[:nh].T.reshape(-1)
    theta[start + o * i:start + o * i + o] = sol[nh]
    if isinstance(net, bpnn.LineOfSightNetwork):
        theta[start + o * i + o:] = sol[nh + 1:].T.reshape(-1)
    return theta


def torch_forward(net, theta, u):
    """The network's outputs on torch tensors (as before the change), independent of numpy's arithmetic."""
    h, start = torch_hidden(net, theta, u)
    o, i = net._shapes[-1]
    out = h @ theta[start:start + o * i].reshape(o, i).T + theta[start + o * i:start + o * i + o]
    if isinstance(net, bpnn.LineOfSightNetwork):
        out = out + net._linear_features(u) @ theta[start + o * i + o:].reshape(net._linear_shape).T
    return out


def torch_predict_with_jacobian(net, inputs):
    """``predict_with_jacobian`` before: torch autograd of the forward pass."""
    theta = torch.tensor(net._theta)
    u = torch.tensor((inputs - net._in_off) / net._in_scale).requires_grad_(True)
    out = torch_forward(net, theta, u)
    jac = np.empty((u.shape[0], out.shape[1], u.shape[1]))
    for k in range(out.shape[1]):
        (gk,) = torch.autograd.grad(out[:, k].sum(), u, retain_graph=True)
        jac[:, k, :] = gk.numpy() * net._out_scale[k] / net._in_scale
    return out.detach().numpy() * net._out_scale + net._out_off, jac


def normalised(net, data):
    """The fitted network's normalised training inputs and targets (N, 3), (N, 2)."""
    x = np.column_stack(data[:3])
    t = (np.column_stack(data[3:]) - net._out_off) / net._out_scale
    return net._normalise_inputs(x), t


NETWORKS = {
    "line-of-sight, sigmoid": lambda: bpnn.LineOfSightNetwork(6, max_iter=30, seed=3),
    "free, sigmoid": lambda: bpnn.BPNetworkGeometryModel(5, max_iter=30, seed=1),
    "free, tanh": lambda: bpnn.BPNetworkGeometryModel(4, activation="tanh", max_iter=30, seed=2),
    "line-of-sight, tanh, two layers": lambda: bpnn.LineOfSightNetwork((4, 3), activation="tanh", max_iter=5, seed=0),
    "free, sigmoid, two layers": lambda: bpnn.BPNetworkGeometryModel((4, 3), max_iter=5, seed=4),
}


@pytest.mark.parametrize("case", sorted(NETWORKS))
def test_first_weights_bit_for_bit_and_output_layer_as_torch_gelsd(data, case):
    net = NETWORKS[case]().fit(*data)
    u, t = normalised(net, data)
    for seed in (0, 7, 2**40 + 11, 2**62 - 5):
        mine = net._init_theta(TorchUniform(seed))
        theirs = torch_init_theta(net, torch.Generator().manual_seed(seed))
        assert mine.shape == theirs.shape == (net.n_parameters,)
        assert np.array_equal(mine, theirs.numpy())  # bit for bit
        start = net._init_output_layer(mine, u, t)
        start_torch = torch_init_output_layer(net, theirs, torch.tensor(u), torch.tensor(t))
        k = bpnn.n_parameters(net._shapes[:-1])
        assert np.array_equal(start[:k], mine[:k])  # the hidden layers are kept
        scale = np.max(np.abs(start_torch.numpy()[k:]))
        np.testing.assert_allclose(start[k:], start_torch.numpy()[k:], rtol=0, atol=1e-12 * scale)
        assert not np.array_equal(start[k:], mine[k:])  # the random output layer was replaced


class _Seed:
    """Stands for TorchUniform in fit_arrays: carries a restart's seed to :func:`_torch_started`'s start."""

    def __init__(self, seed):
        self.seed = seed


def _torch_started(net):
    """``net`` starting each restart from the torch path's start (torch generator, torch gelsd; with
    ``bpnn.TorchUniform`` patched to :class:`_Seed`)."""
    net._init_theta = lambda seed: torch_init_theta(net, torch.Generator().manual_seed(seed.seed))
    net._init_output_layer = lambda theta, u, t: torch_init_output_layer(
        net, theta, torch.tensor(u), torch.tensor(t)).numpy().copy()
    return net


@pytest.mark.parametrize("case", ["line-of-sight, sigmoid", "free, sigmoid", "free, tanh"])
def test_a_training_from_the_torch_start_equals_the_numpy_one_to_round_off(data, monkeypatch, case):
    """The path before (torch's start, the compiled trainer) and now (numpy's start): the same epochs and stop, the
    weights to the tolerance tests/methods/test_lm_compiled.py holds the compiled trainer to against torch's."""
    numpy_net = NETWORKS[case]().fit(*data)
    monkeypatch.setattr(bpnn, "TorchUniform", _Seed)
    torch_net = _torch_started(NETWORKS[case]()).fit(*data)
    a, b = torch_net.fit_info, numpy_net.fit_info
    assert a["iterations"] == b["iterations"] >= 10 and a["stop"] == b["stop"]
    np.testing.assert_allclose(numpy_net._theta, torch_net._theta, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(b["train_rms"], a["train_rms"], rtol=1e-8)


def test_a_refused_fit_keeps_the_torch_start(data, monkeypatch):
    """Too few points: no training, the first start kept -- that of the torch path to round-off."""
    small = tuple(a[:20] for a in data)
    net = bpnn.LineOfSightNetwork(6, seed=5).fit(*small)
    assert net.fit_info["stop"] == "too_few_points" and net.fit_info["iterations"] == 0
    monkeypatch.setattr(bpnn, "TorchUniform", _Seed)
    before = _torch_started(bpnn.LineOfSightNetwork(6, seed=5)).fit(*small)
    np.testing.assert_allclose(net._theta, before._theta, rtol=1e-11, atol=1e-12)
    x = np.column_stack(small[:3])
    np.testing.assert_allclose(net.predict(x), before.predict(x), rtol=0, atol=1e-6)  # metres


@pytest.mark.parametrize("name", ["bpnn", "nn-rfm"])
def test_the_methods_answer_as_from_the_torch_start(monkeypatch, name):
    """The whole method (bpnn: training and the Newton inversion on the network's Jacobian; nn-rfm: training, the
    synthetic grid and its RFM) from the torch path's start and from numpy's: the same rows and columns to 1e-8 px
    (measured 1e-12 to 1.2e-11 px after 200 epochs, against the methods' own 3e-4 px RMS error here)."""
    from explorer.methods import create
    from explorer.points import simulate_points

    scene = scene_for("WSU", 800.0)
    scops = simulate_points(scene, 100, layers=3)
    check = simulate_points(scene, 2000, kind="scp", layers=2)
    mine = create(name, scene, max_iter=200, seed=1).fit(scops).ground_to_image(check.ground)
    monkeypatch.setattr(bpnn, "TorchUniform", _Seed)
    for cls in (bpnn.MLPRegressor, bpnn.LineOfSightNetwork):
        monkeypatch.setattr(cls, "_init_theta",
                            lambda self, seed: torch_init_theta(self, torch.Generator().manual_seed(seed.seed)))
        monkeypatch.setattr(cls, "_init_output_layer", lambda self, theta, u, t: torch_init_output_layer(
            self, theta, torch.tensor(u), torch.tensor(t)).numpy().copy())
    before = create(name, scene, max_iter=200, seed=1).fit(scops).ground_to_image(check.ground)
    assert mine.valid.all() and before.valid.all()
    np.testing.assert_allclose(mine.row, before.row, rtol=0, atol=1e-8)
    np.testing.assert_allclose(mine.col, before.col, rtol=0, atol=1e-8)
    assert np.sqrt(np.mean((mine.row - check.row) ** 2)) < 0.01  # and both are the trained method (sub-pixel)


@pytest.mark.parametrize("case", sorted(NETWORKS))
def test_predict_and_its_jacobian_equal_torch_forward_and_autograd(data, case):
    net = NETWORKS[case]().fit(*data)
    rng = np.random.default_rng(1)
    x = np.column_stack(data[:3])[rng.permutation(len(data[0]))[:50]]
    x = x + rng.normal(0.0, [40.0, 40.0, 30.0], x.shape)  # between the training points, heights too
    out, jac = net.predict_with_jacobian(x)
    out_t, jac_t = torch_predict_with_jacobian(net, x)
    scale = np.abs(out_t).max(axis=0)
    np.testing.assert_allclose(out, out_t, rtol=0, atol=1e-13 * scale.max())
    np.testing.assert_allclose(net.predict(x), out, rtol=0, atol=0)  # the same arithmetic: the same bits
    jscale = np.abs(jac_t).max(axis=0)  # per output and input (metres per pixel, per metre)
    assert np.all(np.abs(jac - jac_t) <= 1e-11 * jscale + 1e-300)
    assert jac.shape == (50, 2, 3)


def test_the_surface_network_with_three_outputs(data):
    """nn-rfm's surface variant: an MLPRegressor (row, col) -> (X, Y, Z): its Jacobian against autograd too."""
    rng = np.random.default_rng(4)
    rc = rng.uniform(0, 1000, (80, 2))
    xyz = np.column_stack([2 * rc[:, 0] + 0.01 * rc[:, 1] ** 1.5, 3 * rc[:, 1], 50 * np.sin(rc[:, 0] / 300)])
    net = bpnn.MLPRegressor(5, max_iter=25, seed=2).fit_arrays(rc, xyz)
    out, jac = net.predict_with_jacobian(rc[:30])
    out_t, jac_t = torch_predict_with_jacobian(net, rc[:30])
    np.testing.assert_allclose(out, out_t, rtol=1e-13, atol=1e-10)
    np.testing.assert_allclose(jac, jac_t, rtol=1e-11, atol=1e-14)


def test_same_bits_run_to_run(data):
    one, two = (bpnn.LineOfSightNetwork(6, max_iter=50, seed=5).fit(*data) for _ in range(2))
    assert np.array_equal(one._theta, two._theta)
    x = np.column_stack(data[:3])
    for a, b in zip(one.predict_with_jacobian(x), two.predict_with_jacobian(x), strict=True):
        assert np.array_equal(a, b)
    r1 = one.ground_to_image(data[3], data[4], data[2])
    r2 = two.ground_to_image(data[3], data[4], data[2])
    assert np.array_equal(r1[0], r2[0]) and np.array_equal(r1[1], r2[1])


@pytest.mark.skipif(not _lm_compiled.NUMBA_AVAILABLE, reason="numba is not installed")
def test_fitting_and_evaluating_bpnn_and_nn_rfm_never_imports_torch():
    """In a fresh process: bpnn and nn-rfm fitted on SCOPs (compiled trainer), one refused fit of each (too few
    SCOPs), every answer evaluated -- and torch is never imported."""
    code = textwrap.dedent("""
        import sys
        import numpy as np
        from explorer.methods import create
        from explorer.points import simulate_points
        from explorer.presets import build_scene

        scene = build_scene("WSU", relief_m=300.0, relief_seed=3)
        check = simulate_points(scene, 30, kind="scp", layers=2)
        for n in (60, 4):  # 60 x 3 SCOPs train; 4 x 3 are refused before training
            scops = simulate_points(scene, n, layers=3)
            for name in ("bpnn", "nn-rfm"):
                m = create(name, scene, max_iter=40, seed=1).fit(scops)
                res = m.ground_to_image(check.ground)
                assert m.fit_info.get("too_few_points", m.fit_info.get("network", {}).get("too_few_points")) is (
                    n == 4), (name, n, m.fit_info)
                assert bool(res.valid.any()) is (n != 4), (name, n)  # a refused network's answers are not trusted
        print("torch" in sys.modules)
    """)
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.strip().splitlines()[-1] == "False"
