"""The sensor interface: what every image geometry of the package offers.

A :class:`Sensor` maps between an image of ``n_rows`` x ``n_columns`` pixels and the ground, expressed
in local ENU metres of its :class:`~explorer.geometry.frames.LocalFrame` (``docs/conventions.md``):

========================================  ======================================================
implementation                            where
========================================  ======================================================
MPC scene (presets, files, resection)     :class:`explorer.scene.Scene`
rigorous line-scan model (WorldView,      :class:`explorer.real.linescan.RigorousLineScanScene`
Pleiades DIMAP)
RPC model                                 :class:`explorer.rpc.sensor.RPCSensor` (wraps a
                                          :class:`~explorer.rpc.RationalFunctionModel`)
========================================  ======================================================

Code that only needs to project, localise or outline an image (building an MPC scene from any model
by resection, :func:`explorer.real.mpc_fit.mpc_scene_from_sensor`; footprints in the explorer) takes a
:class:`Sensor` and works with all of them.  ``isinstance(obj, Sensor)`` checks the methods exist.

Optional capabilities are declared explicitly as class attributes, never discovered by catching
``AttributeError``: :class:`PolynomialExteriorSensor` (``has_polynomial_exterior = True``) says the
exterior orientation is MPC polynomials of time, which the compiled collinearity kernels
(:mod:`explorer.geometry.kernels`) pack.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:  # typing only
    from explorer.geometry.frames import LocalFrame


@runtime_checkable
class Sensor(Protocol):
    """Ground <-> image of one image, in local ENU metres of ``frame``.

    Attributes
    ----------
    name : str
    frame : LocalFrame
        Where the local ENU frame of the ground coordinates sits on the WGS84 ellipsoid.
    n_rows, n_columns : int
        Image size, pixels (rows are scanlines).
    """

    name: str

    @property
    def frame(self) -> LocalFrame: ...

    @property
    def n_rows(self) -> int: ...

    @property
    def n_columns(self) -> int: ...

    def ground_to_image(self, ground: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ground points (N, 3), local ENU metres -> (row, col), each (N,), fractional pixels (0-based,
        pixel centre); NaN where the model has no image point."""
        ...

    def image_to_ground(
        self, row: np.ndarray, col: np.ndarray, *, height: np.ndarray | float | None = None
    ) -> np.ndarray:
        """Image points (N,) -> ground points (N, 3), local ENU metres: on the plane(s) ``Z = height``
        when given, else on the sensor's own terrain; NaN rows where the line of sight misses it."""
        ...

    def footprint(self, height: float | None = None) -> np.ndarray:
        """Ground corners (4, 3) of the image (pixel edges) at a height (default: the mean terrain height),
        order (row 0, col 0), (row 0, last col), (last row, last col), (last row, col 0)."""
        ...

    def time_range(self) -> tuple[float, float]:
        """(earliest, latest) exposure time of the image, seconds on the sensor's own time axis."""
        ...


@runtime_checkable
class PolynomialExteriorSensor(Sensor, Protocol):
    """Capability: the exterior orientation is MPC polynomials of time plus jitter sinusoids
    (:class:`~explorer.geometry.exterior.ExteriorOrientation`), so the compiled kernels apply.

    Declared by the class attribute ``has_polynomial_exterior = True`` (and False where a subclass
    replaces the polynomials, e.g. by interpolated ephemeris and attitude tables).
    """

    has_polynomial_exterior: ClassVar[bool]


def has_polynomial_exterior(sensor: object) -> bool:
    """True where ``sensor`` declares the :class:`PolynomialExteriorSensor` capability."""
    return bool(getattr(type(sensor), "has_polynomial_exterior", False))


__all__ = ["PolynomialExteriorSensor", "Sensor", "has_polynomial_exterior"]
