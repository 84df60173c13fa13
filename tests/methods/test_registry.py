"""The registry: every method of the issue is registered, imports cleanly and follows the interface."""

import numpy as np
import pytest

from explorer.errors import NotFittedError
from explorer.methods import DISCOVERY_ERRORS, available, create, registry
from explorer.points import simulate_points
from explorer.presets import build_scene

EXPECTED = {
    "ss", "bws", "ss-interp", "bws-interp", "nr", "cpp", "gdp", "hybrid",
    "ogp", "ann", "mlp", "lrm", "prm", "rfm", "bpnn", "nn-rfm", "exact", "csm-secant",
}


def test_every_method_is_registered_and_imports():
    names = set(available())  # runs the discovery
    assert DISCOVERY_ERRORS == {}
    assert EXPECTED <= names


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_interface_metadata(name):
    cls = registry()[name]
    assert cls.name == name and cls.label and cls.reference
    assert cls.family in ("search", "learned", "generalized")
    assert cls.exactness in ("exact", "pixel", "approximate")


@pytest.mark.parametrize("name", sorted(n for n in EXPECTED if registry()[n].needs_fit))
def test_learned_methods_refuse_to_predict_before_fit(name):
    method = create(name, build_scene("SCB"))
    with pytest.raises(NotFittedError):
        method.ground_to_image(np.zeros((2, 3)))


def test_unknown_method_is_a_clear_error():
    with pytest.raises(KeyError, match="unknown method"):
        create("nope", build_scene("SCB"))


@pytest.mark.parametrize("name", sorted(EXPECTED - {"ss", "ss-interp"}))
def test_far_outside_points_flagged_by_every_method(name):
    scene = build_scene("SCB")
    method = create(name, scene)
    if method.needs_fit:
        method.fit(simulate_points(scene, 500, kind="scop"))
    far = scene.image_to_ground(np.array([-400.0, scene.n_rows + 400.0, 100.0]),
                                np.array([100.0, 100.0, scene.n_columns + 300.0]))
    res = method.ground_to_image(far)
    assert not res.valid.any()


@pytest.mark.parametrize("name, params", [("nr", {"evaluator": "numpy"}), ("bws", {}), ("exact", {}), ("gdp", {}),
                                          ("bpnn", {})])
def test_chunked_ground_to_image_equals_one_call(name, params):
    """Methods that bound their working memory by chunking give the same arrays as one call."""
    scene = build_scene("WSU")
    pts = simulate_points(scene, 3000, kind="scp", seed=4)
    ground = np.vstack([pts.ground, [[0.0, 0.0, 9e6]]])  # one point above the satellite: not converged
    m = create(name, scene, **params)
    if m.needs_fit:
        m.fit(simulate_points(scene, 100, kind="scop", seed=1))
    whole = m.ground_to_image(ground)
    m.chunk_points = 700
    parts = m.ground_to_image(ground)
    for field in ("row", "col", "converged", "inside", "ce_evaluations"):
        np.testing.assert_array_equal(getattr(parts, field), getattr(whole, field))
    for key, value in whole.info.items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(parts.info[key], value)
        elif key == "status_counts":
            assert parts.info[key] == value


def test_registry_import_does_not_import_torch():
    """torch (about 2 s to import) loads on the first use of a torch-trained method, not with the registry."""
    import subprocess
    import sys

    code = ("import sys; from explorer.methods import available, create; from explorer.presets import build_scene; "
            "names = available(); create('exact', build_scene('WSU')); assert 'mlp' in names; "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("name, params",
                         [("exact", {}), ("csm-secant", {}), ("nr", {}), ("nr", {"evaluator": "numpy"})])
def test_columns_with_non_uniform_detector_spacing(name, params):
    """The compiled solvers map their evenly spaced kernel column through the camera's column polynomial."""
    import dataclasses

    from explorer.scene import Scene

    base = build_scene("PAU")
    interior = dataclasses.replace(base.interior, column_polynomial=(1e-5, -2e-9))
    scene = Scene("spaced", interior, base.exterior, base.timing, base.n_rows, base.terrain, base.frame)
    rng = np.random.default_rng(9)
    row, col = rng.uniform(0, scene.n_rows - 1, 300), rng.uniform(0, scene.n_columns - 1, 300)
    res = create(name, scene, **params).ground_to_image(scene.image_to_ground(row, col))
    assert res.valid.all()
    np.testing.assert_allclose(res.row, row, atol=1e-7)
    np.testing.assert_allclose(res.col, col, atol=1e-7)
