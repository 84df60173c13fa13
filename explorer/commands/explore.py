"""``pushbroom explore``: serve the interactive explorer, or export what it shows (``docs/explorer.md``).

One source: ``--preset ID | --scene FILE | --rpc FILE | --dimap FILE | --dg FILE | --isd FILE``
(``--dem`` with ``--rpc``, ``--dimap``, ``--dg``; ``--adjusted SIDECAR`` with the last three or alone: the
sensor ``pushbroom refine`` adjusted), checked before anything is served; ``--export DIR`` writes
``summary.json``, ``residuals.csv``, ``panels.html``, ``timing.json`` and ``timing.js`` and exits.  Only the
standard library is imported here; the explorer (viser, plotly, the methods) loads inside :func:`cmd_explore`.
"""

from __future__ import annotations

import argparse

from explorer.commands._args import (
    add_dem_datum_argument,
    existing_file,
    method_list,
    name_text,
    port_number,
    positive_float,
    positive_int,
    random_seed,
)


def _check_refine_options(args: argparse.Namespace) -> None:
    """``--gcps`` / ``--check`` only where they act (the live Refinement folder of one image), never ignored."""
    from explorer.errors import InputError

    gcps = getattr(args, "gcps", None)
    if getattr(args, "check", None) is not None and gcps is None:
        raise InputError("--check goes with --gcps (the check points of the refinement)")
    if getattr(args, "adjusted", None) is not None and getattr(args, "pair", None):
        raise InputError("--adjusted goes with one image (--dimap, --dg, --isd or alone), not a --pair")
    if gcps is not None and getattr(args, "pair", None):
        raise InputError("--gcps refines one image, not a --pair (adjust a pair to tie points with "
                         "'pushbroom refine --images A B --ties ties.csv')")
    if gcps is not None and getattr(args, "export", None) is not None:
        raise InputError("--gcps refines live in the explorer and is not part of --export; write the refinement's "
                         "files with 'pushbroom refine SOURCE --gcps FILE --out DIR' (report.json, points.csv, "
                         "panels.html)")


def cmd_explore(args: argparse.Namespace) -> int:
    """Handler of ``explore``: validate the source and address, then export or serve."""
    _check_refine_options(args)
    if getattr(args, "pair", None):  # a stereo pair: its own scene and panels (explorer.app.pair)
        from explorer.app.pair import run_pair

        return run_pair(args)
    for side in ("left", "right"):
        if getattr(args, f"{side}_kind", "auto") != "auto":
            from explorer.errors import InputError

            raise InputError(f"--{side}-kind goes with --pair LEFT RIGHT")
    from explorer.io_atomic import check_output_folder
    from explorer.memory import check_allocation
    from explorer.points import BYTES_PER_POINT

    if args.export is not None:
        check_output_folder(args.export)  # before the source is loaded and the methods run

    n_methods = len(args.methods.split(",")) if args.methods else 4
    check_allocation(float(args.scps) * (BYTES_PER_POINT + EXPLORE_BYTES_PER_SCP_METHOD * n_methods),
                     f"--scps {args.scps} with {n_methods} method(s)", "lower --scps")
    from explorer.app.server import run_explore  # viser and plotly load only for this command

    return run_explore(args)


#: Memory per check point and method of the explorer (residuals, status, the residuals.csv text and the
#: panels' arrays), a generous figure: the guard refuses what cannot fit, it does not promise what can.
EXPLORE_BYTES_PER_SCP_METHOD = 400


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``explore`` command."""
    p = sub.add_parser("explore", help="serve the interactive 3D explorer (viser) and print its URL, or --export",
                       description="Serve the explorer on one source (default: the default preset), or export "
                                   "the panels' numbers with --export DIR.")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--preset", default=None, type=name_text,
                     help="a synthetic preset (default: the presets file's default, WSU)")
    src.add_argument("--scene", default=None, metavar="FILE", help="a scene JSON written by the `scene` commands")
    src.add_argument("--rpc", default=None, metavar="FILE",
                     help="an RPC file: the RPC itself (no scanlines: the learned methods run on it, the search "
                          "methods are shown unavailable; --as-mpc for its resected MPC)")
    src.add_argument("--dimap", default=None, metavar="FILE", help="a Pleiades DIMAP v1.4 PHRDIMAP_*.XML")
    src.add_argument("--dg", default=None, metavar="FILE", help="a DigitalGlobe / Maxar XML (EPH, ATT, GEO, IMD)")
    src.add_argument("--isd", default=None, metavar="FILE", help="a USGS CSM line-scan ISD (JSON)")
    src.add_argument("--pair", nargs=2, default=None, metavar=("LEFT", "RIGHT"),
                     help="a stereo pair (RPC files, scene JSONs or ISDs): both trajectories and footprints, a "
                          "pixel's lines of sight and epipolar curve, the approximation maps (docs/stereo.md)")
    for side in ("left", "right"):
        p.add_argument(f"--{side}-kind", choices=("auto", "rpc", "scene", "dimap", "dg", "isd"), default="auto",
                       help=f"with --pair: what the {side} file is (default auto: scene/ISD JSON by content, else an "
                            "RPC; dimap / dg: the rigorous model of the metadata rather than its vendor RPC)")
    p.add_argument("--adjusted", default=None, metavar="SIDECAR", type=existing_file,
                   help="the adjusted_model.json that 'pushbroom refine --dimap/--dg/--isd' wrote: explore the "
                        "adjusted sensor (every map against it); with --dimap/--dg/--isd FILE that file, alone the "
                        "file the sidecar names beside it; its SHA-256 must match the sidecar's (docs/refine.md)")
    p.add_argument("--as-mpc", action="store_true",
                   help="with --rpc: the MPC resected from the RPC instead of the RPC (a stand-in, labelled so; every "
                        "method runs on it, and the RPC against it is the stand-in map)")
    p.add_argument("--dem", default=None, metavar="DEM",
                   help="DEM for --rpc / --dimap / --dg / --pair (GeoTIFF or SRTM .hgt; vertical datum: "
                        "--dem-datum); points where it has no height are left out and the covered share of the "
                        "image is stated; refused below half of the image")
    add_dem_datum_argument(p)
    p.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=port_number, default=8080,
                   help="port (default 8080; 0 picks a free one; a busy port is an error)")
    p.add_argument("--methods", default=None, type=method_list,
                   help="comma-separated methods (default: lrm,prm,mlp,nr where registered; with --export of a "
                        "file, every learned and generalized method and every exact search method: exact, "
                        "csm-secant, nr, ...; the search methods are unavailable on an RPC)")
    p.add_argument("--scops", type=positive_int, default=100, help="SCOPs (control points) to train on (default 100)")
    p.add_argument("--scps", type=positive_int, default=50_000, help="SCPs (check points) of the maps (default 50000)")
    p.add_argument("--seed", type=random_seed, default=0, help="seed of the point heights and subsamples (default 0)")
    p.add_argument("--export", default=None, metavar="DIR",
                   help="write DIR/summary.json, residuals.csv, panels.html (every SCP; byte-identical on every run "
                        "with the same settings) and timing.json / timing.js (the measured times) and exit without "
                        "serving")
    p.add_argument("--no-sweep", action="store_true",
                   help="leave out the accuracy-vs-SCOPs sweep (it refits every learned method at 8 SCOP counts) "
                        "from the GUI and the export")
    p.add_argument("--gcps", default=None, metavar="CSV",
                   help="control points id,lon,lat,h,row,col: a Refinement folder adjusts the source (RPC, "
                        "scene, preset, rigorous DIMAP/DG model, CSM camera) to them, live, and draws the original "
                        "and adjusted trajectories in 3D (docs/refine.md)")
    p.add_argument("--check", default=None, metavar="CSV", help="check points for --gcps (never adjusted to)")
    p.add_argument("--sigma-px", type=positive_float, default=0.5, help="sigma of a GCP's pixel, px (default 0.5)")
    p.set_defaults(func=cmd_explore)
