"""``rpc`` command group: ``info``, ``project`` and ``localize`` with RPC files.

Image coordinates in and out are 0-based with integer = pixel centre, whatever the file's own
convention (see ``docs/conventions.md`` and the format table in ``docs/rpc.md``).
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, TextIO

from explorer.commands._args import (
    add_dem_datum_argument,
    existing_file,
    height_m,
    latitude,
    longitude,
    output_file,
    pixel_coordinate,
    raster_file,
)

if TYPE_CHECKING:
    from explorer.rpc import RationalFunctionModel

__all__ = ["cmd_info", "cmd_localize", "cmd_project", "register"]

_CONVENTIONS = {
    "rpc00b_txt": "0-based, integer = pixel centre (RPC00B); read as is",
    "dg_rpb": "0-based, integer = pixel centre (RPC00B); read as is",
    "dg_xml": "0-based, integer = pixel centre (RPC00B); read as is",
    "ossim_geom": "0-based, integer = pixel centre; read as is",
    "gdal_vrt": "0-based, integer = pixel centre (GDAL RPC metadata); read as is",
    "raster_rpc": "0-based, integer = pixel centre (GDAL RPC metadata); read as is",
    "dimap_v2": "1-based in the file; converted to 0-based centre (offsets - 1)",
    "dimap_v1.4": "1-based in the file; converted to 0-based centre (offsets - 1)",
}


def _read_csv(path: str, columns: Sequence[str]) -> tuple[list[dict[str, str]], dict[str, Any]]:
    """Rows of a CSV file and its ``columns`` as float arrays (:func:`explorer.io_input.read_points_csv`)."""
    from explorer.io_input import read_points_csv

    return read_points_csv(path, tuple(columns))


def _write_csv(
    rows: list[dict[str, Any]], fieldnames: Sequence[str], out: str | None
) -> None:
    handle: TextIO
    if out is None:
        handle = sys.stdout
        writer = csv.DictWriter(handle, fieldnames=list(fieldnames))
        writer.writeheader()
        writer.writerows(rows)
        return
    from explorer.io_atomic import atomic_path

    with atomic_path(out) as tmp, open(tmp, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(fieldnames))
        writer.writeheader()
        writer.writerows(rows)


def _fmt(value: Any) -> str:
    return repr(float(value))


def describe(model: RationalFunctionModel) -> str:
    """Multi-line human-readable summary of a model."""
    d = model.domain
    lines = [
        f"file: {model.source_path}",
        f"format: {model.source_format}",
        f"pixel convention: {_CONVENTIONS.get(model.source_format, '0-based pixel centre')}",
        f"inverse (image->ground) coefficients: {'yes' if model.inverse is not None else 'no'}",
        f"image size (rows, cols): {model.image_size if model.image_size else 'unknown'}",
        "offsets / scales:",
        f"  row     {model.row_offset!r} / {model.row_scale!r}",
        f"  col     {model.col_offset!r} / {model.col_scale!r}",
        f"  lon     {model.lon_offset!r} / {model.lon_scale!r}",
        f"  lat     {model.lat_offset!r} / {model.lat_scale!r}",
        f"  height  {model.height_offset!r} / {model.height_scale!r}",
        "validity domain:",
        f"  lon    [{d.lon_min}, {d.lon_max}] deg",
        f"  lat    [{d.lat_min}, {d.lat_max}] deg",
        f"  height [{d.h_min}, {d.h_max}] m",
        f"  row    [{d.row_min}, {d.row_max}]",
        f"  col    [{d.col_min}, {d.col_max}]",
    ]
    if "raster_size" in model.metadata:
        lines.append(f"raster size of the file (rows, cols): {model.metadata['raster_size']}")
    return "\n".join(lines)


def cmd_info(args: argparse.Namespace) -> int:
    """``rpc info FILE``: print format, convention, offsets/scales and validity domain."""
    from explorer.rpc import read_rpc

    print(describe(read_rpc(args.file)))
    return 0


def cmd_project(args: argparse.Namespace) -> int:
    """``rpc project FILE``: ground (lon, lat, h) to image (row, col), 0-based pixel centre."""
    import numpy as np

    from explorer.errors import InputError
    from explorer.rpc import read_rpc

    if not args.points and (args.lon is None or args.lat is None):
        raise InputError("give --lon and --lat (and --h), or --points")
    model = read_rpc(args.file)
    # valid: inside the RPC's validity domain (RationalFunctionModel.ground_validity / image_validity);
    # outside, the row and column are extrapolated numbers and are flagged, not hidden
    if args.points:
        rows, arrays = _read_csv(args.points, ("lon", "lat", "h"))
        row, col, valid = model.projection(arrays["lon"], arrays["lat"], arrays["h"], return_valid=True)
        out_rows = [
            {**r, "row": _fmt(rr), "col": _fmt(cc), "valid": bool(v)} for r, rr, cc, v in zip(rows, row, col, valid,
                                                                                             strict=True)
        ]
        _write_csv(out_rows, [*rows[0].keys(), "row", "col", "valid"], args.out)
    else:
        row, col, valid = model.projection(args.lon, args.lat, args.h, return_valid=True)
        print(f"row={_fmt(row)} col={_fmt(col)} valid={bool(valid)}")
    n_outside = int(np.size(valid) - np.count_nonzero(valid))
    if n_outside:
        print(f"warning: {n_outside} point(s) outside the RPC's validity domain: extrapolated (valid=False)",
              file=sys.stderr)
    return 0


def _load_dem(args: argparse.Namespace) -> Any:
    from explorer.terrain_io import read_dem_above_ellipsoid

    return read_dem_above_ellipsoid(args.dem, datum=args.dem_datum)


def cmd_localize(args: argparse.Namespace) -> int:
    """``rpc localize FILE``: image (row, col) to ground at a height or on a DEM."""
    import numpy as np

    from explorer.errors import InputError
    from explorer.rpc import read_rpc
    from explorer.rpc.dem import localization_on_dem

    if not args.points:
        if args.row is None or args.col is None:
            raise InputError("give --row and --col, or --points")
        if args.dem is None and args.h is None:
            raise InputError("give --h or --dem")
    model = read_rpc(args.file)
    dem = _load_dem(args) if args.dem else None
    if args.points:
        rows, arrays = _read_csv(args.points, ("row", "col") if dem is not None else
                                 ("row", "col", "h"))
    else:
        rows = []
        arrays = {"row": np.array([args.row]), "col": np.array([args.col])}
        if dem is None:
            arrays["h"] = np.array([args.h])
    if dem is not None:
        lon, lat, h, ok = localization_on_dem(model, arrays["row"], arrays["col"], dem)
    else:
        h = arrays["h"]
        lon, lat, ok = model.localization(arrays["row"], arrays["col"], h)
    n_failed = int((~ok).sum())
    if args.points:
        out_rows = []
        for i, record in enumerate(rows):
            extra = {"lon": _fmt(lon[i]), "lat": _fmt(lat[i]), "converged": bool(ok[i])}
            if dem is not None:
                extra["h"] = _fmt(h[i])
            out_rows.append({**record, **extra})
        fields = [*rows[0].keys()]
        fields += [f for f in ("h", "lon", "lat", "converged") if f not in fields and
                   (f != "h" or dem is not None)]
        _write_csv(out_rows, fields, args.out)
    else:
        print(f"lon={_fmt(lon[0])} lat={_fmt(lat[0])} h={_fmt(np.ravel(h)[0])} "
              f"converged={bool(ok[0])}")
    if n_failed:
        print(f"warning: {n_failed} point(s) did not converge (lon/lat NaN)", file=sys.stderr)
    return 0 if n_failed == 0 else 1


def register(subparsers: Any) -> None:
    """Add the ``rpc`` command group (``info``, ``project``, ``localize``) to ``subparsers``.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        From ``ArgumentParser.add_subparsers()``. Each leaf parser sets ``func`` to its handler
        ``(args) -> int``.
    """
    rpc = subparsers.add_parser(
        "rpc", help="RPC files: info, projection, localisation (0-based pixel centre)"
    )
    sub = rpc.add_subparsers(dest="rpc_command", required=True)

    info = sub.add_parser("info", help="format, convention, offsets/scales, validity domain")
    info.add_argument("file", type=existing_file, help="RPC file (any supported format)")
    info.set_defaults(func=cmd_info)

    project = sub.add_parser("project", help="ground (lon, lat, h) -> image (row, col)")
    project.add_argument("file", type=existing_file)
    project.add_argument("--lon", type=longitude, help="degrees")
    project.add_argument("--lat", type=latitude, help="degrees")
    project.add_argument("--h", type=height_m, default=0.0, help="metres above the ellipsoid")
    project.add_argument("--points", type=existing_file, help="CSV with columns lon,lat,h")
    project.add_argument("--out", type=output_file, help="output CSV (default: stdout); adds row,col")
    project.set_defaults(func=cmd_project)

    localize = sub.add_parser("localize", help="image (row, col) -> ground (lon, lat)")
    localize.add_argument("file", type=existing_file)
    localize.add_argument("--row", type=pixel_coordinate)
    localize.add_argument("--col", type=pixel_coordinate)
    localize.add_argument("--h", type=height_m, help="metres above the ellipsoid")
    localize.add_argument("--dem", type=raster_file, help="GeoTIFF or SRTM .hgt DEM to intersect")
    add_dem_datum_argument(localize)
    localize.add_argument("--points", type=existing_file, help="CSV with columns row,col[,h]")
    localize.add_argument("--out", type=output_file, help="output CSV (default: stdout); adds lon,lat,converged")
    localize.set_defaults(func=cmd_localize)
