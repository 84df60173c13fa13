"""Sensor presets: the ten images of the MLP/LRM papers plus the ``linear`` and
``agile`` teaching presets, read from ``assets/presets.json`` (data, not code) and
built into :class:`explorer.scene.Scene` objects.

The builder places a Keplerian circular orbit (spherical Earth of the local mean
radius, Earth rotation not modelled) so that the sensor, tilted by the preset's
roll and pitch, looks at the scene centre at the reference row; the attitude
follows the orbital frame plus the preset's body rates.  The MPC polynomials are
the exact second-order Taylor expansions at t = 0.  Product grids are resampled in
reality, so the detector pitch and line period are scaled so that the simulated
GSD at the image centre equals the table value.  See ``docs/presets.md``.
"""

from __future__ import annotations

import copy
import json
from functools import lru_cache

import numpy as np

from explorer._resources import asset_path
from explorer.errors import SceneFileError, UnknownNameError
from explorer.geometry.exterior import ExteriorOrientation, Jitter, LineTiming
from explorer.geometry.frames import WGS84_A, WGS84_E2, LocalFrame
from explorer.geometry.interior import InteriorOrientation
from explorer.geometry.rotations import axis_angle_matrix, opk_from_rotation, rotation_from_opk
from explorer.geometry.terrain import FlatTerrain, synthetic_relief
from explorer.scene import Scene

GM_EARTH = 3.986004418e14  # m^3 s^-2 (WGS84)
REQUIRED_FIELDS = (
    "id", "sensor", "region", "rows", "columns", "gsd_m", "lat_deg", "lon_deg", "mean_height_m",
    "altitude_m", "focal_length_m", "native_detector_pitch_m", "inclination_deg", "pass",
    "roll_deg", "pitch_deg", "body_rates_deg_s", "orbit_model", "sources",
)


@lru_cache(maxsize=1)
def _load_table() -> dict:
    path = asset_path("presets.json")
    doc = json.loads(path.read_text())
    if doc.get("format") != "pushbroom-explorer presets":
        raise SceneFileError(f"{path}: not a presets file")
    for p in doc["presets"]:
        missing = [k for k in REQUIRED_FIELDS if k not in p]
        if missing:
            raise SceneFileError(f"{path}: preset {p.get('id', '?')!r} misses {missing}")
    return doc


def preset_ids() -> list[str]:
    """Preset identifiers in file order (the ten paper images, then ``linear``, ``agile``)."""
    return [p["id"] for p in _load_table()["presets"]]


def default_preset_id() -> str:
    """The preset the explorer and the CLI use when none is named."""
    return _load_table()["default"]


def preset_spec(preset_id: str) -> dict:
    """The raw preset record (a copy) for ``preset_id`` (case-insensitive)."""
    for p in _load_table()["presets"]:
        if p["id"].lower() == preset_id.lower():
            return copy.deepcopy(p)
    raise UnknownNameError("preset", preset_id, preset_ids())


def _heading_azimuth(lat_deg: float, inclination_deg: float, direction: str) -> float:
    """Ground-track azimuth (radians, clockwise from north) of a circular orbit at a latitude."""
    s = np.cos(np.radians(inclination_deg)) / np.cos(np.radians(lat_deg))
    if abs(s) > 1:
        raise ValueError(f"latitude {lat_deg} is not reached by an orbit inclined {inclination_deg} deg")
    asc = np.arcsin(s)
    if direction == "ascending":
        return float(asc)
    if direction == "descending":
        return float(np.pi - asc)
    raise ValueError(f"pass must be 'ascending' or 'descending', got {direction!r}")


def _local_radius(lat_deg: float) -> float:
    """Gaussian mean radius of curvature of the ellipsoid at a latitude, metres."""
    s2 = np.sin(np.radians(lat_deg)) ** 2
    return float(WGS84_A * np.sqrt(1 - WGS84_E2) / (1 - WGS84_E2 * s2))


def _orbit_and_attitude(spec: dict, rate_scale: float) -> ExteriorOrientation:
    """MPC polynomials (degree 2, or 1/0 for the straight teaching orbit)."""
    radius = _local_radius(spec["lat_deg"])
    h = float(spec["mean_height_m"])
    r = radius + float(spec["altitude_m"])
    up = np.array([0.0, 0.0, 1.0])
    az = _heading_azimuth(spec["lat_deg"], spec["inclination_deg"], spec["pass"])
    fwd = np.array([np.sin(az), np.cos(az), 0.0])
    right = np.cross(fwd, up)
    tr, tp = np.tan(np.radians(spec["roll_deg"])), np.tan(np.radians(spec["pitch_deg"]))
    look_h = tp * fwd + tr * right
    off_nadir = np.arctan(np.hypot(tr, tp))
    ground = np.array([0.0, 0.0, h])
    centre = np.array([0.0, 0.0, -radius])
    if off_nadir > 0:
        incidence = np.arcsin(np.clip(r / (radius + h) * np.sin(off_nadir), -1, 1))
        gamma = incidence - off_nadir
        axis = np.cross(up, look_h / np.linalg.norm(look_h))
        rot = axis_angle_matrix(axis, -gamma)
    else:
        rot = np.eye(3)
    e_s = rot @ up
    sat = centre + r * e_s
    u_s = rot @ fwd
    v_dir = u_s - (u_s @ e_s) * e_s
    v_dir /= np.linalg.norm(v_dir)
    speed = np.sqrt(GM_EARTH / r)
    vel = speed * v_dir
    acc = -GM_EARTH / r**2 * e_s

    z_axis = -(ground - sat) / np.linalg.norm(ground - sat)
    x_axis = vel - (vel @ z_axis) * z_axis
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    r0 = np.stack([x_axis, y_axis, z_axis], axis=1)

    straight = spec["orbit_model"] == "straight"
    if straight:
        pos = np.stack([sat, vel], axis=1)
        att = np.array(opk_from_rotation(r0)).reshape(3, 1)
        return ExteriorOrientation(pos, att, [])
    if spec["orbit_model"] != "keplerian":
        raise SceneFileError(f"preset {spec['id']}: unknown orbit_model {spec['orbit_model']!r}")

    normal = np.cross(e_s, v_dir)
    orbit_rate = speed / r
    rates = np.radians(np.asarray(spec["body_rates_deg_s"], dtype=float)) * rate_scale
    accs = np.radians(np.asarray(spec.get("body_accelerations_deg_s2", [0, 0, 0]), dtype=float)) * rate_scale

    def angles_at(t: float) -> np.ndarray:
        body = rates * t + 0.5 * accs * t * t
        rt = axis_angle_matrix(normal, orbit_rate * t) @ r0 @ rotation_from_opk(*body)
        return np.array(opk_from_rotation(rt))

    step = 0.25
    samples = np.stack([angles_at(k * step) for k in (-2, -1, 0, 1, 2)])
    samples = np.unwrap(samples, axis=0)
    a0 = samples[2]
    # fourth-order central differences
    d1 = (samples[0] - 8 * samples[1] + 8 * samples[3] - samples[4]) / (12 * step)
    d2 = (-samples[0] + 16 * samples[1] - 30 * samples[2] + 16 * samples[3] - samples[4]) / (12 * step**2)
    att = np.stack([a0, d1, 0.5 * d2], axis=1)
    pos = np.stack([sat, vel, 0.5 * acc], axis=1)
    return ExteriorOrientation(pos, att, [])


def build_scene(
    preset_id: str | None = None,
    *,
    relief_m: float = 0.0,
    relief_seed: int = 0,
    attitude_rate_scale: float = 1.0,
    jitter_amplitude_scale: float = 1.0,
    extra_jitter: list[Jitter] | None = None,
) -> Scene:
    """Build the scene of a preset, optionally perturbed.

    Parameters
    ----------
    preset_id : str, optional
        Preset id (case-insensitive); default :func:`default_preset_id`.
    relief_m : float
        Amplitude of a seeded synthetic relief around the mean height, metres (0 = flat).
    relief_seed : int
        Seed of the relief.
    attitude_rate_scale : float
        Multiplies the preset's body rates and accelerations (0 = orbit-following attitude only).
    jitter_amplitude_scale : float
        Multiplies the preset's jitter amplitudes.
    extra_jitter : list of Jitter, optional
        Added sinusoids.
    """
    spec = preset_spec(preset_id or default_preset_id())
    exterior = _orbit_and_attitude(spec, attitude_rate_scale)
    jit = [
        Jitter(j["angle"], j["amplitude_rad"] * jitter_amplitude_scale, j["frequency_hz"], j.get("phase_rad", 0.0))
        for j in spec.get("jitter", [])
    ] + list(extra_jitter or [])
    exterior.jitter = [j for j in jit if j.amplitude_rad != 0.0]
    rows, cols = int(spec["rows"]), int(spec["columns"])
    gsd = float(spec["gsd_m"])
    speed_ground = np.linalg.norm(exterior.position_coeffs[:, 1]) * _local_radius(spec["lat_deg"]) / (
        _local_radius(spec["lat_deg"]) + spec["altitude_m"]
    )
    interior = InteriorOrientation(spec["focal_length_m"], spec["native_detector_pitch_m"], cols)
    timing = LineTiming(gsd / speed_ground, (rows - 1) / 2.0)
    frame = LocalFrame(float(spec["lat_deg"]), float(spec["lon_deg"]), 0.0)
    metadata = {
        "preset": spec["id"], "sensor": spec["sensor"], "region": spec["region"], "table_gsd_m": gsd,
        "relief_m": relief_m, "relief_seed": relief_seed, "attitude_rate_scale": attitude_rate_scale,
        "jitter_amplitude_scale": jitter_amplitude_scale,
    }
    scene = Scene(spec["id"], interior, exterior, timing, rows, FlatTerrain(float(spec["mean_height_m"])),
                  frame, metadata)
    # Scale pitch and line period so the simulated product GSD equals the table value.
    for _ in range(4):
        along, across = scene.ground_sample_distance()
        interior.detector_pitch_m *= gsd / across
        scene.timing = LineTiming(scene.timing.line_period_s * gsd / along, scene.timing.reference_row)
    scene.metadata["detector_pitch_scale"] = interior.detector_pitch_m / spec["native_detector_pitch_m"]
    if relief_m:
        h = float(spec["mean_height_m"])
        corners = np.vstack([scene.footprint(h - abs(relief_m)), scene.footprint(h + abs(relief_m))])
        span = corners[:, :2].max(0) - corners[:, :2].min(0)
        lo = corners[:, :2].min(0) - 0.05 * span
        hi = corners[:, :2].max(0) + 0.05 * span
        scene.terrain = synthetic_relief((lo[0], hi[0], lo[1], hi[1]), relief_m, relief_seed, base_height_m=h)
    from explorer.scene_checks import check_scene_physics

    # a preset shaped by options (relief, attitude rates, jitter) is checked like a scene file (docs/validation.md)
    check_scene_physics(scene, f"preset {spec['id']}")
    return scene


def presets_table() -> list[dict]:
    """One summary row per preset (id, sensor, region, size, GSD, centre, orbit, view)."""
    rows = []
    for p in _load_table()["presets"]:
        rows.append({
            "id": p["id"], "sensor": p["sensor"], "region": p["region"], "rows": p["rows"],
            "columns": p["columns"], "gsd_m": p["gsd_m"], "lat_deg": p["lat_deg"], "lon_deg": p["lon_deg"],
            "altitude_km": p["altitude_m"] / 1000.0, "roll_deg": p["roll_deg"], "pitch_deg": p["pitch_deg"],
            "orbit_model": p["orbit_model"],
        })
    return rows
