"""How long the exported ``panels.html`` takes to open offline in headless Chromium (issue 24).

The export of the Pleiades DIMAP scene with its DEM (``--scps`` check points, default 50,000; ``--methods``,
default lrm, prm, nr, exact; the accuracy-vs-SCOPs sweep included) is written to a temporary folder with
``timing.js`` beside it, then opened ``--repeat`` times from disk (``file://``) in a fresh offline browser
context whose every non-file request is aborted.  We time, in the page's own clock (``performance.now()``,
zero at the navigation start), until every Plotly panel is drawn -- each ``.plotly-graph-div`` has its SVG,
every residual map its raster image -- and the Timing panel has been filled from ``timing.js``; the load
average is recorded with each figure.  ``--root`` measures another checkout (before/after figures); the
export is computed by that checkout's ``explorer.app.export.export_files``.

Usage::

    python benchmarks/panels_open.py --json benchmarks/results/panels_open.json
    python benchmarks/panels_open.py --root /path/to/old/checkout
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DIMAP = ROOT / "tests" / "data" / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML"
DEM = ROOT / "assets" / "dem" / "MNT_P1BP--2017030824934340CP.tif"
CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-quic",
        "--no-first-run", "--disable-component-update", "--disable-sync"]
LOCAL = ("file:", "data:", "blob:", "about:")

DRAWN = """() => {
  const gds = Array.from(document.querySelectorAll('.plotly-graph-div'));
  if (gds.length === 0 || !gds.every(gd => gd._fullLayout && gd.querySelector('.main-svg'))) return false;
  const maps = gds[0];
  const want = (maps.data || []).filter(t => t.type === 'heatmap' && t.visible !== false).length;
  if (maps.querySelectorAll('.heatmaplayer image, .hm image').length < want) return false;
  const timing = gds[gds.length - 1];
  if (!(timing.data || []).some(t => Array.isArray(t.y) && t.y.some(v => v !== null))) return false;
  return performance.now();
}"""


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def run(args: argparse.Namespace) -> dict:
    sys.path.insert(0, str(Path(args.root).resolve()))
    from playwright.sync_api import sync_playwright

    from explorer.app.export import run_export
    from explorer.sources import load_source

    out: dict = {"root": str(Path(args.root).resolve()), "scps": args.scps, "methods": args.methods.split(","),
                 "load_start": _load()}
    src = load_source("dimap", str(DIMAP), dem=str(DEM), dem_datum="egm96")
    tmp_dir = tempfile.TemporaryDirectory()
    t0 = time.perf_counter()
    # what ``pushbroom explore --dimap ... --dem ... --export DIR --methods ...`` writes
    written = run_export(src, tmp_dir.name, methods=args.methods.split(","), scops=args.scops, scps=args.scps,
                         log=lambda *a: None)
    out["export_s"] = time.perf_counter() - t0
    out["panels_html_bytes"] = Path(written["panels.html"]).stat().st_size
    opens = []
    with tmp_dir, sync_playwright() as p:
        page_path = Path(written["panels.html"]).resolve()
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        for _ in range(args.repeat):
            context = browser.new_context(viewport={"width": 1300, "height": 900}, offline=True)
            leaked: list[str] = []
            context.route("**/*", lambda r, leaked=leaked: r.continue_() if r.request.url.startswith(LOCAL)
                          else (leaked.append(r.request.url), r.abort()))
            page = context.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda exc, errors=errors: errors.append(str(exc)[:200]))
            load = _load()
            page.goto(page_path.as_uri(), wait_until="commit")
            drawn_ms = page.wait_for_function(DRAWN, polling=10, timeout=args.timeout * 1000).json_value()
            opens.append({"drawn_s": drawn_ms / 1000.0, "load": load, "network_requests": leaked,
                          "errors": errors})
            print(f"  panels.html drawn in {drawn_ms / 1000:.2f} s (load {load})", flush=True)
            context.close()
        browser.close()
    out["opens"] = opens
    out["drawn_s_min"] = min(o["drawn_s"] for o in opens)
    out["drawn_s_median"] = sorted(o["drawn_s"] for o in opens)[len(opens) // 2]
    out["load_end"] = _load()
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--root", default=str(ROOT), help="checkout whose explorer package is measured")
    p.add_argument("--scps", type=int, default=50_000)
    p.add_argument("--scops", type=int, default=100)
    p.add_argument("--methods", default="lrm,prm,nr,exact")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--timeout", type=float, default=120.0)
    p.add_argument("--json", help="write the results here")
    args = p.parse_args()
    out = run(args)
    print(json.dumps({k: v for k, v in out.items() if k != "opens"}, indent=1))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
