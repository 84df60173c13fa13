"""What the explorer shows of a stereo pair, as numbers (numpy only; the 3D scene and the panels draw them):
both images' trajectories and footprints, and for a selected left pixel its two lines of sight meeting on the
ground and its epipolar curve in the right image.  Everything is expressed in the **left sensor's local ENU
frame** (metres): the right image's geometry is carried over through body-fixed coordinates.

The exact sensors compute (localisation, projection, the curve); the trajectories come from the display
scenes (for an RPC: the MPC scene fitted by resection, as ``pushbroom explore --rpc`` shows), since an RPC has
no orbit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from explorer.errors import InputError
from explorer.scene import Scene
from explorer.sensor import Sensor
from explorer.stereo.epipolar import EpipolarCurve, epipolar_curve
from explorer.stereo.sensors import as_sensor, check_same_body, localise, mean_height, project, rpc_model
from explorer.stereo.triangulation import Triangulation, triangulate

#: Heights either side of the pair's height that the selected pixel's curve spans (metres).
CURVE_HALF_SPAN_M = 500.0


@dataclass
class PairView:
    """A pair for display.

    Attributes
    ----------
    left, right : Sensor
        The exact models.
    left_scene, right_scene : Scene or None
        Scenes with an orbit for the trajectories (None: no trajectory shown).
    height : float
        Ellipsoidal height of the footprints and of a selection without DEM, metres.
    dem : object or None
        DEM (ellipsoidal heights) under the selected pixel (RPC left image).
    """

    left: Sensor
    right: Sensor
    left_scene: Scene | None = None
    right_scene: Scene | None = None
    height: float = 0.0
    dem: Any = None

    def to_left(self, sensor: Sensor, enu: np.ndarray) -> np.ndarray:
        """Points (N, 3) in ``sensor``'s local ENU -> the left sensor's local ENU."""
        return self.left.frame.ecef_to_enu(sensor.frame.enu_to_ecef(np.asarray(enu, dtype=np.float64)))

    def ecef_to_left(self, ecef: np.ndarray) -> np.ndarray:
        return self.left.frame.ecef_to_enu(np.asarray(ecef, dtype=np.float64))


@dataclass(frozen=True)
class PairSelection:
    """A selected left pixel, in the left sensor's ENU metres.

    Attributes
    ----------
    left_pixel, right_pixel : (float, float)
        (row, col); the right one is where the right image sees the ground point.
    ground : ndarray, shape (3,)
    height : float
        Its ellipsoidal height, metres.
    left_centre, right_centre : ndarray (3,) or None
        Perspective centres of the two pixels' scanlines (display scenes).
    curve : EpipolarCurve
        The left pixel's curve in the right image over ``height +- CURVE_HALF_SPAN_M``.
    check : Triangulation
        The two pixels triangulated back (ray distance, reprojection).
    """

    left_pixel: tuple[float, float]
    right_pixel: tuple[float, float]
    ground: np.ndarray
    height: float
    left_centre: np.ndarray | None
    right_centre: np.ndarray | None
    curve: EpipolarCurve
    check: Triangulation


def pair_view(left: Any, right: Any, *, left_scene: Scene | None = None, right_scene: Scene | None = None,
              height: float | None = None, dem: Any = None) -> PairView:
    """Bundle a pair for display (sensors checked to be on one body)."""
    left_s, right_s = as_sensor(left, "left"), as_sensor(right, "right")
    check_same_body(left_s, right_s)
    h = 0.5 * (mean_height(left_s) + mean_height(right_s)) if height is None else float(height)
    if dem is not None and rpc_model(left_s) is None:
        raise InputError("a DEM under the selected pixel needs an RPC left image")
    return PairView(left_s, right_s, left_scene, right_scene, h, dem)


def footprint_outlines(view: PairView, per_edge: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Both images' borders at the pair's height as closed polylines (4 per_edge + 1, 3), left ENU metres."""
    out = []
    for sensor in (view.left, view.right):
        r1, c1 = sensor.n_rows - 0.5, sensor.n_columns - 0.5
        s = np.linspace(0.0, 1.0, per_edge, endpoint=False)
        rows = np.concatenate([np.full_like(s, -0.5), -0.5 + s * sensor.n_rows, np.full_like(s, r1),
                               r1 - s * sensor.n_rows, [-0.5]])
        cols = np.concatenate([-0.5 + s * sensor.n_columns, np.full_like(s, c1), c1 - s * sensor.n_columns,
                               np.full_like(s, -0.5), [-0.5]])
        ecef, _ = localise(sensor, rows, cols, np.full(rows.size, view.height))
        out.append(view.ecef_to_left(ecef))
    return out[0], out[1]


def trajectories(view: PairView, n: int = 32) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Perspective centres (n, 3) over each image's rows, left ENU metres (None without a display scene)."""
    out: list[np.ndarray | None] = []
    for scene in (view.left_scene, view.right_scene):
        if scene is None:
            out.append(None)
            continue
        rows = np.linspace(-0.5, scene.n_rows - 0.5, n)
        out.append(view.to_left(scene, scene.exterior.position(scene.scanline_time(rows))))
    return out[0], out[1]


def select(view: PairView, row: float, col: float) -> PairSelection:
    """The selected left pixel's ground point (on the DEM, else at the pair's height), the right pixel seeing it,
    both perspective centres, its epipolar curve and the triangulation of the two pixels.

    Raises
    ------
    InputError
        The pixel is outside the left image, or its line of sight does not reach the ground.
    """
    row, col = float(row), float(col)
    if not (-0.5 <= row <= view.left.n_rows - 0.5 and -0.5 <= col <= view.left.n_columns - 0.5):
        raise InputError(f"pixel ({row:g}, {col:g}) is outside the left image "
                         f"({view.left.n_rows} x {view.left.n_columns})")
    h = view.height
    if view.dem is not None:
        from explorer.rpc.dem import localization_on_dem

        model = rpc_model(view.left)
        assert model is not None
        _, _, hh, ok = localization_on_dem(model, np.array([row]), np.array([col]), view.dem)
        if not ok[0]:
            raise InputError(f"the line of sight of pixel ({row:g}, {col:g}) does not meet the DEM")
        h = float(hh[0])
    ecef, ok = localise(view.left, np.array([row]), np.array([col]), np.array([h]))
    if not ok[0]:
        raise InputError(f"pixel ({row:g}, {col:g}) does not localise at {h:g} m")
    r_row, r_col = project(view.right, ecef)
    curve = epipolar_curve(view.left, view.right, row, col,
                           np.linspace(h - CURVE_HALF_SPAN_M, h + CURVE_HALF_SPAN_M, 21))
    check = triangulate(view.left, view.right, [row], [col], r_row, r_col)
    centres: list[np.ndarray | None] = []
    for scene, rr in ((view.left_scene, row), (view.right_scene, float(r_row[0]))):
        if scene is None or not np.isfinite(rr):
            centres.append(None)
            continue
        centres.append(view.to_left(scene, scene.exterior.position(scene.scanline_time(np.array([rr]))))[0])
    return PairSelection((row, col), (float(r_row[0]), float(r_col[0])), view.ecef_to_left(ecef)[0], h,
                         centres[0], centres[1], curve, check)


__all__ = ["CURVE_HALF_SPAN_M", "PairSelection", "PairView", "footprint_outlines", "pair_view", "select",
           "trajectories"]
