"""RFM fitting: exact recovery of known functional forms (closed-form truth)."""

import numpy as np
import pytest

from explorer.rpc import read_rpc
from explorer.rpc.fit import fit_rfm_from_gcps, fit_rfm_terrain_independent

from .conftest import RPC_DIR


@pytest.mark.parametrize(
    "name", ["rpc_IKONOS.txt", "rpc_PLEIADES.xml", "rpc_5395.vrt", "md_dg.RPB", "rpc_WV1.xml"]
)
def test_terrain_independent_fit_reproduces_real_rpc(name):
    """Same functional form as the source RPC, so the fit must reproduce it (< 1e-6 px) on
    an independent check grid offset by half a cell."""
    source = read_rpc(RPC_DIR / name)
    d = source.domain
    fit = fit_rfm_terrain_independent(
        source.projection,
        (source.lon_offset - abs(source.lon_scale), source.lon_offset + abs(source.lon_scale)),
        (source.lat_offset - abs(source.lat_scale), source.lat_offset + abs(source.lat_scale)),
        (d.h_min, d.h_max),
        grid=(12, 12, 6),
    )
    assert fit.n_check_points == 11 * 11 * 5
    assert fit.max_px < 1e-6
    assert fit.check_max_px < 1e-6
    # and independently of the fit's own check: a random sample of the domain
    rng = np.random.default_rng(7)
    lon = rng.uniform(d.lon_min, d.lon_max, 500)
    lat = rng.uniform(d.lat_min, d.lat_max, 500)
    h = rng.uniform(d.h_min, d.h_max, 500)
    r0, c0 = source.projection(lon, lat, h)
    r1, c1 = fit.model.projection(lon, lat, h)
    assert np.max(np.hypot(r1 - r0, c1 - c0)) < 1e-6


def test_regularised_fit_still_close():
    source = read_rpc(RPC_DIR / "rpc_IKONOS.txt")
    d = source.domain
    fit = fit_rfm_terrain_independent(
        source.projection,
        (d.lon_min, d.lon_max),
        (d.lat_min, d.lat_max),
        (d.h_min, d.h_max),
        grid=(10, 10, 5),
        regularization=1e-12,
    )
    assert fit.check_max_px < 1e-2


def test_grid_too_small():
    with pytest.raises(ValueError, match="too small"):
        fit_rfm_terrain_independent(lambda x, y, z: (x, y), (0, 1), (0, 1), (0, 1), grid=(3, 3, 1))


def _affine_truth(lon, lat, h):
    row = 100.0 + 2000.0 * (lon - 7.0) - 5000.0 * (lat - 43.0) + 0.3 * h
    col = -50.0 + 4000.0 * (lon - 7.0) + 300.0 * (lat - 43.0) - 0.1 * h
    return row, col


@pytest.mark.parametrize("rational", [True, False])
def test_gcp_fit_recovers_affine_model_exactly(rational):
    rng = np.random.default_rng(0)
    lon, lat, h = rng.uniform(7.0, 7.2, 30), rng.uniform(43.0, 43.1, 30), rng.uniform(0, 500, 30)
    row, col = _affine_truth(lon, lat, h)
    fit = fit_rfm_from_gcps(lon, lat, h, row, col, order=1, rational=rational)
    assert fit.max_px < 1e-8
    lon2, lat2, h2 = rng.uniform(7.0, 7.2, 50), rng.uniform(43.0, 43.1, 50), rng.uniform(0, 500, 50)
    r_true, c_true = _affine_truth(lon2, lat2, h2)
    r_fit, c_fit = fit.model.projection(lon2, lat2, h2)
    assert np.max(np.abs(r_fit - r_true)) < 1e-8
    assert np.max(np.abs(c_fit - c_true)) < 1e-8
    # first-order: only the 4 first terms are used
    assert not fit.model.row_num[4:].any() and not fit.model.row_den[4:].any()


@pytest.mark.parametrize(
    ("order", "rational", "needed"), [(1, True, 7), (2, True, 19), (3, True, 39), (3, False, 20)]
)
def test_gcp_fit_too_few_points(order, rational, needed):
    rng = np.random.default_rng(1)
    n = needed - 1
    lon, lat, h = rng.uniform(0, 1, (3, n))
    with pytest.raises(ValueError, match=f"at least {needed} needed"):
        fit_rfm_from_gcps(lon, lat, h, lon, lat, order=order, rational=rational)


def test_gcp_fit_bad_order_and_nan():
    with pytest.raises(ValueError, match="order must be"):
        fit_rfm_from_gcps([0], [0], [0], [0], [0], order=4)
    with pytest.raises(ValueError, match="lat contains NaN"):
        fit_rfm_from_gcps([0] * 8, [np.nan] * 8, [0] * 8, [0] * 8, [0] * 8, order=1)
