"""An MPC :class:`~explorer.scene.Scene` fitted to any :class:`~explorer.sensor.Sensor` by space resection.

The sensor is used only through its interface: lines of sight of an image grid (two
:meth:`~explorer.sensor.Sensor.image_to_ground` heights) give closed-form initial values
(:func:`explorer.real.resection.mpc_from_lines_of_sight`), ground points it localises on ``layers``
height planes are the control points of the resection (:func:`explorer.real.resection.resect`,
focal length and exterior free), and an offset grid at random heights gives independent check points.
This is how a rigorous line-scan model becomes an MPC scene the methods can run on (Ahooei Nezhad et
al., "Best Scanline Determination of Pushbroom Images for a Direct Object to Image Space
Transformation Using Multilayer Perceptron", Remote Sensing 2024, Sec. 2.1-2.3: MPC by resection).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from explorer.geometry.exterior import LineTiming
from explorer.geometry.terrain import FlatTerrain, Terrain
from explorer.real.from_rpc import _grid as image_grid  # same package (real)
from explorer.real.resection import ResectionReport, image_residuals, mpc_from_lines_of_sight, resect
from explorer.scene import Scene
from explorer.sensor import Sensor


def mpc_scene_from_sensor(
    sensor: Sensor,
    *,
    height_range: tuple[float, float],
    degree: int = 3,
    n: int = 200,
    layers: int = 3,
    n_check: int = 400,
    seed: int = 0,
    focal_length_m: float | None = None,
    timing: LineTiming | None = None,
    terrain: Terrain | None = None,
    metadata: dict | None = None,
) -> tuple[Scene, ResectionReport]:
    """Fit an MPC scene to a sensor model.

    Parameters
    ----------
    sensor : Sensor
    height_range : (float, float)
        Lowest and highest ground height (local Z, metres) of the control and check points.
    degree : int
        Degree of the MPC polynomials.
    n : int
        About ``n`` image points per height layer (a regular grid spanning the image).
    layers : int
        Height layers of the control points over ``height_range``.
    n_check : int
        About this many check points (cell-centred grid, seeded random heights); 0 to skip.
    seed : int
        Seed of the check-point heights.
    focal_length_m : float, optional
        Initial focal length (estimated by the resection either way).
    timing : LineTiming, optional
        Scanline timing of the result; default: linear over :meth:`Sensor.time_range`.
    terrain : Terrain, optional
        Terrain of the result (default: flat at the middle of ``height_range``).
    metadata : dict, optional
        Entries added to the result's metadata (with ``mpc_fit``, the report).

    Returns
    -------
    scene : Scene
        Same frame, timing, image size.
    report : ResectionReport
        Control and check-point residuals (pixels, sensor vs fitted scene).
    """
    lo, hi = (float(v) for v in height_range)
    n_rows, n_cols = int(sensor.n_rows), int(sensor.n_columns)
    if timing is None:
        t0, t1 = sensor.time_range()
        period = (t1 - t0) / n_rows
        timing = LineTiming(period, -0.5 - t0 / period)
    terrain = FlatTerrain(0.5 * (lo + hi)) if terrain is None else terrain
    rows = np.linspace(0.0, n_rows - 1.0, 11)
    cols = np.linspace(0.0, n_cols - 1.0, 9)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    low = sensor.image_to_ground(rr.ravel(), cc.ravel(), height=lo).reshape(rr.shape + (3,))
    high = sensor.image_to_ground(rr.ravel(), cc.ravel(), height=hi).reshape(rr.shape + (3,))
    s0, _ = mpc_from_lines_of_sight(
        rows, cols, low, high, n_rows=n_rows, n_columns=n_cols, frame=sensor.frame,
        degree=degree, focal_length_m=focal_length_m,
        line_period_s=timing.line_period_s, terrain=terrain, name=sensor.name,
    )  # fmt: skip
    s0 = replace(s0, timing=timing, metadata={})
    g_row, g_col = image_grid(n, n_rows, n_cols, offset=False)
    heights = np.linspace(lo, hi, max(layers, 1))
    r3 = np.tile(g_row, heights.size)
    c3 = np.tile(g_col, heights.size)
    ground = sensor.image_to_ground(r3, c3, height=np.repeat(heights, g_row.size))
    mpc, report = resect(s0, r3, c3, ground, degree=degree, estimate_focal=True)
    if n_check:
        k_row, k_col = image_grid(n_check, n_rows, n_cols, offset=True)
        hk = np.random.default_rng(seed).uniform(lo, hi, k_row.size)
        gk = sensor.image_to_ground(k_row, k_col, height=hk)
        report = report.with_check(*image_residuals(mpc, gk, k_row, k_col))
    report.info.update({"height_range_m": [lo, hi]})
    mpc = Scene(sensor.name, mpc.interior, mpc.exterior, timing, n_rows, terrain, sensor.frame,
                {**(metadata or {}), "mpc_fit": report.to_dict()})
    return mpc, report


__all__ = ["mpc_scene_from_sensor"]
