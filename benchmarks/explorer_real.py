"""The explorer on a real sensor: start-up, memory and slider settling, measured as a user meets them.

1. **Start-up on the Pleiades DIMAP scene** (shareloc's 2017 product with its DEM, as
   ``pushbroom explore --dimap PHRDIMAP_...XML --dem MNT_...tif --port 0``): a fresh process is
   started; we time the URL line on its stdout, then open the URL in headless Chromium and time
   the first residual map and the complete maps (every default method drawn, none "waiting"),
   and read the server's resident memory (``VmRSS``) and its peak (``VmHWM``) from ``/proc``.
2. **Slider drag settling** (in-process, the app driven as the browser drives it): 20 values
   50 ms apart on a slider, then the time from the last value until the scene and the panels
   show it and all work has stopped.  The relief slider on the default preset (the drag the issue
   measured at 38 s with 19 queued rebuilds) and the height exaggeration on the DIMAP scene; with
   and without the debounce (``debounce_s=0`` is the old behaviour, newest-wins only).

Prints a table and writes JSON.  ``docs/explorer.md#responsiveness`` quotes the numbers.

Usage::

    python benchmarks/explorer_real.py --json out/explorer_real.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
DIMAP = ROOT / "tests" / "data" / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML"
DEM = ROOT / "assets" / "dem" / "MNT_P1BP--2017030824934340CP.tif"
CHROMIUM = "/usr/bin/chromium"


def _proc_kib(pid: int, key: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1])
    return 0


def startup(methods: str | None, timeout: float) -> dict:
    """Cold start of ``pushbroom explore --dimap ... --dem ...`` in a fresh process, seen from a browser."""
    cmd = [sys.executable, "-m", "explorer", "explore", "--dimap", str(DIMAP), "--dem", str(DEM),
           "--dem-datum", "egm96", "--port", "0"]
    if methods:
        cmd += ["--methods", methods]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out: dict = {"command": " ".join(cmd[1:])}
    stderr_lines: list[str] = []
    threading.Thread(target=lambda: stderr_lines.extend(proc.stderr), daemon=True).start()
    try:
        url = None
        for line in proc.stdout:
            m = re.search(r"(http://\S+)", line)
            if m:
                url = m.group(1)
                break
        out["url_s"] = time.perf_counter() - t0
        if url is None:
            out["error"] = "".join(stderr_lines)[-2000:]
            return out
        from playwright.sync_api import sync_playwright

        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=["--headless", "--no-sandbox", "--disable-gpu"])
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.set_default_timeout(timeout * 1000)
            page.goto(url)
            page.wait_for_function("() => document.body.innerText.includes(' row: RMSE')")
            out["first_map_s"] = time.perf_counter() - t0
            names = (methods or "lrm,prm,mlp,nr").split(",")
            js = ("() => { const t = document.body.innerText; return " +
                  " && ".join(f"t.includes('{n} row: RMSE')" for n in names) + " && !t.includes('training:'); }")
            page.wait_for_function(js)
            out["complete_maps_s"] = time.perf_counter() - t0
            out["rss_mib"] = _proc_kib(proc.pid, "VmRSS") / 1024
            out["peak_rss_mib"] = _proc_kib(proc.pid, "VmHWM") / 1024
            browser.close()
    finally:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
    out["python_warning_records"] = [ln for ln in stderr_lines if "Warning:" in ln and ".py:" in ln]
    out["stderr_lines"] = len(stderr_lines)
    return out


def drag(source: str, key: str, values: list, debounce_s: float, methods: list[str], scps: int) -> dict:
    """Settle time after a drag of ``key`` over ``values`` (50 ms apart) on ``source``."""
    import viser

    from explorer.app import ExplorerApp

    sources = []
    if source == "dimap":
        from explorer.sources import load_source

        sources = [load_source("dimap", str(DIMAP), dem=str(DEM), dem_datum="egm96")]
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = ExplorerApp(server, preset=None if sources else source, methods=methods, sources=sources, scp_count=scps,
                      sweep=False, debounce_s=debounce_s)
    try:
        app.wait_idle(600)
        built = app.model.counters["scene"]
        t_first = time.perf_counter()
        for v in values:
            app.handles[key].value = v
            time.sleep(0.05)
        t_last = time.perf_counter()
        app.wait_idle(600)
        settle = time.perf_counter() - t_last
        shown = app.settings()
        return {"source": source, "control": key, "values": len(values), "drag_s": t_last - t_first,
                "debounce_s": debounce_s, "settle_s": settle, "scene_builds": app.model.counters["scene"] - built,
                "final_value_shown": getattr(shown, {"relief": "relief_m", "exaggeration": "height_exaggeration"}[key])
                == float(values[-1])}
    finally:
        app.close()
        server.stop()


SLIDER_TRACK = """(label) => {
  const lab = Array.from(document.querySelectorAll('label')).find(l => l.textContent.trim() === label);
  let node = lab;
  while (node && !(node.querySelector && node.querySelector('.mantine-Slider-root'))) node = node.parentElement;
  const r = node.querySelector('.mantine-Slider-root').getBoundingClientRect();
  return {x: r.x, y: r.y + r.height / 2, width: r.width};
}"""


def browser_drag(debounce_s: float, steps: int = 20, drag_s: float = 2.0) -> dict:
    """Drag the relief slider of the default preset in headless Chromium (mouse down, ``steps`` moves
    over ``drag_s``, mouse up); time from mouse up until the app shows the final value and is idle."""
    from playwright.sync_api import sync_playwright

    from explorer.app import serve

    box: dict = {}
    stop = threading.Event()
    th = threading.Thread(target=lambda: serve("WSU", port=0, methods=["lrm", "prm", "nr"], stop_event=stop,
                                               ready=lambda a: box.setdefault("app", a), sweep=False,
                                               debounce_s=debounce_s), daemon=True)
    th.start()
    while "app" not in box:
        time.sleep(0.05)
    app = box["app"]
    try:
        app.wait_idle(600)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=["--headless", "--no-sandbox", "--disable-gpu"])
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.set_default_timeout(600_000)
            page.goto(app.url)
            page.wait_for_function("() => document.body.innerText.includes('nr row: RMSE')")
            track = page.evaluate(SLIDER_TRACK, "Relief (m)")
            built = app.model.counters["scene"]
            y = track["y"]
            page.mouse.move(track["x"] + 2, y)
            page.mouse.down()
            for k in range(1, steps + 1):
                page.mouse.move(track["x"] + 2 + (track["width"] - 4) * k / steps, y)
                time.sleep(drag_s / steps)
            page.mouse.up()
            t_up = time.perf_counter()
            time.sleep(0.3)  # the last value on its way from the browser
            while True:
                app.wait_idle(600)
                if app.settings().relief_m == float(app.handles["relief"].value) and app.scene is not None \
                        and app._sent.get("frame", (None,))[0] == app.settings().scene_key:
                    break
                time.sleep(0.05)
            settle = time.perf_counter() - t_up
            browser.close()
        return {"source": "WSU (browser)", "control": "relief", "values": steps, "drag_s": drag_s,
                "debounce_s": debounce_s, "settle_s": settle, "scene_builds": app.model.counters["scene"] - built,
                "final_value_shown": float(app.handles["relief"].value) == app.settings().relief_m,
                "final_relief_m": float(app.handles["relief"].value)}
    finally:
        stop.set()
        th.join(60)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--methods", default=None, help="methods of the start-up run (default: the explorer's)")
    p.add_argument("--timeout", type=float, default=600.0)
    p.add_argument("--no-startup", action="store_true", help="skip the cold start (no browser)")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    res: dict = {"benchmark": "explorer_real",
                 "machine": {"cpus": os.cpu_count(), "loadavg_start": os.getloadavg(),
                             "python": platform.python_version()}}
    if not args.no_startup:
        res["startup"] = startup(args.methods, args.timeout)
    drags = []
    relief = list(range(100, 2001, 100))
    exag = [1.5 + 0.5 * k for k in range(18)]
    for debounce in (0.25, 0.0):
        if os.path.exists(CHROMIUM):
            drags.append(browser_drag(debounce))
        drags.append(drag("WSU", "relief", relief, debounce, ["lrm", "prm", "nr"], 50_000))
        drags.append(drag("dimap", "exaggeration", exag, debounce, ["lrm", "prm", "nr"], 50_000))
    res["drags"] = drags
    res["machine"]["loadavg_end"] = os.getloadavg()
    st = res.get("startup")
    if st:
        if "error" in st:
            print("start-up failed:", st["error"])
        else:
            print(f"DIMAP start-up: URL {st['url_s']:.2f} s, first map {st['first_map_s']:.2f} s, complete maps "
                  f"{st['complete_maps_s']:.2f} s; RSS {st['rss_mib']:.0f} MiB (peak {st['peak_rss_mib']:.0f}); "
                  f"Python warning records on stderr: {len(st['python_warning_records'])}")
    print(f"  {'drag':34} {'debounce':>8} {'settle s':>9} {'builds':>7} last shown")
    for d in drags:
        print(f"  {d['source'] + ' ' + d['control'] + ' x' + str(d['values']):34} {d['debounce_s']:8.2f} "
              f"{d['settle_s']:9.2f} {d['scene_builds']:7d} {d['final_value_shown']}")
    print(f"  load average {res['machine']['loadavg_start'][0]:.1f} -> {res['machine']['loadavg_end'][0]:.1f} "
          f"on {res['machine']['cpus']} CPUs")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(res, indent=1, default=str))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
