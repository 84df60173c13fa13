"""Orthorectification benchmark: our RPC orthoimage against GDAL's RPC warp on the same points in one run,
and the scale run.  Writes ``benchmarks/results/ortho.json``.

Usage: python benchmarks/ortho_bench.py [--size 400] [--scale 10000] [--schedulers 1500]
  --size        source crop (pixels) of the real Pleiades RPC scene for the GDAL comparison
  --scale       output size of the synthetic ISB scale run (0 skips it)
  --schedulers  source crop of the threads-vs-processes run on a big DEM (0 skips it): the same job written with
                ``--scheduler threads`` and ``processes`` in one run (blocks/s of each)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from explorer.geometry.frames import LocalFrame
from explorer.methods.adapter import MethodSensor
from explorer.ortho import (
    DEMHeights,
    OrthoGeometry,
    SensorTerrain,
    SourceImage,
    default_pattern,
    gdal_rpc_orthoimage,
    grid_covering,
    measure_geolocation,
    ortho_dask_array,
    render_synthetic_source,
    write_orthoimage,
)
from explorer.presets import build_scene
from explorer.rpc import read_rpc
from explorer.rpc.dem import localization_on_dem
from explorer.rpc.sensor import RPCSensor
from explorer.terrain_io import read_geotiff_dem

ROOT = Path(__file__).resolve().parent.parent
DEM = ROOT / "assets" / "dem" / "MNT_P1BP--2018122638935449CP.tif"
RPC_FILE = ROOT / "tests" / "data" / "rpc" / "PHRDIMAP_P1BP--2018122638935449CP.XML"


def gdal_comparison(n: int, tmp: Path, repeats: int = 3) -> dict:
    rpc = read_rpc(RPC_FILE).with_pixel_shift(-19000, -19500)
    dem = read_geotiff_dem(DEM)
    r = np.array([0, 0, n - 1, n - 1.0])
    c = np.array([0, n - 1, n - 1, 0.0])
    lon, lat, _, _ = localization_on_dem(rpc, r, c, dem)
    epsg = LocalFrame(float(lat.mean()), float(lon.mean())).utm_epsg()
    grid = grid_covering(lon, lat, 0.5, epsg)
    pattern = default_pattern(epsg, 0.5, (grid.x0, grid.y0))

    def to_lonlat(rr, cc):
        lo, la, _, _ = localization_on_dem(rpc, rr, cc, dem)
        return lo, la

    t0 = time.perf_counter()
    src = render_synthetic_source(to_lonlat, (n, n), pattern, tmp / "src.npy")
    t_render = time.perf_counter() - t0
    source = np.load(src)
    projector = OrthoGeometry(RPCSensor(dataclasses.replace(rpc, image_size=(n, n))), DEMHeights(dem))
    np.asarray(ortho_dask_array(projector, SourceImage(src), grid, 512).compute())  # warm (kernels, caches)
    ours_t, gdal_t = [], []
    for _ in range(repeats):  # round robin: both see the same machine load
        t0 = time.perf_counter()
        ours = np.asarray(ortho_dask_array(projector, SourceImage(src), grid, 512).compute())
        ours_t.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        gdal = gdal_rpc_orthoimage(source, rpc, grid, DEM)
        gdal_t.append(time.perf_counter() - t0)
    t_ours, t_gdal = float(np.median(ours_t)), float(np.median(gdal_t))
    return {"source_px": [n, n], "output_px": [grid.height, grid.width], "ours_s": t_ours, "gdal_s": t_gdal,
            "gdal_over_ours": t_gdal / t_ours, "ours_times_s": ours_t, "gdal_times_s": gdal_t,
            "render_source_s": t_render, "load_avg_1min": os.getloadavg()[0],
            "ours_vs_pattern": measure_geolocation(ours, grid, pattern, block=32),
            "gdal_vs_pattern": measure_geolocation(gdal, grid, pattern, block=32),
            "ours_vs_gdal": measure_geolocation(ours, grid, pattern, block=32, reference=gdal)}


def scale_run(n: int, chunk: int, tmp: Path) -> dict:
    scene = build_scene("ISB")
    lon, lat, _ = scene.frame.enu_to_geodetic(scene.footprint())
    epsg = LocalFrame(float(np.mean(lat)), float(np.mean(lon))).utm_epsg()
    g0 = grid_covering(lon, lat, 1.0, epsg)
    gsd = max(g0.width, g0.height) / n
    g1 = grid_covering(lon, lat, gsd, epsg)
    grid = type(g1)(epsg, g1.x0, g1.y0, gsd, n, n)
    pattern = default_pattern(epsg, gsd, (grid.x0, grid.y0))
    geometry = OrthoGeometry(MethodSensor.create(scene, "exact"), SensorTerrain(scene.terrain))
    src = render_synthetic_source(geometry.image_to_lonlat, scene.shape, pattern, tmp / "isb.npy")
    arr = ortho_dask_array(geometry, SourceImage(src), grid, chunk)
    t0 = time.perf_counter()
    stats = write_orthoimage(arr, grid, tmp / "isb.tif", scheduler="threads")
    dt = time.perf_counter() - t0
    return {"output_px": [n, n], "gsd_m": gsd, "chunk": chunk, "seconds": dt, "s_per_1e8_px": dt / n / n * 1e8,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, **stats}


def scheduler_comparison(n: int, chunk: int, tmp: Path, upsample: int = 20) -> dict:
    """The same orthoimage (Pleiades RPC crop on its DEM resampled ``upsample`` x finer: a 34 MB grid, as a big
    DEM tile) written with the threads and the processes scheduler, one after the other in one run."""
    import cloudpickle

    from explorer.terrain_io import GeoDEM

    rpc = read_rpc(RPC_FILE).with_pixel_shift(-19000, -19500)
    dem0 = read_geotiff_dem(DEM)
    a, b, c, d, e, f = dem0.transform
    dem = GeoDEM(np.kron(dem0.heights, np.ones((upsample, upsample))), (a / upsample, b, c, d, e / upsample, f),
                 dem0.crs, "ellipsoid")
    r = np.array([0, 0, n - 1, n - 1.0])
    cc = np.array([0, n - 1, n - 1, 0.0])
    lon, lat, _, _ = localization_on_dem(rpc, r, cc, dem)
    epsg = LocalFrame(float(lat.mean()), float(lon.mean())).utm_epsg()
    grid = grid_covering(lon, lat, 0.5, epsg)
    pattern = default_pattern(epsg, 0.5, (grid.x0, grid.y0))
    geometry = OrthoGeometry(RPCSensor(dataclasses.replace(rpc, image_size=(n, n))), DEMHeights(dem))
    src = render_synthetic_source(geometry.image_to_lonlat, (n, n), pattern, tmp / "sched_src.npy")
    arr = ortho_dask_array(geometry, SourceImage(src), grid, chunk)
    out: dict = {"source_px": [n, n], "output_px": [grid.height, grid.width], "chunk": chunk,
                 "dem_cells": list(dem.heights.shape), "geometry_pickle_mb": len(cloudpickle.dumps(geometry)) / 1e6,
                 "load_avg_1min": os.getloadavg()[0]}
    files = {}
    for scheduler in ("threads", "processes"):
        t0 = time.perf_counter()
        stats = write_orthoimage(arr, grid, tmp / f"sched_{scheduler}.tif", scheduler=scheduler)
        dt = time.perf_counter() - t0
        out[scheduler] = {"seconds": dt, "blocks": stats["blocks"], "blocks_per_s": stats["blocks"] / dt}
        files[scheduler] = (tmp / f"sched_{scheduler}.tif").read_bytes()
    out["identical_files"] = files["threads"] == files["processes"]
    out["threads_over_processes"] = out["processes"]["seconds"] / out["threads"]["seconds"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=400)
    ap.add_argument("--scale", type=int, default=10000)
    ap.add_argument("--chunk", type=int, default=2048)
    ap.add_argument("--schedulers", type=int, default=1500)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "ortho.json")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = {"measured": time.strftime("%Y-%m-%dT%H:%M:%S"),
               "gdal_comparison": gdal_comparison(args.size, Path(tmp), args.repeats)}
        print(json.dumps(out, indent=1), flush=True)
        if args.schedulers:
            out["schedulers"] = scheduler_comparison(args.schedulers, 128, Path(tmp))
            print(json.dumps(out["schedulers"], indent=1), flush=True)
        if args.scale:
            out["scale"] = scale_run(args.scale, args.chunk, Path(tmp))
            print(json.dumps(out["scale"], indent=1))
    if "scale" not in out and args.out.exists():  # keep the last scale run when this one skipped it
        previous = json.loads(args.out.read_text())
        if "scale" in previous:
            out["scale"] = previous["scale"]
    args.out.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
