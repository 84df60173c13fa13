"""The compiled collinearity kernels against the numpy model and finite differences."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from explorer.geometry.exterior import Jitter
from explorer.geometry.kernels import NUMBA_AVAILABLE, CollinearityParams, residual_and_rate
from explorer.points import simulate_points
from explorer.presets import build_scene, preset_ids
from explorer.scene import Scene
from tests import scenes

ALL_PRESETS = preset_ids()
ROOT = Path(__file__).resolve().parents[2]
BACKENDS = ["numba", "numpy"] if NUMBA_AVAILABLE else ["numpy"]


def curved_scene(jitter: bool = False) -> Scene:
    """WSU with a displaced, curved detector line and radial distortion (principal column 1990.3)."""
    return scenes.curved_scene("WSU", jitter=jitter, principal_column=1990.3)


def scene_cases():
    cases = [(p, lambda p=p: build_scene(p)) for p in ALL_PRESETS]
    cases.append(("agile-relief", lambda: build_scene("agile", relief_m=1000.0, jitter_amplitude_scale=5.0)))
    cases.append(("curved", lambda: curved_scene()))
    cases.append(("curved-jitter", lambda: curved_scene(jitter=True)))
    return cases


CASES = scene_cases()


def _points_and_times(scene, n=400, seed=0):
    pts = simulate_points(scene, n, kind="scp", layers=2)
    rng = np.random.default_rng(seed)
    t = scene.scanline_time(rng.uniform(-0.5, scene.n_rows - 0.5, len(pts)))
    return pts.ground, t


def _tolerance(scene, ref):
    # 1e-12 relative, with an absolute floor of 1e-9 px: the residual's own float floor is
    # eps * |S - P| / GSD ~ 1e-10 px (the orbit radius is ~7e5 m, a pixel ~0.5 m on the ground)
    return 1e-12 * np.abs(ref) + 1e-9 * scene.pixel_size_m


def _assert_matches_scene(scene, ground, t, g, col):
    """Residual within :func:`_tolerance` of the scene's, column within 1e-9 px of the scene's."""
    ref = scene.along_track_residual(ground, t)
    assert np.all(np.abs(g - ref) <= _tolerance(scene, ref))
    np.testing.assert_allclose(col, scene.column_at_time(ground, t), rtol=0, atol=1e-9)


@pytest.mark.parametrize("name, make", CASES, ids=[c[0] for c in CASES])
@pytest.mark.parametrize(("evaluator", "backend"), [("reference", b) for b in BACKENDS] + [("fast", "auto"),
                                                                                           ("fixed", "auto")])
def test_evaluators_match_scene_residual_and_column(name, make, evaluator, backend):
    """Residual and column of every evaluator and backend equal the scene's; the fast evaluators' rate equals
    the reference evaluator's."""
    scene = make()
    ground, t = _points_and_times(scene, seed=1)
    g, g_t, col = residual_and_rate(scene, ground, t, evaluator=evaluator, backend=backend)
    _assert_matches_scene(scene, ground, t, g, col)
    if evaluator != "reference":
        np.testing.assert_allclose(g_t, residual_and_rate(scene, ground, t)[1], rtol=1e-12)


@pytest.mark.parametrize("name, make", CASES, ids=[c[0] for c in CASES])
@pytest.mark.parametrize("evaluator", ["reference", "fixed"])
def test_time_derivative_matches_finite_difference(name, make, evaluator):
    scene = make()
    ground, t = _points_and_times(scene, seed=2)
    _, g_t, _ = residual_and_rate(scene, ground, t, evaluator=evaluator)
    h = 0.2 * scene.timing.line_period_s  # fourth-order stencil: truncation and round-off < 1e-9
    f = [scene.along_track_residual(ground, t + k * h) for k in (-2, -1, 1, 2)]
    fd = (f[0] - 8 * f[1] + 8 * f[2] - f[3]) / (12 * h)
    np.testing.assert_allclose(g_t, fd, rtol=1e-8)


@pytest.mark.parametrize("evaluator", ["reference", "fast", "fixed"])
def test_numpy_fallback_equals_compiled(evaluator):
    if not NUMBA_AVAILABLE:
        pytest.skip("numba not installed")
    scene = build_scene("agile")
    ground, t = _points_and_times(scene, seed=3)
    a = residual_and_rate(scene, ground, t, backend="numba", evaluator=evaluator)
    b = residual_and_rate(scene, ground, t, backend="numpy", evaluator=evaluator)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-13, atol=1e-9 * scene.pixel_size_m)


def test_derivative_sign_is_the_residual_orientation():
    # the residual is monotone in time over a scene: one sign of dg/dt everywhere
    for p in ("WSU", "agile", "linear"):
        scene = build_scene(p)
        ground, t = _points_and_times(scene, seed=4)
        _, g_t, _ = residual_and_rate(scene, ground, t)
        assert np.all(np.sign(g_t) == np.sign(g_t[0]))


def test_fixed_model_refuses_scenes_it_cannot_represent():
    params = CollinearityParams.from_scene(build_scene("WSU"))
    assert params.fixed_model((-0.5, 3995.5)) is not None
    fast_jitter = build_scene("WSU", extra_jitter=[Jitter("phi", 1e-6, 5000.0)])
    assert CollinearityParams.from_scene(fast_jitter).fixed_model((-0.5, 3995.5)) is None
    with pytest.raises(ValueError, match="fixed evaluator"):
        residual_and_rate(fast_jitter, np.zeros((1, 3)), np.zeros(1), evaluator="fixed")


def test_import_without_numba_uses_the_numpy_path():
    code = (
        "import numpy as np\n"
        "from explorer.geometry import kernels as k\n"
        "from explorer.presets import build_scene\n"
        "s = build_scene('WSU')\n"
        "g = s.image_to_ground(np.array([10.0, 2000.0]), np.array([5.0, 3000.0]))\n"
        "t = s.scanline_time(np.array([12.0, 1990.0]))\n"
        "r, _, _ = k.residual_and_rate(s, g, t)\n"
        "assert not k.NUMBA_AVAILABLE\n"
        "assert np.array_equal(r, s.along_track_residual(g, t))\n"
        "print('ok')\n"
    )
    env = dict(os.environ, EXPLORER_DISABLE_NUMBA="1")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def test_columns_with_non_uniform_detector_spacing():
    import dataclasses

    base = build_scene("WSU")
    if "column_polynomial" not in {f.name for f in dataclasses.fields(base.interior)}:
        pytest.skip("InteriorOrientation has no column_polynomial")
    interior = dataclasses.replace(base.interior, column_polynomial=(1e-5, -2e-9))
    scene = Scene("spaced", interior, base.exterior, base.timing, base.n_rows, base.terrain, base.frame)
    ground, t = _points_and_times(scene, seed=5)
    for evaluator in ("reference", "fixed"):
        for backend in BACKENDS:
            _, _, col = residual_and_rate(scene, ground, t, evaluator=evaluator, backend=backend)
            np.testing.assert_allclose(col, scene.column_at_time(ground, t), rtol=0, atol=1e-9)


@pytest.mark.parametrize("name, make", [c for c in CASES if c[0] in ("WSU", "agile", "curved-jitter")],
                         ids=["WSU", "agile", "curved-jitter"])
def test_columns_at_rows_match_the_scene(name, make):
    """The learned methods' column: compiled, equal to Scene.column_at_row, including rows far off the image
    (reference evaluator), NaN rows (NaN) and a non-uniform detector spacing."""
    import dataclasses

    from explorer.geometry.kernels import COLUMN_WINDOW_MARGIN, columns_at_rows

    scene = make()
    ground, _ = _points_and_times(scene, n=2000, seed=9)
    rng = np.random.default_rng(4)
    rows = rng.uniform(-0.5, scene.n_rows - 0.5, len(ground))
    rows[:5] = [-3 * COLUMN_WINDOW_MARGIN, scene.n_rows + 2 * COLUMN_WINDOW_MARGIN, np.nan, -0.5, scene.n_rows - 0.5]
    cases = [scene]
    if "column_polynomial" in {f.name for f in dataclasses.fields(scene.interior)}:
        spaced = dataclasses.replace(scene.interior, column_polynomial=(1e-5, -2e-9))
        cases.append(Scene("spaced", spaced, scene.exterior, scene.timing, scene.n_rows, scene.terrain, scene.frame))
    for sc in cases:
        params = CollinearityParams.from_scene(sc)
        col = columns_at_rows(params, ground, rows)
        ok = np.isfinite(rows)
        assert np.all(np.isnan(col[~ok])) and np.all(np.isfinite(col[ok]))
        np.testing.assert_allclose(col[ok], sc.column_at_row(ground[ok], rows[ok]), rtol=0, atol=1e-9)


def test_columns_at_rows_without_the_fixed_evaluator():
    from explorer.geometry.kernels import columns_at_rows

    scene = build_scene("WSU", extra_jitter=[Jitter("phi", 1e-6, 5000.0)])  # too fast for the fixed evaluator
    params = CollinearityParams.from_scene(scene)
    assert params.fixed_model((-64.5, scene.n_rows + 63.5)) is None
    ground, _ = _points_and_times(scene, n=500, seed=2)
    rows = np.random.default_rng(1).uniform(-0.5, scene.n_rows - 0.5, len(ground))
    np.testing.assert_allclose(columns_at_rows(params, ground, rows), scene.column_at_row(ground, rows),
                               rtol=0, atol=1e-9)
