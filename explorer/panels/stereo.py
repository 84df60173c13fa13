"""Plotly panels of a stereo pair: the approximation residual maps (:func:`approximation_figure`) and one
pixel's epipolar curve against its chord (:func:`epipolar_curve_figure`).  Results in, ``go.Figure`` out
(``docs/stereo.md``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

if TYPE_CHECKING:  # typing only
    from explorer.stereo.approximation import ApproximationMaps
    from explorer.stereo.epipolar import EpipolarCurve


def approximation_figure(maps: ApproximationMaps, *, height: int = 360) -> go.Figure:
    """One heat map per approximation: its largest distance from the exact epipolar curve over the height range
    (pixels, right image) at each left pixel of the sample; each map has its own colour bar (their scales differ
    by orders of magnitude)."""
    names = list(maps.maps)
    fig = make_subplots(rows=1, cols=len(names), subplot_titles=[_title(n, maps) for n in names],
                        horizontal_spacing=0.08)
    for k, name in enumerate(names):
        values = maps.maps[name]
        x_bar = (k + 1) / len(names) - 0.015
        fig.add_trace(go.Heatmap(
            z=values, x=maps.cols, y=maps.rows, colorscale="Viridis", zmin=0.0,
            colorbar={"title": "px", "x": x_bar, "len": 0.8, "thickness": 10},
            hovertemplate="row %{y:.0f}, col %{x:.0f}<br>%{z:.3g} px<extra>" + name + "</extra>",
        ), row=1, col=k + 1)
        fig.update_yaxes(autorange="reversed", title_text="left row" if k == 0 else None, row=1, col=k + 1)
        fig.update_xaxes(title_text="left column", row=1, col=k + 1)
    h0, h1 = float(np.min(maps.heights)), float(np.max(maps.heights))
    fig.update_layout(height=height, margin={"l": 50, "r": 30, "t": 70, "b": 40},
                      title=f"Epipolar approximations vs the exact curve, heights {h0:g} .. {h1:g} m")
    return fig


def _title(name: str, maps: ApproximationMaps) -> str:
    if name.startswith("grid") and maps.step is not None:
        return f"{name} (step {maps.step:g})"
    return name


def epipolar_curve_figure(curve: EpipolarCurve, *, exaggeration: float = 1.0, height: int = 360) -> go.Figure:
    """The exact curve of one left pixel and its chord: the chord deviation against height (pixels), and the
    curve in the right image with the deviation exaggerated ``exaggeration`` times across the chord."""
    if curve.row.ndim != 1:
        raise ValueError("epipolar_curve_figure takes the curve of one left pixel (1-D rows and columns)")
    fig = make_subplots(rows=1, cols=2, subplot_titles=("distance from the chord",
                                                        f"curve in the right image (x{exaggeration:g} across)"))
    fig.add_trace(go.Scatter(x=curve.heights, y=curve.chord_deviation_px, mode="lines+markers", name="deviation",
                             hovertemplate="h %{x:.0f} m<br>%{y:.4f} px<extra></extra>"), row=1, col=1)
    fig.update_xaxes(title_text="height (m)", row=1, col=1)
    fig.update_yaxes(title_text="px", row=1, col=1)
    r0, c0 = curve.row[0], curve.col[0]
    d = np.array([curve.row[-1] - r0, curve.col[-1] - c0])
    d /= np.linalg.norm(d)
    normal = np.array([d[1], -d[0]])  # deviation sign of explorer.stereo.epipolar.chord_deviation
    shift = (exaggeration - 1.0) * curve.chord_deviation_px
    rows = curve.row + shift * normal[0]
    cols = curve.col + shift * normal[1]
    fig.add_trace(go.Scatter(x=cols, y=rows, mode="lines+markers", name="exact curve",
                             text=[f"{h:g} m" for h in curve.heights],
                             hovertemplate="%{text}<br>row %{y:.3f}, col %{x:.3f}<extra></extra>"), row=1, col=2)
    fig.add_trace(go.Scatter(x=[c0, curve.col[-1]], y=[r0, curve.row[-1]], mode="lines", name="chord",
                             line={"dash": "dash"}), row=1, col=2)
    fig.update_yaxes(autorange="reversed", title_text="right row", row=1, col=2)
    fig.update_xaxes(title_text="right column", row=1, col=2)
    fig.update_layout(height=height, margin={"l": 50, "r": 20, "t": 60, "b": 40})
    return fig


__all__ = ["approximation_figure", "epipolar_curve_figure"]
