"""CPU of the export's figure phase: ``residual_maps``, ``accuracy_vs_density`` and ``timing_bars`` built, then
written into ``panels.html`` (``figures_html``), each checkout in a fresh process (plotly's lazy imports of its
classes are part of the cost, as in the export), several checkouts interleaved.

The figure functions' inputs are captured once from a real export (``pushbroom explore <case> --export``, run in
this process with the three functions wrapped) and pickled; every checkout then builds and writes the same figures,
and the page parts are compared byte for byte across checkouts.  Quote ``uptime``'s load with the figures (recorded).

Usage::

    python benchmarks/export_figures.py --root /tmp/before --root . --repeat 4 --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

from explorer_export import CASES  # noqa: E402

PHASE = r"""
import hashlib, pickle, sys, time
calls = pickle.load(open(sys.argv[1], "rb"))
import plotly.graph_objects  # noqa: F401  (imported by the export before its figures)
import explorer.panels.figures as F
t0 = time.process_time()
figs = [(name, getattr(F, name)(*args, **kwargs)) for name, args, kwargs in calls]
t1 = time.process_time()
page = F.figures_html(figs, "figures", ["note"])
t2 = time.process_time()
print(f"{t1 - t0:.4f} {t2 - t1:.4f} {hashlib.sha256(page.encode()).hexdigest()}")
"""


def capture(case: str, out: Path) -> None:
    """Run the export of ``case`` in this process and pickle the figure functions' calls to ``out``."""
    import explorer.panels.figures as F  # noqa: N812
    from explorer.cli import main

    calls: list = []
    def wrapped(name: str):
        orig = getattr(F, name)

        def wrap(*a, **k):
            calls.append((name, a, k))
            return orig(*a, **k)
        return wrap

    for name in ("residual_maps", "accuracy_vs_density", "timing_bars"):
        setattr(F, name, wrapped(name))
    with tempfile.TemporaryDirectory() as tmp:
        cwd = os.getcwd()
        os.chdir(ROOT)
        try:
            main(["explore", *CASES[case], "--export", tmp])
        except SystemExit:
            pass
        finally:
            os.chdir(cwd)
    out.write_bytes(pickle.dumps(calls))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--root", action="append", help="checkout to measure (repeat: interleaved)")
    p.add_argument("--case", default="dimap-dem", choices=sorted(CASES))
    p.add_argument("--repeat", type=int, default=4)
    p.add_argument("--json", help="write the results here")
    args = p.parse_args()
    roots = [Path(r).resolve() for r in (args.root or [str(ROOT)])]
    with tempfile.TemporaryDirectory() as tmp:
        calls = Path(tmp) / "calls.pkl"
        subprocess.run([sys.executable, __file__, "--capture", str(calls), "--case", args.case], check=True,
                       capture_output=True)
        runs: dict[str, list[dict]] = {str(r): [] for r in roots}
        for k in range(args.repeat):
            for r in roots:
                load = round(os.getloadavg()[0], 2)
                proc = subprocess.run([sys.executable, "-c", PHASE, str(calls)], capture_output=True, text=True,
                                      cwd=r, env=dict(os.environ, PYTHONPATH=str(r)), check=True)
                build, write, digest = proc.stdout.split()
                runs[str(r)].append({"build_cpu_s": float(build), "write_cpu_s": float(write), "page_sha256": digest,
                                     "load": load})
                print(f"{r} run {k + 1}: build {float(build):.3f} s, page {float(write):.3f} s CPU, load {load}")
    digests = {run["page_sha256"] for rs in runs.values() for run in rs}
    summary = {str(r): {"median_cpu_s": round(statistics.median(x["build_cpu_s"] + x["write_cpu_s"] for x in rs), 4)}
               for r, rs in runs.items()}
    print(json.dumps(summary, indent=1), "pages identical across checkouts and runs:", len(digests) == 1)
    if args.json:
        Path(args.json).write_text(json.dumps({"case": args.case, "runs": runs, "summary": summary,
                                               "identical": len(digests) == 1}, indent=1) + "\n")


if __name__ == "__main__":
    if "--capture" in sys.argv:
        i = sys.argv.index("--capture")
        case = sys.argv[sys.argv.index("--case") + 1] if "--case" in sys.argv else "dimap-dem"
        capture(case, Path(sys.argv[i + 1]))
    else:
        main()
