"""How fast the explorer answers its controls: drive the app from Python and time it.

Starts a viser server on a free port, builds :class:`explorer.app.ExplorerApp` in its
interactive (background) mode and changes controls the way a user would (setting a
handle's ``.value`` runs its callbacks).  For each change it records

* ``first_s`` -- until the scene and the panels show the new settings (every method whose
  fit is ready evaluated; a method still training is shown as pending), and
* ``idle_s`` -- until every fit it started has finished and been drawn,

plus the stage breakdown of the update and per method the points evaluated (a slow
method runs on a subsample that fits the time budget), fit and ground-to-image times.
Prints a table and writes JSON.  See ``docs/explorer.md#responsiveness``.

Usage::

    python benchmarks/explorer_responsiveness.py --scps 250000 --json out/explorer_responsiveness.json
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


COLD_START = r"""
import json, sys, threading, time
T = time.perf_counter()
sys.path.insert(0, {root!r})
from explorer.app import serve
box, stop = {{}}, threading.Event()
th = threading.Thread(target=serve, kwargs=dict(port=0, ready=lambda a: box.setdefault("app", a), stop_event=stop),
                      daemon=True)
th.start()
while "app" not in box:
    time.sleep(0.01)
app = box["app"]
out = {{"url_s": app.startup_s + 0.0, "app_s": time.perf_counter() - T}}
app.wait_update(1, 300)
out["scene_s"] = time.perf_counter() - T
app.wait_update(app.wait_methods(300), 300)
out["methods_s"] = time.perf_counter() - T
out["pending_at_methods"] = list(app.pending)
app.wait_idle(600)
out["idle_s"] = time.perf_counter() - T
stop.set()
th.join(60)
print("COLD" + json.dumps(out))
"""


def cold_start() -> dict:
    """``pushbroom explore`` as a user starts it (default preset, methods and SCP count), in a
    fresh interpreter: seconds from the start of the process to the app existing (the URL is
    printed just before), the scene drawn, the methods evaluated, and all training done."""
    import subprocess

    root = str(Path(__file__).resolve().parent.parent)
    proc = subprocess.run([sys.executable, "-c", COLD_START.format(root=root)], capture_output=True,
                          text=True, timeout=900, cwd=root)
    line = [x for x in proc.stdout.splitlines() if x.startswith("COLD")]
    if not line:
        return {"error": proc.stderr[-2000:]}
    return json.loads(line[0][4:])


def run(args: argparse.Namespace) -> dict:
    cold = cold_start() if args.cold_start else None
    t_import = time.perf_counter()
    import viser

    from explorer.app import DEFAULT_METHODS, ExplorerApp, ExplorerModel, safe_available

    for mod in args.imports:
        importlib.import_module(mod)
    names, err = safe_available()
    methods = args.methods.split(",") if args.methods else [m for m in DEFAULT_METHODS if m in names]
    import_s = time.perf_counter() - t_import

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    model = ExplorerModel(preview_after_s=args.budget)
    t0 = time.perf_counter()
    app = ExplorerApp(server, preset=args.preset, methods=methods, scp_count=args.scps,
                      scop_density=args.density, sweep=args.sweep, model=model, background=True)
    ctor_s = time.perf_counter() - t0
    app.wait_update(1, timeout=args.timeout)
    startup_scene_s = time.perf_counter() - t0
    app.wait_update(app.wait_methods(args.timeout), timeout=args.timeout)
    startup_first_s = time.perf_counter() - t0
    startup_pending = dict(app.pending)
    startup_stages = dict(app.last_times)
    app.wait_idle(timeout=args.timeout)
    startup_idle_s = time.perf_counter() - t0

    def snapshot() -> dict:
        return {
            n: {"n_evaluated": r.evaluation.n_evaluated if r.ok else 0, "preview": r.preview,
                "fit_s": r.fit.fit_s, "locate_s": r.evaluation.locate_s if r.ok else None,
                "rmse_px": r.evaluation.rmse_px if r.ok else None, "error": r.error}
            for n, r in app.runs.items()
        }

    steps = []
    presets = args.presets.split(",")
    changes = [("preset", p) for p in presets] + [
        ("density", d) for d in args.densities.split(",")] + [("preset", presets[0])]
    for key, value in changes:
        handle = app.handles[key]
        t = time.perf_counter()
        handle.value = value
        gen = app._gen
        ok_first = app.wait_update(gen, timeout=args.timeout)
        first_s = time.perf_counter() - t
        pending = dict(app.pending)
        stages = dict(app.last_times)
        ok_idle = app.wait_idle(timeout=args.timeout)
        idle_s = time.perf_counter() - t
        steps.append({"control": key, "value": value, "first_s": first_s, "idle_s": idle_s,
                      "completed": ok_first and ok_idle, "pending_at_first": pending,
                      "stages_s": stages, "methods": snapshot()})
    app.close()
    server.stop()
    return {
        "benchmark": "explorer_responsiveness",
        "machine": {"cpus": os.cpu_count(), "loadavg": os.getloadavg(), "python": platform.python_version()},
        "settings": {"preset": args.preset, "scps": args.scps, "scop_density": args.density,
                     "methods": methods, "preview_after_s": args.budget, "sweep": args.sweep,
                     "max_cloud_points": app.max_cloud_points, "max_map_cells": app.max_map_cells},
        "discovery_error": err,
        "cold_start": cold,
        "import_s": import_s,
        "startup": {"constructor_s": ctor_s, "scene_s": startup_scene_s, "first_update_s": startup_first_s,
                    "pending_at_first": startup_pending, "stages_s": startup_stages,
                    "idle_s": startup_idle_s},
        "steps": steps,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--preset", default="WSU")
    p.add_argument("--presets", default="ISB,WSU", help="presets switched to, in order")
    p.add_argument("--densities", default="30,100", help="SCOP densities switched to, in order")
    p.add_argument("--density", type=int, default=100, help="SCOP density at start")
    p.add_argument("--scps", type=int, default=250_000)
    p.add_argument("--methods", default=None, help="comma-separated (default lrm,prm,mlp,nr where registered)")
    p.add_argument("--budget", type=float, default=2.0,
                   help="projected ground-to-image seconds beyond which a method shows a seeded preview first")
    p.add_argument("--sweep", action="store_true", help="also run the accuracy-vs-SCOPs sweep")
    p.add_argument("--timeout", type=float, default=600.0)
    p.add_argument("--cold-start", action="store_true",
                   help="also time a fresh `pushbroom explore` start (defaults, in a subprocess)")
    p.add_argument("--import", dest="imports", action="append", default=[],
                   help="import a module first (e.g. one registering extra methods)")
    p.add_argument("--json", default=None, help="write the results here")
    args = p.parse_args(argv)
    res = run(args)
    st = res["startup"]
    if res["cold_start"]:
        c = res["cold_start"]
        if "error" in c:
            print("cold start failed:", c["error"])
        else:
            print(f"cold start (pushbroom explore defaults): app + URL {c['app_s']:.2f} s, scene {c['scene_s']:.2f} s, "
                  f"methods {c['methods_s']:.2f} s (training {c['pending_at_methods']}), all done {c['idle_s']:.2f} s")
    print(f"explorer responsiveness: {res['settings']['scps']:,} SCPs, methods {res['settings']['methods']}, "
          f"{res['machine']['cpus']} CPUs, load {res['machine']['loadavg'][0]:.1f}")
    print(f"  imports {res['import_s']:.2f} s; startup: constructor {st['constructor_s']:.2f} s, scene "
          f"{st['scene_s']:.2f} s, methods {st['first_update_s']:.2f} s (pending {list(st['pending_at_first'])}), "
          f"idle {st['idle_s']:.2f} s")
    print(f"  {'change':22} {'first s':>8} {'idle s':>8}  pending at first / subsampled")
    for s in res["steps"]:
        sub = [n for n, m in s["methods"].items() if m["preview"]]
        print(f"  {s['control'] + ' -> ' + str(s['value']):22} {s['first_s']:8.2f} {s['idle_s']:8.2f}  "
              f"{list(s['pending_at_first'])} / {sub}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(res, indent=1, default=str))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
