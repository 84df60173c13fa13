"""``scene`` command group: build pushbroom scenes from real image metadata.

* ``pushbroom scene from-rpc FILE`` -- the papers' pipeline: GCPs through the RPC, MPC space
  resection (``explorer.real.from_rpc``);
* ``pushbroom scene from-dimap FILE`` / ``from-dg FILE`` -- rigorous line-scan models read from
  Pleiades DIMAP v1.4 and DigitalGlobe/Maxar XML metadata, compared with the vendor RPC of the
  same file and converted to an MPC scene (``explorer.real``);
* ``pushbroom scene from-isd FILE`` -- a USGS CSM line-scan camera (ISD written by ALE: Mars CTX,
  HiRISE, LRO NAC, ...) converted to an MPC scene (``explorer.real.csm``).

Every written scene is a regular MPC scene JSON that all commands accept (``--scene``).
Pixel conventions: ``docs/conventions.md``; details and measured numbers: ``docs/real_images.md``.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

from explorer.commands._args import (
    add_dem_datum_argument,
    existing_file,
    int_in_range,
    output_file,
    random_seed,
    raster_file,
)

__all__ = ["cmd_from_dg", "cmd_from_dimap", "cmd_from_isd", "cmd_from_rpc", "register"]


def _write_report(path: str | None, payload: dict) -> None:
    if path:
        from explorer.io_atomic import write_text_atomic

        write_text_atomic(path, json.dumps(payload, indent=1, default=float, allow_nan=False))
        print(f"wrote {path}")


#: Peak memory per GCP of the space resection (two rows of a least-squares Jacobian of up to ~60 unknowns, and
#: the points' ground coordinates and residuals), rounded up.
RESECTION_BYTES_PER_POINT = 2000


def cmd_from_rpc(args: argparse.Namespace) -> int:
    """Handler of ``scene from-rpc``."""
    from explorer.memory import check_allocation
    from explorer.real.from_rpc import scene_from_rpc

    n = int(args.gcps) * int(args.layers) + int(args.check)
    check_allocation(n * RESECTION_BYTES_PER_POINT, f"--gcps {args.gcps} x --layers {args.layers} + --check "
                     f"{args.check} ({n:,} points)", "lower --gcps, --layers or --check")
    t0 = time.perf_counter()
    scene, report = scene_from_rpc(
        args.file, dem=args.dem, n_gcps=args.gcps, preset=args.preset, layers=args.layers,
        dem_datum=args.dem_datum, degree=args.degree, column_terms=args.column_terms,
        n_check=args.check, seed=args.seed, method=args.method,
        estimate_focal=True if args.estimate_focal else None,
    )  # fmt: skip
    from explorer.scene_checks import check_scene_physics

    check_scene_physics(scene, str(args.file) if args.dem is None else f"{args.file} with DEM {args.dem}")
    dt = time.perf_counter() - t0
    print(report.summary())
    print(f"  time {dt:.2f} s")
    if args.per_point:
        print("  GCP residuals (row, col) px:")
        for dr, dc in zip(report.gcp_row_residual_px, report.gcp_col_residual_px, strict=True):
            print(f"    {dr:+.5f} {dc:+.5f}")
    if args.out:
        scene.save(args.out)
        print(f"wrote {args.out}")
    _write_report(args.report, report.to_dict(per_point=True))
    return 0


#: Peak memory per comparison point of ``--compare-points x --compare-layers`` (measured: ~2.3 KB on the
#: Pleiades DIMAP with aberration, refraction and the RPC projection).
COMPARE_BYTES_PER_POINT = 3000


def _rigorous(args: argparse.Namespace, kind: str) -> int:
    from explorer.memory import check_allocation
    from explorer.real.compare import compare_with_rpc

    if not args.no_compare:  # refused before the metadata is even read
        n = int(args.compare_points) * int(args.compare_layers)
        check_allocation(n * COMPARE_BYTES_PER_POINT,
                         f"--compare-points {args.compare_points} x --compare-layers {args.compare_layers} "
                         f"({n:,} points)", "lower --compare-points or --compare-layers (or --no-compare)")
    t0 = time.perf_counter()
    if kind == "dimap":
        from explorer.real.dimap import rigorous_scene_from_dimap

        model, calibration = rigorous_scene_from_dimap(
            args.file, aberration=args.aberration, refraction=args.refraction,
            look_angle_degree=args.look_degree,
            attitude_smoothing=None if args.attitude_smoothing < 0 else args.attitude_smoothing,
        )  # fmt: skip
        print(calibration.summary())
    else:
        from explorer.real.worldview import rigorous_scene_from_dg

        model = rigorous_scene_from_dg(args.file, aberration=args.aberration, refraction=args.refraction)
    from explorer.scene_checks import check_scene_physics

    check_scene_physics(model, str(args.file))
    print(model.describe())
    payload: dict[str, Any] = {"model": model.describe_dict()}
    if not args.no_compare:
        cmp = compare_with_rpc(model, n=args.compare_points, layers=args.compare_layers)
        print(cmp.summary())
        payload["rpc_comparison"] = cmp.to_dict()
    if args.out:
        mpc, fit = model.to_mpc_scene(degree=args.degree)
        check_scene_physics(mpc, f"{args.file} (its MPC scene)")
        print(fit.summary())
        payload["mpc_fit"] = fit.to_dict()
        mpc.save(args.out)
        print(f"wrote {args.out} (MPC scene, degree {args.degree})")
    if args.rigorous_out:
        model.save(args.rigorous_out)
        print(f"wrote {args.rigorous_out} (rigorous line-scan scene; load with explorer.real.load_scene)")
    print(f"  time {time.perf_counter() - t0:.2f} s")
    _write_report(args.report, payload)
    return 0


def cmd_from_dimap(args: argparse.Namespace) -> int:
    """Handler of ``scene from-dimap``."""
    return _rigorous(args, "dimap")


def cmd_from_dg(args: argparse.Namespace) -> int:
    """Handler of ``scene from-dg``."""
    return _rigorous(args, "dg")


def cmd_from_isd(args: argparse.Namespace) -> int:
    """Handler of ``scene from-isd``."""
    from explorer.real.csm import read_isd, scene_from_camera

    t0 = time.perf_counter()
    camera = read_isd(args.file, interpolation=args.interpolation)
    print(camera.describe())
    scene = scene_from_camera(camera, degree=args.degree, n_check=args.check, seed=args.seed,
                              harmonics=args.harmonics)
    from explorer.scene_checks import check_scene_physics

    check_scene_physics(scene, f"{args.file} (its MPC scene)")
    fit = scene.metadata.get("csm_fit")
    if fit:
        print(f"MPC fit to the CSM camera ({fit['n']} check points): row max {fit['row_max_px']:.3g} px, "
              f"RMS {fit['row_rms_px']:.3g} px; column max {fit['col_max_px']:.3g} px, RMS {fit['col_rms_px']:.3g} px")
    if args.out:
        scene.save(args.out)
        print(f"wrote {args.out} (MPC scene, degree {args.degree}; row = line - 0.5, col = sample - 0.5)")
    print(f"  time {time.perf_counter() - t0:.2f} s")
    _write_report(args.report, {"camera": camera.describe(), "csm_fit": fit, "csm": scene.metadata["csm"]})
    return 0


def _rigorous_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", type=existing_file, help="metadata file")
    p.add_argument("--out", type=output_file, help="MPC scene JSON (polynomials fitted to the rigorous model)")
    p.add_argument("--rigorous-out", type=output_file,
                   help="rigorous line-scan scene JSON (explorer.real.load_scene)")
    p.add_argument("--degree", type=int_in_range(0, 9, "--degree"), default=3,
                   help="MPC polynomial degree of --out (default 3)")
    p.add_argument("--no-compare", action="store_true", help="skip the comparison with the file's RPC")
    p.add_argument("--compare-points", type=int_in_range(4, 1_000_000, "--compare-points"), default=400,
                   help="image points per height layer")
    p.add_argument("--compare-layers", type=int_in_range(1, 100, "--compare-layers"), default=5,
                   help="height layers over the RPC's range")
    p.add_argument("--report", type=output_file, help="write the numbers as JSON")


def _light_path_arguments(p: argparse.ArgumentParser, *, default: bool, aberration_note: str,
                          refraction_note: str) -> None:
    """``--aberration`` / ``--refraction``: the line-of-sight corrections of a rigorous model, on or off."""
    for flag, what, note in (("--aberration", "the aberration of light", aberration_note),
                             ("--refraction", "atmospheric refraction", refraction_note)):
        p.add_argument(flag, action=argparse.BooleanOptionalAction, default=default, help=f"model {what} ({note})")


def register(subparsers: Any) -> None:
    """Add the ``scene`` command group (``from-rpc``, ``from-dimap``, ``from-dg``, ``from-isd``)."""
    scene = subparsers.add_parser("scene", help="build scenes from real image metadata (RPC, DIMAP, DG XML)")
    sub = scene.add_subparsers(dest="scene_command", required=True)

    p = sub.add_parser("from-rpc", help="MPC scene from an RPC file by space resection (the papers' pipeline)")
    p.add_argument("file", type=existing_file, help="RPC file (any format `pushbroom rpc info` reads)")
    p.add_argument("--dem", type=raster_file,
                   help="DEM (GeoTIFF or SRTM .hgt) for the GCP heights and the scene terrain")
    add_dem_datum_argument(p)
    p.add_argument("--gcps", type=int_in_range(4, 1_000_000, "--gcps"), default=100,
                   help="about this many GCPs per height layer (default 100; at least 4, a 2 x 2 grid)")
    p.add_argument("--layers", type=int_in_range(1, 100, "--layers"), default=3,
                   help="GCP height layers over the RPC's validity range when no DEM is given (default 3)")
    p.add_argument("--preset", help="preset id for the interior orientation (focal length) and altitude")
    p.add_argument("--estimate-focal", action="store_true", help="estimate the focal length even with --preset")
    p.add_argument("--degree", type=int_in_range(0, 9, "--degree"), default=2,
                   help="MPC polynomial degree (default 2 as in the papers; 3 for agile Pleiades/SPOT)")
    p.add_argument("--column-terms", type=int_in_range(0, 5, "--column-terms"), default=0,
                   help="non-uniform detector spacing terms (1 for products resampled across track, e.g. IKONOS)")
    p.add_argument("--check", type=int_in_range(0, 1_000_000, "--check"), default=400,
                   help="about this many check points (0: none)")
    p.add_argument("--seed", type=random_seed, default=0, help="seed of the check-point heights")
    p.add_argument("--method", choices=("lm", "trf"), default="lm", help="least-squares method")
    p.add_argument("--per-point", action="store_true", help="print every GCP residual")
    p.add_argument("--out", type=output_file, help="output scene JSON")
    p.add_argument("--report", type=output_file, help="write the resection report (with per-point residuals) as JSON")
    p.set_defaults(func=cmd_from_rpc)

    p = sub.add_parser("from-dimap", help="rigorous Pleiades model from a DIMAP v1.4 PHRDIMAP_*.XML")
    _rigorous_arguments(p)
    p.add_argument("--look-degree", type=int_in_range(0, 9, "--look-degree"), default=3,
                   help="degree of the look-angle polynomials calibrated on the RPC (default 3)")
    p.add_argument("--attitude-smoothing", type=int_in_range(-1, 9, "--attitude-smoothing"), default=3,
                   help="degree of the polynomial replacing the attitude samples (perfect sensor; -1: raw)")
    _light_path_arguments(p, default=False, aberration_note="default off for Pleiades",
                          refraction_note="default off for Pleiades")
    p.set_defaults(func=cmd_from_dimap)

    p = sub.add_parser("from-dg",
                       help="rigorous WorldView/QuickBird model from a DigitalGlobe XML (EPH, ATT, GEO, IMD)")
    _rigorous_arguments(p)
    _light_path_arguments(p, default=True, aberration_note="default on: 25 px without it on WV1",
                          refraction_note="default on: 2 px across track without it on WV1")
    p.set_defaults(func=cmd_from_dg)

    p = sub.add_parser("from-isd",
                       help="MPC scene from a USGS CSM line-scan ISD (ALE JSON: Mars CTX, HiRISE, LRO NAC, ...)")
    p.add_argument("file", type=existing_file, help="image support data (JSON)")
    p.add_argument("--out", type=output_file, help="output scene JSON")
    p.add_argument("--degree", type=int_in_range(1, 9, "--degree"), default=3,
                   help="degree of the position and attitude polynomials (default 3)")
    p.add_argument("--harmonics", type=int_in_range(0, 200, "--harmonics"), default=0,
                   help="attitude sinusoids per angle fitted to what the polynomials leave (default 0; "
                        "CTX: 20 brings the fit from 0.5 to 0.15 px, slower methods)")
    p.add_argument("--interpolation", choices=("usgscsm", "tables"), default="usgscsm",
                   help="usgscsm's resampled state (default) or the ISD's tables as given")
    p.add_argument("--check", type=int_in_range(0, 1_000_000, "--check"), default=2000,
                   help="CSM check points on which the scene's fit is reported (0: none)")
    p.add_argument("--seed", type=random_seed, default=0, help="seed of the check points")
    p.add_argument("--report", type=output_file, help="write the camera description and the fit as JSON")
    p.set_defaults(func=cmd_from_isd)
