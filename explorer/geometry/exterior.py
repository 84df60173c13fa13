"""Exterior orientation per scanline: the Multiple Projection Center (MPC) model.

The perspective centre ``S(t) = (X_S, Y_S, Z_S)`` and the attitude angles
``(omega, phi, kappa)(t)`` are polynomials of the scanline time ``t`` (seconds,
``t = 0`` at the reference row; ``docs/conventions.md#time``), any degree, plus
optional sinusoidal attitude jitter.  Rotation order: ``explorer.geometry.rotations``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from explorer.errors import InputError
from explorer.geometry.rotations import rotation_from_opk

ANGLE_NAMES = ("omega", "phi", "kappa")


@dataclass(frozen=True)
class Jitter:
    """One sinusoidal attitude disturbance ``amplitude * sin(2 pi frequency t + phase)``.

    Parameters
    ----------
    angle : {"omega", "phi", "kappa"}
    amplitude_rad : float
    frequency_hz : float
    phase_rad : float
    """

    angle: str
    amplitude_rad: float
    frequency_hz: float
    phase_rad: float = 0.0

    def __post_init__(self) -> None:
        if self.angle not in ANGLE_NAMES:
            raise ValueError(f"jitter angle must be one of {ANGLE_NAMES}, got {self.angle!r}")
        for name in ("amplitude_rad", "frequency_hz", "phase_rad"):  # numbers, finite (a scene file may hold anything)
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise InputError(f"jitter {name} must be a number, got {value!r}")
            if not np.isfinite(float(value)):
                raise InputError(f"jitter {name} must be finite, got {value!r}")
            object.__setattr__(self, name, float(value))


def polyval_ascending(coeffs: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Evaluate polynomials with ascending coefficients by Horner's rule.

    Parameters
    ----------
    coeffs : ndarray, shape (K, D+1)
        ``coeffs[k, j]`` multiplies ``t**j``.
    t : ndarray, shape (N,)

    Returns
    -------
    ndarray, shape (N, K)
    """
    t = np.asarray(t)
    out = np.broadcast_to(coeffs[:, -1], t.shape + (coeffs.shape[0],)).astype(
        np.result_type(t, np.float64), copy=True
    )
    for j in range(coeffs.shape[1] - 2, -1, -1):
        out *= t[..., None]
        out += coeffs[:, j]
    return out


def _derivative_coeffs(coeffs: np.ndarray) -> np.ndarray:
    d = coeffs.shape[1]
    if d == 1:
        return np.zeros_like(coeffs)
    return coeffs[:, 1:] * np.arange(1, d, dtype=np.float64)


@dataclass
class ExteriorOrientation:
    """MPC exterior orientation.

    Parameters
    ----------
    position_coeffs : ndarray, shape (3, D+1)
        Ascending polynomial coefficients of X_S, Y_S, Z_S in t: metres, m/s, m/s^2, ...
    attitude_coeffs : ndarray, shape (3, D+1)
        Ascending polynomial coefficients of omega, phi, kappa: rad, rad/s, ...
    jitter : list of Jitter
    """

    position_coeffs: np.ndarray
    attitude_coeffs: np.ndarray
    jitter: list[Jitter] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.position_coeffs = np.atleast_2d(np.asarray(self.position_coeffs, dtype=np.float64))
        self.attitude_coeffs = np.atleast_2d(np.asarray(self.attitude_coeffs, dtype=np.float64))
        for name, c in (("position_coeffs", self.position_coeffs), ("attitude_coeffs", self.attitude_coeffs)):
            if c.shape[0] != 3 or c.shape[1] < 1:
                raise ValueError(f"{name} must have shape (3, degree + 1), got {c.shape}")
            if not np.all(np.isfinite(c)):
                raise ValueError(f"{name} contains NaN or infinite values")
        self.jitter = [j if isinstance(j, Jitter) else Jitter(**j) for j in self.jitter]

    @property
    def is_constant_velocity_and_attitude(self) -> bool:
        """True when S(t) is linear in t and the attitude is constant (no jitter)."""
        return (
            not np.any(self.position_coeffs[:, 2:])
            and not np.any(self.attitude_coeffs[:, 1:])
            and not self.jitter
        )

    def position(self, t: np.ndarray) -> np.ndarray:
        """Perspective centre S(t), shape (N, 3), metres."""
        return polyval_ascending(self.position_coeffs, np.asarray(t, dtype=np.float64))

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """dS/dt, shape (N, 3), m/s."""
        return polyval_ascending(_derivative_coeffs(self.position_coeffs), np.asarray(t, dtype=np.float64))

    def angles(self, t: np.ndarray) -> np.ndarray:
        """(omega, phi, kappa)(t) including jitter, shape (N, 3), radians."""
        t = np.asarray(t, dtype=np.float64)
        out = polyval_ascending(self.attitude_coeffs, t)
        for j in self.jitter:
            k = ANGLE_NAMES.index(j.angle)
            out[..., k] += j.amplitude_rad * np.sin(2.0 * np.pi * j.frequency_hz * t + j.phase_rad)
        return out

    def angle_rates(self, t: np.ndarray) -> np.ndarray:
        """d(omega, phi, kappa)/dt including jitter, shape (N, 3), rad/s."""
        t = np.asarray(t, dtype=np.float64)
        out = polyval_ascending(_derivative_coeffs(self.attitude_coeffs), t)
        for j in self.jitter:
            k = ANGLE_NAMES.index(j.angle)
            w = 2.0 * np.pi * j.frequency_hz
            out[..., k] += j.amplitude_rad * w * np.cos(w * t + j.phase_rad)
        return out

    def rotation(self, t: np.ndarray) -> np.ndarray:
        """Sensor -> object rotation R(t), shape (N, 3, 3)."""
        a = self.angles(t)
        return rotation_from_opk(a[..., 0], a[..., 1], a[..., 2])

    def to_dict(self) -> dict:
        """JSON-ready dict (exact float round trip)."""
        return {
            "position_coeffs": self.position_coeffs.tolist(),
            "attitude_coeffs": self.attitude_coeffs.tolist(),
            "jitter": [
                {"angle": j.angle, "amplitude_rad": j.amplitude_rad, "frequency_hz": j.frequency_hz,
                 "phase_rad": j.phase_rad}
                for j in self.jitter
            ],
        }

    @classmethod
    def from_dict(cls, d: dict) -> ExteriorOrientation:
        """Inverse of :meth:`to_dict`."""
        return cls(
            position_coeffs=np.asarray(d["position_coeffs"], dtype=np.float64),
            attitude_coeffs=np.asarray(d["attitude_coeffs"], dtype=np.float64),
            jitter=[Jitter(**j) for j in d.get("jitter", [])],
        )


@dataclass(frozen=True)
class LineTiming:
    """Row <-> scanline time: ``t = (row - reference_row) * line_period_s``.

    Rows are 0-based with integer = pixel centre; a fractional row is a time between
    two exposures (``docs/conventions.md#time``).
    """

    line_period_s: float
    reference_row: float

    def __post_init__(self) -> None:
        if not self.line_period_s > 0:
            raise ValueError(f"line_period_s must be positive, got {self.line_period_s}")

    def scanline_time(self, row: ArrayLike) -> np.ndarray:
        """Row (N,) -> exposure time (N,), seconds."""
        return (np.asarray(row, dtype=np.float64) - self.reference_row) * self.line_period_s

    def row_at_time(self, t: np.ndarray) -> np.ndarray:
        """Exposure time (N,) seconds -> row (N,)."""
        return np.asarray(t, dtype=np.float64) / self.line_period_s + self.reference_row
