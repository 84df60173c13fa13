"""Interior orientation of a linear-array pushbroom camera.

Focal-plane coordinates are metres: x along track, y across track, principal point
at (0, 0), see ``docs/conventions.md#focal-plane``.  Detector ``col`` (0-based,
integer = detector centre) sits at

    y = (col - principal_column) * detector_pitch
    x = along_track_offset + sum_k line_curvature[k-1] * y**k     (k >= 1)

Optionally the detectors are unevenly spaced (products resampled to a uniform ground spacing,
look-angle tables): with ``u = col - principal_column`` (pixels),
``y = detector_pitch * (u + sum_k column_polynomial[k-2] * u**k)`` (k >= 2); empty by default.

The lens may add radial distortion; ``distort`` maps ideal (pinhole) focal-plane
coordinates to the measured ones, ``undistort`` inverts it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class InteriorOrientation:
    """Camera constants.

    Parameters
    ----------
    focal_length_m : float
        Principal distance, metres.
    detector_pitch_m : float
        Detector spacing across track, metres.
    n_columns : int
        Number of detectors (image columns).
    principal_column : float or None
        Column of the principal point (0-based, pixel centre); ``None`` means the
        array centre ``(n_columns - 1) / 2``.
    along_track_offset_m : float
        Along-track position of the detector line in the focal plane, metres.
    line_curvature : tuple of float
        Coefficients ``c1, c2, ...`` of the detector line shape
        ``x(y) = offset + c1 y + c2 y**2 + ...`` (units m^(1-k)).
    radial_distortion : tuple of float
        ``k1, k2, ...`` of ``r_d = r (1 + k1 r**2 + k2 r**4 + ...)`` (units m^-2k).
    column_polynomial : tuple of float
        ``a2, a3, ...`` of a non-uniform detector spacing
        ``y = pitch * (u + a2 u**2 + a3 u**3 + ...)``, ``u = col - principal_column`` in pixels
        (units px^(1-k)).  Empty (default): evenly spaced detectors.  ``y`` must stay monotonic
        in ``col`` over the array.
    """

    focal_length_m: float
    detector_pitch_m: float
    n_columns: int
    # None (the default) means the image centre; always a float after __post_init__
    principal_column: float = None  # type: ignore[assignment]
    along_track_offset_m: float = 0.0
    line_curvature: tuple[float, ...] = field(default_factory=tuple)
    radial_distortion: tuple[float, ...] = field(default_factory=tuple)
    column_polynomial: tuple[float, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if not (self.focal_length_m > 0 and self.detector_pitch_m > 0):
            raise ValueError("focal_length_m and detector_pitch_m must be positive")
        if int(self.n_columns) < 2:
            raise ValueError(f"n_columns must be >= 2, got {self.n_columns}")
        self.n_columns = int(self.n_columns)
        if self.principal_column is None:
            self.principal_column = (self.n_columns - 1) / 2.0
        self.principal_column = float(self.principal_column)
        self.line_curvature = tuple(float(c) for c in self.line_curvature)
        self.radial_distortion = tuple(float(k) for k in self.radial_distortion)
        self.column_polynomial = tuple(float(a) for a in self.column_polynomial)

    @property
    def has_uniform_spacing(self) -> bool:
        """True when the detectors are evenly spaced (``column_to_y`` is linear)."""
        return not any(self.column_polynomial)

    @property
    def is_straight_line(self) -> bool:
        """True when the detector line is straight through x = offset, there is no distortion and
        the detectors are evenly spaced (the simplest model; fast paths may assume it)."""
        return not any(self.line_curvature) and not any(self.radial_distortion) and self.has_uniform_spacing

    def _spacing(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``g(u) = u + sum a_k u**k`` and ``g'(u)`` for offsets u (pixels)."""
        g = u.copy()
        dg = np.ones_like(u)
        power = u.copy()  # u**(k-1)
        for k, a in enumerate(self.column_polynomial, start=2):
            dg = dg + k * a * power
            power = power * u
            g = g + a * power
        return g, dg

    def column_to_y(self, col: np.ndarray) -> np.ndarray:
        """Detector column (N,) -> across-track focal-plane coordinate y (N,), metres."""
        u = np.asarray(col, dtype=np.float64) - self.principal_column
        if self.column_polynomial:
            u = self._spacing(u)[0]
        return u * self.detector_pitch_m

    def y_to_column(self, y: np.ndarray) -> np.ndarray:
        """Across-track focal-plane coordinate y (N,), metres -> column (N,).

        With a ``column_polynomial`` the inverse is found by Newton's method (to 1e-12 px)."""
        target = np.asarray(y, dtype=np.float64) / self.detector_pitch_m
        if not self.column_polynomial:
            return target + self.principal_column
        u = target.copy()
        for _ in range(30):
            g, dg = self._spacing(u)
            step = (g - target) / dg
            u = u - step
            if np.all(np.abs(step[np.isfinite(step)]) < 1e-12):
                break
        return u + self.principal_column

    def detector_x(self, y: np.ndarray) -> np.ndarray:
        """Along-track position of the detector line at y (N,) metres -> x (N,) metres."""
        y = np.asarray(y, dtype=np.float64)
        x = np.full_like(y, self.along_track_offset_m)
        power = np.ones_like(y)
        for c in self.line_curvature:
            power = power * y
            x = x + c * power
        return x

    def _radial_factor(self, r2: np.ndarray) -> np.ndarray:
        factor = np.ones_like(r2)
        power = np.ones_like(r2)
        for k in self.radial_distortion:
            power = power * r2
            factor = factor + k * power
        return factor

    def distort(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal focal-plane coordinates (N,), (N,) metres -> measured (distorted) ones."""
        if not self.radial_distortion:
            return x, y
        f = self._radial_factor(x * x + y * y)
        return x * f, y * f

    def undistort(
        self, xd: np.ndarray, yd: np.ndarray, iterations: int = 20
    ) -> tuple[np.ndarray, np.ndarray]:
        """Measured focal-plane coordinates -> ideal ones (fixed-point iteration, to < 1e-15 m
        for distortions below a few pixels)."""
        if not self.radial_distortion:
            return xd, yd
        x, y = xd, yd
        for _ in range(iterations):
            f = self._radial_factor(x * x + y * y)
            x, y = xd / f, yd / f
        return x, y

    def detector_focal_plane(self, col: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Measured focal-plane coordinates (x, y) of detector ``col`` (N,), metres."""
        y = self.column_to_y(col)
        return self.detector_x(y), y

    def to_dict(self) -> dict:
        """JSON-ready dict (exact float round trip)."""
        d = {
            "focal_length_m": self.focal_length_m,
            "detector_pitch_m": self.detector_pitch_m,
            "n_columns": self.n_columns,
            "principal_column": self.principal_column,
            "along_track_offset_m": self.along_track_offset_m,
            "line_curvature": list(self.line_curvature),
            "radial_distortion": list(self.radial_distortion),
        }
        if self.column_polynomial:
            d["column_polynomial"] = list(self.column_polynomial)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> InteriorOrientation:
        """Inverse of :meth:`to_dict`."""
        return cls(
            focal_length_m=float(d["focal_length_m"]),
            detector_pitch_m=float(d["detector_pitch_m"]),
            n_columns=int(d["n_columns"]),
            principal_column=d.get("principal_column"),  # type: ignore[arg-type]  # None: the image centre
            along_track_offset_m=float(d.get("along_track_offset_m", 0.0)),
            line_curvature=tuple(d.get("line_curvature", ())),
            radial_distortion=tuple(d.get("radial_distortion", ())),
            column_polynomial=tuple(d.get("column_polynomial", ())),
        )
