"""GDP (general distance prediction) against independent truth: the exact rows of simulated
check points and the brute-force bracketing solver of ``tests/truth.py``."""


import numpy as np
import pytest

from explorer.errors import InputError
from explorer.methods import create
from explorer.methods.gdp import GeneralDistancePrediction
from explorer.presets import preset_ids
from tests.methods.cases import ce_counts, scene_for, scps_for

BAR_PX = 1e-6  # the accuracy bar for exact methods
SMOOTH_PRESETS = [p for p in preset_ids() if p != "agile"]


def test_agile_attitude_rates_alone_meet_the_bar():
    """``agile`` without its jitter (strong body rates and accelerations only): prediction from the
    first line still converges and the interpolation stays below the bar (measured 3.1e-7 px)."""
    scene, scps = scene_for("agile", jitter=0.0), scps_for("agile", jitter=0.0)
    res = create("gdp", scene).ground_to_image(scps.ground)
    assert res.valid.all()
    assert np.max(np.abs(res.row - scps.row)) < BAR_PX


@pytest.mark.parametrize(("preset", "max_ce"), [("WSU", 7), ("ISB", 7), ("agile", 9)])
def test_ce_per_point_is_plausible(preset, max_ce):
    """CE = predictions + neighbour line (+ rare widening) + 1 column.  The residual slope is
    1.003-1.04 px per row on the paper presets, so each prediction leaves <= 4 % of the distance
    plus 0.5 of rounding: from the first line (<= 8300 lines away) 8300 -> 333 -> 14 -> 1.1 -> < 1,
    i.e. <= 4-5 predictions, + 1 neighbour + 1 column <= 7.  On ``agile`` the slope is up to 1.14
    (14 % left per prediction): 6000 -> 840 -> 118 -> 17 -> 2.9 -> < 1, 6 predictions, <= 9."""
    setup, ce = ce_counts("gdp", preset)
    assert setup == 0 and ce.min() >= 3 and ce.max() <= max_ce


def test_trace_converges_to_exact_row():
    scene, scps = scene_for("ISB"), scps_for("ISB").sample(300, seed=1)
    res = create("gdp", scene).ground_to_image(scps.ground, trace=True)
    assert res.trace is not None and len(res.trace) >= 3
    assert all(t.shape == scps.row.shape for t in res.trace)
    np.testing.assert_array_equal(res.trace[0], np.zeros(len(scps)))  # the FIRST scanline
    for t in res.trace[:-1]:
        np.testing.assert_array_equal(t, np.rint(t))  # predictions jump between integer lines
    np.testing.assert_array_equal(res.trace[-1], res.row)
    err = np.array([np.max(np.abs(t - scps.row)) for t in res.trace])
    assert err[0] > 8000
    assert np.all(np.diff(err[err > 1.0]) < 0)  # each prediction closes in until within a line
    assert err[-2] <= 1.0  # the bracketing neighbour
    assert err[-1] < BAR_PX


def test_registry_and_parameters():
    scene = scene_for("WSU")
    assert isinstance(create("gdp", scene), GeneralDistancePrediction)
    with pytest.raises(InputError):
        create("gdp", scene, tol=0.2)
    with pytest.raises(InputError):
        create("gdp", scene, start_row=0.5)
    # starting from the last line instead of the first changes the path, not the answer
    scps = scps_for("WSU").sample(200, seed=2)
    a = create("gdp", scene).ground_to_image(scps.ground)
    b = create("gdp", scene, start_row=scene.n_rows - 1).ground_to_image(scps.ground)
    np.testing.assert_allclose(a.row, b.row, atol=1e-9)
