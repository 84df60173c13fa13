"""``stereo`` command group: ``grids`` (epipolar resampling grids) and ``triangulate`` (matched pixels -> ground).

Pixels in and out are the package's: 0-based, integer = pixel centre (``docs/conventions.md``); the grid files
follow OTB's/shareloc's convention (``docs/stereo.md``).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from explorer.commands._args import (
    add_dem_datum_argument,
    existing_file,
    finite_float,
    height_m,
    output_file,
    positive_float,
    raster_file,
)

__all__ = ["cmd_grids", "cmd_triangulate", "register"]

#: Columns of the matches CSV read by ``stereo triangulate``.
MATCH_COLUMNS = ("left_row", "left_col", "right_row", "right_col")
#: Columns ``stereo triangulate`` adds to each match.
POINT_COLUMNS = ("lon", "lat", "height", "x", "y", "z", "ray_distance_m", "left_reprojection_px",
                 "right_reprojection_px", "valid", "flags")


def _pair(args: argparse.Namespace) -> tuple[Any, Any]:
    from explorer.sources import load_sensor

    return load_sensor(args.left, args.left_kind), load_sensor(args.right, args.right_kind)


def cmd_grids(args: argparse.Namespace) -> int:
    """``stereo grids LEFT RIGHT (--height H | --dem DEM) --step N --out DIR``."""
    from explorer.stereo.grids import epipolar_grids, write_grids

    left, right = _pair(args)
    from explorer.terrain_io import read_dem_above_ellipsoid

    dem = read_dem_above_ellipsoid(args.dem, datum=args.dem_datum) if args.dem else None
    grids = epipolar_grids(left, right, height=args.height, dem=dem, step=args.step,
                           elevation_offset_m=args.elevation_offset)
    paths = write_grids(grids, args.out)
    print(f"epipolar image {grids.epipolar_size[0]} x {grids.epipolar_size[1]} px (rows x columns), "
          f"grid {grids.shape[0]} x {grids.shape[1]} nodes every {grids.step:g} px at "
          f"{'the DEM' if dem is not None else f'{grids.height:g} m'}")
    print(f"mean baseline ratio {grids.mean_baseline_ratio:.6f} px/m, disparity-to-height ratio "
          f"{grids.disparity_to_height_ratio:.6f} m/px")
    for key in ("left", "right", "summary"):
        print(f"wrote {paths[key]}")
    return 0


def cmd_triangulate(args: argparse.Namespace) -> int:
    """``stereo triangulate LEFT RIGHT --matches matches.csv --out points.csv``."""
    import numpy as np

    from explorer.io_atomic import atomic_path
    from explorer.io_input import read_points_csv
    from explorer.stereo.triangulation import triangulate

    left, right = _pair(args)
    rows, arrays = read_points_csv(args.matches, MATCH_COLUMNS)
    out = triangulate(left, right, arrays["left_row"], arrays["left_col"], arrays["right_row"],
                      arrays["right_col"], min_angle_deg=args.min_angle)
    import csv

    fields = list(rows[0].keys()) if rows else list(MATCH_COLUMNS)
    fields += [c for c in POINT_COLUMNS if c not in fields]
    with atomic_path(args.out) as tmp, open(tmp, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        for i, record in enumerate(rows):
            writer.writerow({**record, "lon": repr(float(out.lon[i])), "lat": repr(float(out.lat[i])),
                             "height": repr(float(out.height[i])), "x": repr(float(out.xyz[i, 0])),
                             "y": repr(float(out.xyz[i, 1])), "z": repr(float(out.xyz[i, 2])),
                             "ray_distance_m": repr(float(out.ray_distance_m[i])),
                             "left_reprojection_px": repr(float(out.reprojection_px[i, 0])),
                             "right_reprojection_px": repr(float(out.reprojection_px[i, 1])),
                             "valid": bool(out.valid[i]), "flags": int(out.flags[i])})
    n_bad = int(np.count_nonzero(~out.valid))
    good = out.valid
    if good.any():
        ray = out.ray_distance_m[good]
        print(f"{int(good.sum())} of {len(out)} matches triangulated; ray distance median "
              f"{float(np.median(ray)):.4g} m, max {float(np.max(ray)):.4g} m")
    if n_bad:
        counts = ", ".join(f"{name} {n}" for name, n in out.flag_counts().items())
        print(f"warning: {n_bad} match(es) flagged (valid=False, coordinates NaN): {counts}", file=sys.stderr)
    print(f"wrote {args.out}")
    return 0


#: The ``--left-kind`` / ``--right-kind`` choices (explorer.sources.SENSOR_KINDS; argparse only here).
SENSOR_KINDS = ("auto", "rpc", "scene", "dimap", "dg", "isd")


def _add_pair(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("left", type=existing_file, help="left image geometry (RPC file, scene JSON, DIMAP, DG, ISD)")
    parser.add_argument("right", type=existing_file, help="right image geometry")
    for side in ("left", "right"):
        parser.add_argument(f"--{side}-kind", choices=SENSOR_KINDS, default="auto",
                            help=f"what the {side} file is (default auto: scene/ISD JSON by content, else an RPC)")


def register(subparsers: Any) -> None:
    """Add the ``stereo`` command group (``grids``, ``triangulate``)."""
    stereo = subparsers.add_parser("stereo", help="stereo pairs: epipolar grids, triangulation")
    sub = stereo.add_subparsers(dest="stereo_command", required=True)

    grids = sub.add_parser("grids", help="epipolar resampling grids (OTB/shareloc GeoTIFF)")
    _add_pair(grids)
    where = grids.add_mutually_exclusive_group(required=True)
    where.add_argument("--height", type=height_m, help="grid height, metres above the ellipsoid")
    where.add_argument("--dem", type=raster_file, help="DEM (GeoTIFF or .hgt) under the nodes (RPC left image)")
    add_dem_datum_argument(grids)
    grids.add_argument("--step", type=positive_float, default=30.0, help="grid step, pixels (default 30)")
    grids.add_argument("--elevation-offset", type=positive_float, default=50.0,
                       help="metres either side of the height for the local epipolar direction (default 50)")
    grids.add_argument("--out", required=True, help="output folder (created)")
    grids.set_defaults(func=cmd_grids)

    tri = sub.add_parser("triangulate", help="matched pixels -> ground points (lon, lat, height, ECEF)")
    _add_pair(tri)
    tri.add_argument("--matches", type=existing_file, required=True,
                     help="CSV with columns " + ",".join(MATCH_COLUMNS) + " (0-based pixel centre)")
    tri.add_argument("--out", type=output_file, required=True,
                     help="output CSV: the matches plus " + ",".join(POINT_COLUMNS))
    tri.add_argument("--min-angle", type=finite_float, default=0.01,
                     help="lines of sight meeting at a smaller angle (degrees) are flagged parallel")
    tri.set_defaults(func=cmd_triangulate)
