"""Plotly panels: the figures carry exactly the model's numbers, on one fixed diverging
colour scale centred at 0; the colour helpers map values to the right ends."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from explorer.evaluate import evaluate_method
from explorer.panels import (
    DIVERGING,
    INVALID_RGB,
    NEGATIVE_END,
    POSITIVE_END,
    diverging_rgb,
    height_rgb,
    plotly_colorscale,
    ramp,
)
from explorer.panels import figures as F  # noqa: N812
from explorer.points import simulate_points
from explorer.presets import build_scene
from tests.test_app import ToyBisect, ToyPoly


@pytest.fixture(scope="module")
def results():
    scene = build_scene("WSU")
    scops = simulate_points(scene, 50, kind="scop")
    scps = simulate_points(scene, 2000, kind="scp")
    evs = {
        "toy_poly": evaluate_method(ToyPoly(scene), scps, scops),
        "toy_bisect": evaluate_method(ToyBisect(scene), scps, max_points=500, seed=3),
    }
    return scene, scops, scps, evs


def test_colour_helpers():
    assert tuple(diverging_rgb(np.array([0.0]), 1.0)[0]) == DIVERGING[4][1]  # centre
    c = diverging_rgb(np.array([5.0, 1.0, -1.0, -3.0, np.nan, 0.5]), 1.0)
    assert tuple(c[0]) == POSITIVE_END and tuple(c[1]) == POSITIVE_END
    assert tuple(c[2]) == NEGATIVE_END and tuple(c[3]) == NEGATIVE_END
    assert tuple(c[4]) == INVALID_RGB
    assert tuple(c[5]) == DIVERGING[6][1]  # +0.5 of +-1 is the 0.75 stop
    np.testing.assert_array_equal(ramp(np.array([0.25]), [(0.0, (0, 0, 0)), (1.0, (200, 100, 40))], 0, 1),
                                  [[50, 25, 10]])
    assert (height_rgb(np.array([5.0, 5.0]), 5.0, 5.0) == height_rgb(np.array([1.0]), 0, 0)[0]).all()
    with pytest.raises(ValueError):
        diverging_rgb(np.zeros(2), 0.0)
    cs = plotly_colorscale(DIVERGING)
    assert cs[0] == [0.0, "rgb(59,76,192)"] and cs[-1][0] == 1.0


def test_residual_maps_hold_the_residuals(results):
    scene, scops, scps, evs = results
    fig = F.residual_maps(evs, scps, control=scops, shape=scene.shape, limit_px=0.02, max_points=None)
    for name, ev in evs.items():
        (tr,) = [t for t in fig.data if t.name == name]
        ok = np.isfinite(ev.residual_row)
        np.testing.assert_array_equal(np.asarray(tr.customdata), ev.residual_row[ok])
        np.testing.assert_array_equal(np.asarray(tr.marker.color), ev.residual_row[ok])
        np.testing.assert_array_equal(np.asarray(tr.x), scps.col[ev.evaluated_index[ok]])
        np.testing.assert_array_equal(np.asarray(tr.y), scps.row[ev.evaluated_index[ok]])
        assert tr.marker.coloraxis == "coloraxis"
        for word in ("row", "col", "residual"):
            assert word in tr.hovertemplate
    # the residuals themselves against truth: rows minus the SCPs' exact rows
    poly = evs["toy_poly"]
    truth = ToyPoly(scene).fit(scops).ground_to_image(scps.ground).row - scps.row
    np.testing.assert_allclose(poly.residual_row, truth, atol=1e-9)
    # one shared, fixed, symmetric scale centred at 0
    ca = fig.layout.coloraxis
    assert (ca.cmin, ca.cmax, ca.cmid) == (-0.02, 0.02, 0.0)
    assert [list(x) for x in ca.colorscale] == plotly_colorscale(DIVERGING)
    scop_traces = [t for t in fig.data if t.name and t.name.startswith("SCOPs")]
    assert len(scop_traces) == 2 and len(scop_traces[0].x) == len(scops)
    np.testing.assert_array_equal(np.asarray(scop_traces[0].x), scops.col)
    # image axes: column across, row down (row 0 at the top)
    assert tuple(fig.layout.yaxis.range) == (scene.n_rows - 0.5, -0.5)
    assert fig.layout.xaxis2.matches == "x" and fig.layout.yaxis2.matches == "y"
    titles = [a.text for a in fig.layout.annotations]
    assert f"500 of {len(scps):,} SCPs" in titles[1]  # the subsample is named
    fig.to_json()


def test_residual_maps_decimate_and_name_it(results):
    scene, scops, scps, evs = results
    fig = F.residual_maps(evs, scps, shape=scene.shape, max_points=100)
    ev = evs["toy_poly"]
    (tr,) = [t for t in fig.data if t.name == "toy_poly"]
    assert len(tr.x) == 100
    pos = F.decimation_index(len(ev.residual_row), 100)
    np.testing.assert_array_equal(np.asarray(tr.customdata), ev.residual_row[pos])
    assert "100 drawn" in fig.layout.annotations[0].text
    assert np.all(np.diff(pos) > 0) and len(np.unique(np.diff(pos))) <= 2  # an even stride


def test_invalid_points_get_their_own_trace(results):
    scene, _, scps, evs = results
    ev = evs["toy_poly"]
    res = ev.residual_row.copy()
    res[[3, 10]] = np.nan
    bad = dataclasses.replace(ev, residual_row=res)
    fig = F.residual_maps({"m": bad}, scps, max_points=None)
    (inv,) = [t for t in fig.data if t.name == "no valid row"]
    np.testing.assert_array_equal(np.asarray(inv.x), scps.col[ev.evaluated_index[[3, 10]]])
    (tr,) = [t for t in fig.data if t.name == "m"]
    assert len(tr.x) == len(res) - 2
    assert fig.layout.yaxis.autorange == "reversed"


def test_accuracy_vs_density(results):
    scene, _, scps, evs = results
    sweep_poly = []
    for n in (30, 10, 100):
        scops = simulate_points(scene, n, kind="scop")
        sweep_poly.append(evaluate_method(ToyPoly(scene), scps, scops))
    fig = F.accuracy_vs_density({"toy_poly": sweep_poly, "toy_bisect": [evs["toy_bisect"]]})
    (rm,) = [t for t in fig.data if t.name == "toy_poly RMSE"]
    (dm,) = [t for t in fig.data if t.name == "toy_poly dr_max"]
    order = np.argsort([e.n_scops for e in sweep_poly])
    np.testing.assert_array_equal(np.asarray(rm.x), [sweep_poly[i].n_scops for i in order])
    np.testing.assert_array_equal(np.asarray(rm.customdata), [sweep_poly[i].rmse_px for i in order])
    np.testing.assert_array_equal(np.asarray(dm.customdata), [sweep_poly[i].dr_max_px for i in order])
    assert dm.line.dash == "dash"
    (flat,) = [t for t in fig.data if t.name.startswith("toy_bisect RMSE")]
    assert "no SCOPs" in flat.name and tuple(flat.x) == (10, 1000)
    np.testing.assert_allclose(np.asarray(flat.y), max(evs["toy_bisect"].rmse_px, F.LOG_FLOOR_PX))
    assert fig.layout.xaxis.type == "log" and fig.layout.yaxis.type == "log"
    (line,) = [s for s in fig.layout.shapes if s.y0 == 1.0 and s.y1 == 1.0]
    assert line.line.dash == "dot"


def test_timing_bars(results):
    _, _, _, evs = results
    fig = F.timing_bars(evs)
    fit, per = fig.data
    assert list(fit.x) == ["toy_poly", "toy_bisect"]
    assert fit.y[0] == pytest.approx(evs["toy_poly"].fit_s) and fit.y[1] is None
    for k, n in enumerate(evs):
        assert per.y[k] == pytest.approx(1e6 * evs[n].locate_s / evs[n].n_evaluated)
    assert fig.layout.yaxis.type == "log" and fig.layout.yaxis2.type == "log"
    assert "500 pts" in per.text[1]


def test_empty_inputs():
    fig = F.residual_maps({}, simulate_points(build_scene("WSU"), 10, kind="scp"))
    assert fig.layout.annotations[0].text == "no method evaluated"
