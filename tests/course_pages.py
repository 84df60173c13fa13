"""Check built course pages in headless Debian Chromium with the network blocked.

Used by ``tests/test_course.py`` (and runnable by hand: ``python -m tests.course_pages OUT_DIR``): every page of
a folder written by ``notebooks/build_course.py`` is opened from disk (``file://``) with the browser context
offline and every non-file request aborted, and the check records

* every request that is not ``file:``, ``data:``, ``blob:`` or ``about:`` (must be none),
* raw TeX left in the visible prose (a ``$`` outside code; the equations must be MathML),
* the MathML elements drawn (must be at least one on a page whose notebook has equations),
* every Plotly figure (``.pbx-figure`` / ``.plotly-graph-div``) that plotly.js did not draw (no ``.main-svg``
  with at least one trace),
* every inline 3D view (viser's static viewer in an ``<iframe srcdoc>``) whose WebGL canvas stays blank,
* JavaScript errors thrown on the page.
"""

from __future__ import annotations

import io
import sys
from dataclasses import dataclass, field
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-quic",
        "--no-first-run", "--disable-component-update", "--disable-sync"]
LOCAL_SCHEMES = ("file:", "data:", "blob:", "about:")

_PROSE_DOLLARS = """() => {
  const root = document.body.cloneNode(true);
  root.querySelectorAll('pre, code, script, style, math, .jp-InputArea, .jp-OutputArea-output pre')
      .forEach(e => e.remove());
  const text = root.innerText || root.textContent || '';
  const out = [];
  let i = text.indexOf('$');
  while (i >= 0 && out.length < 5) { out.push(text.slice(Math.max(0, i - 40), i + 40)); i = text.indexOf('$', i + 1); }
  return out;
}"""

_FIGURES = """() => Array.from(document.querySelectorAll('.pbx-figure, .plotly-graph-div')).map(gd => ({
  id: gd.id,
  drawn: gd.querySelectorAll('.main-svg').length > 0 && !!gd._fullData && gd._fullData.length > 0,
  message: (gd.innerText || '').slice(0, 120),
}))"""

_CANVAS_SIZE = """() => Array.from(document.querySelectorAll('canvas')).map(c => [c.width, c.height])"""


@dataclass
class PageReport:
    """What one page did in the browser."""

    page: str
    network: list[str] = field(default_factory=list)
    raw_tex: list[str] = field(default_factory=list)
    n_math: int = 0
    figures_blank: list[str] = field(default_factory=list)
    n_figures: int = 0
    views_blank: list[str] = field(default_factory=list)
    n_views: int = 0
    errors: list[str] = field(default_factory=list)

    def problems(self, needs_math: bool = False) -> list[str]:
        """Human-readable problems (empty when the page is fine)."""
        out = [f"network request {u}" for u in self.network]
        out += [f"raw TeX in the text: ...{t}..." for t in self.raw_tex]
        if needs_math and self.n_math == 0:
            out.append("no rendered equation (MathML) on the page")
        out += [f"figure not drawn: {f}" for f in self.figures_blank]
        out += [f"3D view blank: {v}" for v in self.views_blank]
        out += [f"JavaScript error: {e}" for e in self.errors]
        return [f"{self.page}: {p}" for p in out]


def _pixel_spread(png: bytes) -> float:
    import numpy as np
    from PIL import Image

    a = np.asarray(Image.open(io.BytesIO(png)).convert("L"), dtype=np.float64)
    return float(a.std())


def check_page(browser, path: Path, *, timeout_ms: int = 120_000) -> PageReport:
    """Open one built page offline and report what it loaded and drew (see the module docstring)."""
    report = PageReport(path.name)
    context = browser.new_context(viewport={"width": 1300, "height": 900}, offline=True)
    try:
        def route(r) -> None:
            if r.request.url.startswith(LOCAL_SCHEMES):
                r.continue_()
            else:
                r.abort()

        context.route("**/*", route)
        context.on("request", lambda req: None if req.url.startswith(LOCAL_SCHEMES) else report.network.append(
            req.url))
        page = context.new_page()
        page.set_default_timeout(timeout_ms)
        page.on("pageerror", lambda exc: report.errors.append(str(exc)[:200]))
        page.goto(path.resolve().as_uri(), wait_until="load")
        page.wait_for_timeout(500)
        report.raw_tex = page.evaluate(_PROSE_DOLLARS)
        report.n_math = page.evaluate("() => document.querySelectorAll('math').length")
        try:  # plotly draws synchronously on load for most traces; give WebGL traces a moment
            page.wait_for_function("() => Array.from(document.querySelectorAll('.pbx-figure, .plotly-graph-div'))"
                                   ".every(gd => gd.querySelectorAll('.main-svg').length > 0)", timeout=30_000)
        except Exception:  # noqa: BLE001 - the per-figure report below says which
            pass
        figures = page.evaluate(_FIGURES)
        report.n_figures = len(figures)
        report.figures_blank = [f"{f['id']} {f['message']!r}" for f in figures if not f["drawn"]]
        iframes = page.query_selector_all("iframe[srcdoc]")
        report.n_views = len(iframes)
        for k, handle in enumerate(iframes):
            handle.scroll_into_view_if_needed()
            frame = handle.content_frame()
            try:
                frame.wait_for_function("() => Array.from(document.querySelectorAll('canvas'))"
                                        ".some(c => c.width > 200 && c.height > 200)", timeout=timeout_ms)
                page.wait_for_timeout(2000)  # the first frames of the scene
                spread = _pixel_spread(handle.screenshot())
                if spread < 3.0:
                    report.views_blank.append(f"view {k}: uniform image (pixel spread {spread:.1f})")
            except Exception as exc:  # noqa: BLE001
                report.views_blank.append(f"view {k}: no canvas ({type(exc).__name__})")
    finally:
        context.close()
    return report


def check_folder(out_dir: Path, pages: list[Path] | None = None) -> list[PageReport]:
    """Check every ``*.html`` of a built course folder (``index.html`` included) in one browser."""
    from playwright.sync_api import sync_playwright

    pages = pages if pages is not None else sorted(out_dir.rglob("*.html"))
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            return [check_page(browser, page) for page in pages]
        finally:
            browser.close()


if __name__ == "__main__":
    reports = check_folder(Path(sys.argv[1]))
    bad = 0
    for r in reports:
        problems = r.problems()
        bad += bool(problems)
        print(f"{r.page}: {r.n_math} equations, {r.n_figures} figures, {r.n_views} 3D views"
              + ("".join("\n  " + p for p in problems) if problems else ": ok"))
    sys.exit(1 if bad else 0)
