"""The two images of a pair as :class:`explorer.sensor.Sensor` objects, and what stereo needs from each:
lines of sight, localisation at an ellipsoidal height and projection of body-fixed (ECEF) points.

Each sensor has its own local ENU ``frame`` (``docs/conventions.md#frames``); two images of a pair never share
one, so everything between them goes through body-fixed Cartesian coordinates (ECEF, metres).  Heights
given here are **ellipsoidal** (above the body's ellipsoid), as in an RPC and in stereo tools, not the local
``Z`` of a frame.

An RPC model (what :func:`explorer.read_rpc` returns) is wrapped in :class:`explorer.rpc.sensor.RPCSensor`; for
RPC sensors localisation is the compiled exact Newton inverse of the projection (1e-7 px), never the vendor's
approximate inverse polynomials.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from explorer.errors import InputError
from explorer.rpc.model import RationalFunctionModel
from explorer.rpc.sensor import RPCSensor
from explorer.scene import Scene
from explorer.sensor import Sensor, has_line_geometry
from explorer.stereo import _kernels

#: Newton iterations of the compiled RPC localisation at most.
RPC_MAX_ITER = 50
#: Fixed-point steps from a local ``Z`` plane to an ellipsoidal height (generic sensors) at most, and the stop (m).
HEIGHT_ITERATIONS = 12
HEIGHT_TOL_M = 1e-7


def as_sensor(obj: Any, name: str = "sensor") -> Sensor:
    """A :class:`Sensor` for ``obj``: a sensor as it is, an RPC model wrapped in :class:`RPCSensor`.

    Raises
    ------
    InputError
        ``obj`` is neither (the message names the argument and its type).
    """
    if isinstance(obj, RationalFunctionModel):
        return RPCSensor(obj, name=name)
    if isinstance(obj, Sensor):
        return obj
    raise InputError(f"{name} must be a Sensor or an RPC model (explorer.read_rpc), got {type(obj).__name__}")


def rpc_model(sensor: Sensor) -> RationalFunctionModel | None:
    """The RPC behind ``sensor`` when it is an :class:`RPCSensor`, else None."""
    return sensor.rpc if isinstance(sensor, RPCSensor) else None


def rpc_arrays(model: RationalFunctionModel) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients (4, 20) and normalisation (10,) of an RPC as the compiled kernels take them."""
    coef = np.ascontiguousarray(np.stack([model.row_num, model.row_den, model.col_num, model.col_den]))
    norm = np.array([model.lon_offset, model.lon_scale, model.lat_offset, model.lat_scale, model.height_offset,
                     model.height_scale, model.row_offset, model.row_scale, model.col_offset, model.col_scale])
    return coef, norm


def geodetic_to_ecef(sensor: Sensor, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Geodetic coordinates on the sensor's body (degrees, metres above the ellipsoid) -> ECEF (N, 3)."""
    frame = sensor.frame
    enu = frame.geodetic_to_enu(np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64),
                                np.asarray(h, dtype=np.float64))
    return frame.enu_to_ecef(enu)


def ecef_to_geodetic(sensor: Sensor, ecef: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ECEF (N, 3) -> (lon_deg, lat_deg, h_m) on the sensor's body."""
    frame = sensor.frame
    return frame.enu_to_geodetic(frame.ecef_to_enu(np.asarray(ecef, dtype=np.float64)))


def mean_height(sensor: Sensor) -> float:
    """A height inside the sensor's scene (ellipsoidal metres): the RPC's height offset, a scene's mean terrain
    height, else the frame origin's height."""
    model = rpc_model(sensor)
    if model is not None:
        return float(model.height_offset)
    if isinstance(sensor, Scene):
        return float(sensor.terrain.mean_height) + float(sensor.frame.h0_m)
    return float(sensor.frame.h0_m)


def localise(sensor: Sensor, row: np.ndarray, col: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image points (N,) at ellipsoidal heights (N,) -> ECEF (N, 3) and ok (N,).

    RPC: the compiled exact inverse of the projection.  Other sensors: ``image_to_ground`` on the local plane
    ``Z`` whose point has the asked ellipsoidal height, found by fixed-point steps on ``Z`` (converges to
    :data:`HEIGHT_TOL_M`; ``dh/dZ`` is the cosine between the local and the ellipsoid normals).
    """
    row, col, h = (np.ascontiguousarray(a, dtype=np.float64).ravel() for a in np.broadcast_arrays(row, col, h))
    model = rpc_model(sensor)
    if model is not None:
        coef, norm = rpc_arrays(model)
        lon, lat, ok = _kernels.rpc_localise(coef, norm, row, col, h, RPC_MAX_ITER)
        xyz = geodetic_to_ecef(sensor, lon, lat, h)
        return xyz, ok & np.isfinite(xyz[:, 0])
    frame = sensor.frame
    z = h - frame.h0_m
    enu = np.full((row.size, 3), np.nan)
    for _ in range(HEIGHT_ITERATIONS):
        enu = sensor.image_to_ground(row, col, height=z)
        _, _, h_now = frame.enu_to_geodetic(enu)
        dz = np.where(np.isfinite(h_now), h - h_now, 0.0)
        z = z + dz
        if not np.max(np.abs(dz), initial=0.0) > HEIGHT_TOL_M:
            break
    enu = sensor.image_to_ground(row, col, height=z)
    ecef = frame.enu_to_ecef(enu)
    _, _, h_now = frame.enu_to_geodetic(enu)
    ok = np.isfinite(ecef[:, 0]) & (np.abs(h_now - h) <= 10 * HEIGHT_TOL_M)
    return ecef, ok


def localise_geodetic(sensor: Sensor, row: np.ndarray, col: np.ndarray, h: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`localise` as (lon_deg, lat_deg, ok) on the sensor's body (RPC: no Cartesian round trip); NaN where
    not ok."""
    row, col, h = (np.ascontiguousarray(a, dtype=np.float64).ravel() for a in np.broadcast_arrays(row, col, h))
    model = rpc_model(sensor)
    if model is not None:
        coef, norm = rpc_arrays(model)
        return _kernels.rpc_localise(coef, norm, row, col, h, RPC_MAX_ITER)
    ecef, ok = localise(sensor, row, col, h)
    lon, lat, _ = ecef_to_geodetic(sensor, ecef)
    return np.where(ok, lon, np.nan), np.where(ok, lat, np.nan), ok


def project_geodetic(sensor: Sensor, lon: np.ndarray, lat: np.ndarray, h: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project` of geodetic points (degrees, ellipsoidal metres; NaN in, NaN out): the sensor's geodetic
    entry (:meth:`explorer.sensor.Sensor.geodetic_to_image`), which converts them only into the coordinates its
    model is defined on (none for an RPC)."""
    lon, lat, h = (np.asarray(a, dtype=np.float64).ravel() for a in np.broadcast_arrays(lon, lat, h))
    ok = np.isfinite(lon) & np.isfinite(lat) & np.isfinite(h)
    out = np.full((2, lon.size), np.nan)
    if ok.any():
        out[0, ok], out[1, ok] = sensor.geodetic_to_image(lon[ok], lat[ok], h[ok])
    return out[0], out[1]


def project(sensor: Sensor, ecef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ECEF points (N, 3) -> (row, col) in the sensor's image (NaN where the model has no image point)."""
    ecef = np.asarray(ecef, dtype=np.float64)
    model = rpc_model(sensor)
    if model is not None:
        lon, lat, h = ecef_to_geodetic(sensor, ecef)
        out = np.full((2, ecef.shape[0]), np.nan)
        ok = np.isfinite(lon) & np.isfinite(lat) & np.isfinite(h)
        if ok.any():
            out[0, ok], out[1, ok] = model.projection(lon[ok], lat[ok], h[ok])
        return out[0], out[1]
    enu = sensor.frame.ecef_to_enu(ecef)
    out = np.full((2, ecef.shape[0]), np.nan)
    ok = np.isfinite(enu).all(axis=1)
    if ok.any():
        out[0, ok], out[1, ok] = sensor.ground_to_image(enu[ok])
    return out[0], out[1]


def inside_image(sensor: Sensor, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """True where (row, col) is on the image (``docs/conventions.md#pixels``: pixel edges included)."""
    row = np.asarray(row, dtype=np.float64)
    col = np.asarray(col, dtype=np.float64)
    return (row >= -0.5) & (row <= sensor.n_rows - 0.5) & (col >= -0.5) & (col <= sensor.n_columns - 0.5)


def perspective_centres(sensor: Sensor, row: np.ndarray, col: np.ndarray) -> np.ndarray | None:
    """Perspective centres (N, 3) ECEF of image points where the sensor declares line geometry
    (:func:`explorer.sensor.has_line_geometry`: MPC, rigorous line-scan, CSM), else None (an RPC has no sensor
    position)."""
    if not has_line_geometry(sensor):
        return None
    line_sensor: Any = sensor
    centres = line_sensor.perspective_centre(line_sensor.line_time(np.asarray(row, dtype=np.float64)))
    return sensor.frame.enu_to_ecef(np.asarray(centres, dtype=np.float64))


def check_same_body(left: Sensor, right: Sensor) -> None:
    """Raise :class:`InputError` when the two sensors' frames are on different bodies."""
    body_l = getattr(left.frame, "body", None)
    body_r = getattr(right.frame, "body", None)
    if body_l != body_r:
        raise InputError(f"the two images are on different bodies ({body_l} and {body_r})")


__all__ = ["as_sensor", "check_same_body", "ecef_to_geodetic", "geodetic_to_ecef", "inside_image", "localise",
           "localise_geodetic", "mean_height", "perspective_centres", "project", "project_geodetic", "rpc_arrays",
           "rpc_model"]
