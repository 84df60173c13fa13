"""A USGS CSM line-scan camera as the project's :class:`~explorer.sensor.Sensor` -- the camera itself, not a fit.

Beyond the papers.  :class:`CsmScene` wraps a :class:`~explorer.real.csm_camera.CsmCamera` (read from an ISD
by :func:`~explorer.real.csm_camera.read_isd`) behind the :class:`~explorer.scene.Scene` interface, so that
every part of the package that takes a scene -- the search methods, SCOP/SCP simulation, the bench, the
explorer -- runs on the camera's own geometry:

* **frame and body**: a local east-north-up frame (:class:`~explorer.geometry.frames.LocalFrame`) on the
  ISD's ellipsoid (``frame.body``), its origin the ground point of the image centre at height 0;
  ENU <-> body-fixed is ``frame.enu_to_ecef`` / ``frame.ecef_to_enu`` (exact, a rotation and a shift);
* **pixels**: ``(row, col) = (line - 0.5, sample - 0.5)`` of usgscsm (``docs/conventions.md#usgs-csm-line-scan-isds``);
* **ground to image** is the camera's :meth:`~explorer.real.csm_camera.CsmCamera.ground_to_image` (usgscsm's
  detector-line residual solved to 1e-11 lines); **image to ground** intersects the camera's own lines of
  sight (:meth:`~explorer.real.csm_camera.CsmCamera.rays`: focal2pixel, distortion, summing, attitude) with
  the local planes ``Z = height`` or the terrain (plane or DEM);
* **the collinearity residual** the search methods evaluate (:meth:`CsmScene.focal_plane`) is usgscsm's
  detector-line residual (one compiled evaluation per point, :meth:`CsmCamera.detector_residual`),
  expressed in the focal plane of the scene's interior: the detector point of the sample plus the residual
  times the pitch along track.  Its root and its column are the camera's exactly; its scale is lines.
  Far from the root (thousands of lines), where a focal-plane point lies so far off the detector that
  usgscsm's distortion cannot be applied (its Newton diverges), the residual is taken without the
  distortion: only its sign matters to a search there;
* **time**: ``scanline_time`` is linear in the row (the methods' parameter); with one line rate it is the
  camera's clock (seconds from ``center_ephemeris_time``), with several it is a linear stand-in and
  :meth:`CsmScene.line_time` gives the camera's time of a row.  ``exterior`` evaluates the camera's
  centres and rotations at the camera time of the row;
* **interior**: focal length and a detector line fitted to the camera's (undistorted) detector through
  ``focal2pixel`` (degree 7 polynomials, :func:`csm_interior`): only the geometric *guesses* of methods
  that build their own perspective planes use it (``cpp``); every residual comes from the camera.

``has_polynomial_exterior`` is False (interpolated tables): the methods whose compiled kernels pack MPC
polynomials run their line-geometry form (:mod:`explorer.methods.line_geometry`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from explorer._numba import kernel_array
from explorer.errors import SceneFileError, as_points, check_finite
from explorer.geometry.exterior import LineTiming
from explorer.geometry.frames import MARS, MOON, WGS84, Ellipsoid, LocalFrame, ecef_to_geodetic, geodetic_to_ecef
from explorer.geometry.interior import InteriorOrientation
from explorer.geometry.rotations import opk_from_rotation
from explorer.geometry.terrain import FlatTerrain
from explorer.real.csm_camera import CsmCamera
from explorer.scene import Scene
from explorer.sensor import Projection

__all__ = ["CsmExterior", "CsmScene", "csm_body", "csm_interior", "csm_scene"]

KNOWN_BODIES = (WGS84, MARS, MOON)
"""Ellipsoids named when an ISD's radii match them to 1 m."""


def csm_body(camera: CsmCamera) -> Ellipsoid:
    """The ISD's ellipsoid: a named one (WGS84, Mars, Moon) when the radii match it to 1 m, else its radii."""
    a, b = float(camera.semi_major_m), float(camera.semi_minor_m)
    for e in KNOWN_BODIES:
        if abs(e.a_m - a) <= 1.0 and abs(e.b_m - b) <= 1.0:
            return e if (e.a_m, e.b_m) == (a, b) else Ellipsoid(e.name, a, b)
    return Ellipsoid(f"ellipsoid a={a:.1f} m b={b:.1f} m", a, b)


def _scaled_fit(x: np.ndarray, y: np.ndarray, degree: int, scale: float) -> np.ndarray:
    """Ascending polynomial coefficients in ``x`` fitted by least squares in ``x / scale`` (conditioning)."""
    c = np.polynomial.polynomial.polyfit(x / scale, y, degree)
    return c / scale ** np.arange(degree + 1)


def csm_interior(camera: CsmCamera, degree: int = 7) -> tuple[InteriorOrientation, np.ndarray]:
    """The camera's detector line in the project's sensor axes, and the axis flips.

    The CSM detector (``focal2pixel`` inverted, distortion removed) sampled along the line and fitted by
    polynomials of the column (across track) and of ``y`` (along track).

    Returns
    -------
    interior : InteriorOrientation
        Focal length, pitch, principal column, detector offset / curvature and column spacing.
    s_matrix : ndarray (3, 3)
        Project sensor axes -> CSM camera axes (a turn about the boresight that puts the detector along y,
        and axis flips).
    """
    cam = camera
    n_cols = cam.n_samples
    cols = np.linspace(-0.5, n_cols - 0.5, 513)
    samples = cols + 0.5
    fl, fs = cam.focal2pixel_lines, cam.focal2pixel_samples
    t1 = np.full(cols.shape, cam.starting_line - cam.line_origin - fl[0])
    t2 = samples * cam.sample_summing + cam.starting_sample - cam.sample_origin - fs[0]
    det = fl[1] * fs[2] - fl[2] * fs[1]
    xd = (fs[2] * t1 - fl[2] * t2) / det
    yd = (-fs[1] * t1 + fl[1] * t2) / det
    xc, yc = cam.remove_distortion(xd, yd)
    # turn the camera frame about its boresight so that the detector runs along its y axis (any
    # focal2pixel matrix: the detector may run along the focal plane's x axis or at any angle)
    phi = float(np.arctan2(-(xc[-1] - xc[0]), yc[-1] - yc[0]))
    cphi, sphi = np.cos(phi), np.sin(phi)
    xu, yu = cphi * xc + sphi * yc, -sphi * xc + cphi * yc
    turn = np.array([[cphi, -sphi, 0.0], [sphi, cphi, 0.0], [0.0, 0.0, 1.0]])  # turned -> camera axes
    sign = cam.look_sign
    sy = -sign * np.sign(yu[-1] - yu[0])
    sz = sign
    sx = sy * sz
    s_matrix = turn @ np.diag([sx, sy, sz])
    x_p = -sx * sign * xu * 1e-3  # metres
    y_p = -sy * sign * yu * 1e-3
    if np.any(np.diff(y_p) <= 0):
        raise SceneFileError(f"{cam.source}: the undistorted detector line is not monotonic across track")
    half = 0.5 * n_cols
    pc = float(np.interp(0.0, y_p, cols))
    for _ in range(3):
        cu = _scaled_fit(cols - pc, y_p, degree, half)
        pc -= float(cu[0] / cu[1])
    cu = _scaled_fit(cols - pc, y_p, degree, half)
    pitch = float(cu[1])
    cx = _scaled_fit(y_p, x_p, degree, float(np.max(np.abs(y_p))))
    interior = InteriorOrientation(
        focal_length_m=cam.focal_length_mm * 1e-3, detector_pitch_m=pitch, n_columns=n_cols, principal_column=pc,
        along_track_offset_m=float(cx[0]), line_curvature=tuple(float(c) for c in cx[1:]),
        column_polynomial=tuple(float(c / pitch) for c in cu[2:]),
    )
    return interior, s_matrix


def csm_frame(camera: CsmCamera) -> LocalFrame:
    """Local ENU frame on the ISD's ellipsoid at the ground point (height 0) of the image centre (or of the
    image point nearest to it that sees the body: :meth:`CsmCamera.anchor_point`)."""
    line, sample = camera.anchor_point()
    centre = camera.image_to_ground([line], [sample], 0.0)
    if not centre.hit[0]:
        raise SceneFileError(f"{camera.source}: the image centre does not see the body")
    body = csm_body(camera)
    lon, lat, _ = ecef_to_geodetic(centre.ground, body)
    return LocalFrame(float(lat[0]), float(lon[0]), 0.0, body=body)


def csm_timing(camera: CsmCamera) -> LineTiming:
    """Row -> time of the methods: the camera's clock with one line rate, else its mean rate over the image."""
    if camera.rate_lines.size == 1:
        period = float(camera.rate_periods[0])
        # t = t0 + dt (line - l0 + 0.5) with line = row + 0.5  ->  t = dt (row - (l0 - 1 - t0 / dt))
        ref = float(camera.rate_lines[0]) - 1.0 - float(camera.rate_times[0]) / period
        return LineTiming(period, ref)
    t_first, t_last = camera.line_time(np.array([0.5, camera.n_lines - 0.5]))
    period = float((t_last - t_first) / (camera.n_lines - 1))
    ref = 0.5 * (camera.n_lines - 1)
    t_ref = float(camera.line_time(np.array([ref + 0.5]))[0])
    return LineTiming(period, ref - t_ref / period)


@dataclass
class CsmExterior:
    """The camera's perspective centres and camera -> ENU rotations as functions of the scene's time.

    Same evaluation interface as :class:`~explorer.geometry.exterior.ExteriorOrientation` (``position``,
    ``velocity``, ``rotation``, ``angles``, ``angle_rates``): scene time -> row -> the camera's time of
    that row (:meth:`CsmCamera.line_time`) -> :meth:`CsmCamera.exterior`, rotated into the local frame.
    """

    camera: CsmCamera
    frame: LocalFrame
    timing: LineTiming
    s_matrix: np.ndarray

    def camera_time(self, t: np.ndarray) -> np.ndarray:
        """The camera's time (N,) of scene times (N,)."""
        row = self.timing.row_at_time(np.atleast_1d(np.asarray(t, dtype=np.float64)))
        return self.camera.line_time(row + 0.5)

    def _state(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        centre, rot = self.camera.exterior(self.camera_time(t))
        axes = self.frame.enu_to_ecef_rotation
        return self.frame.ecef_to_enu(centre), np.einsum("ji,njk,kl->nil", axes, rot, self.s_matrix)

    def position(self, t: np.ndarray) -> np.ndarray:
        """Perspective centres (N, 3), local ENU metres."""
        return self._state(t)[0]

    def rotation(self, t: np.ndarray) -> np.ndarray:
        """Sensor -> local ENU rotations (N, 3, 3)."""
        return self._state(t)[1]

    def velocity(self, t: np.ndarray, h: float = 1e-3) -> np.ndarray:
        """d(position)/dt (N, 3) by central differences (step ``h`` seconds), m/s."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return (self.position(t + h) - self.position(t - h)) / (2 * h)

    def angles(self, t: np.ndarray) -> np.ndarray:
        """(omega, phi, kappa)(t) of :meth:`rotation` (``docs/conventions.md#rotations``), (N, 3)."""
        return np.stack(opk_from_rotation(self.rotation(t)), axis=-1)

    def angle_rates(self, t: np.ndarray, h: float = 1e-3) -> np.ndarray:
        """d(omega, phi, kappa)/dt by central differences, (N, 3), rad/s."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        d = self.angles(t + h) - self.angles(t - h)
        return ((d + np.pi) % (2 * np.pi) - np.pi) / (2 * h)

    def to_dict(self) -> dict:
        return {"kind": "usgscsm-isd", "isd": str(self.camera.source)}


@dataclass
class CsmScene(Scene):
    """A USGS CSM line-scan camera as a :class:`~explorer.scene.Scene` (see the module docstring).

    Build it with :func:`csm_scene`.  Extra attributes: ``camera`` (the :class:`CsmCamera`) and
    ``residual_sign`` (+-1: usgscsm's detector-line residual turned into the scene convention, positive
    before the best scanline; where the camera's image is mirrored against the scene's sensor axes this is
    the opposite of the physical ``x - x_det(y)``, which methods that build their own planes allow for).
    """

    camera: Any = field(default=None, repr=False, compare=False)
    residual_sign: float = 1.0
    exterior: CsmExterior  # type: ignore[assignment]

    #: Interpolated tables, not MPC polynomials; the camera's own lines of sight.
    has_polynomial_exterior: ClassVar[bool] = False
    has_line_coverage: ClassVar[bool] = True  # the ISD's tables may stop before the last line (sensor.py)

    # ------------------------------------------------------------ frames
    def to_body_fixed(self, enu: np.ndarray) -> np.ndarray:
        """Local ENU metres (N, 3) -> the ISD's body-fixed metres (N, 3)."""
        return self.frame.enu_to_ecef(enu)

    def from_body_fixed(self, xyz: np.ndarray) -> np.ndarray:
        """Body-fixed metres (N, 3) -> local ENU metres (N, 3)."""
        return self.frame.ecef_to_enu(xyz)

    def geodetic_to_body_fixed(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Planetodetic longitude, latitude (N,) degrees and height above the body's ellipsoid (N,) metres -> the
        ISD's body-fixed metres (N, 3) (:func:`explorer.geometry.frames.geodetic_to_ecef`, compiled: the
        geodetic entry's only conversion; within an ulp of it)."""
        from explorer._numba import NUMBA_AVAILABLE
        from explorer.real import csm_kernels as K

        body = self.frame.body
        if not NUMBA_AVAILABLE:
            return geodetic_to_ecef(lon, lat, h, body)
        lon, lat, h = (kernel_array(np.ravel(a)) for a in np.broadcast_arrays(lon, lat, h))
        out = np.empty((lon.shape[0], 3))
        K.geodetic_to_body_fixed_nb(lon, lat, h, float(body.a_m), float(body.e2), out)  # type: ignore[call-arg]
        return out

    # ------------------------------------------------------------ line geometry
    def rows_covered(self, row: np.ndarray) -> np.ndarray:
        """True (N,) where scene rows (N,) (CSM line - 0.5) lie on lines the ISD's tables cover
        (:meth:`CsmCamera.line_covered`; False for NaN)."""
        return self.camera.line_covered(np.asarray(row, dtype=np.float64) + 0.5)

    def line_time(self, row: np.ndarray) -> np.ndarray:
        """The camera's time (N,) of rows (N,), seconds from the ISD's ``center_ephemeris_time``."""
        return self.camera.line_time(np.atleast_1d(np.asarray(row, dtype=np.float64)) + 0.5)

    def time_range(self) -> tuple[float, float]:
        """(earliest, latest) exposure time of the image on the camera's clock (seconds from the ISD's
        ``center_ephemeris_time``): the first and last lines' outer edges, every line-rate segment included."""
        rows = np.concatenate([[-0.5, self.n_rows - 0.5], self.camera.rate_lines - 1.0])
        t = self.line_time(rows[(rows >= -0.5) & (rows <= self.n_rows - 0.5)])
        return float(np.min(t)), float(np.max(t))

    def perspective_centre(self, t: np.ndarray) -> np.ndarray:
        """Perspective centres (N, 3), local ENU metres, at camera times (N,)."""
        centre, _ = self.camera.exterior(np.atleast_1d(np.asarray(t, dtype=np.float64)))
        return self.frame.ecef_to_enu(centre)

    def attitude(self, t: np.ndarray) -> np.ndarray:
        """Sensor -> local ENU rotations (N, 3, 3) at camera times (N,) (project sensor axes)."""
        _, rot = self.camera.exterior(np.atleast_1d(np.asarray(t, dtype=np.float64)))
        return np.einsum("ji,njk,kl->nil", self.frame.enu_to_ecef_rotation, rot, self.exterior.s_matrix)

    # ------------------------------------------------------------ collinearity
    def focal_plane(self, ground: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The camera's detector-line residual and sample as focal-plane coordinates (x, y) (N,), metres.

        ``y`` is the detector's across-track coordinate of the camera's sample; ``x`` the detector line
        there plus ``residual_sign`` times usgscsm's detector-line residual (lines) times the pitch, so
        :meth:`along_track_residual` / pitch is the residual in lines and :meth:`column_at_time` the sample.
        NaN behind the camera.
        """
        ground = np.asarray(ground, dtype=np.float64)
        t = np.broadcast_to(np.asarray(t, dtype=np.float64), ground.shape[:1])
        line = self.timing.row_at_time(t) + 0.5
        xyz = self.frame.enu_to_ecef(ground)
        res, sample = self.camera.detector_residual(xyz, line)
        lost = np.flatnonzero(~np.isfinite(res))
        if lost.size:  # usgscsm's distortion is not applicable that far off the detector: its sign without it
            res[lost], sample[lost] = _undistorted_residual(self.camera, xyz[lost], line[lost])
        xd, yd = self.interior.detector_focal_plane(sample - 0.5)
        return xd + self.residual_sign * res * self.interior.detector_pitch_m, yd

    def rays(self, row: np.ndarray, col: np.ndarray, height: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """The camera's lines of sight (origin (N, 3), unit direction (N, 3)) in the local frame."""
        row = check_finite(np.atleast_1d(np.asarray(row, dtype=np.float64)), "row")
        col = check_finite(np.atleast_1d(np.asarray(col, dtype=np.float64)), "col")
        row, col = np.broadcast_arrays(row, col)
        centre, look = self.camera.rays(row + 0.5, col + 0.5)
        return self.frame.ecef_to_enu(centre), look @ self.frame.enu_to_ecef_rotation

    def ground_to_image(
        self, ground: np.ndarray, *, row_guess: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The camera's own ground to image (:meth:`CsmCamera.ground_to_image`) of local ENU points (N, 3):
        (row, col) = (line - 0.5, sample - 0.5); NaN where the camera solves no line (behind it, no root
        in its search window) and where that line is outside the ISD's ephemeris tables (status 5: flagged,
        never extrapolated).  ``row_guess`` is not needed (the camera seeds itself)."""
        g = self.camera.ground_to_image(self.frame.enu_to_ecef(as_points(ground)))
        solved = g.status == 0
        return np.where(solved, g.line - 0.5, np.nan), np.where(solved, g.sample - 0.5, np.nan)

    def project(self, ground: np.ndarray) -> Projection:
        """:meth:`ground_to_image` with the camera's validity flags (solved, and on the image)."""
        g = self.camera.ground_to_image(self.frame.enu_to_ecef(as_points(ground)))
        return Projection(g.line - 0.5, g.sample - 0.5, g.valid)

    def geodetic_to_image(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`ground_to_image` of planetodetic points on the camera's body -- longitude, latitude (N,) degrees,
        height above its ellipsoid (N,) metres -- converted straight to the body-fixed coordinates the camera is
        defined on (:meth:`explorer.sensor.Sensor.geodetic_to_image`)."""
        g = self.camera.ground_to_image(self.geodetic_to_body_fixed(lon, lat, h))
        solved = g.status == 0
        return np.where(solved, g.line - 0.5, np.nan), np.where(solved, g.sample - 0.5, np.nan)

    def project_geodetic(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> Projection:
        """:meth:`geodetic_to_image` with the camera's validity flags (solved, and on the image)."""
        g = self.camera.ground_to_image(self.geodetic_to_body_fixed(lon, lat, h))
        return Projection(g.line - 0.5, g.sample - 0.5, g.valid)

    # ------------------------------------------------------------ description
    def describe(self) -> str:
        return self.camera.describe()

    def with_terrain(self, terrain: Any) -> CsmScene:
        from dataclasses import replace

        return replace(self, terrain=terrain)


def _undistorted_residual(camera: CsmCamera, xyz: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """usgscsm's detector-line residual and sample without the optical distortion (NaN behind the camera)."""
    from explorer.real import csm_kernels as K

    cam, rl, rt, rp, ext, _, _ = camera._all_args()
    res, sample = np.empty(line.size), np.empty(line.size)
    K.residual_many(kernel_array(xyz), kernel_array(line), cam, rl, rt, rp, ext,  # type: ignore[call-arg]
                    int(K.DIST_NONE), np.zeros(1), res, sample)
    return res, sample


def csm_scene(camera: CsmCamera, *, terrain: Any = None, interior_degree: int = 7) -> CsmScene:
    """The :class:`CsmScene` of a camera (default terrain: the local plane ``Z = 0``)."""
    frame = csm_frame(camera)
    interior, s_matrix = csm_interior(camera, interior_degree)
    timing = csm_timing(camera)
    exterior = CsmExterior(camera, frame, timing, s_matrix)
    meta = {"source": "usgscsm-isd", "isd": str(camera.source), "sensor": camera.metadata.get("sensor"),
            "platform": camera.metadata.get("platform"), "body": frame.body.name,
            "pixel_convention": "scene (row, col) = CSM (line - 0.5, sample - 0.5)"}
    scene = CsmScene(name=camera.name, interior=interior, exterior=exterior, timing=timing, n_rows=camera.n_lines,
                     terrain=FlatTerrain(0.0) if terrain is None else terrain, frame=frame, metadata=meta,
                     camera=camera)
    # the scene convention (docs/conventions.md#best-scanline): the residual is positive before the best scanline
    # (it predicts how many lines ahead the root lies, as GDP reads it), whatever the camera's axes
    line, sample = camera.anchor_point()  # a line the tables cover, a point that sees the body
    rc, cc = line - 0.5, sample - 0.5
    g = scene.image_to_ground(np.array([rc]), np.array([cc]), height=0.0)
    res, _ = camera.detector_residual(frame.enu_to_ecef(g), np.array([rc + 0.5 - 1.0]))
    if not (np.isfinite(res[0]) and res[0] != 0.0):
        raise SceneFileError(f"{camera.source}: the detector-line residual does not change with the line "
                             "at the image centre")
    scene.residual_sign = 1.0 if res[0] > 0 else -1.0
    return scene
