"""Epipolar resampling grids: every node's lines of sight meet at the grid's height (independent check:
rpcm localises both sensor positions), the nodes agree with shareloc's own grids, and the GeoTIFF files follow
OTB's convention."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio

from explorer import read_rpc
from explorer.errors import InputError
from explorer.geometry.frames import geodetic_to_ecef
from explorer.stereo import epipolar_grids, triangulate, write_grids
from tests.stereo.pairs import PHR_PAIRS, rpcm_localise, rpcm_pair

HEIGHT = 300.0


@pytest.fixture(scope="module")
def pair():
    return tuple(read_rpc(p) for p in PHR_PAIRS["xml"])


@pytest.fixture(scope="module")
def grids30(pair):
    return epipolar_grids(*pair, height=HEIGHT, step=30)


@pytest.mark.slow
def test_step_30_every_node_meets_within_1cm(pair, grids30):
    g = grids30
    assert g.shape == (1519, 1188)
    assert g.epipolar_size == (45520, 35595)  # shareloc's size for this pair at this height
    # every node: the package's exact localisation of both positions at the grid's height
    from explorer.stereo.sensors import as_sensor, localise

    h = np.full(g.left_rows.size, HEIGHT)
    a, ok_a = localise(as_sensor(pair[0]), g.left_rows.ravel(), g.left_cols.ravel(), h)
    b, ok_b = localise(as_sensor(pair[1]), g.right_rows.ravel(), g.right_cols.ravel(), h)
    assert ok_a.all() and ok_b.all()
    assert np.max(np.linalg.norm(a - b, axis=1)) < 0.01
    # every 4th row and column of nodes (115,000): rpcm (its exact inverse) localises them independently
    peer_l, peer_r = rpcm_pair()
    sub = (slice(None, None, 4), slice(None, None, 4))
    hs = np.full(g.left_rows[sub].size, HEIGHT)
    lon_l, lat_l = rpcm_localise(peer_l, g.left_rows[sub].ravel(), g.left_cols[sub].ravel(), hs)
    lon_r, lat_r = rpcm_localise(peer_r, g.right_rows[sub].ravel(), g.right_cols[sub].ravel(), hs)
    miss = np.linalg.norm(geodetic_to_ecef(lon_l, lat_l, hs) - geodetic_to_ecef(lon_r, lat_r, hs), axis=1)
    assert np.max(miss) < 0.01
    # nodes inside both images triangulate to the grid's height with rays meeting within 1 cm
    out = triangulate(*pair, g.left_rows.ravel(), g.left_cols.ravel(), g.right_rows.ravel(), g.right_cols.ravel())
    inside = out.valid
    assert inside.sum() > 0.3 * inside.size
    assert np.max(np.abs(out.height[inside] - HEIGHT)) < 0.01
    assert np.max(out.ray_distance_m[inside]) < 0.01
    # Pleiades pair: ~0.74 px of disparity per metre of height (1.35 m per px)
    assert g.mean_baseline_ratio == pytest.approx(0.743, abs=0.005)
    assert g.disparity_to_height_ratio == pytest.approx(1.0 / g.mean_baseline_ratio)


@pytest.mark.slow
def test_nodes_agree_with_shareloc(pair):
    shareloc = pytest.importorskip("shareloc")
    from affine import Affine
    from shareloc.geofunctions.rectification import compute_stereorectification_epipolar_grids
    from shareloc.geomodels import GeoModel
    from shareloc.image import Image

    def image(n_rows, n_cols):
        im = Image(None)
        im.nb_rows, im.nb_columns = n_rows, n_cols
        im.transform = Affine(1, 0, 0, 0, 1, 0)
        im.trans_inv = ~im.transform
        im.pixel_size_row = im.pixel_size_col = 1.0
        return im

    left_f, right_f = (str(p) for p in PHR_PAIRS["xml"])
    assert shareloc
    lg, rg, size, _ = compute_stereorectification_epipolar_grids(
        image(22940, 40000), GeoModel(left_f, "RPC"), image(22940, 40000), GeoModel(right_f, "RPC"), HEIGHT, 600.0,
        50.0)
    g = epipolar_grids(*pair, height=HEIGHT, step=600)
    assert tuple(size) == g.epipolar_size
    assert lg.shape[:2] == g.shape
    # shareloc's pixels are ours + 0.5; its localisation stops near 1e-5 px
    for ours, theirs in ((g.left_rows, lg[..., 0]), (g.left_cols, lg[..., 1]), (g.right_rows, rg[..., 0]),
                         (g.right_cols, rg[..., 1])):
        assert np.max(np.abs(theirs - 0.5 - ours)) < 1e-4


def test_geotiff_in_otb_convention(tmp_path, pair):
    g = epipolar_grids(*pair, height=HEIGHT, step=900)
    paths = write_grids(g, tmp_path)
    for side, rows, cols in (("left", g.left_rows, g.left_cols), ("right", g.right_rows, g.right_cols)):
        with rasterio.open(paths[side]) as ds:
            assert ds.count == 3 and ds.dtypes[0] == "float64"
            assert ds.transform.a == 900 and ds.transform.e == 900
            assert ds.transform.c == -450 and ds.transform.f == -450
            dx, dy, hh = ds.read(1), ds.read(2), ds.read(3)
        # node (i, j): epipolar physical (y, x) = (i, j) * step; sensor physical = package pixel + 0.5
        i, j = np.meshgrid(np.arange(g.shape[0]), np.arange(g.shape[1]), indexing="ij")
        np.testing.assert_allclose(j * 900.0 + dx, cols + 0.5, atol=1e-9)
        np.testing.assert_allclose(i * 900.0 + dy, rows + 0.5, atol=1e-9)
        assert np.all(hh == HEIGHT)
    summary = json.loads(paths["summary"].read_text())
    assert summary["epipolar_size"] == {"rows": g.epipolar_size[0], "columns": g.epipolar_size[1]}
    assert summary["disparity_to_height_ratio_m_per_px"] == pytest.approx(g.disparity_to_height_ratio)


def test_bilinear_reading_and_its_inverse(pair):
    g = epipolar_grids(*pair, height=HEIGHT, step=900)
    er, ec = g.node_positions()
    r, c = g.to_sensor("left", er, ec)
    np.testing.assert_allclose(r, g.left_rows, atol=1e-9)
    np.testing.assert_allclose(c, g.left_cols, atol=1e-9)
    rng = np.random.default_rng(5)
    pr = rng.uniform(0, g.epipolar_size[0] * 0.9, 50)
    pc = rng.uniform(0, g.epipolar_size[1] * 0.9, 50)
    sr, sc = g.to_sensor("right", pr, pc)
    br, bc = g.to_epipolar("right", sr, sc)
    np.testing.assert_allclose(br, pr, atol=1e-6)
    np.testing.assert_allclose(bc, pc, atol=1e-6)


def test_bad_grid_input(pair):
    with pytest.raises(InputError, match="step"):
        epipolar_grids(*pair, height=HEIGHT, step=0)
    with pytest.raises(InputError, match="height"):
        epipolar_grids(*pair, height=float("nan"), step=30)
