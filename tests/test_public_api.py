"""The curated public API of ``explorer/__init__.py``: every name resolves to its defining object, lazily."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

import explorer


@pytest.mark.parametrize("name", sorted(explorer._LAZY))
def test_every_public_name_is_the_object_its_module_defines(name):
    module = importlib.import_module(explorer._LAZY[name])
    assert getattr(explorer, name) is getattr(module, name)
    assert name in explorer.__all__ and name in dir(explorer)


def test_unknown_names_raise_attribute_error():
    with pytest.raises(AttributeError, match="no_such_name"):
        explorer.no_such_name  # noqa: B018


def test_import_explorer_imports_no_heavy_module():
    code = (
        "import sys, explorer\n"
        "heavy = [m for m in ('numba', 'torch', 'scipy', 'explorer.scene', 'explorer.methods', 'viser', 'plotly')"
        " if m in sys.modules]\n"
        "print(heavy)"
    )
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
    assert out.strip() == "[]"


def test_a_notebook_workflow_through_the_public_names():
    from explorer import available, build_scene, create, evaluate_method, simulate_points

    scene = build_scene("WSU")
    check = simulate_points(scene, 50, kind="scp", seed=0)  # rows known by construction (image -> ground)
    assert "exact" in available()
    ev = evaluate_method(create("exact", scene), check)
    assert ev.rmse_px < 1e-6 and ev.valid_frac == 1.0
