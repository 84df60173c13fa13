"""``pushbroom explore <file> --export DIR`` with the file's DEFAULT settings, timed as a user runs it (issue 24:
"``--export`` of the DIMAP scene in under 5 s").

Each run is the real command in a fresh Python process (``python -m explorer explore ... --export DIR``, nothing
added: a file's default is every learned and exact method, 50,000 SCPs, 100 SCOPs and the accuracy-vs-SCOPs sweep)
and records

* **wall** seconds from starting the process to its exit;
* **CPU** seconds (user + system) of the process and of every process it waited for (the sweep's worker): on a
  shared machine the wall time stretches with the load, the CPU time much less;
* the export's own line (its time and the sweep's share) and ``timing.json``'s ``sweep_s``;
* the machine's 1-minute load average before and after: quote it with every figure;
* whether every file but the run-dependent ``timing.json`` / ``timing.js`` is byte-identical to the first run of
  the same checkout (and, across checkouts, to the first checkout's).

Several checkouts (``--root``, e.g. an older commit unpacked with ``git archive``) are run **interleaved**, one run
of each in turn, so that a before / after comparison sees the same load.  A checkout's first run after a change
of its numba kernels compiles them: ``--warm`` runs each checkout once first without recording it (or run
``pushbroom warmup``).

Usage::

    python benchmarks/explorer_export.py --json benchmarks/results/explorer_export.json
    python benchmarks/explorer_export.py --root /tmp/base --root . --repeat 3 --warm   # before / after
    python benchmarks/explorer_export.py --case isd-ctx
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: name -> the source options of ``pushbroom explore`` (paths relative to the checkout)
CASES: dict[str, list[str]] = {
    "dimap-dem": ["--dimap", "tests/data/rpc/PHRDIMAP_P1BP--2017030824934340CP.XML", "--dem",
                  "assets/dem/MNT_P1BP--2017030824934340CP.tif", "--dem-datum", "egm96"],
    "isd-ctx": ["--isd", "tests/data/usgscsm/ctxLineScan.json"],
    "rpc": ["--rpc", "tests/data/rpc/RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML"],
}
RUN_DEPENDENT = ("timing.json", "timing.js")


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_once(root: Path, case: str, out: Path, python: str, extra: list[str] | None = None) -> dict:
    """One export of ``case`` by the checkout ``root`` into ``out`` (replaced); ``extra``: options added (not the
    default command then: for floor figures such as ``--no-sweep``)."""
    if out.exists():
        shutil.rmtree(out)
    cmd = [python, "-m", "explorer", "explore", *CASES[case], *(extra or []), "--export", str(out)]
    env = dict(os.environ, PYTHONPATH=str(root), PYTHONUNBUFFERED="1")
    load_before, cpu0, t0 = _load(), _children_cpu(), time.perf_counter()
    proc = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True, check=False)
    wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-2000:]}")
    line = next((ln for ln in proc.stdout.splitlines() if "exported" in ln), "")
    timing = json.loads((out / "timing.json").read_text())
    return {"wall_s": round(wall, 3), "cpu_s": round(cpu, 3), "load_before": load_before, "load_after": _load(),
            "sweep_s": timing.get("sweep_s"), "export_line": line.strip()}


def _files(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(out.iterdir()) if p.name not in RUN_DEPENDENT}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--root", action="append", help="checkout to measure (repeat for an interleaved comparison; "
                                                   "default: this one)")
    p.add_argument("--case", default="dimap-dem", choices=sorted(CASES))
    p.add_argument("--repeat", type=int, default=3, help="runs per checkout (interleaved)")
    p.add_argument("--warm", action="store_true", help="one unrecorded run per checkout first (kernel compiles)")
    p.add_argument("--python", default=sys.executable)
    p.add_argument("--extra", default="", help="options added to the command (e.g. '--no-sweep'): NOT the default "
                                               "command then, a floor figure")
    p.add_argument("--json", help="write the results here")
    args = p.parse_args(argv)
    roots = [Path(r).resolve() for r in (args.root or [str(ROOT)])]
    tmp = Path(tempfile.mkdtemp(prefix="pushbroom-export-bench-"))
    first: dict[int, dict[str, bytes]] = {}
    runs: list[dict] = []
    try:
        if args.warm:
            for k, root in enumerate(roots):
                run_once(root, args.case, tmp / f"warm{k}", args.python, args.extra.split())
        for rep in range(args.repeat):
            for k, root in enumerate(roots):
                out = tmp / f"r{k}"
                rec = run_once(root, args.case, out, args.python, args.extra.split())
                files = _files(out)
                first.setdefault(k, files)
                rec.update(root=str(root), repeat=rep, identical_to_first_run=files == first[k],
                           identical_to_first_root=files == first[0])
                runs.append(rec)
                print(f"{root} run {rep + 1}: wall {rec['wall_s']:.2f} s, CPU {rec['cpu_s']:.2f} s, load "
                      f"{rec['load_before']} -> {rec['load_after']}, sweep {rec['sweep_s']}, identical "
                      f"{rec['identical_to_first_run']} / {rec['identical_to_first_root']}", flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    summary = {}
    for root in roots:
        mine = [r for r in runs if r["root"] == str(root)]
        summary[str(root)] = {"wall_s_median": statistics.median(r["wall_s"] for r in mine),
                              "cpu_s_median": statistics.median(r["cpu_s"] for r in mine),
                              "load_range": [min(r["load_before"] for r in mine), max(r["load_after"] for r in mine)]}
    result = {"benchmark": "explorer_export", "case": args.case,
              "command": f"pushbroom explore {' '.join([*CASES[args.case], *args.extra.split()])} --export DIR",
              "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                          "python": platform.python_version()},
              "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "runs": runs, "summary": summary}
    print(json.dumps(summary, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
