"""explorer.stereo.epipolar_curve against rpcm (the exact inverse of its projection) and against a brute-force
curve found from the other side (dense right-image localisation, inverted by interpolation)."""

from __future__ import annotations

import numpy as np
import pytest

from explorer import read_rpc
from explorer.errors import InputError
from explorer.stereo import epipolar_curve
from explorer.stereo.epipolar import chord_deviation
from explorer.stereo.sensors import localise, project
from tests.stereo.pairs import PHR_PAIRS, rpcm_localise, rpcm_pair, synthetic_pair

HEIGHTS = np.linspace(60.0, 1100.0, 12)


@pytest.mark.parametrize("kind", ["xml", "geom"])
def test_curve_matches_rpcm_within_1e6_px(kind):
    peer_l, peer_r = rpcm_pair()
    left, right = (read_rpc(p) for p in PHR_PAIRS[kind])
    rows = np.array([0.0, 5000.0, 11469.5, 22939.0, 17000.0])
    cols = np.array([0.0, 39999.0, 20000.0, 100.0, 31000.0])
    curve = epipolar_curve(left, right, rows, cols, HEIGHTS)
    assert curve.row.shape == (5, HEIGHTS.size) and curve.direction.shape == (5, HEIGHTS.size, 2)
    for i in range(rows.size):
        lon, lat = rpcm_localise(peer_l, np.full(HEIGHTS.size, rows[i]), np.full(HEIGHTS.size, cols[i]), HEIGHTS)
        col_ref, row_ref = peer_r.projection(lon, lat, HEIGHTS)
        assert np.max(np.abs(curve.row[i] - row_ref)) < 1e-6
        assert np.max(np.abs(curve.col[i] - col_ref)) < 1e-6
        # the tangent: direction of rpcm's curve over +-0.01 m
        lo2, la2 = rpcm_localise(peer_l, np.full(HEIGHTS.size, rows[i]), np.full(HEIGHTS.size, cols[i]),
                                 HEIGHTS + 0.01)
        c2, r2 = peer_r.projection(lo2, la2, HEIGHTS + 0.01)
        d = np.stack([r2 - row_ref, c2 - col_ref], -1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        assert np.max(np.abs(curve.direction[i] - d)) < 1e-5
    # the Pleiades pair's curves bend: a few hundredths of a pixel over 1 km of height (docs/stereo.md)
    assert 1e-3 < np.max(curve.max_chord_deviation_px) < 1.0


def test_chord_deviation_of_a_parabola():
    x = np.linspace(-1.0, 1.0, 21)
    row, col = 3.0 * x**2, 4.0 * x  # chord from (3, -4) to (3, 4) along col; deviation = row - 3 (sign: left)
    dev = chord_deviation(row, col)
    np.testing.assert_allclose(np.abs(dev), np.abs(3.0 - row), atol=1e-12)


def test_brute_force_curve_of_the_synthetic_pair():
    """For each height, localise a dense 21 x 21 patch of the right image at that height, project it into the
    left image, and find where it hits the left pixel by a local quadratic fit (inverse interpolation)."""
    left, right = synthetic_pair()
    row0, col0 = 900.0, 1100.0
    heights = np.linspace(-200.0, 900.0, 6)
    curve = epipolar_curve(left, right, row0, col0, heights)
    assert np.max(np.abs(curve.chord_deviation_px)) > 0.0
    for k, h in enumerate(heights):
        centre_r, centre_c = np.round(curve.row[k]), np.round(curve.col[k])
        rr, cc = np.meshgrid(centre_r + np.arange(-10, 11), centre_c + np.arange(-10, 11), indexing="ij")
        g, ok = localise(right, rr.ravel(), cc.ravel(), np.full(rr.size, h))
        assert ok.all()
        lr, lc = project(left, g)
        # quadratic model right(row, col) = f(left row, left col) over the patch, evaluated at the left pixel
        du, dv = lr - row0, lc - col0
        design = np.column_stack([np.ones_like(du), du, dv, du * du, du * dv, dv * dv])
        coef_r = np.linalg.lstsq(design, rr.ravel(), rcond=None)[0]
        coef_c = np.linalg.lstsq(design, cc.ravel(), rcond=None)[0]
        assert abs(coef_r[0] - curve.row[k]) < 1e-4
        assert abs(coef_c[0] - curve.col[k]) < 1e-4


def test_bad_heights():
    left, right = (read_rpc(p) for p in PHR_PAIRS["xml"])
    with pytest.raises(InputError, match="at least 2"):
        epipolar_curve(left, right, 10.0, 10.0, [100.0])
    with pytest.raises(InputError, match="heights"):
        epipolar_curve(left, right, 10.0, 10.0, [100.0, np.nan])
