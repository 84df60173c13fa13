"""Plotly figures of best-scanline results: model results in, ``go.Figure`` out.

These functions only lay out numbers the model layer already computed
(:class:`explorer.evaluate.Evaluation` residuals, :class:`explorer.points.PointSet`
image coordinates); they never compute geometry.  The explorer shows them in its
viser panel (``gui.add_plotly``) and they work unchanged in a notebook::

    from explorer.panels.figures import residual_maps
    residual_maps({"lrm": ev}, scps, control=scops, shape=scene.shape).show()

* :func:`residual_maps` -- signed scanline residual (estimated - exact row, pixels)
  over the image, one small multiple per method, one shared FIXED diverging colour
  scale centred at 0, SCOPs overlaid; hover shows row, column, residual.
* :func:`accuracy_vs_density` -- RMSE (Eq. 4) and dr_max (Eq. 5) against the
  number of SCOPs, log axes, the 1-pixel (sub-pixel) line marked.
* :func:`timing_bars` -- fit time and ground-to-image time per point per method.

Colours: :mod:`explorer.panels`.  Conventions: ``docs/conventions.md``; the
explorer: ``docs/explorer.md``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, MutableMapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import plotly.graph_objects as go

from explorer.evaluate import STAND_IN_METHOD, Evaluation
from explorer.panels import (
    DIVERGING,
    INVALID_RGB,
    LOG_MAGNITUDE,
    ROBUST_PERCENTILE,
    SCOP_RGB,
    count_text,
    plotly_colorscale,
    rgb_string,
    robust_limit,
)
from explorer.panels.raster import AGGREGATES, MAX_CELLS, MAX_FIGURE_CELLS, cell_grid, occupied
from explorer.panels.raster import aggregate as aggregate_cells
from explorer.points import PointSet

SCOP_MARKS = (10, 20, 30, 50, 100, 300, 500, 1000)
"""SCOP counts of the papers' experiments (MLP paper, Section 3)."""
PLOT_BG = "rgb(64,64,64)"
"""Dark plot background, so the light-grey zero of the diverging scale stays visible."""
METHOD_PALETTE = (  # plotly's Dark24: distinct colours for up to 24 registered methods
    "#2E91E5", "#E15F99", "#1CA71C", "#FB0D0D", "#DA16FF", "#222A2A", "#B68100", "#750D86",
    "#EB663B", "#511CFB", "#00A08B", "#FB00D1", "#FC0080", "#B2828D", "#6C7C32", "#778AAE",
    "#862A16", "#A777F1", "#620042", "#1616A7", "#DA60CA", "#6C4516", "#0D2A63", "#AF0038",
)
LOG_FLOOR_PX = 1e-7
"""Values below this (an exact method's ~1e-10 px, or 0) are drawn at it on log axes; hover tells the truth."""


VALIDATE_FIGURES = False
"""Whether :func:`_figure` lets plotly validate every property of the figures built here (``True``: plotly's own
checks and coercions, the reference the tests compare with).  The values laid out here are valid by construction,
and validation was most of the cost of building a figure (property setters, copies); without it the figure's
JSON is the same (tests/panels/test_figures_fast.py)."""


_DATA_VALUED = frozenset({"meta"})
"""Properties whose value is data (plotly stores a dict given there as it is, in its own key order)."""


def _in_plotly_order(value: Any, key: str = "") -> Any:
    """``value`` with the keys of every nested property object in the order plotly's validated objects store them
    (alphabetical: each generated class sets its properties in that order), leaving data-valued properties
    (:data:`_DATA_VALUED`), arrays and strings as they are."""
    if isinstance(value, dict) and key not in _DATA_VALUED:
        return {k: _in_plotly_order(value[k], k) for k in sorted(value)}
    if isinstance(value, list) and any(isinstance(v, dict) for v in value):
        return [_in_plotly_order(v) for v in value]
    return value


def _figure(data: list[dict], layout: dict) -> go.Figure:
    """``go.Figure(data=data, layout=layout)`` built without plotly's per-property validation unless
    :data:`VALIDATE_FIGURES`: the same figure (the same ``to_dict`` / JSON) at a fraction of the cost.  Unvalidated,
    plotly keeps a nested dict as given, so each is put in the order its validated object has (the layout's own
    keys stay in the caller's order: plotly takes subplot axes such as ``xaxis2`` in that order either way)."""
    if VALIDATE_FIGURES:
        return go.Figure(data=data, layout=layout)
    data = [{k: _in_plotly_order(v, k) for k, v in trace.items()} for trace in data]
    layout = {k: _in_plotly_order(v, k) for k, v in layout.items()}
    fig = go.Figure(data=data, layout=layout, _validate=False)
    fig._in_plotly_order = True  # render_figure may write it without a validated copy
    return fig


def _layout_as_copied(layout: dict) -> dict:
    """The layout dict of a figure from :func:`_figure` with its keys in the order a copy (``go.Figure(fig)``) has
    them: plotly's layout class sets its own properties in alphabetical order, then the numbered subplots
    (``xaxis2``, ``coloraxis2``, ...) in the order given."""
    props = go.Layout._valid_props
    out = {k: layout[k] for k in sorted(layout) if k in props}
    out.update((k, v) for k, v in layout.items() if k not in props)
    if isinstance(out.get("template"), dict):
        out["template"] = _template_as_copied(out["template"])
    return out


def _sorted_deep(value: Any) -> Any:
    """``value`` with the keys of every dict in it in alphabetical order (lists walked, anything else as it is)."""
    if isinstance(value, dict):
        return {k: _sorted_deep(value[k]) for k in sorted(value)}
    if isinstance(value, list):
        return [_sorted_deep(v) for v in value]
    return value


def _template_as_copied(template: dict) -> dict:
    """A layout template as a copy of its figure holds it.  Plotly's template files have their own key order; a copy
    validates the template again and each class sets its properties in its order: alphabetical, except the trace
    types of ``template.data`` (the order of plotly's ``layout.template.Data`` class) and ``type`` last in each trace.
    The same bytes as that validation for every template plotly ships (tests/panels/test_figures_fast.py), without
    importing every trace type's class (~0.1 s of the export's CPU)."""
    import inspect

    out: dict = {}
    for part in sorted(template):
        value = template[part]
        if part == "data" and isinstance(value, dict):
            order = [p for p in inspect.signature(go.layout.template.Data.__init__).parameters if p in value]
            order += [k for k in value if k not in order]
            value = {kind: [_trace_as_copied(t) for t in value[kind]] if isinstance(value[kind], list)
                     else _sorted_deep(value[kind]) for kind in order}
        else:
            value = _sorted_deep(value)
        out[part] = value
    return out


def _trace_as_copied(trace: Any) -> Any:
    if not isinstance(trace, dict):
        return trace
    out = {k: _sorted_deep(trace[k]) for k in sorted(trace) if k != "type"}
    if "type" in trace:
        out["type"] = trace["type"]
    return out


def method_colors(names: Sequence[str]) -> dict[str, str]:
    """A stable colour per method name (position in ``names``)."""
    return {n: METHOD_PALETTE[i % len(METHOD_PALETTE)] for i, n in enumerate(names)}


def empty_figure(message: str, height: int = 240) -> go.Figure:
    """A blank figure carrying a message (placeholder while results are computed)."""
    fig = go.Figure()
    fig.add_annotation(text=message, x=0.5, y=0.5, xref="paper", yref="paper", showarrow=False,
                       font={"size": 14})
    fig.update_layout(height=height, xaxis={"visible": False}, yaxis={"visible": False},
                      margin={"l": 10, "r": 10, "t": 10, "b": 10}, meta={"height_over_width": 0.5})
    return fig


def decimation_index(n: int, max_points: int | None) -> np.ndarray:
    """Positions of an evenly strided subset of ``min(n, max_points)`` of ``n`` items.

    A constant stride over a row-major grid of points keeps an even lattice (a random subset
    of a grid looks patchy).
    """
    if max_points is None or n <= max_points:
        return np.arange(n)
    return np.unique(np.floor(np.arange(max_points) * (n / max_points)).astype(np.int64))


def _grid(
    n: int, ncol: int, titles: Sequence[str], *, hgap: float = 0.05, vgap: float = 0.14,
    shared: bool = True,
) -> tuple[dict, list[tuple[str, str]]]:
    """Layout axes for ``n`` small multiples on ``ncol`` columns (plotly's ``make_subplots``
    is ~0.15 s per call; this is microseconds).  Returns (layout dict, [(xref, yref)] per cell)."""
    nrow = math.ceil(n / ncol)
    w = (1.0 - hgap * (ncol - 1)) / ncol
    h = (1.0 - vgap * (nrow - 1)) / nrow
    layout: dict = {"annotations": []}
    refs = []
    for k in range(n):
        r, c = divmod(k, ncol)
        x0 = c * (w + hgap)
        y1 = 1.0 - r * (h + vgap)
        sx = "" if k == 0 else str(k + 1)
        xa: dict = {"domain": [max(x0, 0.0), min(x0 + w, 1.0)], "anchor": f"y{sx}"}
        ya: dict = {"domain": [max(y1 - h, 0.0), min(y1, 1.0)], "anchor": f"x{sx}"}
        if shared and k > 0:
            xa["matches"] = "x"
            ya["matches"] = "y"
        if r < nrow - 1 and k + ncol < n:
            xa["showticklabels"] = False
        if c > 0 and shared:
            ya["showticklabels"] = False
        layout[f"xaxis{sx}"] = xa
        layout[f"yaxis{sx}"] = ya
        refs.append((f"x{sx}", f"y{sx}"))
        layout["annotations"].append({
            "text": titles[k], "x": x0 + w / 2, "y": y1, "xref": "paper", "yref": "paper",
            "xanchor": "center", "yanchor": "bottom", "showarrow": False, "font": {"size": 11},
        })
    return layout, refs


def _label(name: str, labels: Mapping[str, str] | None) -> str:
    return labels.get(name, name) if labels else name


PLOTLY_CONFIG = {
    "displaylogo": False,
    "showSendToCloud": False,
    "modeBarButtonsToRemove": ["sendDataToCloud"],
}
"""Plotly config of every panel: no "share to cloud" / Chart Studio button, nothing leaves the machine."""
STATUS_STYLE = {
    "refused": ("rgb(0,200,200)", "circle-open", "refused (outside its domain, e.g. height extrapolation)"),
    "not converged": (rgb_string(INVALID_RGB), "x", "not converged"),
    "outside image": ("rgb(255,255,255)", "square-open", "outside the image"),
    "outside tables": ("rgb(255,160,0)", "diamond-open", "outside the sensor's tables (line not covered)"),
}
"""Marker colour, symbol and legend text of points without a residual, by status name."""
MANY_SCOPS = 200
"""Beyond this many SCOPs the maps start with them hidden (one legend click shows them), so they never
cover the residuals."""
_TITLE_PX = 34
_AXIS_PX = 40
_REF_WIDTH_PX = 520


@dataclass
class MapPanel:
    """One residual map: its values at check points and how to title it."""

    title: str
    values: np.ndarray
    index: np.ndarray
    missing: dict[str, np.ndarray]
    method: str = ""
    source: Any = None
    """What the values were taken from (the Evaluation and the component), for :func:`residual_maps`' cache."""


def _panels(
    evaluations: Mapping[str, Evaluation], check: PointSet, component: str,
    difference: tuple[str, str] | None, status: Mapping[str, np.ndarray] | None,
    labels: Mapping[str, str] | None, aggregate: str, against: str | None = None,
) -> list[MapPanel]:
    comps = {"row": ("row",), "column": ("column",), "row and column": ("row", "column")}.get(component)
    if comps is None:
        raise ValueError(f"component must be 'row', 'column' or 'row and column', got {component!r}")
    out = []
    for n, ev in evaluations.items():
        idx = np.asarray(ev.evaluated_index)
        st = None if status is None else status.get(n)
        for c in comps:
            res = np.asarray(ev.residual_row if c == "row" else ev.residual_col, dtype=np.float64)
            ok = np.isfinite(res)
            rms = float(np.sqrt(np.mean(res[ok] ** 2))) if ok.any() else float("nan")
            m = idx.size
            sub = f"{m:,} of {ev.n_scps:,} SCPs: seeded preview" if m < ev.n_scps else f"all {m:,} SCPs"
            vs = f"; against {against}" if against and n != STAND_IN_METHOD else ""
            title = f"{_label(n, labels)} {c}: RMSE {rms:.3g} px<br>({sub}; cell {aggregate}{vs})"
            missing: dict[str, np.ndarray] = {}
            if (~ok).any():
                if st is not None and np.shape(st) == res.shape:
                    for code, name in enumerate(("valid", "refused", "not converged", "outside image",
                                                 "outside tables")):
                        if code and ((~ok) & (st == code)).any():
                            missing[name] = idx[(~ok) & (st == code)]
                    rest = (~ok) & (st == 0)
                    if rest.any():
                        missing["not converged"] = np.union1d(missing.get("not converged", []), idx[rest])
                else:
                    missing["not converged"] = idx[~ok]
            out.append(MapPanel(title, res[ok], idx[ok], missing, _label(n, labels), (ev, c)))
    if difference is not None:
        a, b = difference
        if a in evaluations and b in evaluations and a != b:
            ea, eb = evaluations[a], evaluations[b]
            common, ia, ib = np.intersect1d(ea.evaluated_index, eb.evaluated_index, return_indices=True)
            d = np.asarray(ea.residual_row)[ia] - np.asarray(eb.residual_row)[ib]
            ok = np.isfinite(d)
            rms = float(np.sqrt(np.mean(d[ok] ** 2))) if ok.any() else float("nan")
            title = (f"{_label(a, labels)} minus {_label(b, labels)} (row): RMS {rms:.3g} px"
                     f"<br>({int(ok.sum()):,} points both evaluated; cell {aggregate})")
            out.append(MapPanel(title, d[ok], common[ok], {}, "difference"))
    return out


def residual_maps(
    evaluations: Mapping[str, Evaluation],
    check: PointSet,
    *,
    control: PointSet | None = None,
    shape: tuple[int, int] | None = None,
    limit_px: float | None = None,
    mode: str | None = None,
    component: str = "row",
    difference: tuple[str, str] | None = None,
    status: Mapping[str, np.ndarray] | None = None,
    aggregate: str = "mean",
    max_cells: int = MAX_CELLS,
    labels: Mapping[str, str] | None = None,
    columns: int | None = None,
    show_control: bool = True,
    percentile: float = ROBUST_PERCENTILE,
    against: str | None = None,
    cache: MutableMapping | None = None,
) -> go.Figure:
    """Residual maps over the image: one small multiple per method (and component), each a raster of
    the residual aggregated per image cell (:mod:`explorer.panels.raster`).

    Parameters
    ----------
    evaluations : mapping of str to Evaluation
        Method name -> evaluation on ``check`` (``residual_row`` / ``residual_col`` (M,)
        aligned with ``evaluated_index`` (M,), pixels, NaN where the method gave no answer).
    check : PointSet
        The SCPs the evaluations used (image row/col of each point).
    control : PointSet, optional
        SCOPs, an overlay of gold crosses on every map (one legend entry toggles them); beyond
        :data:`MANY_SCOPS` they are small and start hidden.
    shape : (int, int), optional
        Image (rows, columns) for the axis ranges (pixel edges).
    limit_px : float, optional
        Colour limit of the ``"fixed"`` mode, pixels.
    mode : {"per method", "shared", "log magnitude", "fixed"}, optional
        ``"per method"``: every map its own symmetric diverging scale ``[-L, +L]`` with L the
        ``percentile`` of its |residual| (:func:`explorer.panels.robust_limit`, stated on its
        colour bar), so 1e-10 px and 10 px both show structure; ``"shared"``: one such L over
        all maps; ``"log magnitude"``: log10 |residual| on a sequential scale spanning the 1st
        to 99th percentile over all maps; ``"fixed"``: ``[-limit_px, +limit_px]``.  Default:
        ``"fixed"`` when ``limit_px`` is given, else ``"per method"``.
    component : {"row", "column", "row and column"}
        The scanline (row) residual, the column residual, or both (two maps per method).
    difference : (str, str), optional
        Also map the row residual of the first method minus that of the second, on the
        points both evaluated.
    status : mapping of str to ndarray, optional
        Per method the status codes (M,) of ``explorer.app.model.STATUS_NAMES``; points
        without a residual are then drawn and named as refused / not converged / outside
        the image (else all as not converged).
    aggregate : {"mean", "max |residual|"}
        Cell value: the signed mean of the cell's residuals, or the signed residual of largest
        magnitude (:data:`explorer.panels.raster.AGGREGATES`).  Cells with no check point are
        transparent (a legend entry counts them); cells whose points all lack a residual show their
        status (refused / not converged / outside the image, named and counted in the legend).
    max_cells : int
        At most this many cells per map (:func:`explorer.panels.raster.cell_grid`); with many maps the
        figure's budget :data:`explorer.panels.raster.MAX_FIGURE_CELLS` lowers it (``layout.meta["cells"]``
        gives the grid drawn).
    labels : mapping, optional
        Display names.
    columns : int, optional
        Maps per figure row (default 2, 3 beyond four maps).
    show_control : bool
        Draw the SCOPs.
    percentile : float
        Percentile of |residual| that sets the automatic limits.
    against : str, optional
        What the residuals are measured against when it is not the sensor itself (``--as-mpc``: "the
        STAND-IN MPC"); every method's title then says so (the stand-in's own map is labelled already).
    cache : mutable mapping, optional
        Keeps each map's cell aggregates between calls (the caller owns it and may clear it): a map drawn again
        from the *same* Evaluation object on the same check points and cells is not aggregated again (an
        explorer update redraws every map when one method's result changed).  Entries hold their evaluation,
        check points and cells and are used only when these are the very same objects.

    Returns
    -------
    go.Figure
        Per map one ``heatmap`` trace (``x`` / ``y`` = cell edges in image columns / rows, ``z`` =
        the cell aggregate in pixels -- log10 of its magnitude in the log mode -- NaN for no value,
        ``customdata`` = (points in the cell, SCP index of its worst point), ``meta`` = map name),
        one heatmap per status of cells without a residual, and the SCOP overlay (``scatter``).
        Legend-only ``scatter`` entries name the empty cells and the statuses.  ``layout.meta``
        holds ``height_over_width``, ``mode``, ``aggregate``, ``limits_px`` (per map the colour
        limit; for the log mode the exponent range), ``titles`` and ``cells`` (rows, columns).
    """
    if mode is None:
        mode = "fixed" if limit_px is not None else "per method"
    if mode not in ("per method", "shared", "log magnitude", "fixed"):
        raise ValueError(f"mode must be 'per method', 'shared', 'log magnitude' or 'fixed', got {mode!r}")
    if mode == "fixed" and not (limit_px is not None and limit_px > 0):
        raise ValueError(f"the fixed mode needs a positive limit_px, got {limit_px}")
    if aggregate not in AGGREGATES:
        raise ValueError(f"aggregate must be one of {AGGREGATES}, got {aggregate!r}")
    panels = _panels(evaluations, check, component, difference, status, labels, aggregate, against)
    if not panels:
        return empty_figure("no method evaluated")
    n = len(panels)
    ncol = columns or (2 if n <= 4 else 3)
    ncol = max(1, min(ncol, n))
    nrow = math.ceil(n / ncol)
    per_map = mode == "per method"
    # geometry in pixels at a reference width; fractions of the figure keep titles clear of the
    # maps above them (the figure's height follows its width through height_over_width)
    cbar_px = 70 if per_map else 0
    hgap_px = 16 + cbar_px
    plot_w = (_REF_WIDTH_PX - 60 - 70 * (not per_map) - hgap_px * (ncol - 1) - cbar_px) / ncol
    image_hw = shape[0] / shape[1] if shape is not None else 1.0
    plot_h = float(np.clip(plot_w * image_hw, 80.0, 420.0))
    top, bottom = _TITLE_PX + 6, _AXIS_PX
    row_px = plot_h + _TITLE_PX + _AXIS_PX
    height_px = top + bottom + nrow * plot_h + (nrow - 1) * (_TITLE_PX + _AXIS_PX)
    inner_h = height_px - top - bottom
    inner_w = _REF_WIDTH_PX - 60 - (70 if not per_map else 0)
    hgap = hgap_px / inner_w
    vgap = (row_px - plot_h) / inner_h
    layout, refs = _grid(n, ncol, [p.title for p in panels], hgap=hgap, vgap=vgap)
    for ann in layout["annotations"]:
        ann["font"] = {"size": 10}
    limits: list[float] = []
    if mode == "log magnitude":
        logs = [np.log10(np.maximum(np.abs(p.values), 1e-300)) for p in panels]
        allv = np.concatenate([v for v in logs if v.size]) if any(v.size for v in logs) else np.zeros(1)
        lo, hi = (float(np.percentile(allv, 100 - percentile)), float(np.percentile(allv, percentile)))
        if hi <= lo:
            lo, hi = lo - 0.5, hi + 0.5
        limits = [lo, hi]
    elif mode == "shared":
        limits = [robust_limit(np.concatenate([p.values for p in panels]), percentile)]
    elif mode == "fixed":
        limits = [float(limit_px or 0.0)]
    else:
        limits = [robust_limit(p.values, percentile) for p in panels]
    gshape = check.grid_shape
    grid_rc = (int(gshape[0]), int(gshape[1])) if len(gshape) >= 2 and gshape[0] * gshape[1] > 0 and \
        (len(gshape) < 3 or gshape[2] == 1) else None
    image_shape = shape if shape is not None else (
        int(np.ceil(np.max(check.row) + 0.5)) if len(check) else 1, int(np.ceil(np.max(check.col) + 0.5)) if len(check)
        else 1)
    # the figure's cell budget: many maps get fewer cells each (the same grid for every map)
    cells = cell_grid(image_shape, len(check), grid_rc, max(1, min(max_cells, MAX_FIGURE_CELLS // n)))
    check_cell = cells.cell_of(check.row, check.col)  # once for every map: they share the check points and cells
    all_points = occupied(cells, None, None, cell=check_cell)
    empty_cells = int((all_points == 0).sum())
    value_word = "mean residual" if aggregate == "mean" else "max |residual| (signed)"
    data: list[dict] = []
    legend_seen: set[str] = set()
    xe, ye = cells.col_edges, cells.row_edges
    for k, p in enumerate(panels):
        xr, yr = refs[k]
        key = None if cache is None or p.source is None else (id(p.source[0]), p.source[1], aggregate)
        hit = cache.get(key) if cache is not None and key is not None else None
        if hit is not None and hit[0] is p.source[0] and hit[1] is check and np.array_equal(hit[2], cells.row_edges) \
                and np.array_equal(hit[3], cells.col_edges):
            field = hit[4]
        else:
            field = aggregate_cells(cells, None, None, p.values, p.index, aggregate, cell=check_cell[p.index])
            if cache is not None and key is not None:
                cache[key] = (p.source[0], check, cells.row_edges, cells.col_edges, field)
        axis = f"coloraxis{k + 1 if k else ''}" if per_map else "coloraxis"
        z = np.log10(np.maximum(np.abs(field.value), 1e-300)) if mode == "log magnitude" else field.value
        shown = "log10 |px| %{z:.3f}" if mode == "log magnitude" else f"{value_word} %{{z:.4g}} px"
        data.append({
            "type": "heatmap", "x": xe, "y": ye, "z": z, "coloraxis": axis, "zsmooth": False,
            "customdata": np.stack([field.count, field.worst_index], axis=-1).astype(np.int32),
            "xaxis": xr, "yaxis": yr, "name": p.title.split(":")[0], "meta": p.title.split(":")[0],
            "hoverongaps": False,
            "hovertemplate": f"row %{{y:.0f}}, col %{{x:.0f}}<br>{shown}<br>%{{customdata[0]}} points; worst: "
                             "SCP %{customdata[1]}<extra>%{meta}</extra>",
            "showlegend": False,
        })
        valid_cells = field.count > 0
        total = len(p.values) + sum(len(v) for v in p.missing.values())
        for what, where in p.missing.items():
            colour_s, _, text = STATUS_STYLE[what]
            cnt = occupied(cells, None, None, cell=check_cell[where])
            only = (cnt > 0) & ~valid_cells  # cells with points, none of them with a residual
            group = f"{p.method}: {what}"  # one legend entry per method and status (its row and column maps)
            data.append({  # 1 byte per cell: 0 transparent, 1 the status colour
                "type": "heatmap", "x": xe, "y": ye, "z": only.astype(np.uint8), "zmin": 0, "zmax": 1,
                "colorscale": [[0.0, "rgba(0,0,0,0)"], [0.5, "rgba(0,0,0,0)"], [0.5, colour_s], [1.0, colour_s]],
                "showscale": False, "zsmooth": False, "xaxis": xr, "yaxis": yr, "legendgroup": group,
                "showlegend": False, "hoverinfo": "skip",
            })
            if group not in legend_seen:
                data.append({
                    "type": "scatter", "x": [None], "y": [None], "mode": "markers", "xaxis": xr, "yaxis": yr,
                    "marker": {"color": colour_s, "size": 9, "symbol": "square"}, "legendgroup": group,
                    "name": f"{p.method}: {text}: {count_text(len(where), total)}", "showlegend": True,
                    "hoverinfo": "skip",
                })
            legend_seen.add(group)
        if show_control and control is not None and len(control):
            many = len(control) > MANY_SCOPS
            data.append({
                "type": "scatter", "x": control.col, "y": control.row, "mode": "markers",
                "xaxis": xr, "yaxis": yr,
                "marker": {"color": rgb_string(SCOP_RGB), "size": 3 if many else 6, "symbol": "cross",
                           "opacity": 0.8},
                "visible": "legendonly" if many else True,
                "name": f"SCOPs ({len(control)}): click to {'show' if many else 'hide'}", "legendgroup": "scop",
                "showlegend": "scop" not in legend_seen,
                "hoverinfo": "skip",  # a hover or click always reaches the raster cell under the pointer
            })
            legend_seen.add("scop")
    if empty_cells:
        data.append({
            "type": "scatter", "x": [None], "y": [None], "mode": "markers", "xaxis": refs[0][0],
            "yaxis": refs[0][1], "marker": {"color": PLOT_BG, "size": 9, "symbol": "square",
                                            "line": {"color": "rgb(160,160,160)", "width": 1}},
            "name": f"no check point (transparent): {empty_cells:,} of {all_points.size:,} cells",
            "showlegend": True, "hoverinfo": "skip", "legendgroup": "empty",
        })
    for k in range(n):
        r, c = divmod(k, ncol)
        sx = "" if k == 0 else str(k + 1)
        xa, ya = layout[f"xaxis{sx}"], layout[f"yaxis{sx}"]
        xa.update(showgrid=False, zeroline=False)
        ya.update(showgrid=False, zeroline=False)
        if r == nrow - 1 or k + ncol >= n:
            xa["title"] = {"text": "column", "standoff": 2}
        xa["showticklabels"] = True
        if c == 0:
            ya["title"] = {"text": "row", "standoff": 2}
        if shape is not None:
            xa["range"] = [-0.5, shape[1] - 0.5]
            ya["range"] = [shape[0] - 0.5, -0.5]
        else:
            ya["autorange"] = "reversed"
        # few, upright, small tick labels: rotated ones would grow into the title of the map below
        xa.update(nticks=3, tickangle=0, tickfont={"size": 9})
        ya.update(nticks=5, tickfont={"size": 9})
    pct = f"p{percentile:g} |residual|"
    if per_map:
        for k, lim in enumerate(limits):
            xd, yd = layout[f"xaxis{k + 1 if k else ''}"]["domain"], layout[f"yaxis{k + 1 if k else ''}"]["domain"]
            layout[f"coloraxis{k + 1 if k else ''}"] = {
                "colorscale": plotly_colorscale(DIVERGING), "cmin": -lim, "cmax": lim, "cmid": 0.0,
                "colorbar": {"title": {"text": f"+-{lim:.2g} px<br>({pct})", "font": {"size": 9}},
                             "thickness": 8, "len": yd[1] - yd[0], "lenmode": "fraction", "y": yd[0],
                             "yanchor": "bottom", "x": xd[1] + 0.01, "xanchor": "left",
                             "tickfont": {"size": 8}, "nticks": 5, "exponentformat": "e"}}
    elif mode == "log magnitude":
        layout["coloraxis"] = {
            "colorscale": plotly_colorscale(LOG_MAGNITUDE), "cmin": limits[0], "cmax": limits[1],
            "colorbar": {"title": {"text": "|residual| px<br>(log, p1-p99)", "font": {"size": 9}},
                         "thickness": 10, "len": 0.8, "y": 1.0, "yanchor": "top", "tickprefix": "1e",
                         "tickformat": ".0f", "dtick": max(1, int(np.ceil((limits[1] - limits[0]) / 6)))}}
    else:
        what = f"+-{limits[0]:.2g} px<br>({pct}, all maps)" if mode == "shared" else f"+-{limits[0]:g} px (fixed)"
        layout["coloraxis"] = {
            "colorscale": plotly_colorscale(DIVERGING), "cmin": -limits[0], "cmax": limits[0], "cmid": 0.0,
            "colorbar": {"title": {"text": what, "font": {"size": 9}}, "thickness": 10, "len": 0.8, "y": 1.0,
                         "yanchor": "top", "exponentformat": "e"}}
    layout.update(
        height=int(height_px), margin={"l": 50, "r": 10 if per_map else 80, "t": top, "b": bottom},
        legend={"orientation": "h", "x": 0.0, "xanchor": "left", "y": -bottom / height_px - 0.01,
                "yanchor": "top", "font": {"size": 9}},
        plot_bgcolor=PLOT_BG,
        meta={"height_over_width": height_px / _REF_WIDTH_PX, "mode": mode, "limits_px": limits,
              "titles": [p.title for p in panels], "title_px": _TITLE_PX, "axis_px": _AXIS_PX,
              "aggregate": aggregate, "cells": list(cells.shape)},
    )
    if any(d.get("showlegend") for d in data):  # room for the legend under the maps
        extra = 18 * (1 + sum(1 for d in data if d.get("showlegend")) // 2)
        layout["height"] = int(height_px + extra)
        layout["margin"]["b"] = bottom + extra
        layout["legend"]["y"] = -(bottom - 6) / (height_px - top - bottom)
        layout["meta"]["height_over_width"] = (height_px + extra) / _REF_WIDTH_PX
    return _figure(data, layout)


_FAILED_NOTE_CHARS = 140
"""Longest reason quoted per method in the accuracy-vs-SCOPs note (the summary has it whole)."""


def accuracy_vs_density(
    sweep: Mapping[str, Sequence[Evaluation]],
    *,
    labels: Mapping[str, str] | None = None,
    marks: Sequence[int] = SCOP_MARKS,
    colors: Mapping[str, str] | None = None,
    failed: Mapping[str, Mapping[int, str]] | None = None,
) -> go.Figure:
    """RMSE and dr_max per method against the number of SCOPs (log-log).

    Parameters
    ----------
    sweep : mapping of str to sequence of Evaluation
        Method name -> evaluations at several SCOP counts (``n_scops``).  A method that
        needs no SCOPs (``n_scops == 0``) is drawn as a flat line across ``marks``.
    labels, colors : mapping, optional
    marks : sequence of int
        The SCOP counts shown as x ticks.
    failed : mapping of str to mapping of int to str, optional
        Method name -> {SCOP count: reason} where the method could not be fitted or evaluated: those
        counts have no point, and a note under the plot names each with its reason.

    Returns
    -------
    go.Figure
        Per method a solid RMSE trace and a dashed dr_max trace (``customdata`` holds
        the exact values; the plotted y is floored at :data:`LOG_FLOOR_PX`), and a
        dotted line at 1 px.
    """
    colors = dict(colors or method_colors(list(sweep)))
    data: list[dict] = []
    lo, hi = min(marks), max(marks)
    for n, evs in sweep.items():
        evs = [e for e in evs if e is not None]
        if not evs:
            continue
        col = colors.get(n, METHOD_PALETTE[0])
        fitted = [e for e in evs if e.n_scops > 0]
        if fitted:
            fitted.sort(key=lambda e: e.n_scops)
            x = np.array([e.n_scops for e in fitted], dtype=float)
            rm = np.array([e.rmse_px for e in fitted], dtype=float)
            dm = np.array([e.dr_max_px for e in fitted], dtype=float)
            mode = "lines+markers"
        else:
            x = np.array([lo, hi], dtype=float)
            rm = np.full(2, evs[-1].rmse_px, dtype=float)
            dm = np.full(2, evs[-1].dr_max_px, dtype=float)
            mode = "lines"
        suffix = "" if fitted else " (no SCOPs needed)"
        for vals, kind, dash in ((rm, "RMSE", "solid"), (dm, "dr_max", "dash")):
            data.append({
                "type": "scatter", "x": x, "y": np.maximum(vals, LOG_FLOOR_PX), "customdata": vals,
                "mode": mode, "line": {"color": col, "dash": dash}, "legendgroup": n,
                "name": f"{_label(n, labels)} {kind}{suffix}", "meta": kind,
                "hovertemplate": f"{_label(n, labels)}<br>%{{x:.0f}} SCOPs<br>%{{meta}} %{{customdata:.3g}} px"
                                 "<extra></extra>",
            })
    # the 1-pixel line and its label, as plotly's add_hline(y=1, annotation_position="top left") makes them
    annotations: list[dict] = [{"showarrow": False, "text": "1 px (sub-pixel below)", "x": 0, "xanchor": "left",
                                "xref": "x domain", "y": 1.0, "yanchor": "bottom", "yref": "y"}]
    notes = [f"{_label(n, labels)}: no point at {', '.join(f'{d:,}' for d in sorted(by))} SCOPs "
             f"({by[min(by)][:_FAILED_NOTE_CHARS]})" for n, by in (failed or {}).items() if by]
    if notes:
        annotations.append({"text": "<br>".join(notes), "xref": "paper", "yref": "paper", "x": 0.0, "y": 0.0,
                            "yshift": -42, "xanchor": "left", "yanchor": "top", "showarrow": False, "align": "left",
                            "font": {"size": 10}})
    below = 14 * len(notes) + 10 if notes else 0  # the notes' lines under the axis title
    layout = {
        "shapes": [{"line": {"color": "black", "dash": "dot"}, "type": "line", "x0": 0, "x1": 1, "xref": "x domain",
                    "y0": 1.0, "y1": 1.0, "yref": "y"}],
        "annotations": annotations,
        "xaxis": {"title": {"text": "number of SCOPs"}, "type": "log", "tickvals": list(marks)},
        "yaxis": {"title": {"text": "scanline error, px"}, "type": "log", "exponentformat": "power"},
        "margin": {"l": 60, "r": 10, "t": 30, "b": 40 + below}, "legend": {"font": {"size": 10}},
        "title": {"text": "accuracy vs SCOP density (solid RMSE, dashed dr_max)", "font": {"size": 12}},
        "height": 380 + below, "meta": {"height_over_width": 0.8},
    }
    return _figure(data, layout)


def timing_bars(
    evaluations: Mapping[str, Evaluation],
    *,
    labels: Mapping[str, str] | None = None,
    colors: Mapping[str, str] | None = None,
    deferred: bool = False,
) -> go.Figure:
    """Fit time and ground-to-image time per method, as bars (log y).

    Parameters
    ----------
    evaluations : mapping of str to Evaluation
    labels, colors : mapping, optional
    deferred : bool
        Leave the measured times out (bars empty, texts "timing.js not loaded"): the figure then depends
        only on what is reproducible (method names, SCOP and point counts) and
        :func:`timing_fill_script` fills it in the browser from ``timing.js`` (the export's one
        run-dependent file, ``explorer.app.export``).

    Returns
    -------
    go.Figure
        Left: fit time, seconds (0 for methods that do not learn).  Right:
        ground-to-image time per point, microseconds (``locate_s / n_evaluated``), the
        text naming the number of points it was measured on.
    """
    names = list(evaluations)
    colors = dict(colors or method_colors(names))
    layout, refs = _grid(2, 2, ("fit (s)", "ground-to-image (us / point)"), hgap=0.14, shared=False)
    disp = [_label(n, labels) for n in names]
    fit = [evaluations[n].fit_s for n in names]
    per = [1e6 * evaluations[n].locate_s / max(evaluations[n].n_evaluated, 1) for n in names]
    cols = [colors.get(n, METHOD_PALETTE[0]) for n in names]
    data = [
        {"type": "bar", "x": disp, "y": [f if f > 0 else None for f in fit], "marker": {"color": cols},
         "showlegend": False, "xaxis": refs[0][0], "yaxis": refs[0][1],
         "text": [f"{f:.3g} s" if f > 0 else "no fit" for f in fit], "textposition": "outside",
         "customdata": [evaluations[n].n_scops for n in names],
         "hovertemplate": "%{x}<br>fit %{y:.3g} s on %{customdata} SCOPs<extra></extra>"},
        {"type": "bar", "x": disp, "y": per, "marker": {"color": cols}, "showlegend": False,
         "xaxis": refs[1][0], "yaxis": refs[1][1],
         "text": [f"{evaluations[n].n_evaluated:,} pts" for n in names], "textposition": "outside",
         "customdata": [[evaluations[n].locate_s, evaluations[n].n_evaluated] for n in names],
         "hovertemplate": "%{x}<br>%{y:.3g} us/point<br>%{customdata[0]:.3g} s on "
                          "%{customdata[1]:,} points<extra></extra>"},
    ]
    if deferred:  # only the reproducible parts; timing_fill_script puts the measured times in
        data[0].update(y=[None] * len(names), text=[TIMING_NOT_LOADED] * len(names))
        data[1].update(y=[None] * len(names), customdata=[[None, evaluations[n].n_evaluated] for n in names])
    for ax in ("yaxis", "yaxis2"):
        layout[ax].update(type="log", exponentformat="power")
    layout.update(height=300, margin={"l": 50, "r": 10, "t": 40, "b": 40},
                  meta={"height_over_width": 0.6, "methods": names, "deferred": bool(deferred)})
    return _figure(data, layout)


TIMING_NOT_LOADED = "timing.js not loaded"
"""Bar text of a deferred timing panel until :func:`timing_fill_script` has filled it."""
TIMING_GLOBAL = "PUSHBROOM_TIMING"
"""The global (``window.PUSHBROOM_TIMING``) that ``timing.js`` sets: ``{"methods": {name: {"fit_s", "eval_s",
"n_evaluated", ...}}, ...}`` (the content of ``timing.json``)."""


def timing_fill_script(names: Sequence[str]) -> str:
    """JavaScript (a plotly ``post_script``, ``{plot_id}`` = the timing figure's div) that fills a
    :func:`timing_bars` figure drawn with ``deferred=True`` from ``window.PUSHBROOM_TIMING`` (set by the
    export's ``timing.js``, loaded beside the page), with the texts :func:`timing_bars` writes (3
    significant digits, "no fit" for a method that does not learn).  Without it the panel says so."""
    import json

    return ("(function () {\n"
            "  var gd = document.getElementById('{plot_id}'), t = window." + TIMING_GLOBAL + ";\n"
            "  var names = " + json.dumps(list(names)) + ";\n"
            "  if (!t || !t.methods) {\n"
            "    Plotly.relayout(gd, {'annotations[2]': {text: 'the measured times are in timing.js beside this "
            "page (not found)', x: 0.5, y: 0.5, xref: 'paper', yref: 'paper', showarrow: false}});\n"
            "    return;\n  }\n"
            "  function g3(v) { return String(Number(v.toPrecision(3))); }\n"
            "  var fit = [], fitText = [], per = [], perData = [];\n"
            "  names.forEach(function (n) {\n"
            "    var m = t.methods[n] || {}, f = m.fit_s, e = m.eval_s, k = m.n_evaluated || 0;\n"
            "    fit.push(f > 0 ? f : null); fitText.push(f > 0 ? g3(f) + ' s' : 'no fit');\n"
            "    per.push(e != null && k > 0 ? 1e6 * e / k : null); perData.push([e, k]);\n"
            "  });\n"
            "  Plotly.restyle(gd, {y: [fit], text: [fitText]}, [0]);\n"
            "  Plotly.restyle(gd, {y: [per], customdata: [perData]}, [1]);\n"
            "})();")


CARTESIAN_TRACE_TYPES = frozenset({"bar", "box", "candlestick", "contour", "funnel", "heatmap", "histogram",
                                   "histogram2d", "histogram2dcontour", "image", "ohlc", "pie", "scatter",
                                   "scatterternary", "violin", "waterfall"})
"""Trace types of plotly.js's cartesian partial bundle (``assets/plotlyjs``)."""


def _plotlyjs_for(types: set[str] | frozenset[str]) -> str:
    """The plotly.js source to inline: the cartesian partial bundle (1.5 MB) when every trace type (``types``) is
    one of its types and it is the plotly.js version plotly.py was built for, else plotly.py's full bundle (4.8 MB)."""
    from plotly.offline import get_plotlyjs, get_plotlyjs_version

    if types <= CARTESIAN_TRACE_TYPES:
        try:
            from explorer._resources import asset

            text = asset("plotlyjs", "plotly-cartesian.min.js").read_text(encoding="utf-8")
        except Exception:  # an installation without the bundle: the full one still works
            text = ""
        if f"(cartesian - minified) v{get_plotlyjs_version()}" in text[:200]:
            return text
    return get_plotlyjs()


@dataclass(frozen=True)
class RenderedFigure:
    """One figure's part of the :func:`figures_html` page, made ahead of the page (:func:`render_figure`)."""

    position: int
    """The figure's position in the page's ``figures`` (its div's id is ``panel-<position>``)."""
    html: str
    trace_types: frozenset[str]


def render_figure(fig: Any, position: int, post_script: str | None = None) -> RenderedFigure:
    """The page part of ``fig`` (a ``go.Figure`` or its dict) at ``position`` in :func:`figures_html`'s
    ``figures``, written as a validated copy of it would be (the caller's figure is not changed), 1000 px wide at
    the height its ``layout.meta.height_over_width`` asks, its div ``panel-<position>``, ``post_script`` run once it
    is drawn.  A figure of this module (:func:`_figure`) is written from its own dict in a copy's key order, the
    same bytes without a second validation; any other figure or dict goes through one validated copy.  The export
    makes its maps' part while it waits for the sweep's last results."""
    import plotly.io as pio

    if getattr(fig, "_in_plotly_order", False):  # from _figure: valid, its dicts in order; to_dict is a copy already
        spec = fig.to_dict()
        spec["layout"] = _layout_as_copied(spec["layout"])
    else:  # anything else is written from a validated copy, checked by plotly once
        spec = go.Figure(fig).to_dict()
    types = frozenset(t.get("type") or "scatter" for t in spec["data"])
    layout = spec["layout"]
    aspect = float((layout.get("meta") or {}).get("height_over_width", 0.6))
    layout["width"] = 1000  # as update_layout(width=..., height=...) sets them (new keys last, in that order)
    layout["height"] = int(1000 * aspect)
    text = _unescape_base64(pio.to_html(spec, full_html=False, include_plotlyjs=False, div_id=f"panel-{position}",
                                        config=PLOTLY_CONFIG, post_script=post_script, validate=False))
    return RenderedFigure(int(position), text, types)


def figures_html(figures: Sequence[tuple], title: str, notes: Sequence[str] = (),
                 scripts: Sequence[str] = ()) -> str:
    """The figures in one self-contained HTML page: plotly.js inlined once (its cartesian partial bundle
    when the figures need nothing else, :func:`_plotlyjs_for`), no script or style loaded from the
    network (opens offline), deterministic element ids.

    Parameters
    ----------
    figures : sequence of (heading, go.Figure), (heading, go.Figure, post_script) or (heading, str)
        ``post_script``: JavaScript run once the figure is drawn (``{plot_id}`` is its div's id); a ``str``
        in place of the figure is an HTML block written as it is (a table); a :class:`RenderedFigure` in place
        of a figure is its part made ahead (:func:`render_figure`, at this position).
    title : str
        Page title and top heading.
    notes : sequence of str
        Paragraphs under the heading (what was computed, on which points).
    scripts : sequence of str
        File names *relative to the page* (files written beside it, never a URL) loaded before the figures
        with ``<script src>``; a missing one leaves the page working (the post-scripts check for it).
    """
    import html

    for src in scripts:
        if "/" in src or ":" in src or not src.endswith(".js"):
            raise ValueError(f"scripts must be .js files beside the page, got {src!r}")
    rendered: dict[int, RenderedFigure] = {}
    for k, entry in enumerate(figures):
        body = entry[1]
        if isinstance(body, RenderedFigure):
            if body.position != k:
                raise ValueError(f"figure {entry[0]!r} was rendered for position {body.position}, not {k}")
            rendered[k] = body
        elif not isinstance(body, str):
            rendered[k] = render_figure(body, k, entry[2] if len(entry) > 2 else None)
    parts = [f"<h1>{html.escape(title)}</h1>"] + [f"<p>{html.escape(t)}</p>" for t in notes]
    parts += [f'<script src="{html.escape(src)}"></script>' for src in scripts]
    if rendered:
        types = frozenset().union(*(r.trace_types for r in rendered.values()))
        parts.append('<script type="text/javascript">' + _plotlyjs_for(types) + "</script>")
    for k, entry in enumerate(figures):
        parts.append(f"<h2>{html.escape(entry[0])}</h2>")
        parts.append(rendered[k].html if k in rendered else entry[1])  # a figure's part, or an HTML block as given
    return ("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>" + html.escape(title)
            + "</title></head><body style=\"font-family: sans-serif\">\n" + "\n".join(parts) + "\n</body></html>\n")


_BDATA = re.compile(r'("bdata":")([A-Za-z0-9+=\\]*)(")')


def _unescape_base64(html_part: str) -> str:
    """Plotly's HTML writer escapes every ``/`` of the figure JSON as ``\\u002f`` (6 bytes for 1), also inside the
    base64 ``bdata`` of the arrays, where it cannot start a ``</script>`` (base64 has no ``<``).  An empty map cell
    is a NaN, whose float64 bytes make a ``/`` every 32 base64 characters, so a map with many empty cells (a DEM
    covering 60 % of the image) grew the page by a fifth; the escape is undone inside ``bdata`` only."""
    return _BDATA.sub(lambda m: m.group(1) + m.group(2).replace("\\u002f", "/") + m.group(3), html_part)


__all__ = [
    "CARTESIAN_TRACE_TYPES", "PLOTLY_CONFIG", "SCOP_MARKS", "accuracy_vs_density", "decimation_index", "empty_figure",
    "RenderedFigure", "figures_html", "method_colors", "render_figure", "residual_maps", "timing_bars",
    "timing_fill_script",
]
