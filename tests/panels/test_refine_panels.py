"""Refinement panels: the quiver shows each point's residual, the removed field equals the correction, the
table the parameters, the trajectory the adjusted orbit."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from explorer.panels.refine import (  # noqa: E402
    correction_field,
    correction_field_figure,
    parameter_table_figure,
    refinement_html,
    residual_quiver_figure,
    trajectory_figure,
)
from explorer.presets import build_scene  # noqa: E402
from explorer.refine.adjust import refine_images  # noqa: E402
from explorer.refine.corrections import apply_correction  # noqa: E402
from explorer.refine.points_io import PointTable  # noqa: E402
from explorer.refine.torch_scene import adjusted_scene  # noqa: E402
from tests.refine.cases import pleiades, simulate_points  # noqa: E402


@pytest.fixture(scope="module")
def rpc_ref():
    rpc = pleiades()
    control = simulate_points(rpc, 25, seed=1)
    control.row[3] += 30.0  # an outlier
    return refine_images([rpc], model="affine", control=control, check=simulate_points(rpc, 20, seed=2, prefix="c"),
                         sigma_px=0.3)


def test_quiver_draws_every_residual(rpc_ref):
    fig = residual_quiver_figure(rpc_ref, scale=10.0)
    lines = [t for t in fig.data if t.mode == "lines" and t.name == "control residual"]
    assert len(lines) == 2  # before and after
    xs = np.asarray([v for v in lines[0].x if v is not None], dtype=float).reshape(-1, 2)
    rows = [r for r in rpc_ref.points_rows() if r["role"] == "control"]
    np.testing.assert_allclose(xs[:, 1] - xs[:, 0], [10.0 * r["residual_col_before"] for r in rows], rtol=1e-12)
    assert any(t.name == "outlier" for t in fig.data)


def test_removed_field_is_the_correction(rpc_ref):
    r, c, field = correction_field(rpc_ref, n=7)
    rpc = rpc_ref.images[0].sensor
    rr, cc = np.meshgrid(r, c, indexing="ij")
    lon, lat = rpc.localization(rr.ravel(), cc.ravel(), np.full(rr.size, rpc.height_offset))[:2]
    row, col = rpc.projection(lon, lat, np.full(rr.size, rpc.height_offset))
    want = np.stack(apply_correction("affine", rpc_ref.parameters, row, col), axis=1) - np.stack([row, col], axis=1)
    np.testing.assert_allclose(field.reshape(-1, 2), want, atol=1e-9)
    assert len(correction_field_figure(rpc_ref, n=7).data) == 2


def test_parameter_table(rpc_ref):
    fig = parameter_table_figure(rpc_ref)
    cells = fig.data[0].cells.values
    assert list(cells[1]) == ["row_shift", "row_per_row", "row_per_col", "col_shift", "col_per_row", "col_per_col"]
    assert float(cells[2][0]) == pytest.approx(rpc_ref.parameters[0], rel=1e-5)
    with pytest.raises(ValueError, match="no trajectory"):
        trajectory_figure(rpc_ref)


def test_trajectory_and_page_of_a_scene(tmp_path):
    scene = build_scene("WSU")
    true = np.array([20.0, -10.0, 5.0, 1e-5, -1e-5, 2e-5])
    rng = np.random.default_rng(5)
    g = scene.image_to_ground(rng.uniform(0.1, 0.9, 20) * scene.n_rows, rng.uniform(0.1, 0.9, 20) * scene.n_columns,
                              height=rng.uniform(-50, 50, 20))
    row, col = adjusted_scene(scene, "attitude", true).ground_to_image(g)
    lon, lat, h = scene.frame.enu_to_geodetic(g)
    ref = refine_images([scene], model="attitude", control=PointTable([f"g{i}" for i in range(20)], row, col,
                                                                      lon, lat, h), sigma_px=0.3)
    fig = trajectory_figure(ref)
    orbit = [t for t in fig.data if t.name == "adjusted orbit"][0]
    t0 = scene.time_range()[0]
    want = adjusted_scene(scene, "attitude", ref.parameters).exterior.position(np.array([t0]))[0] / 1e3
    np.testing.assert_allclose([orbit.x[0], orbit.y[0], orbit.z[0]], want, rtol=1e-12)
    html = refinement_html(ref)
    assert html.count("<script") >= 4 and "plotly" in html
