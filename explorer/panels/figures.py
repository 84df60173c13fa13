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
from collections.abc import Mapping, Sequence

import numpy as np
import plotly.graph_objects as go

from explorer.evaluate import Evaluation
from explorer.panels import (
    DIVERGING,
    INVALID_RGB,
    SCOP_RGB,
    plotly_colorscale,
    rgb_string,
)
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
        xa: dict = {"domain": [x0, x0 + w], "anchor": f"y{sx}"}
        ya: dict = {"domain": [y1 - h, y1], "anchor": f"x{sx}"}
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


def residual_maps(
    evaluations: Mapping[str, Evaluation],
    check: PointSet,
    *,
    control: PointSet | None = None,
    shape: tuple[int, int] | None = None,
    limit_px: float = 1.0,
    max_points: int | None = 20000,
    labels: Mapping[str, str] | None = None,
    columns: int | None = None,
) -> go.Figure:
    """Scanline residual maps over the image, one small multiple per method.

    Parameters
    ----------
    evaluations : mapping of str to Evaluation
        Method name -> evaluation on ``check`` (``residual_row`` (M,) aligned with
        ``evaluated_index`` (M,), pixels, NaN where the method gave no valid row).
    check : PointSet
        The SCPs the evaluations used (image row/col of each point).
    control : PointSet, optional
        SCOPs, drawn as gold crosses on every map.
    shape : (int, int), optional
        Image (rows, columns) for the axis ranges (pixel edges).
    limit_px : float
        The shared colour scale spans ``[-limit_px, +limit_px]`` and is centred at 0;
        larger residuals saturate.  It is fixed: the same for every method.
    max_points : int or None
        Draw at most this many points per method (an evenly strided subset, named in the
        subplot title); None draws all.
    labels : mapping, optional
        Display names.
    columns : int, optional
        Small multiples per figure row (default 2, or 3 beyond four methods).

    Returns
    -------
    go.Figure
        One ``scattergl`` trace per method (``x`` = column, ``y`` = row, ``customdata`` =
        residual, all on ``coloraxis``), plus traces for invalid points and SCOPs.
        ``layout.meta["height_over_width"]`` suggests a display aspect.
    """
    names = list(evaluations)
    if not names:
        return empty_figure("no method evaluated")
    ncol = columns or (2 if len(names) <= 4 else 3)
    ncol = max(1, min(ncol, len(names)))
    nrow = math.ceil(len(names) / ncol)
    titles = []
    for n in names:
        ev = evaluations[n]
        m = len(ev.evaluated_index)
        shown = min(m, max_points) if max_points is not None else m
        sub = f"{m:,} of {ev.n_scps:,} SCPs" if m < ev.n_scps else f"{m:,} SCPs"
        dec = f", {shown:,} drawn" if shown < m else ""
        titles.append(f"{_label(n, labels)}: RMSE {ev.rmse_px:.3g} px<br>({sub}{dec})")
    layout, refs = _grid(len(names), ncol, titles, hgap=0.04, vgap=0.16)
    image_hw = shape[0] / shape[1] if shape is not None else 1.0
    hw = float(np.clip(0.25 + 0.85 * nrow / ncol * image_hw, 0.4, 2.5))
    hover = "row %{y:.2f}<br>col %{x:.2f}<br>residual %{customdata:.4g} px<extra>%{meta}</extra>"
    data: list[dict] = []
    for k, n in enumerate(names):
        ev = evaluations[n]
        xr, yr = refs[k]
        res = np.asarray(ev.residual_row, dtype=np.float64)
        idx = np.asarray(ev.evaluated_index)
        pos = decimation_index(res.size, max_points)
        res_s, idx_s = res[pos], idx[pos]
        ok = np.isfinite(res_s)
        data.append({
            "type": "scattergl", "x": check.col[idx_s[ok]], "y": check.row[idx_s[ok]],
            "customdata": res_s[ok], "mode": "markers", "xaxis": xr, "yaxis": yr,
            "marker": {"color": res_s[ok], "coloraxis": "coloraxis", "size": 4},
            "name": _label(n, labels), "meta": _label(n, labels), "hovertemplate": hover,
            "showlegend": False,
        })
        if (~ok).any():
            data.append({
                "type": "scattergl", "x": check.col[idx_s[~ok]], "y": check.row[idx_s[~ok]],
                "mode": "markers", "xaxis": xr, "yaxis": yr,
                "marker": {"color": rgb_string(INVALID_RGB), "size": 5, "symbol": "x"},
                "name": "no valid row", "legendgroup": "invalid", "showlegend": False,
                "hovertemplate": "row %{y:.2f}<br>col %{x:.2f}<br>no valid row<extra></extra>",
            })
        if control is not None and len(control):
            data.append({
                "type": "scattergl", "x": control.col, "y": control.row, "mode": "markers",
                "xaxis": xr, "yaxis": yr,
                "marker": {"color": rgb_string(SCOP_RGB), "size": 7, "symbol": "cross",
                           "line": {"width": 1, "color": "black"}},
                "name": f"SCOPs ({len(control)})", "legendgroup": "scop", "showlegend": k == 0,
                "hovertemplate": "SCOP<br>row %{y:.2f}<br>col %{x:.2f}<extra></extra>",
            })
    for k in range(len(names)):
        r, c = divmod(k, ncol)
        sx = "" if k == 0 else str(k + 1)
        xa, ya = layout[f"xaxis{sx}"], layout[f"yaxis{sx}"]
        xa.update(showgrid=False, zeroline=False)
        ya.update(showgrid=False, zeroline=False)
        if r == nrow - 1 or k + ncol >= len(names):
            xa["title"] = {"text": "column"}
        if c == 0:
            ya["title"] = {"text": "row"}
        if shape is not None:
            xa["range"] = [-0.5, shape[1] - 0.5]
            ya["range"] = [shape[0] - 0.5, -0.5]
        else:
            ya["autorange"] = "reversed"
    layout.update(
        coloraxis={"colorscale": plotly_colorscale(DIVERGING), "cmin": -limit_px, "cmax": limit_px,
                   "cmid": 0.0, "colorbar": {"title": {"text": "row error<br>px"}, "thickness": 12,
                                                "len": 0.7, "y": 1.0, "yanchor": "top"}},
        height=int(500 * hw), margin={"l": 50, "r": 10, "t": 60, "b": 40},
        legend={"x": 1.02, "xanchor": "left", "y": 0.0, "yanchor": "bottom", "font": {"size": 10}},
        plot_bgcolor=PLOT_BG,
        meta={"height_over_width": hw, "limit_px": limit_px},
    )
    fig = go.Figure(data=data, layout=layout)
    return fig


def accuracy_vs_density(
    sweep: Mapping[str, Sequence[Evaluation]],
    *,
    labels: Mapping[str, str] | None = None,
    marks: Sequence[int] = SCOP_MARKS,
    colors: Mapping[str, str] | None = None,
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

    Returns
    -------
    go.Figure
        Per method a solid RMSE trace and a dashed dr_max trace (``customdata`` holds
        the exact values; the plotted y is floored at :data:`LOG_FLOOR_PX`), and a
        dotted line at 1 px.
    """
    colors = dict(colors or method_colors(list(sweep)))
    fig = go.Figure()
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
            rm = np.array([e.rmse_px for e in fitted])
            dm = np.array([e.dr_max_px for e in fitted])
            mode = "lines+markers"
        else:
            x = np.array([lo, hi], dtype=float)
            rm = np.full(2, evs[-1].rmse_px)
            dm = np.full(2, evs[-1].dr_max_px)
            mode = "lines"
        suffix = "" if fitted else " (no SCOPs needed)"
        for vals, kind, dash in ((rm, "RMSE", "solid"), (dm, "dr_max", "dash")):
            fig.add_trace(go.Scatter(
                x=x, y=np.maximum(vals, LOG_FLOOR_PX), customdata=vals,
                mode=mode, line={"color": col, "dash": dash}, legendgroup=n,
                name=f"{_label(n, labels)} {kind}{suffix}", meta=kind,
                hovertemplate=f"{_label(n, labels)}<br>%{{x:.0f}} SCOPs<br>%{{meta}} %{{customdata:.3g}} px"
                              "<extra></extra>",
            ))
    fig.add_hline(y=1.0, line={"dash": "dot", "color": "black"},
                  annotation_text="1 px (sub-pixel below)", annotation_position="top left")
    fig.update_xaxes(type="log", title_text="number of SCOPs", tickvals=list(marks))
    fig.update_yaxes(type="log", title_text="scanline error, px", exponentformat="power")
    fig.update_layout(height=380, margin={"l": 60, "r": 10, "t": 30, "b": 40},
                      legend={"font": {"size": 10}}, meta={"height_over_width": 0.8},
                      title={"text": "accuracy vs SCOP density (solid RMSE, dashed dr_max)",
                             "font": {"size": 12}})
    return fig


def timing_bars(
    evaluations: Mapping[str, Evaluation],
    *,
    labels: Mapping[str, str] | None = None,
    colors: Mapping[str, str] | None = None,
) -> go.Figure:
    """Fit time and ground-to-image time per method, as bars (log y).

    Parameters
    ----------
    evaluations : mapping of str to Evaluation
    labels, colors : mapping, optional

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
    for ax in ("yaxis", "yaxis2"):
        layout[ax].update(type="log", exponentformat="power")
    layout.update(height=300, margin={"l": 50, "r": 10, "t": 40, "b": 40},
                  meta={"height_over_width": 0.6})
    fig = go.Figure(data=data, layout=layout)
    return fig


__all__ = [
    "SCOP_MARKS", "accuracy_vs_density", "decimation_index", "empty_figure", "method_colors",
    "residual_maps", "timing_bars",
]
