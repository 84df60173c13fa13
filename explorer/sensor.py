"""The sensor interface: what every image geometry of the package offers.

A :class:`Sensor` maps between an image of ``n_rows`` x ``n_columns`` pixels and the ground, expressed
in local ENU metres of its :class:`~explorer.geometry.frames.LocalFrame` on the sensor's ``body`` (the
ellipsoid of the file: WGS84, Mars, the Moon ...; ``docs/conventions.md``):

========================================  ======================================================
implementation                            where
========================================  ======================================================
MPC scene (presets, files, resection)     :class:`explorer.scene.Scene`
rigorous line-scan model (WorldView,      :class:`explorer.real.linescan.RigorousLineScanScene`
Pleiades DIMAP)
USGS CSM line-scan camera (ISD)           :class:`explorer.real.csm_sensor.CsmScene` (wraps a
                                          :class:`~explorer.real.csm_camera.CsmCamera`)
RPC model                                 :class:`explorer.rpc.sensor.RPCSensor` (wraps a
                                          :class:`~explorer.rpc.RationalFunctionModel`)
========================================  ======================================================

What every sensor offers:

* ``ground_to_image(ground) -> (row, col)`` and ``project(ground) -> Projection(row, col, valid)``
  (``valid``: the model solved the point and it lies on the image, pixel edges included);
* the same from geodetic coordinates, ``geodetic_to_image(lon, lat, h)`` and ``project_geodetic(lon, lat, h)``
  (degrees, metres above the ellipsoid of ``body``): callers whose points are geodetic (GCP files, orthoimage
  grids in a geographic CRS, an RPC's own localisations) hand them over as they are, and each sensor converts
  them only into the coordinates its model is defined on -- nothing for an RPC, body-fixed for a CSM camera,
  the local frame for a scene (``docs/conventions.md#geodetic-entry``).  An RPC asked in local ENU pays
  an exact ENU -> geodetic conversion that costs several RPC evaluations; asked in geodetic coordinates it is
  within a few per cent of the RPC itself (``benchmarks/sensor_path.py``);
* ``image_to_ground(row, col, height=...)`` on the plane(s) ``Z = height``, or on the sensor's own
  terrain (plane or DEM; first hit from the sensor); ``localize(row, col, height=...) -> Localization
  (ground, flags)`` says per point why there is no ground point (outside the DEM, no-data, no hit);
* ``n_rows``, ``n_columns``, ``footprint(height)``, ``time_range()``, ``frame`` and ``body``.

Optional capabilities are declared explicitly as class attributes, never discovered by catching
``AttributeError``:

* :class:`LineGeometrySensor` (``has_line_geometry = True``): the model has physical scanlines --
  the time of a line, the perspective centre and attitude at a time, the look direction of a detector
  position -- so the best-scanline *search* methods (ss, bws, nr, exact, csm-secant ...) run on it.
  Declared by the scenes (MPC, rigorous DIMAP / DG, CSM); an RPC has no lines (False);
* :class:`PolynomialExteriorSensor` (``has_polynomial_exterior = True``): the exterior orientation is
  MPC polynomials of time, which the compiled collinearity kernels (:mod:`explorer.geometry.kernels`)
  pack;
* :class:`GeodeticSensor` (``has_geodetic_projection = True``): the model is defined on longitude, latitude
  and ellipsoidal height (an RPC), so it localises in them too (on heights, on a lon/lat DEM) and
  orthorectification asks it without the local-frame round trip.
* :class:`LineCoverageSensor` (``has_line_coverage = True``): its tables may cover only some lines (a CSM
  camera); ``rows_covered(row)`` says which, and every best-scanline method flags a row outside them.

Code that only needs to project, localise or outline an image (building an MPC scene from any model
by resection, :func:`explorer.real.mpc_fit.mpc_scene_from_sensor`; footprints in the explorer) takes a
:class:`Sensor` and works with all of them.  ``isinstance(obj, Sensor)`` checks the methods exist.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple, Protocol, cast, runtime_checkable

import numpy as np

if TYPE_CHECKING:  # typing only
    from explorer.geometry.frames import Ellipsoid, LocalFrame

#: ``Localization.flags`` codes (as :mod:`explorer.geometry.dem_intersection`).
FLAG_OK, FLAG_OUTSIDE_DEM, FLAG_NO_DATA, FLAG_NO_HIT = 0, 1, 2, 3
FLAG_NAMES = {FLAG_OK: "ok", FLAG_OUTSIDE_DEM: "outside the DEM", FLAG_NO_DATA: "DEM no-data",
              FLAG_NO_HIT: "no intersection"}


class Projection(NamedTuple):
    """Result of :meth:`Sensor.project`.

    row, col : ndarray (N,)
        Fractional image coordinates (0-based, pixel centre; ``docs/conventions.md#pixels``); NaN where
        the model has no image point.
    valid : ndarray of bool (N,)
        The model solved the point and (row, col) lies on the image, pixel edges included
        (``-0.5 <= row <= n_rows - 0.5``, same for columns).
    """

    row: np.ndarray
    col: np.ndarray
    valid: np.ndarray


class Localization(NamedTuple):
    """Result of :meth:`Sensor.localize`.

    ground : ndarray (N, 3)
        Local ENU metres; NaN rows where there is no ground point.
    flags : ndarray of int8 (N,)
        :data:`FLAG_OK` (0), :data:`FLAG_OUTSIDE_DEM` (1), :data:`FLAG_NO_DATA` (2), :data:`FLAG_NO_HIT` (3).
    """

    ground: np.ndarray
    flags: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """True where a ground point was found."""
        return np.asarray(self.flags == FLAG_OK, dtype=bool)


def inside_image(row: np.ndarray, col: np.ndarray, n_rows: int, n_columns: int) -> np.ndarray:
    """True where (row, col) lies on an ``n_rows`` x ``n_columns`` image, pixel edges included (NaN: False)."""
    row = np.asarray(row, dtype=np.float64)
    col = np.asarray(col, dtype=np.float64)
    return (row >= -0.5) & (row <= n_rows - 0.5) & (col >= -0.5) & (col <= n_columns - 0.5)


@runtime_checkable
class Sensor(Protocol):
    """Ground <-> image of one image, in local ENU metres of ``frame`` on ``body``.

    Attributes
    ----------
    name : str
    frame : LocalFrame
        Where the local ENU frame of the ground coordinates sits on the body's ellipsoid.
    body : Ellipsoid
        The body (``frame.body``): WGS84 for Earth images, the file's radii for a CSM camera.
    n_rows, n_columns : int
        Image size, pixels (rows are scanlines).
    has_line_geometry : bool (class attribute)
        The :class:`LineGeometrySensor` capability.
    """

    name: str
    has_line_geometry: ClassVar[bool]

    @property
    def frame(self) -> LocalFrame: ...

    @property
    def body(self) -> Ellipsoid: ...

    @property
    def n_rows(self) -> int: ...

    @property
    def n_columns(self) -> int: ...

    def ground_to_image(self, ground: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ground points (N, 3), local ENU metres -> (row, col), each (N,), fractional pixels (0-based,
        pixel centre); NaN where the model has no image point."""
        ...

    def project(self, ground: np.ndarray) -> Projection:
        """:meth:`ground_to_image` with the validity flags (:class:`Projection`)."""
        ...

    def geodetic_to_image(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The geodetic entry of :meth:`ground_to_image`: ground points given as longitude, latitude (N,) degrees
        and height above the ellipsoid of :attr:`body` (N,) metres -> (row, col) (N,), the same numbers as
        ``ground_to_image(frame.geodetic_to_enu(lon, lat, h))``; the sensor converts them only into the
        coordinates its model is defined on (none for an RPC, body-fixed for a CSM camera, the local frame for a
        scene; ``docs/conventions.md#geodetic-entry``)."""
        ...

    def project_geodetic(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> Projection:
        """:meth:`geodetic_to_image` with the validity flags of :meth:`project` (:class:`Projection`)."""
        ...

    def image_to_ground(
        self, row: np.ndarray, col: np.ndarray, *, height: np.ndarray | float | None = None
    ) -> np.ndarray:
        """Image points (N,) -> ground points (N, 3), local ENU metres: on the plane(s) ``Z = height``
        when given, else on the sensor's own terrain; NaN rows where the line of sight misses it."""
        ...

    def localize(
        self, row: np.ndarray, col: np.ndarray, *, height: np.ndarray | float | None = None
    ) -> Localization:
        """:meth:`image_to_ground` with a flag per point (:class:`Localization`): on a DEM the first
        intersection from the sensor."""
        ...

    def footprint(self, height: float | None = None) -> np.ndarray:
        """Ground corners (4, 3) of the image (pixel edges) at a height (default: the mean terrain height),
        order (row 0, col 0), (row 0, last col), (last row, last col), (last row, col 0)."""
        ...

    def time_range(self) -> tuple[float, float]:
        """(earliest, latest) exposure time of the image, seconds on the sensor's own time axis."""
        ...


@runtime_checkable
class LineGeometrySensor(Sensor, Protocol):
    """Capability: physical scanlines (declared by ``has_line_geometry = True``).

    Times are seconds on the sensor's own clock (``line_time``); rotations map camera axes to local ENU
    (``docs/conventions.md#rotations``: the camera looks along its ``-z`` axis).
    """

    def line_time(self, row: np.ndarray) -> np.ndarray:
        """Exposure time (N,) of (fractional) rows (N,), seconds."""
        ...

    def perspective_centre(self, t: np.ndarray) -> np.ndarray:
        """Perspective centres (N, 3), local ENU metres, at times (N,) seconds."""
        ...

    def attitude(self, t: np.ndarray) -> np.ndarray:
        """Camera -> local ENU rotations (N, 3, 3) at times (N,) seconds."""
        ...

    def look_direction(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """Unit lines of sight (N, 3), local ENU, of detector position ``col`` at the time of ``row``
        (everything the model applies: distortion, detector layout, aberration ...)."""
        ...


@runtime_checkable
class PolynomialExteriorSensor(Sensor, Protocol):
    """Capability: the exterior orientation is MPC polynomials of time plus jitter sinusoids
    (:class:`~explorer.geometry.exterior.ExteriorOrientation`), so the compiled kernels apply.

    Declared by the class attribute ``has_polynomial_exterior = True`` (and False where a subclass
    replaces the polynomials, e.g. by interpolated ephemeris and attitude tables).
    """

    has_polynomial_exterior: ClassVar[bool]


@runtime_checkable
class LineCoverageSensor(LineGeometrySensor, Protocol):
    """Capability: the line geometry is defined on some of the image's lines only -- interpolated ephemeris tables
    (a USGS CSM ISD's position / pointing / body-rotation tables) that stop before the last line or start after
    the first.  Lines outside them are flagged, never extrapolated: a best-scanline method whose row falls there
    has no answer (``explorer.methods.base``: status "outside tables").

    Declared by the class attribute ``has_line_coverage = True`` (:class:`explorer.real.csm_sensor.CsmScene`).
    """

    has_line_coverage: ClassVar[bool]

    def rows_covered(self, row: np.ndarray) -> np.ndarray:
        """True (N,) where the time of (fractional) rows (N,) lies inside the sensor's tables (False for NaN)."""
        ...


@dataclass
class StandIn:
    """A model that stands in for a sensor (an MPC fitted to a CSM camera, the vendor RPC of a rigorous DIMAP / DG
    model, the resected MPC of an RPC): what a user measuring against it instead of the sensor would see.

    Parameters
    ----------
    label : str
        What it is, e.g. ``"MPC degree 3 fitted to the CSM camera"``.
    sensor : Sensor
        The stand-in model (its own local frame, on the same body).
    truth_frame : LocalFrame
        The frame of the ground points given to :meth:`ground_to_image` (the true sensor's).
    """

    label: str
    sensor: Sensor
    truth_frame: LocalFrame

    def ground_to_image(self, ground: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) (N,) of the stand-in for ground points (N, 3) in local ENU metres of ``truth_frame``
        (converted through body-fixed coordinates when the stand-in has another frame)."""
        frame = self.sensor.frame
        if frame != self.truth_frame:
            ground = frame.ecef_to_enu(self.truth_frame.enu_to_ecef(ground))
        return self.sensor.ground_to_image(ground)


@runtime_checkable
class GeodeticSensor(Sensor, Protocol):
    """Capability: the model is defined on longitude, latitude (degrees) and ellipsoidal height (metres), as an
    RPC is, so it also *localises* in geodetic coordinates (every sensor projects them:
    :meth:`Sensor.geodetic_to_image`); a caller localising onto a lon/lat DEM (orthorectification) asks it
    directly instead of through the local frame.

    Declared by the class attribute ``has_geodetic_projection = True`` (:class:`explorer.rpc.sensor.RPCSensor`).
    """

    has_geodetic_projection: ClassVar[bool]

    def geodetic_localization(
        self, row: np.ndarray, col: np.ndarray, h: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Image points (N,) at ellipsoidal heights (N,) -> (lon, lat, converged)."""
        ...

    def geodetic_localization_on_dem(
        self, row: np.ndarray, col: np.ndarray, dem: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Image points (N,) -> (lon, lat, h, found): first hit on a lon/lat DEM of ellipsoidal heights."""
        ...

    def image_to_ground_geodetic(
        self, row: np.ndarray, col: np.ndarray, *, height: np.ndarray | float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`Sensor.image_to_ground` and the geodetic coordinates (N, 3) -- longitude, latitude degrees,
        ellipsoidal height metres -- the model's own localisation found (the ENU points are converted from them):
        simulated check points keep them, so the model's truth is its projection of those very coordinates."""
        ...


def has_geodetic_projection(sensor: object) -> bool:
    """True where ``sensor`` declares the :class:`GeodeticSensor` capability."""
    return bool(getattr(type(sensor), "has_geodetic_projection", False))


def has_polynomial_exterior(sensor: object) -> bool:
    """True where ``sensor`` declares the :class:`PolynomialExteriorSensor` capability."""
    return bool(getattr(type(sensor), "has_polynomial_exterior", False))


def has_line_geometry(sensor: object) -> bool:
    """True where ``sensor`` declares the :class:`LineGeometrySensor` capability."""
    return bool(getattr(type(sensor), "has_line_geometry", False))


def has_line_coverage(sensor: object) -> bool:
    """True where ``sensor`` declares the :class:`LineCoverageSensor` capability (tables that may not cover
    every line)."""
    return bool(getattr(type(sensor), "has_line_coverage", False))


def rows_covered(sensor: object, row: np.ndarray) -> np.ndarray:
    """True (N,) where rows (N,) are on lines the sensor's tables cover: :meth:`LineCoverageSensor.rows_covered`,
    or every row of a sensor that does not declare the capability (its geometry holds on every line)."""
    row = np.asarray(row, dtype=np.float64)
    if not has_line_coverage(sensor):
        return np.ones(row.shape, bool)
    return np.asarray(cast("LineCoverageSensor", sensor).rows_covered(row), bool)


__all__ = [
    "FLAG_NAMES",
    "FLAG_NO_DATA",
    "FLAG_NO_HIT",
    "FLAG_OK",
    "FLAG_OUTSIDE_DEM",
    "GeodeticSensor",
    "LineCoverageSensor",
    "LineGeometrySensor",
    "Localization",
    "PolynomialExteriorSensor",
    "Projection",
    "Sensor",
    "StandIn",
    "has_geodetic_projection",
    "has_line_coverage",
    "has_line_geometry",
    "has_polynomial_exterior",
    "inside_image",
    "rows_covered",
]
