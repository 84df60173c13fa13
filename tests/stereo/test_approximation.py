"""Approximation maps against rpcm: the straight-line and local-affine residuals recomputed at map pixels from
rpcm's exact curves (numpy least squares), the grid read by scipy's bilinear interpolator."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from explorer import read_rpc
from explorer.stereo import approximation_maps, epipolar_grids
from tests.stereo.pairs import PHR_PAIRS, rpcm_localise, rpcm_pair

HEIGHTS = np.linspace(100.0, 1000.0, 7)


@pytest.fixture(scope="module")
def maps():
    left, right = (read_rpc(p) for p in PHR_PAIRS["xml"])
    grids = epipolar_grids(left, right, height=550.0, step=600)
    return approximation_maps(left, right, heights=HEIGHTS, shape=(3, 4), grids=grids, affine_window_px=400.0,
                              margin_px=500.0), grids


def _rpcm_curve(row, col, heights):
    peer_l, peer_r = rpcm_pair()
    lon, lat = rpcm_localise(peer_l, np.full(heights.size, row), np.full(heights.size, col), heights)
    c, r = peer_r.projection(lon, lat, heights)
    return r, c


def test_straight_line_and_affine_maps_recomputed_from_rpcm(maps):
    m, _ = maps
    for i, j in ((0, 0), (1, 2), (2, 3)):
        row, col = m.rows[i], m.cols[j]
        r, c = _rpcm_curve(row, col, HEIGHTS)
        d = np.array([r[-1] - r[0], c[-1] - c[0]])
        d /= np.linalg.norm(d)
        dist = np.abs((r - r[0]) * d[1] - (c - c[0]) * d[0])
        assert m.maps["straight line"][i, j] == pytest.approx(dist.max(), abs=1e-6)
        # affine over the 3 x 3 pixels 400 px apart, every height
        rows_a, cols_a, hs, tr, tc = [], [], [], [], []
        for du in (-400.0, 0.0, 400.0):
            for dv in (-400.0, 0.0, 400.0):
                rr, cc = _rpcm_curve(row + du, col + dv, HEIGHTS)
                rows_a += [du] * HEIGHTS.size
                cols_a += [dv] * HEIGHTS.size
                hs += list(HEIGHTS)
                tr += list(rr)
                tc += list(cc)
        design = np.column_stack([rows_a, cols_a, hs, np.ones(len(hs))])
        coef = np.linalg.lstsq(design, np.column_stack([tr, tc]), rcond=None)[0]
        pred = np.column_stack([np.zeros(HEIGHTS.size), np.zeros(HEIGHTS.size), HEIGHTS,
                                np.ones(HEIGHTS.size)]) @ coef
        err = np.hypot(pred[:, 0] - r, pred[:, 1] - c).max()
        assert m.maps["local affine"][i, j] == pytest.approx(err, abs=1e-5)
    # the Pleiades pair: the curve bends by about 0.01 px over 900 m
    assert 1e-3 < np.max(m.maps["straight line"]) < 0.05


def test_grid_maps_with_scipy_bilinear(maps):
    m, grids = maps
    i_nodes = np.arange(grids.shape[0]) * grids.step - 0.5
    j_nodes = np.arange(grids.shape[1]) * grids.step - 0.5
    interp = {name: RegularGridInterpolator((i_nodes, j_nodes), getattr(grids, name))
              for name in ("left_rows", "left_cols", "right_rows", "right_cols")}
    peer_l, peer_r = rpcm_pair()
    for i, j in ((0, 1), (2, 2)):
        row, col = m.rows[i], m.cols[j]
        e_r, e_c = grids.to_epipolar("left", np.array([row]), np.array([col]))
        p = np.array([[e_r[0], e_c[0]]])
        assert interp["left_rows"](p)[0] == pytest.approx(row, abs=1e-6)
        assert interp["left_cols"](p)[0] == pytest.approx(col, abs=1e-6)
        lon, lat = rpcm_localise(peer_l, np.array([row]), np.array([col]), np.array([grids.height]))
        c_x, r_x = peer_r.projection(lon, lat, grids.height)
        err = np.hypot(interp["right_rows"](p)[0] - r_x[0], interp["right_cols"](p)[0] - c_x[0])
        assert m.maps["grid interpolation"][i, j] == pytest.approx(err, abs=1e-6)
    assert np.all(np.isfinite(m.maps["grid"]))
    summary = m.summary()
    assert set(summary) == {"straight line", "local affine", "grid", "grid interpolation"}
