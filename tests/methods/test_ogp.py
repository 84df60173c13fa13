"""``ogp`` (Ahooei Nezhad et al. 2021, three stages with a GA-selected polynomial) against exact truth.

Truth: the exact rows of ``simulate_points(kind="scp")`` check points; for the genetic algorithm, a
target built from known monomials (closed form).
"""


import numpy as np
import pytest

from explorer.methods import available, create
from explorer.methods.ogp import OGPMethod, genetic_term_selection
from explorer.methods.regression import design_matrix, monomial_exponents
from explorer.points import simulate_points
from tests.methods.cases import check_affine_plus_correction, fitted, scps_for
from tests.methods.cases import scene_for as _scene


def _scps(preset, n=20000):
    return scps_for(preset, n=n)


def _fitted(preset, n_scops=500, seed=0):
    return fitted("ogp", preset, n_scops, seed)


def test_ga_finds_the_true_terms():
    """Target = 2 + 3 u v - u^3 v^2 exactly: the GA must keep exactly those three monomials."""
    exps = monomial_exponents(2, 5)
    rng = np.random.default_rng(1)
    u = rng.uniform(-1, 1, (300, 2))
    a = design_matrix(u, exps)
    want = {(0, 0): 2.0, (1, 1): 3.0, (3, 2): -1.0}
    y = sum(c * a[:, exps.tolist().index(list(e))] for e, c in want.items())
    mask, fit, info = genetic_term_selection(a[:200], y[:200], a[200:], y[200:], seed=0,
                                             complexity_penalty=1e-6)
    assert {tuple(e) for e in exps[mask]} == set(want)
    assert info["val_rmse"] < 1e-12 and fit == pytest.approx(3e-6, abs=1e-12)


@pytest.mark.parametrize("preset", ["WSU", "SAN", "ISB"])
def test_ogp_sub_pixel_with_500_scops(preset):
    """Paper (Sensors 24:5594 Table 4): RMSE 0.28-0.31 px, dr_max 0.52-0.81 px with 200-1000 SCOPs.
    Measured here with 500 SCOPs: WSU 3.1e-6 px, SAN 1.7e-4 px RMSE (3 terms selected: the affine
    stage leaves a smooth, mostly quadratic error).  Asserted: sub-pixel and better than the affine."""
    m = _fitted(preset)
    check_affine_plus_correction(m, _scps(preset))
    assert 1 <= m.fit_info["n_terms"] <= 21


def test_same_seed_same_terms():
    s = _scene("SAN")
    scops = simulate_points(s, 300, kind="scop")
    a = OGPMethod(s, seed=7).fit(scops)
    b = OGPMethod(s, seed=7).fit(scops)
    assert a.fit_info["selected_terms"] == b.fit_info["selected_terms"]
    assert a.fit_info["ga_best_fitness"] == b.fit_info["ga_best_fitness"]
    g = _scps("SAN", 1000).ground
    np.testing.assert_array_equal(a.ground_to_image(g).row, b.ground_to_image(g).row)


def test_bad_degree_raises():
    s = _scene("WSU")
    with pytest.raises(ValueError, match="max_degree"):
        OGPMethod(s, max_degree=6).fit(simulate_points(s, 100, kind="scop"))


def test_registered_as_learned():
    learned = set(available("learned"))
    assert "ogp" in learned
    m = create("ogp", _scene("WSU"))
    assert m.needs_fit and m.exactness == "approximate" and m.reference


def test_single_threaded_blas_selects_the_same_terms_to_the_bit(monkeypatch):
    """The GA's least-squares solves run on one OpenBLAS thread (15x faster on the busy 2-core machine with 3,000
    SCOPs); the selection, its fitness history and the rows are the same to the bit as with OpenBLAS's default
    threads (the truth: the same computation without the single-thread block)."""
    import contextlib

    import explorer.methods.ogp as ogp

    s = _scene("SAN")
    scops = simulate_points(s, 1000, kind="scop", seed=2)  # 700 training rows: above OpenBLAS's threading size
    g = _scps("SAN", 1000).ground
    one = OGPMethod(s, seed=3).fit(scops)
    monkeypatch.setattr(ogp, "blas_threads", lambda n=1: contextlib.nullcontext())
    default = OGPMethod(s, seed=3).fit(scops)
    assert one.fit_info["selected_terms"] == default.fit_info["selected_terms"]
    assert one.fit_info["ga_best_fitness"] == default.fit_info["ga_best_fitness"]
    np.testing.assert_array_equal(one.ground_to_image(g).row, default.ground_to_image(g).row)
