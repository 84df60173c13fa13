"""Plotly panels: the figures carry exactly the model's numbers; colour scales are symmetric
about 0 with limits from the residual percentiles (per map, shared, log magnitude) or fixed;
points without a residual are named by why; titles keep clear of the maps; the export page
opens offline.  The colour helpers map values to the right ends."""

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
        (tr,) = [t for t in fig.data if t.name == f"{name} row"]
        ok = np.isfinite(ev.residual_row)
        np.testing.assert_array_equal(np.asarray(tr.customdata)[:, 0], ev.residual_row[ok])
        np.testing.assert_array_equal(np.asarray(tr.customdata)[:, 1], ev.evaluated_index[ok])
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
    (tr,) = [t for t in fig.data if t.name == "toy_poly row"]
    assert len(tr.x) == 100
    pos = F.decimation_index(len(ev.residual_row), 100)
    np.testing.assert_array_equal(np.asarray(tr.customdata)[:, 0], ev.residual_row[pos])
    assert "100 drawn" in fig.layout.annotations[0].text
    assert np.all(np.diff(pos) > 0) and len(np.unique(np.diff(pos))) <= 2  # an even stride


def test_invalid_points_get_their_own_trace(results):
    scene, _, scps, evs = results
    ev = evs["toy_poly"]
    res = ev.residual_row.copy()
    res[[3, 10]] = np.nan
    bad = dataclasses.replace(ev, residual_row=res)
    fig = F.residual_maps({"m": bad}, scps, max_points=None)
    (inv,) = [t for t in fig.data if "not converged" in t.name]
    np.testing.assert_array_equal(np.asarray(inv.x), scps.col[ev.evaluated_index[[3, 10]]])
    assert inv.name.endswith(f"2 of {len(res):,}") and "%" not in inv.name  # no percentage of two points
    (tr,) = [t for t in fig.data if t.name == "m row"]
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


def _scaled(ev, factor: float):
    return dataclasses.replace(ev, residual_row=ev.residual_row * factor, residual_col=ev.residual_col * factor)


def test_automatic_per_map_limits_show_structure_at_1e_10_and_10_px(results):
    _, _, scps, evs = results
    ev = evs["toy_poly"]
    unit = ev.residual_row / np.nanmax(np.abs(ev.residual_row))
    tiny = dataclasses.replace(ev, residual_row=unit * 1e-10)
    big = dataclasses.replace(ev, residual_row=unit * 10.0)
    fig = F.residual_maps({"tiny": tiny, "big": big}, scps, max_points=None)  # default: per map
    assert fig.layout.meta["mode"] == "per method"
    for k, (name, e) in enumerate((("tiny", tiny), ("big", big))):
        axis = fig.layout[f"coloraxis{k + 1 if k else ''}"]
        lim = np.percentile(np.abs(e.residual_row), 99)
        assert axis.cmax == pytest.approx(lim, rel=1e-12) and axis.cmin == pytest.approx(-lim, rel=1e-12)
        assert f"{lim:.2g}" in axis.colorbar.title.text and "p99" in axis.colorbar.title.text
        (tr,) = [t for t in fig.data if t.name == f"{name} row"]
        assert tr.marker.coloraxis == f"coloraxis{k + 1 if k else ''}"
        colours = diverging_rgb(np.asarray(tr.marker.color), axis.cmax)
        assert len(np.unique(colours, axis=0)) > 20  # structure, not one flat colour
    # shared: one limit over both maps -- the tiny map then sits at the centre colour
    shared = F.residual_maps({"tiny": tiny, "big": big}, scps, max_points=None, mode="shared")
    lim = np.percentile(np.abs(np.concatenate([tiny.residual_row, big.residual_row])), 99)
    assert shared.layout.coloraxis.cmax == pytest.approx(lim, rel=1e-12)
    # log magnitude: log10 |residual| on one scale from the 1st to the 99th percentile
    log = F.residual_maps({"tiny": tiny, "big": big}, scps, max_points=None, mode="log magnitude")
    (tr,) = [t for t in log.data if t.name == "tiny row"]
    np.testing.assert_allclose(np.asarray(tr.marker.color), np.log10(np.abs(tiny.residual_row)), rtol=1e-12)
    allv = np.log10(np.abs(np.concatenate([tiny.residual_row, big.residual_row])))
    assert log.layout.coloraxis.cmin == pytest.approx(np.percentile(allv, 1))
    assert log.layout.coloraxis.cmax == pytest.approx(np.percentile(allv, 99))
    with pytest.raises(ValueError, match="mode"):
        F.residual_maps({"big": big}, scps, mode="linear")


def test_row_column_and_difference_maps(results):
    _, _, scps, evs = results
    fig = F.residual_maps(evs, scps, max_points=None, component="row and column",
                          difference=("toy_poly", "toy_bisect"))
    names = [t.name for t in fig.data if t.type == "scattergl" and t.showlegend is False]
    assert names == ["toy_poly row", "toy_poly column", "toy_bisect row", "toy_bisect column",
                     "toy_poly minus toy_bisect (row)"]
    poly, bis = evs["toy_poly"], evs["toy_bisect"]
    (col,) = [t for t in fig.data if t.name == "toy_poly column"]
    ok = np.isfinite(poly.residual_col)
    np.testing.assert_array_equal(np.asarray(col.customdata)[:, 0], poly.residual_col[ok])
    (diff,) = [t for t in fig.data if t.name.startswith("toy_poly minus")]
    idx = np.asarray(diff.customdata)[:, 1].astype(int)  # SCP indexes both methods evaluated
    assert set(idx) <= set(bis.evaluated_index) and len(idx) == np.isfinite(bis.residual_row).sum()
    pos_b = np.searchsorted(bis.evaluated_index, idx)
    expect = poly.residual_row[idx] - bis.residual_row[pos_b]  # toy_poly evaluated every SCP
    np.testing.assert_allclose(np.asarray(diff.customdata)[:, 0], expect, rtol=0, atol=0)


def test_refused_points_are_named_refused(results):
    _, _, scps, evs = results
    ev = evs["toy_poly"]
    res = ev.residual_row.copy()
    res[:40] = np.nan
    status = np.zeros(len(res), np.int8)
    status[:37] = 1  # refused (outside the method's domain)
    status[37:40] = 2  # not converged
    fig = F.residual_maps({"m": dataclasses.replace(ev, residual_row=res)}, scps, status={"m": status},
                          max_points=None)
    (ref,) = [t for t in fig.data if "refused" in t.name]
    (nc,) = [t for t in fig.data if "not converged" in t.name]
    assert len(ref.x) == 37 and len(nc.x) == 3 and "invalid" not in ref.name
    assert ref.name.endswith(f"37 ({100 * 37 / len(res):.2g}%)")
    np.testing.assert_array_equal(np.asarray(ref.x), scps.col[ev.evaluated_index[:37]])
    both = F.residual_maps({"m": dataclasses.replace(ev, residual_row=res, residual_col=res)}, scps,
                           status={"m": status}, max_points=None, component="row and column")
    refused = [t for t in both.data if "refused" in t.name]
    assert len(refused) == 2 and sum(bool(t.showlegend) for t in refused) == 1  # one entry toggles both maps


def test_titles_keep_clear_of_the_maps_and_many_scops_stay_small(results):
    scene, _, scps, evs = results
    scops = simulate_points(scene, 1000, kind="scop")
    five = {f"m{k}": evs["toy_poly"] for k in range(5)}
    fig = F.residual_maps(five, scps, control=scops, shape=scene.shape, component="row and column")
    meta = fig.layout.meta
    height = fig.layout.height
    inner = height - fig.layout.margin.t - fig.layout.margin.b
    doms = [fig.layout[f"yaxis{k + 1 if k else ''}"].domain for k in range(10)]
    tops = sorted({round(d[1], 9) for d in doms}, reverse=True)
    bottoms = sorted({round(d[0], 9) for d in doms}, reverse=True)
    assert len(tops) == 4  # 10 maps on 3 columns
    for upper_bottom, lower_top in zip(bottoms[:-1], tops[1:], strict=True):
        gap_px = (upper_bottom - lower_top) * inner
        # room for a two-line title above the lower map and the tick labels under the upper one
        assert gap_px >= meta["title_px"] + meta["axis_px"] - 1e-6
    assert fig.layout.margin.t >= meta["title_px"]  # the first row's titles
    for a in fig.layout.annotations:
        assert a.yanchor == "bottom" and a.text.count("<br>") == 1
    scop = [t for t in fig.data if t.name.startswith("SCOPs")]
    # 1,000 SCOPs: small and hidden at first, so they never cover the map; one legend entry shows them all
    assert scop[0].marker.size <= 4 and scop[0].showlegend and "click to show" in scop[0].name
    assert all(t.legendgroup == "scop" and t.visible == "legendonly" for t in scop)
    few = F.residual_maps(five, scps, control=simulate_points(scene, 100, kind="scop"))
    assert all(t.visible is not False and t.visible != "legendonly" for t in few.data if t.name.startswith("SCOPs"))
    hidden = F.residual_maps(five, scps, control=scops, show_control=False)
    assert not [t for t in hidden.data if t.name.startswith("SCOPs")]


def test_panels_html_opens_offline_and_is_deterministic(results):
    scene, scops, scps, evs = results
    figs = [("maps", F.residual_maps(evs, scps, control=scops, shape=scene.shape)), ("timing", F.timing_bars(evs))]
    page = F.figures_html(figs, "export", ["note"])
    assert page == F.figures_html(figs, "export", ["note"])  # no random element ids
    assert "<script src=" not in page.replace(" ", "") and "cdn.plot.ly" not in page.split("/*")[0]
    assert page.count('id="panel-') == 2 and "Plotly.newPlot" in page
    assert len(page) > 3_000_000  # plotly.js inlined
    assert F.PLOTLY_CONFIG["showSendToCloud"] is False
    assert "sendDataToCloud" in F.PLOTLY_CONFIG["modeBarButtonsToRemove"]
    assert '"showSendToCloud": false' in page and '"displaylogo": false' in page
