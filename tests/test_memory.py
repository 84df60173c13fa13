"""explorer.memory (issue 25 class 3): the estimate is made before allocating and a request that does not fit is
refused with the figure and the option to change; a GeoTIFF header claiming 150,000 x 150,000 cells is refused
before a single cell is read."""

from __future__ import annotations

import numpy as np
import pytest

from explorer.errors import InputError
from explorer.memory import USABLE_FRACTION, available_memory, check_allocation, format_bytes


def test_limit_from_the_environment_and_the_message(monkeypatch):
    monkeypatch.setenv("PUSHBROOM_MEMORY_LIMIT", "2GiB")
    assert available_memory() == 2 * 1024**3
    monkeypatch.setenv("PUSHBROOM_MEMORY_LIMIT", "512M")
    assert available_memory() == 512 * 1024**2
    check_allocation(0.5 * USABLE_FRACTION * 512 * 1024**2, "half of it", "lower --n")  # fits
    with pytest.raises(InputError, match=r"1000 points needs about 1\.0 GiB of memory, more than the 409\.6 MiB "
                                         r"this machine can give; lower --n"):
        check_allocation(1024**3, "1000 points", "lower --n")
    monkeypatch.delenv("PUSHBROOM_MEMORY_LIMIT")
    assert available_memory() > 0


def test_format_bytes():
    assert format_bytes(84 * 1024**3) == "84.0 GiB" and format_bytes(512) == "512 bytes"


def test_geotiff_header_of_150000_squared_cells_is_refused_before_reading(tmp_path, monkeypatch):
    rasterio = pytest.importorskip("rasterio")
    from rasterio.transform import Affine

    from explorer.terrain_io import read_geotiff_dem

    path = tmp_path / "huge.tif"
    with rasterio.open(path, "w", driver="GTiff", width=150_000, height=150_000, count=1, dtype="float32",
                       crs="EPSG:4326", transform=Affine(1e-5, 0, 7, 0, -1e-5, 44), tiled=True, sparse_ok=True,
                       compress="deflate"):
        pass  # no block written: a small file whose header claims 84 GiB of float32
    assert path.stat().st_size < 50 * 1024**2
    monkeypatch.setenv("PUSHBROOM_MEMORY_LIMIT", "64G")
    with pytest.raises(InputError, match=r"huge\.tif \(150000 x 150000 cells\) needs about 670\.6 GiB.*crop or "
                                         r"resample"):
        read_geotiff_dem(path)
    small = tmp_path / "small.tif"
    with rasterio.open(small, "w", driver="GTiff", width=4, height=3, count=1, dtype="float32", crs="EPSG:4326",
                       transform=Affine(0.1, 0, 7, 0, -0.1, 44)) as dst:
        dst.write(np.full((1, 3, 4), 120.0, np.float32))
    assert read_geotiff_dem(small).heights.shape == (3, 4)  # the guard lets a normal DEM through
