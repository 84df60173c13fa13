"""explorer.notebook: the residual panel recomputes through the model layer when a control changes, the
inline 3D view holds the explorer's scene, the interactive figure follows its controls.

Truth for the panel: residuals computed directly with build_scene / simulate_points / create / fit /
ground_to_image (the model layer), independently of the panel's code path.
"""

import base64

import numpy as np
import pytest

pytest.importorskip("ipywidgets")
pytest.importorskip("anywidget")

import plotly.graph_objects as go  # noqa: E402

from explorer.errors import InputError  # noqa: E402
from explorer.methods import create  # noqa: E402
from explorer.notebook import (  # noqa: E402
    SCOP_MARKS,
    interactive_figure,
    residual_panel,
    scene_view,
    static_figure_html,
)
from explorer.points import simulate_points  # noqa: E402
from explorer.presets import build_scene  # noqa: E402

N_SCPS = 1500
SEED = 3


def direct_residuals(preset, method, n_scops, *, relief_m=0.0, attitude_rate_scale=1.0):
    """Signed row residual per SCP (estimated - exact, px), straight from the model layer."""
    scene = build_scene(preset, relief_m=relief_m, attitude_rate_scale=attitude_rate_scale)
    scps = simulate_points(scene, N_SCPS, kind="scp", seed=SEED)
    scops = simulate_points(scene, n_scops, kind="scop", seed=SEED)
    m = create(method, scene)
    m.fit(scops)
    res = m.ground_to_image(scps.ground)
    return scps, np.where(res.valid, res.row - scps.row, np.nan)


def map_traces(fig):
    """{method: residual-map raster}: the heatmaps carrying residuals, keyed by the method their ``meta`` names."""
    return {str(t.meta).split()[0]: t for t in fig.data if t.type == "heatmap" and t.meta is not None}


def residuals_of(fig, name):
    """(SCP index, SCP index, residual) of the drawn cells of a method's map.  With fewer SCPs than the
    map's cells every cell holds one SCP (customdata: points in the cell, the SCP's index), so the
    cell's value is that SCP's residual."""
    t = map_traces(fig)[name]
    z = np.asarray(t.z, dtype=float).ravel()
    cd = np.asarray(t.customdata)
    assert cd[..., 0].max() == 1
    drawn = np.isfinite(z)
    idx = cd[..., 1].ravel()[drawn]
    return idx, idx, z[drawn]


@pytest.fixture(scope="module")
def panel():
    return residual_panel("WSU", methods=("lrm", "prm"), scop_density=100, n_scps=N_SCPS, seed=SEED)


def test_setting_the_scop_density_redraws_the_model_residuals(panel):
    before = residuals_of(panel.figure, "lrm")[2]
    updates = panel.n_updates
    panel.controls["scop_density"].value = 10
    assert panel.n_updates == updates + 1
    idx, _, after = residuals_of(panel.figure, "lrm")
    scps, truth = direct_residuals("WSU", "lrm", 10)
    ok = np.isfinite(truth)
    # same points, same order (one SCP per map cell, row-major); value = the model's new residual
    np.testing.assert_array_equal(idx, np.flatnonzero(ok))
    np.testing.assert_allclose(after, truth[ok], rtol=0, atol=1e-12)
    assert np.abs(after - before).max() > 1e-4, "the data changed with the density"
    scops = [t for t in panel.figure.data if t.name and t.name.startswith("SCOPs")]
    assert scops and len(scops[0].x) == len(simulate_points(build_scene("WSU"), 10, kind="scop", seed=SEED))
    _, prm_truth = direct_residuals("WSU", "prm", 10)
    np.testing.assert_allclose(residuals_of(panel.figure, "prm")[2], prm_truth[np.isfinite(prm_truth)],
                               rtol=0, atol=1e-12)


def test_relief_and_attitude_controls_recompute_the_scene(panel):
    panel.controls["scop_density"].value = 30
    panel.controls["attitude_rate_scale"].value = 2.5
    _, truth = direct_residuals("WSU", "lrm", 30, attitude_rate_scale=2.5)
    np.testing.assert_allclose(residuals_of(panel.figure, "lrm")[2], truth[np.isfinite(truth)], rtol=0, atol=1e-12)
    panel.controls["relief_m"].value = 1000.0
    _, truth = direct_residuals("WSU", "lrm", 30, relief_m=1000.0, attitude_rate_scale=2.5)
    got = residuals_of(panel.figure, "lrm")[2]
    np.testing.assert_allclose(got, truth[np.isfinite(truth)], rtol=0, atol=1e-12)
    assert panel.scene.metadata["relief_m"] == 1000.0


def test_colour_limit_and_method_controls(panel):
    panel.controls["limit_px"].value = 0.1
    assert panel.figure.layout.coloraxis.cmin == -0.1 and panel.figure.layout.coloraxis.cmax == 0.1
    panel.controls["colour_mode"].value = "per method"
    assert panel.figure.layout.meta["mode"] == "per method"
    panel.controls["methods"].value = ("prm",)
    assert set(map_traces(panel.figure)) == {"prm"}


def test_panel_scene_view_traces_the_worst_point(panel):
    view = panel.scene_view("prm")
    ev = panel.evaluations["prm"]
    worst = int(np.asarray(ev.evaluated_index)[np.nanargmax(np.abs(ev.residual_row))])
    assert view.best_row == panel.check.row[worst]
    assert {"/points/scps", "/points/scops", "/selected/ray"} <= set(view.nodes)
    with pytest.raises(InputError, match="not evaluated"):
        panel.scene_view("nr")


def test_panel_displays_a_widget_with_a_static_copy(panel):
    bundle = panel._repr_mimebundle_()
    assert "application/vnd.jupyter.widget-view+json" in bundle
    assert '"customdata"' in bundle["text/html"] and ".newPlot(" in bundle["text/html"]


def test_panel_rejects_bad_input():
    with pytest.raises(InputError, match="unknown method"):
        residual_panel("WSU", methods=("no-such-method",), n_scps=100)
    with pytest.raises(InputError, match="marks"):
        residual_panel("WSU", methods=("lrm",), scop_density=42, n_scps=100)
    with pytest.raises(InputError, match="colour_mode"):
        residual_panel("WSU", methods=("lrm",), colour_mode="rainbow", n_scps=100)
    with pytest.raises(InputError, match="unknown preset"):
        residual_panel("nowhere", methods=("lrm",), n_scps=100)
    assert 42 not in SCOP_MARKS


def _embedded_scene(view) -> bytes:
    marker = 'window.__VISER_EMBED_DATA__="'
    start = view.html.index(marker) + len(marker)
    return base64.b64decode(view.html[start:view.html.index('"', start)])


def test_scene_view_holds_the_explorer_scene_and_the_search_trace():
    scene = build_scene("linear")
    point = (0.1 * scene.n_rows, 0.2 * scene.n_columns)
    view = scene_view(scene, point=point, method="bws")
    for node in ("/ground/surface", "/orbit/track", "/scanlines/planes/0", "/selected/point", "/selected/ray",
                 "/selected/trace"):
        assert node in view.nodes
    ground = scene.image_to_ground(np.array([point[0]]), np.array([point[1]]))
    expected = create("bws", scene).ground_to_image(ground, trace=True).trace
    np.testing.assert_array_equal(view.trace_rows, [float(np.asarray(a).ravel()[0]) for a in expected])
    assert view.best_row == point[0]
    payload = _embedded_scene(view)
    assert len(payload) > 1000
    html = view._repr_html_()
    assert html.startswith("<div") and "<iframe srcdoc=" in html and "__VISER_EMBED_DATA__" in html


def test_scene_view_colours_points_and_rejects_bad_input():
    scene = build_scene("WSU")
    scps = simulate_points(scene, 200, kind="scp")
    view = scene_view(scene, check=scps, residual_px=np.linspace(-1, 1, len(scps)))
    assert "/points/scps" in view.nodes and view.trace_rows is None
    with pytest.raises(InputError, match="outside the image"):
        scene_view(scene, point=(-5.0, 10.0))
    with pytest.raises(InputError, match="residual_px"):
        scene_view(scene, check=scps, residual_px=np.zeros(3))
    with pytest.raises(InputError, match="unknown method"):
        scene_view(scene, method="no-such-method")


def test_interactive_figure_follows_its_controls():
    calls = []

    def make(a=2.0, kind="sin"):
        calls.append((a, kind))
        x = np.arange(20.0)
        return go.Figure(go.Scatter(x=x, y=np.sin(a * x) if kind == "sin" else np.cos(a * x)))

    fig = interactive_figure(make, a=(0.0, 5.0, 0.5), kind=["sin", "cos"])
    assert calls == [(2.0, "sin")]
    fig.controls["a"].value = 3.0
    fig.controls["kind"].value = "cos"
    assert calls[-1] == (3.0, "cos") and fig.n_updates == 3
    np.testing.assert_allclose(np.array(fig.figure.data[0].y), np.cos(3.0 * np.arange(20.0)), rtol=0, atol=0)
    assert ".newPlot(" in static_figure_html(fig.figure)
    with pytest.raises(InputError):
        interactive_figure(make)


# ------------------------------------------------------------------------------------------ 3D view framing
def _pinhole(cam, points):
    """Normalised image coordinates (x, y in units of tan(fov/2)) and depths of points, up = +Z."""
    forward = cam.look_at - cam.position
    forward = forward / np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rel = np.asarray(points) - cam.position
    depth = rel @ forward
    t = np.tan(cam.fov_rad / 2)
    return np.c_[(rel @ right) / depth / t, (rel @ up) / depth / t], depth


@pytest.mark.parametrize("preset", ["WSU", "agile", "SCB"])
def test_the_inline_3d_view_frames_the_footprint_and_the_whole_track(preset):
    """The initial camera of scene_view sees every footprint corner and both track ends inside the view (a square
    viewport, the narrowest case) within its clipping range, and the footprint is not a speck."""
    from explorer.scene3d import builders as B  # noqa: N812

    scene = build_scene(preset)
    view = scene_view(scene)
    frame = B.DisplayFrame.for_scene(scene)
    footprint = frame.ground(B.footprint_outline(scene, per_edge=4).reshape(-1, 3))
    _, positions = B.track_positions(scene, 50)
    track = frame.sensor(positions)
    for name, pts in (("footprint", footprint), ("track", track)):
        xy, depth = _pinhole(view.camera, pts)
        assert np.all(np.abs(xy) < 0.95), f"{preset}: {name} leaves the view ({np.abs(xy).max():.2f})"
        assert np.all((depth > view.camera.near) & (depth < view.camera.far)), f"{preset}: {name} clipped"
    xy, _ = _pinhole(view.camera, footprint)
    assert (xy[:, 0].max() - xy[:, 0].min()) > 0.3, "the footprint spans at least 15% of the view's width"
