"""The maps and timing figures are built without plotly's per-property validation and written without a validated
copy (explorer.panels.figures._figure, render_figure): the truth is plotly's own validated construction of the same
figure, whose JSON and page part must be the same bytes.  The raster's worst point per cell (a radix sort and
per-cell maxima) against a brute-force loop over the cells, ties included."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import plotly.graph_objects as go
import pytest

from explorer.panels import figures as F  # noqa: N812
from explorer.panels.raster import AGGREGATES, aggregate, cell_grid
from explorer.points import simulate_points
from tests.panels.test_figures import results  # noqa: F401  (the module's fixture)


def _cases(scene, scops, scps, evs):
    """(name, builder) of figures covering every branch of residual_maps' layout and timing_bars."""
    ev = evs["toy_poly"]
    res = ev.residual_row.copy()
    res[:40] = np.nan
    status = np.zeros(len(res), np.int8)
    status[:30], status[30:36], status[36:40] = 1, 3, 4  # refused, outside the image, outside the tables
    bad = {"m": dataclasses.replace(ev, residual_row=res, residual_col=res)}
    many = simulate_points(scene, 300, kind="scop")  # beyond MANY_SCOPS: small and hidden
    return [
        ("per method, row and column", lambda: F.residual_maps(evs, scps, control=scops, shape=scene.shape,
                                                              component="row and column")),
        ("shared, difference", lambda: F.residual_maps(evs, scps, control=many, shape=scene.shape, mode="shared",
                                                      difference=("toy_poly", "toy_bisect"))),
        ("log magnitude, column, labels", lambda: F.residual_maps(evs, scps, mode="log magnitude", component="column",
                                                                 labels={"toy_poly": "poly"}, columns=1)),
        ("fixed, max |residual|, against", lambda: F.residual_maps(evs, scps, control=scops, limit_px=0.5,
                                                                  aggregate="max |residual|", against="an MPC")),
        ("statuses, no SCOPs drawn", lambda: F.residual_maps(bad, scps, control=scops, shape=scene.shape,
                                                            status={"m": status}, component="row and column",
                                                            show_control=False, max_cells=300)),
        ("timing", lambda: F.timing_bars(evs)),
        ("timing deferred", lambda: F.timing_bars(evs, deferred=True, labels={"toy_bisect": "bisect"})),
    ]


def test_unvalidated_figures_are_plotlys_validated_figures(results, monkeypatch):  # noqa: F811
    """Each figure, built unvalidated, has the JSON of plotly's validated construction of the same input, and so has
    its validated copy; its page part (written from its own dict) is the validated copy's (the path every figure took
    before); a later change as the GUI makes (``layout.meta``) gives the same JSON too."""
    scene, scops, scps, evs = results
    for name, build in _cases(scene, scops, scps, evs):
        monkeypatch.setattr(F, "VALIDATE_FIGURES", True)
        truth = build()
        monkeypatch.setattr(F, "VALIDATE_FIGURES", False)
        fast = build()
        assert getattr(fast, "_in_plotly_order", False) and not getattr(truth, "_in_plotly_order", False), name
        assert fast.to_json() == truth.to_json(), name
        assert go.Figure(fast).to_json() == go.Figure(truth).to_json(), name
        for pos, post in ((0, None), (3, "console.log('{plot_id}');")):
            assert F.render_figure(fast, pos, post) == F.render_figure(truth, pos, post), name
        for fig in (fast, truth):
            fig.layout.meta = {**fig.layout.meta, "revision": 7}
        assert fast.to_json() == truth.to_json(), name


def test_the_fast_figures_leave_plotlys_array_validation_out(results, monkeypatch):  # noqa: F811
    """The point of it: no array of the maps' figure (cell edges, values, customdata: the large part) goes through
    plotly's array validator (a copy each), where the validated construction validates every one.  (Plotly still
    validates the numbered subplots -- ``xaxis2``, ``coloraxis2`` ... -- of a layout built unvalidated.)"""
    from _plotly_utils import basevalidators

    scene, scops, scps, evs = results
    calls = []
    orig = basevalidators.DataArrayValidator.validate_coerce

    def counted(self, v, *a, **k):
        calls.append(self.plotly_name)
        return orig(self, v, *a, **k)

    monkeypatch.setattr(basevalidators.DataArrayValidator, "validate_coerce", counted)
    F.residual_maps(evs, scps, control=scops, shape=scene.shape, component="row and column")
    assert calls == []
    monkeypatch.setattr(F, "VALIDATE_FIGURES", True)
    fig = F.residual_maps(evs, scps, control=scops, shape=scene.shape, component="row and column")
    heatmaps = sum(t.type == "heatmap" for t in fig.data)
    assert heatmaps == 4 and calls.count("z") == heatmaps and calls.count("customdata") == heatmaps


def _worst_brute_force(cell, values, index, n_cells):
    """Per cell: the point of largest |value|, among equals the largest index, among those the last one given."""
    worst = np.full(n_cells, -1)
    value = np.full(n_cells, np.nan)
    for c in range(n_cells):
        best = None
        for p in np.flatnonzero((cell == c) & np.isfinite(values)):
            if best is None or (abs(values[p]), index[p]) >= (abs(values[best]), index[best]):
                best = p
        if best is not None:
            worst[c], value[c] = index[best], values[best]
    return worst, value


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_worst_point_per_cell_with_ties_is_the_brute_force_one(seed):
    """Residuals of equal magnitude and opposite sign, repeated indices, NaNs, a cell count beyond 65,536 (no
    16-bit sort) in one case: the cell's worst index and the max |residual| value are the brute force's; the mean is
    the cells' mean."""
    rng = np.random.default_rng(seed)
    n = 3000
    shape = (400, 300) if seed < 2 else (3000, 3000)
    grid = cell_grid(shape, n, (300, 300) if seed == 2 else None, 100_000 if seed == 2 else 400)
    row, col = rng.uniform(-0.5, shape[0] - 0.5, n), rng.uniform(-0.5, shape[1] - 0.5, n)
    values = rng.integers(-2, 3, n).astype(float) * 0.25  # many ties in |value|
    values[rng.uniform(size=n) < 0.1] = np.nan
    index = rng.integers(0, n // 3, n)
    cell = grid.cell_of(row, col)
    n_cells = grid.shape[0] * grid.shape[1]
    assert (n_cells > 1 << 16) == (seed == 2)
    worst, value = _worst_brute_force(cell, values, index, n_cells)
    for how in AGGREGATES:
        field = aggregate(grid, row, col, values, index, how)
        np.testing.assert_array_equal(field.worst_index.ravel(), worst)
        same = aggregate(grid, None, None, values, index, how, cell=cell)  # the cells given: the same field
        for a, b in ((field.value, same.value), (field.count, same.count), (field.worst_index, same.worst_index)):
            np.testing.assert_array_equal(a, b)
        if how == "max |residual|":
            np.testing.assert_array_equal(field.value.ravel(), value)
        else:
            ok = np.isfinite(values)
            sums = np.bincount(cell[ok], weights=values[ok], minlength=n_cells)
            counts = np.bincount(cell[ok], minlength=n_cells)
            with np.errstate(invalid="ignore"):
                np.testing.assert_allclose(field.value.ravel(), sums / counts, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("name", ["plotly", "plotly_dark", "ggplot2", "seaborn", "simple_white", "presentation",
                                  "none"])
def test_templates_are_written_in_a_copys_order(name, monkeypatch):
    """The page writes a figure's template in the order a validated copy holds it: the same JSON as plotly's own
    validation of the template, for plotly's templates; with one of them as the default, a figure's page part is the
    validated copy's."""
    import plotly.io as pio

    template = pio.templates[name].to_plotly_json()
    truth = go.Figure(layout={"template": template}).to_dict()["layout"]["template"]
    assert json.dumps(F._template_as_copied(template)) == json.dumps(truth)
    monkeypatch.setattr(pio.templates, "default", name)
    monkeypatch.setattr(F, "VALIDATE_FIGURES", True)
    slow = F.timing_bars({})
    monkeypatch.setattr(F, "VALIDATE_FIGURES", False)
    assert F.render_figure(F.timing_bars({}), 1) == F.render_figure(slow, 1)


def _accuracy_by_plotlys_helpers(sweep, *, labels=None, marks=F.SCOP_MARKS, colors=None, failed=None):
    """The accuracy figure as it was built before (to 6adf1ef): validated traces and plotly's own helpers
    (add_hline with its annotation, add_annotation, update_xaxes / update_yaxes / update_layout)."""
    colors = dict(colors or F.method_colors(list(sweep)))
    fig = go.Figure()
    lo, hi = min(marks), max(marks)
    for n, evs in sweep.items():
        evs = [e for e in evs if e is not None]
        if not evs:
            continue
        col = colors.get(n, F.METHOD_PALETTE[0])
        fitted = sorted((e for e in evs if e.n_scops > 0), key=lambda e: e.n_scops)
        if fitted:
            x = np.array([e.n_scops for e in fitted], dtype=float)
            rm, dm = np.array([e.rmse_px for e in fitted]), np.array([e.dr_max_px for e in fitted])
            mode = "lines+markers"
        else:
            x = np.array([lo, hi], dtype=float)
            rm, dm = np.full(2, evs[-1].rmse_px), np.full(2, evs[-1].dr_max_px)
            mode = "lines"
        suffix = "" if fitted else " (no SCOPs needed)"
        for vals, kind, dash in ((rm, "RMSE", "solid"), (dm, "dr_max", "dash")):
            name = labels.get(n, n) if labels else n
            fig.add_trace(go.Scatter(
                x=x, y=np.maximum(vals, F.LOG_FLOOR_PX), customdata=vals, mode=mode, line={"color": col, "dash": dash},
                legendgroup=n, name=f"{name} {kind}{suffix}", meta=kind,
                hovertemplate=f"{name}<br>%{{x:.0f}} SCOPs<br>%{{meta}} %{{customdata:.3g}} px<extra></extra>"))
    fig.add_hline(y=1.0, line={"dash": "dot", "color": "black"},
                  annotation_text="1 px (sub-pixel below)", annotation_position="top left")
    notes = [f"{labels.get(n, n) if labels else n}: no point at {', '.join(f'{d:,}' for d in sorted(by))} SCOPs "
             f"({by[min(by)][:F._FAILED_NOTE_CHARS]})" for n, by in (failed or {}).items() if by]
    if notes:
        fig.add_annotation(text="<br>".join(notes), xref="paper", yref="paper", x=0.0, y=0.0, yshift=-42,
                           xanchor="left", yanchor="top", showarrow=False, align="left", font={"size": 10})
    fig.update_xaxes(type="log", title_text="number of SCOPs", tickvals=list(marks))
    fig.update_yaxes(type="log", title_text="scanline error, px", exponentformat="power")
    below = 14 * len(notes) + 10 if notes else 0
    fig.update_layout(height=380 + below, margin={"l": 60, "r": 10, "t": 30, "b": 40 + below},
                      legend={"font": {"size": 10}}, meta={"height_over_width": 0.8},
                      title={"text": "accuracy vs SCOP density (solid RMSE, dashed dr_max)", "font": {"size": 12}})
    return fig


def test_accuracy_figure_is_the_one_plotlys_helpers_built(results):  # noqa: F811
    """The accuracy-vs-SCOPs figure laid out as dicts is the figure plotly's helpers made (the same properties and
    values, the 1-pixel line and label of add_hline included), and its page part is the same bytes: with fitted
    methods, a method needing no SCOPs, an empty method, failures' notes, labels and other marks."""
    scene, _, scps, evs = results
    poly = [dataclasses.replace(evs["toy_poly"], n_scops=n, rmse_px=0.5 / n, dr_max_px=3.0 / n) for n in (30, 10, 100)]
    cases = [
        ({"toy_poly": poly, "toy_bisect": [evs["toy_bisect"]]}, {}),
        ({"toy_poly": poly, "none": [None], "empty": []}, {"labels": {"toy_poly": "poly"}, "marks": (10, 100),
                                                        "failed": {"toy_poly": {20: "too few points " * 20},
                                                                   "other": {}, "x": {5: "a", 7: "b"}}}),
        ({}, {}),
    ]
    for sweep, kw in cases:
        truth = _accuracy_by_plotlys_helpers(sweep, **kw)
        fast = F.accuracy_vs_density(sweep, **kw)
        assert json.loads(fast.to_json()) == json.loads(truth.to_json())
        assert F.render_figure(fast, 2) == F.render_figure(truth, 2)
