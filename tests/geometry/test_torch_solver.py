"""``solve_exact_torch``: the exact solver's fast passes on a torch device against the numpy path and brute force."""

import dataclasses
import os
import subprocess
import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import torch

from explorer.geometry.kernels import (
    STATUS_CONVERGED,
    STATUS_INVALID,
    STATUS_NO_ROOT_IN_WINDOW,
    solve_exact,
)
from explorer.geometry.torch_solver import solve_exact_torch
from explorer.methods import create
from explorer.presets import build_scene
from tests.geometry.test_kernels import curved_scene
from tests.truth import brute_force_rows

ROOT = Path(__file__).resolve().parents[2]
N_POINTS = 20_000
N_TRUTH = 200  # brute force scans every row: a subset
CASES = ["WSU", "agile", "PMA-relief", "curved-jitter"]
CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device (torch.cuda.is_available())")


@cache
def case(name: str):
    """(scene, exact method, ground (N + 12, 3), true rows (N,), true cols (N,)); the last 12 points are off the
    image: 6 inside the search window (image +- 50 rows), 3 beyond it, 2 far away, 1 above the satellite."""
    if name == "PMA-relief":
        scene = build_scene("PMA", relief_m=1000.0, relief_seed=4)
    elif name == "curved-jitter":
        scene = curved_scene(jitter=True)
    else:
        scene = build_scene(name)
    method = create("exact", scene, backend="numpy")
    rng = np.random.default_rng(11)
    n, nr = N_POINTS, scene.n_rows
    row = rng.uniform(-0.5, nr - 0.5, n)
    col = rng.uniform(-0.5, scene.n_columns - 0.5, n)
    height = None if name == "PMA-relief" else rng.uniform(-300.0, 900.0, n)
    ground = scene.image_to_ground(row, col, height=height)
    off_rows = np.array([-0.3, nr - 0.7, -3.0, nr + 2.0, -40.0, nr + 45.0, -80.0, nr + 400.0, -2000.0])
    off_cols = np.array([10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0])
    off = scene.image_to_ground(off_rows, off_cols, height=scene.terrain.mean_height)
    far = np.array([[2e6, 2e6, 0.0], [-6e5, 0.0, 0.0]])
    above = scene.exterior.position(np.zeros(1)) + np.array([[0.0, 0.0, 1e5]])
    return scene, method, np.vstack([ground, off, far, above]), row, col


def solver_kwargs(method, **over):
    kw = dict(
        window=method.window,
        orient=method.orient,
        tol=method.tol,
        accept_step=method.accept_step,
        max_iter=method.max_iter,
        first_evaluations=method.first_evaluations,
    )
    kw.update(over)
    return kw


@cache
def numpy_result(name: str, **over):
    _, m, ground, _, _ = case(name)
    return solve_exact(m.kernel_params, ground, m.seed, backend="numpy", **solver_kwargs(m, **over))[:4]


def torch_result(name: str, device="cpu", chunk=None, **over):
    _, m, ground, _, _ = case(name)
    return solve_exact_torch(m.kernel_params, ground, m.seed, device=device, chunk=chunk, **solver_kwargs(m, **over))


def assert_same(a, b, atol):
    row_a, col_a, status_a, ce_a = a
    row_b, col_b, status_b, ce_b = b
    np.testing.assert_array_equal(status_a, status_b)
    np.testing.assert_allclose(row_a, row_b, rtol=0, atol=atol)  # NaN where NaN
    np.testing.assert_allclose(col_a, col_b, rtol=0, atol=atol)


@pytest.mark.parametrize("name", CASES)
def test_cpu_torch_matches_the_numpy_path(name):
    a, b = numpy_result(name), torch_result(name)
    for x, y in zip(a, b, strict=True):
        assert x.dtype == y.dtype and x.shape == y.shape
    assert_same(a, b, atol=1e-9)
    np.testing.assert_array_equal(a[3], b[3])  # CE per point
    counts = [np.bincount(x[2], minlength=4).tolist() for x in (a, b)]
    assert counts[0] == counts[1]


@pytest.mark.parametrize("name", CASES)
def test_cpu_torch_rows_are_exact(name):
    scene, _, ground, row, col = case(name)
    got_row, got_col, status, _ = torch_result(name)
    n = row.size
    assert (status[:n] == STATUS_CONVERGED).all()
    np.testing.assert_allclose(got_row[:n], row, rtol=0, atol=1e-7)
    np.testing.assert_allclose(got_col[:n], col, rtol=0, atol=1e-7)
    sub = np.r_[np.arange(0, n, n // N_TRUTH), n + np.arange(6)]  # image points and the 6 off-image roots
    truth = brute_force_rows(scene, ground[sub], margin=60)
    np.testing.assert_allclose(got_row[sub], truth, rtol=0, atol=1e-7)


@pytest.mark.parametrize("name", CASES)
def test_points_off_the_image_are_flagged_like_numpy(name):
    scene, _, ground, row, _ = case(name)
    n = row.size
    got_row, _, status, ce = torch_result(name)
    np.testing.assert_array_equal(status[n:], numpy_result(name)[2][n:])
    assert (status[n : n + 6] == STATUS_CONVERGED).all()  # in the window: a root, flagged outside by the method
    assert (status[n + 6 : n + 9] == STATUS_NO_ROOT_IN_WINDOW).all()
    assert np.isin(status[n + 9 : n + 11], [STATUS_NO_ROOT_IN_WINDOW, STATUS_INVALID]).all()
    assert status[n + 11] == STATUS_INVALID  # above the satellite: handed to the host iteration
    assert np.isnan(got_row[n + 6 :]).all()


def test_chunking_gives_identical_results():
    whole = torch_result("agile")
    for chunk in (997, 50_000):
        for x, y in zip(whole, torch_result("agile", chunk=chunk), strict=True):
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("passes, first", [(0, 1), (1, 1), (2, 1), (1, 2), (3, 2)])
def test_handoff_to_the_host_iteration_matches_numpy(passes, first):
    # few fast passes on agile (strong rates, jitter): many points finish in the host's safeguarded iteration
    a = numpy_result("agile", max_fast_passes=passes, first_evaluations=first)
    b = torch_result("agile", max_fast_passes=passes, first_evaluations=first)
    assert_same(a, b, atol=1e-9)
    np.testing.assert_array_equal(a[3], b[3])
    if first == 1 and passes <= 1:
        assert (b[3] > max(passes, 1)).sum() > 1000


def test_bad_arguments_raise_clear_errors():
    scene, m, ground, _, _ = case("WSU")
    kw = solver_kwargs(m)
    for device, match in [("gpu", "not a torch device"), ("meta", "'cpu' or 'cuda'"), (3.5, "not a torch device")]:
        with pytest.raises(ValueError, match=match):
            solve_exact_torch(m.kernel_params, ground[:10], m.seed, device=device, **kw)
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="CUDA is not available"):
            solve_exact_torch(m.kernel_params, ground[:10], m.seed, device="cuda", **kw)
    with pytest.raises(ValueError, match="chunk"):
        solve_exact_torch(m.kernel_params, ground[:10], m.seed, chunk=0, **kw)
    with pytest.raises(ValueError, match="first_evaluations"):
        solve_exact_torch(m.kernel_params, ground[:10], m.seed, **{**kw, "first_evaluations": 3})
    # a quartic orbit is beyond the branch-free evaluator
    p = m.kernel_params
    quartic = dataclasses.replace(p, pos=np.pad(p.pos, ((0, 0), (0, 5 - p.pos.shape[1]))))
    assert quartic.fixed_model(m.window) is None
    with pytest.raises(ValueError, match="branch-free"):
        solve_exact_torch(quartic, ground[:10], m.seed, **kw)


def test_empty_input_and_torch_device_objects():
    _, m, ground, _, _ = case("WSU")
    row, col, status, ce = solve_exact_torch(m.kernel_params, ground[:0], m.seed, **solver_kwargs(m))
    assert row.shape == col.shape == status.shape == ce.shape == (0,)
    assert (row.dtype, status.dtype, ce.dtype) == (np.float64, np.int8, np.int64)
    one = solve_exact_torch(m.kernel_params, ground[:5], m.seed, device=torch.device("cpu"), **solver_kwargs(m))
    np.testing.assert_array_equal(one[0], numpy_result("WSU")[0][:5])


def test_torch_is_imported_lazily():
    code = "import sys, explorer.geometry.torch_solver; assert 'torch' not in sys.modules"
    subprocess.run(
        [sys.executable, "-c", code], check=True, cwd=ROOT, env={**os.environ, "EXPLORER_DISABLE_NUMBA": "1"}
    )


@pytest.mark.cuda
@CUDA
@pytest.mark.parametrize("name", CASES)
def test_cuda_matches_the_numpy_path(name):
    a, b = numpy_result(name), torch_result(name, device="cuda")
    assert_same(a, b, atol=1e-6)
    chunked = torch_result(name, device="cuda", chunk=4099)
    assert_same(b, chunked, atol=0)
