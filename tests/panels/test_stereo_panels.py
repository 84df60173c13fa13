"""Stereo panels: one heat map per approximation with the map's values, the curve panel's deviation trace."""

from __future__ import annotations

import numpy as np

from explorer.panels.stereo import approximation_figure, epipolar_curve_figure
from explorer.stereo.approximation import ApproximationMaps
from explorer.stereo.epipolar import EpipolarCurve, chord_deviation


def test_approximation_figure_shows_every_map():
    maps = ApproximationMaps(np.array([0.0, 10.0]), np.array([0.0, 5.0, 10.0]), np.array([0.0, 500.0, 1000.0]),
                             {"straight line": np.arange(6.0).reshape(2, 3), "grid": np.ones((2, 3)) * 1e-3},
                             step=30.0)
    fig = approximation_figure(maps)
    assert len(fig.data) == 2
    np.testing.assert_array_equal(fig.data[0].z, maps.maps["straight line"])
    titles = [a.text for a in fig.layout.annotations]
    assert "grid (step 30)" in titles and "straight line" in titles


def test_curve_figure_deviation_and_exaggeration():
    h = np.linspace(0.0, 1000.0, 5)
    row = np.array([0.0, 0.5, 1.0, 1.5, 2.0]) * 100
    col = np.array([0.0, 0.01, 0.0133, 0.01, 0.0])
    dev = chord_deviation(row, col)
    curve = EpipolarCurve(h, row, col, dev, np.zeros((5, 2)), np.zeros((5, 3)))
    fig = epipolar_curve_figure(curve, exaggeration=100.0)
    np.testing.assert_allclose(fig.data[0].y, dev)
    # exaggerated across the chord (the column axis here): 100 x the deviation
    np.testing.assert_allclose(np.abs(fig.data[1].x), 100 * np.abs(col), rtol=1e-9)
