"""Orthorectification memory: bounded by the output chunk, not by the source area a chunk covers nor the scene.

The peaks are the Python-traced allocations (``tracemalloc``; numpy reports its array buffers to it), so
they count the arrays ortho allocates and not the interpreter, numba or GDAL.  No wall time is asserted.
"""

import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import rasterio
from scipy.ndimage import map_coordinates

import explorer.ortho as ortho_module
from explorer.cli import main
from explorer.ortho import SAMPLER_PIXELS_PER_POINT, SourceImage

RPC_FILE = Path(__file__).parent / "data" / "rpc" / "PHRDIMAP_P1BP--2018122638935449CP.XML"


def _traced_peak(fn, *args):
    """(result, peak bytes allocated by ``fn`` above what was allocated when it started)."""
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        result = fn(*args)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return result, peak


def _rotated_points(n_side: int, step: float, centre: tuple[float, float], angle_deg: float = 17.0):
    """An n_side x n_side grid of points ``step`` source pixels apart, rotated like a scene's scan lines."""
    a = np.radians(angle_deg)
    u, v = np.meshgrid((np.arange(n_side) - n_side / 2) * step, (np.arange(n_side) - n_side / 2) * step)
    row = centre[0] + u * np.cos(a) - v * np.sin(a)
    col = centre[1] + u * np.sin(a) + v * np.cos(a)
    return row.ravel(), col.ravel()


@pytest.fixture(scope="module")
def large_source(tmp_path_factory):
    """A 2600 x 2600 float32 source (.npy) of noise: every pixel differs from its neighbours."""
    path = tmp_path_factory.mktemp("src") / "src.npy"
    image = np.random.default_rng(7).normal(100.0, 20.0, size=(2600, 2600)).astype(np.float32)
    np.save(path, image)
    return path, image


def test_strip_sampling_matches_scipy_on_npy_and_geotiff(large_source, tmp_path):
    path, image = large_source
    tif = tmp_path / "src.tif"
    with rasterio.open(tif, "w", driver="GTiff", width=image.shape[1], height=image.shape[0], count=1,
                       dtype="float32", tiled=True, blockxsize=256, blockysize=256) as ds:
        ds.write(image, 1)
    # 128 x 128 points 14 source pixels apart: the window they span is 49 times their number, so the
    # sampler reads it in many strips (the path a coarse output GSD takes)
    row, col = _rotated_points(128, 14.0, (1300.0, 1300.0))
    truth = map_coordinates(image.astype(np.float64), [row, col], order=1)
    valid = np.ones(row.size, bool)
    valid[::97] = False
    for src in (path, tif):
        values = SourceImage(src).sample_bilinear(row, col, valid)
        assert np.isnan(values[~valid]).all()
        np.testing.assert_allclose(values[valid], truth[valid], rtol=0, atol=1e-9)


def test_sampler_memory_does_not_grow_with_the_source_area_a_block_covers(large_source):
    """Same number of points (128 x 128) over a window 1x and 64x their number of source pixels.

    Reading the whole window as before (float32 read + float64 copy, 12 bytes per source pixel) costs
    64 x 12 = 768 bytes per point at the coarse spacing; the points' own float64 arrays cost about 150 bytes
    per point.  The strips hold at most SAMPLER_PIXELS_PER_POINT (4) source pixels per point in float32
    (16 bytes), so the peak may not grow by more than 25 % between the two spacings, and stays under
    400 bytes per point.
    """
    path, _ = large_source
    source = SourceImage(path)
    n = 128 * 128
    peaks = {}
    for step in (1.0, 8.0):  # an output GSD equal to the source's, then 8 times it (Pleiades 0.5 m -> 4 m)
        row, col = _rotated_points(128, step, (1300.0, 1300.0))
        valid = np.ones(n, bool)
        _, peaks[step] = _traced_peak(source.sample_bilinear, row, col, valid)
    assert SAMPLER_PIXELS_PER_POINT <= 4
    assert peaks[8.0] < 1.25 * peaks[1.0], peaks
    assert peaks[8.0] < 400 * n, peaks


def test_ortho_cli_memory_does_not_grow_with_the_scene(tmp_path, monkeypatch):
    """The whole `ortho --rpc --synthetic` run at a fixed chunk, for a scene of 512^2 and one 4x larger.

    The synthetic source is rendered in blocks of BLOCK_PIXELS (lowered here to 4096 pixels, so that the
    blocks are smaller than both scenes), the orthoimage in 64 x 64 blocks, and the geolocation is measured
    on strips of the written file: the traced peak is then about 2.6 MB for both scenes.  Anything sized by
    the scene -- the 1024^2 source is 4 MB in float32, its orthoimage at the source's GSD (1087 x 1129) 4.9 MB;
    a whole-output read, a materialised dask result, a whole-source window -- adds at least 4 MB to the
    larger run (measured: reading the output as one array for the geolocation gave a ratio of 2.6), so the
    peak may grow by at most 40 %.  A first, smaller run is not measured: it loads modules and caches once.
    """
    monkeypatch.setattr(ortho_module, "BLOCK_PIXELS", 1 << 12)
    peaks = {}
    for n in (256, 512, 1024):
        out = tmp_path / f"o{n}.tif"
        argv = ["ortho", "--rpc", str(RPC_FILE), "--synthetic", "--rpc-shape", f"{n}x{n}", "--gsd", "0.5",
                "--chunk", "64", "--scheduler", "synchronous", "--out", str(out)]
        status, peaks[n] = _traced_peak(main, argv)
        assert status == 0
        with rasterio.open(out) as ds:
            assert ds.width * ds.height > 0.8 * n * n  # the output grows with the scene
    assert peaks[1024] < 1.4 * peaks[512], peaks
