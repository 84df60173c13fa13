"""CPU seconds of a ``bpnn`` / ``nn-rfm`` fit and its answers, each in a fresh process as an export's sweep makes them,
and whether the process imported torch.

For each method and SCOP count one fresh Python process (``PYTHONPATH`` = the checkout) builds the scene (a preset
with seeded relief), simulates the SCOPs on its terrain and 50,000 check points, then records the CPU seconds of

* **fit**: ``create(method, scene).fit(scops)`` with the method's defaults (the compiled trainer for one hidden
  layer), including any import it triggers (torch, before the networks held numpy weights);
* **answer**: ``ground_to_image`` of the check points (bpnn: Newton on the network and its Jacobian);
* **process**: the whole process (user + system, read by the parent after it exited: imports, scene, teardown);

and ``torch`` in ``sys.modules`` at the end.  Several checkouts (``--root``) are run interleaved, one run of each in
turn, so a before / after comparison sees the same load; the machine's 1-minute load average is recorded with every
run.  Run ``pushbroom warmup`` in each checkout first (its numba kernels compiled and cached).

Usage::

    python benchmarks/learned_fit_cpu.py --root /tmp/base --root . --repeat 2 --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = """
import json, sys, time
import numpy as np
from explorer.methods import create
from explorer.points import simulate_points
from explorer.presets import build_scene

scene = build_scene("WSU", relief_m=300.0, relief_seed=3)
scops = simulate_points(scene, {n}, kind="scop")
check = simulate_points(scene, 50_000, kind="scp")
t0 = time.process_time()
method = create("{method}", scene).fit(scops)
t1 = time.process_time()
res = method.ground_to_image(check.ground)
t2 = time.process_time()
ok = res.valid
rmse = float(np.sqrt(np.mean((res.row[ok] - check.row[ok]) ** 2))) if ok.any() else float("nan")
print(json.dumps({{"fit_s": t1 - t0, "answer_s": t2 - t1, "n_scops": len(scops.row), "row_rmse_px": rmse,
                  "valid": float(np.mean(ok)), "torch": "torch" in sys.modules}}))
"""


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_once(root: Path, method: str, n: int, python: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(root), PYTHONUNBUFFERED="1")
    load = round(os.getloadavg()[0], 2)
    before = _children_cpu()
    proc = subprocess.run([python, "-c", CHILD.format(method=method, n=n)], cwd=root, env=env, capture_output=True,
                          text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"{root} {method} {n}: {proc.stderr[-2000:]}")
    rec = json.loads(proc.stdout.strip().splitlines()[-1])
    rec.update(process_s=_children_cpu() - before, load=load, root=str(root), method=method, n=n)
    return rec


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--root", action="append", help="checkout to measure (repeat for an interleaved comparison)")
    p.add_argument("--methods", default="bpnn,nn-rfm")
    p.add_argument("--scops", default="50,100,1000", help="SCOP counts (simulate_points' n)")
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--python", default=sys.executable)
    p.add_argument("--json", help="write the runs and medians here")
    args = p.parse_args()
    roots = [Path(r).resolve() for r in (args.root or [str(ROOT)])]
    runs = []
    for rep in range(args.repeat):
        for method in args.methods.split(","):
            for n in (int(v) for v in args.scops.split(",")):
                for root in roots:
                    rec = run_once(root, method, n, args.python)
                    rec["repeat"] = rep
                    runs.append(rec)
                    print(f"{root} {method} n={n} ({rec['n_scops']} SCOPs): fit {rec['fit_s']:.2f} s, answer "
                          f"{rec['answer_s']:.2f} s, process {rec['process_s']:.2f} s CPU, torch {rec['torch']}, "
                          f"row RMSE {rec['row_rmse_px']:.4f} px, load {rec['load']}", flush=True)
    summary = {}
    for root in roots:
        for method in args.methods.split(","):
            for n in (int(v) for v in args.scops.split(",")):
                mine = [r for r in runs if r["root"] == str(root) and r["method"] == method and r["n"] == n]
                summary[f"{root} {method} {n}"] = {k: statistics.median(r[k] for r in mine)
                                                   for k in ("fit_s", "answer_s", "process_s", "row_rmse_px")}
    print(json.dumps(summary, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps({"runs": runs, "median": summary}, indent=1))


if __name__ == "__main__":
    main()
