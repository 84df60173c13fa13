"""Orthorectification: synthetic ground pattern geolocation, GDAL peer check, schedulers."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import rasterio

from explorer.cli import main
from explorer.geometry.frames import LocalFrame
from explorer.methods.adapter import MethodSensor
from explorer.ortho import (
    NODATA,
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

DATA = Path(__file__).parent / "data" / "rpc"
ASSETS = Path(__file__).parent.parent / "assets" / "dem"


def _synthetic_ortho(tmp_path, scene, gsd, chunk=128):
    lon, lat, _ = scene.frame.enu_to_geodetic(scene.footprint())
    epsg = LocalFrame(float(np.mean(lat)), float(np.mean(lon))).utm_epsg()
    grid = grid_covering(lon, lat, gsd, epsg)
    pattern = default_pattern(epsg, gsd, (grid.x0, grid.y0))
    geometry = OrthoGeometry(MethodSensor.create(scene, "exact"), SensorTerrain(scene.terrain))
    src = render_synthetic_source(geometry.image_to_lonlat, scene.shape, pattern, tmp_path / "src.npy")
    arr = ortho_dask_array(geometry, SourceImage(src), grid, chunk)
    return np.asarray(arr.compute(scheduler="threads")), grid, pattern


@pytest.mark.parametrize("relief", [0.0, 600.0])
def test_synthetic_orthoimage_geolocation_below_a_tenth_of_a_pixel(tmp_path, relief):
    scene = build_scene("SCB", relief_m=relief, relief_seed=2)
    ortho, grid, pattern = _synthetic_ortho(tmp_path, scene, gsd=12.0)
    geo = measure_geolocation(ortho, grid, pattern, block=32)
    assert geo["n_tiles"] > 20
    assert geo["max_px"] < 0.1
    # outside the footprint: no-data, never extrapolated
    assert ortho[0, 0] == NODATA and ortho[-1, -1] == NODATA
    assert (ortho != NODATA).mean() > 0.3


def test_geolocation_measure_detects_a_known_shift(tmp_path):
    scene = build_scene("SCB")
    ortho, grid, pattern = _synthetic_ortho(tmp_path, scene, gsd=12.0)
    shifted = type(grid)(grid.epsg, grid.x0 + 0.3 * grid.gsd, grid.y0, grid.gsd, grid.width, grid.height)
    geo = measure_geolocation(ortho, shifted, pattern, block=32)
    assert abs(abs(geo["mean_shift_px"][0]) - 0.3) < 0.01


def test_rpc_orthoimage_agrees_with_gdal_rpc_warp(tmp_path):
    from explorer.rpc import read_rpc
    from explorer.terrain_io import read_geotiff_dem

    dem_path = ASSETS / "MNT_P1BP--2018122638935449CP.tif"  # heights above the ellipsoid
    rpc = read_rpc(DATA / "PHRDIMAP_P1BP--2018122638935449CP.XML").with_pixel_shift(-19000, -19500)
    dem = read_geotiff_dem(dem_path)
    n = 200
    corners = np.array([0, 0, n - 1, n - 1.0]), np.array([0, n - 1, n - 1, 0.0])
    lon, lat, _, ok = localization_on_dem(rpc, *corners, dem)
    assert ok.all()
    epsg = LocalFrame(float(lat.mean()), float(lon.mean())).utm_epsg()
    grid = grid_covering(lon, lat, 0.5, epsg)
    pattern = default_pattern(epsg, 0.5, (grid.x0, grid.y0))

    def to_lonlat(r, c):
        lo, la, _, _ = localization_on_dem(rpc, r, c, dem, n_levels=12)
        return lo, la

    src = render_synthetic_source(to_lonlat, (n, n), pattern, tmp_path / "src.npy")
    sensor = RPCSensor(dataclasses.replace(rpc, image_size=(n, n)))
    ours = np.asarray(ortho_dask_array(OrthoGeometry(sensor, DEMHeights(dem)), SourceImage(src), grid, 64).compute())
    gdal = gdal_rpc_orthoimage(np.load(src), rpc, grid, dem_path)
    ours_geo = measure_geolocation(ours, grid, pattern, block=32)
    gdal_geo = measure_geolocation(gdal, grid, pattern, block=32)
    between = measure_geolocation(ours, grid, pattern, block=32, reference=gdal)
    assert ours_geo["n_tiles"] >= 4 and between["n_tiles"] >= 4
    assert ours_geo["max_px"] < 0.1 and gdal_geo["max_px"] < 0.1
    assert between["max_px"] < 0.1


def test_threaded_and_local_cluster_outputs_are_byte_identical(tmp_path):
    scene = build_scene("SCB")
    lon, lat, _ = scene.frame.enu_to_geodetic(scene.footprint())
    epsg = LocalFrame(float(np.mean(lat)), float(np.mean(lon))).utm_epsg()
    grid = grid_covering(lon, lat, 40.0, epsg)
    pattern = default_pattern(epsg, 40.0, (grid.x0, grid.y0))
    geometry = OrthoGeometry(MethodSensor.create(scene, "exact"), SensorTerrain(scene.terrain))
    src = render_synthetic_source(geometry.image_to_lonlat, scene.shape, pattern, tmp_path / "src.npy")
    arr = ortho_dask_array(geometry, SourceImage(src), grid, 96)
    a, b = tmp_path / "threads.tif", tmp_path / "cluster.tif"
    write_orthoimage(arr, grid, a, scheduler="threads")
    write_orthoimage(arr, grid, b, scheduler="local-cluster:2")
    assert a.read_bytes() == b.read_bytes()
    with rasterio.open(a) as ds:
        assert ds.crs.to_epsg() == epsg and ds.nodata == float(NODATA)
        assert ds.transform.a == 40.0 and ds.transform.e == -40.0


def test_ortho_cli_synthetic(tmp_path, capsys):
    out = tmp_path / "o.tif"
    assert main(["ortho", "--preset", "SCB", "--synthetic", "--gsd", "30", "--chunk", "64", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert '"geolocation"' in text
    with rasterio.open(out) as ds:
        assert ds.width > 10 and ds.height > 10


def test_block_lonlat_interpolation_matches_proj_per_pixel():
    import pyproj

    from explorer.ortho import LONLAT_TOLERANCE_PX, OrthoGrid, block_lonlat

    grid = OrthoGrid(32631, 430_000.0, 3_440_000.0, 0.5, 700, 500)
    rows, cols = slice(37, 337), slice(11, 411)
    lon, lat = block_lonlat(grid, rows, cols)
    e, n = grid.pixel_centres(rows, cols)
    lon_x, lat_x = pyproj.Transformer.from_crs(32631, 4326, always_xy=True).transform(e, n)
    err_m = np.hypot((lon - lon_x) * 111_320.0 * np.cos(np.radians(lat_x)), (lat - lat_x) * 110_574.0)
    assert lon.shape == (300, 400)
    assert err_m.max() <= LONLAT_TOLERANCE_PX * grid.gsd


def test_compiled_dem_lookup_matches_numpy_bilinear():
    from explorer.geometry.dem_intersection import heights_at
    from explorer.terrain_io import DEFAULT_ASSETS_DIR, read_geotiff_dem

    dem = read_geotiff_dem(DEFAULT_ASSETS_DIR / "MNT_P1BP--2018122638935449CP.tif")
    rng = np.random.default_rng(4)
    x0, y0, x1, y1 = dem.bounds
    lon = rng.uniform(x0 - 0.01, x1 + 0.01, 5000)
    lat = rng.uniform(y0 - 0.01, y1 + 0.01, 5000)
    ours = heights_at(dem.height_grid(), lon, lat)
    ref = dem.height(lon, lat)
    assert np.array_equal(np.isnan(ours), np.isnan(ref)) and np.isnan(ref).any()
    np.testing.assert_allclose(ours[np.isfinite(ref)], ref[np.isfinite(ref)], atol=1e-9)


def test_sparse_sampling_of_a_large_source_matches_scipy(tmp_path):
    from scipy.ndimage import map_coordinates

    from explorer.ortho import SourceImage

    image = np.random.default_rng(0).normal(size=(300, 400)).astype(np.float32)
    np.save(tmp_path / "src.npy", image)
    source = SourceImage(tmp_path / "src.npy")
    rng = np.random.default_rng(1)
    row, col = rng.uniform(0, 299, 50), rng.uniform(0, 399, 50)  # few points over a large window: gathered
    values = source.sample_bilinear(row, col, np.ones(50, bool))
    truth = map_coordinates(image.astype(np.float64), [row, col], order=1)
    np.testing.assert_allclose(values, truth, atol=1e-12)


class _LocalFrameOnly:
    """An RPCSensor seen only through the Sensor interface (no geodetic capability declared)."""

    def __init__(self, sensor):
        self._s = sensor
        self.frame, self.n_rows, self.n_columns = sensor.frame, sensor.n_rows, sensor.n_columns

    def ground_to_image(self, ground):
        return self._s.ground_to_image(ground)

    def project(self, ground):
        return self._s.project(ground)

    def geodetic_to_image(self, lon, lat, h):
        return self._s.ground_to_image(self.frame.geodetic_to_enu(lon, lat, h))

    def project_geodetic(self, lon, lat, h):
        return self._s.project(self.frame.geodetic_to_enu(lon, lat, h))

    def image_to_ground(self, row, col, *, height=None):
        return self._s.image_to_ground(row, col, height=height)


def test_ortho_geometry_takes_any_sensor_rpc_in_geodetic_or_local_coordinates():
    """Truth: the RPC's own projection at the same ground points; the local-frame path (any Sensor) agrees."""
    from explorer.ortho import EllipsoidHeight

    rpc = read_rpc(DATA / "PHRDIMAP_P1BP--2018122638935449CP.XML")
    sensor = RPCSensor(rpc)
    from explorer.sensor import GeodeticSensor, has_geodetic_projection

    assert isinstance(sensor, GeodeticSensor) and has_geodetic_projection(sensor)
    assert not has_geodetic_projection(_LocalFrameOnly(sensor))
    rng = np.random.default_rng(4)
    lon = rpc.lon_offset + rng.uniform(-0.8, 0.8, 500) * rpc.lon_scale
    lat = rpc.lat_offset + rng.uniform(-0.8, 0.8, 500) * rpc.lat_scale
    h = 310.0
    row, col, valid = OrthoGeometry(sensor, EllipsoidHeight(h)).locate(lon, lat)
    r_ref, c_ref = rpc.projection(lon, lat, np.full(lon.shape, h))[:2]
    np.testing.assert_array_equal(row, r_ref)
    np.testing.assert_array_equal(valid, (r_ref >= -0.5) & (r_ref <= sensor.n_rows - 0.5) & (c_ref >= -0.5)
                                  & (c_ref <= sensor.n_columns - 0.5))
    assert valid.mean() > 0.5
    row2, col2, valid2 = OrthoGeometry(_LocalFrameOnly(sensor), EllipsoidHeight(h)).locate(lon, lat)
    assert np.max(np.hypot(row2 - r_ref, col2 - c_ref)) < 1e-6
    # image -> ground on the height: back where the projection put it
    lo, la = OrthoGeometry(_LocalFrameOnly(sensor), EllipsoidHeight(h)).image_to_lonlat(r_ref[:20], c_ref[:20])
    assert np.max(np.abs(lo - lon[:20])) < 1e-9 and np.max(np.abs(la - lat[:20])) < 1e-9
