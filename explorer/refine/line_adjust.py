"""Adjusted rigorous (DIMAP/DG) and CSM line scanners: the corrections of :mod:`explorer.refine.line_corrections`
applied to their tables, the trajectories before and after, and the sidecar JSON that carries an adjustment.

- :func:`correction_for` -- the :class:`~explorer.refine.line_corrections.LineCorrection` of a sensor (its
  reference time, orbital frame, default jitter frequencies);
- :func:`adjusted_sensor` -- a :class:`~explorer.real.linescan.RigorousLineScanScene` or
  :class:`~explorer.real.csm_sensor.CsmScene` whose position and attitude samples carry the correction (the
  same class, the same compiled ground to image; the same frame as the base sensor);
- :func:`trajectories` -- perspective centres and attitudes of the original and the adjusted sensor along the
  line time (for the 3D scene);
- :func:`sidecar_dict` / :func:`apply_sidecar` / :func:`load_adjusted` -- the adjusted model as a JSON sidecar
  (the parameters, their sigmas, the correction's definition, the base file's name and SHA-256) and back.
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from explorer.errors import InputError, SceneFileError
from explorer.refine.line_corrections import (
    LineCorrection,
    file_sha256,
    orbital_axes,
    quaternion_multiply,
)

__all__ = ["SIDECAR_FORMAT", "adjusted_sensor", "apply_sidecar", "correction_for", "is_line_scanner",
           "load_adjusted", "read_sidecar", "sidecar_dict", "trajectories", "write_sidecar"]

SIDECAR_FORMAT = "pushbroom-explorer adjusted line scanner v1"


def _kind(sensor: Any) -> str:
    from explorer.real.csm_sensor import CsmScene
    from explorer.real.linescan import RigorousLineScanScene

    if isinstance(sensor, CsmScene):
        return "csm"
    if isinstance(sensor, RigorousLineScanScene):
        return "rigorous"
    raise InputError(f"cannot apply a line-scanner correction to a {type(sensor).__name__}: a rigorous DIMAP/DG "
                     "model or a CSM camera is needed")


def is_line_scanner(sensor: Any) -> bool:
    """True for the sensors :func:`adjusted_sensor` adjusts (rigorous DIMAP/DG models, CSM cameras)."""
    try:
        _kind(sensor)
    except InputError:
        return False
    return True


def correction_for(sensor: Any, model: str, frequencies_hz: tuple[float, ...] | None = None) -> LineCorrection:
    """The correction ``model`` of ``sensor``: reference time the middle of its exposure, orbital axes from its
    own trajectory there, jitter frequencies ``1/T, 2/T`` (``T`` the exposure time) unless stated."""
    kind = _kind(sensor)
    t0, t1 = sensor.time_range()
    t_ref = 0.5 * (t0 + t1)
    if kind == "rigorous":
        eph = sensor.exterior.ephemeris
        axes = orbital_axes(eph.position(np.array([t_ref]))[0], eph.velocity(np.array([t_ref]))[0])
        attitude_times = sensor.exterior.attitude.time_s
    else:
        from explorer.real.linescan import lagrange_interpolate

        cam = sensor.camera
        p = lagrange_interpolate(cam.position_times, cam.positions_m, np.array([t_ref - 0.5, t_ref, t_ref + 0.5]),
                                 min(8, cam.position_times.size))
        axes = orbital_axes(p[1], p[2] - p[0])
        attitude_times = cam.pointing_times
    if model == "jitter" and not frequencies_hz:
        frequencies_hz = (1.0 / (t1 - t0), 2.0 / (t1 - t0))
    corr = LineCorrection(model, float(t_ref), axes, tuple(frequencies_hz or ()))
    corr.check_sampling(np.asarray(attitude_times), "sensor's")
    return corr


def adjusted_sensor(sensor: Any, correction: LineCorrection, params: np.ndarray, *, reuse_setup: bool = False) -> Any:
    """The sensor with its position and attitude samples corrected (same class and frame).

    ``reuse_setup`` (CSM cameras; what the adjustment's iterations use): the adjusted camera keeps the base camera's
    seed polynomial and solver constants instead of measuring its own (0.1-0.5 s per camera); its lines are solved
    from the same kind of start to the same tolerance (the differentiable model's Newton step then takes them to
    the root); without it (default) the adjusted camera is set up as a camera read from a file."""
    p = np.asarray(params, dtype=np.float64).reshape(-1)
    if p.size != correction.n_parameters:
        raise InputError(f"the {correction.model} correction has {correction.n_parameters} parameters, got {p.size}")
    if not np.isfinite(p).all():
        raise InputError("correction parameters contain NaN or infinite values")
    t_ref = correction.reference_time_s
    if _kind(sensor) == "rigorous":
        ext = sensor.exterior
        eph, att = ext.ephemeris, ext.attitude
        pos, vel = eph.position_m, eph.velocity_m_s
        if correction.has_position:
            pos = pos + correction.position_offset(eph.time_s - t_ref, p)
            vel = vel + (correction.position_offset(eph.time_s - t_ref + 1.0, p)
                         - correction.position_offset(eph.time_s - t_ref, p))
        dq = correction.rotation_quaternion(att.time_s - t_ref, p, ext.sensor_to_body)
        q = quaternion_multiply(att.quaternion, dq)
        new_ext = replace(ext, ephemeris=replace(eph, position_m=pos, velocity_m_s=vel),
                          attitude=replace(att, quaternion=q))
        return replace(sensor, exterior=new_ext)
    cam = sensor.camera
    pos = cam.positions_m
    if correction.has_position:
        pos = pos + correction.position_offset(cam.position_times - t_ref, p)
    dq = correction.rotation_quaternion(cam.pointing_times - t_ref, p, cam.pointing_constant.T, inverse=True)
    q = quaternion_multiply(dq, cam.pointing_quaternions)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    if reuse_setup:  # a copy with the corrected tables and the base camera's seed and solver constants
        new_cam = copy.copy(cam)
        new_cam.positions_m = np.ascontiguousarray(pos)
        new_cam.pointing_quaternions = np.ascontiguousarray(q)
        new_cam._cam = cam._cam.copy()
        new_cam._ext = None
    else:
        new_cam = replace(cam, positions_m=np.ascontiguousarray(pos), pointing_quaternions=np.ascontiguousarray(q))
    return replace(sensor, camera=new_cam, exterior=replace(sensor.exterior, camera=new_cam))


def trajectories(sensor: Any, correction: LineCorrection, params: np.ndarray, n: int = 50) -> dict[str, np.ndarray]:
    """Original and adjusted perspective centres and attitudes along the image's line time.

    Returns
    -------
    dict
        ``time_s`` (n,) on the sensor's clock; ``centre_original``, ``centre_adjusted`` (n, 3) local ENU metres of
        ``sensor.frame``; ``attitude_original``, ``attitude_adjusted`` (n, 3, 3) sensor -> local ENU rotations;
        ``roll_pitch_yaw`` (n, 3) radians, the correction's angles at those times.
    """
    t0, t1 = sensor.time_range()
    t = np.linspace(t0, t1, int(n))
    adjusted = adjusted_sensor(sensor, correction, params)
    angles = correction.angles(t - correction.reference_time_s, np.asarray(params, dtype=np.float64))
    return {"time_s": t,
            "centre_original": sensor.perspective_centre(t), "centre_adjusted": adjusted.perspective_centre(t),
            "attitude_original": sensor.attitude(t), "attitude_adjusted": adjusted.attitude(t),
            "roll_pitch_yaw": np.stack(angles, axis=1)}


# ------------------------------------------------------------------------------ sidecar
def sidecar_dict(correction: LineCorrection, params: np.ndarray, sigmas: np.ndarray | None, *,
                 base_file: str | Path | None, source_kind: str) -> dict[str, Any]:
    """The sidecar of an adjusted line scanner (JSON-ready); ``base_file`` None (a sensor built in memory) leaves
    the base file's name and hash empty (:func:`load_adjusted` then needs the base given)."""
    p = np.asarray(params, dtype=np.float64).reshape(-1)
    s = np.full(p.size, math.nan) if sigmas is None else np.asarray(sigmas, dtype=np.float64).reshape(-1)
    base = None if base_file is None else Path(base_file)
    out: dict[str, Any] = {
        "format": SIDECAR_FORMAT,
        "source_kind": source_kind,
        "base_file": None if base is None else base.name,
        "base_sha256": None if base is None else file_sha256(base),
        "correction": correction.to_dict(),
        "parameters": [{"name": n, "value": float(v), "sigma": None if not math.isfinite(float(e)) else float(e)}
                       for n, v, e in zip(correction.parameter_names, p, s, strict=True)],
        "conventions": ("position offsets in the orbital frame at reference_time_s (columns along, cross, radial "
                        "in the position table's frame), metres and m/s; attitude R_x(roll) R_y(pitch) R_z(yaw) "
                        "about the sensor axes, applied on the sensor side, radians and rad/s; corrections applied "
                        "to the table samples (explorer.refine.line_corrections)"),
    }
    if correction.frequencies_hz:
        out["harmonics"] = correction.harmonics(p)
    return out


def apply_sidecar(sensor: Any, sidecar: dict[str, Any], source: str = "<sidecar>") -> Any:
    """The adjusted sensor of a sidecar dict applied to its (already loaded) base sensor."""
    if not isinstance(sidecar, dict) or sidecar.get("format") != SIDECAR_FORMAT:
        raise SceneFileError(f"{source}: not an adjusted line-scanner sidecar (format {SIDECAR_FORMAT!r})")
    try:
        correction = LineCorrection.from_dict(sidecar["correction"])
        values = {str(e["name"]): float(e["value"]) for e in sidecar["parameters"]}
        params = np.array([values[n] for n in correction.parameter_names])
    except (KeyError, TypeError, ValueError) as exc:
        raise SceneFileError(f"{source}: malformed sidecar ({exc})") from exc
    return adjusted_sensor(sensor, correction, params)


def _load_base(kind: str, path: Path) -> Any:
    """The sensor of a base file as :func:`explorer.sources.load_source` reads it (without a DEM)."""
    if kind == "dimap":
        from explorer.real.dimap import rigorous_scene_from_dimap

        return rigorous_scene_from_dimap(path)[0]
    if kind == "dg":
        from explorer.real.worldview import rigorous_scene_from_dg

        return rigorous_scene_from_dg(path)
    if kind == "isd":
        from explorer.real.csm_camera import read_isd
        from explorer.real.csm_sensor import csm_scene

        return csm_scene(read_isd(path))
    raise SceneFileError(f"{path}: unknown source kind {kind!r} in the sidecar (dimap, dg or isd)")


def load_adjusted(sidecar_path: str | Path, base_path: str | Path | None = None) -> Any:
    """Load an adjusted sensor: the sidecar's base file (beside the sidecar unless ``base_path``; its SHA-256
    checked) read as :func:`explorer.sources.load_source` reads it, then the correction.

    Raises
    ------
    SceneFileError
        Not a sidecar, malformed, or a base file whose hash differs from the one the sidecar names.
    """
    d, base = read_sidecar(sidecar_path, base_path)
    return apply_sidecar(_load_base(str(d.get("source_kind")), base), d, str(sidecar_path))


def read_sidecar(sidecar_path: str | Path, base_path: str | Path | None = None,
                 kind: str | None = None) -> tuple[dict[str, Any], Path]:
    """A sidecar's dict and its base file: ``base_path``, else the file it names beside the sidecar; the base
    file's SHA-256 checked against the one the sidecar records (what :func:`load_adjusted` and
    ``pushbroom explore --adjusted`` read); ``kind`` (``"dimap"``, ``"dg"``, ``"isd"``): the kind of source the
    base file is read as, which must be the sidecar's.

    Raises
    ------
    SceneFileError
        Not a sidecar, malformed, no base file named nor given, the base file missing, or its hash not the one
        the sidecar records (one line naming both files).
    InputError
        ``kind`` is not the sidecar's source kind.
    """
    from explorer.io_input import load_json_file

    path = Path(sidecar_path)
    d = load_json_file(path, "sidecar")
    if not isinstance(d, dict) or d.get("format") != SIDECAR_FORMAT:
        raise SceneFileError(f"{path}: not an adjusted line-scanner sidecar (format {SIDECAR_FORMAT!r})")
    if kind is not None and d.get("source_kind") != kind:
        raise InputError(f"{path} adjusts a --{d.get('source_kind')} file, not a --{kind} one")
    if base_path is None and not d.get("base_file"):
        raise SceneFileError(f"{path}: the sidecar names no base file (give its path)")
    base = Path(base_path) if base_path is not None else path.parent / str(d.get("base_file"))
    if not base.is_file():
        raise SceneFileError(f"{path}: its base file {str(base)!r} is not there (give its path)")
    if d.get("base_sha256") is not None and file_sha256(base) != d.get("base_sha256"):
        raise SceneFileError(f"{path}: {base} is not the file this adjustment was made on (SHA-256 differs)")
    return d, base


def write_sidecar(path: str | Path, sidecar: dict[str, Any]) -> Path:
    """Write a sidecar dict as JSON (atomic)."""
    from explorer.io_atomic import write_text_atomic

    return write_text_atomic(Path(path), json.dumps(sidecar, indent=2) + "\n")
