"""Fuzzing the DEM reader with small generated GeoTIFFs (issue 18).

Small rasters written with rasterio: 1..6 x 1..6 cells of every common dtype, holding NaN, +-inf,
huge values, the SRTM void value or the file's no-data value; geotransforms with tiny, huge,
negative or rotated pixels and origins off the globe; geographic, projected (reprojected on read)
or no CRS; one or two bands; and byte-mutated (truncated, flipped) files.  Whatever comes out,
:func:`explorer.terrain_io.read_geotiff_dem` (and :func:`explorer.real.from_rpc.load_dem` on the
same path) must give a DEM whose heights at its cell centres are finite or NaN (no-data), within
the range of the file's finite values, and whose kernel grid builds, or raise the package's own
error (:class:`~explorer.errors.ExplorerError`); never another exception.  At least 1,000
deterministic cases.
"""

import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, event, given
from hypothesis import strategies as st

from explorer.errors import ExplorerError
from explorer.real.from_rpc import load_dem
from explorer.terrain_io import height_grid_of, read_geotiff_dem

from .conftest import FUZZ

rasterio = pytest.importorskip("rasterio")
from rasterio.transform import Affine  # noqa: E402

TMP = Path(tempfile.mkdtemp(prefix="fuzz_dem_"))
DTYPES = ["uint8", "int16", "uint16", "int32", "float32", "float64"]
SPECIAL = [np.nan, np.inf, -np.inf, 1e30, -3.4028235e38, -32768.0, 0.0, 8848.0, -11000.0, 1e6]


@st.composite
def dem_files(draw):
    """(path, finite values written, description)."""
    ny, nx = draw(st.integers(1, 6)), draw(st.integers(1, 6))
    dtype = draw(st.sampled_from(DTYPES))
    info = np.iinfo(dtype) if dtype[0] in "iu" else None
    base = draw(st.lists(st.floats(-500.0, 5000.0, allow_nan=False), min_size=ny * nx, max_size=ny * nx))
    data = np.asarray(base).reshape(ny, nx)
    for _ in range(draw(st.integers(0, 3))):  # special values in random cells
        data[draw(st.integers(0, ny - 1)), draw(st.integers(0, nx - 1))] = draw(st.sampled_from(SPECIAL))
    if info is not None:
        data = np.clip(np.nan_to_num(data, nan=0.0, posinf=info.max, neginf=info.min), info.min, info.max)
    with np.errstate(over="ignore", invalid="ignore"):
        data = data.astype(dtype)
    nodata = draw(st.sampled_from([None, None, 0, -9999, -32768, "nan", "cell"]))
    if nodata == "nan":
        nodata = np.nan if info is None else None
    elif nodata == "cell":
        nodata = data.flat[draw(st.integers(0, data.size - 1))].item()
    if nodata is not None and info is not None and not info.min <= nodata <= info.max:
        nodata = None
    a = draw(st.sampled_from([1e-12, 1e-6, 1 / 3600, 0.01, 1.0, 30.0, 1e6, -0.01]))
    e = draw(st.sampled_from([-abs(a), abs(a), -1e-9, -5.0]))
    b = draw(st.sampled_from([0.0, 0.0, 0.0, 1e-5]))
    c = draw(st.sampled_from([7.0, -180.0, 179.9999, 1e6, -1e9, 500000.0]))
    f = draw(st.sampled_from([44.0, 90.0, -89.9, 1e6, 4_900_000.0]))
    crs = draw(st.sampled_from(["EPSG:4326", "EPSG:4326", None, "EPSG:32631"]))
    bands = draw(st.sampled_from([1, 1, 1, 2]))
    path = TMP / "dem.tif"
    path.unlink(missing_ok=True)  # GDAL does not overwrite a corrupt file of the previous case
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with rasterio.open(path, "w", driver="GTiff", width=nx, height=ny, count=bands, dtype=dtype,
                               crs=crs, transform=Affine(a, b, c, 0.0, e, f), nodata=nodata) as dst:
                for k in range(1, bands + 1):
                    dst.write(data, k)
    except Exception:  # noqa: BLE001 - a combination GDAL cannot write is not a reader case
        assume(False)
    mutate = draw(st.sampled_from(["none"] * 8 + ["truncate", "flip"]))
    if mutate != "none":
        raw = path.read_bytes()
        pos = draw(st.integers(0, len(raw) - 1))
        raw = raw[:pos] if mutate == "truncate" else raw[:pos] + bytes([raw[pos] ^ 0xFF]) + raw[pos + 1:]
        path.write_bytes(raw)
    values = data.astype(np.float64)
    finite = values[np.isfinite(values)]
    return path, finite, f"{dtype} {crs} a={a:g} mutate={mutate}"


def _check(dem, finite):
    ny, nx = dem.heights.shape
    a, _, c, _, e, f = dem.transform
    cols, rows = np.meshgrid(np.arange(nx) + 0.5, np.arange(ny) + 0.5)
    lon, lat = c + a * cols.ravel(), f + e * rows.ravel()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no overflow/invalid warnings either
        h = np.asarray(dem.height(lon, lat), dtype=np.float64)
    assert not np.any(np.isinf(h)), "heights are finite or NaN"
    ok = np.isfinite(h)
    if ok.any() and finite.size:
        assert np.all(h[ok] >= finite.min() - 1e-6) and np.all(h[ok] <= finite.max() + 1e-6)
    grid = height_grid_of(dem)
    if grid is not None:
        assert grid.heights.shape[0] >= 1


@FUZZ
@given(dem_files())
def test_generated_dems_give_a_dem_or_the_packages_error(case):
    path, finite, what = case
    try:
        dem = read_geotiff_dem(path)
    except ExplorerError as exc:
        assert str(path) in str(exc) or path.name in str(exc)
        event(f"refused ({what.split()[-1]})")
        return
    event(f"read ({what.split()[-1]})")
    try:
        _check(dem, finite)
    except ExplorerError:
        event("kernel grid refused")
    try:
        load_dem(path, "ellipsoid")
    except ExplorerError:
        pass
