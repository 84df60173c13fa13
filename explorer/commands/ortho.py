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

from explorer.commands._args import (
    existing_file,
    finite_float,
    int_in_range,
    output_file,
    positive_float,
    raster_file,
)
from explorer.commands._progress import with_compile_progress
from explorer.commands.simulate import add_scene_arguments, scene_from_args

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


def _rpc_image_to_lonlat(rpc, dem, height):
    import numpy as np

    from explorer.rpc.dem import localization_on_dem

    def fn(row, col):
        if dem is not None:
            lon, lat, _, ok = localization_on_dem(rpc, row, col, dem)
        else:
            lon, lat, ok = rpc.localization(row, col, np.full(row.shape, float(height)))
        return lon, lat

    return fn


def build_ortho_job(args: argparse.Namespace, workdir: Path):
    """(projector, source, grid, pattern or None) for the parsed arguments."""
    import numpy as np

    from explorer.errors import InputError
    from explorer.ortho import (
        RPCProjector,
        SceneProjector,
        SourceImage,
        default_pattern,
        grid_covering,
        render_synthetic_source,
        scene_image_to_lonlat,
    )

    dem = None
    if args.dem:
        from explorer.terrain_io import read_geotiff_dem, read_hgt

        dem = read_hgt(args.dem) if str(args.dem).lower().endswith(".hgt") else read_geotiff_dem(args.dem)
    if args.rpc:
        from explorer.rpc import read_rpc

        rpc = read_rpc(args.rpc)
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
        height = args.height if args.height is not None else (None if dem is not None else rpc.height_offset)
        projector: RPCProjector | SceneProjector = RPCProjector(rpc, shape, height=height, dem=dem)
        r = np.array([0, 0, shape[0] - 1, shape[0] - 1, shape[0] / 2], float)
        c = np.array([0, shape[1] - 1, shape[1] - 1, 0, shape[1] / 2], float)
        h0 = rpc.height_offset if height is None else height
        lon, lat, _ = rpc.localization(r, c, np.full(5, h0))
        to_lonlat = _rpc_image_to_lonlat(rpc, dem, h0 if dem is None else None)
    else:
        scene = scene_from_args(args)
        projector = SceneProjector(scene, args.method, height=args.height, dem=dem)
        shape = scene.shape
        lon, lat, _ = scene.frame.enu_to_geodetic(scene.footprint())
        to_lonlat = scene_image_to_lonlat(scene)
    if dem is not None:
        from explorer.terrain_io import height_grid_of, require_coverage

        # corners and centre at one height: a DEM that misses them all is the wrong DEM; one that misses
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
        src_path = render_synthetic_source(to_lonlat, shape, pattern, workdir / "synthetic_source.npy")
        source = SourceImage(src_path)
    else:
        source = SourceImage(args.image)
        if tuple(source.shape) != tuple(shape):
            raise InputError(
                f"--image {args.image} is {source.shape[0]} x {source.shape[1]} pixels but the scene is "
                f"{shape[0]} x {shape[1]}: not the image of this scene"
            )
    return projector, source, grid, pattern


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
        projector, source, grid, pattern = build_ortho_job(args, tmp)
        t_setup = time.perf_counter() - t0
        arr = ortho_dask_array(projector, source, grid, args.chunk)
        bar = tqdm(total=arr.npartitions, desc="ortho blocks", unit="block")

        def progress(done: int, total: int) -> None:
            bar.n = done
            bar.refresh()

        t0 = time.perf_counter()
        try:
            with atomic_path(args.out) as partial:
                stats = write_orthoimage(arr, grid, partial, scheduler=args.scheduler, progress=progress)
        finally:
            bar.close()
        dt = time.perf_counter() - t0
        pixels = grid.width * grid.height
        report = {"out": args.out, "width": grid.width, "height": grid.height, "epsg": grid.epsg,
                  "gsd_m": grid.gsd, "setup_s": t_setup, "ortho_s": dt,
                  "s_per_1e8_px": dt / pixels * 1e8, **stats}
        if pattern is not None:
            import rasterio

            from explorer.ortho import measure_geolocation

            with rasterio.open(args.out) as ds:  # read by strips of tiles, not as one array
                report["geolocation"] = measure_geolocation(ds, grid, pattern)
        print(json.dumps(report, indent=1))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ortho", help="orthorectify an image (or a synthetic one) to a UTM GeoTIFF on dask")
    add_scene_arguments(p)
    p.add_argument("--rpc", default=None, type=existing_file, help="RPC file (any supported format) instead of a scene")
    p.add_argument("--rpc-shape", default=None, type=image_shape, help="source size ROWSxCOLS for --rpc --synthetic")
    p.add_argument("--dem", default=None, type=raster_file, help="GeoTIFF or .hgt DEM, heights above the ellipsoid")
    p.add_argument("--height", type=finite_float, default=None, help="constant ellipsoidal height, metres")
    p.add_argument("--image", default=None, type=existing_file,
                   help="source image (.npy or any raster rasterio reads); must have the scene's size")
    p.add_argument("--synthetic", action="store_true", help="render a known ground pattern as the source")
    p.add_argument("--gsd", type=positive_float, required=True, help="output pixel size, metres (> 0)")
    p.add_argument("--method", default="exact", help="best-scanline method (a search method)")
    p.add_argument("--chunk", type=int_in_range(16, 65536, "--chunk"), default=2048,
                   help="output chunk size, pixels (16 .. 65536)")
    p.add_argument("--scheduler", default="threads", type=scheduler_name,
                   help="threads | processes | synchronous | local-cluster:N | tcp://host:port")
    p.add_argument("--out", required=True, type=output_file,
                   help="output GeoTIFF (written beside as a hidden partial file, renamed when complete)")
    p.set_defaults(func=with_compile_progress("ortho", cmd_ortho))  # a progress line while kernels compile
