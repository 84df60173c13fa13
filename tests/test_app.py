"""The explorer driven from Python: a viser server on a free port, the GUI's handles set
from the test (setting ``.value`` runs the callbacks), the scene and panels checked.

The methods used here are tiny test-only methods registered for the duration of these
tests only (``toy_methods``), so the explorer is tested through the registry alone,
whatever methods the package ships.  Truth: the SCPs' exact rows (``simulate_points``)
and the brute-force solver of ``tests/truth.py``.
"""

from __future__ import annotations

import contextlib
import html
import socket
import threading
import time
import warnings
from collections.abc import Iterator

import numpy as np
import pytest

from explorer.methods import base as methods_base
from explorer.methods.base import BestScanlineMethod, ScanlineResult
from explorer.points import PointSet
from tests.truth import brute_force_rows

viser = pytest.importorskip("viser")

from explorer.app import (  # noqa: E402
    SCOP_DENSITIES,
    ExplorerApp,
    ExplorerModel,
    FitPool,
    Settings,
    accepted_params,
    gui_params,
    serve,
)
from explorer.panels import NEGATIVE_END, POSITIVE_END, diverging_rgb  # noqa: E402


# ------------------------------------------------------------------ toy methods
class ToyPoly(BestScanlineMethod):
    """Test-only learned method: least-squares polynomial row(x, y) of degree ``hidden_layers``.

    Parameters
    ----------
    hidden_layers : int
        Polynomial degree (stands in for an MLP's depth).
    neurons : int
        Unused.
    """

    name = "toy_poly"
    label = "toy polynomial"
    reference = "test only"
    family = "learned"
    needs_fit = True
    exactness = "approximate"

    def __init__(self, scene, *, hidden_layers: int = 1, neurons: int = 10, **params) -> None:
        super().__init__(scene, hidden_layers=hidden_layers, neurons=neurons, **params)
        self.degree = int(hidden_layers)

    def _features(self, g: np.ndarray) -> np.ndarray:
        x = (g[:, 0] - self.mu[0]) / self.sd[0]
        y = (g[:, 1] - self.mu[1]) / self.sd[1]
        cols = [np.ones_like(x)]
        for d in range(1, self.degree + 1):
            for i in range(d + 1):
                cols.append(x ** (d - i) * y**i)
        return np.stack(cols, 1)

    def _fit(self, control: PointSet) -> None:
        self.mu = control.ground.mean(0)
        self.sd = control.ground.std(0) + 1e-9
        self.coef, *_ = np.linalg.lstsq(self._features(control.ground), control.row, rcond=None)

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        row = self._features(ground) @ self.coef
        n = len(row)
        return self._result(ground, row, np.ones(n, bool), np.zeros(n, int))


class ToyBisect(BestScanlineMethod):
    """Test-only search: 40 bisections of the along-track residual over the image rows."""

    name = "toy_bisect"
    label = "toy bisection"
    reference = "test only"
    family = "search"
    needs_fit = False
    exactness = "exact"
    iterations = 40

    def _locate(self, ground: np.ndarray, *, trace: bool) -> ScanlineResult:
        sc = self.scene
        n = len(ground)
        lo = np.full(n, -0.5)
        hi = np.full(n, sc.n_rows - 0.5)
        flo = sc.along_track_residual(ground, sc.scanline_time(lo))
        fhi = sc.along_track_residual(ground, sc.scanline_time(hi))
        ok = np.sign(flo) != np.sign(fhi)
        visited: list[np.ndarray] | None = [] if trace else None
        for _ in range(self.iterations):
            mid = 0.5 * (lo + hi)
            fm = sc.along_track_residual(ground, sc.scanline_time(mid))
            if visited is not None:
                visited.append(mid.copy())
            same = np.sign(fm) == np.sign(flo)
            lo = np.where(same, mid, lo)
            flo = np.where(same, fm, flo)
            hi = np.where(same, hi, mid)
        row = np.where(ok, 0.5 * (lo + hi), np.nan)
        return self._result(ground, row, ok, np.full(n, 2 + self.iterations), trace=visited)


class ToySlow(ToyPoly):
    """Test-only learned method whose training takes 1.5 s."""

    name = "toy_slow"
    label = "toy slow"

    def _fit(self, control: PointSet) -> None:
        time.sleep(1.5)
        super()._fit(control)


class ToyLong(ToyPoly):
    """Test-only learned method declaring a long training (``long_fit``, like an MLP); records when it starts."""

    name = "toy_long"
    label = "toy long"
    long_fit = True
    started: list[float] = []

    def _fit(self, control: PointSet) -> None:
        ToyLong.started.append(time.monotonic())
        super()._fit(control)


class ToyBroken(ToyPoly):
    """Test-only learned method whose training fails."""

    name = "toy_broken"
    label = "toy broken"

    def _fit(self, control: PointSet) -> None:
        raise RuntimeError("toy training failure")


class ToyUnconverged(ToyPoly):
    """Test-only learned method whose training reports no convergence (and warns)."""

    name = "toy_unconverged"
    label = "toy unconverged"

    def _fit(self, control: PointSet) -> None:
        super()._fit(control)
        self.fit_info.update(converged=False, stop_reason="max_epochs", val_rmse_px=3.5)
        warnings.warn("toy_unconverged: training did not converge", RuntimeWarning, stacklevel=2)


TOYS = (ToyPoly, ToyBisect, ToySlow, ToyLong, ToyBroken, ToyUnconverged)


@contextlib.contextmanager
def toy_registry() -> Iterator[None]:
    """Register the toy methods while the block runs (never leaks into other tests)."""
    methods_base.registry()  # discover the package's own methods first
    with pytest.MonkeyPatch.context() as mp:
        for cls in TOYS:
            mp.setitem(methods_base._REGISTRY, cls.name, cls)
        yield


@pytest.fixture(scope="module", autouse=True)
def toy_methods():
    with toy_registry():
        yield


@pytest.fixture
def server():
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield srv
    srv.stop()


def make_app(server, methods=("toy_poly", "toy_bisect"), **kw) -> ExplorerApp:
    kw.setdefault("scp_count", 3000)
    kw.setdefault("sweep", False)
    kw.setdefault("background", False)
    return ExplorerApp(server, methods=list(methods), **kw)


# ------------------------------------------------------------------------ tests
def test_lighting_costs_a_software_webgl_browser_no_environment_map_and_no_shadows(server):
    """What every browser is sent (the server's persistent messages, newest last): no environment map (its
    GGX pre-filtering took 4.9-7.3 s of one software-WebGL frame in Chrome traces) and default lights without
    shadows, an ambient light instead for the lit objects."""
    from viser import _messages

    make_app(server)
    buffer = server._websock_server._broadcast_buffer
    sent = [buffer.message_from_id[k] for k in sorted(buffer.message_from_id)]
    env = [m for m in sent if isinstance(m, _messages.EnvironmentMapMessage)]
    lights = [m for m in sent if isinstance(m, _messages.EnableLightsMessage)]
    ambient = [m for m in sent if isinstance(m, _messages.AmbientLightMessage)]
    assert env and env[-1].hdri_data is None
    assert lights and lights[-1].enabled and not lights[-1].cast_shadow
    assert len(ambient) == 1 and ambient[0].props.intensity > 0


def test_maps_drawn_reports_are_read_and_an_update_without_a_browser_does_not_wait(server):
    """The page's report (``drawn <revision>``, controls.DRAWN_SCRIPT) sets the newest revision drawn; other text is
    ignored; each maps figure sent carries the next revision; with no browser open an update never waits for one."""
    app = make_app(server)
    rev = app.handles["maps"].figure.layout.meta["revision"]
    assert rev >= 1 and app.maps_drawn == 0
    app.handles["maps_drawn"].value = f"drawn {rev}"
    assert app.maps_drawn == rev
    app.handles["maps_drawn"].value = "not a report"
    app.handles["maps_drawn"].value = "drawn 0"  # an older revision does not lower it
    assert app.maps_drawn == rev
    app.handles["density"].value = "30"
    assert app.handles["maps"].figure.layout.meta["revision"] == rev + 1
    app._maps_wait_rev = rev + 5  # never reported; no browser connected: the wait returns (not after an hour)
    th = threading.Thread(target=app._wait_maps_drawn, args=(None, 3600.0), daemon=True)
    th.start()
    th.join(30)
    assert not th.is_alive()


def test_3d_view_reports_end_an_update_and_hold_idle_until_drawn(server, monkeypatch):
    """The page's report of its 3D view drawn (``drawn <n>`` in the hidden *View drawn* control,
    controls.VIEW_DRAWN_SCRIPT): each update's 3D batch is numbered (``view <n>`` sent to the page); with a browser
    open, the app is idle only once the newest batch is reported drawn, or VIEW_DRAWN_WAIT_S after it was sent;
    without a browser it never waits."""
    from explorer.app import views

    app = make_app(server)
    sent = app._view_sent
    assert sent >= 1 and app.handles["view_drawn"].value == f"view {sent}" and app.view_drawn == 0
    assert app.wait_idle(5)  # no browser: idle at once
    app.handles["view_drawn"].value = "view 99"  # the server's own message is not a report
    app.handles["view_drawn"].value = "not a report"
    assert app.view_drawn == 0
    monkeypatch.setattr(app, "_open_browsers", lambda: [object()])  # a browser open, one that never reports
    monkeypatch.setattr(views, "VIEW_DRAWN_WAIT_S", 1.5)
    app.handles["density"].value = "30"  # an update: its 3D batch is the next number
    assert app._view_sent == sent + 1 and app.handles["view_drawn"].value == f"view {sent + 1}"
    assert app._view_drawing()
    assert not app.wait_idle(0.3)  # still drawing: not idle
    t0 = time.monotonic()
    threading.Timer(0.4, lambda: setattr(app.handles["view_drawn"], "value", f"drawn {sent + 1}")).start()
    assert app.wait_idle(10)  # the report ends the wait (not the 1.5 s deadline)
    assert 0.3 < time.monotonic() - t0 < 1.4 and app.view_drawn == sent + 1 and not app._view_drawing()
    app.handles["view_drawn"].value = f"drawn {sent}"  # an older report does not lower it
    assert app.view_drawn == sent + 1
    app.handles["density"].value = "50"  # never reported: idle once the deadline passed
    t0 = time.monotonic()
    assert app._view_drawing() and app.wait_idle(10)
    assert 1.0 < time.monotonic() - t0 < 5.0 and not app._view_drawing()


def test_scene_nodes_and_counts(server):
    app = make_app(server)
    s = app.settings()
    names = set(app.nodes)
    for n in ("/ground/surface", "/ground/outline", "/orbit/track", "/orbit/sensor_frames",
              "/orbit/direction", "/orbit/flight_label", "/scanlines/planes/3", "/scanlines/edges",
              "/scanlines/labels/0", "/scanlines/labels/2", "/points/scops", "/points/scps",
              "/selected/point", "/selected/ray", "/selected/label"):
        assert n in names, n
    # first / middle / last / selected scanline planes: their outlines 12 segments, the selected one filled (an
    # unlit triangle image)
    assert sorted(n for n in names if n.startswith("/scanlines/planes/")) == ["/scanlines/planes/3"]
    assert app.nodes["/scanlines/edges"].points.shape == (12, 2, 3)
    assert app.nodes["/scanlines/labels/0"].text.startswith("first scanline")
    assert app.nodes["/scanlines/labels/2"].text.startswith("last scanline")
    scops = app.model.scops(s)
    scps = app.model.scps(s)
    assert app.nodes["/points/scops"].points.shape == (len(scops), 3)
    assert app.nodes["/points/scps"].points.shape == (len(scps), 3)
    # kilometres around the scene centre, float32 on the wire
    pts = app.nodes["/points/scps"].points
    assert pts.dtype == np.float32
    assert np.abs(pts).max() < 10.0  # WSU is ~2 km wide
    # the satellite track is displayed at the compressed distance (2.5 footprint diagonals)
    track = app.nodes["/orbit/track"].points
    d = np.linalg.norm(track.mean(0))
    assert 2.0 * app.frame.diagonal_km < d < 3.0 * app.frame.diagonal_km


def test_scop_change_moves_the_scop_cloud_and_redraws_the_selection_only_when_it_moved(server):
    """A SCOP change sends the SCOP cloud's new points and size to the same node (a new node is a new material: a
    software-WebGL browser re-links its shader); the selected point's nodes are drawn again exactly when what they
    show changed (its point, scanline, search path or label), not merely because the colour method's result did."""
    from explorer.scene3d import builders as B  # noqa: N812

    app = make_app(server, methods=("toy_poly", "toy_bisect"))
    assert app.settings().color_method == "toy_poly"
    node = app.nodes["/points/scops"]
    for density in ("30", "300", "50"):
        before = app.selection
        selected = {k: v for k, v in app.nodes.items() if k.startswith("/selected/")}
        app.handles["density"].value = density
        s = app.settings()
        scops = app.model.scops(s)
        assert app.nodes["/points/scops"] is node  # the same cloud, moved
        np.testing.assert_allclose(node.points, app.frame.ground(scops.ground), rtol=0, atol=1e-5)  # float32 km
        assert node.point_size == pytest.approx(B.scop_point_size_km(app.frame, len(scops)))
        sel = app.selection
        same = (np.array_equal(sel.ground, before.ground) and sel.exact_row == before.exact_row
                and sel.exact_col == before.exact_col
                and (sel.trace_rows is None) == (before.trace_rows is None)
                and (sel.trace_rows is None or np.array_equal(sel.trace_rows, before.trace_rows)))
        now = {k: v for k, v in app.nodes.items() if k.startswith("/selected/")}
        assert (set(now) == set(selected) and all(now[k] is selected[k] for k in now)) == same, (density, same)
        assert app.nodes["/selected/label"].text == f"selected: row {sel.exact_row:.2f}, col {sel.exact_col:.2f}"
    # another point selected: drawn again, at its own row
    selected = dict(app.nodes)
    app.handles["sel_mode"].value = "image point"
    app.handles["sel_row"].value = float(round(app.selection.exact_row / 2))
    sel = app.selection
    assert app.nodes["/selected/point"] is not selected["/selected/point"]
    assert app.nodes["/selected/label"].text == f"selected: row {sel.exact_row:.2f}, col {sel.exact_col:.2f}"


def test_scp_colours_follow_residuals(server):
    app = make_app(server)
    app.handles["colour_mode"].value = "fixed"
    app.handles["limit"].value = "0.01"  # toy_poly errs by up to ~0.03 px: both ends saturate
    s = app.settings()
    assert s.color_method == "toy_poly" and s.limit_px == 0.01
    ev = app.runs["toy_poly"].evaluation
    scps = app.model.scps(s)
    # the residuals are the method's rows minus the SCPs' exact rows
    truth = ToyPoly(app.scene).fit(app.model.scops(s)).ground_to_image(scps.ground).row - scps.row
    np.testing.assert_allclose(ev.residual_row, truth[ev.evaluated_index], atol=1e-9)
    cloud = app.nodes["/points/scps"]
    res = truth[app.cloud_index]
    np.testing.assert_array_equal(cloud.colors, diverging_rgb(res, 0.01))
    assert res.max() > 0.01 and res.min() < -0.01
    assert tuple(cloud.colors[np.argmax(res)]) == POSITIVE_END  # red end
    assert tuple(cloud.colors[np.argmin(res)]) == NEGATIVE_END  # blue end
    # the cloud's points are those SCPs' ground coordinates (km from the scene centre)
    np.testing.assert_allclose(cloud.points, app.frame.ground(scps.ground[app.cloud_index]), atol=1e-5)


def test_exact_method_colours_are_neutral_and_its_rows_exact(server):
    app = make_app(server)
    app.handles["colour_mode"].value = "fixed"
    app.handles["color_method"].value = "toy_bisect"
    ev = app.runs["toy_bisect"].evaluation
    assert np.nanmax(np.abs(ev.residual_row)) < 1e-6
    colors = app.nodes["/points/scps"].colors
    assert np.all(np.abs(colors.astype(int) - 221) <= 1)  # the light-grey centre of the fixed +-1 px scale
    # the automatic scale (default) is scale-free: the same tiny residuals fill the whole ramp
    app.handles["colour_mode"].value = "per method"
    lim = np.percentile(np.abs(ev.residual_row[np.isfinite(ev.residual_row)]), 99)
    np.testing.assert_array_equal(app.nodes["/points/scps"].colors, diverging_rgb(app.cloud_residual, lim))
    assert len(np.unique(app.nodes["/points/scps"].colors, axis=0)) > 10


def test_point_cloud_decimation_is_named(server):
    app = make_app(server, max_cloud_points=1000)
    assert app.nodes["/points/scps"].points.shape == (1000, 3)
    assert "1,000 of 3,0" in app.handles["cloud_text"].content  # names the decimation


def test_changing_preset_rebuilds_only_the_scene_dependent_parts(server):
    app = make_app(server)
    c0 = dict(app.model.counters)
    old_ground = app.nodes["/ground/surface"]
    app.handles["preset"].value = "ISB"
    assert app.scene.name == "ISB"
    assert app.handles["sel_row"].max == app.scene.n_rows - 1
    assert app.nodes["/ground/surface"] is not old_ground
    c1 = dict(app.model.counters)
    assert c1["scene"] == c0["scene"] + 1 and c1["scps"] == c0["scps"] + 1
    # back to WSU: everything cached, nothing recomputed
    app.handles["preset"].value = "WSU"
    assert app.model.counters == c1


def test_caches_recompute_only_what_depends_on_a_control(server):
    app = make_app(server)
    c = dict(app.model.counters)
    app.handles["scps"].value = "10000"  # SCPs: new points, new evaluations, no refit
    c2 = dict(app.model.counters)
    assert c2["fit"] == c["fit"] and c2["scene"] == c["scene"] and c2["scops"] == c["scops"]
    assert c2["scps"] == c["scps"] + 1 and c2["evaluate"] == c["evaluate"] + 2
    assert app.runs["toy_bisect"].evaluation.fit_s == 0.0 and app.runs["toy_poly"].evaluation.fit_s > 0
    app.handles["density"].value = "30"  # SCOPs: refit only the learned method
    c3 = dict(app.model.counters)
    assert c3["fit"] == c2["fit"] + 1 and c3["scene"] == c2["scene"] and c3["scps"] == c2["scps"]
    assert app.runs["toy_poly"].evaluation.n_scops == len(app.model.scops(app.settings()))
    for key, value in (("color_method", "toy_bisect"), ("limit", "0.5"), ("exaggeration", 2.0)):
        app.handles[key].value = value  # presentation only
    assert app.model.counters == c3


def test_mlp_controls_reach_methods_that_declare_them(server):
    assert {"hidden_layers", "neurons"} <= set(accepted_params(ToyPoly))
    assert gui_params(ToyPoly, Settings(mlp_layers=3, mlp_neurons=7)) == {"hidden_layers": 3, "neurons": 7}
    assert gui_params(ToyBisect, Settings(mlp_layers=3)) == {}
    app = make_app(server)
    rmse1 = app.runs["toy_poly"].evaluation.rmse_px
    app.handles["layers"].value = 3
    run = app.runs["toy_poly"]
    assert run.fit.params["hidden_layers"] == 3 and run.fit.method.degree == 3
    assert run.evaluation.rmse_px < rmse1


def test_residual_map_panel_holds_the_model_residuals(server):
    app = make_app(server)
    fig = app.handles["maps"].figure
    s = app.settings()
    scps = app.model.scps(s)
    from explorer.panels.raster import aggregate, cell_grid

    for k, name in enumerate(("toy_poly", "toy_bisect")):
        ev = app.runs[name].evaluation
        (tr,) = [t for t in fig.data if t.name == f"{name} row"]
        assert tr.type == "heatmap"
        ok = np.isfinite(ev.residual_row)
        # the raster is the per-cell mean of the model's residuals (the same cells as the export)
        cells = cell_grid(app.scene.shape, len(scps), scps.grid_shape[:2], app.max_map_cells)
        idx = ev.evaluated_index[ok]
        want = aggregate(cells, scps.row[idx], scps.col[idx], ev.residual_row[ok], idx)
        np.testing.assert_array_equal(np.asarray(tr.z), want.value)
        np.testing.assert_array_equal(np.asarray(tr.customdata)[..., 1], want.worst_index)  # what a click selects
        np.testing.assert_array_equal(np.asarray(tr.x), cells.col_edges)
        np.testing.assert_array_equal(np.asarray(tr.y), cells.row_edges)
        # default colour scale: per map, symmetric, the 99th percentile of |residual|
        axis = fig.layout[f"coloraxis{k + 1 if k else ''}"]
        lim = np.percentile(np.abs(ev.residual_row[ok]), 99)
        assert axis.cmax == pytest.approx(lim, rel=1e-12) and axis.cmin == -axis.cmax
        assert f"{lim:.2g}" in axis.colorbar.title.text
    app.handles["colour_mode"].value = "fixed"
    fig = app.handles["maps"].figure
    assert fig.layout.coloraxis.cmin == -1.0 and fig.layout.coloraxis.cmax == 1.0
    assert "toy_poly" in app.handles["summary"].content


def test_worst_point_selection_and_search_trace(server):
    app = make_app(server)
    app.handles["color_method"].value = "toy_bisect"
    sel = app.selection
    s = app.settings()
    scps = app.model.scps(s)
    ev = app.runs["toy_bisect"].evaluation
    i = ev.evaluated_index[np.nanargmax(np.abs(ev.residual_row))]
    np.testing.assert_array_equal(sel.ground, scps.ground[i])
    assert sel.exact_row == scps.row[i]
    # the search path: one scanline per bisection, converging on the exact row
    assert len(sel.trace_rows) == ToyBisect.iterations
    assert app.nodes["/selected/trace"].points.shape == (ToyBisect.iterations, 2, 3)
    assert abs(sel.trace_rows[-1] - scps.row[i]) < 1e-6
    assert abs(sel.trace_rows[0] - (app.scene.n_rows - 1) / 2) < 1e-9  # first midpoint
    assert "visited 40 scanlines" in app.handles["sel_text"].content
    # the ray joins the point to the (displayed) perspective centre of its exact scanline
    ray = app.nodes["/selected/ray"].points[0]
    centre = app.scene.exterior.position(app.scene.scanline_time(np.array([scps.row[i]])))
    np.testing.assert_allclose(ray[0], app.frame.ground(scps.ground[i][None])[0], atol=1e-5)
    np.testing.assert_allclose(ray[1], app.frame.sensor(centre)[0], atol=1e-4)


def test_image_point_selection_from_the_sliders(server):
    app = make_app(server)
    app.handles["sel_row"].value = 1234.5
    assert app.handles["sel_mode"].value == "image point"
    app.handles["sel_col"].value = 2000.0
    sel = app.selection
    assert (sel.exact_row, sel.exact_col) == (1234.5, 2000.0)
    exact = brute_force_rows(app.scene, sel.ground[None])[0]
    assert abs(exact - 1234.5) < 1e-6
    assert abs(sel.est_row - exact) < 0.1  # toy_poly, the colour method, is close


def test_a_failing_method_is_reported_not_fatal(server):
    app = make_app(server, methods=("toy_poly", "toy_broken"))
    assert not app.runs["toy_broken"].ok and app.runs["toy_poly"].ok
    assert "toy training failure" in app.handles["summary"].content
    assert "failed: toy_broken" in app.handles["status"].content
    assert app.errors == []


def test_unconverged_training_is_reported(server):
    with pytest.warns(RuntimeWarning, match="did not converge"):
        app = make_app(server, methods=("toy_unconverged",))
    assert app.runs["toy_unconverged"].ok
    text = app.handles["summary"].content
    assert "did not reach its accuracy goal (validation RMSE 3.5 px; stop: max_epochs); the map shows the best " \
        "model reached" in text


def test_slow_method_shows_a_named_preview_then_every_point(server):
    """Issue 24: a method projected to be slow is shown on a fixed seeded preview first (named as one in
    the map title and the summary), then on every SCP; the final state never depends on timing."""
    model = ExplorerModel(preview_after_s=1e-9, preview_points=500, probe_points=200)
    s = Settings(preset="WSU", scp_count=3000, methods=("toy_bisect",))
    rec = model.fit("toy_bisect", s)
    assert model.needs_preview("toy_bisect", s, rec)
    preview = model.evaluate("toy_bisect", s, fit=rec, max_points=model.preview_points)
    assert preview.preview and preview.evaluation.n_evaluated == 500
    again = ExplorerModel(preview_after_s=1e-9, preview_points=500, probe_points=200)
    np.testing.assert_array_equal(preview.evaluation.evaluated_index,  # fixed and seeded
                                  again.evaluate("toy_bisect", s, max_points=500).evaluation.evaluated_index)
    from explorer.panels.figures import residual_maps

    fig = residual_maps({"toy_bisect": preview.evaluation}, model.scps(s), shape=model.scene(s).shape)
    assert "500 of 3,0" in fig.layout.meta["titles"][0] and "preview" in fig.layout.meta["titles"][0]
    app = make_app(server, model=model, background=True)
    try:
        assert app.wait_idle(60)
        run = app.runs["toy_bisect"]
        assert not run.preview and run.evaluation.n_evaluated == len(model.scps(app.settings()))
        assert "preview" not in app.handles["summary"].content
    finally:
        app.close()


def test_the_cost_probe_leaves_one_time_costs_out(server):
    """A method whose first call pays a one-time cost (loading its compiled kernels: here 1 s) and is fast per
    point is projected fast from one probe (after an untimed 2-point call), not probed a second time on 8x the
    points; the projection is the per-point cost times the points."""
    calls: list[int] = []

    class FirstCallSlow(ToyBisect):
        def _locate(self, ground, **kw):
            if not calls:
                time.sleep(1.0)
            calls.append(len(ground))
            return super()._locate(ground, **kw)

    model = ExplorerModel(preview_after_s=1.0, preview_points=500, probe_points=200)
    s = Settings(preset="linear", scp_count=1000, methods=("toy_bisect",))
    rec = model.fit("toy_bisect", s)
    rec.method.__class__ = FirstCallSlow
    t0 = time.perf_counter()
    rec.method.ground_to_image(model.scps(s).ground[:200])
    per_point = (time.perf_counter() - t0) / 200
    calls.clear()
    projected = model._projection("toy_bisect", rec, s, model.scps(s))
    assert calls == [2, 200]
    assert projected < 1.0 and projected < 20 * per_point * 1000
    assert not model.needs_preview("toy_bisect", s, rec)


def test_foreground_app_always_evaluates_every_point(server):
    model = ExplorerModel(preview_after_s=1e-9, preview_points=500, probe_points=200)
    app = make_app(server, model=model)
    run = app.runs["toy_bisect"]
    assert not run.preview and run.evaluation.n_evaluated == len(model.scps(app.settings()))


def test_accuracy_sweep_over_scop_densities(server):
    app = make_app(server, sweep=True)
    evs = app.sweeps["toy_poly"]
    assert [e.n_scops for e in evs] == sorted(e.n_scops for e in evs) and len(evs) == 8
    assert len(app.sweeps["toy_bisect"]) == 1 and app.sweeps["toy_bisect"][0].n_scops == 0
    fig = app.handles["accuracy"].figure
    (rm,) = [t for t in fig.data if t.name == "toy_poly RMSE"]
    np.testing.assert_array_equal(np.asarray(rm.customdata), [e.rmse_px for e in evs])
    assert fig.layout.xaxis.type == "log" and fig.layout.yaxis.type == "log"


def test_background_worker_shows_fast_methods_while_a_slow_one_trains(server):
    app = make_app(server, methods=("toy_poly", "toy_slow"), background=True, fit_wait_s=0.2)
    try:
        assert app.wait_update(1, timeout=60)  # the scene, drawn while the methods load
        assert app.scene is not None and "/ground/surface" in app.nodes
        assert app.wait_update(app.wait_methods(60), timeout=60)
        assert "toy_poly" in app.runs
        assert "toy_slow" in app.pending or "toy_slow" in app.runs
        assert app.wait_idle(timeout=60)
        assert app.runs["toy_slow"].ok and not app.pending
        assert app.runs["toy_slow"].evaluation.fit_s >= 1.5
        gen = app.request_update()
        app.handles["preset"].value = "linear"
        assert app.wait_update(gen + 1, timeout=60) and app.wait_idle(timeout=60)
        assert app.scene.name == "linear" and app.runs["toy_slow"].ok
        assert app.errors == []
    finally:
        app.close()
    assert not app._worker.is_alive()


def test_long_trainings_start_once_the_first_maps_are_on_screen(server, monkeypatch):
    """A ``long_fit`` method (an MLP: seconds of training, torch to import) trains only after the first update that
    drew the other methods' maps: beside it, it took the CPU from them.  It then trains and is drawn."""
    ToyLong.started.clear()
    shown: list[tuple[float, tuple, str]] = []
    real = ExplorerApp._maps_shown

    def spy(self, s):
        shown.append((time.monotonic(), tuple(self.runs), self.handles["summary"].content))
        real(self, s)

    monkeypatch.setattr(ExplorerApp, "_maps_shown", spy)
    app = make_app(server, methods=("toy_poly", "toy_long"), background=True, fit_wait_s=0.2)
    try:
        assert app.wait_idle(timeout=60)
        assert app.runs["toy_long"].ok and app.runs["toy_poly"].ok and not app.pending
        first = next(i for i, (_, runs, _) in enumerate(shown) if "toy_poly" in runs)
        t_first, runs, summary = shown[first]
        assert "toy_long" not in runs and "toy_long" in summary and "starts once the other maps are drawn" in summary
        assert len(ToyLong.started) == 1 and ToyLong.started[0] > t_first
        assert not app.fits.held and not app.hold_long_fits
    finally:
        app.close()


class _SlowBrowser:
    """A browser double for :meth:`ExplorerApp._browsers_caught_up`: answers each localStorage question ``delay_s``
    after it is asked (never, with ``delay_s=None``), recording when it was asked and when it answered."""

    def __init__(self, delay_s: float | None) -> None:
        self.delay_s = delay_s
        self.asked: list[float] = []
        self.answered: list[float] = []
        self.local_storage = self

    def get_item(self, key: str, timeout: float | None = None) -> str | None:
        self.asked.append(time.monotonic())
        if self.delay_s is None or (timeout is not None and timeout < self.delay_s):
            time.sleep(timeout or 0.0)
            raise TimeoutError("no answer")
        time.sleep(self.delay_s)
        self.answered.append(time.monotonic())
        return None


@pytest.mark.parametrize("delay_s", [0.6, None])
def test_held_work_waits_until_the_browsers_have_taken_in_the_first_maps(server, monkeypatch, delay_s):
    """The long trainings and the accuracy sweep start only once every open browser answered two questions asked
    after the first complete maps were sent (it took them in and drew a frame after them), or, from a browser that
    never answers, after BROWSER_CATCH_UP_S; what they compute is the same either way."""
    from explorer.app import gui as gui_module

    ToyLong.started.clear()
    browser = _SlowBrowser(delay_s)
    monkeypatch.setattr(ExplorerApp, "_open_browsers", lambda self: [browser])
    monkeypatch.setattr(gui_module, "BROWSER_CATCH_UP_S", 1.5)
    shown: list[float] = []
    real_shown = ExplorerApp._maps_shown

    def spy(self, s):
        if "toy_poly" in self.runs and not shown:
            shown.append(time.monotonic())
        real_shown(self, s)

    monkeypatch.setattr(ExplorerApp, "_maps_shown", spy)
    sweeps: list[float] = []
    real_sweep = ExplorerModel.sweep

    def sweep_spy(self, *a, **kw):
        sweeps.append(time.monotonic())
        return real_sweep(self, *a, **kw)

    monkeypatch.setattr(ExplorerModel, "sweep", sweep_spy)
    app = make_app(server, methods=("toy_poly", "toy_long"), background=True, fit_wait_s=0.2, sweep=True)
    try:
        assert app.wait_idle(timeout=60)
        assert app.runs["toy_long"].ok and app.runs["toy_poly"].ok and not app.pending
        assert shown and ToyLong.started and sweeps  # the training at the shown SCOP count, the sweep's at the others
        if delay_s is not None:  # two questions, the second asked after the first answer
            assert len(browser.answered) == 2 and browser.asked[1] >= browser.answered[0]
            assert browser.asked[0] >= shown[0]
            start = browser.answered[1]
        else:  # no answer: the held work starts when the wait is over
            assert browser.answered == []
            start = shown[0] + 1.5
        assert min(ToyLong.started) >= start and min(sweeps) >= start
        assert not app.fits.held and not app.hold_long_fits
    finally:
        app.close()


def test_long_trainings_wait_while_a_preview_is_on_screen(server, monkeypatch):
    """Maps shown as a preview are not complete: its full evaluation runs on the fit threads, and a long training
    beside it would slow it; the training starts once the full maps are drawn."""
    ToyLong.started.clear()
    shown: list[tuple[float, bool]] = []
    real = ExplorerApp._maps_shown

    def spy(self, s):
        run = self.runs.get("toy_bisect")
        shown.append((time.monotonic(), run is not None and run.preview))
        real(self, s)

    monkeypatch.setattr(ExplorerApp, "_maps_shown", spy)

    class SlowOnEveryPoint(ToyBisect):  # the full evaluation (3,000 points) lasts 1 s: the preview is drawn first
        def _locate(self, ground, **kw):
            if len(ground) > 1000:
                time.sleep(1.0)
            return super()._locate(ground, **kw)

    monkeypatch.setitem(methods_base._REGISTRY, "toy_bisect", SlowOnEveryPoint)
    model = ExplorerModel(preview_after_s=1e-9, preview_points=500, probe_points=200)
    app = make_app(server, model=model, methods=("toy_bisect", "toy_long"), background=True, fit_wait_s=0.2)
    try:
        assert app.wait_idle(timeout=60)
        assert app.runs["toy_long"].ok and not app.runs["toy_bisect"].preview
        previews = [t for t, preview in shown if preview]
        full = [t for t, preview in shown if not preview and t > (previews[0] if previews else 0.0)]
        assert previews and full, shown  # a preview first, then the full maps
        assert len(ToyLong.started) == 1 and ToyLong.started[0] > full[0] > previews[0]
    finally:
        app.close()


def test_fit_pool_holds_jobs_until_released():
    cond = threading.Condition()
    pool = FitPool(cond, lambda key, prio: None, threads=2)
    order: list = []
    try:
        pool.submit("held", lambda: order.append("held"), 0, cost=0.0, hold=True)
        pool.submit("free", lambda: order.append("free"), 0, cost=1.0)
        pool.wait_for(["free"], time.monotonic() + 10)
        time.sleep(0.2)
        assert order == ["free"] and pool.is_pending("held") and pool.busy
        pool.release()
        pool.wait_for(["held"], time.monotonic() + 10)
    finally:
        pool.close()
    assert order == ["free", "held"] and not pool.busy and not pool.held


def _port_free(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def test_explore_command_and_clean_shutdown():
    from explorer.cli import build_parser

    args = build_parser().parse_args(["explore", "--preset", "ISB", "--host", "127.0.0.1", "--port", "0"])
    assert (args.preset, args.host, args.port) == ("ISB", "127.0.0.1", 0)
    assert callable(args.func)
    box: dict = {}
    stop = threading.Event()
    th = threading.Thread(target=lambda: box.setdefault("rc", serve(
        "ISB", port=0, methods=["toy_poly"], ready=lambda a: box.setdefault("app", a), stop_event=stop,
        scp_count=2000, sweep=False)), daemon=True)
    th.start()
    t0 = time.monotonic()
    while "app" not in box and time.monotonic() - t0 < 60:
        time.sleep(0.05)
    app = box["app"]
    assert app.url.startswith("http://127.0.0.1:")
    port = int(app.url.rsplit(":", 1)[1])
    assert app.wait_idle(60) and app.scene.name == "ISB"
    stop.set()
    th.join(30)
    assert not th.is_alive() and box["rc"] == 0
    assert _port_free(port)


def test_fit_pool_order_priorities_and_keep():
    cond = threading.Condition()
    done: list = []
    pool = FitPool(cond, lambda key, prio: done.append((key, prio)), threads=1)
    gate = threading.Event()
    order: list = []
    try:
        pool.submit("blocker", lambda: (gate.wait(10), order.append("blocker")), 0)
        t0 = time.monotonic()
        while "blocker" not in pool.running and time.monotonic() - t0 < 10:
            time.sleep(0.01)
        pool.submit("sweep-cheap", lambda: order.append("sweep-cheap"), 1, cost=0.1)
        pool.submit("main-dear", lambda: order.append("main-dear"), 0, cost=5.0)
        pool.submit("main-cheap", lambda: order.append("main-cheap"), 0, cost=0.1)
        pool.submit("dropped", lambda: order.append("dropped"), 0, cost=0.0)
        pool.submit("main-cheap", lambda: order.append("twice"), 0)  # already queued: ignored
        pool.keep({"sweep-cheap", "main-dear", "main-cheap"})
        assert pool.is_pending("main-dear") and not pool.is_pending("dropped")
        gate.set()
        pool.wait_for(["sweep-cheap"], time.monotonic() + 10)
    finally:
        pool.close()
    # priority first, then expected cost; a dropped job never runs
    assert order == ["blocker", "main-cheap", "main-dear", "sweep-cheap"]
    assert [k for k, _ in done] == order and not pool.busy


# ------------------------------------------------------- issue 16: maps, picks, sources
def test_a_point_picked_in_a_map_is_selected_in_the_3d_view(server):
    app = make_app(server)
    app.handles["color_method"].value = "toy_bisect"
    s = app.settings()
    scps = app.model.scps(s)
    i = 1234
    app.handles["pick"].value = f"scp {i}"  # what a click on that point of a residual map types
    assert app.handles["sel_mode"].value == "picked SCP"
    sel = app.selection
    np.testing.assert_array_equal(sel.ground, scps.ground[i])
    assert (sel.exact_row, sel.exact_col) == (scps.row[i], scps.col[i])
    np.testing.assert_allclose(app.nodes["/selected/point"].position, app.frame.ground(scps.ground[i][None])[0],
                               atol=1e-5)
    # its search trace converges on its exact row; the ray goes to that scanline's perspective centre
    assert abs(sel.trace_rows[-1] - scps.row[i]) < 1e-6
    centre = app.scene.exterior.position(app.scene.scanline_time(np.array([scps.row[i]])))
    np.testing.assert_allclose(app.nodes["/selected/ray"].points[0][1], app.frame.sensor(centre)[0], atol=1e-4)
    assert f"SCP {i}" in app.handles["sel_text"].content
    # the maps carry the SCP index a click sends
    (tr,) = [t for t in app.handles["maps"].figure.data if t.name == "toy_bisect row"]
    assert i in np.asarray(tr.customdata)[..., 1]


def test_row_column_difference_and_colour_mode_controls_reach_the_maps(server):
    app = make_app(server)
    app.handles["component"].value = "row and column"
    app.handles["diff_a"].value = "toy_poly"
    app.handles["diff_b"].value = "toy_bisect"
    fig = app.handles["maps"].figure
    names = [t.name for t in fig.data if t.showlegend is False and not t.name.startswith("SCOPs")]
    assert names == ["toy_poly row", "toy_poly column", "toy_bisect row", "toy_bisect column",
                     "toy_poly minus toy_bisect (row)"]
    app.handles["colour_mode"].value = "log magnitude"
    fig = app.handles["maps"].figure
    assert fig.layout.meta["mode"] == "log magnitude" and "log" in fig.layout.coloraxis.colorbar.title.text
    app.handles["show_scops"].value = False
    assert not [t for t in app.handles["maps"].figure.data if t.name.startswith("SCOPs")]


def test_plotly_panels_have_no_share_to_cloud_button(server):
    app = make_app(server)
    import json

    for key in ("maps", "timing", "accuracy"):
        cfg = json.loads(app.handles[key]._plotly_json_str)["config"]
        assert cfg["showSendToCloud"] is False and "sendDataToCloud" in cfg["modeBarButtonsToRemove"]


def test_a_loaded_scene_is_named_and_the_preset_dropdown_still_switches(server, tmp_path):
    from explorer.presets import build_scene
    from explorer.sources import load_source

    path = tmp_path / "my_sensor.json"
    build_scene("ISB", relief_m=500.0).save(path)
    src = load_source("scene", str(path))
    app = make_app(server, sources=[src])
    assert app.handles["preset"].value == src.label and app.handles["preset"].options[0] == src.label
    assert app.scene is src.scene and app.handles["relief"].disabled  # preset sliders do not apply
    assert src.label in html.unescape(app.handles["status"].content)  # Markdown: "_" as an entity
    pose = app.camera_pose
    app.handles["preset"].value = "WSU"
    assert app.scene.name == "WSU" and not app.handles["relief"].disabled
    assert app.camera_pose != pose  # reframed on the new footprint
    assert tuple(server.initial_camera.position) == pytest.approx(app.camera_pose[0])


def test_gui_export_is_every_point_and_reproducible(server):
    import io
    import zipfile

    app = make_app(server)
    a, b = app.export_bytes(), app.export_bytes()
    za, zb = zipfile.ZipFile(io.BytesIO(a)), zipfile.ZipFile(io.BytesIO(b))
    assert sorted(za.namelist()) == ["panels.html", "residuals.csv", "summary.json", "timing.js", "timing.json"]
    from explorer.app.export import RUN_DEPENDENT

    for name in za.namelist():  # every file but the measured times, byte for byte
        if name not in RUN_DEPENDENT:
            assert za.read(name) == zb.read(name), name
    rows = za.read("residuals.csv").decode().splitlines()
    n = len(app.model.scps(app.settings()))
    assert rows[0].startswith("method,scp_index,row_px,col_px,row_residual_px,col_residual_px")
    assert sum(r.startswith("toy_bisect,") for r in rows) == n
    import json

    summary = json.loads(za.read("summary.json"))
    assert summary["methods"]["toy_bisect"]["n_valid"] + summary["methods"]["toy_bisect"]["n_invalid"] == n
    assert summary["settings"]["subsampled"] is False
    assert sorted(summary["run_dependent"]) == ["timing.js", "timing.json"]
    timing = json.loads(za.read("timing.json"))["methods"]
    assert timing["toy_bisect"]["n_evaluated"] == n and timing["toy_bisect"]["eval_s"] > 0


def test_gui_export_with_the_sweep_equals_a_fresh_export(server):
    """The GUI's zip reuses the GUI's own fits (maps and accuracy-vs-SCOPs sweep); its files are byte for byte
    those of an export that fits everything afresh (the CLI's path), but the measured times."""
    import io
    import zipfile

    from explorer.app.export import RUN_DEPENDENT, export_files

    app = make_app(server, sweep=True)
    s = app.settings()
    assert s.sweep
    gui = zipfile.ZipFile(io.BytesIO(app.export_bytes()))
    fresh = export_files(app.model.scene(s), s, source=app._source_info(s), seed=app.model.seed)
    assert sorted(gui.namelist()) == sorted(fresh)
    for name, data in fresh.items():
        if name not in RUN_DEPENDENT:
            assert gui.read(name) == data, name
    import json

    sweep = json.loads(fresh["summary.json"])["accuracy_vs_scops"]
    assert [e["n_scops"] for e in sweep["toy_poly"]] == list(SCOP_DENSITIES) and len(sweep["toy_bisect"]) == 1
    assert "Accuracy vs SCOP density" in fresh["panels.html"].decode()


def test_slider_drag_is_debounced_to_the_last_value(server):
    app = make_app(server, methods=("toy_poly",), background=True, debounce_s=0.25)
    try:
        assert app.wait_idle(60)
        built = app.model.counters["scene"]
        for relief in range(100, 2001, 100):  # a drag: 20 values, one every 20 ms
            app.handles["relief"].value = relief
            time.sleep(0.02)
        assert app.wait_idle(60)
        assert app.settings().relief_m == 2000.0 and app.scene.terrain.max_height > app.scene.terrain.min_height
        assert app.model.counters["scene"] - built <= 2  # not 20 queued rebuilds
        assert f"{app.scene.name}" in app.handles["status"].content
    finally:
        app.close()


def test_model_layer_imports_neither_viser_nor_plotly():
    import subprocess
    import sys

    code = ("import sys; import explorer.app, explorer.sources; from explorer.app import model, export, jobs; "
            "print(sorted(m for m in ('viser', 'plotly') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_reset_view_frames_every_client_on_the_footprint(server):
    """Issue 24: every browser's camera is framed for its own canvas (the aspect it reported) so the footprint
    fills at least half of the view -- checked by projecting the footprint corners through the pose."""
    from explorer.scene3d.camera import DEFAULT_ASPECT, VIEW_FOV_Y, footprint_share, view_ndc

    class Camera:
        far = near = look_at = position = None

        def __init__(self, width: int, height: int) -> None:
            self.image_width, self.image_height, self.fov = width, height, VIEW_FOV_Y

    class Client:
        def __init__(self, cid: int, width: int, height: int) -> None:
            self.client_id, self.camera = cid, Camera(width, height)

        def atomic(self):
            return contextlib.nullcontext()

    app = make_app(server)
    clients = {1: Client(1, 512, 900), 2: Client(2, 1600, 900), 3: Client(3, 0, 0)}  # 3: not reported yet
    server.get_clients = lambda: clients  # three browsers looking elsewhere
    app.reset_view()
    corners = app.frame.ground(np.asarray(app.scene.footprint(), dtype=np.float64))
    for c, aspect in ((clients[1], 512 / 900), (clients[2], 1600 / 900), (clients[3], DEFAULT_ASPECT)):
        assert (c.camera.position, c.camera.look_at, c.camera.far, c.camera.near) == app.client_poses[c.client_id]
        ndc, depth = view_ndc(corners, np.array(c.camera.position), np.array(c.camera.look_at), aspect=aspect)
        assert np.all(depth > 0) and np.all(np.abs(ndc) < 0.9)  # the whole footprint, inside the view
        assert max(np.ptp(ndc, axis=0)) / 2 >= 0.5  # and at least half of it along the binding axis
    assert clients[1].camera.position != clients[2].camera.position  # each canvas its own pose
    # the default pose (new browsers) is the one for the default canvas
    pos, look, far = app.camera_pose
    assert (pos, look, far) == app.client_poses[3][:3]

    class Pose:  # footprint_share on the default pose
        position, look_at, fov_y, aspect = np.array(pos), np.array(look), VIEW_FOV_Y, DEFAULT_ASPECT

    assert max(footprint_share(corners, Pose)) >= 0.5


class _FakeBrowserCamera:
    """A browser's camera as the app sees it: what it *reports* (``reported``) kept apart from what the app sends it
    (``received``, in order); a 1400 x 900 canvas (before the panels dock) at the server's initial camera."""

    def __init__(self, pos0, look0) -> None:
        from explorer.scene3d.camera import VIEW_FOV_Y

        self.image_width, self.image_height, self.fov = 1400, 900, VIEW_FOV_Y
        self.reported = {"position": np.array(pos0), "look_at": np.array(look0)}
        self.received: list[tuple] = []
        self.far = self.near = None

    position = property(lambda self: self.reported["position"],
                        lambda self, v: self.received.append(("position", tuple(v))))
    look_at = property(lambda self: self.reported["look_at"],
                       lambda self, v: self.received.append(("look_at", tuple(v))))


def test_two_camera_reports_at_once_leave_the_browser_at_the_pose_recorded_for_it(server):
    """Issue 24 (a CTX ISD's browser test failed under load): viser runs each camera report's callback in a pool
    thread of its own. The call for the first report (the wide canvas, before the panels docked) computes its
    pose; the call for the next report (the docked canvas) runs meanwhile. The browser must end at the pose the
    app recorded for it, framed for the docked canvas: interleaved, the docked pose went out first and the wide
    one last, and a young browser at neither pose was never framed again. A fake browser: what it receives is
    kept apart from what it reports."""
    from explorer.scene3d.camera import VIEW_FOV_Y, frame_footprint

    app = make_app(server)
    pos0, look0, _ = app.camera_pose
    in_first, second_sent = threading.Event(), threading.Event()

    class Client:
        client_id = 7

        def __init__(self) -> None:
            self.camera, self.calls = _FakeBrowserCamera(pos0, look0), 0

        @contextlib.contextmanager
        def atomic(self):
            self.calls += 1
            if self.calls == 1:  # the first report's call, its pose computed: the second report's call runs now
                in_first.set()
                second_sent.wait(2.0)  # (serialised, it cannot send before this one: wait no longer than that)
            yield
            if self.calls >= 2:
                second_sent.set()

    client = Client()
    server.get_clients = lambda: {7: client}
    app._client_since[7] = time.monotonic()  # just connected
    first = threading.Thread(target=app._client_camera_reported, args=(client,))
    first.start()
    assert in_first.wait(30)
    client.camera.image_width = 512  # the panels docked: the next report, still at the initial camera
    second = threading.Thread(target=app._client_camera_reported, args=(client,))
    second.start()
    first.join(30)
    second.join(30)
    assert not first.is_alive() and not second.is_alive()
    # the truth: the footprint framed for the docked canvas, computed here from the app's framing
    ground, track, _ = app._framing
    want = frame_footprint(ground, track, aspect=512 / 900, fov_y=VIEW_FOV_Y)
    sent = dict(client.camera.received[-2:])  # the last pose the browser received
    assert np.allclose(sent["position"], want.position) and np.allclose(sent["look_at"], want.look_at)
    assert np.allclose(app.client_poses[7][0], want.position)  # the pose recorded as this browser's
    assert app._framed_clients[7][1] == pytest.approx(512 / 900)
    # and the browser, now reporting that pose for that canvas, is left there
    client.camera.reported = {"position": np.array(sent["position"]), "look_at": np.array(sent["look_at"])}
    n = len(client.camera.received)
    app._client_camera_reported(client)
    assert len(client.camera.received) == n


def test_a_browser_that_applied_an_earlier_framing_last_is_framed_again_a_moved_one_is_not(server):
    """Issue 24 (the default preset's browser test failed in a CI run at low load): the browser ended at the pose
    framed for its wide canvas before the panels docked, after the docked canvas's pose -- the one the app recorded
    for it.  A report at a pose the app sent it EARLIER is a stale framing, not a user's move: it is framed again
    for its canvas.  A report anywhere else (the user moved the camera) is left alone.  Fake browser, the truth
    computed here with ``frame_footprint``."""
    from explorer.scene3d.camera import VIEW_FOV_Y, frame_footprint

    app = make_app(server)
    pos0, look0, _ = app.camera_pose

    class Client:
        client_id = 8

        def __init__(self) -> None:
            self.camera = _FakeBrowserCamera(pos0, look0)

        @contextlib.contextmanager
        def atomic(self):
            yield

    client = Client()
    server.get_clients = lambda: {8: client}
    ground, track, _ = app._framing
    wide = frame_footprint(ground, track, aspect=1400 / 900, fov_y=VIEW_FOV_Y)
    docked = frame_footprint(ground, track, aspect=512 / 900, fov_y=VIEW_FOV_Y)
    app._client_since[8] = time.monotonic() - 60  # long connected: only the stale-framing rule can reframe it
    app._client_camera_reported(client)  # the first report: framed for the wide canvas
    assert np.allclose(dict(client.camera.received[-2:])["position"], wide.position)
    client.camera.image_width = 512
    app._client_camera_reported(client)  # docked, still at the initial camera: framed for the docked canvas
    assert np.allclose(dict(client.camera.received[-2:])["position"], docked.position)
    # the wide framing applied last: the browser reports it with the docked canvas -> framed again (docked)
    client.camera.reported = {"position": np.array(wide.position), "look_at": np.array(wide.look_at)}
    n = len(client.camera.received)
    app._client_camera_reported(client)
    assert len(client.camera.received) > n
    assert np.allclose(dict(client.camera.received[-2:])["position"], docked.position)
    # the user moves the camera (a pose the app never sent): left alone
    client.camera.reported = {"position": np.array(docked.position) * 1.3 + 0.1,
                              "look_at": np.array(docked.look_at)}
    n = len(client.camera.received)
    app._client_camera_reported(client)
    assert len(client.camera.received) == n


def test_controls_reach_the_app_through_its_public_methods_only(server):
    """Issue 23: the controls own their handles and call only the host's public methods (a host that has
    nothing else receives every request)."""
    import contextlib

    from explorer.app.controls import Controls

    class Host:
        def __init__(self) -> None:
            self.calls: list[str] = []
            self._quiet = False

        def request_update(self, *, debounce: bool = True) -> int:
            self.calls.append("update" if not debounce else "debounced update")
            return len(self.calls)

        def reset_view(self) -> None:
            self.calls.append("reset")

        def export_to_client(self, client=None) -> None:
            self.calls.append("export")

        @contextlib.contextmanager
        def quiet(self):
            old, self._quiet = self._quiet, True
            try:
                yield
            finally:
                self._quiet = old

        def is_quiet(self) -> bool:
            return self._quiet

    host = Host()
    c = Controls(host, server.gui, scene_ids=["WSU"], scene_id="WSU", scp_count=1000, scop_density=30, sweep=False)
    c.handles["relief"].value = 200  # a slider: debounced
    c.handles["density"].value = "50"  # a dropdown: at once
    assert host.calls == ["debounced update", "update"]
    with host.quiet():
        c.handles["relief"].value = 300
    assert host.calls == ["debounced update", "update"]
    c.handles["pick"].value = "scp 12"
    assert c.pick_index() == 12 and c.handles["sel_mode"].value == "picked SCP" and host.calls[-1] == "update"
    c.add_method_boxes(["a", "b"], ["b"], lambda n: n)
    assert c.checked_methods() == ["b"]
    c.set_method_options(c.checked_methods())
    assert c.handles["color_method"].options == ("b",) and c.handles["diff_a"].options == ("(none)", "b")


def test_a_file_source_shows_its_truth_and_the_stand_in_map(server):
    """An ISD source: the maps measure against the camera itself, and the MPC fitted to it is drawn beside the
    methods' maps as the stand-in (its own error against the camera), named in the notes."""
    import json
    from pathlib import Path

    from explorer.sources import load_source

    isd = Path(__file__).resolve().parent / "data" / "usgscsm" / "orbitalLineScan.json"
    src = load_source("isd", str(isd))
    app = make_app(server, sources=[src], methods=("toy_poly",))
    fig = json.loads(app.handles["maps"]._plotly_json_str)
    titles = " ".join(a.get("text", "") for a in fig["layout"].get("annotations", []))
    assert "stand-in" in titles, titles
    assert "Truth: USGS CSM" in app.handles["maps_note"].content and "stand-in" in app.handles["maps_note"].content


def test_log_lines_of_background_work_name_it(caplog, monkeypatch):
    """Issue 24: a fit's log line says which work it comes from (the sweep, or the maps)."""
    import logging

    from explorer import _log
    from explorer.app.model import SWEEP_PURPOSE

    class ToyLogs(ToyPoly):
        name = "toy_logs"

        def _fit(self, control: PointSet) -> None:
            super()._fit(control)
            _log.warn("toy_logs: training did not reach its accuracy goal")

    monkeypatch.setitem(methods_base._REGISTRY, ToyLogs.name, ToyLogs)
    model = ExplorerModel()
    s = Settings(preset="WSU", scop_density=30, scp_count=1000, methods=("toy_logs",))
    with caplog.at_level(logging.WARNING, logger="explorer"):
        model.fit("toy_logs", s, 30, purpose=SWEEP_PURPOSE)
        model.fit("toy_logs", s, 50)
    msgs = [r.getMessage() for r in caplog.records if r.name == "explorer"]
    assert msgs == ["[accuracy-vs-SCOPs sweep, 30 SCOPs] toy_logs: training did not reach its accuracy goal",
                    "[maps, 50 SCOPs] toy_logs: training did not reach its accuracy goal"]


def test_an_rpc_source_runs_the_learned_methods_and_says_why_a_search_is_unavailable(server):
    """Issue 23: ``explore --rpc`` measures against the RPC itself; a search method (no scanlines on an RPC) is
    listed unavailable with the reason in the summary panel and the status line, never run on a hidden MPC; the 3D
    view draws an MPC fitted to the RPC and says so."""
    from explorer.sources import load_source
    from tests.rpc.conftest import RPC_DIR

    src = load_source("rpc", str(RPC_DIR / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML"))
    app = make_app(server, sources=[src], methods=("lrm", "toy_bisect"), scp_count=2000)
    assert app.errors == [] and app.scene is src.scene
    summary = app.handles["summary"].content
    assert "| toy_bisect | - | - | - | unavailable |" in summary and "searches the scanlines" in summary
    assert "--as-mpc" in summary and "| lrm |" in summary
    assert "unavailable on this sensor" in app.handles["status"].content and "failed" not in app.handles[
        "status"].content
    run = app.runs["lrm"]
    assert run.ok and run.evaluation.n_evaluated == len(app.model.scps(app.settings()))
    assert "/orbit/track" in app.nodes and "an MPC fitted to its lines of sight" in app.handles["cloud_text"].content
    box = app.handles["method_boxes"]["toy_bisect"]  # the method list says it too, with the reason as the hint
    assert box.label == "toy_bisect (unavailable here)" and "searches the scanlines" in box.hint
    assert app.handles["method_boxes"]["lrm"].label == "lrm"
    app.handles["preset"].value = "WSU"  # a scene with scanlines: the label and hint come back
    assert box.label == "toy_bisect" and "searches the scanlines" not in box.hint


@pytest.mark.parametrize("preset", ["WSU", "ISB"])
def test_3d_labels_are_inside_the_framed_view_and_apart(server, preset):
    """Issue 24: in the framed view of the default canvas every shown 3D label lies inside the view and clear of
    the others (boxes recomputed here from each label's anchor, text and point through the camera model); a
    label that would not be is hidden; the three scanlines' and the selected point's labels are shown."""
    import itertools

    from explorer.scene3d.camera import DEFAULT_CANVAS_PX, VIEW_FOV_Y, view_ndc
    from explorer.scene3d.labels import box_at, boxes_overlap, label_box_px

    app = make_app(server, preset=preset)
    w, h = DEFAULT_CANVAS_PX
    pos, look, _ = app.camera_pose
    boxes = {}
    for key, node in app.nodes.items():
        if not (hasattr(node, "anchor") and hasattr(node, "text")):
            continue
        if not node.visible:
            assert app.label_layout[key] is None
            continue
        ndc, depth = view_ndc(np.asarray(node.position)[None], np.array(pos), np.array(look), fov_y=VIEW_FOV_Y,
                              aspect=w / h)
        assert depth[0] > 0
        p = np.array([(ndc[0, 0] + 1) * w / 2, (1 - ndc[0, 1]) * h / 2])
        boxes[key] = b = box_at(p, label_box_px(node.text, node.font_screen_scale), node.anchor)
        assert b[0] >= 0 and b[1] >= 0 and b[2] <= w and b[3] <= h, (key, b)
    assert {"/selected/label", "/scanlines/labels/0", "/scanlines/labels/1", "/scanlines/labels/2"} <= set(boxes)
    for a, b in itertools.combinations(boxes, 2):
        assert not boxes_overlap(boxes[a], boxes[b]), (a, boxes[a], b, boxes[b])
    # a scanline's label stands at one end of its ground trace
    scene = app.scene
    for i, row in ((0, 0.0), (2, scene.n_rows - 1.0)):
        ends = app.frame.ground(app._B.scanline_footprints(scene, np.array([row]), scene.terrain.mean_height)[0])
        at = np.asarray(app.nodes[f"/scanlines/labels/{i}"].position)
        assert min(np.linalg.norm(ends - at, axis=1)) < 1e-5


def test_status_line_shortens_a_long_name_and_gives_it_whole_in_a_tooltip(server, tmp_path):
    """Issue 24: a long file name is shortened in the status line, its start and end kept, the full name in a
    tooltip (an HTML title attribute; viser's Markdown passes HTML through); Markdown characters in it are
    literal."""
    import re

    from explorer.app.views import STATUS_NAME_CHARS
    from explorer.presets import build_scene
    from explorer.sources import load_source

    path = tmp_path / "PHR1B_P_201709281038045_SEN_PRG_FC_178608-001_a_very_long_delivery_name.json"
    build_scene("WSU").save(path)
    src = load_source("scene", str(path))
    assert len(src.label) > STATUS_NAME_CHARS
    app = make_app(server, sources=[src])
    content = app.handles["status"].content
    m = re.search(r'<span title="([^"]*)">(.*?)</span>', content)
    assert m is not None and html.unescape(m.group(1)) == src.label
    shown = html.unescape(m.group(2))
    assert len(shown) == STATUS_NAME_CHARS and "\u2026" in shown
    head, tail = shown.split("\u2026")
    assert src.label.startswith(head) and src.label.endswith(tail) and len(head) > 20 and len(tail) > 10
    assert "_" not in m.group(2) and "&#95;" in m.group(2)  # no emphasis from the name's underscores
    assert src.label in app.handles["preset"].hint  # the Scene dropdown's tooltip names it whole too
    app.handles["preset"].value = "WSU"  # a short name: as it is, no tooltip
    assert app.handles["status"].content.startswith("**Status:** WSU: updated in") and "<span" not in \
        app.handles["status"].content


def test_status_line_times_the_whole_update_from_the_change(server):
    """Issue 24: the status line's time runs from the user's change (a slider: its debounce included) to the
    scene and maps shown, not only the last redraw -- checked against the test's own stopwatch."""
    import re

    app = make_app(server, methods=("toy_poly",), background=True, debounce_s=0.4)
    try:
        assert app.wait_idle(60)
        t0 = time.monotonic()
        app.handles["relief"].value = 700  # a slider: computed once it has been still for debounce_s
        assert app.wait_idle(60)
        elapsed = time.monotonic() - t0
        m = re.search(r"updated in ([0-9.]+) s", app.handles["status"].content)
        assert m is not None and app.settings().relief_m == 700.0
        whole = float(m.group(1))
        assert 0.4 <= whole <= elapsed + 0.01  # the debounce wait is part of it; nothing before the change
        assert whole >= app.last_times["total"] + 0.39  # more than the redraw alone
    finally:
        app.close()


def test_the_height_exaggeration_is_written_in_the_3d_view(server):
    """Issue 24: relief exaggerated automatically (the factor of auto_height_exaggeration) and the factor written
    in the 3D view itself, at a corner of the footprint, laid out with the other labels; none on flat ground."""
    from explorer.scene3d.builders import auto_height_exaggeration

    app = make_app(server)
    assert "/ground/note" not in app.nodes  # WSU is flat: nothing exaggerated
    app.handles["preset"].value = "SCB"  # a wide footprint (the relief slider's 100 m are ~1 % of it)
    app.handles["relief"].value = 100
    factor, relief = auto_height_exaggeration(app.scene)
    assert factor > 1 and relief > 100
    note = app.nodes["/ground/note"]
    assert note.text == f"heights x{factor:g} (auto)" and note.visible and app.label_layout["/ground/note"] is not None
    assert app.frame.height_exaggeration == factor
    corners = app.frame.ground(app._B.footprint_corners(app.scene))
    assert min(np.linalg.norm(corners - np.asarray(note.position), axis=1)) < 1e-5
    app.handles["exaggeration"].value = 5.0  # by hand: the automatic one is off, the note says the new factor
    assert app.nodes["/ground/note"].text == "heights x5" and app.frame.height_exaggeration == 5.0


def test_the_dem_mesh_does_not_cut_through_the_check_points_markers(server):
    """Issue 24: the check points' markers tile the footprint (drawn SCP_COVER * VISER_POINT_SCALE spacings wide,
    more than the sqrt(2) a grid needs); the DEM mesh under them, which cut through each marker (a marker is drawn
    at its centre's depth) and striped the residual colours, is not drawn."""
    from explorer.scene3d.builders import SCP_COVER, VISER_POINT_SCALE

    assert SCP_COVER * VISER_POINT_SCALE >= 2 ** 0.5
    app = make_app(server, preset="SCB")
    app.handles["relief"].value = 300
    assert app.scene.terrain.max_height > app.scene.terrain.min_height
    assert "/ground/surface" in app.nodes and not app.nodes["/ground/surface"].visible
    assert app.nodes["/ground/outline"].visible and app.nodes["/points/scps"].visible
    size = app._B.point_size_km(app.frame, len(app.cloud_index), SCP_COVER)
    assert app.nodes["/points/scps"].point_size == pytest.approx(size)


def test_as_mpc_maps_name_the_stand_in_they_are_measured_against(server):
    """Issue 23: with ``--as-mpc`` every method runs on the resected MPC and is measured against it, so each
    method's map title says so (the RPC-vs-MPC map beside them is the stand-in's own error)."""
    import json

    from explorer.evaluate import STAND_IN_METHOD
    from explorer.sources import load_source
    from tests.rpc.conftest import RPC_DIR

    src = load_source("rpc", str(RPC_DIR / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML"), as_mpc=True)
    app = make_app(server, sources=[src], methods=("toy_poly",), scp_count=2000)
    assert app.errors == []
    fig = json.loads(app.handles["maps"]._plotly_json_str)
    titles = [a.get("text", "") for a in fig["layout"].get("annotations", []) if " px<br>" in a.get("text", "")]
    method_titles = [t for t in titles if t.startswith("toy_poly")]
    assert method_titles and all(t.endswith("; against the STAND-IN MPC (--as-mpc))") for t in method_titles)
    stand_in = [t for t in titles if t.startswith(f"{STAND_IN_METHOD}:")]
    assert stand_in and not any(t.endswith("(--as-mpc))") for t in stand_in), titles


def test_a_browser_whose_only_camera_report_is_its_first_is_framed(server):
    """Issue 24 (browser tests in CI: a wide window's browser never framed, at the server's initial camera).
    viser counts a browser as connected on its first camera report, runs a plain connect callback in its thread
    pool and at once hands that report to the camera callbacks registered so far. When the pool has an idle
    thread (a server that has served browsers before) the report went out before the app's callback was
    registered, and a browser whose canvas never changes shape sends no other. Clients speaking viser's
    websocket protocol (no browser) each send exactly one camera report, one after another; each must be
    framed for its canvas -- the truth: the footprint framed by :func:`explorer.scene3d.camera.frame_footprint`
    for the reported aspect."""
    import msgspec
    from websockets.sync.client import connect

    from explorer.scene3d.camera import VIEW_FOV_Y, frame_footprint

    app = make_app(server)
    pos0, look0, _ = app.camera_pose
    ground, track, _ = app._framing
    for width in (1400, 1800, 1200):  # the later browsers find idle threads in viser's pool
        report = {"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0], "position": [float(v) for v in pos0],
                  "fov": float(VIEW_FOV_Y), "near": 0.001, "far": 5000.0, "image_height": 900,
                  "image_width": width, "look_at": [float(v) for v in look0], "up_direction": [0.0, 0.0, 1.0]}
        before = set(app.client_poses)
        with connect(f"ws://127.0.0.1:{server.get_port()}", subprotocols=[f"viser-v{viser.__version__}"],
                     max_size=None) as ws:
            ws.send(msgspec.msgpack.encode(report))
            t0 = time.monotonic()
            while time.monotonic() - t0 < 10 and not set(app.client_poses) - before:  # set once framed
                with contextlib.suppress(TimeoutError):
                    ws.recv(timeout=0.1)  # keep reading what the server sends
            new = set(app.client_poses) - before
            assert new, f"the browser with a {width} x 900 canvas was never framed"
            (cid,) = new
            want = frame_footprint(ground, track, aspect=width / 900, fov_y=VIEW_FOV_Y)
            assert app._framed_clients[cid][1] == pytest.approx(width / 900)
            assert np.allclose(app.client_poses[cid][0], want.position)
            assert np.allclose(app.client_poses[cid][1], want.look_at)
