"""USGS Community Sensor Model line-scan cameras read from their image support data (ISD).

Imported through :mod:`explorer.real.csm` (the public API).

Beyond the papers.  The planetary pushbroom cameras (Mars CTX and HiRISE, LRO NAC, Kaguya TC,
...) are described by an ISD -- a JSON file written by USGS ALE -- that usgscsm's
``UsgsAstroLsSensorModel`` turns into a camera.  :func:`read_isd` reads the same fields and
returns a :class:`CsmCamera` whose two directions follow usgscsm's conventions
(``docs/conventions.md#usgs-csm-line-scan-isds``):

* ``image_to_ground(line, sample, height)``: body-fixed metres on the ellipsoid of the file
  inflated by ``height`` (semi-axes ``a + h, a + h, b + h``, as usgscsm);
* ``ground_to_image(xyz)``: the best line solved to ``tol`` lines (default 1e-11) by a
  safeguarded secant on usgscsm's detector-line residual from a tabulated seed, then the sample
  -- where usgscsm stops at its ``desired_precision`` (its tests accept 0.1 px).

What is read (every key is checked; a missing key, a NaN or a bad unit raises
:class:`~explorer.errors.SceneFileError` naming the file and the key):

* ``image_lines``, ``image_samples``; ``line_scan_rate`` (rows ``[line, time relative to
  center_ephemeris_time, seconds per line]``, one or several rates); ``center_ephemeris_time``;
* ``instrument_position`` (``ephemeris_times``, ``positions``, optional ``velocities``, ``unit``
  m or km -- km, ALE's unit, when absent -- and ``reference_frame``: 1 means J2000, rotated into
  the body frame by ``body_rotation``; the body's frame code means body-fixed); Lagrange of order
  ``interpolation_order`` (top level or in the table; default 8, usgscsm's) with usgscsm's window;
  ``interpolation_method`` must be ``lagrange`` when present;
* ``instrument_pointing`` (J2000 -> sensor) and ``body_rotation`` (J2000 -> body):
  ``ephemeris_times``, ``quaternions`` ``(w, x, y, z)``, optional ``constant_rotation`` (3 x 3,
  row-major) applied after the time-dependent rotation;
* how the tables are interpolated (``interpolation`` of :func:`read_isd`): ``"usgscsm"`` (default)
  rebuilds usgscsm's state (Hermite-resampled positions, slerp-resampled sensor -> body
  quaternions, both through usgscsm's Lagrange window); ``"tables"`` interpolates the samples as
  given (Lagrange for positions, slerp for rotations);
* ``focal_length_model.focal_length`` (mm), ``detector_center`` (line, sample),
  ``starting_detector_line``/``sample``, ``focal2pixel_lines``/``samples``,
  ``detector_line_summing``/``sample_summing``;
* ``optical_distortion``: usgscsm's ``radial``, ``transverse``, ``kaguyalism``, ``lrolrocnac``, ``dawnfc``,
  ``cahvor`` (``coefficients``: k0, k1, k2, x and y offsets), ``radtan`` (k1, k2, p1, p2, k3 on
  coordinates divided by the focal length), ``kplo_shadowcam`` (one coefficient) and ``lunarorbiter``
  (``perspective_x``/``_y``, ``center_point_x``/``_y``, optional ``coefficients`` k0, k1 -- no
  other key -- ISIS's ``LoHighDistortionMap``), and the models ALE writes for line scanners that usgscsm does not read:
  ``legendre`` (New Horizons MVIC TDI, ``x_coefficients``/``y_coefficients`` of 20 terms: ISIS's
  ``NewHorizonsMvicTdiCameraDistortionMap``, x only, over half of ``image_samples`` x the pixel pitch of
  ``focal2pixel_samples``) and ``themisir`` (Mars Odyssey THEMIS IR, ISIS's ``ThemisIrDistortionMap``:
  ``p_k``, ``p_alpha1``, ``p_alpha2`` as ALE writes them); each closed form one way and solved by
  Newton the other (:mod:`explorer.real.csm_kernels`); any other model (usgscsm's ``cassis``, ...)
  raises :class:`~explorer.errors.SceneFileError` naming it;
* ``radii`` (``semimajor``, ``semiminor``, ``unit`` m or km): any body.

Checked at read time against what a physical camera can be (one-line
:class:`~explorer.errors.SceneFileError` naming the file and the key): every position outside the body,
unit quaternions, proper constant rotations, whole image sizes, reference heights within half the body's
smaller semi-axis and below the sensor, and ephemeris tables that cover at least one image line.  Lines
the tables do not cover are flagged by :meth:`CsmCamera.image_to_ground`, :meth:`CsmCamera.ground_to_image`
(``status`` 5) and :meth:`CsmCamera.rays`, never extrapolated (:meth:`CsmCamera.line_covered`,
:meth:`CsmCamera.covered_line_ranges`).  The file itself is read through :mod:`explorer.io_input`
(regular files only, any text encoding, no binary junk, bounded nesting and number literals).

A ray that misses the body comes back as NaN with ``hit=False``: usgscsm instead returns the
point of the ray closest to the ellipsoid (its ``OffBody`` test), a ground point that does not
lie on the surface asked for; a silent wrong number is what this package never returns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from explorer._numba import kernel_array
from explorer.errors import InputError, SceneFileError, as_points, check_finite
from explorer.io_input import load_json_file
from explorer.real import csm_kernels as K
from explorer.real.linescan import matrix_to_quaternion

__all__ = ["SUPPORTED_DISTORTIONS", "CsmCamera", "GroundToImage", "ImageToGround", "camera_from_isd", "read_isd"]

SUPPORTED_DISTORTIONS = {
    "radial": K.DIST_RADIAL,
    "transverse": K.DIST_TRANSVERSE,
    "kaguyalism": K.DIST_KAGUYALISM,
    "dawnfc": K.DIST_DAWNFC,
    "lrolrocnac": K.DIST_LROLROCNAC,
    "cahvor": K.DIST_CAHVOR,
    "lunarorbiter": K.DIST_LUNARORBITER,
    "radtan": K.DIST_RADTAN,
    "kplo_shadowcam": K.DIST_KPLOSHADOWCAM,
    "legendre": K.DIST_LEGENDRE,
    "themisir": K.DIST_THEMISIR,
}

UNIT_TO_M = {"m": 1.0, "km": 1000.0}
QUATERNION_NORM_TOL = 1e-5  # |norm - 1| above this is not a rounding of a unit quaternion
STATUS_OUTSIDE_TABLES = 5  # GroundToImage.status: solved at a line the ephemeris tables do not cover
J2000_FRAME = 1


class ImageToGround(NamedTuple):
    """Result of :meth:`CsmCamera.image_to_ground`.

    ground : ndarray (N, 3)
        Body-fixed metres; NaN rows where the ray misses the body.
    hit : ndarray of bool (N,)
    """

    ground: np.ndarray
    hit: np.ndarray


class GroundToImage(NamedTuple):
    """Result of :meth:`CsmCamera.ground_to_image`.

    line, sample : ndarray (N,)
        CSM image coordinates (the first pixel's centre is (0.5, 0.5)); NaN where not solved.
    valid : ndarray of bool (N,)
        Solved (``status == 0``) and on the image (``0 <= line <= lines``, ``0 <= sample <= samples``).
    status : ndarray of int8 (N,)
        0 solved, 1 behind the camera, 2 no root in the search window, 3 iteration limit, 5 solved at a
        line whose time is outside the ephemeris tables (``STATUS_OUTSIDE_TABLES``: the line is
        returned, computed from extrapolated tables, and flagged).
    evaluations : ndarray of int64 (N,)
        Residual evaluations per point.
    """

    line: np.ndarray
    sample: np.ndarray
    valid: np.ndarray
    status: np.ndarray
    evaluations: np.ndarray


# --------------------------------------------------------------------------- reading helpers
class _Isd:
    """Key access with errors that name the file and the key path."""

    def __init__(self, data: Any, source: str) -> None:
        if not isinstance(data, dict):
            raise SceneFileError(f"{source}: an ISD must be a JSON object, got {type(data).__name__}")
        self.data = data
        self.source = source

    def fail(self, path: str, what: str) -> SceneFileError:
        return SceneFileError(f"{self.source}: ISD key {path!r} {what}")

    def get(self, *path: str, default: Any = ...) -> Any:
        node: Any = self.data
        for k, key in enumerate(path):
            if not isinstance(node, dict) or key not in node:
                if default is not ...:
                    return default
                where = ".".join(path[: k + 1])
                raise self.fail(where, "is missing")
            node = node[key]
        return node

    def number(self, *path: str, default: Any = ..., positive: bool = False) -> float:
        v = self.get(*path, default=default)
        name = ".".join(path)
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise self.fail(name, f"must be a number, got {v!r}") from None
        if not math.isfinite(x):
            raise self.fail(name, f"must be finite, got {v!r}")
        if positive and not x > 0:
            raise self.fail(name, f"must be positive, got {v!r}")
        return x

    def array(self, *path: str, shape: tuple[int | None, ...], default: Any = ...) -> np.ndarray:
        v = self.get(*path, default=default)
        name = ".".join(path)
        try:
            arr = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            raise self.fail(name, "must be an array of numbers") from None
        if arr.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, arr.shape, strict=True)):
            want = " x ".join("N" if s is None else str(s) for s in shape)
            raise self.fail(name, f"must have shape ({want}), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise self.fail(name, "contains NaN or infinite values")
        return arr

    def unit(self, *path: str, default: Any = ...) -> float:
        u = self.get(*path, default=default)
        if not isinstance(u, str) or u.lower() not in UNIT_TO_M:
            raise self.fail(".".join(path), f"must be 'm' or 'km', got {u!r}")
        return UNIT_TO_M[u.lower()]


def _continuous(q: np.ndarray) -> np.ndarray:
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    for i in range(1, q.shape[0]):
        if np.dot(q[i], q[i - 1]) < 0:
            q[i] = -q[i]
    return np.ascontiguousarray(q)


def _times(isd: _Isd, table: str, n: int) -> np.ndarray:
    t = isd.array(table, "ephemeris_times", shape=(n,))
    if n > 1 and np.any(np.diff(t) <= 0):
        raise isd.fail(f"{table}.ephemeris_times", "must increase strictly")
    return np.ascontiguousarray(t)


def _rotation_table(isd: _Isd, table: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q = isd.array(table, "quaternions", shape=(None, 4))
    if q.shape[0] < 1:
        raise isd.fail(f"{table}.quaternions", "is empty")
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > QUATERNION_NORM_TOL)
    if bad.size:
        i = int(bad[0])
        raise isd.fail(f"{table}.quaternions", f"row {i} has norm {norm[i]:.9g}, not a unit quaternion "
                       f"({bad.size} of {norm.size} rows off by more than {QUATERNION_NORM_TOL:g})")
    t = _times(isd, table, q.shape[0])
    c = isd.array(table, "constant_rotation", shape=(9,), default=np.eye(3).ravel().tolist()).reshape(3, 3)
    if not np.allclose(c @ c.T, np.eye(3), atol=1e-6):
        raise isd.fail(f"{table}.constant_rotation", "is not a rotation matrix (not orthonormal)")
    if np.linalg.det(c) < 0:
        raise isd.fail(f"{table}.constant_rotation", "is a reflection (determinant -1), not a rotation")
    return t, _continuous(q), np.ascontiguousarray(c)


def _distortion(isd: _Isd) -> tuple[str, int, np.ndarray]:
    dist = isd.get("optical_distortion")
    if not isinstance(dist, dict) or len(dist) != 1:
        raise isd.fail("optical_distortion", "must be an object with exactly one model")
    (name, params), = dist.items()
    if name not in SUPPORTED_DISTORTIONS:
        raise SceneFileError(
            f"{isd.source}: optical distortion model {name!r} is not supported "
            f"(supported: {', '.join(sorted(SUPPORTED_DISTORTIONS))})"
        )
    key = ("optical_distortion", name)
    if name == "radial":
        c = isd.array(*key, "coefficients", shape=(None,))
        if c.size > 3:
            raise isd.fail("optical_distortion.radial.coefficients", f"has {c.size} terms; usgscsm reads 3")
        coef = np.zeros(3)
        coef[: c.size] = c
    elif name in ("transverse", "kaguyalism"):  # x terms then y terms; kaguyalism: each after its boresight
        limit, first = (10, 0) if name == "transverse" else (4, 1)
        cx, cy = (isd.array(*key, axis, shape=(None,)) for axis in ("x", "y"))
        if cx.size > limit or cy.size > limit:
            raise isd.fail(f"optical_distortion.{name}", f"x and y take at most {limit} coefficients each")
        coef = np.zeros(2 * (first + limit))
        for start, axis, c in ((0, "x", cx), (first + limit, "y", cy)):
            if first:
                coef[start] = isd.number(*key, f"boresight_{axis}")
            coef[start + first: start + first + c.size] = c
    elif name in ("cahvor", "radtan"):  # cahvor: k0, k1, k2, x offset, y offset; radtan: k1, k2, p1, p2, k3
        coef = _exact_size(isd, (*key, "coefficients"), 5)
        if name == "radtan":  # on coordinates normalised by the focal length (usgscsm)
            coef = np.append(coef, isd.number("focal_length_model", "focal_length", positive=True))
    elif name == "lunarorbiter":  # ISIS LoHighDistortionMap: perspective factors, point of symmetry, k0, k1
        known = ("perspective_x", "perspective_y", "center_point_x", "center_point_y", "coefficients")
        extra = sorted(set(params) - set(known)) if isinstance(params, dict) else []
        if extra:  # a radial term under another name must not be dropped in silence
            raise isd.fail(f"optical_distortion.{name}", f"has unknown key(s) {', '.join(extra)}; "
                           f"read are {', '.join(known)}")
        # ALE writes the perspective factors and the point of symmetry only (its Lunar Orbiter ISDs carry no k;
        # ISIS takes k0, k1 from the instrument kernel): k0 = k1 = 0 unless the ISD gives them
        k = isd.array(*key, "coefficients", shape=(None,), default=[0.0, 0.0])
        if not 1 <= k.size <= 2:
            raise isd.fail(f"optical_distortion.{name}.coefficients", f"must hold 1 or 2 values, got {k.size}")
        coef = np.array([isd.number(*key, "perspective_x"), isd.number(*key, "perspective_y"),
                         isd.number(*key, "center_point_x"), isd.number(*key, "center_point_y"),
                         k[0], k[1] if k.size == 2 else 0.0])
    elif name == "legendre":  # ISIS NewHorizonsMvicTdiCameraDistortionMap: 20 x terms over the half detector
        cx = _exact_size(isd, (*key, "x_coefficients"), 20)
        _exact_size(isd, (*key, "y_coefficients"), 20)  # read and checked; the TDI map corrects x only
        fs = isd.array("focal2pixel_samples", shape=(3,))
        pitch = 1.0 / math.hypot(fs[1], fs[2]) if math.hypot(fs[1], fs[2]) > 0 else math.nan
        half = 0.5 * isd.number("image_samples", positive=True) * pitch  # ISIS: half of Samples() x PixelPitch()
        if not (math.isfinite(half) and half > 0):
            raise isd.fail("focal2pixel_samples", "gives no pixel pitch for the legendre model's half detector")
        coef = np.concatenate([[half], cx])
    elif name == "themisir":  # ALE: ISIS ThemisIrDistortionMap's p_k (x scale of the band), p_alpha1, p_alpha2
        coef = np.array([isd.number(*key, "p_k", positive=True), isd.number(*key, "p_alpha1"),
                         isd.number(*key, "p_alpha2")])
    else:  # dawnfc, lrolrocnac, kplo_shadowcam: one coefficient
        coef = _exact_size(isd, (*key, "coefficients"), 1)
    return name, SUPPORTED_DISTORTIONS[name], np.ascontiguousarray(coef, dtype=np.float64)


def _exact_size(isd: _Isd, path: tuple[str, ...], n: int) -> np.ndarray:
    c = isd.array(*path, shape=(None,))
    if c.size != n:
        raise isd.fail(".".join(path), f"must hold {n} value{'s' if n > 1 else ''}, got {c.size}")
    return c.copy()


# --------------------------------------------------------------------------- camera
@dataclass
class CsmCamera:
    """A USGS CSM line-scan camera (usgscsm ``UsgsAstroLsSensorModel`` conventions).

    Built by :func:`read_isd`.  Lengths: metres in the body-fixed frame; focal plane in mm;
    times in seconds (ephemeris time).  ``image_to_ground`` / ``ground_to_image`` are
    vectorised and compiled (numba ``prange``).
    """

    source: str
    name: str
    n_lines: int
    n_samples: int
    semi_major_m: float
    semi_minor_m: float
    center_time: float
    rate_lines: np.ndarray
    rate_times: np.ndarray
    rate_periods: np.ndarray
    position_times: np.ndarray
    positions_m: np.ndarray
    position_order: int
    position_in_j2000: bool
    pointing_times: np.ndarray
    pointing_quaternions: np.ndarray
    pointing_constant: np.ndarray
    body_times: np.ndarray
    body_quaternions: np.ndarray
    body_constant: np.ndarray
    attitude_interpolation: str
    attitude_order: int
    focal_length_mm: float
    line_origin: float
    sample_origin: float
    starting_line: float
    starting_sample: float
    line_summing: float
    sample_summing: float
    focal2pixel_lines: np.ndarray
    focal2pixel_samples: np.ndarray
    distortion_name: str
    distortion_model: int
    distortion_coefficients: np.ndarray
    height_range_m: tuple[float, float] = (-1000.0, 1000.0)
    metadata: dict = field(default_factory=dict)
    table_span: tuple[float, float] = (-math.inf, math.inf)
    table_span_names: tuple[str, str] = ("", "")

    def __post_init__(self) -> None:
        fl, fs = self.focal2pixel_lines, self.focal2pixel_samples
        if fl[1] * fs[2] - fl[2] * fs[1] == 0.0:
            raise SceneFileError(f"{self.source}: focal2pixel_lines/samples are singular")
        cam = np.zeros(K.N_CAM)
        cam[K.C_FOCAL] = self.focal_length_mm
        cam[K.C_LINE_ORIGIN], cam[K.C_SAMPLE_ORIGIN] = self.line_origin, self.sample_origin
        cam[K.C_START_LINE], cam[K.C_START_SAMPLE] = self.starting_line, self.starting_sample
        cam[K.C_LINE_SUM], cam[K.C_SAMPLE_SUM] = self.line_summing, self.sample_summing
        cam[K.C_TL0: K.C_TL2 + 1] = fl
        cam[K.C_TS0: K.C_TS2 + 1] = fs
        cam[K.C_A], cam[K.C_B] = self.semi_major_m, self.semi_minor_m
        cam[K.C_N_LINES], cam[K.C_N_SAMPLES] = self.n_lines, self.n_samples
        cam[K.C_SLOPE] = -1.0
        cam[K.C_LOOK] = 1.0
        cam[K.C_CURV] = np.inf  # until measured: accept on the step only
        self._cam = cam
        self._check_coverage()
        self._set_look_sign()
        self._seed: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._seed_table: tuple = ()
        self._ext: tuple | None = None
        self._setup_seed()

    # ------------------------------------------------------------------ packing
    def _tables(self) -> tuple:
        return (self.rate_lines, self.rate_times, self.rate_periods)

    def _exterior_args(self) -> tuple:
        """The ``ext`` tuple of the kernels (tables with their precomputed Lagrange windows)."""
        ext = getattr(self, "_ext", None)
        if ext is None:
            pw, pd = K.window_tables(self.position_times, int(self.position_order))
            qpw, qpd = K.window_tables(self.pointing_times, int(self.attitude_order))
            qbw, qbd = K.window_tables(self.body_times, int(self.attitude_order))
            ref = np.ascontiguousarray(self.positions_m[self.positions_m.shape[0] // 2])
            ext = (self.position_times, np.ascontiguousarray(self.positions_m - ref), ref, pw, pd,
                         self.pointing_times,
                         self.pointing_quaternions, qpw, qpd, self.pointing_constant, self.body_times,
                         self.body_quaternions, qbw, qbd, self.body_constant,
                         1 if self.attitude_interpolation == "lagrange" else 0, bool(self.position_in_j2000),
                         self._is_simple())
            self._ext = ext
        return ext

    def _is_simple(self) -> bool:
        """Identity body rotation and constant rotations with body-fixed positions (the usgscsm state)."""
        ident = np.eye(3)
        return bool(not self.position_in_j2000 and self.body_times.size == 1
                    and np.array_equal(self.body_quaternions[0], [1.0, 0.0, 0.0, 0.0])
                    and np.array_equal(self.body_constant, ident) and np.array_equal(self.pointing_constant, ident))

    def _all_args(self) -> tuple:
        return (self._cam, *self._tables(), self._exterior_args(), int(self.distortion_model),
                self.distortion_coefficients)

    # ------------------------------------------------------------------ time
    def line_time(self, line: np.ndarray) -> np.ndarray:
        """Time (N,) of CSM lines (N,), seconds from ``center_ephemeris_time``:
        ``t_k + dt_k (line - line_k + 0.5)``."""
        line = np.atleast_1d(np.asarray(line, dtype=np.float64))
        k = np.clip(np.searchsorted(self.rate_lines, line, side="right") - 1, 0, None)
        return self.rate_times[k] + self.rate_periods[k] * (line - self.rate_lines[k] + 0.5)

    def time_line(self, t: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`line_time` (the line whose centre is exposed at time ``t``).

        With several rates usgscsm's map is not monotonic: each ``line_scan_rate`` row gives its line's
        start time and the formula adds half a line, so the time steps back by ``(dt_(k-1) - dt_k) / 2``
        at a change to a faster rate; there the later segment's line is returned.
        """
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        starts = self.rate_times  # the time of line_k - 0.5 ... times increase with the table
        k = np.clip(np.searchsorted(starts + 0.5 * self.rate_periods, t, side="right") - 1, 0, None)
        return self.rate_lines[k] - 0.5 + (t - self.rate_times[k]) / self.rate_periods[k]

    def line_period(self, line: np.ndarray) -> np.ndarray:
        """Seconds per line (N,) of the ``line_scan_rate`` row in effect at CSM lines (N,)."""
        line = np.atleast_1d(np.asarray(line, dtype=np.float64))
        k = np.clip(np.searchsorted(self.rate_lines, line, side="right") - 1, 0, None)
        return self.rate_periods[k]

    def line_covered(self, line: ArrayLike) -> np.ndarray:
        """True (N,) where the time of CSM lines (N,) lies inside every ephemeris table (``table_span``).

        A line is covered when its time is within the span of the position, pointing and body-rotation
        tables (those with more than one sample), widened by half a line (plus 1e-6 line of round-off)
        at either end: ALE starts and ends its tables at the first and last pixels' centres or outer
        edges, so the outer half of the first and last lines is the most a table may be extrapolated.
        Lines that are not covered are flagged by :meth:`image_to_ground` and :meth:`ground_to_image`,
        never extrapolated (``docs/conventions.md#usgs-csm-line-scan-isds``).
        """
        line = np.atleast_1d(np.asarray(line, dtype=np.float64))
        lo, hi = self.table_span
        t = self.line_time(line)
        slack = (0.5 + 1e-6) * self.line_period(line)
        with np.errstate(invalid="ignore"):
            return (t >= lo - slack) & (t <= hi + slack)

    def covered_line_ranges(self) -> list[tuple[float, float]]:
        """The image's covered stretches as ``(first, last)`` CSM line pairs: the whole lines ``j`` (pixel
        edges ``j`` to ``j + 1``) whose centre ``j + 0.5`` is covered (:meth:`line_covered`).

        Solved per ``line_scan_rate`` segment in closed form (time is linear in the line there), then each
        end checked against :meth:`line_covered` itself: no per-line arrays, whatever the image size."""
        lo, hi = self.table_span
        n = self.n_lines
        rl, rt, rp = self.rate_lines, self.rate_times, self.rate_periods
        slack = 0.5 + 1e-6
        ranges: list[list[int]] = []
        for k in range(rl.size):
            seg_lo = -math.inf if k == 0 else float(rl[k])
            seg_hi = math.inf if k == rl.size - 1 else float(rl[k + 1])
            # t(L) = rt + rp (L - rl + 0.5) within [lo - slack rp, hi + slack rp]
            a = float(rl[k] - 0.5 + (lo - rt[k]) / rp[k] - slack)
            b = float(rl[k] - 0.5 + (hi - rt[k]) / rp[k] + slack)
            c_lo = min(max(a, seg_lo, 0.0), float(n))
            c_hi = max(min(b, seg_hi, float(n)), 0.0)
            if not c_lo <= c_hi:
                continue
            j_lo, j_hi = max(math.ceil(c_lo - 0.5) - 2, 0), min(math.floor(c_hi - 0.5) + 2, n - 1)
            # exact ends: the centres in this segment that line_covered accepts (a few evaluations)
            while j_lo <= j_hi and not self._centre_in_segment(j_lo, k, seg_lo, seg_hi):
                j_lo += 1
            while j_hi >= j_lo and not self._centre_in_segment(j_hi, k, seg_lo, seg_hi):
                j_hi -= 1
            if j_lo > j_hi:
                continue
            if ranges and j_lo <= ranges[-1][1]:
                ranges[-1][1] = max(ranges[-1][1], j_hi + 1)
            else:
                ranges.append([j_lo, j_hi + 1])
        return [(float(a), float(b)) for a, b in ranges]

    def _centre_in_segment(self, j: int, k: int, seg_lo: float, seg_hi: float) -> bool:
        c = j + 0.5
        return bool(seg_lo <= c < seg_hi and self.line_covered(np.array([c]))[0])

    def covered_fraction(self) -> float:
        """Fraction of the image's lines (their centres) covered by every ephemeris table."""
        return sum(b - a for a, b in self.covered_line_ranges()) / self.n_lines

    def _check_coverage(self) -> None:
        """Refuse a camera whose tables cover none of the image's lines, naming the table and the times."""
        if self.covered_fraction() > 0.0:
            return
        edges = np.concatenate([[0.0, float(self.n_lines)], self.rate_lines[(self.rate_lines > 0)
                                                                            & (self.rate_lines < self.n_lines)]])
        times = np.concatenate([self.line_time(edges), self.line_time(np.maximum(edges - 1e-9, 0.0))])
        t0, t1 = float(times.min()), float(times.max())
        lo, hi = self.table_span
        names = []
        for name, (a, b) in self.metadata.get("table_spans", {}).items():
            if a > t1 or b < t0:
                names.append(f"{name!r} covers ephemeris times {a + self.center_time:.6f} .. "
                             f"{b + self.center_time:.6f} s")
        which = "; ".join(names) if names else (
            f"{self.table_span_names[0]!r} starts at {lo + self.center_time:.6f} s and "
            f"{self.table_span_names[1]!r} ends at {hi + self.center_time:.6f} s")
        raise SceneFileError(
            f"{self.source}: the ephemeris tables do not cover the image: {which}, but the image is exposed "
            f"from {t0 + self.center_time:.6f} to {t1 + self.center_time:.6f} s")

    def exterior(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Perspective centres (N, 3) body-fixed metres and camera -> body rotations (N, 3, 3) at times (N,)
        (seconds from ``center_ephemeris_time``); beyond the tables' ends (:meth:`time_covered` False) the
        tables are extrapolated linearly.

        The camera frame is usgscsm's: a focal-plane point ``(x, y)`` looks along ``(-x, -y, -f)``.
        """
        t = kernel_array(np.atleast_1d(np.asarray(t, dtype=np.float64)))
        centre, rot = np.empty((t.size, 3)), np.empty((t.size, 3, 3))
        K.exterior_many(t, self._exterior_args(), centre, rot)
        return centre, rot

    # ------------------------------------------------------------------ distortion
    def remove_distortion(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distorted -> undistorted focal-plane coordinates (mm), arrays (N,)."""
        return self._distort(x, y, True)

    def apply_distortion(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Undistorted -> distorted focal-plane coordinates (mm), arrays (N,)."""
        return self._distort(x, y, False)

    def _distort(self, x, y, remove: bool) -> tuple[np.ndarray, np.ndarray]:
        x, y = (kernel_array(np.atleast_1d(np.asarray(v, dtype=np.float64))) for v in (x, y))
        ox, oy = np.empty_like(x), np.empty_like(y)
        K.distortion_many(int(self.distortion_model), self.distortion_coefficients, x, y, remove, ox, oy)
        return ox, oy

    # ------------------------------------------------------------------ image -> ground
    def image_to_ground(self, line: ArrayLike, sample: ArrayLike, height: ArrayLike = 0.0) -> ImageToGround:
        """Ground points of CSM image coordinates at heights above the file's ellipsoid.

        Parameters
        ----------
        line, sample : ndarray, shape (N,)
            CSM image coordinates (first pixel centre (0.5, 0.5)).
        height : float or ndarray (N,)
            Metres; the ellipsoid's semi-axes are inflated by it (usgscsm).

        Returns
        -------
        ImageToGround
            ``ground`` (N, 3) body-fixed metres, NaN where the ray misses or the line's time is outside
            the ephemeris tables (:meth:`line_covered`: flagged, never extrapolated); ``hit`` (N,).
        """
        line, sample, height = self._broadcast(line, sample, height)
        ground, hit = self._image_to_ground_raw(line, sample, height)
        outside = ~self.line_covered(line)
        if outside.any():
            ground[outside] = np.nan
            hit = hit & ~outside
        return ImageToGround(ground, hit)

    def _image_to_ground_raw(self, line: np.ndarray, sample: np.ndarray,
                             height: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`image_to_ground` without the table-coverage flag (the tables extrapolated linearly):
        only for the solver's own set-up (seed polynomial and its correction table)."""
        line, sample, height = self._broadcast(line, sample, height)
        n = line.size
        ground, status = np.empty((n, 3)), np.empty(n, np.int8)
        centre, look = np.empty((n, 3)), np.empty((n, 3))
        K.image_to_ground_nb(line, sample, height, *self._all_args(), ground, status, centre,  # type: ignore[call-arg]
                             look)
        return ground, status == K.STATUS_OK

    def rays(self, line: ArrayLike, sample: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Perspective centres (N, 3) and unit look directions (N, 3), body-fixed, of image points.

        NaN rows for lines whose time is outside the ephemeris tables (:meth:`line_covered`): flagged,
        never extrapolated."""
        line, sample, height = self._broadcast(line, sample, 0.0)
        n = line.size
        ground, status = np.empty((n, 3)), np.empty(n, np.int8)
        centre, look = np.empty((n, 3)), np.empty((n, 3))
        K.image_to_ground_nb(line, sample, height, *self._all_args(), ground, status, centre,  # type: ignore[call-arg]
                             look)
        outside = ~self.line_covered(line)
        centre[outside] = np.nan
        look[outside] = np.nan
        return centre, look

    def time_covered(self, t: ArrayLike) -> np.ndarray:
        """True (N,) where times (N,) (seconds from ``center_ephemeris_time``) lie inside every ephemeris
        table (``table_span``, no slack): :meth:`exterior` and :meth:`detector_residual` compute anywhere
        (the tables extrapolated linearly, for searches), and this says where their numbers are the tables'."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        lo, hi = self.table_span
        with np.errstate(invalid="ignore"):
            return (t >= lo) & (t <= hi)

    @staticmethod
    def _broadcast(line, sample, height) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        line = check_finite(np.atleast_1d(np.asarray(line, dtype=np.float64)), "line")
        sample = check_finite(np.atleast_1d(np.asarray(sample, dtype=np.float64)), "sample")
        height = check_finite(np.atleast_1d(np.asarray(height, dtype=np.float64)), "height")
        try:
            line, sample, height = np.broadcast_arrays(line, sample, height)
        except ValueError as exc:
            raise InputError(f"line, sample and height do not broadcast: {exc}") from None
        return tuple(kernel_array(a.ravel()) for a in (line, sample, height))  # type: ignore[return-value]

    # ------------------------------------------------------------------ ground -> image
    def _setup_seed(self) -> None:
        """Cubic seed ``line(X, Y, Z)`` fitted on a grid of image points at three heights, and the
        residual's slope (lines per line) at the image centre."""
        lo, hi = self.height_range_m
        lines = np.linspace(0.0, self.n_lines, 9)
        samples = np.linspace(0.0, self.n_samples, 7)
        ll, ss = (a.ravel() for a in np.meshgrid(lines, samples, indexing="ij"))
        pts, rows, covered_rows = [], [], []
        covered = self.line_covered(ll)
        for h in (lo, 0.5 * (lo + hi), hi):
            g, hit = self._image_to_ground_raw(ll, ss, h)
            pts.append(g[hit])
            rows.append(ll[hit])
            covered_rows.append(covered[hit])
        ground = np.concatenate(pts)
        line = np.concatenate(rows)
        if line.size < 10:
            raise SceneFileError(f"{self.source}: fewer than 10 image points of the setup grid reach the body; "
                                 "the camera does not look at it")
        mean = ground.mean(axis=0)
        scale = ground.std(axis=0)
        scale[scale == 0] = 1.0
        feats = _cubic((ground - mean) / scale)
        if line.size < 2 * feats.shape[1]:
            feats = _quadratic((ground - mean) / scale)
        coef, *_ = np.linalg.lstsq(feats, line, rcond=None)
        samp = np.concatenate([ss[self._image_to_ground_raw(ll, ss, h)[1]] for h in (lo, 0.5 * (lo + hi), hi)])
        scoef, *_ = np.linalg.lstsq(feats, samp, rcond=None)
        self._seed = (mean, scale, coef)
        self._seed_table = self._correction_table(mean, scale, coef, scoef, 0.5 * (lo + hi))
        # slope of the residual at the centre, and the curvature constant C = max |g''| / (2 |g'|) around
        # the grid points' lines (times a safety factor of 4), for the secant's acceptance test
        in_tables = np.concatenate(covered_rows)
        mid_line = self.covered_centre_line()
        k = int(np.argmin(np.where(in_tables, np.abs(line - mid_line), np.inf)))
        c = ground[k][None, :]
        mid = np.array([line[k]])
        r0, _ = self.detector_residual(c, mid - 0.5)
        r1, _ = self.detector_residual(c, mid + 0.5)
        slope = float(r1[0] - r0[0])
        if not (np.isfinite(slope) and slope != 0.0):
            raise SceneFileError(f"{self.source}: the detector-line residual does not change with the line")
        self._cam[K.C_SLOPE] = slope
        offsets = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])
        probe = np.repeat(ground, offsets.size, axis=0)
        at = (line[:, None] + offsets[None, :]).ravel()
        res5, _ = self.detector_residual(probe, at)
        res5 = res5.reshape(-1, offsets.size)
        d1 = 0.5 * (res5[:, 2:] - res5[:, :-2])
        d2 = res5[:, 2:] - 2 * res5[:, 1:-1] + res5[:, :-2]
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.abs(d2) / (2.0 * np.abs(d1))
        ratio = ratio[np.isfinite(ratio)]
        self._cam[K.C_CURV] = 4.0 * float(np.max(ratio)) if ratio.size else 1.0

    def _correction_table(self, mean, scale, coef, scoef, height: float) -> tuple:
        """The seed polynomial's error along the image (attitude jitter is no polynomial of the ground):
        ``line - seed(ground)`` at the first, middle and last samples at ``height``, tabulated on an even
        grid of the seed's own line (where it is looked up; linear in the line, quadratic in the sample
        from a second polynomial ``sample(X, Y, Z)``).  Empty when the seed is not monotonic along a
        column."""
        margin = 0.25 * self.n_lines + 60.0
        span = self.n_lines + 2 * margin
        step = max(1.0, span / 65536.0)
        lines = np.arange(-margin, self.n_lines + margin + step, step)
        seeds, errors = [], []
        for c in (0.0, 0.5 * self.n_samples, float(self.n_samples)):
            g, hit = self._image_to_ground_raw(lines, np.full(lines.size, c), height)
            if not hit.all():
                return _no_table(coef.size, scoef)
            ls = _features((g - mean) / scale, coef.size) @ coef
            if not np.all(np.diff(ls) > 0):
                return _no_table(coef.size, scoef)
            seeds.append(ls)
            errors.append(lines - ls)
        lo = max(a[0] for a in seeds)
        hi = min(a[-1] for a in seeds)
        nodes = np.arange(lo, hi, step)
        table = np.column_stack([np.interp(nodes, a, e) for a, e in zip(seeds, errors, strict=True)])
        return (np.ascontiguousarray(scoef), np.ascontiguousarray(table), float(nodes[0]), 1.0 / step,
                0.5 * self.n_samples, 2.0 / self.n_samples)

    def _set_look_sign(self) -> None:
        """usgscsm intersects the whole line of sight (the root nearest the camera on either side); here
        the look direction is the one of ``+-(-x, -y, -f)`` that points at the body at the centre line
        (``look_sign``), so that points behind the camera and rays that miss can be told apart."""
        centre, look = self.rays(np.array([self.covered_centre_line()]), np.array([0.5 * self.n_samples]))
        self._cam[K.C_LOOK] = 1.0 if float(np.dot(look[0], -centre[0])) > 0 else -1.0

    def covered_centre_line(self) -> float:
        """The image's centre line (CSM), or the centre of its longest stretch of lines covered by the ephemeris
        tables when the centre is not covered: where frames and set-ups anchor."""
        centre = 0.5 * self.n_lines
        ranges = self.covered_line_ranges()
        if not ranges or bool(self.line_covered(np.array([centre]))[0]):
            return centre
        a, b = max(ranges, key=lambda r: r[1] - r[0])
        return 0.5 * (a + b)

    def anchor_point(self) -> tuple[float, float]:
        """(line, sample) (CSM) where frames and set-ups anchor on the body: the image centre on a covered line
        (:meth:`covered_centre_line`) when its line of sight meets the ellipsoid, else the point nearest to it
        (in pixels) of a 65 x 65 grid over the covered lines whose line of sight does -- a disc of the body
        filling part of the field (New Horizons MVIC on Jupiter).

        Raises
        ------
        SceneFileError
            No point of the grid sees the body (naming the file)."""
        line0, sample0 = self.covered_centre_line(), 0.5 * self.n_samples
        if self._image_to_ground_raw(np.array([line0]), np.array([sample0]), 0.0)[1][0]:
            return line0, sample0
        ranges = self.covered_line_ranges() or [(0.0, float(self.n_lines))]
        lines = np.concatenate([np.linspace(a + 0.5, b - 0.5, 65) for a, b in ranges])
        ll, ss = np.meshgrid(lines, np.linspace(0.5, self.n_samples - 0.5, 65), indexing="ij")
        ll, ss = ll.ravel(), ss.ravel()
        hit = self._image_to_ground_raw(ll, ss, 0.0)[1] & self.line_covered(ll)
        if not hit.any():
            raise SceneFileError(f"{self.source}: no line of sight of the image meets the body's ellipsoid "
                                 "(65 x 65 image points tried)")
        k = int(np.argmin(np.where(hit, np.hypot(ll - line0, ss - sample0), np.inf)))
        return float(ll[k]), float(ss[k])

    @property
    def look_sign(self) -> float:
        """+1 when the camera looks along ``(-x, -y, -f)`` of the focal plane, -1 when along ``(x, y, f)``."""
        return float(self._cam[K.C_LOOK])

    def seed_line(self, ground: np.ndarray) -> np.ndarray:
        """The seed polynomial's line (N,) for body-fixed points (N, 3)."""
        mean, scale, coef = self._seed  # type: ignore[misc]
        return _features((ground - mean) / scale, coef.size) @ coef

    def detector_residual(self, ground: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """usgscsm's detector-line residual (image lines, zero at the best line) and the sample of
        ground points (N, 3) seen at lines (N,); NaN behind the camera.  Computed at any line (the tables
        extrapolated linearly beyond their ends, so that a search can cross them): check a solved line with
        :meth:`line_covered`, as :meth:`ground_to_image` does."""
        ground = kernel_array(as_points(ground))
        # a writable C array whatever the caller passed (a broadcast view is read-only: another numba signature)
        line = kernel_array(np.broadcast_to(np.asarray(line, dtype=np.float64), ground.shape[:1]))
        res, samp = np.empty(line.size), np.empty(line.size)
        K.residual_many(ground, line, *self._all_args(), res, samp)  # type: ignore[call-arg]
        return res, samp

    def ground_to_image(self, ground: np.ndarray, *, tol: float = 1e-11, max_iter: int = 60,
                        margin_lines: float | None = None) -> GroundToImage:
        """Image coordinates of body-fixed ground points (usgscsm ``groundToImage``, solved exactly).

        Parameters
        ----------
        ground : ndarray, shape (N, 3)
            Body-fixed metres.
        tol : float
            Target line error (default 1e-11): stop when the step, or the secant error estimate
            ``C |step| |x1 - x0|``, is at most this.
        max_iter : int
            Residual evaluations per point before ``status = 3``.
        margin_lines : float, optional
            The search window is ``[-margin, lines + margin]`` (default a quarter of the image + 50).

        Returns
        -------
        GroundToImage
        """
        ground = kernel_array(as_points(ground))
        if not (tol > 0 and max_iter >= 2):
            raise InputError(f"tol must be > 0 and max_iter >= 2, got {tol}, {max_iter}")
        margin = 0.25 * self.n_lines + 50.0 if margin_lines is None else float(margin_lines)
        n = ground.shape[0]
        mean, scale, coef = self._seed  # type: ignore[misc]
        seed = (mean, 1.0 / scale, np.ascontiguousarray(coef), *self._seed_table)
        line, sample = np.empty(n), np.empty(n)
        status, evals = np.empty(n, np.int8), np.empty(n, np.int64)
        K.ground_to_image_nb(ground, seed, -margin, self.n_lines + margin, float(tol),  # type: ignore[call-arg]
                             int(max_iter), *self._all_args(), line, sample, status, evals)
        with np.errstate(invalid="ignore"):
            inside = (line >= 0) & (line <= self.n_lines) & (sample >= 0) & (sample <= self.n_samples)
        solved = status == K.STATUS_OK
        outside_tables = solved & ~self.line_covered(line)
        status[outside_tables] = STATUS_OUTSIDE_TABLES
        return GroundToImage(line, sample, solved & ~outside_tables & inside, status, evals)

    # ------------------------------------------------------------------ description
    def describe(self) -> str:
        """A few lines describing the camera."""
        span = self.line_time(np.array([0.0, float(self.n_lines)]))
        ranges = self.covered_line_ranges()
        fraction = sum(b - a for a, b in ranges) / self.n_lines
        coverage = "" if fraction == 1.0 else (
            f"\n  ephemeris tables cover {100 * fraction:.1f} % of the lines ("
            + ", ".join(f"{a:.0f}-{b:.0f}" for a, b in ranges) + "); the other lines are flagged, not extrapolated")
        return (
            f"CSM line scanner {self.name}: {self.n_lines} lines x {self.n_samples} samples, "
            f"{self.rate_lines.size} line rate(s), imaging {span[1] - span[0]:.4f} s\n"
            f"  body radii {self.semi_major_m:.3f} / {self.semi_minor_m:.3f} m, focal length "
            f"{self.focal_length_mm} mm, distortion {self.distortion_name}, summing "
            f"{self.line_summing:g} x {self.sample_summing:g}\n"
            f"  {self.position_times.size} positions (Lagrange order {self.position_order}, "
            f"{'J2000' if self.position_in_j2000 else 'body-fixed'}), {self.pointing_times.size} pointing and "
            f"{self.body_times.size} body-rotation quaternions ({self.attitude_interpolation})"
            + coverage
        )


def _features(u: np.ndarray, n_terms: int) -> np.ndarray:
    return _cubic(u) if n_terms == 20 else _quadratic(u)


def _no_table(n_terms: int, scoef: np.ndarray) -> tuple:
    return (np.ascontiguousarray(scoef), np.zeros((0, 3)), 0.0, 1.0, 0.0, 1.0)


def _cubic(u: np.ndarray) -> np.ndarray:
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    return np.column_stack([_quadratic(u), x**3, y**3, z**3, x * x * y, x * x * z, y * y * x, y * y * z,
                            z * z * x, z * z * y, x * y * z])


def _quadratic(u: np.ndarray) -> np.ndarray:
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    return np.column_stack([np.ones_like(x), x, y, z, x * x, y * y, z * z, x * y, x * z, y * z])


# --------------------------------------------------------------------------- reader
def read_isd(path: str | Path, *, interpolation: str = "usgscsm") -> CsmCamera:
    """Read a USGS CSM line-scan ISD (JSON written by ALE) into a :class:`CsmCamera`.

    Parameters
    ----------
    path : str or Path
    interpolation : {"usgscsm", "tables"}
        ``"usgscsm"`` (default) reproduces usgscsm's camera state: the positions are resampled
        onto ``max(n, 25)`` evenly spaced nodes by cubic Hermite interpolation with the ISD's
        velocities (ALE's spline; plain Lagrange of the stated order without velocities), the
        sensor -> body rotation onto as many nodes as the union of the two rotation tables' times by
        slerp, and both are then interpolated by usgscsm's Lagrange window (order 8; 4 for fewer
        than 6 quaternions), the quaternion components renormalised.  ``"tables"`` interpolates the
        tables as given: Lagrange of the stated order on the position samples, slerp between
        the rotation samples.

    Raises
    ------
    SceneFileError
        A file that is not a regular, readable text file (FIFO, device, binary junk), not valid JSON
        (nested deeper than :data:`explorer.io_input.MAX_JSON_DEPTH`, number literals longer than
        :data:`explorer.io_input.MAX_NUMBER_DIGITS`), a missing key, NaN values, bad units, an
        unsupported distortion model, a physically impossible camera (see :func:`camera_from_isd`)
        or a sensor model other than the line scanner: one line naming the file (and the key).
    """
    path = Path(path)
    # a regular file only (never blocks on a FIFO or device), any text encoding (BOM, UTF-8, UTF-16,
    # Latin-1), binary content, deep nesting and absurd number literals refused by name (explorer.io_input)
    data = load_json_file(path, what="ISD")
    return camera_from_isd(data, source=str(path), interpolation=interpolation)


def camera_from_isd(data: dict, *, source: str = "<isd>", interpolation: str = "usgscsm") -> CsmCamera:
    """:func:`read_isd` on an already parsed ISD dict."""
    isd = _Isd(data, source)
    if interpolation not in ("usgscsm", "tables"):
        raise InputError(f"interpolation must be 'usgscsm' or 'tables', got {interpolation!r}")
    model = isd.get("name_model", default="USGS_ASTRO_LINE_SCANNER_SENSOR_MODEL")
    if model != "USGS_ASTRO_LINE_SCANNER_SENSOR_MODEL":
        raise isd.fail("name_model", f"is {model!r}; only USGS_ASTRO_LINE_SCANNER_SENSOR_MODEL is read")
    n_lines = isd.number("image_lines", positive=True)
    n_samples = isd.number("image_samples", positive=True)
    for key, v in (("image_lines", n_lines), ("image_samples", n_samples)):
        if v != round(v) or v < 1 or v > 1e9:
            raise isd.fail(key, f"must be a whole number of pixels between 1 and 1e9, got {v!r}")
    center = isd.number("center_ephemeris_time")
    rates = isd.array("line_scan_rate", shape=(None, 3))
    if rates.shape[0] < 1:
        raise isd.fail("line_scan_rate", "is empty")
    if rates.shape[0] > 1 and np.any(np.diff(rates[:, 0]) <= 0):
        raise isd.fail("line_scan_rate", "start lines must increase")
    if np.any(rates[:, 2] <= 0):
        raise isd.fail("line_scan_rate", "integration times must be positive")
    method = isd.get("interpolation_method", default="lagrange")
    if str(method).lower() != "lagrange":
        raise isd.fail("interpolation_method", f"is {method!r}; only 'lagrange' is supported")
    order = isd.get("instrument_position", "interpolation_order", default=isd.get("interpolation_order", default=8))
    if not isinstance(order, int) or isinstance(order, bool) or order < 2:
        raise isd.fail("interpolation_order", f"must be an integer >= 2, got {order!r}")
    a = isd.number("radii", "semimajor", positive=True) * isd.unit("radii", "unit")
    b = isd.number("radii", "semiminor", positive=True) * isd.unit("radii", "unit")
    # positions
    pos = isd.array("instrument_position", "positions", shape=(None, 3))
    if pos.shape[0] < 2:
        raise isd.fail("instrument_position.positions", "needs at least 2 samples")
    # every time is kept relative to center_ephemeris_time: absolute ephemeris times (~3e8 s) have
    # a float64 spacing of 6e-8 s, tens of microlines for a fast line scanner
    pos_t = _times(isd, "instrument_position", pos.shape[0]) - center
    pos_m = np.ascontiguousarray(pos * isd.unit("instrument_position", "unit", default="km"))
    # the sensor must be outside the body: a position within the inscribed sphere (radius = the smaller
    # semi-axis) is inside it whatever the frame (J2000 or body-fixed, both centred on the body)
    dist = np.linalg.norm(pos_m, axis=1)
    inside = np.flatnonzero(dist <= min(a, b))
    if inside.size:
        i = int(inside[0])
        raise isd.fail("instrument_position.positions",
                       f"row {i} is {dist[i]:.6g} m from the body centre, inside the body (radii {a:.6g} / "
                       f"{b:.6g} m; {inside.size} of {dist.size} rows): a line scanner images from above the "
                       "surface")
    frame = isd.get("instrument_position", "reference_frame", default=J2000_FRAME)
    body_frames = isd.get("body_rotation", "time_dependent_frames", default=[None])
    body_frame = body_frames[0] if isinstance(body_frames, list) and body_frames else None
    if frame == J2000_FRAME:
        in_j2000 = True
    elif body_frame is not None and frame == body_frame:
        in_j2000 = False
    else:
        raise isd.fail("instrument_position.reference_frame",
                       f"is {frame!r}: expected 1 (J2000) or the body frame {body_frame!r}")
    qp_t, qp, cp = _rotation_table(isd, "instrument_pointing")
    qb_t, qb, cb = _rotation_table(isd, "body_rotation")
    qp_t, qb_t = qp_t - center, qb_t - center
    spans = {name: (float(t[0]), float(t[-1])) for name, t in
             (("instrument_position", pos_t), ("instrument_pointing", qp_t), ("body_rotation", qb_t)) if t.size > 1}
    span_lo = max(spans.items(), key=lambda kv: kv[1][0], default=("", (-math.inf, 0.0)))
    span_hi = min(spans.items(), key=lambda kv: kv[1][1], default=("", (0.0, math.inf)))
    vel = None
    if "velocities" in isd.get("instrument_position"):
        vel = isd.array("instrument_position", "velocities", shape=pos.shape)
        vel = vel * isd.unit("instrument_position", "unit", default="km")
    att_mode, att_order = "slerp", int(order)
    if interpolation == "usgscsm":
        pos_t, pos_m, in_j2000, qp_t, qp, cp, qb_t, qb, cb = _usgscsm_state(
            pos_t, pos_m, vel, int(order), in_j2000, qp_t, qp, cp, qb_t, qb, cb)
        att_mode, att_order, order = "lagrange", (8 if qp_t.size >= 6 else 4), 8
    fl = isd.array("focal2pixel_lines", shape=(3,))
    fs = isd.array("focal2pixel_samples", shape=(3,))
    name, code, coef = _distortion(isd)
    h_lo, h_hi = -1000.0, 1000.0
    if "reference_height" in data:
        hu = isd.unit("reference_height", "unit")
        h_lo = isd.number("reference_height", "minheight") * hu
        h_hi = isd.number("reference_height", "maxheight") * hu
        if not h_hi > h_lo:
            raise isd.fail("reference_height", "maxheight must exceed minheight")
        small = min(a, b)
        if not (-0.5 * small < h_lo and h_hi < 0.5 * small):
            raise isd.fail("reference_height", f"minheight {h_lo:.6g} m / maxheight {h_hi:.6g} m must lie within "
                           f"half the body's smaller semi-axis ({0.5 * small:.6g} m) of its surface")
        lowest = float(np.min(np.linalg.norm(pos_m, axis=1))) - small  # the most lenient altitude estimate
        if h_hi >= lowest:
            raise isd.fail("reference_height", f"maxheight {h_hi:.6g} m is not below the sensor (lowest position "
                           f"at most {lowest:.6g} m above the surface)")
    return CsmCamera(
        source=source,
        name=str(isd.get("image_identifier", default=isd.get("name_sensor", default=Path(source).stem))),
        n_lines=int(round(n_lines)),
        n_samples=int(round(n_samples)),
        semi_major_m=a,
        semi_minor_m=b,
        center_time=center,
        rate_lines=np.ascontiguousarray(rates[:, 0]),
        rate_times=np.ascontiguousarray(rates[:, 1]),
        rate_periods=np.ascontiguousarray(rates[:, 2]),
        position_times=pos_t,
        positions_m=pos_m,
        position_order=int(order),
        position_in_j2000=in_j2000,
        pointing_times=qp_t,
        pointing_quaternions=qp,
        pointing_constant=cp,
        body_times=qb_t,
        body_quaternions=qb,
        body_constant=cb,
        attitude_interpolation=att_mode,
        attitude_order=att_order,
        focal_length_mm=isd.number("focal_length_model", "focal_length", positive=True),
        line_origin=isd.number("detector_center", "line"),
        sample_origin=isd.number("detector_center", "sample"),
        starting_line=isd.number("starting_detector_line"),
        starting_sample=isd.number("starting_detector_sample"),
        line_summing=isd.number("detector_line_summing", positive=True),
        sample_summing=isd.number("detector_sample_summing", positive=True),
        focal2pixel_lines=np.ascontiguousarray(fl),
        focal2pixel_samples=np.ascontiguousarray(fs),
        distortion_name=name,
        distortion_model=code,
        distortion_coefficients=coef,
        height_range_m=(h_lo, h_hi),
        metadata={"platform": data.get("name_platform"), "sensor": data.get("name_sensor"),
                  "starting_ephemeris_time": data.get("starting_ephemeris_time"), "interpolation": interpolation,
                  "table_spans": spans},
        table_span=(span_lo[1][0], span_hi[1][1]),
        table_span_names=(span_lo[0], span_hi[0]),
    )


def _hermite(times: np.ndarray, pos: np.ndarray, vel: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Cubic Hermite interpolation of positions with their velocities (between neighbours)."""
    i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, times.size - 2)
    h = (times[i + 1] - times[i])[:, None]
    s = ((t - times[i]) / (times[i + 1] - times[i]))[:, None]
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return h00 * pos[i] + h10 * h * vel[i] + h01 * pos[i + 1] + h11 * h * vel[i + 1]


def _matrix_quaternion(m: np.ndarray) -> np.ndarray:
    """Unit quaternions (N, 4) ``(w, x, y, z)`` of rotation matrices (N, 3, 3)."""
    return matrix_to_quaternion(m)


def _usgscsm_state(pos_t, pos_m, vel, order, in_j2000, qp_t, qp, cp, qb_t, qb, cb) -> tuple:
    """usgscsm's state: positions on max(n, 25) even nodes (Hermite with velocities, else Lagrange),
    body-fixed; sensor -> body quaternions on as many even nodes as the union of the rotation
    tables' times (slerp of each table).  Returned as tables for the Lagrange kernels: the
    conjugate quaternions play the J2000 -> sensor table with an identity body rotation."""
    nodes = np.linspace(pos_t[0], pos_t[-1], max(pos_t.size, 25))
    if vel is not None:
        p_nodes = _hermite(pos_t, pos_m, vel, nodes)
    else:
        p_nodes = np.empty((nodes.size, 3))
        out = np.empty(3)
        for k, t in enumerate(nodes):
            K.lagrange_eval(pos_t, pos_m, float(t), order, out)
            p_nodes[k] = out
    union = np.union1d(qp_t, qb_t)
    q_nodes = np.linspace(union[0], union[-1], union.size) if union.size > 1 else union
    both = np.union1d(nodes, q_nodes)
    centre_fixed = np.empty((0, 3))
    rot = np.empty((both.size, 3, 3))
    body = np.empty((both.size, 3, 3))
    q, r = np.empty(4), np.empty((3, 3))
    for k, t in enumerate(both):
        K.quaternion_at(qb_t, qb, float(t), 0, 8, q)
        K.quaternion_matrix(q, r)
        b = cb @ r
        K.quaternion_at(qp_t, qp, float(t), 0, 8, q)
        K.quaternion_matrix(q, r)
        body[k] = b
        rot[k] = b @ (cp @ r).T
    idx = np.searchsorted(both, nodes)
    centre_fixed = np.einsum("nij,nj->ni", body[idx], p_nodes) if in_j2000 else p_nodes
    qn = _matrix_quaternion(rot[np.searchsorted(both, q_nodes)])
    qn[:, 1:] *= -1.0  # conjugate: the camera -> body rotation M enters the kernels as M = I P^T
    ident_t = np.array([q_nodes[0]])
    return (np.ascontiguousarray(nodes), np.ascontiguousarray(centre_fixed), False, np.ascontiguousarray(q_nodes),
            _continuous(qn), np.eye(3), ident_t, np.array([[1.0, 0.0, 0.0, 0.0]]), np.eye(3))
