"""``pushbroom ortho``: orthorectification over dask (see ``explorer.ortho``)."""

from __future__ import annotations

import argparse
import json
import re
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from explorer.commands._args import (
    add_dem_datum_argument,
    existing_file,
    finite_float,
    int_in_range,
    output_file,
    positive_float,
    raster_file,
)
from explorer.commands._progress import with_compile_progress
from explorer.commands.simulate import FILE_SOURCES, add_file_sources, add_scene_arguments, scene_from_args

if TYPE_CHECKING:
    import numpy as np

    from explorer.ortho import Surface
    from explorer.sensor import Sensor

_SCHEDULER = re.compile(r"^(threads|processes|synchronous|local-cluster(:[1-9][0-9]{0,2})?|tcp://[^\s:/]+:[0-9]{1,5})$")


def scheduler_name(text: str) -> str:
    """A dask scheduler: threads | processes | synchronous | local-cluster[:N] | tcp://host:port."""
    if not _SCHEDULER.match(text):
        raise argparse.ArgumentTypeError(
            f"unknown scheduler {text!r}: use threads, processes, synchronous, local-cluster:N or tcp://HOST:PORT"
        )
    return text


def image_shape(text: str) -> tuple[int, int]:
    """``ROWSxCOLS`` with positive integers."""
    m = re.fullmatch(r"\s*([0-9]{1,7})\s*[xX]\s*([0-9]{1,7})\s*", text)
    if not m or int(m.group(1)) < 2 or int(m.group(2)) < 2:
        raise argparse.ArgumentTypeError(f"{text!r} is not ROWSxCOLS (two integers >= 2, e.g. 40000x40000)")
    return int(m.group(1)), int(m.group(2))


#: Output pixels along each image edge whose ground points outline the footprint (plus the centre).
OUTLINE_POINTS = 9


def _outline(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Image points (pixel edges) along the border of a ``shape`` image, and its centre."""
    import numpy as np

    r1, c1 = shape[0] - 0.5, shape[1] - 0.5
    t = np.linspace(0.0, 1.0, OUTLINE_POINTS)
    rows = np.concatenate([np.full_like(t, -0.5), -0.5 + t * shape[0], np.full_like(t, r1), r1 - t * shape[0],
                           [0.5 * (shape[0] - 1)]])
    cols = np.concatenate([-0.5 + t * shape[1], np.full_like(t, c1), c1 - t * shape[1], np.full_like(t, -0.5),
                           [0.5 * (shape[1] - 1)]])
    return rows, cols


def _surface_option(args: argparse.Namespace) -> str:
    """The option that chose the ground surface (for error messages)."""
    if args.dem:
        return f"--dem {args.dem}"
    if args.height is not None:
        return f"--height {args.height:g}"
    return "the scene's terrain" if not args.rpc else "the RPC's height offset (no --height or --dem)"


def build_ortho_job(args: argparse.Namespace, workdir: Path):
    """(geometry, source, grid, pattern or None) for the parsed arguments.

    The sensor is the scene (through the chosen best-scanline method, :class:`explorer.methods.adapter.
    MethodSensor`) or the RPC (:class:`explorer.rpc.sensor.RPCSensor`); the ground is the DEM (heights above the
    ellipsoid, :func:`explorer.terrain_io.read_dem_above_ellipsoid`), a constant ellipsoidal height or the
    scene's own terrain.  A scene's DEM becomes its own terrain (resampled onto its local frame), so the
    synthetic source and the orthoimage see the same ground.
    """
    import dataclasses

    import numpy as np

    from explorer.errors import InputError
    from explorer.ortho import (
        DEMHeights,
        EllipsoidHeight,
        OrthoGeometry,
        SensorTerrain,
        SourceImage,
        default_pattern,
        grid_covering,
        render_synthetic_source,
    )

    dem = None
    if args.dem:
        from explorer.terrain_io import read_dem_above_ellipsoid

        dem = read_dem_above_ellipsoid(args.dem, datum=args.dem_datum)
    if args.rpc:
        from explorer.rpc import read_rpc
        from explorer.rpc.sensor import RPCSensor

        others = [f"--{k}" for k in (*FILE_SOURCES, "preset") if getattr(args, k, None) is not None]
        if others:
            raise InputError(f"give one source: --rpc and {' and '.join(others)} were given")

        rpc = read_rpc(args.rpc)
        if args.method is not None:
            from explorer.methods import unavailable_reason

            reason = unavailable_reason(args.method, RPCSensor(rpc))  # what the method needs, declared
            if reason is not None:
                raise InputError(f"--method {args.method}: {reason}; ortho projects with the RPC itself without "
                                 "--method")
        if args.image:
            shape = SourceImage(args.image).shape
            if rpc.image_size and tuple(rpc.image_size) != tuple(shape):
                raise InputError(
                    f"--image {args.image} is {shape[0]} x {shape[1]} pixels but the RPC describes a "
                    f"{rpc.image_size[0]} x {rpc.image_size[1]} image"
                )
        elif args.rpc_shape:
            shape = args.rpc_shape
        else:
            raise InputError("--rpc with --synthetic needs --rpc-shape ROWSxCOLS (the source image size)")
        rpc = dataclasses.replace(rpc, image_size=(int(shape[0]), int(shape[1])))
        sensor: Sensor = RPCSensor(rpc)
        if args.height is not None:
            lo, hi = rpc.height_range()
            if not lo <= args.height <= hi:
                raise InputError(f"--height {args.height:g} m is outside the RPC's height range "
                                 f"{lo:g} .. {hi:g} m (its validity domain)")
        surface: Surface = DEMHeights(dem) if dem is not None else EllipsoidHeight(
            float(args.height if args.height is not None else rpc.height_offset))
        h_ref = float(args.height) if args.height is not None else float(rpc.height_offset)
        if args.method is not None:  # a learned method fitted on SCOPs of the RPC itself (it needs only pairs)
            from explorer.methods.adapter import MethodSensor

            lo_h, hi_h = surface.height_range()  # ellipsoidal; the RPC's local frame sits on the ellipsoid (h0 = 0)
            pad = max(100.0, 0.1 * (hi_h - lo_h))
            # (the methods take any sensor; their annotations name the Scene they were written for)
            sensor = MethodSensor.create(cast(Any, sensor), args.method, height_range=(lo_h - pad, hi_h + pad),
                                         scops=args.scops)
    else:
        from explorer.methods.adapter import MethodSensor

        scene = scene_from_args(args)
        body = scene.frame.body
        if not body.is_wgs84:  # the output grid is a UTM zone of WGS84: Earth longitudes and latitudes only
            given = next((f"--{k} {getattr(args, k)}" for k in FILE_SOURCES if getattr(args, k, None)), "the scene")
            raise InputError(f"{given}: the image is on {body.name}; ortho writes WGS84 UTM grids (the Earth) only")
        if dem is not None:
            scene = scene.with_terrain(_dem_as_terrain(scene, dem, str(args.dem)))
            from explorer.scene_checks import check_scene_physics

            check_scene_physics(scene, f"--dem {args.dem}")  # the sensor above this terrain, its rays meeting it
        shape = scene.shape
        if args.height is not None:
            surface = EllipsoidHeight(float(args.height))
            lo_h, hi_h = (args.height - scene.frame.h0_m,) * 2
        else:
            surface = SensorTerrain(scene.terrain)
            lo_h, hi_h = surface.height_range()
        method = args.method or "exact"
        pad = max(100.0, 0.1 * (hi_h - lo_h))  # the learned methods' SCOPs span the heights asked for, and more
        sensor = MethodSensor.create(scene, method, height_range=(lo_h - pad, hi_h + pad), scops=args.scops)
        h_ref = float(args.height) if args.height is not None else scene.terrain.mean_height + scene.frame.h0_m
    geometry = OrthoGeometry(sensor, surface)
    rows, cols = _outline(shape)
    lon, lat = EllipsoidHeight(h_ref).image_to_lonlat(sensor, rows, cols)
    ok = np.isfinite(lon) & np.isfinite(lat)
    if not ok.any():
        raise InputError(f"{_surface_option(args)}: no line of sight of the image reaches the ground at "
                         f"{h_ref:.6g} m above the ellipsoid (is the sensor below it?)")
    lon, lat = lon[ok], lat[ok]
    if dem is not None:
        from explorer.terrain_io import height_grid_of, require_coverage

        # outline and centre at one height: a DEM that misses them all is the wrong DEM; one that misses
        # a corner by metres is not (the pixels it does not cover are no-data in the output)
        dem_grid = height_grid_of(dem)
        if dem_grid is not None:
            require_coverage(dem_grid, lon, lat, "the image footprint", str(args.dem), partial=True)
    from explorer.geometry.frames import LocalFrame

    epsg = LocalFrame(float(np.mean(lat)), float(np.mean(lon))).utm_epsg()
    grid = grid_covering(lon, lat, args.gsd, epsg)
    if grid.width * grid.height > 4_000_000_000:
        raise InputError(f"--gsd {args.gsd} gives a {grid.width} x {grid.height} output: too large")
    if grid.width < 8 or grid.height < 8:
        raise InputError(f"--gsd {args.gsd} m is too coarse for the footprint: the output would be "
                         f"{grid.width} x {grid.height} pixels")
    pattern = None
    if args.synthetic:
        pattern = default_pattern(epsg, args.gsd, (grid.x0, grid.y0))
        src_path = render_synthetic_source(geometry.image_to_lonlat, shape, pattern, workdir / "synthetic_source.npy")
        source = SourceImage(src_path)
    else:
        source = SourceImage(args.image)
        if tuple(source.shape) != tuple(shape):
            raise InputError(
                f"--image {args.image} is {source.shape[0]} x {source.shape[1]} pixels but the scene is "
                f"{shape[0]} x {shape[1]}: not the image of this scene"
            )
    return geometry, source, grid, pattern


#: Largest side of the local grid a scene's DEM is resampled onto (nodes).
MAX_TERRAIN_NODES = 2048


def _dem_as_terrain(scene, dem, label: str):
    """The DEM (ellipsoidal heights) resampled onto the scene's local frame over its footprint (+5 %), at the
    DEM's own spacing (at most :data:`MAX_TERRAIN_NODES` nodes a side)."""
    import numpy as np

    from explorer.errors import InputError
    from explorer.real.from_rpc import terrain_from_dem
    from explorer.terrain_io import height_grid_of, require_coverage

    lo_h, hi_h = float(dem.min), float(dem.max)
    corners = np.vstack([scene.footprint(lo_h - scene.frame.h0_m), scene.footprint(hi_h - scene.frame.h0_m)])
    if not np.isfinite(corners).all():
        raise InputError(f"--dem {label}: the image's lines of sight do not reach the DEM's heights "
                         f"{lo_h:g} .. {hi_h:g} m")
    lo, hi = corners[:, :2].min(0), corners[:, :2].max(0)
    pad = 0.05 * (hi - lo)
    extent = (lo[0] - pad[0], hi[0] + pad[0], lo[1] - pad[1], hi[1] + pad[1])
    grid = height_grid_of(dem)
    if grid is not None:  # a DEM that misses the whole footprint is the wrong DEM (one line naming both extents)
        lon, lat, _ = scene.frame.enu_to_geodetic(corners)
        require_coverage(grid, lon, lat, "the image footprint", f"--dem {label}", partial=True)
    spacing_m = 30.0 if grid is None else abs(grid.dy) * 110_574.0
    cell = max(spacing_m, max(extent[1] - extent[0], extent[3] - extent[2]) / (MAX_TERRAIN_NODES - 1))
    try:
        return terrain_from_dem(dem, scene.frame, extent, cell_m=cell)
    except ValueError as exc:  # no height at any node (GridDEM refuses an empty grid)
        raise InputError(f"--dem {label} has no height over the image footprint ({exc})") from None


WORK_PREFIX = "pushbroom-ortho-"


def remove_stale_work_folders(root: Path) -> list[Path]:
    """Remove the work folders of ortho runs that were killed (SIGKILL, out of memory) in ``root``.

    A run holds an exclusive ``flock`` on the ``.lock`` file of its folder while it lives (:func:`work_folder`);
    a folder whose lock can be taken belongs to a process that no longer exists (the kernel releases the lock
    with the process, in any PID namespace sharing the file system).  Folders without a ``.lock`` are left alone.

    Returns
    -------
    list of Path
        The folders removed.
    """
    import fcntl
    import shutil

    removed = []
    for folder in sorted(root.glob(WORK_PREFIX + "*")):
        try:
            with open(folder / ".lock", "rb") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)  # raises while its run is alive
                shutil.rmtree(folder, ignore_errors=True)
                removed.append(folder)
        except OSError:
            continue
    return removed


@contextmanager
def work_folder() -> Iterator[Path]:
    """A temporary folder for one run, removed when the run ends (normally, on an error, Ctrl-C or SIGTERM).

    The folder is locked (``.lock``, see :func:`remove_stale_work_folders`) so that the next run removes it
    if this process is killed before it can clean up.
    """
    import fcntl
    import shutil

    folder = Path(tempfile.mkdtemp(prefix=WORK_PREFIX))
    lock = open(folder / ".lock.new", "wb")  # locked before it gets the name a sweeper looks for
    try:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        (folder / ".lock.new").rename(folder / ".lock")
        remove_stale_work_folders(folder.parent)
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        lock.close()


def cmd_ortho(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from explorer.errors import InputError
    from explorer.io_atomic import atomic_path
    from explorer.ortho import ortho_dask_array, write_orthoimage

    if not args.synthetic and not args.image:
        raise InputError("give --image IMG or --synthetic")
    if args.synthetic and args.image:
        raise InputError("give either --image or --synthetic, not both")
    with work_folder() as tmp:
        t0 = time.perf_counter()
        geometry, source, grid, pattern = build_ortho_job(args, tmp)
        t_setup = time.perf_counter() - t0
        arr = ortho_dask_array(geometry, source, grid, args.chunk)
        bar = tqdm(total=arr.npartitions, desc="ortho blocks", unit="block")

        def progress(done: int, total: int) -> None:
            bar.n = done
            bar.refresh()

        t0 = time.perf_counter()
        geolocation: dict | None = None
        try:
            with atomic_path(args.out) as partial:  # nothing under the final name unless all of this succeeds
                stats = write_orthoimage(arr, grid, partial, scheduler=args.scheduler, progress=progress)
                if stats["valid_pixels"] == 0:
                    raise InputError(f"{_surface_option(args)}: no output pixel sees the image (every ground point "
                                     f"is off the image or off the DEM); {args.out} not written")
                dt = time.perf_counter() - t0
                if pattern is not None:
                    import rasterio

                    from explorer.ortho import measure_geolocation

                    with rasterio.open(partial) as ds:  # read by strips of tiles, not as one array
                        try:
                            geolocation = measure_geolocation(ds, grid, pattern)
                        except InputError as exc:  # a coarse grid: the orthoimage stands, unmeasured
                            geolocation = {"n_tiles": 0, "note": str(exc)}
        finally:
            bar.close()
        pixels = grid.width * grid.height
        report = {"out": args.out, "width": grid.width, "height": grid.height, "epsg": grid.epsg,
                  "gsd_m": grid.gsd, "setup_s": t_setup, "ortho_s": dt,
                  "s_per_1e8_px": dt / pixels * 1e8, **stats}
        if geolocation is not None:
            report["geolocation"] = geolocation
        print(json.dumps(report, indent=1))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ortho", help="orthorectify an image (or a synthetic one) to a UTM GeoTIFF on dask")
    add_scene_arguments(p)
    add_file_sources(p)  # --isd, --dimap, --dg: the sensor itself (explorer.sources.load_source)
    p.add_argument("--rpc", default=None, type=existing_file, help="RPC file (any supported format) instead of a scene")
    p.add_argument("--rpc-shape", default=None, type=image_shape, help="source size ROWSxCOLS for --rpc --synthetic")
    p.add_argument("--dem", default=None, type=raster_file,
                   help="GeoTIFF or SRTM .hgt DEM (vertical datum: --dem-datum)")
    add_dem_datum_argument(p)
    p.add_argument("--height", type=finite_float, default=None, help="constant ellipsoidal height, metres")
    p.add_argument("--image", default=None, type=existing_file,
                   help="source image (.npy or any raster rasterio reads); must have the scene's size")
    p.add_argument("--synthetic", action="store_true", help="render a known ground pattern as the source")
    p.add_argument("--gsd", type=positive_float, required=True, help="output pixel size, metres (> 0)")
    p.add_argument("--method", default=None,
                   help="best-scanline method on the scene (default exact; a learned one is fitted on --scops SCOPs "
                        "simulated from the scene); with --rpc a learned method fitted on the RPC (default: the RPC "
                        "itself; the search methods need scanlines, which an RPC has none of)")
    p.add_argument("--scops", type=int_in_range(4, 100_000, "--scops"), default=100,
                   help="SCOPs per height layer a learned --method is fitted on (default 100, 3 layers)")
    p.add_argument("--chunk", type=int_in_range(16, 65536, "--chunk"), default=2048,
                   help="output chunk size, pixels (16 .. 65536)")
    p.add_argument("--scheduler", default="threads", type=scheduler_name,
                   help="threads | processes | synchronous | local-cluster:N | tcp://host:port")
    p.add_argument("--out", required=True, type=output_file,
                   help="output GeoTIFF (written beside as a hidden partial file, renamed when complete)")
    p.set_defaults(func=with_compile_progress("ortho", cmd_ortho))  # a progress line while kernels compile
