"""Plotly panels of a refinement (:class:`explorer.refine.adjust.Refinement`): results in, ``go.Figure`` out.

- :func:`residual_quiver_figure` -- residual vectors (measured - model) of control, check and tie points
  over the image, before and after the adjustment, outliers crossed;
- :func:`correction_field_figure` -- the field the adjustment removed: the change of the model's pixel
  (after - before) over a grid of the image, row and column components;
- :func:`parameter_table_figure` -- the parameters with their a posteriori sigmas;
- :func:`trajectory_figure` -- a line-scan sensor's original and adjusted perspective centres and boresights in 3D;
- :func:`refinement_html` -- all of them in one offline HTML page (``pushbroom refine`` writes it).

Pixels: ``docs/conventions.md`` (rows down, columns across); ``docs/refine.md`` for the adjustment.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

if TYPE_CHECKING:  # typing only
    from explorer.refine.adjust import Refinement

__all__ = ["correction_field_figure", "parameter_table_figure", "refinement_html", "residual_quiver_figure",
           "trajectory_figure"]

ROLE_COLOURS = {"control": "#1f77b4", "check": "#2ca02c", "tie": "#9467bd"}


def _points(ref: Refinement, image: int) -> dict[str, np.ndarray]:
    """Per measured point of ``image``: role, row, col, residuals before/after (N, 2), outlier."""
    rows = [r for r in ref.points_rows() if r["image"] == ref.image_names[image]]
    return {
        "role": np.asarray([r["role"] for r in rows]),
        "row": np.asarray([r["row"] for r in rows], dtype=float),
        "col": np.asarray([r["col"] for r in rows], dtype=float),
        "before": np.asarray([[r["residual_row_before"], r["residual_col_before"]] for r in rows], dtype=float),
        "after": np.asarray([[r["residual_row_after"], r["residual_col_after"]] for r in rows], dtype=float),
        "outlier": np.asarray([bool(r["outlier"]) for r in rows]),
    }


def _segments(x: np.ndarray, y: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> tuple[list, list]:
    xs: list = []
    ys: list = []
    for a, b, c, d in zip(x, y, dx, dy, strict=True):
        xs += [a, a + c, None]
        ys += [b, b + d, None]
    return xs, ys


def residual_quiver_figure(ref: Refinement, image: int = 0, *, scale: float | None = None,
                           height: int = 460) -> go.Figure:
    """Residual vectors of one image's points, before (left) and after (right), drawn ``scale`` times
    their length (default: the median residual before shows as 4 % of the image's larger side)."""
    p = _points(ref, image)
    rows, cols = ref.images[image].size
    norm = np.hypot(p["before"][:, 0], p["before"][:, 1])
    if scale is None:
        median = float(np.median(norm)) if norm.size else 0.0
        scale = 0.04 * max(rows, cols) / median if median > 0 else 1.0
    fig = make_subplots(rows=1, cols=2, subplot_titles=(f"before (vectors x{scale:.3g})",
                                                        f"after (vectors x{scale:.3g})"))
    for k, key in enumerate(("before", "after")):
        for role, colour in ROLE_COLOURS.items():
            m = p["role"] == role
            if not m.any():
                continue
            d = p[key][m]
            xs, ys = _segments(p["col"][m], p["row"][m], scale * d[:, 1], scale * d[:, 0])
            fig.add_trace(go.Scatter(x=xs, y=ys, mode="lines", line={"color": colour, "width": 1.5},
                                     name=f"{role} residual", legendgroup=role, showlegend=k == 0,
                                     hoverinfo="skip"), row=1, col=k + 1)
            text = [f"{role}: d_row {a:+.3f}, d_col {b:+.3f} px" for a, b in d]
            fig.add_trace(go.Scatter(x=p["col"][m], y=p["row"][m], mode="markers", marker={"color": colour, "size": 4},
                                     name=role, legendgroup=role, showlegend=False, text=text,
                                     hovertemplate="%{text}<extra></extra>"), row=1, col=k + 1)
        bad = p["outlier"]
        if bad.any():
            fig.add_trace(go.Scatter(x=p["col"][bad], y=p["row"][bad], mode="markers", name="outlier",
                                     marker={"symbol": "x", "color": "#d62728", "size": 9}, showlegend=k == 0),
                          row=1, col=k + 1)
        fig.update_xaxes(range=[-0.5, cols - 0.5], title_text="column", row=1, col=k + 1)
        fig.update_yaxes(range=[rows - 0.5, -0.5], title_text="row" if k == 0 else None, row=1, col=k + 1)
    rep = ref.report()
    fig.update_layout(height=height, margin={"l": 50, "r": 20, "t": 70, "b": 40},
                      title=f"{ref.image_names[image]}: residuals (measured - model), {ref.models[image]}; "
                            f"control RMSE "
                            f"{_fmt(rep['control_rmse_px_before'])} -> {_fmt(rep['control_rmse_px'])} px")
    return fig


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def correction_field(ref: Refinement, image: int = 0, n: int = 25) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows (n,), cols (n,), field (n, n, 2)): the model's pixel after minus before for the ground seen at
    each grid pixel (RPC: at its height offset; scene: on its terrain), pixels; NaN where it does not localise."""
    adapter = ref.images[image]
    rows, cols = adapter.size
    r = np.linspace(0.0, rows - 1.0, n)
    c = np.linspace(0.0, cols - 1.0, n)
    rr, cc = np.meshgrid(r, c, indexing="ij")
    lon, lat, h, ok = adapter.localise(rr.ravel(), cc.ravel())
    field = np.full((n * n, 2), np.nan)
    if ok.any():
        before = adapter.project(lon[ok], lat[ok], h[ok], ref.models[image], None)
        after = adapter.project(lon[ok], lat[ok], h[ok], ref.models[image], ref.result.parameters[image])
        field[ok] = after - before
    return r, c, field.reshape(n, n, 2)


def correction_field_figure(ref: Refinement, image: int = 0, *, n: int = 25, height: int = 380) -> go.Figure:
    """Maps of the removed field (row and column components, pixels) over the image."""
    r, c, field = correction_field(ref, image, n)
    fig = make_subplots(rows=1, cols=2, subplot_titles=("row correction (px)", "column correction (px)"),
                        horizontal_spacing=0.12)
    for k in range(2):
        fig.add_trace(go.Heatmap(z=field[:, :, k], x=c, y=r, colorscale="RdBu_r",
                                 colorbar={"title": "px", "x": 0.44 if k == 0 else 1.0, "len": 0.8, "thickness": 10},
                                 hovertemplate="row %{y:.0f}, col %{x:.0f}<br>%{z:.3f} px<extra></extra>"),
                      row=1, col=k + 1)
        fig.update_yaxes(autorange="reversed", title_text="row" if k == 0 else None, row=1, col=k + 1)
        fig.update_xaxes(title_text="column", row=1, col=k + 1)
    fig.update_layout(height=height, margin={"l": 50, "r": 30, "t": 70, "b": 40},
                      title=f"{ref.image_names[image]}: the field the {ref.models[image]} adjustment removed "
                            "(after - before)")
    return fig


def parameter_table_figure(ref: Refinement, *, height: int | None = None) -> go.Figure:
    """The parameters: image, name, value, a posteriori sigma and value / sigma; sigma0 in the title."""
    table = ref.parameter_table()
    columns = [[p["image"] for p in table], [p["name"] for p in table], [f"{p['value']:+.6g}" for p in table],
               [f"{p['sigma']:.3g}" for p in table],
               [f"{p['value'] / p['sigma']:+.1f}" if p["sigma"] > 0 else "-" for p in table]]
    fig = go.Figure(go.Table(header={"values": ["image", "parameter", "value", "sigma", "value / sigma"]},
                             cells={"values": columns}))
    fig.update_layout(height=height or 120 + 24 * len(table), margin={"l": 10, "r": 10, "t": 50, "b": 10},
                      title=f"{ref.model}: sigma0 {ref.result.sigma0:.3f}, redundancy {ref.result.redundancy}")
    return fig


def trajectory_figure(ref: Refinement, image: int = 0, *, n: int = 30, boresight_m: float | None = None,
                      height: int = 480) -> go.Figure:
    """A line-scan sensor's perspective centres over the image's time (original and adjusted, local ENU km,
    :func:`explorer.refine.trajectory.refinement_trajectory`) with the boresight (camera -z axis) drawn
    ``boresight_m`` long at a few times; ValueError for an RPC (no orbit)."""
    from explorer.refine.trajectory import refinement_trajectory

    try:
        comparison = refinement_trajectory(ref, image, n)
    except ValueError:
        raise ValueError("an RPC has no trajectory: the 3D panel needs a sensor with scanlines") from None
    fig = go.Figure()
    step = max(1, n // 5)
    for label, centres, attitude, colour in (
            ("original", comparison.original_centre_m, comparison.original_attitude, "#7f7f7f"),
            ("adjusted", comparison.adjusted_centre_m, comparison.adjusted_attitude, "#d62728")):
        pos = centres / 1e3
        fig.add_trace(go.Scatter3d(x=pos[:, 0], y=pos[:, 1], z=pos[:, 2], mode="lines", name=f"{label} orbit",
                                   line={"color": colour, "width": 5}))
        axis = -attitude[::step, :, 2]  # the camera looks along -z
        length = (boresight_m if boresight_m is not None else 0.15 * float(pos[0, 2]) * 1e3) / 1e3
        xs, ys = _segments(pos[::step, 0], pos[::step, 1], length * axis[:, 0], length * axis[:, 1])
        zs = _segments(pos[::step, 2], pos[::step, 2], length * axis[:, 2], length * axis[:, 2])[0]
        fig.add_trace(go.Scatter3d(x=xs, y=ys, z=zs, mode="lines", name=f"{label} boresight",
                                   line={"color": colour, "width": 2, "dash": "dot"}))
    summary = comparison.summary()
    d, a = summary["displacement_m"], summary["attitude_change_urad"]
    fig.update_layout(height=height, margin={"l": 0, "r": 0, "t": 50, "b": 0},
                      scene={"xaxis_title": "east (km)", "yaxis_title": "north (km)", "zaxis_title": "up (km)"},
                      title=f"{ref.image_names[image]}: trajectory moved by {d[0]:.2f} .. {d[1]:.2f} m, attitude "
                            f"turned {a[0]:.2f} .. {a[1]:.2f} urad")
    return fig


def refinement_html(ref: Refinement) -> str:
    """Every panel of the refinement as one offline HTML page (plotly.js inlined once)."""
    from explorer.sensor import has_line_geometry

    figures = [parameter_table_figure(ref)]
    for k in range(len(ref.images)):
        figures += [residual_quiver_figure(ref, k), correction_field_figure(ref, k)]
        if has_line_geometry(ref.images[k].sensor):
            figures.append(trajectory_figure(ref, k))
    parts = [fig.to_html(full_html=False, include_plotlyjs=(k == 0)) for k, fig in enumerate(figures)]
    return ("<!DOCTYPE html><html><head><meta charset='utf-8'><title>refinement</title></head><body>"
            + "\n".join(parts) + "</body></html>\n")
