"""Bundle adjustment of a stereo pair of rigorous line scanners with many tie points: time, iterations, memory.

The pair of ``tests/refine/linescan_pair.py`` (the 2017 Pleiades DIMAP model and a copy moved 250 km along its
orbit and turned back to the same ground, both biased by known position / attitude offsets), N tie points
(default 50,000) and 8 GCPs measured in both images with 0.3 px of seeded noise: 2 N + 16 image measurements
(50,000 ties: 100,016 measurements of a row and a column each, 150,000 ground unknowns + 6 or 12 image
parameters), model ``attitude`` (default; the biases' attitude part) or ``position-attitude`` (the whole biases;
with 50,000 ties it is refused as a degenerate configuration: the along/cross offsets and pitch/roll that only the
8 GCPs tell apart leave the reduced system a condition of ~1e11), adjusted by
:func:`explorer.refine.adjust.refine_images` (Levenberg-Marquardt, the Schur complement of
:mod:`explorer.refine.bundle`: 3 x 3 blocks per ground point, never a normal matrix over all of them -- that one
would be 150,000^2 doubles, 180 GB).

Reported: wall time of the adjustment (set-up excluded), iterations, sigma0, the largest |error| / sigma of the
parameters against the known biases, the peak resident memory of the process (``ru_maxrss``) before and after
the adjustment, and the load (``os.getloadavg``) at the start and the end.

Usage::

    .venv/bin/python benchmarks/bundle_linescan.py [--ties 50000] [--model position-attitude] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ties", type=int, default=50000)
    ap.add_argument("--gcps", type=int, default=8)
    ap.add_argument("--model", default="attitude", choices=("attitude", "position-attitude"))
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    from explorer.refine.adjust import refine_images
    from tests.refine.linescan_pair import NOISE_PX, TRUE_BIAS, biased, load_dimap_2017, off_nadir_copy, simulate

    load_start = os.getloadavg()[0]
    a = load_dimap_2017()
    b = off_nadir_copy(a)
    # attitude: the biases' attitude part only (the model then fits the truth exactly)
    bias = TRUE_BIAS if args.model == "position-attitude" else tuple(p[3:] for p in TRUE_BIAS)
    truths = biased([a, b], bias, args.model)
    rng = np.random.default_rng(50000)
    ties = simulate(truths, a.frame, args.ties, rng, "t", ground_known=False)
    gcps = simulate(truths, a.frame, args.gcps, rng, "g", ground_known=True)
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    t = time.perf_counter()
    ref = refine_images([a, b], model=args.model, control=gcps, ties=ties, sigma_px=NOISE_PX, names=["A", "B"])
    seconds = time.perf_counter() - t
    rss_after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    out = {
        "ties": args.ties, "gcps": args.gcps, "model": args.model,
        "observations": int(ref.result.outlier.size), "ground_unknowns": 3 * args.ties,
        "image_parameters": int(ref.parameters.size),
        "seconds": round(seconds, 2), "iterations": ref.result.iterations, "sigma0": round(ref.result.sigma0, 4),
        "n_outliers": int(ref.result.outlier.sum()),
        "peak_rss_mb_before": round(rss_before, 1), "peak_rss_mb_after": round(rss_after, 1),
        "load_start": round(load_start, 2), "load_end": round(os.getloadavg()[0], 2),
    }
    z = (ref.parameters - np.concatenate(bias)) / ref.result.parameter_sigma
    out["max_abs_error_over_sigma"] = round(float(np.max(np.abs(z))), 3)
    print(json.dumps(out, indent=2))
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
