"""Refinement speed: one LM iteration over 10,000 GCP observations, and the whole adjustment against scipy.

The problem: the Pleiades RPC of tests/data/rpc (PHRDIMAP 2017) biased by a known affine, N GCPs (default
10,000) with 0.3 px noise and ground coordinates known to 0.5 m (so each GCP's ground is an unknown with a
prior: 6 image parameters + 3 N ground unknowns, 5 N observations).  Both solvers minimise the same
least-squares cost (loss ``linear``; scipy's robust losses act per residual component, ours per point):

- ``explorer.refine``: Levenberg-Marquardt, torch autograd Jacobians, Schur complement on the 3 x 3 ground
  blocks (:mod:`explorer.refine.bundle`);
- scipy ``least_squares`` (method ``trf``) with finite-difference Jacobians (``jac="2-point"``) on the same
  residuals, given the Jacobian's sparsity (``jac_sparsity``: without it the dense 50,000 x 30,006 Jacobian
  does not fit in memory) and ``x_scale="jac"``.

Times are wall-clock medians of ``--repeat`` runs in one process (torch imported and numba compiled first).

``--pair-ties N`` also times a bundle adjustment of the shareloc Pleiades stereo pair (both images biased by
known affines) with N tie points and 6 GCPs measured in both images (2 N + 12 image measurements of a row and
a column each; 50,000 ties are 100,012 measurements and 150,030 unknowns), once.

``--line-sensors`` also runs the same comparison on line scanners: the rigorous Pleiades DIMAP model
(tests/data/rpc PHRDIMAP 2018), the rigorous WorldView-1 DG model (tests/data/rpc rpc_WV1.xml) and the MRO CTX CSM
camera (tests/data/usgscsm), model ``position-attitude`` (6 parameters), the GCPs simulated by the sensor with known
offsets + 0.3 px noise, ground known to 0.5 m as above (:mod:`explorer.refine.torch_linescan`: the compiled line
search, then torch).  For each: one LM iteration (median of ``--repeat``; the projector keeps the lines of its
previous call as a warm start, as an adjustment's iterations do), the whole adjustment and its seconds per
iteration, and scipy ``least_squares`` (``trf``, ``2-point`` finite differences with the Jacobian's sparsity,
``x_scale="jac"``) on the same residuals from the same compiled ground to image of the adjusted sensor (its lines
warm-started from the previous evaluation in the same way), once.  ``--line-gcps`` sets their number of GCPs
(default ``--gcps``).  The LM iteration, the adjustment and scipy are also given in CPU seconds of this process
(``*_cpu_s``, ``*_speedup_vs_scipy_cpu``): on the shared machine the wall time is several times that, and a load
spike during the short adjustment moves the wall-time ratio by 3x from one run to the next.  scipy's finite
differences step the position offsets by ~1.5e-8 m, which moves a rigorous model's lines by ~2e-8 px against their
float64 noise of ~1e-9 px: its solution is reported against the truth as well as against ours.

Usage::

    .venv/bin/python benchmarks/refine_bench.py [--gcps 10000] [--repeat 3] [--pair-ties 50000] [--line-sensors]
        [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _problem(n: int, seed: int):
    from explorer.refine.bundle import BundleProblem
    from explorer.refine.torch_rpc import TorchRPC
    from tests.refine.cases import TRUE_AFFINE, pleiades, simulate_points

    rpc = pleiades()
    pts = simulate_points(rpc, n, noise_px=0.3, seed=seed)
    ground = np.stack([pts.lon, pts.lat, pts.h], axis=1)
    rng = np.random.default_rng(seed + 1)
    from explorer.refine.bundle import metres_per_degree

    m_lon, m_lat = metres_per_degree(ground[:, 1], ground[:, 2])
    surveyed = ground + rng.normal(0.0, 0.5, ground.shape) / np.stack([m_lon, m_lat, np.ones(n)], axis=1)
    problem = BundleProblem(projectors=[TorchRPC(rpc, "affine")], initial_parameters=[np.zeros(6)],
                            ground=surveyed, ground_sigma_m=np.full((n, 3), 0.5), image_index=np.zeros(n, int),
                            point_index=np.arange(n), measured=np.stack([pts.row, pts.col], axis=1),
                            sigma_px=np.full(n, 0.3))
    return rpc, problem, TRUE_AFFINE, (m_lon, m_lat)


def _scipy(rpc, problem, scales):
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    from explorer.refine.corrections import apply_correction

    n = problem.ground.shape[0]
    m_lon, m_lat = scales
    g0 = problem.ground

    def residuals(x):
        theta, d = x[:6], x[6:].reshape(n, 3)
        lon = g0[:, 0] + d[:, 0] / m_lon
        lat = g0[:, 1] + d[:, 1] / m_lat
        row, col = apply_correction("affine", theta, *rpc.projection(lon, lat, g0[:, 2] + d[:, 2]))
        image = ((problem.measured - np.stack([row, col], axis=1)) / 0.3).ravel()
        return np.concatenate([image, (d / 0.5).ravel()])

    sparsity = lil_matrix((5 * n, 6 + 3 * n), dtype=np.int8)
    obs = np.arange(n)
    for c in range(2):
        sparsity[2 * obs + c, :6] = 1
        for a in range(3):
            sparsity[2 * obs + c, 6 + 3 * obs + a] = 1
    for a in range(3):
        sparsity[2 * n + 3 * obs + a, 6 + 3 * obs + a] = 1
    result = least_squares(residuals, np.zeros(6 + 3 * n), jac="2-point", jac_sparsity=sparsity.tocsr(),
                           method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    return result


def _pair(n_ties: int, seed: int) -> dict:
    from explorer.refine.adjust import refine_images
    from explorer.rpc import read_rpc
    from tests.refine.cases import PAIR, TRUE_PAIR, simulate_pair_points

    rpcs = [read_rpc(p) for p in PAIR]
    rng = np.random.default_rng(seed)
    ties = simulate_pair_points(rpcs, n_ties, ground_known=False, prefix="t", rng=rng)
    gcps = simulate_pair_points(rpcs, 6, ground_known=True, prefix="g", rng=rng)
    t0 = time.perf_counter()
    ref = refine_images(rpcs, model="affine", control=gcps, ties=ties, sigma_px=0.3)
    elapsed = time.perf_counter() - t0
    z = (ref.parameters - np.concatenate(TRUE_PAIR)) / ref.result.parameter_sigma
    return {"pair_tie_points": n_ties, "pair_observations": int(ref.result.outlier.size),
            "pair_unknowns": 12 + 3 * (n_ties + 6), "pair_adjustment_s": elapsed,
            "pair_iterations": ref.result.iterations, "pair_sigma0": ref.result.sigma0,
            "pair_max_error_vs_truth_in_sigmas": float(np.max(np.abs(z)))}


LINE_SENSORS = {"dimap": ("dimap", "tests/data/rpc/PHRDIMAP_P1BP--2018122638935449CP.XML"),
                "dg": ("dg", "tests/data/rpc/rpc_WV1.xml"),
                "ctx": ("isd", "tests/data/usgscsm/ctxLineScan.json")}
LINE_TRUTH = np.array([60.0, -40.0, 20.0, 3e-5, -2e-5, 4e-5])


def _line_problem(which: str, n: int, seed: int):
    from explorer.refine.bundle import BundleProblem, metres_per_degree
    from explorer.refine.line_adjust import adjusted_sensor, correction_for
    from explorer.refine.torch_linescan import line_projector
    from explorer.sources import load_source

    kind, path = LINE_SENSORS[which]
    sensor = load_source(kind, str(ROOT / path)).scene
    corr = correction_for(sensor, "position-attitude")
    biased = adjusted_sensor(sensor, corr, LINE_TRUTH)
    rng = np.random.default_rng(seed)
    rows, cols = sensor.n_rows - 1, sensor.n_columns - 1
    g = biased.image_to_ground(rng.uniform(0.05 * rows, 0.95 * rows, n), rng.uniform(0.05 * cols, 0.95 * cols, n),
                               height=rng.uniform(-300.0, 300.0, n))
    row, col = biased.ground_to_image(g)
    ok = np.isfinite(row) & np.isfinite(sensor.ground_to_image(g)[0])  # seen by the unadjusted sensor too
    lon, lat, h = sensor.frame.enu_to_geodetic(g[ok])
    m = int(ok.sum())
    axes = (float(sensor.frame.body.a_m), float(sensor.frame.body.b_m))
    m_lon, m_lat = metres_per_degree(lat, h, axes)
    ground = np.stack([lon, lat, h], axis=1)
    surveyed = ground + rng.normal(0.0, 0.5, ground.shape) / np.stack([m_lon, m_lat, np.ones(m)], axis=1)
    measured = np.stack([row[ok], col[ok]], axis=1) + rng.normal(0.0, 0.3, (m, 2))
    return BundleProblem(projectors=[line_projector(sensor, corr)], initial_parameters=[np.zeros(6)], ground=surveyed,
                         ground_sigma_m=np.full((m, 3), 0.5), image_index=np.zeros(m, int), point_index=np.arange(m),
                         measured=measured, sigma_px=np.full(m, 0.3), axes=axes)


def _line_scipy(problem):
    """scipy least_squares with 2-point finite differences on the line-scanner problem (same residuals: the
    compiled ground to image of the adjusted sensor, lines warm-started from the previous evaluation)."""
    import torch
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    from explorer.refine.bundle import metres_per_degree

    proj = problem.projectors[0]
    proj.forget_roots()
    n = problem.ground.shape[0]
    g0 = problem.ground
    m_lon, m_lat = metres_per_degree(g0[:, 1], g0[:, 2], problem.axes)
    p = len(proj.parameter_names)

    def residuals(x):
        theta, d = x[:p], x[p:].reshape(n, 3)
        lon = torch.from_numpy(g0[:, 0] + d[:, 0] / m_lon)
        lat = torch.from_numpy(g0[:, 1] + d[:, 1] / m_lat)
        h = torch.from_numpy(g0[:, 2] + d[:, 2])
        if hasattr(proj, "_origin"):  # rigorous: ENU of the frame, the compiled search of the adjusted scene
            frame = proj.sensor.frame
            ground = frame.geodetic_to_enu(lon.numpy(), lat.numpy(), h.numpy())
            row, col = proj._search(theta, ground)
        else:  # CSM: body-fixed points, the adjusted camera's compiled lines and samples
            cam = proj.adjusted(theta).camera
            a, b = float(cam.semi_major_m), float(cam.semi_minor_m)
            from explorer.refine.torch_linescan import geodetic_to_ecef

            xyz = geodetic_to_ecef(lon, lat, h, a, 1.0 - (b * b) / (a * a)).numpy()
            g = cam.ground_to_image(xyz)
            row, col = np.where(g.status == 0, g.line, np.nan) - 0.5, g.sample - 0.5
        image = ((problem.measured - np.stack([row, col], axis=1)) / problem.sigma_px[:, None]).ravel()
        return np.concatenate([image, (d / problem.ground_sigma_m).ravel()])

    sparsity = lil_matrix((5 * n, p + 3 * n), dtype=np.int8)
    obs = np.arange(n)
    for c in range(2):
        sparsity[2 * obs + c, :p] = 1
        for a in range(3):
            sparsity[2 * obs + c, p + 3 * obs + a] = 1
    for a in range(3):
        sparsity[2 * n + 3 * obs + a, p + 3 * obs + a] = 1
    return least_squares(residuals, np.zeros(p + 3 * n), jac="2-point", jac_sparsity=sparsity.tocsr(),
                         method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12)


def _line_sensor(which: str, n: int, seed: int, repeat: int) -> dict:
    from explorer.refine.bundle import bundle_adjust, lm_iteration

    problem = _line_problem(which, n, seed)
    lm_iteration(problem, loss="linear")  # warm-up
    times, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        lm_iteration(problem, loss="linear")
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    problem.projectors[0].forget_roots()  # the whole adjustment from a cold search
    t0, c0 = time.perf_counter(), time.process_time()
    ours = bundle_adjust(problem, loss="linear")
    whole, whole_cpu = time.perf_counter() - t0, time.process_time() - c0
    t0, c0 = time.perf_counter(), time.process_time()
    peer = _line_scipy(problem)
    peer_s, peer_cpu = time.perf_counter() - t0, time.process_time() - c0
    sigma = ours.parameter_sigma
    return {f"{which}_gcps": int(problem.measured.shape[0]), f"{which}_lm_iteration_s": statistics.median(times),
            f"{which}_lm_iteration_cpu_s": statistics.median(cpu),
            f"{which}_adjustment_s": whole, f"{which}_adjustment_iterations": ours.iterations,
            f"{which}_adjustment_s_per_iteration": whole / max(ours.iterations, 1),
            f"{which}_scipy_least_squares_2point_s": peer_s, f"{which}_scipy_nfev": int(peer.nfev),
            f"{which}_speedup_vs_scipy": peer_s / whole,
            f"{which}_adjustment_cpu_s": whole_cpu, f"{which}_scipy_cpu_s": peer_cpu,
            f"{which}_speedup_vs_scipy_cpu": peer_cpu / whole_cpu,
            f"{which}_max_parameter_difference_in_sigmas": float(np.max(np.abs(ours.parameters[0] - peer.x[:6])
                                                                        / sigma)),
            f"{which}_max_error_vs_truth_in_sigmas": float(np.max(np.abs(ours.parameters[0] - LINE_TRUTH) / sigma)),
            f"{which}_scipy_max_error_vs_truth_in_sigmas": float(np.max(np.abs(peer.x[:6] - LINE_TRUTH) / sigma)),
            f"{which}_sigma0": ours.sigma0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--gcps", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pair-ties", type=int, default=0, help="also time a stereo-pair bundle adjustment")
    ap.add_argument("--line-sensors", action="store_true",
                    help="also time one LM iteration and the whole adjustment against scipy on the rigorous DIMAP "
                         "and WorldView-1 models and the CTX CSM camera")
    ap.add_argument("--line-gcps", type=int, default=0, help="GCPs of the line-scanner problems (default --gcps)")
    ap.add_argument("--only-line-sensors", action="store_true", help="skip the RPC problem")
    ap.add_argument("--sensors", default="",
                    help=f"line scanners, comma-separated (default all: {', '.join(LINE_SENSORS)})")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    doc = _rpc_run(args) if not args.only_line_sensors else {}
    if args.pair_ties:
        doc.update(_pair(args.pair_ties, args.seed))
    if args.line_sensors or args.only_line_sensors:
        for which in (args.sensors.split(",") if args.sensors else LINE_SENSORS):
            doc.update(_line_sensor(which, args.line_gcps or args.gcps, args.seed, args.repeat))
    for key, value in doc.items():
        print(f"{key:>38}: {value:.4g}" if isinstance(value, float) else f"{key:>38}: {value}")
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=1) + "\n")
        print(f"wrote {args.json}")


def _rpc_run(args: argparse.Namespace) -> dict:
    from explorer.refine.bundle import bundle_adjust, lm_iteration

    rpc, problem, truth, scales = _problem(args.gcps, args.seed)
    lm_iteration(problem, loss="linear")  # warm-up: torch import, numba compile
    one, whole, scipy_t = [], [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        lm_iteration(problem, loss="linear")
        one.append(time.perf_counter() - t0)
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        ours = bundle_adjust(problem, loss="linear")
        whole.append(time.perf_counter() - t0)
    for _ in range(max(1, args.repeat // 2)):
        t0 = time.perf_counter()
        peer = _scipy(rpc, problem, scales)
        scipy_t.append(time.perf_counter() - t0)
    ours_theta = ours.parameters[0]
    doc = {
        "gcps": args.gcps, "observations": 5 * args.gcps, "unknowns": 6 + 3 * args.gcps,
        "lm_iteration_s": statistics.median(one),
        "adjustment_s": statistics.median(whole), "adjustment_iterations": ours.iterations,
        "scipy_least_squares_2point_s": statistics.median(scipy_t), "scipy_nfev": int(peer.nfev),
        "speedup_vs_scipy": statistics.median(scipy_t) / statistics.median(whole),
        "max_parameter_difference_in_sigmas": float(np.max(np.abs(ours_theta - peer.x[:6]) / ours.parameter_sigma)),
        "sigma0": ours.sigma0,
        "max_error_vs_truth_in_sigmas": float(np.max(np.abs(ours_theta - truth) / ours.parameter_sigma)),
    }
    return doc


if __name__ == "__main__":
    main()
