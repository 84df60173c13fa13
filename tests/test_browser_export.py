"""The exported ``panels.html`` in headless Chromium with the network blocked (issues 23 and 24: the export is the
GUI).

An ``explore --isd`` export of usgscsm's public orbital line-scan ISD (a file source: it has the stand-in map) is
opened from disk with the browser context offline and every non-file request aborted
(:func:`tests.course_pages.check_page`): no request leaves the disk, no JavaScript error, and every panel is drawn
-- the residual maps (the methods' and the stand-in's), the accuracy-vs-SCOPs sweep, the summary table and the
Timing panel.  The Timing panel is filled from ``timing.js`` (the export's run-dependent file): the bars the
browser drew carry the times of ``timing.json``, recomputed here.  The same page copied alone (without
``timing.js``) still draws every panel and says where the times are.
"""

from __future__ import annotations

import json
import os
import shutil

import numpy as np
import pytest

CHROMIUM = "/usr/bin/chromium"
pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(not os.path.exists(CHROMIUM), reason="needs Debian chromium at /usr/bin/chromium"),
]
sync_api = pytest.importorskip("playwright.sync_api")

from explorer.cli import main  # noqa: E402
from tests import course_pages  # noqa: E402
from tests.real.conftest import RPC_DIR  # noqa: E402

ISD = RPC_DIR.parent / "usgscsm" / "orbitalLineScan.json"
METHODS = ["lrm", "prm", "mlp", "exact"]

_TIMING = """() => {
  const gd = Array.from(document.querySelectorAll('.plotly-graph-div')).pop();
  return {fit_y: gd.data[0].y, fit_text: gd.data[0].text, per_y: gd.data[1].y, x: gd.data[0].x,
          bars: gd.querySelectorAll('.bars .point').length,
          notes: (gd.layout.annotations || []).map(a => a.text)};
}"""


@pytest.fixture(scope="module")
def export_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("export") / "isd"
    rc = main(["explore", "--isd", str(ISD), "--methods", ",".join(METHODS), "--scops", "50", "--scps", "3000",
               "--export", str(out)])
    assert rc == 0
    return out


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=course_pages.ARGS)
        yield b
        b.close()


def _open(browser, path):
    """The page offline, network requests recorded; returns (context, page, requests)."""
    context = browser.new_context(viewport={"width": 1300, "height": 900}, offline=True)
    requests: list[str] = []

    def route(r) -> None:
        if r.request.url.startswith(course_pages.LOCAL_SCHEMES):
            r.continue_()
        else:
            requests.append(r.request.url)
            r.abort()

    context.route("**/*", route)
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)[:200]))
    page.goto(path.resolve().as_uri(), wait_until="load")
    page.wait_for_function("() => Array.from(document.querySelectorAll('.plotly-graph-div'))"
                           ".every(gd => gd.querySelectorAll('.main-svg').length > 0)", timeout=60_000)
    page.wait_for_timeout(300)  # the post-scripts run after each figure is drawn
    return context, page, requests, errors


def test_exported_page_draws_every_panel_offline(export_dir, browser):
    report = course_pages.check_page(browser, export_dir / "panels.html")
    assert report.problems() == []  # no network request, every figure drawn, no JavaScript error
    assert report.n_figures == 3  # maps (methods + stand-in), accuracy vs SCOPs, timing
    context, page, requests, errors = _open(browser, export_dir / "panels.html")
    try:
        assert requests == [] and errors == []
        headings = page.eval_on_selector_all("h2", "hs => hs.map(h => h.innerText)")
        assert [h.split(" ")[0] for h in headings] == ["Residual", "Accuracy", "Summary", "Timing"]
        # the maps: one row and one column map per method and for the stand-in, every one a drawn raster
        titles = page.evaluate("() => document.querySelector('.plotly-graph-div').layout.meta.titles")
        for name in METHODS:
            assert any(t.startswith(f"{name} row: RMSE") for t in titles), name
            assert any(t.startswith(f"{name} column: RMSE") for t in titles), name
        assert sum(t.startswith("stand-in: MPC") for t in titles) == 2  # its row and column maps
        assert page.evaluate("() => document.querySelector('.plotly-graph-div')"
                             ".querySelectorAll('.heatmaplayer image, .hm image').length") == 2 * (len(METHODS) + 1)
        # colour bars kept
        assert page.evaluate("() => document.querySelectorAll('.colorbar').length") >= 1
        # the accuracy panel: a trace per method and measure (RMSE, dr_max) with drawn lines
        acc = page.evaluate("() => document.querySelectorAll('.plotly-graph-div')[1].data.map(d => d.name)")
        for name in METHODS:
            assert any(n.startswith(f"{name} RMSE") for n in acc) and any(n.startswith(f"{name} dr_max") for n in acc)
        rows = page.eval_on_selector_all("#summary-table tr", "rs => rs.map(r => r.innerText.split('\\t')[0])")
        assert rows[1:] == METHODS
        # the Timing panel is filled from timing.js with timing.json's numbers
        timing = json.loads((export_dir / "timing.json").read_text())["methods"]
        got = page.evaluate(_TIMING)
        assert got["x"] == METHODS and got["bars"] >= 2 * len(METHODS) - 1  # exact has no fit bar
        for k, name in enumerate(METHODS):
            t = timing[name]
            assert got["per_y"][k] == pytest.approx(1e6 * t["eval_s"] / t["n_evaluated"], rel=1e-12)
            if t["fit_s"] > 0:
                assert got["fit_y"][k] == pytest.approx(t["fit_s"], rel=1e-12)
                # JavaScript's String(Number(v.toPrecision(3))): positional from 1e-6 up
                assert got["fit_text"][k] == np.format_float_positional(float(f"{t['fit_s']:.3g}"), trim="-") + " s"
            else:
                assert got["fit_y"][k] is None and got["fit_text"][k] == "no fit"
    finally:
        context.close()


def test_page_without_timing_js_draws_and_says_where_the_times_are(export_dir, browser, tmp_path):
    alone = tmp_path / "panels.html"
    shutil.copy(export_dir / "panels.html", alone)
    context, page, requests, errors = _open(browser, alone)
    try:
        assert requests == [] and errors == []
        assert page.evaluate("() => document.querySelectorAll('.plotly-graph-div').length") == 3
        got = page.evaluate(_TIMING)
        assert all(v is None for v in got["fit_y"]) and all(v is None for v in got["per_y"])
        assert any("timing.js" in (n or "") for n in got["notes"])
    finally:
        context.close()
