"""Exterior corrections of a rigorous or CSM line scanner: position and attitude offsets, drifts, jitter.

A line scanner's exterior orientation is given by tables sampled along its line time: positions (ECEF for a
rigorous DIMAP/DG model, :class:`explorer.real.linescan.Ephemeris`; the ISD's position table for a USGS CSM
camera, :class:`explorer.real.csm_camera.CsmCamera`) and attitude quaternions.  A correction is a smooth
function of the line time ``tau = t - t_ref`` (``t_ref`` the middle of the image's exposure, stated in the
sidecar) **applied to every table sample**; between samples the corrected tables are interpolated as the model
interpolates its own (Lagrange / slerp).  So the adjusted model is the same kind of model, read by the same
compiled code, and the differentiable model (:mod:`explorer.refine.torch_linescan`) evaluates exactly the
same function.  A constant offset or a linear drift of the position and a constant attitude offset are
reproduced exactly by the interpolation; an attitude drift or a harmonic is the model's interpolation of it
(harmonics must lie below the Nyquist frequency of the attitude table, checked).

Position offsets (metres) and drifts (m/s) are in the **orbital frame at t_ref**, fixed for the image:
``radial`` (away from the body's centre), ``along`` (the velocity direction made orthogonal to radial) and
``cross = radial x along`` (a right-handed triad along, cross, radial), computed from the
model's own trajectory in the frame of its position table (ECEF for DIMAP/DG and body-fixed ISDs, J2000 for
an ISD whose positions are J2000).

Attitude offsets (radians) and drifts (rad/s) are a rotation ``R_delta = R_x(roll) R_y(pitch) R_z(yaw)``
about the **sensor's own axes**, applied on the sensor side: a ground vector's sensor coordinates become
``R_delta^T R^T (P - S)``.  The axes are those of ``docs/conventions.md#frames`` for a rigorous model (x along
the image rows, i.e. the flight direction; y along increasing columns; z away from the ground), and
usgscsm's camera frame for a CSM camera (x, y of its focal plane, z its optical axis).

Models (:data:`LINE_MODELS`):

- ``attitude``: roll, pitch, yaw offsets (3);
- ``attitude-drift``: and their drifts (6);
- ``position-attitude``: along / cross / radial position offsets and the attitude offsets (6);
- ``position-attitude-drift``: both offsets and both drifts (12);
- ``jitter``: ``attitude-drift`` plus, per stated frequency ``f_k`` and axis, a harmonic
  ``s sin(2 pi f_k tau) + c cos(2 pi f_k tau)`` (radians; amplitude ``hypot(s, c)`` and phase ``atan2(c, s)``
  of ``A sin(2 pi f tau + phase)`` are reported).  Default frequencies: ``1 / T`` and ``2 / T``, ``T`` the
  image's exposure time (the two lowest harmonics over the image).

The functions take numpy arrays or torch tensors (the same operations), so the corrected tables are identical
in both paths.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from explorer.errors import InputError

__all__ = ["LINE_MODELS", "LineCorrection", "file_sha256", "line_model_names", "orbital_axes",
           "quaternion_multiply", "quaternion_of_axis_angle"]

_ATT = ("roll_rad", "pitch_rad", "yaw_rad")
_ATT_RATE = ("roll_rad_per_s", "pitch_rad_per_s", "yaw_rad_per_s")
_POS = ("along_m", "cross_m", "radial_m")
_POS_RATE = ("along_m_per_s", "cross_m_per_s", "radial_m_per_s")

#: Parameter names of the fixed part of each model (``jitter`` adds harmonics, :meth:`LineCorrection.names`).
LINE_MODELS: dict[str, tuple[str, ...]] = {
    "attitude": _ATT,
    "attitude-drift": _ATT + _ATT_RATE,
    "position-attitude": _POS + _ATT,
    "position-attitude-drift": _POS + _ATT + _POS_RATE + _ATT_RATE,
    "jitter": _ATT + _ATT_RATE,
}


def line_model_names() -> tuple[str, ...]:
    """The correction models of a rigorous / CSM line scanner."""
    return tuple(LINE_MODELS)


def file_sha256(path: str | Path) -> str:
    """SHA-256 hex digest of a file (the base model a sidecar adjusts)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def orbital_axes(position: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """Columns (along, cross, radial) (3, 3) of the orbital frame of a position and velocity (3,)."""
    radial = np.asarray(position, dtype=np.float64) / np.linalg.norm(position)
    v = np.asarray(velocity, dtype=np.float64)
    along = v - np.dot(v, radial) * radial
    along /= np.linalg.norm(along)
    cross = np.cross(radial, along)
    return np.stack([along, cross, radial], axis=1)


def quaternion_multiply(a: Any, b: Any) -> Any:
    """Hamilton product ``a b`` of quaternions (..., 4) ``(w, x, y, z)`` (numpy or torch)."""
    aw, ax, ay, az = (a[..., k] for k in range(4))
    bw, bx, by, bz = (b[..., k] for k in range(4))
    parts = (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
             aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)
    return _stack(parts, a)


def quaternion_of_axis_angle(axis: np.ndarray, angle: Any) -> Any:
    """Unit quaternions (..., 4) of rotations by ``angle`` (...) about a fixed unit ``axis`` (3,)."""
    s = _sin(angle * 0.5)
    return _stack((_cos(angle * 0.5), s * float(axis[0]), s * float(axis[1]), s * float(axis[2])), angle)


def _is_torch(x: Any) -> bool:
    return type(x).__module__.startswith("torch")


def _stack(parts: tuple, like: Any) -> Any:
    if _is_torch(like):
        import torch

        return torch.stack(parts, dim=-1)
    return np.stack(parts, axis=-1)


def _sin(x: Any) -> Any:
    if _is_torch(x):
        import torch

        return torch.sin(x)
    return np.sin(x)


def _cos(x: Any) -> Any:
    if _is_torch(x):
        import torch

        return torch.cos(x)
    return np.cos(x)


@dataclass
class LineCorrection:
    """One correction model of one line scanner (everything a sidecar needs to re-apply it).

    Parameters
    ----------
    model : str
        One of :data:`LINE_MODELS`.
    reference_time_s : float
        ``t_ref`` on the clock of the model's tables, seconds.
    axes : ndarray, shape (3, 3)
        Columns along, cross, radial (:func:`orbital_axes`) in the frame of the position table.
    frequencies_hz : tuple of float
        Jitter harmonics (``jitter`` only).
    """

    model: str
    reference_time_s: float
    axes: np.ndarray
    frequencies_hz: tuple[float, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if self.model not in LINE_MODELS:
            raise InputError(f"unknown line-scanner correction model {self.model!r} (one of "
                             f"{', '.join(LINE_MODELS)})")
        self.axes = np.asarray(self.axes, dtype=np.float64).reshape(3, 3)
        self.frequencies_hz = tuple(float(f) for f in self.frequencies_hz) if self.model == "jitter" else ()
        if self.model == "jitter" and not self.frequencies_hz:
            raise InputError("the jitter model needs at least one frequency")
        if any(not (math.isfinite(f) and f > 0) for f in self.frequencies_hz):
            raise InputError(f"jitter frequencies must be finite and > 0 Hz, got {self.frequencies_hz}")

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names in the order of the parameter vector."""
        names = LINE_MODELS[self.model]
        for k in range(1, len(self.frequencies_hz) + 1):
            names = names + tuple(f"{axis}_{part}{k}_rad" for axis in ("roll", "pitch", "yaw")
                                  for part in ("sin", "cos"))
        return names

    @property
    def n_parameters(self) -> int:
        return len(self.parameter_names)

    @property
    def has_position(self) -> bool:
        return self.model.startswith("position")

    # -------------------------------------------------------------- the correction functions
    def _get(self, p: Any, name: str) -> Any:
        names = self.parameter_names
        return p[..., names.index(name)] if name in names else None

    def position_offset_orbital(self, tau: Any, p: Any) -> list[Any] | None:
        """(along, cross, radial) offsets, each shaped as ``tau`` (broadcast with ``p[..., k]``); None
        without position parameters."""
        if not self.has_position:
            return None
        out = []
        for name, rate in zip(_POS, _POS_RATE, strict=True):
            value = self._get(p, name) + 0.0 * tau
            r = self._get(p, rate)
            out.append(value if r is None else value + r * tau)
        return out

    def position_offset(self, tau: Any, p: Any) -> Any:
        """Position offsets (..., 3) in the frame of the position table at ``tau = t - t_ref`` (...)."""
        o = self.position_offset_orbital(tau, p)
        if o is None:
            return None
        a = self.axes
        return _stack(tuple(o[0] * a[i, 0] + o[1] * a[i, 1] + o[2] * a[i, 2] for i in range(3)), o[0])

    def angles(self, tau: Any, p: Any) -> list[Any]:
        """[roll, pitch, yaw] (radians) at ``tau = t - t_ref`` (...)."""
        out = []
        for i, (name, rate) in enumerate(zip(_ATT, _ATT_RATE, strict=True)):
            value = self._get(p, name) + 0.0 * tau
            r = self._get(p, rate)
            if r is not None:
                value = value + r * tau
            for k, f in enumerate(self.frequencies_hz, start=1):
                axis = ("roll", "pitch", "yaw")[i]
                w = (2.0 * math.pi * f) * tau
                value = (value + self._get(p, f"{axis}_sin{k}_rad") * _sin(w)
                         + self._get(p, f"{axis}_cos{k}_rad") * _cos(w))
            out.append(value)
        return out

    def rotation_quaternion(self, tau: Any, p: Any, axes: np.ndarray, sign: float = 1.0,
                            inverse: bool = False) -> Any:
        """Quaternion (..., 4) of ``A R_delta A^T`` (``inverse``: of its transpose) for a proper or improper
        3 x 3 ``axes`` ``A`` (the rotations about ``A``'s columns by ``det(A)`` times the angles)."""
        roll, pitch, yaw = self.angles(tau, p)
        det = float(np.sign(np.linalg.det(axes))) * sign
        parts = [quaternion_of_axis_angle(axes[:, k], det * a) for k, a in enumerate((roll, pitch, yaw))]
        if inverse:  # (R_x R_y R_z)^T = R_z^T R_y^T R_x^T
            parts = [quaternion_of_axis_angle(axes[:, k], -det * a) for k, a in enumerate((roll, pitch, yaw))][::-1]
        q = quaternion_multiply(parts[0], parts[1])
        return quaternion_multiply(q, parts[2])

    def check_sampling(self, attitude_times: np.ndarray, what: str) -> None:
        """InputError when a jitter frequency is at or above the attitude table's Nyquist frequency."""
        if not self.frequencies_hz or attitude_times.size < 2:
            return
        nyquist = 0.5 / float(np.max(np.diff(attitude_times)))
        high = [f for f in self.frequencies_hz if f >= nyquist]
        if high:
            raise InputError(f"jitter frequency {high[0]:g} Hz is at or above the Nyquist frequency of the {what} "
                             f"attitude table ({nyquist:g} Hz): the corrected table cannot represent it")

    def harmonics(self, p: np.ndarray) -> list[dict[str, Any]]:
        """Amplitude (rad) and phase (rad) of each harmonic and axis: ``A sin(2 pi f tau + phase)``."""
        out = []
        for k, f in enumerate(self.frequencies_hz, start=1):
            for axis in ("roll", "pitch", "yaw"):
                s, c = float(self._get(p, f"{axis}_sin{k}_rad")), float(self._get(p, f"{axis}_cos{k}_rad"))
                out.append({"axis": axis, "frequency_hz": f, "amplitude_rad": math.hypot(s, c),
                            "phase_rad": math.atan2(c, s)})
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.model, "reference_time_s": self.reference_time_s,
                "orbital_axes_columns_along_cross_radial": self.axes.tolist(),
                "frequencies_hz": list(self.frequencies_hz), "parameter_names": list(self.parameter_names)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LineCorrection:
        return cls(str(d["model"]), float(d["reference_time_s"]),
                   np.asarray(d["orbital_axes_columns_along_cross_radial"], dtype=np.float64),
                   tuple(d.get("frequencies_hz", ())))
