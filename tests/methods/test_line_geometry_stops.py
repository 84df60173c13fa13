"""Where the searches on a rigorous line-scan model stop (issue 24): ``exact`` at the rows to which the model's
residual defines a root (``root_resolution_rows``), ``nr`` on Newton's own error estimate.  Truth: the model's own
ground to image (the bracketed root of its residual); the evaluations per point are counted by the methods."""

import numpy as np
import pytest

from explorer.methods import create
from explorer.points import simulate_points
from explorer.real.dimap import rigorous_scene_from_dimap
from tests.real.conftest import PHR_2017

ROOT_PX = 1e-8  # the model's root resolution (tests/real/test_linescan_kernel.py: roots defined to a few 1e-9 rows)


@pytest.fixture(scope="module")
def case():
    scene = rigorous_scene_from_dimap(PHR_2017, n_gcps=60, n_check=60)[0]
    points = simulate_points(scene, 3000, kind="scp", seed=4)
    truth = scene.project(points.ground)
    assert truth.valid.all()
    return scene, points, truth


def test_exact_stops_at_the_models_root_resolution(case):
    scene, points, truth = case
    assert scene.root_resolution_rows == 1e-8
    r = create("exact", scene).ground_to_image(points.ground)
    assert r.converged.all()
    assert np.max(np.abs(r.row - truth.row)) < ROOT_PX and np.max(np.abs(r.col - truth.col)) < ROOT_PX
    assert r.ce_evaluations.mean() < 5.0  # 7.5 when it asked for 1e-10 rows, below the round-off


def test_nr_stops_on_its_error_estimate_and_evaluates_the_column_at_the_row(case):
    scene, points, truth = case
    nr = create("nr", scene)
    r = nr.ground_to_image(points.ground)
    assert r.converged.all()
    assert np.max(np.abs(r.row - truth.row)) < ROOT_PX and np.max(np.abs(r.col - truth.col)) < ROOT_PX
    stopped = r.info["predicted_stop"]
    assert stopped.mean() > 0.5
    assert r.ce_evaluations.mean() < 10.5  # 11.3 before: a fourth iteration (3 CE) confirmed what the third found
    # without the estimate: the same answers, more evaluations
    nr.predicted_stop = False
    r0 = nr.ground_to_image(points.ground)
    assert np.max(np.abs(r0.row - r.row)) < ROOT_PX and np.max(np.abs(r0.col - r.col)) < ROOT_PX
    assert r0.ce_evaluations.mean() > r.ce_evaluations.mean() + 1.0
