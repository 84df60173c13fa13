"""The Levenberg-Marquardt training's caches change no bit: the normal equations built once per epoch (not once per
damping tried) and the line-of-sight network's weight-independent input parts (kept for the training inputs) give
the same trained network as recomputing them every time (the independent truth: the computation before)."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from explorer.methods import _lm, bpnn
from tests.methods.cases import scene_for


@pytest.fixture(scope="module")
def data():
    from explorer.points import simulate_points

    scops = simulate_points(scene_for("WSU", 800.0), 200, kind="scop", layers=3)
    g = scops.ground
    return scops.row, scops.col, g[:, 2], g[:, 0], g[:, 1]


@pytest.fixture(autouse=True)
def _torch_trainer(monkeypatch):
    """These caches belong to the torch trainer (the compiled one, tests/methods/test_lm_compiled.py, has none)."""
    monkeypatch.setattr(bpnn.MLPRegressor, "compiled_training", False)


def _train(data, **options):
    net = bpnn.LineOfSightNetwork(6, max_iter=150, seed=2, **options)
    return net.fit(*data)


def test_cached_training_equals_recomputing_everything(data, monkeypatch):
    cached = _train(data)
    cached_val = _train(data, validation_fraction=0.2)  # training and validation inputs both kept
    damped = _lm._damped_step

    def recompute_product(normal, mu):  # J^T J (or J J^T) again for every damping, as before
        jac = normal.jac
        return damped(dataclasses.replace(normal, product=jac @ jac.T if normal.dual else jac.T @ jac), mu)

    def fresh_parts(self, u, jacobian=False):  # no cache: built from u at every call, as before
        self.__dict__.pop("_parts", None)
        return original_parts(self, u, jacobian)

    original_parts = bpnn.LineOfSightNetwork._input_parts
    monkeypatch.setattr(_lm, "_damped_step", recompute_product)
    monkeypatch.setattr(bpnn.LineOfSightNetwork, "_input_parts", fresh_parts)
    plain = _train(data)
    plain_val = _train(data, validation_fraction=0.2)
    for a, b in ((cached, plain), (cached_val, plain_val)):
        assert a.fit_info["iterations"] == b.fit_info["iterations"] > 10
        assert np.array_equal(a._theta, b._theta)
        x = np.column_stack(data[:3])
        assert np.array_equal(a.predict(x), b.predict(x))


def test_the_kept_parts_are_not_pickled_and_predictions_are_not_kept(data):
    net = _train(data)
    assert len(net._parts) >= 1
    x = np.column_stack([np.repeat(data[0], 120), np.repeat(data[1], 120), np.repeat(data[2], 120)])
    assert x.shape[0] > bpnn._PARTS_MAX_POINTS
    before = dict(net._parts)
    net.predict(x)
    assert net._parts == before  # a large prediction is not kept
    copy = pickle.loads(pickle.dumps(net))
    assert "_parts" not in copy.__dict__
    assert np.array_equal(copy.predict(x[:50]), net.predict(x[:50]))
