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
    existing_file,
    method_list,
    non_negative_float,
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
    "rpc": "the scene resected from this RPC file instead of a preset",
    "scene": "a scene JSON (any `pushbroom scene` output) instead of a preset",
    "dimap": "the MPC scene of a Pleiades DIMAP rigorous model",
    "dg": "the MPC scene of a DigitalGlobe/Maxar XML rigorous model",
    "isd": "the MPC scene of a USGS CSM line-scan ISD",
}
FILE_SOURCES = tuple(FILE_SOURCE_HELP)


def cmd_bench(args: argparse.Namespace) -> int:
    from explorer.bench import format_table, run_bench
    from explorer.io_atomic import write_text_atomic
    from explorer.memory import check_allocation
    from explorer.points import BYTES_PER_POINT

    params = parse_params(args.param)  # checked before the bench runs
    check_allocation(float(args.scps) * 2 * BYTES_PER_POINT, f"--scps {args.scps}", "lower --scps")
    file_kinds = [k for k in FILE_SOURCES if getattr(args, k, None)]
    if args.dem and not file_kinds:
        from explorer.errors import InputError

        raise InputError("--dem goes with --rpc, --dimap or --dg")
    if file_kinds:
        from explorer.bench import bench_scene, parse_counts, resolve_methods
        from explorer.sources import source_from_args

        methods, counts = resolve_methods(args.methods), parse_counts(args.scops)
        source = source_from_args(args, degree=args.degree, n_gcps=args.gcps)
        print(f"scene: {source.label} ({source.scene.n_rows} x {source.scene.n_columns} pixels)")
        if source.report is not None:
            print(source.report.summary())
        result = bench_scene(
            source.scene, source.label, methods, counts, args.scps,
            seed=args.seed, max_points_slow=args.max_points_slow, slow_seconds=args.slow_seconds,
            method_params=params,
        )
    else:
        result = run_bench(
            args.preset or "WSU", args.methods, args.scops, args.scps, seed=args.seed, relief_m=args.relief,
            relief_seed=args.relief_seed, attitude_rate_scale=args.attitude_rate_scale,
            max_points_slow=args.max_points_slow, slow_seconds=args.slow_seconds,
            method_params=params, progress=not args.no_progress,
        )
    print(format_table(result.runs))
    failed = [r for r in result.runs if r.get("error")]
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
    p.add_argument("--preset", default=None, help="preset ids, comma-separated, or 'all' / 'paper' (default WSU)")
    p.add_argument("--methods", default="all", type=method_list,
                   help="method names, comma-separated, or 'all' (default all)")
    p.add_argument("--scops", default=",".join(map(str, DEFAULT_SCOPS)),
                   help="SCOP counts for learned methods (default 10,30,50,100)")
    p.add_argument("--scps", type=positive_int, default=DEFAULT_SCPS, help="SCPs per preset (default 5000000)")
    p.add_argument("--seed", type=random_seed, default=0)
    p.add_argument("--relief", type=non_negative_float, default=0.0,
                   help="synthetic relief amplitude, metres (default 0)")
    p.add_argument("--relief-seed", type=random_seed, default=0)
    p.add_argument("--attitude-rate-scale", type=non_negative_float, default=1.0,
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
    p.add_argument("--gcps", type=positive_int, default=100, help="with --rpc: about this many GCPs per height layer")
    p.add_argument("--degree", type=non_negative_int, default=3,
                   help="with --rpc/--dimap/--dg: degree of the MPC polynomials (default 3, as explore; the papers: 2)")
    p.set_defaults(func=with_compile_progress("bench", cmd_bench))  # a progress line while kernels compile
