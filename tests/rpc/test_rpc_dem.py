"""RPC image to ground: the fast inverse at a height and the first intersection with a DEM.

Truth: the forward RPC (round trip), the DEM's own numpy bilinear lookup (the point lies on the surface),
GDAL's RPC transformer with ``RPC_DEM`` (peer library, tightened and default thresholds), and synthetic
DEMs written as GeoTIFFs in UTM (a plane, reprojected on read; an SRTM void without a no-data tag).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from explorer.errors import InputError
from explorer.geometry.dem_intersection import NODATA, OK
from explorer.rpc import read_rpc
from explorer.rpc.dem import localization_on_dem
from explorer.rpc.inverse import RPCInverse
from explorer.terrain_io import DEFAULT_ASSETS_DIR, EllipsoidalDEM, Geoid, read_geotiff_dem

DATA = Path(__file__).resolve().parents[1] / "data" / "rpc"
PHR_2018 = DATA / "PHRDIMAP_P1BP--2018122638935449CP.XML"
PHR_2017 = DATA / "PHRDIMAP_P1BP--2017030824934340CP.XML"
DEM_2018 = DEFAULT_ASSETS_DIR / "MNT_P1BP--2018122638935449CP.tif"  # heights above the ellipsoid
DEM_2017 = DEFAULT_ASSETS_DIR / "MNT_P1BP--2017030824934340CP.tif"  # heights above the geoid


def random_pixels(rpc, n, seed):
    rng = np.random.default_rng(seed)
    rows, cols = rpc.image_size
    return rng.uniform(0, rows - 1, n), rng.uniform(0, cols - 1, n)


@pytest.mark.parametrize("name", ["PHRDIMAP_P1BP--2018122638935449CP.XML", "rpc_IKONOS.txt", "rpc_WV2.xml",
                                  "rpc_PLANET_L1B.txt", "md_dg.RPB", "rpc_SPOT6.xml"])
def test_localize_at_height_round_trip(name):
    rpc = read_rpc(DATA / name)
    lo, hi = rpc.height_range(0.5)
    inverse = RPCInverse.for_model(rpc, lo, hi)
    rng = np.random.default_rng(2)
    n = 5000
    row = rpc.row_offset + rpc.row_scale * rng.uniform(-0.9, 0.9, n)
    col = rpc.col_offset + rpc.col_scale * rng.uniform(-0.9, 0.9, n)
    h = rng.uniform(lo, hi, n)
    lon, lat, flags = inverse.localize(row, col, h)
    assert np.all(flags == OK)
    r2, c2 = rpc.projection(lon, lat, h, backend="numpy")
    assert np.max(np.hypot(r2 - row, c2 - col)) < 5e-9
    # the old vectorised Newton (model.localization) agrees
    lon_n, lat_n, ok = rpc.localization(row[:500], col[:500], h[:500])
    assert ok.all()
    np.testing.assert_allclose(lon[:500], lon_n, atol=1e-10)
    np.testing.assert_allclose(lat[:500], lat_n, atol=1e-10)


def test_pleiades_on_its_dem_round_trip_and_surface():
    rpc = read_rpc(PHR_2018)
    dem = read_geotiff_dem(DEM_2018)
    row, col = random_pixels(rpc, 20000, 7)
    lon, lat, h, ok, flags = localization_on_dem(rpc, row, col, dem, return_flags=True)
    assert ok.mean() >= 0.99
    assert np.array_equal(ok, flags == OK)
    r2, c2 = rpc.projection(lon[ok], lat[ok], h[ok], backend="numpy")
    assert np.max(np.hypot(r2 - row[ok], c2 - col[ok])) < 1e-6
    assert np.max(np.abs(dem.height(lon[ok], lat[ok]) - h[ok])) < 1e-3


def test_pleiades_on_geoid_dem_through_egm96():
    rpc = read_rpc(PHR_2017)
    dem = EllipsoidalDEM(read_geotiff_dem(DEM_2017, vertical_reference="egm96"), Geoid.egm96())
    row, col = random_pixels(rpc, 5000, 8)
    lon, lat, h, ok = localization_on_dem(rpc, row, col, dem)
    assert ok.mean() >= 0.99
    r2, c2 = rpc.projection(lon[ok], lat[ok], h[ok])
    assert np.max(np.hypot(r2 - row[ok], c2 - col[ok])) < 1e-6
    # the kernel adds the undulation at the nodes: within a millimetre of bilinear(h) + bilinear(N)
    assert np.max(np.abs(dem.height(lon[ok], lat[ok]) - h[ok])) < 1e-3


def test_pleiades_dem_agrees_with_gdal_rpc_transformer():
    pytest.importorskip("rasterio")
    from rasterio.rpc import RPC
    from rasterio.transform import RPCTransformer

    rpc = read_rpc(PHR_2018)
    dem = read_geotiff_dem(DEM_2018)
    g = RPC(height_off=rpc.height_offset, height_scale=rpc.height_scale, lat_off=rpc.lat_offset,
            lat_scale=rpc.lat_scale, line_den_coeff=list(rpc.row_den), line_num_coeff=list(rpc.row_num),
            line_off=rpc.row_offset, line_scale=rpc.row_scale, long_off=rpc.lon_offset, long_scale=rpc.lon_scale,
            samp_den_coeff=list(rpc.col_den), samp_num_coeff=list(rpc.col_num), samp_off=rpc.col_offset,
            samp_scale=rpc.col_scale)
    row, col = random_pixels(rpc, 5000, 9)
    lon, lat, h, ok = localization_on_dem(rpc, row, col, dem)
    for options, tolerance_m in (({}, 0.10), ({"RPC_PIXEL_ERROR_THRESHOLD": 1e-7}, 1e-3)):
        with RPCTransformer(g, RPC_DEM=str(DEM_2018), **options) as transformer:
            g_lon, g_lat = transformer.xy(row, col, np.zeros(row.size), offset="center")
        g_lon, g_lat = np.asarray(g_lon), np.asarray(g_lat)
        east = (g_lon - lon) * np.cos(np.radians(lat)) * 111_320.0
        north = (g_lat - lat) * 110_574.0
        assert np.nanmax(np.hypot(east, north)[ok]) <= tolerance_m


def write_utm_dem(path, heights, nodata=None, epsg=32631, x0=440_000.0, y0=3_460_000.0, cell=30.0):
    import rasterio
    from rasterio.transform import from_origin

    profile = {"driver": "GTiff", "width": heights.shape[1], "height": heights.shape[0], "count": 1,
               "dtype": "float32" if nodata is None or nodata != -32768 else "int16", "crs": f"EPSG:{epsg}",
               "transform": from_origin(x0, y0, cell, cell)}
    if nodata is not None:
        profile["nodata"] = nodata
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(heights.astype(profile["dtype"]), 1)


def test_utm_dem_reprojected_on_read_plane_and_void(tmp_path):
    pyproj = pytest.importorskip("pyproj")
    rpc = read_rpc(PHR_2018)
    # a UTM 31N plane h = 500 + 0.01 (E - E0) - 0.02 (N - N0) covering the scene with a margin
    to_utm = pyproj.Transformer.from_crs(4326, 32631, always_xy=True)
    e_c, n_c = to_utm.transform(rpc.lon_offset, rpc.lat_offset)
    cell = 30.0
    nx, ny = 1000, 800
    x0, y0 = e_c - nx * cell / 2, n_c + ny * cell / 2
    e = x0 + (np.arange(nx) + 0.5) * cell
    n = y0 - (np.arange(ny) + 0.5) * cell
    plane = 500.0 + 0.01 * (e[None, :] - e_c) - 0.02 * (n[:, None] - n_c)
    heights = plane.copy()
    void = heights.copy()
    void[390:410, 490:510] = -32768  # SRTM void at the centre, no no-data tag in the file
    write_utm_dem(tmp_path / "plane.tif", heights, x0=x0, y0=y0, cell=cell)
    write_utm_dem(tmp_path / "void.tif", void, x0=x0, y0=y0, cell=cell)
    dem = read_geotiff_dem(tmp_path / "plane.tif")
    assert dem.is_geographic and "4326" in dem.crs
    row, col = random_pixels(rpc, 3000, 10)
    lon, lat, h, ok = localization_on_dem(rpc, row, col, dem)
    assert ok.mean() >= 0.99
    pe, pn = to_utm.transform(lon[ok], lat[ok])
    truth = 500.0 + 0.01 * (np.asarray(pe) - e_c) - 0.02 * (np.asarray(pn) - n_c)
    assert np.max(np.abs(h[ok] - truth)) < 1e-3  # a plane resampled onto lon/lat nodes stays (float32 file)
    r2, c2 = rpc.projection(lon[ok], lat[ok], h[ok])
    assert np.max(np.hypot(r2 - row[ok], c2 - col[ok])) < 1e-6
    # the void: -32768 read as no-data; the pixel looking at the scene centre is flagged, not located
    dem_void = read_geotiff_dem(tmp_path / "void.tif")
    assert np.isnan(dem_void.heights).any() and np.nanmin(dem_void.heights) > 0
    centre_row, centre_col = rpc.row_offset, rpc.col_offset
    lon_v, lat_v, h_v, ok_v, flags = localization_on_dem(rpc, np.array([centre_row, 0.0]), np.array([centre_col, 0.0]),
                                                             dem_void, return_flags=True)
    assert flags.tolist() == [NODATA, OK]
    assert np.isnan(h_v[0]) and np.isfinite(h_v[1])


def test_dem_not_covering_the_footprint_is_an_error(tmp_path):
    rpc = read_rpc(PHR_2018)
    write_utm_dem(tmp_path / "far.tif", np.full((50, 50), 100.0), x0=200_000.0, y0=5_000_000.0)
    dem = read_geotiff_dem(tmp_path / "far.tif")
    with pytest.raises(InputError, match="does not cover"):
        localization_on_dem(rpc, np.array([10.0, 2000.0]), np.array([10.0, 3000.0]), dem)
