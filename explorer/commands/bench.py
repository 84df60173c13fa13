"""``pushbroom bench``: benchmark best-scanline methods on presets (see :mod:`explorer.bench`).

Example::

    pushbroom bench --preset WSU,ISB --methods nr,bws,lrm,mlp --scops 10,30,50,100 --scps 5000000 \\
        --seed 0 --json out.json

prints a table and writes ``{"version": 1, "config": {...}, "runs": [{...}, ...]}``.
"""

from __future__ import annotations

import argparse
import json

from explorer.bench_defaults import (
    DEFAULT_MAX_POINTS_SLOW,
    DEFAULT_SCOPS,
    DEFAULT_SCPS,
    DEFAULT_SLOW_SECONDS,
)
from explorer.commands._args import (
    MAX_ATTITUDE_RATE_SCALE,
    MAX_RELIEF_M,
    add_dem_datum_argument,
    existing_file,
    float_in_range,
    method_list,
    name_text,
    non_negative_int,
    output_file,
    positive_float,
    positive_int,
    random_seed,
    raster_file,
)
from explorer.commands._progress import with_compile_progress


def parse_params(items: list[str] | None) -> dict[str, dict]:
    """``["mlp.hidden=[10]", "nr.tol=1e-12"]`` -> ``{"mlp": {"hidden": [10]}, "nr": {"tol": 1e-12}}``.

    Values are JSON when they parse as JSON, else strings.
    """
    from explorer.errors import InputError

    out: dict[str, dict] = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        method, dot, param = key.partition(".")
        if not sep or not dot or not method or not param:
            raise InputError(f"--param must look like METHOD.NAME=VALUE, got {item!r}")
        try:
            parsed = json.loads(value)
        except json.JSONDecodeError:
            parsed = value
        out.setdefault(method.strip(), {})[param.strip()] = parsed
    return out


#: The file sources of ``bench`` (as ``explore``'s, :data:`explorer.sources.SOURCE_KINDS` minus the preset): the
#: option ``--<kind>`` of each and what it benchmarks on, in the order ``--help`` lists them.
FILE_SOURCE_HELP = {
    "rpc": "this RPC file itself (learned methods; the search methods are skipped with the reason, an RPC has no "
           "scanlines; --as-mpc: its resected MPC, a stand-in)",
    "scene": "a scene JSON (any `pushbroom scene` output) instead of a preset",
    "dimap": "a Pleiades DIMAP rigorous model (the truth; its vendor RPC is measured as the stand-in)",
    "dg": "a DigitalGlobe/Maxar XML rigorous model (the truth; its vendor RPC is measured as the stand-in)",
    "isd": "a USGS CSM line-scan ISD: the camera itself (the MPC fitted to it is measured as the stand-in)",
}
FILE_SOURCES = tuple(FILE_SOURCE_HELP)
STAND_IN_POINTS = 50_000
"""SCPs on which the bench measures a file source's stand-in (the model-vs-model map) against the sensor."""


def cmd_bench(args: argparse.Namespace) -> int:
    from explorer.bench import format_table, run_bench
    from explorer.io_atomic import write_text_atomic
    from explorer.memory import check_allocation
    from explorer.points import BYTES_PER_POINT

    params = parse_params(args.param)  # checked before the bench runs
    check_allocation(float(args.scps) * 2 * BYTES_PER_POINT, f"--scps {args.scps}", "lower --scps")
    file_kinds = [k for k in FILE_SOURCES if getattr(args, k, None)]
    if (args.dem or args.as_mpc) and not file_kinds:
        from explorer.errors import InputError

        raise InputError("--dem goes with --rpc, --dimap or --dg" if args.dem else "--as-mpc goes with --rpc")
    if file_kinds:
        from explorer.bench import bench_scene, parse_counts, resolve_methods
        from explorer.sources import source_from_args, table_coverage_text

        methods, counts = resolve_methods(args.methods), parse_counts(args.scops)
        source = source_from_args(args, degree=args.degree, n_gcps=args.gcps)
        print(f"scene: {source.label} ({source.scene.n_rows} x {source.scene.n_columns} pixels)")
        print(f"truth: {source.info.get('truth')}")
        if source.report is not None:
            print(source.report.summary())
        tables = source.info.get("table_coverage")
        if tables:
            print(table_coverage_text(tables))
        coverage = source.info.get("dem_coverage")
        if coverage:
            print(f"DEM covers {100 * coverage['fraction']:.1f} % of the image ({coverage['covered_points']} of "
                  f"{coverage['grid_points']} grid points); {coverage['note']}")
        result = bench_scene(
            source.scene, source.label, methods, counts, args.scps,
            seed=args.seed, max_points_slow=args.max_points_slow, slow_seconds=args.slow_seconds,
            method_params=params,
        )
        result.doc["truth"] = source.info.get("truth")
        result.doc["dem_coverage"] = coverage
        result.doc["table_coverage"] = tables  # None when the ephemeris tables cover every line
        if source.stand_in is not None:
            from explorer.evaluate import evaluate_stand_in
            from explorer.points import simulate_points

            check = simulate_points(source.scene, min(args.scps, STAND_IN_POINTS), kind="scp", seed=args.seed)
            ev, _ = evaluate_stand_in(source.stand_in, check)
            result.doc["stand_in"] = {"model": source.stand_in.label, "n": ev.n_evaluated,
                                      "valid_frac": ev.valid_frac, **{k: v if v == v else None for k, v in (
                                          ("rmse_row_px", ev.rmse_px), ("max_row_px", ev.dr_max_px),
                                          ("rmse_col_px", ev.col_rmse_px))}}
            print(f"stand-in: {source.stand_in.label} vs the sensor on {ev.n_evaluated:,} SCPs: row RMSE "
                  f"{ev.rmse_px:.4g} px, max {ev.dr_max_px:.4g} px; column RMSE {ev.col_rmse_px:.4g} px")
    else:
        result = run_bench(
            args.preset or "WSU", args.methods, args.scops, args.scps, seed=args.seed, relief_m=args.relief,
            relief_seed=args.relief_seed, attitude_rate_scale=args.attitude_rate_scale,
            max_points_slow=args.max_points_slow, slow_seconds=args.slow_seconds,
            method_params=params, progress=not args.no_progress,
        )
    print(format_table(result.runs))
    failed = [r for r in result.runs if r.get("error")]
    skipped = [r for r in result.runs if r.get("skipped")]
    if skipped:
        print(f"\n{len(skipped)} run(s) skipped: the method cannot run on this sensor (reason in the table/JSON)")
    sub = [r for r in result.runs if r.get("subsampled")]
    if sub:
        print(f"\n{len(sub)} run(s) evaluated on a seeded random subsample of the SCPs (column 'SCPs eval'); "
              "'locate_s_full_est' in the JSON scales their time to all the SCPs.")
    warned = [r for r in result.runs if r.get("warnings")]
    if warned:
        print("\nwarnings:")
        for r in warned:
            scops = f" {r['n_scops']} SCOPs" if r["n_scops"] else ""
            for w in r["warnings"]:
                print(f"  {r['preset']} {r['method']}{scops}: {w}")
    if args.json:
        write_text_atomic(args.json, json.dumps(result.doc, indent=1, allow_nan=False) + "\n")
        print(f"wrote {args.json}")
    if failed:
        print(f"{len(failed)} run(s) failed (see 'error' in the table/JSON)")
        return 1
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="benchmark best-scanline methods on presets (the papers' protocol)")
    p.add_argument("--preset", default=None, type=name_text,
                   help="preset ids, comma-separated, or 'all' / 'paper' (default WSU)")
    p.add_argument("--methods", default="all", type=method_list,
                   help="method names, comma-separated, or 'all' (default all)")
    p.add_argument("--scops", default=",".join(map(str, DEFAULT_SCOPS)),
                   help="SCOP counts for learned methods (default 10,30,50,100)")
    p.add_argument("--scps", type=positive_int, default=DEFAULT_SCPS, help="SCPs per preset (default 5000000)")
    p.add_argument("--seed", type=random_seed, default=0)
    p.add_argument("--relief", type=float_in_range(0.0, MAX_RELIEF_M, "--relief", "m"), default=0.0,
                   help="synthetic relief amplitude, metres (default 0)")
    p.add_argument("--relief-seed", type=random_seed, default=0)
    p.add_argument("--attitude-rate-scale",
                   type=float_in_range(0.0, MAX_ATTITUDE_RATE_SCALE, "--attitude-rate-scale"), default=1.0,
                   help="multiplies the presets' body rates (0: orbit-following attitude)")
    p.add_argument("--max-points-slow", type=positive_int, default=DEFAULT_MAX_POINTS_SLOW,
                   help="subsample size for slow methods (default 20000)")
    p.add_argument("--slow-seconds", type=positive_float, default=DEFAULT_SLOW_SECONDS,
                   help="subsample any method whose projected time exceeds this (default 60)")
    p.add_argument("--param", action="append", metavar="METHOD.NAME=VALUE",
                   help="constructor parameter of a method (JSON value), repeatable")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", default=None, metavar="OUT", type=output_file, help="write the runs as JSON")
    for kind, what in FILE_SOURCE_HELP.items():
        p.add_argument(f"--{kind}", default=None, type=existing_file, help=f"benchmark on {what}")
    p.add_argument("--dem", default=None, type=raster_file,
                   help="with --rpc/--dimap/--dg: DEM for the GCP heights and the terrain (GeoTIFF or .hgt)")
    add_dem_datum_argument(p)
    p.add_argument("--as-mpc", action="store_true",
                   help="with --rpc: benchmark on the MPC resected from the RPC (a stand-in: every method runs on it "
                        "and is measured against it; the RPC against it is reported as the stand-in)")
    p.add_argument("--gcps", type=positive_int, default=100,
                   help="with --rpc --as-mpc: about this many GCPs per height layer")
    p.add_argument("--degree", type=non_negative_int, default=3,
                   help="with --rpc/--dimap/--dg: degree of the MPC polynomials (default 3, as explore; the papers: 2)")
    p.set_defaults(func=with_compile_progress("bench", cmd_bench))  # a progress line while kernels compile
