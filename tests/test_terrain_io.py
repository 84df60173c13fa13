"""DEM readers and EGM96 geoid: raw values, synthetic files with closed-form truth, NGA values."""

import struct
import warnings

import numpy as np
import pytest

from explorer.terrain_io import DEFAULT_ASSETS_DIR, GeoDEM, Geoid, read_geotiff_dem, read_hgt

rasterio = pytest.importorskip("rasterio")

DEMS = ["MNT_P1BP--2017030824934340CP.tif", "MNT_P1BP--2018122638935449CP.tif"]


@pytest.mark.parametrize("name", DEMS)
def test_shareloc_dem_nodes_are_raw_values(name):
    path = DEFAULT_ASSETS_DIR / name
    dem = read_geotiff_dem(path)
    with rasterio.open(path) as dataset:
        raw = dataset.read(1).astype(np.float64)
    assert np.isfinite(dem.heights).all()
    i, j = np.meshgrid(np.arange(raw.shape[0]), np.arange(raw.shape[1]), indexing="ij")
    x, y = dem.node_coordinates(i, j)
    h, valid = dem.height_and_mask(x, y)
    assert valid.all()
    np.testing.assert_array_equal(h, raw)  # exact at nodes
    assert dem.min == raw.min() and dem.max == raw.max()


def test_shareloc_dem_bilinear_inside_and_outside():
    path = DEFAULT_ASSETS_DIR / DEMS[1]
    dem = read_geotiff_dem(path)
    with rasterio.open(path) as dataset:
        raw = dataset.read(1).astype(np.float64)
    # midpoint of four nodes = mean of the four (closed form of bilinear)
    x00, y00 = dem.node_coordinates(10, 7)
    x11, y11 = dem.node_coordinates(11, 8)
    h = dem.height(0.5 * (x00 + x11), 0.5 * (y00 + y11))
    assert h == pytest.approx(raw[10:12, 7:9].mean(), abs=1e-9)
    x0, y0, x1, y1 = dem.bounds
    h_out, valid = dem.height_and_mask(
        [x0 - 0.01, x1 + 0.01, 0.5 * (x0 + x1)], [0.5 * (y0 + y1), y1, y1 + 0.01]
    )
    assert not valid.any() and np.isnan(h_out).all()


def test_geotiff_nodata_is_nan_and_flagged(tmp_path):
    data = np.arange(12, dtype=np.int16).reshape(3, 4) * 10
    data[1, 2] = -9999
    path = tmp_path / "dem.tif"

    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        width=4,
        height=3,
        count=1,
        dtype="int16",
        nodata=-9999,
        crs="EPSG:4326",
        transform=rasterio.Affine(0.5, 0.0, 10.0, 0.0, -0.5, 50.0),
    ) as dst:
        dst.write(data, 1)
    dem = read_geotiff_dem(path)
    assert np.isnan(dem.heights[1, 2])
    x, y = dem.node_coordinates(1, 2)
    h, valid = dem.height_and_mask(x, y)
    assert np.isnan(h) and not valid
    # a node next to nodata is still exact (zero-weight neighbour ignored)
    x, y = dem.node_coordinates(1, 1)
    assert dem.height(x, y) == 50.0
    # a point between a valid and a nodata node is flagged, not a wrong number
    x1, y1 = dem.node_coordinates(1, 1.5)
    h, valid = dem.height_and_mask(x1, y1)
    assert np.isnan(h) and not valid
    assert dem.node_coordinates(0, 0) == (10.25, 49.75)


def test_hgt_synthetic_tile(tmp_path):
    n = 1201
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    values = (i + 2 * j).astype(">i2")  # linear in lat and lon: bilinear is exact
    values[0, 0] = -32768
    path = tmp_path / "N43E007.hgt"
    values.tofile(path)
    dem = read_hgt(path)
    assert dem.vertical_reference == "egm96"
    step = 1.0 / 1200
    # node (i, j) at lat = 44 - i * step, lon = 7 + j * step
    lat, lon = 44.0 - 100 * step, 7.0 + 50 * step
    assert dem.height(lon, lat) == 100 + 2 * 50
    assert dem.height(lon + 0.5 * step, lat - 0.25 * step) == pytest.approx(100.25 + 101, abs=1e-9)
    assert np.isnan(dem.height(7.0, 44.0))  # nodata corner
    assert np.isnan(dem.height(6.99, 43.5))  # outside the tile
    assert dem.bounds == pytest.approx((7.0, 43.0, 8.0, 44.0))


def test_hgt_bad_name_and_size(tmp_path):
    bad = tmp_path / "tile.hgt"
    np.zeros(10, ">i2").tofile(bad)
    with pytest.raises(ValueError, match="N43E007"):
        read_hgt(bad)
    wrong = tmp_path / "S10W020.hgt"
    np.zeros(100, ">i2").tofile(wrong)
    with pytest.raises(ValueError, match="not a 1201"):
        read_hgt(wrong)


def _write_gtx(path, lat0, lon0, dlat, dlon, grid):
    rows, cols = grid.shape
    with open(path, "wb") as f:
        f.write(struct.pack(">4d2i", lat0, lon0, dlat, dlon, rows, cols))
        f.write(grid.astype(">f4").tobytes())


def test_synthetic_gtx_round_trip_and_wrap(tmp_path):
    lat = np.arange(-90.0, 90.1, 30.0)  # 7 rows, south to north
    lon = np.arange(0.0, 360.0, 45.0)  # 8 cols covering 360 degrees
    grid = (lat[:, None] * 0.5 + np.arange(lon.size)[None, :]).astype(np.float32)
    grid[0, 3] = -88.8888
    path = tmp_path / "synthetic.gtx"
    _write_gtx(path, -90.0, 0.0, 30.0, 45.0, grid)
    geoid = Geoid.from_gtx(path)
    assert geoid.wraps
    assert geoid.geoid_height(90.0, 30.0) == pytest.approx(30 * 0.5 + 2)  # node
    # wrap-around: between lon 315 (col 7) and 360 = col 0
    assert geoid.geoid_height(337.5, 0.0) == pytest.approx(0.5 * (7 + 0))
    assert geoid.geoid_height(-22.5, 0.0) == pytest.approx(3.5)
    assert np.isnan(geoid.geoid_height(135.0, -90.0))  # GTX no-data
    assert np.isnan(geoid.geoid_height(0.0, 95.0))  # outside latitudes
    h = geoid.orthometric_to_ellipsoidal(100.0, 90.0, 30.0)
    assert h == pytest.approx(117.0)
    assert geoid.ellipsoidal_to_orthometric(h, 90.0, 30.0) == pytest.approx(100.0)


def test_gtx_size_mismatch(tmp_path):
    path = tmp_path / "bad.gtx"
    _write_gtx(path, 0, 0, 1, 1, np.zeros((3, 3)))
    path.write_bytes(path.read_bytes()[:-4])
    with pytest.raises(ValueError, match="GTX header says 3x3"):
        Geoid.from_gtx(path)


# NGA EGM96 README test points (OUTINTPT.DAT: lat, lon, N in metres). NGA interpolates the
# same 15' grid with a 4x4 spline (INTPT.F); bilinear on that grid differs from it by a few
# centimetres in these places (measured max 0.056 m), hence 0.1 m.
NGA_POINTS = [
    (38.6281550, 269.7791550, -31.628),
    (-14.6212170, 305.0211140, -2.969),
    (46.8743190, 102.4487290, -43.575),
    (-23.6174460, 133.8747120, 15.871),
    (38.6254730, 359.9995000, 50.066),
    (-0.4667440, 0.0023000, 17.329),
]


@pytest.mark.parametrize(("lat", "lon", "undulation"), NGA_POINTS)
def test_egm96_matches_nga_reference(lat, lon, undulation):
    geoid = Geoid.egm96()
    assert geoid.geoid_height(lon, lat) == pytest.approx(undulation, abs=0.1)
    assert geoid.geoid_height(lon - 360.0, lat) == pytest.approx(undulation, abs=0.1)


def test_egm96_at_origin():
    # EGM96 N(0, 0) = 17.16 m (grid node)
    assert Geoid.egm96().geoid_height(0.0, 0.0) == pytest.approx(17.16, abs=0.01)


def test_pyproj_egm96_when_available():
    pyproj = pytest.importorskip("pyproj")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            transformer = pyproj.Transformer.from_crs(
                "EPSG:4979", "EPSG:4326+5773", always_xy=True, only_best=True
            )
            _, _, z = transformer.transform(7.1, 43.7, 0.0)
        except Exception:  # noqa: BLE001 - grid not installed
            pytest.skip("PROJ EGM96 grid not available")
    if not np.isfinite(z) or z == 0.0:
        pytest.skip("PROJ EGM96 grid not available")
    assert Geoid.egm96().geoid_height(7.1, 43.7) == pytest.approx(-z, abs=0.1)


def test_geodem_rejects_rotation():
    with pytest.raises(ValueError, match="rotated"):
        GeoDEM(np.zeros((2, 2)), (1.0, 0.1, 0.0, 0.0, -1.0, 0.0))


def test_reading_a_dem_does_not_import_boto3():
    """rasterio imported for a DEM leaves boto3 (the AWS SDK, ~40 % of rasterio's import time) out, and
    ``import boto3`` still works afterwards (fresh process; the DEM's values are tested above)."""
    import subprocess
    import sys

    pytest.importorskip("boto3")
    path = str(DEFAULT_ASSETS_DIR / DEMS[0])
    code = ("import sys, numpy as np; from explorer.terrain_io import read_geotiff_dem; "
            f"dem = read_geotiff_dem({path!r}); assert 'boto3' not in sys.modules and 'botocore' not in sys.modules; "
            "assert np.isfinite(dem.heights).any(); import boto3; print(boto3.__name__, dem.heights.shape)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.split()[0] == "boto3"
