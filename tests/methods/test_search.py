"""SS, BWS and their eq. 4 interpolated versions against independent truth.

Truth: the exact rows of points made by ``image_to_ground`` (round trip checked to 1e-9 px in
``tests/test_scene.py``), the brute-force solver of ``tests/truth.py``, and closed forms (CE
counts of the searches, the error of linear interpolation between two lines).
"""

from functools import lru_cache

import numpy as np
import pytest

from explorer.methods import available, create
from explorer.presets import build_scene, preset_ids
from tests.methods.cases import random_image_points as _points
from tests.truth import brute_force_rows

ALL_PRESETS = preset_ids()
SEARCH = ("ss", "bws", "ss-interp", "bws-interp")

# eq. 4 is a linear interpolation between two lines; on ``agile`` the 67 Hz / 41 Hz attitude jitter
# curves x(t) by ~5e-4 px per line^2, so the interpolation error reaches ~7e-5 px (measured 6.96e-5
# max; without the jitter 3.1e-7).  test_interp_error_is_the_linear_interpolation_error checks that
# the error is exactly that closed form; the 1e-6 px acceptance bar is not met there.
AGILE_XFAIL = pytest.mark.xfail(
    strict=True,
    reason="eq. 4 linear interpolation error on agile is ~7e-5 px (jitter curvature of x(t)), > 1e-6",
)


def _maybe_xfail(preset):
    return pytest.param(preset, marks=AGILE_XFAIL) if preset == "agile" else preset


@lru_cache(maxsize=16)
def _scene(preset, relief=0.0):
    return build_scene(preset, relief_m=relief, relief_seed=3)




def _fpx(scene, ground, row):
    return scene.along_track_residual(ground, scene.scanline_time(row)) / scene.pixel_size_m


def test_registry_entries():
    names = available("search")
    for name in SEARCH:
        assert name in names
    s = _scene("WSU")
    assert create("ss", s).exactness == "pixel" and create("bws", s).exactness == "pixel"
    assert create("ss-interp", s).exactness == "approximate"
    assert create("bws-interp", s).exactness == "approximate"
    with pytest.raises(ValueError):
        create("bws", s, final_window=1)
    with pytest.raises(ValueError):
        create("ss", s, select="middle")
    with pytest.raises(TypeError):
        create("ss", s, final_window=4)


def _check_pixel_rows(scene, res, row, col, ground):
    r = res.row
    assert np.all(res.converged) and np.all(res.valid)
    np.testing.assert_array_equal(r, np.round(r))  # integer rows
    err = r - row
    assert np.max(np.abs(err)) <= 0.5 + 1e-9  # dr_max of a pixel-level search
    # one of the two bracketing rows, and the nearest one away from ties
    assert np.all((r == np.floor(row)) | (r == np.ceil(row)))
    clear = np.abs(row - np.floor(row) - 0.5) > 1e-4
    np.testing.assert_array_equal(r[clear], np.round(row[clear]))
    # the column is the collinearity column at the returned row
    np.testing.assert_allclose(res.col, scene.column_at_row(ground, r), atol=1e-9)


def _pixel_search(name, preset, n, seed):
    """Exact rows (N,) of seeded random image points and the result of the pixel search ``name`` on them
    (checked by :func:`_check_pixel_rows`)."""
    scene = _scene(preset)
    row, col, ground = _points(scene, n, seed=seed)
    res = create(name, scene).ground_to_image(ground)
    _check_pixel_rows(scene, res, row, col, ground)
    return row, res


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_bws_returns_nearest_integer_row(preset):
    row, res = _pixel_search("bws", preset, 2000, seed=1)
    # the RMSE is the rounding RMSE of the exact rows (about 1 / sqrt(12) = 0.289 px)
    rmse = np.sqrt(np.mean((res.row - row) ** 2))
    assert rmse == pytest.approx(np.sqrt(np.mean((np.round(row) - row) ** 2)), abs=1e-9)
    assert 0.27 < rmse < 0.31


@pytest.mark.parametrize("preset", ALL_PRESETS)
def test_ss_returns_nearest_integer_row_and_agrees_with_bws(preset):
    row, res = _pixel_search("ss", preset, 60, seed=2)
    np.testing.assert_array_equal(res.row, _pixel_search("bws", preset, 60, seed=2)[1].row)


def test_select_lower_truncates():
    scene = _scene("WSU")
    row, col, ground = _points(scene, 2000, seed=3)
    row, ground = row[row > 0], ground[row > 0]
    res = create("bws", scene, select="lower").ground_to_image(ground)
    np.testing.assert_array_equal(res.row, np.floor(row))
    assert 0.55 < np.sqrt(np.mean((res.row - row) ** 2)) < 0.6  # uniform [0, 1) error: RMSE 1/sqrt(3)


@pytest.mark.parametrize("preset", [_maybe_xfail(p) for p in ALL_PRESETS])
def test_bws_interp_within_1e6_px(preset):
    scene = _scene(preset)
    row, col, ground = _points(scene, 2000, seed=4)
    res = create("bws-interp", scene).ground_to_image(ground)
    assert np.all(res.valid)
    assert np.max(np.abs(res.row - row)) < 1e-6
    np.testing.assert_allclose(res.col, col, atol=1e-6)


@pytest.mark.parametrize("preset", [_maybe_xfail(p) for p in ALL_PRESETS])
def test_ss_interp_within_1e6_px_and_equal_to_bws_interp(preset):
    scene = _scene(preset)
    row, col, ground = _points(scene, 60, seed=5)
    res = create("ss-interp", scene).ground_to_image(ground)
    # both searches end on the same bracketing pair of lines, so eq. 4 gives the same row
    np.testing.assert_array_equal(res.row, create("bws-interp", scene).ground_to_image(ground).row)
    assert np.all(res.valid)
    assert np.max(np.abs(res.row - row)) < 1e-6


@pytest.mark.parametrize("preset", ["ISB", "PMA", _maybe_xfail("agile")])
def test_interp_within_1e6_px_with_relief(preset):
    scene = _scene(preset, 800.0)
    row, col, ground = _points(scene, 1500, seed=6)
    assert np.ptp(ground[:, 2]) > 400  # the points do spread over the relief
    res = create("bws-interp", scene).ground_to_image(ground)
    assert np.all(res.valid)
    assert np.max(np.abs(res.row - row)) < 1e-6
    sub = slice(0, 30)
    res_ss = create("ss-interp", scene).ground_to_image(ground[sub])
    assert np.max(np.abs(res_ss.row - row[sub])) < 1e-6


@pytest.mark.parametrize("preset,relief", [(p, 0.0) for p in ALL_PRESETS] + [("agile", 800.0), ("ISB", 800.0)])
def test_interp_error_is_the_linear_interpolation_error(preset, relief):
    """For x(t) = a e + b e^2 + c e^3 (e = t - r) the root of the chord between the lines
    t1 = floor(r) and t1 + 1 misses r by -u (1 - u) (b + c (1 - 2 u)) / a + O((b/a)^2), u = r - t1:
    at most about |x''| / (8 |x'|) px."""
    scene = _scene(preset, relief)
    row, col, ground = _points(scene, 400, seed=7)
    res = create("bws-interp", scene).ground_to_image(ground)
    h = 2.0
    f = {k: _fpx(scene, ground, row + k * h) for k in (-2, -1, 0, 1, 2)}
    a = (f[1] - f[-1]) / (2 * h)
    b = (f[1] - 2 * f[0] + f[-1]) / (2 * h**2)
    c = (f[2] - 2 * f[1] + 2 * f[-1] - f[-2]) / (12 * h**3)
    u = row - np.floor(row)
    predicted = -u * (1 - u) * (b + c * (1 - 2 * u)) / a
    err = res.row - row
    assert np.all(np.abs(err - predicted) <= 0.05 * np.abs(predicted) + 5e-10)
    if preset == "agile":
        assert np.max(np.abs(err)) > 1e-5  # documents why agile misses the 1e-6 px bar


def test_ss_ce_closed_form():
    """SS evaluates rows -1, 0, ..., ceil(r): ceil(r) + 2 CE (column free; +1 for the interpolated one)."""
    scene = _scene("SCB")
    row, col, ground = _points(scene, 200, seed=8)
    res = create("ss", scene).ground_to_image(ground)
    expected = np.ceil(row).astype(int) + 2
    np.testing.assert_array_equal(res.ce_evaluations, expected)
    np.testing.assert_array_equal(create("ss-interp", scene).ground_to_image(ground).ce_evaluations, expected + 1)
    # about half the image on average
    assert abs(res.ce_evaluations.mean() - (scene.n_rows / 2 + 2)) < 0.1 * scene.n_rows


def _halvings(length0: int, window: int) -> tuple[int, int]:
    """Fewest and most halvings of an interval of ``length0`` lines (floor/ceil halves) until it
    spans at most ``window - 1`` lines."""
    h_min = next(h for h in range(64) if length0 // 2**h <= window - 1)
    h_max = next(h for h in range(64) if -(-length0 // 2**h) <= window - 1)
    return h_min, h_max


@pytest.mark.parametrize("preset", ["ISB", "WSU", "SCB"])
@pytest.mark.parametrize("window", [2, 8, 16])
def test_bws_ce_closed_form(preset, window):
    scene = _scene(preset)
    row, col, ground = _points(scene, 1000, seed=9)
    res = create("bws", scene, final_window=window).ground_to_image(ground)
    ce = res.ce_evaluations
    length0 = scene.n_rows + 1  # window [-1, rows]
    h_min, h_max = _halvings(length0, window)
    # 2 (window ends) + halvings + at most window - 2 sequential rows; the column is free
    assert ce.min() >= 2 + h_min and ce.max() <= 2 + h_max + window - 2
    # mean: the sequential part of a final window of L lines costs (L - 1)(L + 2) / (2 L) on average
    big = window - 1
    assert 2 + h_min <= ce.mean() <= 2 + h_max + (big - 1) * (big + 2) / (2 * big)
    np.testing.assert_array_equal(
        create("bws-interp", scene, final_window=window).ground_to_image(ground).ce_evaluations, ce + 1
    )
    if window == 2:  # pure bisection: ceil or floor of log2 + 2
        assert set(np.unique(ce)) <= {2 + int(np.floor(np.log2(length0))), 2 + int(np.ceil(np.log2(length0)))}


def test_bws_ce_matches_paper_for_6000_lines():
    """Ahooei Nezhad et al. 2020, Table 2: at most 15 CE per point for the 6000-line SPOT scene."""
    scene = _scene("QII")  # 6000 rows
    row, col, ground = _points(scene, 2000, seed=10)
    assert create("bws", scene, final_window=2).ground_to_image(ground).ce_evaluations.max() == 15


def _outside_and_edge_points(scene):
    rows, cols = scene.n_rows, scene.n_columns
    r = np.array([-50.0, rows + 50.0, 1000.3, 900.6, -0.7, -0.3, rows - 0.7, rows - 0.2, 700.2])
    c = np.array([100.0, 100.0, -100.0, cols + 100.0, 50.0, 50.0, 60.0, 60.0, 300.0])
    #        converged:  F     F       T       T       T     T      T         T       T
    #        inside:     F     F       F       F       F*    T      T         F*      T
    # (* pixel-level: rounds to -1 / rows, outside; interpolated: -0.7 / rows - 0.2, outside)
    return r, c, scene.image_to_ground(r, c, height=scene.terrain.mean_height)


@pytest.mark.parametrize("method", SEARCH)
def test_out_of_image_points_are_flagged(method):
    scene = _scene("WSU")
    r, c, ground = _outside_and_edge_points(scene)
    res = create(method, scene).ground_to_image(ground)
    np.testing.assert_array_equal(res.converged, [False, False, True, True, True, True, True, True, True])
    np.testing.assert_array_equal(res.inside, [False, False, False, False, False, True, True, False, True])
    assert np.all(np.isnan(res.row[:2])) and np.all(np.isnan(res.col[:2]))
    truth = brute_force_rows(scene, ground[2:])
    if method.endswith("interp"):
        np.testing.assert_allclose(res.row[2:], truth, atol=1e-6)
        np.testing.assert_allclose(res.col[2:], c[2:], atol=1e-6)
    else:
        np.testing.assert_array_equal(res.row[2:], np.round(truth))
    # no row, no column CE: SS walked the whole window [-1, rows]; BWS saw the same sign at both ends
    np.testing.assert_array_equal(res.ce_evaluations[:2], scene.n_rows + 2 if method.startswith("ss") else 2)


def test_bws_trace_window_halves():
    scene = _scene("WSU")
    row, col, ground = _points(scene, 50, seed=11)
    ground = np.vstack([ground, _outside_and_edge_points(scene)[2][:1]])  # + a point below the image
    window = 8
    res = create("bws", scene, final_window=window).ground_to_image(ground, trace=True)
    windows = res.info["windows"]
    tr = res.trace
    np.testing.assert_array_equal(tr[0][:-1], -1.0)
    np.testing.assert_array_equal(tr[1][:-1], scene.n_rows)
    assert np.all(np.isnan(np.stack(tr[2:])[:, -1]))  # the outside point stopped after the window ends
    lengths = [w[:-1, 1] - w[:-1, 0] for w in windows]
    np.testing.assert_array_equal(lengths[0], scene.n_rows + 1)
    for k in range(1, len(windows)):
        prev, cur = lengths[k - 1], lengths[k]
        live = np.isfinite(cur)
        assert np.all((cur[live] == np.floor(prev[live] / 2)) | (cur[live] == np.ceil(prev[live] / 2)))
        # the midpoint visited at step k (trace index k + 1) is floor((first + last) / 2) of the window before
        mid = np.floor(0.5 * (windows[k - 1][:-1, 0] + windows[k - 1][:-1, 1]))
        np.testing.assert_array_equal(tr[k + 1][:-1][live], mid[live])
    for w in windows:  # every window holds the exact row
        ok = np.isfinite(w[:-1, 0])
        assert np.all((w[:-1, 0][ok] <= row[ok]) & (row[ok] <= w[:-1, 1][ok]))
    assert np.all(lengths[-1][np.isfinite(lengths[-1])] <= window - 1)
    # the trace holds exactly the CE spent by each point
    visited = np.sum(np.isfinite(np.stack(tr)), axis=0)
    np.testing.assert_array_equal(visited, res.ce_evaluations)


def test_ss_trace_walks_consecutive_rows():
    scene = _scene("SCB")
    row, col, ground = _points(scene, 20, seed=12)
    res = create("ss", scene).ground_to_image(ground, trace=True)
    tr = np.stack(res.trace)
    assert tr.shape == (np.ceil(row).max() + 2, row.size)
    for j in range(row.size):
        seen = tr[:, j][np.isfinite(tr[:, j])]
        np.testing.assert_array_equal(seen, np.arange(-1, np.ceil(row[j]) + 1))
        assert np.all(np.isnan(tr[seen.size:, j]))
