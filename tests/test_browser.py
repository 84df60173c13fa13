"""The explorer in a real browser: headless Debian Chromium through Playwright.

Starts the explorer (``serve``) on a free port in a thread, opens it in one and then two
browser clients, checks the 3D canvas is drawn (pixel variance, the residual colours
present) and the Plotly residual panel is shown, then stops the server and checks the
thread ended and the port is free.  Skipped without /usr/bin/chromium.
"""

from __future__ import annotations

import io
import os
import socket
import threading
import time

import numpy as np
import pytest

CHROMIUM = "/usr/bin/chromium"
pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(not os.path.exists(CHROMIUM), reason="needs Debian chromium at /usr/bin/chromium"),
]
sync_api = pytest.importorskip("playwright.sync_api")
Image = pytest.importorskip("PIL.Image")

from explorer.app import serve  # noqa: E402
from explorer.panels import NEGATIVE_END, POSITIVE_END  # noqa: E402
from tests.test_app import toy_registry  # noqa: E402

ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-quic",
        "--no-first-run", "--disable-component-update", "--disable-sync"]
TIMEOUT_MS = 240_000
BIG_CANVAS = "() => Array.from(document.querySelectorAll('canvas')).some(c => c.width > 300 && c.height > 300)"


@pytest.fixture(scope="module")
def explorer():
    with toy_registry():
        box: dict = {}
        stop = threading.Event()

        def run() -> None:
            box["rc"] = serve("WSU", port=0, methods=["toy_poly", "toy_bisect"], stop_event=stop,
                              ready=lambda a: box.setdefault("app", a), scp_count=3000, sweep=False)

        th = threading.Thread(target=run, daemon=True)
        th.start()
        t0 = time.monotonic()
        while "app" not in box and th.is_alive() and time.monotonic() - t0 < 120:
            time.sleep(0.05)
        app = box["app"]
        app.handles["limit"].value = "0.01"  # toy_poly's residuals reach both ends of the scale
        assert app.wait_idle(120)
        yield app
        stop.set()
        th.join(60)
        box["thread"] = th
        assert not th.is_alive(), "the explorer thread did not stop"
        assert box["rc"] == 0
        port = int(app.url.rsplit(":", 1)[1])
        with pytest.raises(ConnectionRefusedError):  # nobody listens any more
            socket.create_connection(("127.0.0.1", port), timeout=5).close()
        with socket.socket() as s:  # and the port can be bound again (closed connections
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # may linger in TIME_WAIT)
            s.bind(("127.0.0.1", port))


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


def _open(browser, url: str):
    page = browser.new_context(viewport={"width": 1400, "height": 900}).new_page()
    page.set_default_timeout(TIMEOUT_MS)  # software WebGL on a busy machine is slow
    page.goto(url)
    page.wait_for_function(BIG_CANVAS)
    page.wait_for_selector(".js-plotly-plot")
    return page


RECT_3D = """() => {
  let best = null, area = 0;
  for (const c of document.querySelectorAll('canvas')) {
    const r = c.getBoundingClientRect();
    if (r.width * r.height > area) { area = r.width * r.height; best = r; }
  }
  return {x: best.x, y: best.y, width: best.width, height: best.height};
}"""


def _canvas_pixels(page) -> np.ndarray:
    rect = page.evaluate(RECT_3D)  # the 3D view is the largest canvas
    png = page.screenshot(clip=rect)
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int16)


def _wait_drawn(page, timeout: float = 120.0) -> np.ndarray:
    """Screenshots of the 3D canvas until the scene's residual colours show up."""
    end = time.monotonic() + timeout
    while True:
        px = _canvas_pixels(page)
        near = [np.abs(px - np.array(c)).sum(axis=2).min() for c in (POSITIVE_END, NEGATIVE_END)]
        if max(near) < 40 or time.monotonic() > end:
            return px
        time.sleep(1.0)


def test_scene_and_panel_render_in_two_clients(explorer, browser, tmp_path):
    page1 = _open(browser, explorer.url)
    px = _wait_drawn(page1)
    page1.screenshot(path=str(tmp_path / "explorer.png"))
    assert px.reshape(-1, 3).std(axis=0).max() > 10.0, "the 3D canvas is blank"
    for end in (POSITIVE_END, NEGATIVE_END):  # SCPs drawn in the residual colours
        assert np.abs(px - np.array(end)).sum(axis=2).min() < 40
    plot_text = page1.locator(".js-plotly-plot").first.inner_text()
    assert "toy_poly: RMSE" in plot_text and "toy_bisect: RMSE" in plot_text
    assert page1.get_by_text("Residual maps").count() >= 1

    page2 = _open(browser, explorer.url)
    px2 = _wait_drawn(page2)
    assert px2.reshape(-1, 3).std(axis=0).max() > 10.0
    assert "toy_poly: RMSE" in page2.locator(".js-plotly-plot").first.inner_text()
    assert len(explorer.server.get_clients()) == 2

    # a change made by one client reaches the other
    explorer.handles["preset"].value = "ISB"
    assert explorer.wait_idle(120)
    for page in (page2, page1):  # the status line names the scene
        page.wait_for_function("() => document.body.innerText.includes('ISB: updated')")
    for page in (page1, page2):
        page.context.close()
