"""Rigorous line-scan sensor model from tabulated ephemeris and attitude.

Beyond the papers (which solve an MPC model from control points, Ahooei Nezhad et al. 2024,
Sec. 2.2): real metadata give the orbit as ECEF position/velocity samples and the attitude as
quaternion samples, and the camera as a detector line in the focal plane.  This module
interpolates them:

* orbit: Lagrange interpolation (order 8, sliding window) of the ECEF positions and
  velocities (the order used by the CSM/USGS line-scan model);
* attitude: Lagrange interpolation (order 4) of the quaternion components, renormalised, or
  spherical linear interpolation (``"slerp"``) between neighbouring samples;
* optional aberration of light: the apparent line of sight is ``normalize(d + v_rel / c)``
  with ``v_rel = v_ecef + omega_earth x (S - P)`` (satellite velocity relative to the ground
  point, including the light-time rotation of the Earth);
* optional atmospheric refraction: the target appears displaced away from nadir by
  ``N0 * Hs * exp(-h / Hs) * tan(z) / cos(z)**2`` (flat-atmosphere first order; ``z`` the
  zenith angle of the line of sight at the ground).

:class:`RigorousLineScanScene` is a :class:`~explorer.scene.Scene` whose ``exterior`` is a
:class:`LineScanExterior` (same interface as the MPC ``ExteriorOrientation``: ``position``,
``velocity``, ``rotation``, ``angles``, ``angle_rates`` of the scanline time, in the local ENU
frame) and which overrides ``focal_plane`` and ``rays`` for the corrections, so every method
that only uses the scene's collinearity runs on it unchanged; :meth:`to_mpc_scene` converts it
to an MPC scene (polynomials) for the methods that need coefficients.

Conventions (pixels, time, frames, sensor axes): ``docs/conventions.md``; vendor conventions
and measured agreement with the vendor RPCs: ``docs/real_images.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from explorer.errors import SceneFileError, check_finite
from explorer.geometry.exterior import LineTiming
from explorer.geometry.frames import LocalFrame
from explorer.geometry.interior import InteriorOrientation
from explorer.geometry.rotations import opk_from_rotation
from explorer.geometry.terrain import Terrain, intersect_heights, terrain_from_dict
from explorer.io_input import load_json_file
from explorer.real import _linescan_kernel
from explorer.real.mpc_fit import mpc_scene_from_sensor
from explorer.scene import RIGOROUS_SCENE_FORMAT, Scene
from explorer.scene_checks import check_scene_physics

__all__ = [
    "C_LIGHT",
    "OMEGA_EARTH",
    "AttitudeTable",
    "Ephemeris",
    "LineScanExterior",
    "RigorousLineScanScene",
    "lagrange_interpolate",
    "lagrange_position_from",
    "load_scene",
    "matrix_to_quaternion",
    "quaternion_to_matrix",
    "slerp",
]

C_LIGHT = 299_792_458.0  # m/s
OMEGA_EARTH = 7.2921151467e-5  # rad/s, WGS84
REFRACTIVITY_SEA_LEVEL = 2.77e-4  # (n - 1) at the surface, standard atmosphere
SCALE_HEIGHT_M = 8_000.0  # scale height of the refractivity, metres


# --------------------------------------------------------------------------- quaternions
def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions ``(w, x, y, z)`` (scalar first, Hamilton).

    Parameters
    ----------
    q : ndarray, shape (N, 4)

    Returns
    -------
    ndarray, shape (N, 3, 3)
        ``R v = q v q*`` (active rotation).
    """
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - z * w)
    r[..., 0, 2] = 2 * (x * z + y * w)
    r[..., 1, 0] = 2 * (x * y + z * w)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - x * w)
    r[..., 2, 0] = 2 * (x * z - y * w)
    r[..., 2, 1] = 2 * (y * z + x * w)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def matrix_to_quaternion(r: np.ndarray) -> np.ndarray:
    """Inverse of :func:`quaternion_to_matrix` (Shepperd's method), ``w >= 0``; shape (N, 4)."""
    r = np.asarray(r, dtype=np.float64)
    flat = r.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4))
    tr = np.trace(flat, axis1=1, axis2=2)
    cand = np.stack([tr, flat[:, 0, 0], flat[:, 1, 1], flat[:, 2, 2]], axis=1)
    k = np.argmax(cand, axis=1)
    for i in range(flat.shape[0]):
        m = flat[i]
        if k[i] == 0:
            s = 2.0 * np.sqrt(1.0 + tr[i])
            q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
        elif k[i] == 1:
            s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
            q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
        elif k[i] == 2:
            s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
            q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
        else:
            s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
            q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
        out[i] = q
    out *= np.where(out[:, :1] < 0, -1.0, 1.0)
    return out.reshape(r.shape[:-2] + (4,))


def slerp(q0: np.ndarray, q1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation between unit quaternions (N, 4) at fractions s (N,)."""
    q0 = np.asarray(q0, dtype=np.float64)
    q1 = np.asarray(q1, dtype=np.float64)
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where(dot[..., None] < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    small = sin_t < 1e-12
    with np.errstate(invalid="ignore", divide="ignore"):
        w0 = np.where(small, 1.0 - s, np.sin((1.0 - s) * theta) / sin_t)
        w1 = np.where(small, s, np.sin(s * theta) / sin_t)
    q = w0[..., None] * q0 + w1[..., None] * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _continuous_signs(q: np.ndarray) -> np.ndarray:
    """Flip quaternion signs so that consecutive samples have a positive dot product."""
    q = np.array(q, dtype=np.float64)
    for i in range(1, q.shape[0]):
        if np.dot(q[i], q[i - 1]) < 0:
            q[i] = -q[i]
    return q


# --------------------------------------------------------------------------- interpolation
def lagrange_interpolate(ts: np.ndarray, values: np.ndarray, t: np.ndarray, order: int = 8) -> np.ndarray:
    """Lagrange interpolation over a sliding window of ``order`` samples.

    The window is centred on each query time (clamped at the ends of the table); the
    samples need not be evenly spaced.  Vectorised over query times.

    Parameters
    ----------
    ts : ndarray, shape (N,)
        Increasing sample times.
    values : ndarray, shape (N, K)
    t : ndarray, shape (M,)
    order : int
        Number of samples per window (degree ``order - 1``), capped at N.

    Returns
    -------
    ndarray, shape (M, K)
    """
    values = np.asarray(values, dtype=np.float64)
    _, idx, w = _lagrange_windows(ts, t, order)
    return np.einsum("mj,mjk->mk", w, values[idx])


def _lagrange_windows(ts: np.ndarray, t: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each query time's window of ``min(order, N)`` samples, centred and clamped at the table's ends: its first
    sample (M,), the sample indexes (M, m) and the Lagrange weights (M, m) at ``t``."""
    ts = np.asarray(ts, dtype=np.float64)
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    n = ts.size
    m = min(order, n)
    start = np.clip(np.searchsorted(ts, t) - m // 2, 0, n - m)
    idx = start[:, None] + np.arange(m)[None, :]  # (M, m)
    tw = ts[idx]
    dt = t[:, None] - tw  # (M, m)
    w = np.ones_like(dt)
    for j in range(m):
        for k in range(m):
            if k != j:
                w[:, j] *= dt[:, k] / (tw[:, j] - tw[:, k])
    return start, idx, w


def lagrange_position_from(ts: np.ndarray, positions: np.ndarray, velocities: np.ndarray, t: np.ndarray,
                           point: np.ndarray, order: int = 8, parts: bool = False) -> Any:
    """Lagrange-interpolated positions minus ``point``, (M, 3), computed without planetary-size round-off.

    :func:`lagrange_interpolate` of ``positions`` at ``t``, minus ``point``, formed as ``(p_r - point) + (v_r (t -
    t_r) + sum_j w_j (p_j - p_r - v_r (t_j - t_r)))`` with ``(t_r, p_r, v_r)`` the middle sample of each window:
    Lagrange interpolation reproduces the tangent line exactly, so this equals the interpolated position, but the
    weights (rounded to ~1e-16 relative) multiply the samples' departures from that line (tens of kilometres for
    a Pleiades table, metres for a densely sampled one) instead of ECEF positions of 7,000 km.  Summing ECEF
    positions makes the interpolated position wobble by ~3e-9 m from one time to the next, which a 1e-6 rad
    pixel 700 km away sees as a +-3e-9 px non-monotonic line residual; here it is ~1e-10 m.  The compiled line
    geometry (:mod:`explorer.real._linescan_kernel`) and the differentiable model
    (:mod:`explorer.refine.torch_linescan`) form the same sums.

    Parameters
    ----------
    ts : ndarray, shape (N,)
        Increasing sample times, seconds.
    positions, velocities : ndarray, shape (N, 3)
        Samples (metres, metres per second; the velocities only choose the tangent line, any values are exact).
    t : ndarray, shape (M,)
    point : ndarray, shape (3,)
        Subtracted from every position (e.g. a local frame's origin), metres.
    order : int
        Samples per window, as :func:`lagrange_interpolate`.
    parts : bool
        Return the two terms apart: ``p_r - point``, which does not vary within a window, and the rest (the
        motion since ``t_r``, kilometres); a line of sight formed as ``(ground - fixed) - moving`` then varies
        with ``t`` without the round-off of its 700 km length.

    Returns
    -------
    ndarray, shape (M, 3), or (fixed, moving), each (M, 3)
    """
    ts = np.asarray(ts, dtype=np.float64)
    positions = np.asarray(positions, dtype=np.float64)
    velocities = np.asarray(velocities, dtype=np.float64)
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    start, idx, w = _lagrange_windows(ts, t, order)
    m = idx.shape[1]
    mid = start + m // 2
    tw = ts[idx]
    t_r, p_r, v_r = ts[mid], positions[mid], velocities[mid]
    departure = (positions[idx] - p_r[:, None, :]) - v_r[:, None, :] * (tw - t_r[:, None])[:, :, None]
    total = w[:, 0, None] * departure[:, 0]
    for j in range(1, m):  # in the compiled loop's order
        total = total + w[:, j, None] * departure[:, j]
    fixed = p_r - np.asarray(point, dtype=np.float64)
    moving = v_r * (t - t_r)[:, None] + total
    return (fixed, moving) if parts else fixed + moving


@dataclass
class Ephemeris:
    """ECEF position and velocity samples of the perspective centre (or the satellite).

    Attributes
    ----------
    time_s : ndarray, shape (N,)
        Seconds from the scene epoch (scanline time 0).
    position_m : ndarray, shape (N, 3)
        ECEF metres.
    velocity_m_s : ndarray, shape (N, 3)
        ECEF metres per second (Earth-fixed, i.e. relative to the rotating Earth).
    order : int
        Lagrange window (samples).
    """

    time_s: np.ndarray
    position_m: np.ndarray
    velocity_m_s: np.ndarray
    order: int = 8

    def __post_init__(self) -> None:
        self.time_s = np.asarray(self.time_s, dtype=np.float64)
        self.position_m = np.asarray(self.position_m, dtype=np.float64).reshape(-1, 3)
        self.velocity_m_s = np.asarray(self.velocity_m_s, dtype=np.float64).reshape(-1, 3)
        if not (self.time_s.size == self.position_m.shape[0] == self.velocity_m_s.shape[0] >= 2):
            raise ValueError("ephemeris needs >= 2 samples with times, positions and velocities")
        if np.any(np.diff(self.time_s) <= 0):
            raise ValueError("ephemeris times must increase")

    def position(self, t: np.ndarray) -> np.ndarray:
        """ECEF position (M, 3), metres."""
        return lagrange_interpolate(self.time_s, self.position_m, t, self.order)

    def position_from(self, t: np.ndarray, point: np.ndarray) -> np.ndarray:
        """ECEF position minus ``point`` (M, 3), metres, without the round-off of 7,000 km coordinates
        (:func:`lagrange_position_from`)."""
        return lagrange_position_from(self.time_s, self.position_m, self.velocity_m_s, t, point, self.order)

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """ECEF velocity (M, 3), m/s (interpolated velocity samples)."""
        return lagrange_interpolate(self.time_s, self.velocity_m_s, t, self.order)

    def to_dict(self) -> dict:
        return {"time_s": self.time_s.tolist(), "position_m": self.position_m.tolist(),
                "velocity_m_s": self.velocity_m_s.tolist(), "order": self.order}

    @classmethod
    def from_dict(cls, d: dict) -> Ephemeris:
        return cls(np.asarray(d["time_s"]), np.asarray(d["position_m"]), np.asarray(d["velocity_m_s"]),
                   int(d.get("order", 8)))


@dataclass
class AttitudeTable:
    """Attitude samples: unit quaternions (w, x, y, z) rotating body vectors into ECEF.

    Attributes
    ----------
    time_s : ndarray, shape (N,)
        Seconds from the scene epoch.
    quaternion : ndarray, shape (N, 4)
        Scalar first; signs are made continuous on construction.
    method : {"lagrange", "slerp"}
        Lagrange interpolation of the components (``order`` samples, renormalised) or slerp
        between the two neighbouring samples.
    order : int
    """

    time_s: np.ndarray
    quaternion: np.ndarray
    method: str = "lagrange"
    order: int = 4

    def __post_init__(self) -> None:
        self.time_s = np.asarray(self.time_s, dtype=np.float64)
        q = np.asarray(self.quaternion, dtype=np.float64).reshape(-1, 4)
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        self.quaternion = _continuous_signs(q)
        if self.time_s.size != self.quaternion.shape[0] or self.time_s.size < 2:
            raise ValueError("attitude needs >= 2 samples with times and quaternions")
        if np.any(np.diff(self.time_s) <= 0):
            raise ValueError("attitude times must increase")
        if self.method not in ("lagrange", "slerp"):
            raise ValueError(f"attitude method must be 'lagrange' or 'slerp', got {self.method!r}")

    def quaternions(self, t: np.ndarray) -> np.ndarray:
        """Interpolated unit quaternions (M, 4)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if self.method == "lagrange":
            q = lagrange_interpolate(self.time_s, self.quaternion, t, self.order)
            return q / np.linalg.norm(q, axis=1, keepdims=True)
        i = np.clip(np.searchsorted(self.time_s, t) - 1, 0, self.time_s.size - 2)
        s = (t - self.time_s[i]) / (self.time_s[i + 1] - self.time_s[i])
        return slerp(self.quaternion[i], self.quaternion[i + 1], s)

    def rotation(self, t: np.ndarray) -> np.ndarray:
        """Body -> ECEF rotation matrices (M, 3, 3)."""
        return quaternion_to_matrix(self.quaternions(t))

    def smoothed(self, degree: int) -> AttitudeTable:
        """A copy whose quaternions are a least-squares polynomial of time (each component,
        renormalised) evaluated at the sample times: a smooth "perfect" attitude."""
        tm = float(np.mean(self.time_s))
        coef = np.polynomial.polynomial.polyfit(self.time_s - tm, self.quaternion, degree)
        q = np.polynomial.polynomial.polyval(self.time_s - tm, coef).T
        return replace(self, quaternion=q / np.linalg.norm(q, axis=1, keepdims=True))

    def to_dict(self) -> dict:
        return {"time_s": self.time_s.tolist(), "quaternion_wxyz": self.quaternion.tolist(),
                "method": self.method, "order": self.order}

    @classmethod
    def from_dict(cls, d: dict) -> AttitudeTable:
        return cls(np.asarray(d["time_s"]), np.asarray(d["quaternion_wxyz"]), d.get("method", "lagrange"),
                   int(d.get("order", 4)))


# --------------------------------------------------------------------------- exterior
@dataclass
class LineScanExterior:
    """Interpolated exterior orientation in the local ENU frame.

    Same interface as :class:`explorer.geometry.exterior.ExteriorOrientation` (position,
    velocity, rotation, angles, angle_rates of the scanline time ``t``), so a
    :class:`~explorer.scene.Scene` computes its collinearity with it unchanged.  It has no
    polynomial coefficients: use :meth:`RigorousLineScanScene.to_mpc_scene` for methods that
    read ``position_coeffs``/``attitude_coeffs``.

    Attributes
    ----------
    ephemeris : Ephemeris
    attitude : AttitudeTable
    frame : LocalFrame
    sensor_to_body : ndarray, shape (3, 3)
        Rotation of the package's sensor axes (x along the image rows, y along increasing
        columns, z away from the ground, ``docs/conventions.md#frames``) into the body frame
        whose attitude the quaternions give.
    centre_offset_body_m : ndarray, shape (3,)
        Perspective centre minus ephemeris point, body frame, metres.
    """

    ephemeris: Ephemeris
    attitude: AttitudeTable
    frame: LocalFrame
    sensor_to_body: np.ndarray = field(default_factory=lambda: np.eye(3))
    centre_offset_body_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    jitter: list = field(default_factory=list)

    def __post_init__(self) -> None:
        self.sensor_to_body = np.asarray(self.sensor_to_body, dtype=np.float64).reshape(3, 3)
        self.centre_offset_body_m = np.asarray(self.centre_offset_body_m, dtype=np.float64).reshape(3)
        self._e = self.frame.enu_to_ecef_rotation  # columns: ENU axes in ECEF

    @property
    def is_constant_velocity_and_attitude(self) -> bool:
        return False

    def _t(self, t: np.ndarray) -> np.ndarray:
        return np.atleast_1d(np.asarray(t, dtype=np.float64))

    def position_ecef(self, t: np.ndarray) -> np.ndarray:
        """Perspective centre in ECEF (N, 3), metres."""
        t = self._t(t)
        p = self.ephemeris.position(t)
        if np.any(self.centre_offset_body_m):
            p = p + np.einsum("nij,j->ni", self.attitude.rotation(t), self.centre_offset_body_m)
        return p

    def position(self, t: np.ndarray) -> np.ndarray:
        """Perspective centre S(t) in the local ENU frame, shape (N, 3), metres (interpolated relative to the
        frame's origin: :meth:`Ephemeris.position_from`)."""
        fixed, moving = self.position_parts(t)
        return fixed + moving

    def position_parts(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The perspective centre (N, 3) in the local ENU frame as two terms, ``fixed + moving``: the Lagrange
        window's middle sample (constant within a window) and the motion from it, lever arm included
        (:func:`lagrange_position_from`); a line of sight ``(ground - fixed) - moving`` then carries no round-off of
        the 700 km distance that varies with ``t``."""
        t = self._t(t)
        eph = self.ephemeris
        fixed, moving = lagrange_position_from(eph.time_s, eph.position_m, eph.velocity_m_s, t, self.frame.origin_ecef,
                                               eph.order, parts=True)
        if np.any(self.centre_offset_body_m):
            moving = moving + np.einsum("nij,j->ni", self.attitude.rotation(t), self.centre_offset_body_m)
        e = self._e  # E^T p per component, in the compiled loop's order
        return tuple(np.stack([e[0, k] * p[:, 0] + e[1, k] * p[:, 1] + e[2, k] * p[:, 2] for k in range(3)], axis=-1)
                     for p in (fixed, moving))  # type: ignore[return-value]

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """dS/dt in the local frame (Earth-fixed), shape (N, 3), m/s."""
        return self.ephemeris.velocity(self._t(t)) @ self._e

    def rotation_ecef(self, t: np.ndarray) -> np.ndarray:
        """Sensor -> ECEF rotations (N, 3, 3)."""
        return self.attitude.rotation(self._t(t)) @ self.sensor_to_body

    def rotation(self, t: np.ndarray) -> np.ndarray:
        """Sensor -> local ENU rotations R(t), shape (N, 3, 3)."""
        return np.einsum("ji,njk->nik", self._e, self.rotation_ecef(t))

    def angles(self, t: np.ndarray) -> np.ndarray:
        """(omega, phi, kappa)(t) of :meth:`rotation` (``docs/conventions.md#rotations``), (N, 3)."""
        return np.stack(opk_from_rotation(self.rotation(t)), axis=-1)

    def angle_rates(self, t: np.ndarray, h: float = 1e-3) -> np.ndarray:
        """d(omega, phi, kappa)/dt by central differences (step ``h`` seconds), (N, 3), rad/s."""
        t = self._t(t)
        a1, a0 = self.angles(t + h), self.angles(t - h)
        d = (a1 - a0 + np.pi) % (2 * np.pi) - np.pi
        return d / (2 * h)

    def to_dict(self) -> dict:
        return {
            "kind": "interpolated",
            "ephemeris": self.ephemeris.to_dict(),
            "attitude": self.attitude.to_dict(),
            "sensor_to_body": self.sensor_to_body.tolist(),
            "centre_offset_body_m": self.centre_offset_body_m.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict, frame: LocalFrame) -> LineScanExterior:
        return cls(Ephemeris.from_dict(d["ephemeris"]), AttitudeTable.from_dict(d["attitude"]), frame,
                   np.asarray(d["sensor_to_body"]), np.asarray(d.get("centre_offset_body_m", [0, 0, 0])))


# --------------------------------------------------------------------------- scene
RIGOROUS_FORMAT = RIGOROUS_SCENE_FORMAT


@dataclass
class RigorousLineScanScene(Scene):
    """A :class:`~explorer.scene.Scene` with an interpolated (rigorous) exterior orientation.

    Extra attributes
    ----------------
    aberration : bool
        Model the aberration of light (satellite velocity relative to the ground / c).
    refraction : bool
        Model atmospheric refraction (flat standard atmosphere, see the module docstring).
    epoch_utc : str
        UTC time of scanline time 0 (ISO 8601).
    rpc : RationalFunctionModel or None
        The vendor RPC of the same image when the metadata had one (not serialised; its
        file is ``metadata["rpc_file"]``).
    """

    aberration: bool = True
    refraction: bool = False
    epoch_utc: str = ""
    rpc: Any = field(default=None, repr=False, compare=False)
    # interpolated tables with ExteriorOrientation's evaluation interface (position, velocity, rotation, angles)
    exterior: LineScanExterior  # type: ignore[assignment]

    #: Capability: interpolated ephemeris and attitude tables, not MPC polynomials (no compiled kernels).
    has_polynomial_exterior: ClassVar[bool] = False
    #: Rows to which this model's residual defines a root: its round-off made the residual wobble by +-3e-9 px within
    #: +-5e-9 rows of a root while the 7,000 km ECEF positions were summed (2017 DIMAP); interpolated about the
    #: window's tangent line (:func:`lagrange_position_from`) it stays below 1e-9 px, and a search asking for a
    #: smaller step than this still only spends evaluations.
    root_resolution_rows: ClassVar[float] = 1e-8

    # ------------------------------------------------------------ corrections
    def _omega_enu(self) -> np.ndarray:
        return OMEGA_EARTH * self.frame.enu_to_ecef_rotation[2]  # ECEF z axis in ENU components

    def _relative_velocity(self, t: np.ndarray, centre: np.ndarray, ground: np.ndarray) -> np.ndarray:
        v = self.exterior.velocity(t)
        return v + np.cross(self._omega_enu(), centre - ground)

    def _up(self, points: np.ndarray) -> np.ndarray:
        """Ellipsoid normals (N, 3) at local ENU points (geodetic up, in ENU components)."""
        lon, lat, _ = self.frame.enu_to_geodetic(points)
        lo, la = np.radians(lon), np.radians(lat)
        n_ecef = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], axis=-1)
        return n_ecef @ self.frame.enu_to_ecef_rotation

    def _refraction_shift(self, ground: np.ndarray, centre: np.ndarray) -> np.ndarray:
        """Apparent minus true ground position (N, 3): away from nadir, horizontal, metres."""
        up = self._up(ground)
        los = centre - ground
        los /= np.linalg.norm(los, axis=1, keepdims=True)
        cz = np.clip(np.sum(los * up, axis=1), 1e-6, 1.0)
        tz = np.sqrt(1.0 - cz * cz) / cz
        _, _, h = self.frame.enu_to_geodetic(ground)
        shift = REFRACTIVITY_SEA_LEVEL * SCALE_HEIGHT_M * np.exp(-np.clip(h, -500, None) / SCALE_HEIGHT_M) * tz / cz**2
        away = -(los - cz[:, None] * up)  # horizontal, pointing away from the satellite
        norm = np.linalg.norm(away, axis=1, keepdims=True)
        away = np.divide(away, norm, out=np.zeros_like(away), where=norm > 0)
        return shift[:, None] * away

    # ------------------------------------------------------------ collinearity
    def _compiled_exterior(self) -> tuple | None:
        """The arguments of the compiled line geometry (:mod:`explorer.real._linescan_kernel`), or None where it
        does not apply: numba off, or tables / corrections of other classes than this module's (a subclass that
        overrides a correction keeps the numpy path)."""
        if not _linescan_kernel.NUMBA_AVAILABLE:
            return None
        ex = self.exterior
        cls = type(self)
        if (type(ex) is not LineScanExterior or type(ex.ephemeris) is not Ephemeris
                or type(ex.attitude) is not AttitudeTable or ex.jitter
                or any(getattr(cls, name) is not getattr(RigorousLineScanScene, name)
                       for name in ("_omega_enu", "_relative_velocity", "_up", "_refraction_shift"))):
            return None
        return _linescan_kernel.pack_exterior(self, REFRACTIVITY_SEA_LEVEL, SCALE_HEIGHT_M, C_LIGHT)

    def focal_plane(self, ground: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Measured focal-plane coordinates (x, y) (N,) of ground points (N, 3) at times t (N,).

        As :meth:`Scene.focal_plane`, with the apparent line of sight (refraction, aberration): compiled
        (:mod:`explorer.real._linescan_kernel`), the same numbers as :meth:`focal_plane_numpy` (within 1e-9 px).
        """
        packed = self._compiled_exterior()
        if packed is None:
            return self.focal_plane_numpy(ground, t)
        ground = np.asarray(ground, dtype=np.float64)
        x, y = _linescan_kernel.ideal_focal_plane(packed, ground, np.asarray(t, dtype=np.float64))
        return self.interior.distort(x, y)

    def focal_plane_numpy(self, ground: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`focal_plane` in numpy (the reference of the compiled path; used without numba)."""
        ground = np.asarray(ground, dtype=np.float64)
        t = np.broadcast_to(np.asarray(t, dtype=np.float64), ground.shape[:1])
        fixed, moving = self.exterior.position_parts(t)
        centre = fixed + moving
        target = ground
        if self.refraction:
            target = ground + self._refraction_shift(ground, centre)
        d = (target - fixed) - moving  # (linescan.lagrange_position_from)
        if self.aberration:
            rho = np.linalg.norm(d, axis=1, keepdims=True)
            d = d / rho + self._relative_velocity(t, centre, ground) / C_LIGHT
        v = np.einsum("nji,nj->ni", self.exterior.rotation(t), d)
        scale = -self.interior.focal_length_m / v[:, 2]
        return self.interior.distort(v[:, 0] * scale, v[:, 1] * scale)

    def rays(
        self, row: np.ndarray, col: np.ndarray, height: np.ndarray | float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Lines of sight (origin (N, 3), unit direction (N, 3)) in the local frame.

        With aberration the apparent direction is corrected to the geometric one (the exact
        inverse of ``d_app = normalize(d + v_rel / c)``).  With refraction the returned straight line joins
        the perspective centre to the true ground point at ``height`` (default: the mean
        terrain height), so it is exact there; :meth:`image_to_ground` passes the
        intersection height, so its results are exact.
        """
        centre, d = super().rays(row, col)  # the apparent lines of sight, as for any scene
        if not (self.aberration or self.refraction):
            return centre, d
        t = self.scanline_time(np.broadcast_arrays(np.atleast_1d(row), np.atleast_1d(col))[0])
        h_ref = np.broadcast_to(
            np.asarray(self.terrain.mean_height if height is None else height, dtype=np.float64), t.shape
        )
        lam = (h_ref - centre[:, 2]) / d[:, 2]
        ground = centre + lam[:, None] * d
        if self.aberration:
            for _ in range(3):
                # exact inverse of d_app = normalize(d + beta): d = mu d_app - beta with |d| = 1
                beta = self._relative_velocity(t, centre, ground) / C_LIGHT
                db = np.sum(d * beta, axis=1)
                mu = db + np.sqrt(db * db - np.sum(beta * beta, axis=1) + 1.0)
                d_true = mu[:, None] * d - beta
                lam = (h_ref - centre[:, 2]) / d_true[:, 2]
                ground = centre + lam[:, None] * d_true
            d = d_true
        if self.refraction:
            apparent = ground
            true = apparent.copy()
            for _ in range(3):  # the shift is evaluated at the true point
                true = apparent - self._refraction_shift(true, centre)
            d = true - centre
            d /= np.linalg.norm(d, axis=1, keepdims=True)
        return centre, d

    def ground_to_image(
        self, ground: np.ndarray, *, row_guess: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """As :meth:`Scene.ground_to_image` (the bracketed root of this model's own residual); without
        ``row_guess`` the vendor RPC of the same image (when the metadata had one) places the first bracket
        (+-2 rows about its row), instead of sampling the whole image height: about 12 evaluations per point
        instead of 53.  The RPC only seeds the search -- a point whose residual does not change sign within the
        seeded bracket is searched over the whole image, as without it -- so the answer is this model's root."""
        if row_guess is None and self.rpc is not None:
            row_guess = self._rpc_rows(ground)
        return super().ground_to_image(ground, row_guess=row_guess)

    def _rpc_rows(self, ground: np.ndarray) -> np.ndarray | None:
        """Rows (N,) of the vendor RPC at ground points (N, 3), NaN outside its validity domain; None if it fails.

        The geodetic entry (``Scene.geodetic_to_image``) seeds from the local points too, not from the geodetic
        coordinates it was given: the model's root is resolved only to a few 1e-9 px (the residual's float64
        noise: seeds 1e-9 rows apart end 3.8e-9 px apart on WorldView-1), and the same seed makes both entries give
        the same numbers for the same local points."""
        try:
            lon, lat, h = self.frame.enu_to_geodetic(np.asarray(ground, dtype=np.float64).reshape(-1, 3))
        except Exception:  # a seed only: the search over the whole image remains
            return None
        return self._rpc_rows_geodetic(lon, lat, h)

    def _rpc_rows_geodetic(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> np.ndarray | None:
        """:meth:`_rpc_rows` of geodetic points (N,) (degrees, ellipsoidal metres)."""
        try:
            row, _, valid = self.rpc.projection(lon, lat, h, return_valid=True)
        except Exception:  # a seed only: the search over the whole image remains
            return None
        return np.ravel(np.where(valid & np.isfinite(row), row, np.nan))

    def intersect_terrain(
        self, row: np.ndarray, col: np.ndarray, terrain: Terrain | None = None, *,
        height: np.ndarray | float | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """As :meth:`Scene.intersect_terrain` (behind :meth:`Scene.image_to_ground`); the corrected lines of
        sight are evaluated at the intersection height (one extra pass on a DEM), so refraction is exact
        there too."""
        terrain = self.terrain if terrain is None else terrain
        if height is not None:
            h = check_finite(np.asarray(height, dtype=np.float64), "height")
            origin, direction = self.rays(row, col, height=h)
            return intersect_heights(origin, direction, h)
        origin, direction = self.rays(row, col, height=terrain.mean_height)
        points, flags = terrain.intersect(origin, direction)
        if self.refraction and terrain.max_height > terrain.min_height:
            # the refraction shift depends on the height: the lines of sight again at the heights found
            # (a terrain of one height was already met at its own height)
            h = np.where(np.isfinite(points[:, 2]), points[:, 2], terrain.mean_height)
            origin, direction = self.rays(row, col, height=h)
            points, flags = terrain.intersect(origin, direction)
        return points, flags

    # ------------------------------------------------------------ description
    def describe_dict(self) -> dict:
        """Numbers describing the model (epoch, sampling, altitude, view)."""
        e = self.exterior
        t_mid = np.zeros(1)
        _, lat, alt = self.frame.enu_to_geodetic(e.position(t_mid))
        t_first, t_last = self.scanline_time(np.array([0.0, self.n_rows - 1.0]))
        return {
            "name": self.name, "rows": self.n_rows, "columns": self.n_columns, "epoch_utc": self.epoch_utc,
            "line_period_s": self.timing.line_period_s, "imaging_time_s": float(t_last - t_first),
            "ephemeris_samples": int(e.ephemeris.time_s.size),
            "ephemeris_span_s": [float(e.ephemeris.time_s[0]), float(e.ephemeris.time_s[-1])],
            "attitude_samples": int(e.attitude.time_s.size),
            "attitude_span_s": [float(e.attitude.time_s[0]), float(e.attitude.time_s[-1])],
            "attitude_interpolation": e.attitude.method, "altitude_m": float(alt[0]),
            "focal_length_m": self.interior.focal_length_m, "detector_pitch_m": self.interior.detector_pitch_m,
            "aberration": self.aberration, "refraction": self.refraction,
        }  # fmt: skip

    def describe(self) -> str:
        d = self.describe_dict()
        return "\n".join([
            f"rigorous line-scan scene {d['name']}: {d['rows']} rows x {d['columns']} columns, "
            f"epoch {d['epoch_utc']}",
            f"  line period {d['line_period_s'] * 1e3:.7f} ms, imaging time {d['imaging_time_s']:.4f} s, "
            f"altitude {d['altitude_m'] / 1e3:.1f} km",
            f"  ephemeris {d['ephemeris_samples']} samples over {d['ephemeris_span_s']} s, attitude "
            f"{d['attitude_samples']} samples over {d['attitude_span_s']} s ({d['attitude_interpolation']})",
            f"  focal length {d['focal_length_m']} m, pitch {d['detector_pitch_m'] * 1e6:.4f} um, "
            f"aberration {'on' if d['aberration'] else 'off'}, refraction {'on' if d['refraction'] else 'off'}",
        ])  # fmt: skip

    # ------------------------------------------------------------ conversion
    def to_mpc_scene(self, degree: int = 3, n: int = 200, layers: int = 3, n_check: int = 400,
                     height_range: tuple[float, float] | None = None, seed: int = 0):
        """Fit an MPC :class:`~explorer.scene.Scene` (polynomials) to this rigorous model.

        :func:`explorer.real.mpc_fit.mpc_scene_from_sensor` on this model (through the
        :class:`~explorer.sensor.Sensor` interface): closed-form initial values from lines of sight
        (this model's focal length and timing), then a space resection on ``n`` image points x
        ``layers`` heights generated by this model.  The aberration of light is a nearly constant
        small rotation over a scene and is absorbed by the attitude.  The report's check points are
        an offset grid at random heights, generated by this model.

        Returns
        -------
        scene : Scene
            Same frame, timing, image size and terrain.
        report : ResectionReport
        """
        lo, hi = self._height_range() if height_range is None else height_range
        metadata = {k: v for k, v in self.metadata.items() if not isinstance(v, np.ndarray)}
        mpc, report = mpc_scene_from_sensor(
            self, height_range=(lo, hi), degree=degree, n=n, layers=layers, n_check=n_check, seed=seed,
            focal_length_m=self.interior.focal_length_m, timing=self.timing, terrain=self.terrain,
            metadata={**metadata, "source": "rigorous-to-mpc"},
        )
        report.info.update({"source": "rigorous line-scan model"})
        mpc.metadata["mpc_fit"] = report.to_dict()
        return mpc, report

    def _height_range(self) -> tuple[float, float]:
        if self.rpc is not None:
            return self.rpc.height_range(1.0)
        h = self.terrain.mean_height
        return h - 500.0, h + 500.0

    # ------------------------------------------------------------ JSON
    def to_dict(self) -> dict:
        d = super().to_dict()
        d["format"] = RIGOROUS_FORMAT
        d["model"] = {"aberration": self.aberration, "refraction": self.refraction, "epoch_utc": self.epoch_utc}
        return d

    @classmethod
    def from_dict(cls, d: dict, source: str = "<dict>") -> RigorousLineScanScene:
        if not isinstance(d, dict) or d.get("format") != RIGOROUS_FORMAT:
            raise SceneFileError(f"{source}: not a rigorous line-scan scene file")
        try:
            frame = LocalFrame.from_dict(d["frame"])
            model = d.get("model", {})
            return cls(
                name=str(d["name"]),
                interior=InteriorOrientation.from_dict(d["interior"]),
                exterior=LineScanExterior.from_dict(d["exterior"], frame),
                timing=LineTiming(float(d["timing"]["line_period_s"]), float(d["timing"]["reference_row"])),
                n_rows=int(d["n_rows"]),
                terrain=terrain_from_dict(d["terrain"]),
                frame=frame,
                metadata=dict(d.get("metadata", {})),
                aberration=bool(model.get("aberration", True)),
                refraction=bool(model.get("refraction", False)),
                epoch_utc=str(model.get("epoch_utc", "")),
            )
        except KeyError as exc:
            raise SceneFileError(f"{source}: missing field {exc.args[0]!r}") from exc
        except (TypeError, ValueError) as exc:
            raise SceneFileError(f"{source}: {exc}") from exc


def load_scene(path: str | Path) -> Scene:
    """Load an MPC scene or a rigorous line-scan scene JSON, whichever the file holds.

    Raises
    ------
    SceneFileError
        Not valid JSON, not a scene file, or a malformed one (the message names the file).
    """
    path = Path(path)
    d = load_json_file(path, "scene file")
    if isinstance(d, dict) and d.get("format") == RIGOROUS_FORMAT:
        scene: Scene = RigorousLineScanScene.from_dict(d, source=str(path))
    else:
        scene = Scene.from_dict(d, source=str(path))
    check_scene_physics(scene, str(path))  # a physical sensor, above its terrain (docs/validation.md)
    return scene
