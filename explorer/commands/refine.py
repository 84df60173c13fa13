"""``refine``: adjust RPCs (image-space corrections), MPC scenes (exterior offsets and drifts), rigorous
DIMAP/DG models and USGS CSM cameras (position / attitude offsets, drifts, jitter of their tables) to points.

``pushbroom refine SOURCE --gcps gcps.csv [--model shift|affine|poly2] [--check check.csv] --out DIR``
(one image), ``pushbroom refine --dimap X.XML|--dg X.XML|--isd X.json --gcps gcps.csv [--model attitude|
attitude-drift|position-attitude|position-attitude-drift|jitter] --out DIR`` (a line scanner, read by
:func:`explorer.sources.load_source`; the adjusted model is ``DIR/adjusted_model.json``, a sidecar
:func:`explorer.refine.line_adjust.load_adjusted` reads back) and ``pushbroom refine --images A B [C ...]
[--kinds KIND ...] --ties ties.csv [--gcps gcps.csv] [--model MODEL ...] --out DIR`` (bundle adjustment of images
of any kinds, mixed: each file read by :func:`explorer.sources.load_source` as its kind says, each image with its
own correction model; line scanners write ``adjusted_model_K.json``, RPCs ``adjusted_rpc_K.txt``).  Files and results:
:mod:`explorer.refine.adjust`, :mod:`explorer.refine.points_io`.  Pixels are 0-based, integer = pixel centre
(``docs/conventions.md``).
"""

from __future__ import annotations

import argparse
from typing import Any

from explorer.commands._args import choice_list, existing_file, positive_float, positive_float_list, positive_int

__all__ = ["cmd_refine", "register"]

MODELS = ("shift", "affine", "poly2", "attitude", "attitude-drift", "position-attitude", "position-attitude-drift",
          "jitter")
LINE_SOURCES = ("dimap", "dg", "isd")
#: The ``--kinds`` choices (explorer.sources.SENSOR_KINDS; argparse only here).
SENSOR_KINDS = ("auto", "rpc", "scene", "dimap", "dg", "isd")


def _probability(text: str) -> float:
    value = positive_float(text)
    if not value < 1.0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a probability below 1")
    return value


def _non_negative(text: str) -> float:
    from explorer.commands._args import non_negative_float

    return non_negative_float(text)


def cmd_refine(args: argparse.Namespace) -> int:
    """Run the adjustment, write DIR/report.json, points.csv, parameters.csv, adjusted RPC(s); print a summary."""
    from pathlib import Path

    from explorer.errors import InputError
    from explorer.refine.adjust import refine_images
    from explorer.refine.points_io import CONTROL_COLUMNS, TIE_COLUMNS, read_points_csv

    images = list(args.images or [])
    line_given = [(k, getattr(args, k)) for k in LINE_SOURCES if getattr(args, k, None)]
    if len(line_given) > 1 or (line_given and (args.source or images)):
        raise InputError("give one image: SOURCE, --images, " + ", ".join(f"--{k}" for k in LINE_SOURCES)
                         + " exclude each other")
    if args.source and images:
        raise InputError("give either SOURCE (one image) or --images (several), not both")
    kinds = list(args.kinds or ["auto"])
    if args.source:
        images = [args.source]
    if line_given:
        if args.kinds:
            raise InputError(f"--kinds goes with SOURCE or --images, not --{line_given[0][0]}")
        images = [line_given[0][1]]
        kinds = [line_given[0][0]]
    if not images:
        raise InputError("no image: give SOURCE or --images A B ...")
    if len(kinds) == 1:
        kinds = kinds * len(images)
    if len(kinds) != len(images):
        raise InputError(f"--kinds: {len(kinds)} kinds for {len(images)} images (give one for all or one per image)")
    if args.ties and len(images) < 2:
        raise InputError("--ties needs two images or more (--images A B ...)")
    if not args.gcps and not args.ties:
        raise InputError("nothing to adjust to: give --gcps and/or --ties")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {args.out}: exists and is not a folder")
    from explorer.sources import load_source, sensor_kind

    # every image through the one file -> Sensor loader (explorer.sources): an RPC, an MPC scene JSON, a rigorous
    # DIMAP / DG model, a CSM camera; kinds may be mixed, each with its own correction model
    kinds = [sensor_kind(path, kind) for path, kind in zip(images, kinds, strict=True)]
    sensors: list = [load_source(kind, path, stand_in=False).scene for path, kind in zip(images, kinds, strict=True)]
    from explorer.rpc.sensor import RPCSensor

    # an RPC file is refined as the RPC itself (image-space corrections), not through its Sensor wrapper
    sensors = [s.rpc if isinstance(s, RPCSensor) else s for s in sensors]
    model: list[str] | None = list(args.model) if args.model else None
    names = [Path(p).name for p in images]
    if len(set(names)) != len(names):
        names = list(images)
    refinement = refine_images(
        sensors,
        model=model,
        control=read_points_csv(args.gcps, CONTROL_COLUMNS) if args.gcps else None,
        ties=read_points_csv(args.ties, TIE_COLUMNS) if args.ties else None,
        check=read_points_csv(args.check, CONTROL_COLUMNS) if args.check else None,
        names=names,
        sigma_px=args.sigma_px,
        sigma_ground_m=args.sigma_ground,
        loss=args.loss,
        loss_scale=args.loss_scale,
        outlier_probability=args.outlier_probability,
        max_iterations=args.max_iterations,
        image_files=list(images),
        source_kinds=kinds,
        jitter_hz=tuple(args.jitter_hz) if args.jitter_hz else None,
    )
    refinement.write(out)
    if not args.no_panels:
        from explorer.io_atomic import write_text_atomic
        from explorer.panels.refine import refinement_html

        write_text_atomic(out / "panels.html", refinement_html(refinement))
    report = refinement.report()

    def fmt(value: Any) -> str:
        return "-" if value is None else f"{value:.4f}"

    print(f"model {report['model']}: sigma0 {report['sigma0']:.4f}, "
          f"control RMSE {fmt(report['control_rmse_px_before'])} -> {fmt(report['control_rmse_px'])} px, "
          f"check RMSE {fmt(report['check_rmse_px_before'])} -> {fmt(report['check_rmse_px'])} px, "
          f"{report['n_outliers']} outlier(s) of {report['n_observations']}")
    for p in report["parameters"]:
        prefix = f"{p['image']}:" if len(images) > 1 else ""
        print(f"  {prefix}{p['name']:<16} {p['value']:+.6e} +- {p['sigma']:.2e}")
    print(f"wrote {out}/report.json, points.csv, parameters.csv, the adjusted model file(s)"
          + ("" if args.no_panels else " and panels.html (residual vectors, removed field, parameters)"))
    return 0


def register(subparsers: Any) -> None:
    """Add the ``refine`` command to ``subparsers`` (argparse only)."""
    p = subparsers.add_parser(
        "refine", help="adjust RPCs, MPC scenes, rigorous DIMAP/DG models or CSM cameras to control / tie points",
        description="Adjust an image-space correction of an RPC, or the position / attitude of an MPC scene, a "
                    "rigorous DIMAP/DG model or a CSM camera, to control points (one image: SOURCE or --dimap/--dg/"
                    "--isd), or of several images of any kinds to tie points and control points together (--images "
                    "A B ... --ties: a bundle adjustment, image parameters and tie points' ground solved together). "
                    "Levenberg-Marquardt, robust loss. Pixels are 0-based, integer = pixel centre. "
                    "Ties CSV: id,image,row,col (one row per image a point is seen in, two images or more; image = "
                    "the file name or its 0-based position in --images). Control / check CSV: id,lon,lat,h,row,col "
                    "(+ image with several images). Outputs in --out: report.json, points.csv (role control / check / "
                    "tie), parameters.csv, per image the adjusted RPC (adjusted_rpc[_K].txt), scene "
                    "(adjusted_scene[_K].json) or line-scanner sidecar (adjusted_model[_K].json; _K the image's "
                    "position when there are several), panels.html. docs/refine.md.",
    )  # fmt: skip
    p.add_argument("source", nargs="?", type=existing_file,
                   help="the file of one image: an RPC, an MPC scene JSON or an ISD JSON (read as --kinds says; "
                        "auto by default)")
    p.add_argument("--dimap", type=existing_file, metavar="XML",
                   help="Pleiades DIMAP metadata: refine the rigorous model (position / attitude of its tables)")
    p.add_argument("--dg", type=existing_file, metavar="XML", help="DigitalGlobe metadata: refine the rigorous model")
    p.add_argument("--isd", type=existing_file, metavar="JSON", help="USGS CSM line-scan ISD: refine the camera")
    p.add_argument("--jitter-hz", type=positive_float_list, metavar="HZ[,HZ...]",
                   help="--model jitter: frequencies of the attitude harmonics, comma-separated (default 1/T and "
                        "2/T, T the exposure)")
    p.add_argument("--images", nargs="+", type=existing_file, metavar="FILE",
                   help="files of several images (bundle adjustment), read as --kinds says")
    p.add_argument("--kinds", type=choice_list(SENSOR_KINDS, "kind"), metavar="KIND[,KIND...]",
                   help="what SOURCE / each of --images is: one for all or one per image, comma-separated, of "
                        "auto (default: an ISD .json is a CSM camera, another .json an MPC scene, anything else an "
                        "RPC -- a DIMAP or DG XML then gives its vendor RPC), rpc, scene, dimap (the rigorous "
                        "Pleiades/SPOT model), dg (the rigorous WorldView model), isd (a CSM camera)")
    p.add_argument("--gcps", type=existing_file,
                   help="control points CSV: id,lon,lat,h,row,col (+ image with several images)")
    p.add_argument("--ties", type=existing_file,
                   help="tie points CSV: id,image,row,col; one row per image a point is seen in (two or more)")
    p.add_argument("--check", type=existing_file,
                   help="check points CSV: id,lon,lat,h,row,col (+ image); never used as control")
    p.add_argument("--model", type=choice_list(MODELS, "correction model"), default=None,
                   metavar="MODEL[,MODEL...]",
                   help="the correction model, one for all images or one per image, comma-separated: RPC shift, "
                        "affine (default), poly2; MPC scene attitude (default; position and angle offsets), "
                        "attitude-drift (and their rates); rigorous DIMAP/DG model or CSM camera attitude (default; "
                        "roll, pitch, yaw), attitude-drift, position-attitude, position-attitude-drift, jitter "
                        "(docs/refine.md)")
    p.add_argument("--sigma-px", type=positive_float, default=0.5, help="sigma of a measured coordinate, px")
    p.add_argument("--sigma-ground", type=_non_negative, default=0.0,
                   help="sigma of control points' ground coordinates, m (0 = fixed; default)")
    p.add_argument("--loss", choices=("huber", "cauchy", "linear"), default="huber", help="robust loss")
    p.add_argument("--loss-scale", type=positive_float, default=1.5, help="robust loss scale, in sigmas")
    p.add_argument("--outlier-probability", type=_probability, default=0.999,
                   help="chi-square(2) probability beyond which a point is an outlier (default 0.999)")
    p.add_argument("--no-panels", action="store_true", help="do not write DIR/panels.html (the Plotly panels)")
    p.add_argument("--max-iterations", type=positive_int, default=50, help=argparse.SUPPRESS)
    p.add_argument("--out", required=True, help="output folder (created)")
    p.set_defaults(func=cmd_refine)
