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
from explorer.panels.raster import MAX_FIGURE_CELLS
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


def _cell_means(edges_r, edges_c, rows, cols, values, how="mean"):
    """Brute-force truth of a map raster: a loop over the cells with explicit edge tests."""
    out = np.full((len(edges_r) - 1, len(edges_c) - 1), np.nan)
    last_r, last_c = len(edges_r) - 2, len(edges_c) - 2
    for i in range(len(edges_r) - 1):
        in_r = (rows >= edges_r[i]) & ((rows < edges_r[i + 1]) | (i == last_r))
        for j in range(len(edges_c) - 1):
            sel = in_r & (cols >= edges_c[j]) & ((cols < edges_c[j + 1]) | (j == last_c))
            v = values[sel & np.isfinite(values)]
            if v.size:
                out[i, j] = v.mean() if how == "mean" else v[np.argmax(np.abs(v))]
    return out


def _map(fig, name):
    (tr,) = [t for t in fig.data if t.name == name and t.type == "heatmap"]
    return tr


def test_residual_maps_hold_the_residuals(results):
    """Each map is a heatmap of the per-cell mean of the evaluation's residuals (brute-force truth),
    with cells from the SCP grid: one SCP per cell here (2,000 SCPs), so every cell holds exactly the
    residual of its point."""
    scene, scops, scps, evs = results
    fig = F.residual_maps(evs, scps, control=scops, shape=scene.shape, limit_px=0.02)
    for name, ev in evs.items():
        tr = _map(fig, f"{name} row")
        idx = ev.evaluated_index
        truth = _cell_means(np.asarray(tr.y), np.asarray(tr.x), scps.row[idx], scps.col[idx], ev.residual_row)
        np.testing.assert_allclose(np.asarray(tr.z), truth, rtol=1e-12, atol=1e-15)
        assert tr.coloraxis == "coloraxis" and tr.zsmooth is False
        for word in ("row", "col", "residual", "SCP"):
            assert word in tr.hovertemplate
    assert tuple(fig.layout.meta["cells"]) == scps.grid_shape[:2]
    poly = _map(fig, "toy_poly row")
    z = np.asarray(poly.z)
    assert np.isfinite(z).all()  # every SCP evaluated: no empty cell
    # one point per cell: the cell's worst point is that point, and its value the point's residual
    worst = np.asarray(poly.customdata)[..., 1].ravel()
    np.testing.assert_array_equal(np.sort(worst), np.arange(len(scps)))
    np.testing.assert_array_equal(z.ravel(), evs["toy_poly"].residual_row[worst])
    # the residuals themselves against truth: rows minus the SCPs' exact rows
    poly_ev = evs["toy_poly"]
    truth = ToyPoly(scene).fit(scops).ground_to_image(scps.ground).row - scps.row
    np.testing.assert_allclose(poly_ev.residual_row, truth, atol=1e-9)
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
    assert f"500 of {len(scps):,} SCPs: seeded preview" in titles[1]  # the preview is named
    assert f"all {len(scps):,} SCPs" in titles[0]
    # the 1,500 SCPs toy_bisect did not evaluate: transparent cells, named and counted in the legend
    bis = np.asarray(_map(fig, "toy_bisect row").z)
    assert np.isnan(bis).sum() == len(scps) - 500
    fig.to_json()


@pytest.mark.parametrize("how", ["mean", "max |residual|"])
@pytest.mark.parametrize("layout", ["grid", "grid 2x2 per cell", "grid 3x3 ragged", "random", "wide image"])
def test_constant_field_draws_the_constant_in_every_cell(how, layout):
    """Issue 24: no pattern may come from the drawing.  On a residual field that is constant by
    construction, every drawn cell of the raster holds exactly that constant, for any point layout;
    the only cells without a value are those without a point, and grid points fill every cell with the
    same number of points (no stripes from uneven cells)."""
    scene = build_scene("WSU" if layout != "wide image" else "SCB")
    n = {"grid": 2000, "grid 2x2 per cell": 40_000, "grid 3x3 ragged": 45_000, "random": 3000,
         "wide image": 5000}[layout]
    scps = simulate_points(scene, n, kind="scp")
    if layout == "random":
        rng = np.random.default_rng(1)
        rows = rng.uniform(-0.5, scene.n_rows - 0.5, n)
        cols = rng.uniform(-0.5, scene.n_columns - 0.5, n)
        scps = dataclasses.replace(scps, row=rows, col=cols, ground=np.zeros((n, 3)), time=np.zeros(n),
                                   grid_shape=(0, 0, 1))
    n = len(scps)
    c = -0.3712345678901234
    ev = dataclasses.replace(evaluate_method(ToyPoly(scene), scps.subset(np.arange(10)),
                                             simulate_points(scene, 50, kind="scop")),
                             n_scps=n, n_evaluated=n, residual_row=np.full(n, c), residual_col=np.full(n, c),
                             evaluated_index=np.arange(n))
    max_cells = {"grid 2x2 per cell": 10_000, "grid 3x3 ragged": 5_000}.get(layout, 15_000)
    fig = F.residual_maps({"m": ev}, scps, shape=scene.shape, aggregate=how, max_cells=max_cells,
                          component="row and column")
    for comp in ("row", "column"):
        tr = _map(fig, f"m {comp}")
        z = np.asarray(tr.z)
        counts = np.asarray(tr.customdata)[..., 0]
        drawn = np.isfinite(z)
        assert drawn.any() and (z[drawn] == c).all()
        np.testing.assert_array_equal(drawn, counts > 0)  # empty only where no point
        assert counts.sum() == n
        if layout.startswith("grid") or layout == "wide image":
            assert drawn.all()
            inner = counts[:-1, :-1]  # the last row / column of cells may hold fewer grid nodes
            assert inner.min() == inner.max()
    if layout == "grid 2x2 per cell":
        assert np.asarray(_map(fig, "m row").customdata)[..., 0].max() == 4
    with pytest.raises(ValueError, match="aggregate"):
        F.residual_maps({"m": ev}, scps, aggregate="median")


def test_many_maps_share_the_figure_cell_budget():
    """Issue 24: panels.html under 5 MB with every method.  Thirty maps (15 methods, row and column) of
    50,000 grid SCPs share :data:`MAX_FIGURE_CELLS`: each map gets the same coarser grid of whole node
    blocks, a constant field still draws its constant in every cell, and the maps' arrays stay small."""
    scene = build_scene("WSU")
    scps = simulate_points(scene, 50_000, kind="scp")
    n = len(scps)
    c = 0.1234567890123
    base = evaluate_method(ToyPoly(scene), scps.subset(np.arange(10)), simulate_points(scene, 50, kind="scop"))
    ev = dataclasses.replace(base, n_scps=n, n_evaluated=n, residual_row=np.full(n, c),
                             residual_col=np.full(n, c), evaluated_index=np.arange(n))
    few = F.residual_maps({"m0": ev}, scps, shape=scene.shape, component="row and column")
    many = F.residual_maps({f"m{k}": ev for k in range(15)}, scps, shape=scene.shape, component="row and column")
    maps = [t for t in many.data if t.type == "heatmap" and t.coloraxis]
    assert len(maps) == 30
    sizes = {np.asarray(t.z).shape for t in maps}
    assert len(sizes) == 1  # one grid for every map
    (shape,) = sizes
    assert 30 * shape[0] * shape[1] <= MAX_FIGURE_CELLS
    few_shape = np.asarray(_map(few, "m0 row").z).shape
    assert few_shape[0] * few_shape[1] > shape[0] * shape[1]  # one method keeps the finer grid
    for t in maps:
        z = np.asarray(t.z)
        assert np.isfinite(z).all() and (z == c).all()
        assert np.asarray(t.customdata)[..., 0].sum() == n  # every point in one cell
    assert len(many.to_json()) < 3_400_000  # + plotly.js (1.5 MB) and the other panels: < 5 MB


def test_max_residual_cells_hold_the_worst_point(results):
    scene, _, scps, evs = results
    ev = evs["toy_poly"]
    fig = F.residual_maps({"m": ev}, scps, shape=scene.shape, aggregate="max |residual|", max_cells=500)
    tr = _map(fig, "m row")
    truth = _cell_means(np.asarray(tr.y), np.asarray(tr.x), scps.row, scps.col, ev.residual_row, "max")
    np.testing.assert_array_equal(np.asarray(tr.z), truth)
    mean = _map(F.residual_maps({"m": ev}, scps, shape=scene.shape, max_cells=500), "m row")
    truth = _cell_means(np.asarray(mean.y), np.asarray(mean.x), scps.row, scps.col, ev.residual_row)
    np.testing.assert_allclose(np.asarray(mean.z), truth, rtol=1e-12, atol=1e-15)
    assert np.asarray(mean.customdata)[..., 0].max() > 1  # several points per cell here


def test_invalid_points_get_their_own_layer(results):
    scene, _, scps, evs = results
    ev = evs["toy_poly"]
    res = ev.residual_row.copy()
    res[[3, 10]] = np.nan
    bad = dataclasses.replace(ev, residual_row=res)
    fig = F.residual_maps({"m": bad}, scps)
    (entry,) = [t for t in fig.data if t.type == "scatter" and "not converged" in (t.name or "")]
    assert entry.name.endswith(f"2 of {len(res):,}") and "%" not in entry.name  # no percentage of two points
    (layer,) = [t for t in fig.data if t.type == "heatmap" and t.legendgroup == entry.legendgroup]
    assert (np.asarray(layer.z) == 1).sum() == 2  # the two cells of those points (one point each)
    tr = _map(fig, "m row")
    assert np.isnan(np.asarray(tr.z)).sum() == 2
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
    # deferred (the export): no measured time in the figure, the reproducible parts kept
    later = F.timing_bars(evs, deferred=True)
    assert list(later.data[0].y) == [None, None] and list(later.data[1].y) == [None, None]
    assert list(later.data[0].text) == [F.TIMING_NOT_LOADED] * 2 and "500 pts" in later.data[1].text[1]
    assert later.to_json() == F.timing_bars(_slower(evs), deferred=True).to_json()


def _slower(evs):
    return {n: dataclasses.replace(e, fit_s=e.fit_s * 3 + 1, locate_s=e.locate_s * 7) for n, e in evs.items()}


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
    fig = F.residual_maps({"tiny": tiny, "big": big}, scps)  # default: per map
    assert fig.layout.meta["mode"] == "per method"
    for k, (name, e) in enumerate((("tiny", tiny), ("big", big))):
        axis = fig.layout[f"coloraxis{k + 1 if k else ''}"]
        lim = np.percentile(np.abs(e.residual_row), 99)
        assert axis.cmax == pytest.approx(lim, rel=1e-12) and axis.cmin == pytest.approx(-lim, rel=1e-12)
        assert f"{lim:.2g}" in axis.colorbar.title.text and "p99" in axis.colorbar.title.text
        tr = _map(fig, f"{name} row")
        assert tr.coloraxis == f"coloraxis{k + 1 if k else ''}"
        colours = diverging_rgb(np.asarray(tr.z).ravel(), axis.cmax)
        assert len(np.unique(colours, axis=0)) > 20  # structure, not one flat colour
    # shared: one limit over both maps -- the tiny map then sits at the centre colour
    shared = F.residual_maps({"tiny": tiny, "big": big}, scps, mode="shared")
    lim = np.percentile(np.abs(np.concatenate([tiny.residual_row, big.residual_row])), 99)
    assert shared.layout.coloraxis.cmax == pytest.approx(lim, rel=1e-12)
    # log magnitude: log10 |residual| on one scale from the 1st to the 99th percentile
    log = F.residual_maps({"tiny": tiny, "big": big}, scps, mode="log magnitude")
    tr = _map(log, "tiny row")
    worst = np.asarray(tr.customdata)[..., 1]  # one SCP per cell
    np.testing.assert_allclose(np.asarray(tr.z), np.log10(np.abs(tiny.residual_row[worst])), rtol=1e-12)
    allv = np.log10(np.abs(np.concatenate([tiny.residual_row, big.residual_row])))
    assert log.layout.coloraxis.cmin == pytest.approx(np.percentile(allv, 1))
    assert log.layout.coloraxis.cmax == pytest.approx(np.percentile(allv, 99))
    with pytest.raises(ValueError, match="mode"):
        F.residual_maps({"big": big}, scps, mode="linear")


def test_row_column_and_difference_maps(results):
    _, _, scps, evs = results
    fig = F.residual_maps(evs, scps, component="row and column", difference=("toy_poly", "toy_bisect"))
    names = [t.name for t in fig.data if t.type == "heatmap" and t.coloraxis]
    assert names == ["toy_poly row", "toy_poly column", "toy_bisect row", "toy_bisect column",
                     "toy_poly minus toy_bisect (row)"]
    poly, bis = evs["toy_poly"], evs["toy_bisect"]
    col = _map(fig, "toy_poly column")
    truth = _cell_means(np.asarray(col.y), np.asarray(col.x), scps.row, scps.col, poly.residual_col)
    np.testing.assert_allclose(np.asarray(col.z), truth, rtol=1e-12, atol=1e-15)
    (diff,) = [t for t in fig.data if t.name.startswith("toy_poly minus")]
    z = np.asarray(diff.z)
    idx = np.asarray(diff.customdata)[..., 1][np.isfinite(z)]  # SCP indexes both methods evaluated
    assert set(idx) <= set(bis.evaluated_index) and len(idx) == np.isfinite(bis.residual_row).sum()
    pos_b = np.searchsorted(bis.evaluated_index, idx)
    expect = poly.residual_row[idx] - bis.residual_row[pos_b]  # toy_poly evaluated every SCP
    np.testing.assert_allclose(z[np.isfinite(z)], expect, rtol=0, atol=0)


def test_refused_points_are_named_refused(results):
    _, _, scps, evs = results
    ev = evs["toy_poly"]
    res = ev.residual_row.copy()
    res[:40] = np.nan
    status = np.zeros(len(res), np.int8)
    status[:37] = 1  # refused (outside the method's domain)
    status[37:40] = 2  # not converged
    fig = F.residual_maps({"m": dataclasses.replace(ev, residual_row=res)}, scps, status={"m": status})
    (ref,) = [t for t in fig.data if t.type == "scatter" and "refused" in (t.name or "")]
    (nc,) = [t for t in fig.data if t.type == "scatter" and "not converged" in (t.name or "")]
    assert "invalid" not in ref.name
    assert ref.name.endswith(f"37 ({100 * 37 / len(res):.3g} %)")
    assert nc.name.endswith(f"3 ({100 * 3 / len(res):.3g} %)")
    (layer,) = [t for t in fig.data if t.type == "heatmap" and t.legendgroup == ref.legendgroup]
    assert (np.asarray(layer.z) == 1).sum() == 37  # one point per cell here
    both = F.residual_maps({"m": dataclasses.replace(ev, residual_row=res, residual_col=res)}, scps,
                           status={"m": status}, component="row and column")
    refused = [t for t in both.data if t.legendgroup == ref.legendgroup]
    # one layer per map, one legend entry toggles both
    assert sum(t.type == "heatmap" for t in refused) == 2 and sum(bool(t.showlegend) for t in refused) == 1


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
    # plotly.js inlined once: its cartesian partial bundle (heatmaps, scatter and bars need nothing else),
    # the same plotly.js version as plotly.py's
    from plotly.offline import get_plotlyjs_version

    assert page.count("* plotly.js") == 1 and f"(cartesian - minified) v{get_plotlyjs_version()}" in page
    assert 1_400_000 < len(page) < 2_500_000
    # a trace type outside the partial bundle gets the full one
    import plotly.graph_objects as go

    full = F.figures_html([("3d", go.Figure(go.Scatter3d(x=[0], y=[0], z=[0])))], "export")
    assert "(cartesian" not in full and full.count("* plotly.js v") == 1 and len(full) > 4_000_000
    assert F.PLOTLY_CONFIG["showSendToCloud"] is False
    assert "sendDataToCloud" in F.PLOTLY_CONFIG["modeBarButtonsToRemove"]
    assert '"showSendToCloud": false' in page and '"displaylogo": false' in page
    # a script beside the page and a post-script: loaded relatively, run after the figure is drawn
    with_timing = F.figures_html([("timing", F.timing_bars(evs, deferred=True), F.timing_fill_script(list(evs)))],
                                 "export", scripts=["timing.js"])
    assert '<script src="timing.js"></script>' in with_timing and "Plotly.restyle(gd" in with_timing
    assert "document.getElementById('panel-0')" in with_timing
    for bad in ("https://cdn.plot.ly/plotly.js", "../timing.js", "timing.json"):
        with pytest.raises(ValueError):
            F.figures_html([], "export", scripts=[bad])


def test_panels_html_equals_the_validated_copies_path(results):
    """figures_html makes one validated copy of each figure instead of two (the first only read the trace types):
    the page is the same bytes as before -- each figure written from its own validated copy (``go.Figure(fig)``,
    ``update_layout(width, height)``, ``fig.to_html``) -- for the maps, the sweep, the deferred timing bars with
    their post-script, a figure given as a dict, and an HTML block; the caller's figures are left unchanged."""
    import html

    import plotly.graph_objects as go

    scene, scops, scps, evs = results
    sweep = {"toy_poly": [dataclasses.replace(evs["toy_poly"], n_scops=n) for n in (10, 20)]}
    figs = [("maps", F.residual_maps(evs, scps, control=scops, shape=scene.shape, component="row and column")),
            ("sweep", F.accuracy_vs_density(sweep)),
            ("table", "<table><tr><td>a &amp; b</td></tr></table>"),
            ("timing", F.timing_bars(evs, deferred=True), F.timing_fill_script(list(evs))),
            ("a dict", {"data": [{"type": "bar", "x": [1, 2], "y": [np.nan, -0.0]}], "layout": {"title": "d"}})]
    page = F.figures_html(figs, "export", ["note & more"], scripts=["timing.js"])

    parts = ["<h1>export</h1>", "<p>note &amp; more</p>", '<script src="timing.js"></script>']
    copies = [go.Figure(e[1]) for e in figs if not isinstance(e[1], str)]
    types = {t.type or "scatter" for c in copies for t in c.data}
    parts.append('<script type="text/javascript">' + F._plotlyjs_for(types) + "</script>")
    for k, entry in enumerate(figs):
        parts.append(f"<h2>{html.escape(entry[0])}</h2>")
        if isinstance(entry[1], str):
            parts.append(entry[1])
            continue
        fig = go.Figure(entry[1])
        fig.update_layout(width=1000, height=int(1000 * float((fig.layout.meta or {}).get("height_over_width", 0.6))))
        parts.append(F._unescape_base64(fig.to_html(full_html=False, include_plotlyjs=False, div_id=f"panel-{k}",
                                                    config=F.PLOTLY_CONFIG,
                                                    post_script=entry[2] if len(entry) > 2 else None)))
    expected = ("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>export</title></head>"
                "<body style=\"font-family: sans-serif\">\n" + "\n".join(parts) + "\n</body></html>\n")
    assert page == expected
    assert figs[0][1].layout.width is None  # the caller's figure is not changed
    # a figure's part made ahead (the export: the maps while the sweep's last results come) gives the same page
    ahead = [(figs[0][0], F.render_figure(figs[0][1], 0)), *figs[1:3],
             (figs[3][0], F.render_figure(figs[3][1], 3, figs[3][2])), figs[4]]
    assert F.figures_html(ahead, "export", ["note & more"], scripts=["timing.js"]) == expected
    with pytest.raises(ValueError, match="position 0, not 1"):
        F.figures_html([("table", "<p>x</p>"), ahead[0]], "export")


def test_panels_html_keeps_the_arrays_exact_and_does_not_escape_base64():
    """Issue 24 (pages under 5 MB on real files): plotly's HTML writer escapes every ``/`` as ``\\u002f`` (6 bytes
    for 1), also inside the base64 of the arrays.  A map with many empty (NaN) cells -- a DEM covering two thirds
    of a Pleiades image -- made a third of the probe's panels.html escapes (3.92 -> 4.67 MB).  The page now keeps
    base64 unescaped; the arrays read back from the page, with Python's own JSON and base64 decoders, are the
    figure's, bit for bit, NaN cells included; and no ``</script`` can appear inside them."""
    import base64
    import json
    import re

    import plotly.graph_objects as go

    rng = np.random.default_rng(24)
    z = rng.normal(size=(120, 150))
    z[:, :70] = np.nan  # empty cells: NaN float64 bytes give a base64 '/' every 32 characters
    fig = go.Figure(go.Heatmap(z=z, name="map"))
    page = F.figures_html([("maps", fig)], "export")
    written = fig.to_html(full_html=False, include_plotlyjs=False)
    assert written.count("\\u002f") > 1000  # what plotly writes
    assert "\\u002f" not in "".join(re.findall(r'"bdata":"([^"]*)"', page))
    start = page.index("Plotly.newPlot(")
    data, _ = json.JSONDecoder().raw_decode(page[page.index("[", start):])
    (trace,) = data
    enc = trace["z"]
    shape = tuple(int(v) for v in str(enc["shape"]).strip("[]").split(","))
    back = np.frombuffer(base64.b64decode(enc["bdata"]), dtype=np.dtype(enc["dtype"])).reshape(shape)
    np.testing.assert_array_equal(back, z)  # NaN where NaN, every other value bit for bit
    assert page.count("</script") == page.count("<script")


def test_every_method_title_names_a_stand_in_truth_and_only_then(results):
    """``--as-mpc``: each method's map says its residuals are measured against the stand-in; the stand-in's
    own map (its error against the sensor) and maps against the sensor itself do not."""
    from explorer.evaluate import STAND_IN_METHOD

    scene, scops, scps, evs = results
    maps = {**evs, STAND_IN_METHOD: evs["toy_poly"]}
    fig = F.residual_maps(maps, scps, shape=scene.shape, component="row and column",
                          against="the STAND-IN MPC (--as-mpc)")
    titles = [a.text for a in fig.layout.annotations if " px<br>" in str(a.text)]
    assert len(titles) == 6
    marked = [t for t in titles if t.endswith("; against the STAND-IN MPC (--as-mpc))")]
    assert sorted(t.split(":")[0] for t in marked) == ["toy_bisect column", "toy_bisect row",
                                                       "toy_poly column", "toy_poly row"]
    plain = F.residual_maps(evs, scps, shape=scene.shape)
    assert not any("against" in str(a.text) for a in plain.layout.annotations)


def test_map_cache_reuses_only_the_same_evaluation(results, monkeypatch):
    """With a cache, a map drawn again from the same Evaluation object is not aggregated again and the figure is
    the uncached one (z, customdata); a new evaluation (another object, other residuals) is aggregated anew and
    its map holds the brute-force cell means of its own residuals."""
    scene, scops, scps, evs = results
    calls = []
    real = F.aggregate_cells
    monkeypatch.setattr(F, "aggregate_cells", lambda *a, **k: calls.append(1) or real(*a, **k))
    cache: dict = {}
    kw = dict(control=scops, shape=scene.shape, component="row and column")
    first = F.residual_maps(evs, scps, cache=cache, **kw)
    assert len(calls) == 4 and len(cache) == 4  # 2 methods x (row, column)
    again = F.residual_maps(evs, scps, cache=cache, **kw)
    assert len(calls) == 4  # nothing aggregated again
    plain = F.residual_maps(evs, scps, **kw)
    for fig in (first, again):
        for a, b in zip(fig.data, plain.data, strict=True):
            if a.type == "heatmap":
                np.testing.assert_array_equal(np.asarray(a.z), np.asarray(b.z))
                if a.customdata is not None:
                    np.testing.assert_array_equal(np.asarray(a.customdata), np.asarray(b.customdata))
    changed = dict(evs, toy_poly=_scaled(evs["toy_poly"], 3.0))
    calls.clear()
    fig = F.residual_maps(changed, scps, cache=cache, **kw)
    assert len(calls) == 2  # toy_poly's row and column maps only
    tr = _map(fig, "toy_poly row")
    ev = changed["toy_poly"]
    truth = _cell_means(np.asarray(tr.y), np.asarray(tr.x), scps.row[ev.evaluated_index],
                        scps.col[ev.evaluated_index], ev.residual_row)
    np.testing.assert_allclose(np.asarray(tr.z), truth, rtol=1e-12, atol=1e-15)
    # other check points (same evaluations): aggregated again
    calls.clear()
    F.residual_maps(evs, dataclasses.replace(scps), cache=cache, **kw)
    assert len(calls) == 4
