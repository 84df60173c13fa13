"""bracket_best_scanline against the brute-force solver of tests/truth.py (an independent bisection)."""

from __future__ import annotations

import numpy as np

from explorer.geometry.bracket import bracket_best_scanline
from tests.scenes import curved_scene
from tests.truth import brute_force_rows


def test_rows_and_columns_match_brute_force_on_a_curved_jittered_camera():
    scene = curved_scene("agile", jitter=True)
    rng = np.random.default_rng(2)
    row, col = rng.uniform(0, scene.n_rows - 1, 40), rng.uniform(0, scene.n_columns - 1, 40)
    ground = scene.image_to_ground(row, col, height=rng.uniform(-200.0, 800.0, 40))
    r, c, ok = bracket_best_scanline(scene, ground)
    assert ok.all()
    np.testing.assert_allclose(r, brute_force_rows(scene, ground), atol=1e-9)
    np.testing.assert_allclose(c, col, atol=1e-8)


def test_a_row_guess_gives_the_same_rows_and_a_bad_guess_falls_back_to_the_scan():
    scene = curved_scene()
    rng = np.random.default_rng(3)
    row = rng.uniform(0, scene.n_rows - 1, 20)
    ground = scene.image_to_ground(row, rng.uniform(0, scene.n_columns - 1, 20))
    plain, _, _ = bracket_best_scanline(scene, ground)
    guess = row + 0.7
    guess[:5] = np.nan  # no guess
    guess[5:10] += 500.0  # far off: the +-2 row bracket has no sign change
    guessed, _, ok = bracket_best_scanline(scene, ground, row_guess=guess)
    assert ok.all()
    np.testing.assert_allclose(guessed, plain, atol=1e-9)


def test_points_without_a_root_in_the_window_are_nan_and_not_converged():
    scene = curved_scene()
    far = scene.image_to_ground(np.array([-2.0 * scene.n_rows, 3.0 * scene.n_rows]), np.array([10.0, 10.0]),
                                height=0.0)
    r, c, ok = bracket_best_scanline(scene, far)
    assert not ok.any() and np.isnan(r).all() and np.isnan(c).all()
