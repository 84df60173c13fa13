"""Newton-Raphson (``nr``) against independent truth: exact rows of simulated points, the
brute-force solver of ``tests/truth.py`` and finite differences of the scene's residual."""

from functools import lru_cache

import numpy as np
import pytest

from explorer.geometry.interior import InteriorOrientation
from explorer.methods import create
from explorer.methods.newton import residual_and_derivative
from explorer.points import simulate_points
from explorer.presets import build_scene, preset_ids
from explorer.scene import Scene
from tests.methods.cases import random_image_points as _points
from tests.truth import brute_force_rows

ALL_PRESETS = preset_ids()


@lru_cache(maxsize=16)
def _scene(preset, relief=0.0):
    return build_scene(preset, relief_m=relief, relief_seed=3)




def _curved_scene():
    """agile with a displaced, curved detector line, an off-centre principal point and radial distortion."""
    base = build_scene("agile")
    pitch = base.interior.detector_pitch_m
    interior = InteriorOrientation(
        base.interior.focal_length_m, pitch, base.n_columns, principal_column=3190.3,
        along_track_offset_m=37.2 * pitch, line_curvature=(2e-4, 3e-3), radial_distortion=(2e-3,),
    )
    return Scene("curved", interior, base.exterior, base.timing, base.n_rows, base.terrain, base.frame)


def test_registry_entry_and_params():
    s = _scene("WSU")
    m = create("nr", s)
    assert m.family == "search" and m.exactness == "exact" and not m.needs_fit
    for bad in ({"derivative": "secant"}, {"tol_px": 0.0}, {"max_iter": 0}, {"start": "middle"}):
        with pytest.raises(ValueError):
            create("nr", s, **bad)
    with pytest.raises(ValueError):
        create("nr", s, start=-10.0).ground_to_image(np.zeros((1, 3)))


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_nr_matches_exact_rows(preset):
    scene = _scene(preset)
    row, col, ground = _points(scene, 2000, seed=1)
    res = create("nr", scene).ground_to_image(ground)
    assert np.all(res.converged) and np.all(res.valid)
    assert np.max(np.abs(res.row - row)) < 1e-9
    assert np.max(np.abs(res.col - col)) < 1e-8
    # one analytic Newton iteration per CE; a handful from the image centre (agile's jitter: up to 7)
    assert res.ce_evaluations.max() <= 8
    np.testing.assert_array_equal(res.ce_evaluations, res.info["iterations"])


@pytest.mark.parametrize("preset", ["ISB", "PMA", "WSU", "agile"])
def test_nr_with_relief(preset):
    scene = _scene(preset, 1000.0)
    row, col, ground = _points(scene, 1500, seed=2)
    assert np.ptp(ground[:, 2]) > 500
    res = create("nr", scene).ground_to_image(ground)
    assert np.all(res.valid)
    assert np.max(np.abs(res.row - row)) < 1e-9


@pytest.mark.parametrize("preset,relief", [("WSU", 0.0), ("agile", 800.0), ("SCB", 800.0)])
def test_nr_matches_brute_force(preset, relief):
    scene = _scene(preset, relief)
    row, col, ground = _points(scene, 60, seed=3)
    truth = brute_force_rows(scene, ground, margin=2)
    res = create("nr", scene).ground_to_image(ground)
    assert np.max(np.abs(res.row - truth)) < 1e-9


def test_residual_and_analytic_derivative_match_the_scene():
    """Residual equal to Scene.along_track_residual; derivative equal to its central difference
    (h = 1e-3 rows: truncation ~1e-12, rounding ~1e-8 px/row) on jitter + curved detector + distortion."""
    for scene in (_scene("agile", 800.0), _curved_scene(), _scene("linear")):
        rng = np.random.default_rng(4)
        ground = scene.image_to_ground(rng.uniform(0, scene.n_rows, 300), rng.uniform(0, scene.n_columns, 300))
        rows = rng.uniform(-200, scene.n_rows + 200, 300)  # anywhere, not only at the root
        f, d, c = residual_and_derivative(scene, ground, rows)
        pitch = scene.pixel_size_m
        ref = scene.along_track_residual(ground, scene.scanline_time(rows)) / pitch
        np.testing.assert_allclose(f, ref, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(c, scene.column_at_row(ground, rows), atol=1e-9)
        h = 1e-3
        fd = (
            scene.along_track_residual(ground, scene.scanline_time(rows + h))
            - scene.along_track_residual(ground, scene.scanline_time(rows - h))
        ) / (2 * h * pitch)
        np.testing.assert_allclose(d, fd, rtol=1e-6)


def test_central_difference_variant_costs_three_ce_per_iteration():
    scene = _scene("agile")
    row, col, ground = _points(scene, 1000, seed=6)
    res = create("nr", scene, derivative="central").ground_to_image(ground)
    assert np.all(res.valid)
    assert np.max(np.abs(res.row - row)) < 1e-9
    np.testing.assert_array_equal(res.ce_evaluations, 3 * res.info["iterations"])


@pytest.mark.parametrize("evaluator", ["numpy", "compiled"])
def test_out_of_image_points_are_flagged(evaluator):
    scene = _scene("WSU")
    rows, cols = scene.n_rows, scene.n_columns
    r = np.array([-50.0, rows + 50.0, 1000.3, 900.6, -0.7, -0.3, rows - 0.7, rows - 0.2, rows + 0.4])
    c = np.array([100.0, 100.0, -100.0, cols + 100.0, 50.0, 50.0, 60.0, 60.0, 70.0])
    ground = scene.image_to_ground(r, c, height=scene.terrain.mean_height)
    res = create("nr", scene, evaluator=evaluator).ground_to_image(ground)
    # beyond the bracket [-1.5, rows + 0.5]: no root, converged False, row NaN, found in <= 3 CE
    np.testing.assert_array_equal(res.converged, [False, False] + [True] * 7)
    np.testing.assert_array_equal(res.inside, [False, False, False, False, False, True, True, False, False])
    assert np.all(np.isnan(res.row[:2])) and np.all(np.isnan(res.col[:2]))
    assert np.all(res.ce_evaluations[:2] <= 3)
    # roots in the bracket are found exactly, also in the margin off the image
    np.testing.assert_allclose(res.row[2:], r[2:], atol=1e-9)
    np.testing.assert_allclose(res.col[2:], c[2:], atol=1e-8)
    # a wider margin finds the far points too (and still flags them)
    wide = create("nr", scene, margin_px=60.0, evaluator=evaluator).ground_to_image(ground[:2])
    assert np.all(wide.converged) and not np.any(wide.inside)
    np.testing.assert_allclose(wide.row, r[:2], atol=1e-9)


def test_trace_converges_to_the_exact_row():
    scene = _scene("agile", 800.0)
    row, col, ground = _points(scene, 200, seed=7)
    res = create("nr", scene).ground_to_image(ground, trace=True)
    tr = np.stack(res.trace)  # (iterations, N)
    np.testing.assert_array_equal(tr[0], scene.timing.reference_row)
    np.testing.assert_array_equal(np.sum(np.isfinite(tr), axis=0), res.ce_evaluations)
    err = np.abs(tr - row)
    for j in range(row.size):
        e = err[:, j][np.isfinite(err[:, j])]
        assert np.all(np.diff(e) <= 1e-9)  # monotone approach
        assert e[-1] < 1e-9
        if e.size >= 3:  # quadratic convergence: e_{k+1} <~ C e_k^2 with C = |f''| / (2 |f'|) (small)
            assert e[2] <= max(1e-3 * e[1] ** 2, 1e-9)
        assert np.all(np.isnan(tr[e.size:, j]))


@pytest.mark.parametrize("evaluator", ["numpy", "compiled"])
def test_max_iter_gives_not_converged_best_estimate(evaluator):
    scene = _scene("WSU")
    row, col, ground = _points(scene, 100, seed=8)
    res = create("nr", scene, max_iter=1, evaluator=evaluator).ground_to_image(ground)
    assert not np.any(res.converged)
    np.testing.assert_array_equal(res.row, scene.timing.reference_row)
    np.testing.assert_array_equal(res.ce_evaluations, 1)
    res2 = create("nr", scene, max_iter=2, evaluator=evaluator).ground_to_image(ground)
    assert not np.any(res2.converged)
    # one Newton step from the centre of a near-linear x(t): already within half a pixel
    assert np.all(np.abs(res2.row - row) < 0.5)


@pytest.mark.parametrize("evaluator", ["numpy", "compiled"])
@pytest.mark.parametrize("start", ["centre", 0.0, 3000.5])
def test_start_row_does_not_change_the_answer(start, evaluator):
    scene = _scene("WSU")
    row, col, ground = _points(scene, 500, seed=9)
    res = create("nr", scene, start=start, evaluator=evaluator).ground_to_image(ground)
    assert np.all(res.valid)
    assert np.max(np.abs(res.row - row)) < 1e-9


def test_chunked_evaluation_gives_identical_results(monkeypatch):
    import explorer.methods.newton as newton

    scene = _scene("agile")
    row, col, ground = _points(scene, 700, seed=10)
    ref = create("nr", scene, evaluator="numpy").ground_to_image(ground)
    monkeypatch.setattr(newton, "CHUNK", 256)
    res = create("nr", scene, evaluator="numpy").ground_to_image(ground)
    np.testing.assert_array_equal(res.row, ref.row)
    np.testing.assert_array_equal(res.col, ref.col)


@pytest.mark.parametrize("preset", ["WSU", "agile", "ISB"])
def test_compiled_evaluator_gives_the_same_rows(preset):
    """The compiled iteration changes the speed of NR, not its answer (exact SCP rows as truth)."""
    scene = build_scene(preset, relief_m=500.0, relief_seed=1)
    pts = simulate_points(scene, 2000, kind="scp")
    plain = create("nr", scene, evaluator="numpy").ground_to_image(pts.ground)
    fast = create("nr", scene, evaluator="compiled").ground_to_image(pts.ground)
    assert fast.info["evaluator"] == "compiled" and plain.info["evaluator"] == "numpy"
    assert np.max(np.abs(fast.row - pts.row)) < 1e-9
    assert np.max(np.abs(fast.col - pts.col)) < 1e-8
    assert np.max(np.abs(fast.row - plain.row)) < 1e-9
    assert np.max(np.abs(fast.col - plain.col)) < 1e-9
    np.testing.assert_array_equal(fast.converged, plain.converged)
    # the same iteration: round-off in the stopping test may move a point by one iteration at most
    assert np.max(np.abs(fast.ce_evaluations - plain.ce_evaluations)) <= 1
    assert np.mean(fast.ce_evaluations == plain.ce_evaluations) > 0.9
    with pytest.raises(ValueError, match="evaluator"):
        create("nr", scene, evaluator="gpu")


def test_compiled_evaluator_on_a_curved_detector_and_without_numba_support(monkeypatch):
    """The general (non branch-free) evaluator inside the compiled loop, and the fallback to numpy."""
    import explorer.geometry.kernels as kernels
    import explorer.geometry.kernels.residual as kernels_residual  # where collinearity_params_or_none reads it

    base = _curved_scene()
    inner = base.interior
    interior = InteriorOrientation(
        inner.focal_length_m, inner.detector_pitch_m, base.n_columns, principal_column=inner.principal_column,
        along_track_offset_m=inner.along_track_offset_m,
        line_curvature=(2e-4, 3e-3, 1e-2, 5e-2, 0.0, 0.0, 0.0, 0.0, 1e3),  # 9 terms > FIXED_MAX_TERMS
        radial_distortion=inner.radial_distortion,
    )
    scene = Scene("curved4", interior, base.exterior, base.timing, base.n_rows, base.terrain, base.frame)
    fast_nr = create("nr", scene, evaluator="compiled")
    assert fast_nr.kernel_params.fixed_model(fast_nr.bracket) is None  # the general evaluator runs
    row, col, ground = _points(scene, 1000, seed=11)
    fast = fast_nr.ground_to_image(ground)
    assert np.all(fast.valid)
    assert np.max(np.abs(fast.row - row)) < 1e-9 and np.max(np.abs(fast.col - col)) < 1e-8
    monkeypatch.setattr(kernels, "NUMBA_AVAILABLE", False)
    monkeypatch.setattr(kernels_residual, "NUMBA_AVAILABLE", False)
    auto = create("nr", scene)
    assert auto.kernel_params is None
    with pytest.raises(ValueError, match="numba"):
        create("nr", scene, evaluator="compiled")
