"""CPU seconds of ``mlp``'s and ``ann``'s fits (and of their maps) at several SCOP densities on the Pleiades DIMAP
with its DEM, in a fresh process per run, before / after (several checkouts, ``--root``, run interleaved).

Each run loads the scene, then fits every method at every density twice: the first pass pays what a process pays
on its first fit (torch's import where the checkout trains by torch), the second pass is the fit alone.  Each fit
is followed by the method's map at ``--points`` SCPs (its ``ground_to_image``).  Recorded per fit: CPU seconds
(``time.process_time``), epochs and stop reason; per run: whether torch was imported, the process's CPU seconds,
and the 1-minute load average before and after (quote it with every figure).

Usage::

    python benchmarks/network_fits.py --root /tmp/base --root . --repeat 2 --json benchmarks/results/network_fits.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DIMAP = "tests/data/rpc/PHRDIMAP_P1BP--2017030824934340CP.XML"
DEM = "assets/dem/MNT_P1BP--2017030824934340CP.tif"


def child(methods: list[str], densities: list[int], n_points: int) -> dict:
    """One run in this process (the checkout on ``sys.path``)."""
    start = time.process_time()
    from explorer.methods import create
    from explorer.points import simulate_points
    from explorer.sources import load_source

    src = load_source("dimap", DIMAP, dem=DEM, dem_datum="egm96")
    scene = src.scene
    check = simulate_points(scene, n_points, kind="scp")
    scops = {d: simulate_points(scene, d, kind="scop") for d in densities}
    ready = time.process_time()
    fits = []
    for first in (True, False):
        for d in densities:
            for name in methods:
                t = time.process_time()
                m = create(name, scene).fit(scops[d])
                fit_s = time.process_time() - t
                t = time.process_time()
                m.ground_to_image(check.ground)
                fits.append({"pass": "first" if first else "again", "method": name, "scops": d, "fit_cpu_s": fit_s,
                             "map_cpu_s": time.process_time() - t, "epochs": m.fit_info["epochs"],
                             "stop": m.fit_info["stop_reason"]})
    return {"setup_cpu_s": ready - start, "total_cpu_s": time.process_time() - start,
            "torch_imported": "torch" in sys.modules, "fits": fits}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", action="append", help="checkout to run (repeatable; default this one)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--methods", default="mlp,ann")
    ap.add_argument("--densities", default="10,100,1000")
    ap.add_argument("--points", type=int, default=50_000)
    ap.add_argument("--json", default=None)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    methods, densities = a.methods.split(","), [int(v) for v in a.densities.split(",")]
    if a.child:
        print(json.dumps(child(methods, densities, a.points)))
        return
    roots = [Path(r).resolve() for r in (a.root or [str(ROOT)])]
    runs: dict[str, list] = {str(r): [] for r in roots}
    for _ in range(a.repeat):
        for r in roots:  # interleaved: every checkout sees the same load
            env = {**os.environ, "PYTHONPATH": str(r)}
            load0 = os.getloadavg()[0]
            out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", "--methods", a.methods,
                                  "--densities", a.densities, "--points", str(a.points)],
                                 cwd=r, env=env, capture_output=True, text=True, check=True)
            res = json.loads(out.stdout.strip().splitlines()[-1])
            res["load"] = [round(load0, 2), round(os.getloadavg()[0], 2)]
            runs[str(r)].append(res)
    summary = {}
    for r, rs in runs.items():
        rows = {}
        for f in rs[0]["fits"]:
            key = f"{f['pass']} {f['method']} {f['scops']}"
            same = [g for run in rs for g in run["fits"] if f"{g['pass']} {g['method']} {g['scops']}" == key]
            rows[key] = {"fit_cpu_s": statistics.median(g["fit_cpu_s"] for g in same),
                         "map_cpu_s": statistics.median(g["map_cpu_s"] for g in same),
                         "epochs": f["epochs"], "stop": f["stop"]}
        summary[r] = {"torch_imported": [x["torch_imported"] for x in rs],
                      "total_cpu_s": [round(x["total_cpu_s"], 2) for x in rs],
                      "setup_cpu_s": [round(x["setup_cpu_s"], 2) for x in rs],
                      "load": [x["load"] for x in rs], "median": rows}
    doc = {"points": a.points, "repeat": a.repeat, "summary": summary}
    text = json.dumps(doc, indent=1)
    print(text)
    if a.json:
        Path(a.json).write_text(text + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
