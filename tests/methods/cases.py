"""Scenes and check points shared by the method tests (cached: building them is the slow part)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from functools import cache

import numpy as np

from explorer.methods import create
from explorer.points import PointSet, simulate_points
from explorer.presets import build_scene
from explorer.scene import Scene
from tests.scenes import curved_scene  # noqa: F401 - re-exported for the method tests

N_SCPS = 2000


@cache
def scene_for(preset: str, relief: float = 0.0, jitter: float = 1.0) -> Scene:
    """A preset scene, optionally with seeded relief (seed 3) and scaled jitter."""
    return build_scene(preset, relief_m=relief, relief_seed=3, jitter_amplitude_scale=jitter)


@cache
def scps_for(preset: str, relief: float = 0.0, jitter: float = 1.0, n: int = N_SCPS, layers: int = 1) -> PointSet:
    """About ``n`` cell-centred check points with exact rows on :func:`scene_for`."""
    return simulate_points(scene_for(preset, relief, jitter), n, layers=layers, kind="scp")


def random_image_points(scene: Scene, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Seeded random image points on the image (pixel edges included) and their ground points:
    exact rows (N,), columns (N,), ground (N, 3) (points whose line of sight misses a DEM dropped)."""
    rng = np.random.default_rng(seed)
    row = rng.uniform(-0.5, scene.n_rows - 0.5, n)
    col = rng.uniform(-0.5, scene.n_columns - 0.5, n)
    ground = scene.image_to_ground(row, col)
    ok = np.isfinite(ground[:, 0])
    return row[ok], col[ok], ground[ok]


def interpolation_bound(scene: Scene, ground: np.ndarray, row: np.ndarray) -> np.ndarray:
    """Independent bound (rows) of linear interpolation of the residual between the integer lines
    around ``row``: |x''| / (8 |x'|), x'' from second differences on the lines around them."""
    l1 = np.floor(row)
    f = np.array([scene.along_track_residual(ground, scene.scanline_time(l1 + k)) for k in (-1, 0, 1, 2)])
    d2 = np.maximum(np.abs(f[0] - 2 * f[1] + f[2]), np.abs(f[1] - 2 * f[2] + f[3]))
    return d2 / (8 * np.abs(f[2] - f[1]))


@cache
def fitted(name: str, preset: str, n_scops: int = 500, seed: int = 0):
    """Method ``name`` with ``seed`` fitted on ``n_scops`` SCOPs of :func:`scene_for` ``(preset)`` (cached)."""
    scene = scene_for(preset)
    return create(name, scene, seed=seed).fit(simulate_points(scene, n_scops, kind="scop"))


def edge_points(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image points around the image edges and their ground points: rows, cols (12,), ground (12, 3).

    0-5: beyond the search window [-1, rows] (-300, -5, -1.2, rows + 0.2, rows + 5, rows + 300);
    6-7: within the window, just outside the image (-0.7, rows - 0.3); 8-9: columns outside the image;
    10-11: just inside the image (-0.3, rows - 0.7).
    """
    n, m = scene.n_rows, scene.n_columns
    rows = np.array([-300.0, -5.0, -1.2, n + 0.2, n + 5.0, n + 300.0, -0.7, n - 0.3, 100.0, 100.0, -0.3, n - 0.7])
    cols = np.array([100.0] * 8 + [-50.0, m + 20.0, 100.0, 100.0])
    return rows, cols, scene.image_to_ground(rows, cols)


def check_affine_plus_correction(method, check: PointSet):
    """The two-stage learned methods (ann, ogp): trained, every point valid, sub-pixel RMSE and largest
    error, better than their affine stage alone, one collinearity evaluation per point (the column)."""
    res = method.ground_to_image(check.ground)
    assert method.fit_info["converged"] and res.valid.all()
    dr = res.row - check.row
    rmse, dr_max = np.sqrt(np.mean(dr**2)), np.max(np.abs(dr))
    assert rmse < 1.0 and dr_max < 1.0
    assert rmse < method.fit_info["affine_rmse_px"]
    assert np.all(res.ce_evaluations == 1)
    return res


def ce_counts(name: str, preset: str) -> tuple[int, np.ndarray]:
    """(setup CE, CE per point) of method ``name`` on the :func:`scps_for` check points of ``preset``."""
    method = create(name, scene_for(preset))
    res = method.ground_to_image(scps_for(preset).ground)
    return method.setup_ce, res.ce_evaluations


@contextmanager
def caller_at_two_blas_threads() -> Iterator[None]:
    """OpenBLAS set to two threads (the caller's setting: numpy's default on a 2-core machine) for the block, the
    previous setting restored after; skips the test without an OpenBLAS in this process or where it runs on one
    thread only."""
    import pytest

    from explorer import _threads

    api = _threads._openblas_api()
    if api is None or _threads.blas_thread_count() is None:
        pytest.skip("numpy's BLAS is not an OpenBLAS found in this process")
    before = api[1]()
    api[0](2)
    try:
        if _threads.blas_thread_count() != 2:
            pytest.skip("OpenBLAS runs on one thread here")
        yield
    finally:
        api[0](before)
