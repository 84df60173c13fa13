"""``explore SOURCE --gcps`` in a real browser (headless Debian Chromium through Playwright, network blocked):
the Refinement folder shows the residual quiver, the parameter table and the trajectory panel, the 3D scene
draws the original and the adjusted trajectories, and dropping a point in the browser re-adjusts.

Sources: an MPC scene file (``--scene``) and the 2017 Pleiades DIMAP file (``--dimap``: refined through its MPC
stand-in until its own differentiable model lands).  The control points are the sensor's own projections of
seeded ground points plus a known bias and 0.3 px noise.  Skipped without /usr/bin/chromium.
"""

from __future__ import annotations

import io
import os
import threading
import time
from argparse import Namespace
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = "/usr/bin/chromium"
pytestmark = [
    pytest.mark.browser,
    pytest.mark.slow,
    pytest.mark.skipif(not os.path.exists(CHROMIUM), reason="needs Debian chromium at /usr/bin/chromium"),
]
sync_api = pytest.importorskip("playwright.sync_api")
Image = pytest.importorskip("PIL.Image")
pytest.importorskip("torch")

from explorer.app import serve  # noqa: E402
from explorer.app.server import _refine_folder  # noqa: E402
from explorer.refine.points_io import PointTable  # noqa: E402
from explorer.scene3d.refine import ADJUSTED_RGB  # noqa: E402
from explorer.sources import load_source  # noqa: E402
from tests.refine.cases import write_points_csv  # noqa: E402
from tests.test_browser import RECT_3D, _check_framing_and_labels, _restore, _show_only, drawn_change  # noqa: E402

ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-quic",
        "--no-first-run", "--disable-component-update", "--disable-sync"]
TIMEOUT_MS = 240_000
PHR_2017 = Path(__file__).resolve().parent / "data" / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML"
BIAS = np.array([3.0, -2.0])  # rows, columns added to the sensor's projection


def _control(sensor, n: int, seed: int, prefix: str) -> PointTable:
    """``n`` seeded ground points seen by ``sensor`` (on heights over +-200 m), measured at the sensor's own
    pixels plus :data:`BIAS` plus 0.3 px Gaussian noise."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.05, 0.95, n) * sensor.n_rows
    c = rng.uniform(0.05, 0.95, n) * sensor.n_columns
    g = sensor.image_to_ground(r, c, height=float(sensor.terrain.mean_height) + rng.uniform(-200, 200, n))
    proj = sensor.project(g)
    assert proj.valid.all()
    lon, lat, h = sensor.frame.enu_to_geodetic(g)
    return PointTable([f"{prefix}{i}" for i in range(n)], proj.row + BIAS[0] + rng.normal(0, 0.3, n),
                      proj.col + BIAS[1] + rng.normal(0, 0.3, n), lon, lat, h)


def _serve(source, tmp_path: Path):
    gcps = write_points_csv(tmp_path / "gcps.csv", _control(source.scene, 16, 1, "g"))
    check = write_points_csv(tmp_path / "check.csv", _control(source.scene, 20, 2, "c"))
    args = Namespace(gcps=str(gcps), check=str(check), sigma_px=0.3)
    ready = _refine_folder(args, source)
    box: dict = {}
    stop = threading.Event()

    def on_ready(app) -> None:
        ready(app)
        box["app"] = app

    th = threading.Thread(target=lambda: box.setdefault("rc", serve(
        source.label, port=0, methods=["lrm"], sources=[source], stop_event=stop, ready=on_ready,
        scp_count=2000, sweep=False)), daemon=True)
    th.start()
    t0 = time.monotonic()
    while "app" not in box and th.is_alive() and time.monotonic() - t0 < 240:
        time.sleep(0.1)
    app = box["app"]
    assert app.wait_idle(240)
    return app, stop, th, box


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


def _open(browser, url: str):
    context = browser.new_context(viewport={"width": 1400, "height": 900})  # the default canvas: labels laid out
    context.route("**/*", lambda route: route.continue_() if route.request.url.startswith(url)
                  or route.request.url.startswith(url.replace("http", "ws")) else route.abort())
    page = context.new_page()
    page.set_default_timeout(TIMEOUT_MS)
    page.goto(url)
    page.wait_for_function("() => Array.from(document.querySelectorAll('canvas')).some(c => c.width > 300)")
    return page





def _near_mask(png: bytes, rgb, tol: int = 60) -> np.ndarray:
    """Pixels of a screenshot of the 3D canvas within ``tol`` (sum of |channel differences|) of ``rgb``, the axes
    gizmo in the bottom-left corner left out (its x axis is red)."""
    px = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int16)
    near = np.abs(px - np.array(rgb)).sum(axis=2) < tol
    near[px.shape[0] - 110:, :110] = False
    return near


def _plot_texts(page) -> str:
    return page.evaluate("() => Array.from(document.querySelectorAll('.js-plotly-plot')).map(e => e.innerText)"
                         ".join('\\n')")


def _red_on_screen(app, view, page, shot: Path) -> None:
    """In the default framed view (no camera moved): the adjusted (red) trajectory is drawn on the canvas, where
    viser's camera model puts it.  Only the trajectories shown (the SCPs' residual red would count), then none.

    The screenshots are taken again if the canvas changed shape or the app reframed the browser meanwhile (under
    load the page's panels may still be laying out, and the app frames each canvas shape anew): the pose and the
    rectangle used are those of the screenshot."""
    from explorer.scene3d.camera import view_ndc

    (cid, client), = app.server.get_clients().items()
    for _ in range(5):
        rect, pose = page.evaluate(RECT_3D), app.client_poses[cid]
        full = page.screenshot(clip=rect)
        was = _show_only(app, ("/refine/",))
        try:
            png = drawn_change(page, rect, full)
            _show_only(app, ())
            none = drawn_change(page, rect, png)
        finally:
            _restore(app, was)
        if page.evaluate(RECT_3D) == rect and app.client_poses[cid] == pose:
            break
    else:
        raise AssertionError("the 3D canvas kept changing shape")
    hidden = int(_near_mask(none, ADJUSTED_RGB).sum())
    Image.open(io.BytesIO(png)).save(shot)
    w, h = rect["width"], rect["height"]
    pos, look = np.array(pose[0]), np.array(pose[1])
    # closed form: every point of both tracks is inside this browser's view
    for key in ("/refine/original/track", "/refine/adjusted/track"):
        pts = np.asarray(view._nodes[key].points, dtype=np.float64).reshape(-1, 3)
        ndc, depth = view_ndc(pts, pos, look, fov_y=client.camera.fov, aspect=w / h)
        assert np.all(depth > 0) and np.abs(ndc).max() < 1.0, (key, np.abs(ndc).max())
    red_mask = _near_mask(png, ADJUSTED_RGB)
    red = int(red_mask.sum())
    assert red > hidden + 50, (red, hidden)  # the adjusted trajectory is drawn in the default view
    # where the camera model puts it: the red pixels lie within the projected box of the red track and camera
    # axes (+ the 4 px line width)
    segs = np.concatenate([np.asarray(view._nodes[k].points, dtype=np.float64).reshape(-1, 3)
                           for k in ("/refine/adjusted/track", "/refine/adjusted/attitude")])
    ndc, _ = view_ndc(segs, pos, look, fov_y=client.camera.fov, aspect=w / h)
    x, y = (ndc[:, 0] + 1) * w / 2, (1 - ndc[:, 1]) * h / 2
    ys, xs = np.nonzero(red_mask)
    pad = 4
    assert xs.min() >= max(x.min() - pad, 0) and xs.max() <= x.max() + pad, (xs.min(), xs.max(), x.min(), x.max())
    assert ys.min() >= max(y.min() - pad, 0) and ys.max() <= y.max() + pad, (ys.min(), ys.max(), y.min(), y.max())
    # and over most of that box (the grey original, drawn over it where the two coincide, may hide its ends)
    assert xs.max() - xs.min() >= 0.5 * np.ptp(x) and ys.max() - ys.min() >= 0.5 * np.ptp(y), (xs, ys, x, y)


@pytest.mark.parametrize("kind", ["scene", "dimap"])
def test_explore_gcps_in_the_browser(kind, browser, tmp_path):
    if kind == "scene":
        from explorer.presets import build_scene

        path = tmp_path / "wsu.json"
        build_scene("WSU").save(path)
        source = load_source("scene", str(path))
    else:
        source = load_source("dimap", str(PHR_2017))
    app, stop, th, box = _serve(source, tmp_path)
    try:
        view = app.refine_view
        assert view.error is None and view.has_trajectory
        page = _open(browser, app.url)
        page.wait_for_function("() => document.body.innerText.includes('trajectory moved by')")
        text = _plot_texts(page)
        assert "residuals (measured - model)" in text and "before (vectors" in text  # the quiver
        assert f"the field the {view.refinement.model} adjustment removed" in text  # the removed field
        names = view.refinement.parameter_names  # the parameter table: every parameter with its sigma
        assert all(name in text for name in names) and "sigma" in text, (names, text)
        sigma = f"{view.refinement.parameter_table()[0]['sigma']:.3g}"
        assert sigma in text
        body = page.evaluate("() => document.body.innerText")
        # what is adjusted, stated: the scene itself; the DIMAP model itself or its MPC stand-in (with its distance)
        assert f"Adjusting {view.target.label}." in body
        assert view.target.is_stand_in == ("The stand-in is" in body)
        assert (kind == "scene") <= (view.target.label == "the Scene itself")
        assert "adjusted trajectory (red) vs original (grey)" in body  # the folder states the 3D factors
        _check_framing_and_labels(app, page)  # the footprint framed, every label inside the view and apart
        assert app.label_layout.get("/refine/label") is not None  # the trajectories' label among them
        _red_on_screen(app, view, page, tmp_path / f"refine_{kind}.png")  # the red trajectory in that default view

        # drop a point in the browser: the adjustment re-runs and the parameters change
        before = view.refinement.parameters.copy()
        box_ = page.locator("xpath=//label[text()='Drop point ids']"
                            "/ancestor::div[contains(@class, 'mantine-Flex-root')][1]//input")
        box_.fill("g0, g1")
        box_.press("Enter")
        t0 = time.monotonic()
        while view.refinement.result.outlier.size != 14 and time.monotonic() - t0 < 60:
            time.sleep(0.2)
        assert view.refinement.result.outlier.size == 14
        assert np.abs(view.refinement.parameters - before).max() > 0
        page.wait_for_function("() => document.body.innerText.includes('2 point(s) dropped')")
        page.context.close()
    finally:
        stop.set()
        th.join(60)
    assert box["rc"] == 0
