"""CPU seconds of ``residuals.csv`` (:func:`explorer.app.export.residuals_csv`): the compiled kernel
(:func:`explorer.float_text.csv_lines`) against the Python formatting it replaced (``_residuals_csv_python``, the
numba-less fallback), interleaved in one process on the default DIMAP export's shape (14 methods x 50,000 check
points, every method evaluated on every point).

The maps are seeded: rows / columns uniform over a 40,000-pixel image, ECEF coordinates of Earth scale, residuals
``N(0, 1) * 10^U(-12, 1)`` px (what the learned and exact methods give) with 2 % NaN.  Each repeat times both
implementations on the same maps (CPU seconds of this process, the 1-minute load average with each) and checks that
their bytes are identical.  The first kernel call of a process loads the kernel from numba's cache: it is timed
separately (``first_kernel_cpu_s``), after numba's own start-up in this process (loading a small kernel of the same
module first, ``numba_start_cpu_s``: an export has paid it long before it writes the CSV); run ``pushbroom warmup``
first.

Usage::

    python benchmarks/residuals_csv.py --repeat 5 --json benchmarks/results/residuals_csv.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from types import SimpleNamespace

import numpy as np


class _Points(SimpleNamespace):
    def __len__(self) -> int:
        return len(self.row)


def maps(n_methods: int = 14, n_points: int = 50_000, seed: int = 0) -> tuple:
    """Seeded evaluations, statuses, check points and ECEF coordinates of the default export's shape."""
    from explorer.app.model import STATUS_NAMES

    rng = np.random.default_rng(seed)
    scps = _Points(row=rng.uniform(0, 4e4, n_points), col=rng.uniform(0, 4e4, n_points))
    xyz = rng.normal(0, 6.4e6, (n_points, 3))
    evs, status = {}, {}
    for k in range(n_methods):
        r = rng.normal(0, 1, n_points) * 10.0 ** rng.uniform(-12, 1, n_points)
        c = rng.normal(0, 1, n_points) * 10.0 ** rng.uniform(-12, 1, n_points)
        r[::50] = np.nan
        evs[f"method{k}"] = SimpleNamespace(evaluated_index=np.arange(n_points), residual_row=r, residual_col=c)
        status[f"method{k}"] = rng.integers(0, len(STATUS_NAMES), n_points).astype(np.int8)
    return evs, status, scps, xyz


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--json", help="write the results here")
    a = p.parse_args()
    from explorer.app import export
    from explorer.float_text import g17_texts

    args = maps()
    t = time.process_time()
    g17_texts(np.array([1.0]))
    numba_start = time.process_time() - t
    t = time.process_time()
    first = export.residuals_csv(*args)
    first_cpu = time.process_time() - t
    runs = []
    for rep in range(a.repeat):
        for name, fn in (("python", export._residuals_csv_python), ("kernel", export.residuals_csv)):
            load = os.getloadavg()[0]
            t = time.process_time()
            data = fn(*args)
            cpu = time.process_time() - t
            assert data == first, f"{name} wrote other bytes"
            runs.append({"impl": name, "repeat": rep, "cpu_s": round(cpu, 4), "load": round(load, 2)})
            print(f"{name} run {rep}: CPU {cpu:.3f} s, load {load:.2f}")
    summary = {name: statistics.median(r["cpu_s"] for r in runs if r["impl"] == name) for name in ("python", "kernel")}
    result = {"benchmark": "residuals_csv", "bytes": len(first), "lines": first.count(b"\n"),
              "numba_start_cpu_s": round(numba_start, 4),
              "first_kernel_cpu_s": round(first_cpu, 4), "median_cpu_s": summary, "identical": True, "runs": runs,
              "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    print(json.dumps({k: result[k] for k in ("bytes", "numba_start_cpu_s", "first_kernel_cpu_s",
                                                  "median_cpu_s")}))
    if a.json:
        with open(a.json, "w", encoding="utf-8") as f:
            f.write(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
