"""A method's fit runs with one OpenBLAS thread (``BestScanlineMethod.fit``), and that changes no number: the
same fit with OpenBLAS on two threads gives the same model to the bit."""

from __future__ import annotations

import numpy as np
import pytest

from explorer import _threads
from explorer.methods import base, create
from explorer.points import simulate_points
from tests.methods.cases import caller_at_two_blas_threads, scene_for, scps_for


def _needs_openblas() -> None:
    if _threads.blas_thread_count() is None:
        pytest.skip("numpy's BLAS is not an OpenBLAS found in this process")


def test_a_fit_runs_on_one_blas_thread_and_restores_the_setting():
    _needs_openblas()
    scene = scene_for("WSU", 800.0)
    method = create("prm", scene)
    seen: list[int | None] = []
    original = method._fit

    def spy(control):
        seen.append(_threads.blas_thread_count())
        original(control)

    method._fit = spy  # type: ignore[method-assign]
    with caller_at_two_blas_threads():
        method.fit(simulate_points(scene, 100, kind="scop"))
        after = _threads.blas_thread_count()
    assert seen == [1]
    assert after == 2


@pytest.mark.parametrize("name, params", [("nn-rfm", {"max_iter": 60}), ("ogp", {}), ("prm", {})])
def test_one_blas_thread_gives_the_same_model_as_two(monkeypatch, name, params):
    """The independent truth: the same fit with OpenBLAS on two threads (the setting before)."""
    _needs_openblas()
    scene = scene_for("WSU", 800.0)
    scops = simulate_points(scene, 300, kind="scop")
    check = scps_for("WSU", 800.0)
    one = create(name, scene, **params).fit(scops).ground_to_image(check.ground)

    def two_threads(n: int = 1):
        return _threads.blas_threads(2)

    monkeypatch.setattr(base, "blas_threads", two_threads)
    seen: list[int | None] = []
    method = create(name, scene, **params)
    original = method._fit
    method._fit = lambda control: (seen.append(_threads.blas_thread_count()), original(control))  # type: ignore
    two = method.fit(scops).ground_to_image(check.ground)
    assert seen == [2]
    assert np.array_equal(one.row, two.row, equal_nan=True)
    assert np.array_equal(one.col, two.col, equal_nan=True)
    assert np.isfinite(one.row).mean() > 0.9
