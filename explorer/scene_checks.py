"""What a physical pushbroom scene is: the checks every scene file passes when it is read.

A scene JSON that parses is not yet a sensor: a latitude of 95 degrees, a pixel pitch of 1e-300 m or a camera
below the ground give numbers that look normal and mean nothing.  :func:`check_scene_physics` refuses them at
read time (``Scene.load`` and ``explorer.real.load_scene`` call it) with a
:class:`~explorer.errors.SceneFileError` naming the file and the field.  The rules (``docs/validation.md``):

- the local frame's origin is on the body: latitude -90 .. 90, longitude -360 .. 360 degrees, height
  -12 km .. 100 km; the terrain's heights within :data:`TERRAIN_RANGE_M`;
- the camera is a camera: focal length :data:`FOCAL_LENGTH_RANGE_M`, detector pitch :data:`PITCH_RANGE_M`,
  principal column within ten image widths of the image, line period :data:`LINE_PERIOD_RANGE_S`;
- a rigorous scene's sensor-to-body matrix is a proper rotation (orthonormal, determinant +1, not a
  reflection), its quaternions unit quaternions, and its ephemeris and attitude tables cover the image time
  (lines past the tables would be extrapolated);
- the sensor is above the terrain at the first, middle and last line (at most :data:`MAX_SENSOR_HEIGHT_M`
  above the ellipsoid), and the lines of sight meet the terrain (image to ground is not NaN everywhere).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from explorer.errors import ExplorerError, SceneFileError

__all__ = [
    "FOCAL_LENGTH_RANGE_M",
    "LINE_PERIOD_RANGE_S",
    "LOWEST_SENSOR_HEIGHT_M",
    "MAX_SENSOR_HEIGHT_M",
    "PITCH_RANGE_M",
    "TERRAIN_RANGE_M",
    "check_orbit_tables",
    "check_scene_physics",
]

#: Focal lengths of real pushbroom cameras: a few millimetres (cubesats) to ~13 m (WorldView).
FOCAL_LENGTH_RANGE_M = (1e-3, 100.0)
#: Detector pitches: 0.1 um to 1 mm.
PITCH_RANGE_M = (1e-7, 1e-3)
#: Line periods: 0.1 us to 10 s.
LINE_PERIOD_RANGE_S = (1e-7, 10.0)
#: Heights a terrain may have (m): the deepest ocean trench to above Olympus Mons.
TERRAIN_RANGE_M = (-12_000.0, 30_000.0)
#: Lowest height of an Earth sensor's ephemeris above the WGS84 ellipsoid (the lowest dry land, the Dead Sea
#: shore, is about -0.4 km): an ephemeris lower than this is inside the Earth.
LOWEST_SENSOR_HEIGHT_M = -1000.0
#: Highest sensor above the ellipsoid (beyond the Moon's distance is no imaging orbit).
MAX_SENSOR_HEIGHT_M = 5e8


def _fail(source: str, what: str) -> SceneFileError:
    return SceneFileError(f"{source}: {what}")


def _in_range(source: str, name: str, value: float, low: float, high: float, unit: str) -> None:
    if not (np.isfinite(value) and low <= value <= high):
        raise _fail(source, f"{name} = {value:g} {unit} is outside {low:g} .. {high:g} {unit}: not a physical "
                            "sensor")


def _check_frame(scene: Any, source: str) -> None:
    frame = scene.frame
    _in_range(source, "frame.lat0_deg", float(frame.lat0_deg), -90.0, 90.0, "degrees")
    _in_range(source, "frame.lon0_deg", float(frame.lon0_deg), -360.0, 360.0, "degrees")
    _in_range(source, "frame.h0_m", float(frame.h0_m), -12_000.0, 100_000.0, "m")
    _in_range(source, "the terrain's lowest height", float(scene.terrain.min_height), *TERRAIN_RANGE_M, "m")
    _in_range(source, "the terrain's highest height", float(scene.terrain.max_height), *TERRAIN_RANGE_M, "m")


def _check_camera(scene: Any, source: str) -> None:
    io = scene.interior
    _in_range(source, "interior.focal_length_m", float(io.focal_length_m), *FOCAL_LENGTH_RANGE_M, "m")
    _in_range(source, "interior.detector_pitch_m", float(io.detector_pitch_m), *PITCH_RANGE_M, "m")
    n = float(io.n_columns)
    _in_range(source, "interior.principal_column", float(io.principal_column), -10 * n, 11 * n, "px")
    _in_range(source, "timing.line_period_s", float(scene.timing.line_period_s), *LINE_PERIOD_RANGE_S, "s")


def _check_rigorous_tables(scene: Any, source: str) -> None:
    """Sensor-to-body rotation proper, quaternions unit, tables covering the image time (rigorous scenes)."""
    exterior = scene.exterior
    matrix = getattr(exterior, "sensor_to_body", None)
    if matrix is not None:
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape != (3, 3) or not np.all(np.isfinite(m)):
            raise _fail(source, "exterior.sensor_to_body is not a finite 3 x 3 matrix")
        if not np.allclose(m @ m.T, np.eye(3), atol=1e-6):
            raise _fail(source, "exterior.sensor_to_body is not a rotation (its rows are not orthonormal)")
        if np.linalg.det(m) < 0:
            raise _fail(source, "exterior.sensor_to_body is a reflection (determinant -1), not a proper rotation")
    attitude = getattr(exterior, "attitude", None)
    q = getattr(attitude, "quaternion", None)
    if q is not None:
        norms = np.linalg.norm(np.asarray(q, dtype=np.float64), axis=-1)
        if not np.all(np.abs(norms - 1.0) < 1e-3):
            k = int(np.argmax(np.abs(norms - 1.0)))
            raise _fail(source, f"exterior.attitude quaternion {k} has norm {norms[k]:.6g}: not a rotation")
    t0, t1 = (float(v) for v in scene.scanline_time(np.array([0.0, scene.n_rows - 1.0])))
    lo, hi = min(t0, t1), max(t0, t1)
    slack = 0.5 * abs(float(scene.timing.line_period_s))
    for name in ("ephemeris", "attitude"):
        table = getattr(exterior, name, None)
        times = getattr(table, "time_s", None)
        if times is None:
            continue
        times = np.asarray(times, dtype=np.float64)
        if times.size == 0:
            raise _fail(source, f"exterior.{name} is empty")
        if times.min() > lo + slack or times.max() < hi - slack:
            raise _fail(source, f"exterior.{name} covers {times.min():.6g} .. {times.max():.6g} s but the image "
                                f"is taken over {lo:.6g} .. {hi:.6g} s: its lines past the table would be "
                                "extrapolated")


def _check_above_terrain(scene: Any, source: str) -> None:
    rows = np.array([0.0, 0.5 * (scene.n_rows - 1), scene.n_rows - 1.0])
    with np.errstate(all="ignore"):
        centres = np.asarray(scene.exterior.position(scene.scanline_time(rows)), dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(centres)):
        raise _fail(source, "the perspective centre is not finite at the first, middle or last line")
    _, _, height = scene.frame.enu_to_geodetic(centres)
    height = np.atleast_1d(np.asarray(height, dtype=np.float64))
    top = float(scene.terrain.max_height)
    k = int(np.argmin(height))
    if not height[k] > top:
        raise _fail(source, f"the sensor is {height[k]:.1f} m above the ellipsoid at line {rows[k]:g}, not above "
                            f"the terrain (up to {top:.1f} m): below the ground a camera sees nothing")
    k = int(np.argmax(height))
    limit = max_sensor_height_m(scene.frame.body)
    if height[k] > limit:
        raise _fail(source, f"the sensor is {height[k]:.3g} m above the ellipsoid at line {rows[k]:g}: beyond "
                            f"{limit:g} m no camera images the ground")
    cols = np.array([0.5 * (scene.interior.n_columns - 1), 0.0, scene.interior.n_columns - 1.0])
    rr, cc = (g.ravel() for g in np.meshgrid(rows, cols, indexing="ij"))
    try:
        with np.errstate(all="ignore"):
            ground = np.asarray(scene.image_to_ground(rr, cc), dtype=np.float64)
    except ExplorerError:
        ground = np.full((rr.size, 3), np.nan)
    if not np.any(np.all(np.isfinite(ground), axis=1)):
        raise _fail(source, "no line of sight (image centre and corners, first/middle/last line) meets the "
                            "terrain: the camera does not look at the ground")


def max_sensor_height_m(body: Any) -> float:
    """:data:`MAX_SENSOR_HEIGHT_M` for the Earth, scaled by the body's equatorial radius for a larger one: a camera
    images a disc of the body from a distance in proportion to its size (New Horizons MVIC saw Jupiter, 11 Earth
    radii, from 2.3e9 m)."""
    a = float(getattr(body, "a_m", 0.0) or 0.0)
    return MAX_SENSOR_HEIGHT_M * max(1.0, a / 6378137.0)


def check_orbit_tables(source: str, positions: Any, quaternions: Any = None) -> None:
    """Refuse an ephemeris inside the Earth or beyond :data:`MAX_SENSOR_HEIGHT_M`, and non-unit attitude quaternions.

    Called by the rigorous metadata readers (DIMAP, DigitalGlobe) before anything is fitted to the tables, so
    that the message names the table instead of a failure further on.

    Parameters
    ----------
    source : str
        The file, for the messages.
    positions : array_like, shape (N, 3)
        Earth-fixed (ECEF) sensor positions, metres.
    quaternions : array_like, shape (M, 4), optional
        Attitude quaternions (any component order).

    Raises
    ------
    SceneFileError
        Naming the file, the table and the point.
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if p.shape[0] == 0:
        raise _fail(source, "the ephemeris table is empty")
    if not np.all(np.isfinite(p)):
        k = int(np.argmin(np.all(np.isfinite(p), axis=1)))
        raise _fail(source, f"ephemeris point {k} is not finite")
    from explorer.geometry.frames import ecef_to_geodetic

    _, _, h = ecef_to_geodetic(p)
    h = np.atleast_1d(np.asarray(h, dtype=np.float64))
    k = int(np.argmin(h))
    if h[k] < LOWEST_SENSOR_HEIGHT_M:
        raise _fail(source, f"ephemeris point {k} is {-h[k] / 1000:.6g} km below the WGS84 ellipsoid: inside the "
                            "Earth (positions must be Earth-fixed metres of a sensor above the ground)")
    k = int(np.argmax(h))
    if h[k] > MAX_SENSOR_HEIGHT_M:
        raise _fail(source, f"ephemeris point {k} is {h[k] / 1000:.6g} km above the WGS84 ellipsoid: beyond "
                            f"{MAX_SENSOR_HEIGHT_M:g} m no camera images the ground")
    if quaternions is not None:
        q = np.asarray(quaternions, dtype=np.float64).reshape(-1, 4)
        norms = np.linalg.norm(q, axis=1)
        bad = ~(np.abs(norms - 1.0) < 1e-3)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise _fail(source, f"attitude quaternion {k} has norm {norms[k]:.6g}: not a rotation")


def check_scene_physics(scene: Any, source: str) -> None:
    """Refuse a scene that no physical sensor can be (rules in the module docstring).

    Parameters
    ----------
    scene : Scene or RigorousLineScanScene
        The scene as read.
    source : str
        The file name, for the messages.

    Raises
    ------
    SceneFileError
        Naming ``source``, the field and the rule it breaks.
    """
    try:
        _check_frame(scene, source)
        _check_camera(scene, source)
        _check_rigorous_tables(scene, source)
        _check_above_terrain(scene, source)
    except ExplorerError:
        raise
    except (ArithmeticError, ValueError, TypeError, IndexError, AttributeError, np.linalg.LinAlgError) as exc:
        raise _fail(source, f"the scene's geometry cannot be evaluated ({type(exc).__name__}: {exc})") from None
