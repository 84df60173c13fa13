"""Triangulation speed on the public Pleiades pair: explorer.stereo.triangulate on 1,000,000 matches vs a per-point
scipy least_squares loop (timed on a sample, extrapolated) and shareloc's vectorised RPC triangulation
(``shareloc.geofunctions.triangulation.sensor_triangulation``, straight lines of sight between the RPC's height
bounds, no refinement) when shareloc is installed.

The matches are the exact projections (by rpcm, an independent RPC library) of ground points at random
positions and heights (100..1000 m); the accuracy of each method against those ground points is reported too.

Usage::

    .venv/bin/python benchmarks/stereo_bench.py [--n 1000000] [--scipy-sample 300] [--seed 0] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RPC_DIR = ROOT / "tests" / "data" / "rpc"
LEFT = RPC_DIR / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML"
RIGHT = RPC_DIR / "RPC_PHR1B_P_201709281038393_SEN_PRG_FC_178609-001.XML"


def scipy_loop(left, right, lr, lc, rr, rc, x0):
    """One scipy.optimize.least_squares per match on the 4 pixel residuals of (lon, lat, h), started from x0."""
    from scipy.optimize import least_squares

    out = np.empty((lr.size, 3))
    for i in range(lr.size):
        def residual(p, i=i):
            r1, c1 = left.projection(p[0], p[1], p[2])
            r2, c2 = right.projection(p[0], p[1], p[2])
            return np.array([r1 - lr[i], c1 - lc[i], r2 - rr[i], c2 - rc[i]])

        out[i] = least_squares(residual, x0[i], x_scale=[1e-5, 1e-5, 1.0], xtol=1e-12, ftol=1e-12).x
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--scipy-sample", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    import rpcm

    from explorer import read_rpc
    from explorer.geometry.frames import geodetic_to_ecef
    from explorer.stereo import triangulate

    left, right = read_rpc(LEFT), read_rpc(RIGHT)
    peer_l, peer_r = rpcm.rpc_from_rpc_file(str(LEFT)), rpcm.rpc_from_rpc_file(str(RIGHT))
    rng = np.random.default_rng(args.seed)
    n = args.n
    lon, lat, h = rng.uniform(7.08, 7.27, n), rng.uniform(43.63, 43.72, n), rng.uniform(100.0, 1000.0, n)
    lc, lr = peer_l.projection(lon, lat, h)
    rc, rr = peer_r.projection(lon, lat, h)
    truth = geodetic_to_ecef(lon, lat, h)
    doc: dict = {"n": n, "pair": [LEFT.name, RIGHT.name]}

    triangulate(left, right, lr[:1000], lc[:1000], rr[:1000], rc[:1000])  # compile / load the kernels
    t = time.perf_counter()
    out = triangulate(left, right, lr, lc, rr, rc)
    t_ours = time.perf_counter() - t
    err = np.linalg.norm(out.xyz - truth, axis=1)
    doc["explorer"] = {"seconds": t_ours, "valid": int(out.valid.sum()), "max_error_m": float(np.nanmax(err)),
                       "max_ray_distance_m": float(np.nanmax(out.ray_distance_m))}
    print(f"explorer.stereo.triangulate: {n} matches in {t_ours:.2f} s ({t_ours / n * 1e6:.2f} us/match), "
          f"max error {np.nanmax(err):.2e} m, max ray distance {np.nanmax(out.ray_distance_m):.2e} m")

    k = min(args.scipy_sample, n)
    x0 = np.column_stack([lon[:k] + 1e-4, lat[:k] - 1e-4, h[:k] + 50.0])
    t = time.perf_counter()
    sol = scipy_loop(left, right, lr[:k], lc[:k], rr[:k], rc[:k], x0)
    t_k = time.perf_counter() - t
    t_scipy = t_k / k * n
    err_s = np.linalg.norm(geodetic_to_ecef(sol[:, 0], sol[:, 1], sol[:, 2]) - truth[:k], axis=1)
    doc["scipy_loop"] = {"sample": k, "sample_seconds": t_k, "extrapolated_seconds": t_scipy,
                         "max_error_m": float(np.max(err_s)), "ratio": t_scipy / t_ours}
    print(f"scipy least_squares loop: {k} matches in {t_k:.2f} s -> {t_scipy:.0f} s for {n} "
          f"(max error {np.max(err_s):.2e} m): explorer is {t_scipy / t_ours:.0f}x faster")

    try:
        from shareloc.geofunctions.triangulation import sensor_triangulation
        from shareloc.geomodels import GeoModel
    except ImportError as exc:
        print(f"shareloc not installed ({exc}): no shareloc ratio")
    else:
        gl, gr = GeoModel(str(LEFT), "RPC"), GeoModel(str(RIGHT), "RPC")
        matches = np.column_stack([lc + 0.5, lr + 0.5, rc + 0.5, rr + 0.5])  # shareloc: pixel centre at 0.5
        sensor_triangulation(matches[:1000], gl, gr)
        t = time.perf_counter()
        ecef, _, _ = sensor_triangulation(matches, gl, gr)
        t_sl = time.perf_counter() - t
        err_sl = np.linalg.norm(ecef - truth, axis=1)
        doc["shareloc"] = {"seconds": t_sl, "max_error_m": float(np.nanmax(err_sl)),
                           "median_error_m": float(np.nanmedian(err_sl)), "ratio": t_sl / t_ours}
        print(f"shareloc sensor_triangulation: {n} matches in {t_sl:.2f} s, max error {np.nanmax(err_sl):.3g} m "
              f"(median {np.nanmedian(err_sl):.3g} m): explorer is {t_sl / t_ours:.1f}x faster")
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
