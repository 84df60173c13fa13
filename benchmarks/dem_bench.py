"""Image to ground on terrain: ours against GDAL's RPC transformer (``RPC_DEM``) in one process, scaling in the
number of points, and simulation on a rigorous scene with relief against ``exact`` locating the points back.

Writes ``benchmarks/results/dem.json``.

Usage: python benchmarks/dem_bench.py [--points 100000] [--repeats 7] [--rigorous-points 2000000]
       [--rpc FILE --dem DEM [--datum ellipsoid|geoid]]   (another RPC and DEM than the Pleiades pair)
       [--synthetic-dem 1,3]   (also the Pleiades RPC on seeded rough DEMs of 1,700 m relief at these spacings,
                                arc seconds, as SRTM tiles are: fractal terrain, a mountain, a 30 x 60-node void)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RPC_FILE = ROOT / "tests" / "data" / "rpc" / "PHRDIMAP_P1BP--2018122638935449CP.XML"
DEM_FILE = ROOT / "assets" / "dem" / "MNT_P1BP--2018122638935449CP.tif"


def timed(fn, repeats: int) -> tuple[float, list[float], object]:
    times = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times, out


def gdal_rpc(rpc):
    from rasterio.rpc import RPC

    return RPC(height_off=rpc.height_offset, height_scale=rpc.height_scale, lat_off=rpc.lat_offset,
               lat_scale=rpc.lat_scale, line_den_coeff=list(rpc.row_den), line_num_coeff=list(rpc.row_num),
               line_off=rpc.row_offset, line_scale=rpc.row_scale, long_off=rpc.lon_offset, long_scale=rpc.lon_scale,
               samp_den_coeff=list(rpc.col_den), samp_num_coeff=list(rpc.col_num), samp_off=rpc.col_offset,
               samp_scale=rpc.col_scale)


def metres(lon_a, lat_a, lon_b, lat_b):
    east = (lon_a - lon_b) * np.cos(np.radians(lat_b)) * 111_320.0
    north = (lat_a - lat_b) * 110_574.0
    return np.hypot(east, north)


def rpc_vs_gdal(rpc_path: Path, dem_path: Path, datum: str, n: int, repeats: int, seed: int = 0) -> dict:
    from rasterio.transform import RPCTransformer

    from explorer.real.from_rpc import load_dem, rpc_image_size
    from explorer.rpc import read_rpc
    from explorer.rpc.dem import localization_on_dem

    rpc = read_rpc(rpc_path)
    dem = load_dem(dem_path, datum=datum)
    gdal_dem = str(dem_path)
    if getattr(dem, "geoid", None) is not None:
        # GDAL needs heights above the ellipsoid in the file: write the converted grid once
        import rasterio

        grid = dem.height_grid()
        gdal_dem = str(Path("/tmp") / f"dem_bench_ellipsoidal_{os.getpid()}.tif")
        with rasterio.open(gdal_dem, "w", driver="GTiff", width=grid.heights.shape[1],
                           height=grid.heights.shape[0], count=1, dtype="float64", crs="EPSG:4326",
                           transform=rasterio.Affine(*dem.dem.transform), nodata=np.nan) as dst:
            dst.write(grid.heights, 1)
    rows, cols = rpc_image_size(rpc)
    rng = np.random.default_rng(seed)
    row = rng.uniform(0, rows - 1, n)
    col = rng.uniform(0, cols - 1, n)
    localization_on_dem(rpc, row[:100], col[:100], dem)  # fit the inverse, load the kernels
    g = gdal_rpc(rpc)
    zeros = np.zeros(n)
    results = {}
    with RPCTransformer(g, RPC_DEM=gdal_dem) as transformer, \
            RPCTransformer(g, RPC_DEM=gdal_dem, RPC_PIXEL_ERROR_THRESHOLD=1e-7) as tight:
        transformer.xy(row[:100], col[:100], zeros[:100], offset="center")
        # round robin, so both see the same machine load
        ours_t, gdal_t, ours_cpu, gdal_cpu = [], [], [], []
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            lon, lat, h, ok, flags = localization_on_dem(rpc, row, col, dem, return_flags=True)
            ours_t.append(time.perf_counter() - t0)
            ours_cpu.append(time.process_time() - c0)
            t0, c0 = time.perf_counter(), time.process_time()
            g_lon, g_lat = transformer.xy(row, col, zeros, offset="center")
            gdal_t.append(time.perf_counter() - t0)
            gdal_cpu.append(time.process_time() - c0)
        g_lon, g_lat = np.asarray(g_lon), np.asarray(g_lat)
        t_lon, t_lat = (np.asarray(v) for v in tight.xy(row, col, zeros, offset="center"))
    both = ok & np.isfinite(g_lon) & np.isfinite(g_lat) & np.isfinite(t_lon) & np.isfinite(t_lat)
    d = metres(g_lon, g_lat, lon, lat)[both]
    d_tight = metres(t_lon, t_lat, lon, lat)[both]
    r2, c2 = rpc.projection(lon[ok], lat[ok], h[ok], backend="numpy")
    surface = np.abs(dem.height(lon[ok], lat[ok]) - h[ok])
    ours, gdal = statistics.median(ours_t), statistics.median(gdal_t)
    results.update({
        "rpc": rpc_path.name, "dem": dem_path.name, "datum": datum, "points": n, "seed": seed,
        "ours_s": ours, "gdal_s": gdal, "gdal_over_ours": gdal / ours, "ours_times_s": ours_t, "gdal_times_s": gdal_t,
        "ours_cpu_s": statistics.median(ours_cpu), "gdal_cpu_s": statistics.median(gdal_cpu),
        "best_ours_s": min(ours_t), "best_gdal_s": min(gdal_t),
        "best_gdal_over_best_ours": min(gdal_t) / min(ours_t),
        "ok_fraction": float(ok.mean()),
        "flags": {str(k): int(v) for k, v in zip(*np.unique(flags, return_counts=True), strict=True)},
        "gdal_default_max_m": float(np.nanmax(d)), "gdal_default_p99_m": float(np.nanpercentile(d, 99)),
        "gdal_tight_max_m": float(np.nanmax(d_tight)),
        "gdal_finite_fraction": float(np.isfinite(g_lon).mean()),
        "compared_fraction": float(both.mean()),
        "ours_ok_gdal_not": int((ok & ~np.isfinite(g_lon)).sum()),
        "gdal_finite_ours_not": int((~ok & np.isfinite(g_lon)).sum()),
        "round_trip_max_px": float(np.max(np.hypot(r2 - row[ok], c2 - col[ok]))),
        "on_surface_max_m": float(np.max(surface)),
    })
    return results


def synthetic_dem(path: Path, rpc, arcsec: float, seed: int = 0, low: float = 200.0, high: float = 1900.0) -> Path:
    """Write a seeded rough DEM (EPSG:4326, float32, no-data -32768) over the RPC's footprint: power-law terrain
    (amplitude ~ 1/k^2) plus a mountain, scaled to ``low``..``high`` metres, with a 30 x 60-node void."""
    import rasterio

    from explorer.geometry.terrain import mountain_heights

    d = arcsec / 3600.0
    lon0, lon1 = rpc.lon_offset - rpc.lon_scale - 0.02, rpc.lon_offset + rpc.lon_scale + 0.02
    lat0, lat1 = rpc.lat_offset - rpc.lat_scale - 0.02, rpc.lat_offset + rpc.lat_scale + 0.02
    nx, ny = int(np.ceil((lon1 - lon0) / d)) + 1, int(np.ceil((lat1 - lat0) / d)) + 1
    z = mountain_heights((ny, nx), low, high, seed)
    z[ny // 3: ny // 3 + 30, nx // 3: nx // 3 + 60] = -32768.0
    with rasterio.open(path, "w", driver="GTiff", width=nx, height=ny, count=1, dtype="float32", crs="EPSG:4326",
                       transform=rasterio.Affine(d, 0, lon0 - d / 2, 0, -d, lat1 + d / 2), nodata=-32768.0) as dst:
        dst.write(z.astype(np.float32), 1)
    return path


def rpc_scaling(repeats: int) -> list[dict]:
    from explorer.rpc import read_rpc
    from explorer.rpc.dem import localization_on_dem
    from explorer.terrain_io import read_geotiff_dem

    rpc = read_rpc(RPC_FILE)
    dem = read_geotiff_dem(DEM_FILE)
    rows, cols = rpc.image_size
    out = []
    for n in (1_000, 10_000, 100_000, 1_000_000):
        rng = np.random.default_rng(1)
        row, col = rng.uniform(0, rows - 1, n), rng.uniform(0, cols - 1, n)
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        t, _, _ = timed(lambda row=row, col=col: localization_on_dem(rpc, row, col, dem), repeats)
        rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        out.append({"points": n, "s": t, "ns_per_point": t / n * 1e9, "peak_rss_mb": rss1 / 1024,
                    "rss_growth_mb": (rss1 - rss0) / 1024})
    return out


def rigorous(n: int, repeats: int) -> dict:
    from explorer.methods import create
    from explorer.points import simulate_points
    from explorer.presets import build_scene

    scene = build_scene("agile", relief_m=500.0)
    simulate_points(scene, 1000, kind="scp")
    t_sim, _, points = timed(lambda: simulate_points(scene, n, kind="scp"), repeats)
    method = create("exact", scene)
    method.ground_to_image(points.ground[:1000])
    t_exact, _, res = timed(lambda: method.ground_to_image(points.ground), repeats)
    dr = np.hypot(res.row - points.row, res.col - points.col)
    return {"scene": "agile", "relief_m": 500.0, "requested_points": n, "points": len(points),
            "simulate_s": t_sim, "exact_locate_s": t_exact, "simulate_over_exact": t_sim / t_exact,
            "round_trip_max_px": float(np.max(dr)), "valid_fraction": float(np.mean(res.valid))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--rigorous-points", type=int, default=2_000_000)
    parser.add_argument("--rpc", type=Path, default=None)
    parser.add_argument("--dem", type=Path, default=None)
    parser.add_argument("--datum", default="ellipsoid")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "dem.json")
    parser.add_argument("--skip-scaling", action="store_true")
    parser.add_argument("--synthetic-dem", default="", help="comma-separated DEM spacings, arc seconds")
    args = parser.parse_args()
    import numba

    record = {"measured": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": platform.machine(),
              "cpus": os.cpu_count(), "numba_threads": numba.get_num_threads(),
              "load_before": os.getloadavg()[0]}
    record["pleiades_vs_gdal"] = rpc_vs_gdal(RPC_FILE, DEM_FILE, "ellipsoid", args.points, args.repeats)
    if args.rpc is not None and args.dem is not None:
        record["other_vs_gdal"] = rpc_vs_gdal(args.rpc, args.dem, args.datum, args.points, args.repeats)
    for arcsec in (float(v) for v in args.synthetic_dem.split(",") if v.strip()):
        import tempfile

        from explorer.rpc import read_rpc

        with tempfile.TemporaryDirectory() as tmp:
            path = synthetic_dem(Path(tmp) / f"synthetic_{arcsec:g}arcsec.tif", read_rpc(RPC_FILE), arcsec)
            record[f"synthetic_{arcsec:g}arcsec_vs_gdal"] = rpc_vs_gdal(RPC_FILE, path, "ellipsoid", args.points,
                                                                       args.repeats)
    if not args.skip_scaling:
        record["rpc_scaling"] = rpc_scaling(max(3, args.repeats // 2))
    if args.rigorous_points:
        record["rigorous"] = rigorous(args.rigorous_points, 3)
    record["load_after"] = os.getloadavg()[0]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=1))
    print(json.dumps(record, indent=1))


if __name__ == "__main__":
    main()
