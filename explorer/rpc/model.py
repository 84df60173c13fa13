"""Rational function model (RPC00B) evaluation and iterative localisation (the intersection with a DEM is
:func:`explorer.rpc.dem.localization_on_dem`).

Pixel convention (one for the whole package, see ``docs/conventions.md`` and ``docs/rpc.md``):
rows and columns are **0-based and an integer is the centre of a pixel** (the RPC00B/NITF
convention). Readers of 1-based formats (DIMAP v2, DIMAP v1.4) convert at read time, so a
:class:`RationalFunctionModel` never carries another convention.

Ground coordinates are longitude and latitude in degrees (WGS84) and heights in metres above the
ellipsoid. Everything is vectorised with numpy over arrays of any (broadcastable) shape.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from explorer.errors import ConvergenceError, InputError
from explorer.rpc import _kernels
from explorer.rpc.polynomial import (  # noqa: F401 - re-exported: the model's public and shared names
    _CUBE,
    _FILE_KEYS,
    LOCALIZATION_LIMIT,
    MAX_COEFFICIENT,
    RPC00B_TERMS,
    VALIDITY_MARGIN,
    FloatArray,
    HeightSource,
    InverseRFM,
    ValidityDomain,
    _as_float_array,
    _rpc00b_polynomial_and_gradient,
    _use_numba,
    evaluate_rpc00b_polynomial,
    rpc00b_monomials,
)

#: Physical limits every read RPC meets (``docs/validation.md``): the half-extent of the image is at least
#: half a pixel, the height range at least a millimetre, the ground half-extent at least ~1 m (1e-5 degree);
#: the normalised Jacobian |d(row, col) / d(L, P)| (O(1) for every real image) at least 1e-6.
MIN_PIXEL_SCALE = 0.5
MIN_HEIGHT_SCALE_M = 1e-3
MIN_DEGREE_SCALE = 1e-5
MIN_JACOBIAN = 1e-6

__all__ = [
    "LOCALIZATION_LIMIT",
    "VALIDITY_MARGIN",
    "ConvergenceError",
    "InverseRFM",
    "RationalFunctionModel",
    "ValidityDomain",
    "evaluate_rpc00b_polynomial",
    "rpc00b_monomials",
]

@dataclass(frozen=True)
class RationalFunctionModel:
    """RPC00B rational function model, 0-based pixel-centre convention.

    ``row = row_offset + row_scale * row_num(L, P, H) / row_den(L, P, H)`` with
    ``L = (lon - lon_offset) / lon_scale``, ``P = (lat - lat_offset) / lat_scale`` and
    ``H = (h - height_offset) / height_scale``; the same for ``col``.

    Parameters
    ----------
    row_num, row_den, col_num, col_den : ndarray, shape (20,)
        RPC00B coefficients (LINE_NUM, LINE_DEN, SAMP_NUM, SAMP_DEN), file order.
    row_offset, col_offset : float
        Pixels, 0-based pixel-centre convention.
    lat_offset, lon_offset : float
        Degrees.
    height_offset : float
        Metres above the ellipsoid.
    row_scale, col_scale, lat_scale, lon_scale, height_scale : float
        Same units as the offsets; non-zero (may be negative, e.g. PlanetScope ``LAT_SCALE``).
    inverse : InverseRFM, optional
        Image-to-ground functions when the file has them (DIMAP); used as Newton start.
    validity : ValidityDomain, optional
        Declared validity box; defaults to offset +- scale on each axis.
    image_size : (rows, cols), optional
        Image size when the file states it.
    source_format : str
        Name of the format that was read (``"rpc00b_txt"``, ``"dimap_v2"``...).
    source_path : str, optional
        File the model was read from.
    metadata : dict
        Extra fields (error bias, satellite id...).
    """

    row_num: FloatArray
    row_den: FloatArray
    col_num: FloatArray
    col_den: FloatArray
    row_offset: float
    col_offset: float
    lat_offset: float
    lon_offset: float
    height_offset: float
    row_scale: float
    col_scale: float
    lat_scale: float
    lon_scale: float
    height_scale: float
    inverse: InverseRFM | None = None
    validity: ValidityDomain | None = None
    image_size: tuple[int, int] | None = None
    source_format: str = "unknown"
    source_path: str | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("row_num", "row_den", "col_num", "col_den"):
            key = _FILE_KEYS[name]
            coefficients = np.asarray(getattr(self, name), dtype=np.float64).reshape(-1)
            if coefficients.shape != (20,):
                raise InputError(f"{key} ({name}) must have 20 coefficients, got {coefficients.size}")
            if not np.isfinite(coefficients).all():
                k = int(np.flatnonzero(~np.isfinite(coefficients))[0])
                raise InputError(f"{key}_{k + 1} ({name}[{k}]) is not finite: {coefficients[k]}")
            object.__setattr__(self, name, coefficients)
        for name in ("row", "col", "lat", "lon", "height"):
            key = _FILE_KEYS[name]
            offset = float(getattr(self, f"{name}_offset"))
            scale = float(getattr(self, f"{name}_scale"))
            if not np.isfinite(offset):
                raise InputError(f"{key}_OFF ({name}_offset) is not finite: {offset}")
            if not np.isfinite(scale) or scale == 0.0:
                raise InputError(f"{key}_SCALE ({name}_scale) must be finite and non-zero, got {scale}")
            object.__setattr__(self, f"{name}_offset", offset)
            object.__setattr__(self, f"{name}_scale", scale)
        if self.inverse is not None:
            arrays = {
                k: np.asarray(getattr(self.inverse, k), dtype=np.float64).reshape(20)
                for k in ("lon_num", "lon_den", "lat_num", "lat_den")
            }
            for key, v in arrays.items():
                if not np.isfinite(v).all():
                    raise InputError(f"image-to-ground {key} has non-finite coefficients")
            object.__setattr__(self, "inverse", InverseRFM(**arrays))
        if self.validity is not None:
            for key, bound in vars(self.validity).items():
                if bound is not None and not np.isfinite(bound):
                    raise InputError(f"validity domain {key} is not finite: {bound}")
        if self.image_size is not None and not (int(self.image_size[0]) > 0 and int(self.image_size[1]) > 0):
            raise InputError(f"image size {self.image_size} must be positive")

    @property
    def geodetic(self) -> bool:
        """True when the ground coordinates are longitude/latitude degrees (every file format);
        False for models fitted in other coordinates (``source_format="fitted"``, e.g. local ENU
        metres in the roles of lon/lat/h), which skip the degree range checks."""
        return self.source_format != "fitted"

    def validate(self) -> RationalFunctionModel:
        """Check that the values describe a usable RPC; the readers call it on every file.

        Coefficients at most :data:`MAX_COEFFICIENT` in magnitude (normalised RPC00B coefficients
        are O(1)); denominators that neither vanish nor change sign on the normalised cube
        ``[-1, 1]^3`` (7 x 7 x 7 nodes); for :attr:`geodetic` models, ``LAT_OFF`` in
        [-90, 90], ``|LAT_SCALE| <= 90``, ``LONG_OFF`` in [-180, 360], ``|LONG_SCALE| <= 180``,
        heights and pixel offsets/scales below 100 km and 1e8 pixels.

        Returns
        -------
        self

        Raises
        ------
        InputError
            Naming the field (RPC00B key and attribute) and its value.
        """
        for name in ("row_num", "row_den", "col_num", "col_den"):
            coefficients = getattr(self, name)
            if np.max(np.abs(coefficients)) > MAX_COEFFICIENT:
                k = int(np.argmax(np.abs(coefficients)))
                raise InputError(f"{_FILE_KEYS[name]}_{k + 1} ({name}[{k}]) = {coefficients[k]:.6g} is implausibly "
                                 f"large (normalised RPC coefficients are O(1); limit {MAX_COEFFICIENT:g})")
        if self.geodetic:
            self._check_ranges()
        nodes = self._validity_nodes()
        for name in ("row_den", "col_den"):
            den = evaluate_rpc00b_polynomial(getattr(self, name), *nodes)
            if not np.all(np.isfinite(den)) or np.any(den == 0.0) or np.any(np.sign(den) != np.sign(den[0])):
                k = int(np.argmin(np.abs(den)))
                where = ", ".join(f"{a}={v:+.2f}" for a, v in zip("LPH", nodes[:, k], strict=True))
                raise InputError(f"{_FILE_KEYS[name]} ({name}) vanishes inside the validity domain (near {where}): "
                                 "the projection is singular there")
        self._check_scales()
        self._check_ground_to_image_invertible()
        return self

    def _validity_nodes(self) -> np.ndarray:
        """Nodes (3, 343) in normalised (L, P, H) covering the cube [-1, 1]^3 and the declared validity box
        where it reaches past the cube (a box beyond +-2 in normalised units is not a validity domain of these
        polynomials and is not used)."""
        declared = self.validity
        axes = []
        for name, low_key, high_key in (("lon", "lon_min", "lon_max"), ("lat", "lat_min", "lat_max"),
                                        ("height", "h_min", "h_max")):
            low, high = -1.0, 1.0
            if declared is not None:
                offset, scale = getattr(self, f"{name}_offset"), getattr(self, f"{name}_scale")
                bounds = [getattr(declared, k) for k in (low_key, high_key)]
                if all(b is not None for b in bounds):
                    a, b = sorted((float(v) - offset) / scale for v in bounds)
                    if -2.0 <= a and b <= 2.0:
                        low, high = min(low, a), max(high, b)
            axes.append(np.linspace(low, high, 7))
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=0).reshape(3, -1)

    def _check_scales(self) -> None:
        """Scales of a physical image: the pixel and height scales positive (half the image size, half the height
        range), at least half a pixel and a millimetre; the degree scales (negative in PlanetScope files: the
        sign orients the axis) at least ~1 m in magnitude."""
        for name, least, unit in (("row", MIN_PIXEL_SCALE, "px"), ("col", MIN_PIXEL_SCALE, "px"),
                                  ("height", MIN_HEIGHT_SCALE_M, "m")):
            scale = getattr(self, f"{name}_scale")
            if scale <= 0.0:
                raise InputError(f"{_FILE_KEYS[name]}_SCALE ({name}_scale) = {scale:g} {unit} is not positive: a scale "
                                 "is half the extent of its axis")
            if scale < least:
                raise InputError(f"{_FILE_KEYS[name]}_SCALE ({name}_scale) = {scale:g} {unit} is below {least:g} "
                                 f"{unit}: not the extent of a physical image")
        if self.geodetic:
            for name in ("lat", "lon"):
                scale = getattr(self, f"{name}_scale")
                if abs(scale) < MIN_DEGREE_SCALE:
                    raise InputError(f"{_FILE_KEYS[name]}_SCALE ({name}_scale) = {scale:g} degrees is below "
                                     f"{MIN_DEGREE_SCALE:g} degrees (~1 m) in magnitude: not the footprint of an image")

    def _check_ground_to_image_invertible(self) -> None:
        """The ground-to-image map is one-to-one on the normalised cube: the 2 x 2 Jacobian of (row, col) over
        (L, P) neither vanishes nor changes sign (an all-zero numerator, or one that ignores the ground
        position, makes every point project to one row or column)."""
        step = 1e-4
        base = _CUBE.copy()

        def rc(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            r = evaluate_rpc00b_polynomial(self.row_num, *points) / evaluate_rpc00b_polynomial(self.row_den, *points)
            c = evaluate_rpc00b_polynomial(self.col_num, *points) / evaluate_rpc00b_polynomial(self.col_den, *points)
            return r, c

        grads = []
        for axis in (0, 1):
            hi, lo = base.copy(), base.copy()
            hi[axis] += step
            lo[axis] -= step
            (r1, c1), (r0, c0) = rc(hi), rc(lo)
            grads.append(((r1 - r0) / (2 * step), (c1 - c0) / (2 * step)))
        (dr_dl, dc_dl), (dr_dp, dc_dp) = grads
        with np.errstate(over="ignore", invalid="ignore"):
            det = dr_dl * dc_dp - dr_dp * dc_dl
        k = int(np.argmin(np.abs(np.nan_to_num(det, nan=0.0))))
        where = ", ".join(f"{a}={v:+.2f}" for a, v in zip("LPH", _CUBE[:, k], strict=True))
        if not np.all(np.isfinite(det)) or np.min(np.abs(det)) < MIN_JACOBIAN:
            zero = [f"{_FILE_KEYS[n]}" for n in ("row_num", "col_num") if not np.any(getattr(self, n))]
            why = f"{' and '.join(zero)} all zero" if zero else f"near {where}"
            raise InputError(f"the ground-to-image map is degenerate ({why}): rows and columns do not both "
                             "change with longitude and latitude, so ground points cannot be told apart")
        if np.any(np.sign(det) != np.sign(det[0])):
            raise InputError(f"the ground-to-image map folds over inside the normalised domain (near {where}): "
                             "two ground points would project to one pixel")

    def _check_ranges(self) -> None:
        """Offsets and scales of a geodetic model in their physical ranges."""
        if not -90.0 <= self.lat_offset <= 90.0:
            raise InputError(f"LAT_OFF (lat_offset) = {self.lat_offset:g} is outside [-90, 90] degrees")
        if not abs(self.lat_scale) <= 90.0:
            raise InputError(f"LAT_SCALE (lat_scale) = {self.lat_scale:g} exceeds 90 degrees")
        if not -180.0 <= self.lon_offset <= 360.0:
            raise InputError(f"LONG_OFF (lon_offset) = {self.lon_offset:g} is outside [-180, 360] degrees")
        if not abs(self.lon_scale) <= 180.0:
            raise InputError(f"LONG_SCALE (lon_scale) = {self.lon_scale:g} exceeds 180 degrees")
        if not abs(self.height_offset) <= 1e5 or not abs(self.height_scale) <= 1e5:
            raise InputError(f"HEIGHT_OFF / HEIGHT_SCALE ({self.height_offset:g} / {self.height_scale:g} m) "
                             "beyond 100 km: not a ground RPC")
        for name in ("row", "col"):
            off, scale = getattr(self, f"{name}_offset"), getattr(self, f"{name}_scale")
            if not (abs(off) <= 1e8 and abs(scale) <= 1e8):
                raise InputError(f"{_FILE_KEYS[name]}_OFF / {_FILE_KEYS[name]}_SCALE ({off:g} / {scale:g} px) "
                                 "beyond 1e8 pixels")

    # ------------------------------------------------------------------ domain
    @property
    def domain(self) -> ValidityDomain:
        """Validity domain: the declared one, completed with offset +- |scale| on each axis."""
        declared = self.validity or ValidityDomain()

        def pick(value: float | None, default: float) -> float:
            return float(default) if value is None else float(value)

        return ValidityDomain(
            lon_min=pick(declared.lon_min, self.lon_offset - abs(self.lon_scale)),
            lon_max=pick(declared.lon_max, self.lon_offset + abs(self.lon_scale)),
            lat_min=pick(declared.lat_min, self.lat_offset - abs(self.lat_scale)),
            lat_max=pick(declared.lat_max, self.lat_offset + abs(self.lat_scale)),
            h_min=pick(declared.h_min, self.height_offset - abs(self.height_scale)),
            h_max=pick(declared.h_max, self.height_offset + abs(self.height_scale)),
            row_min=pick(declared.row_min, self.row_offset - abs(self.row_scale)),
            row_max=pick(declared.row_max, self.row_offset + abs(self.row_scale)),
            col_min=pick(declared.col_min, self.col_offset - abs(self.col_scale)),
            col_max=pick(declared.col_max, self.col_offset + abs(self.col_scale)),
        )

    def height_range(self, fraction: float = 1.0) -> tuple[float, float]:
        """Height interval ``height_offset -+ fraction * |height_scale|`` in metres.

        ``fraction=1`` is the normalisation domain ([-1, 1] in normalised height). CNES shareloc's
        ``get_alt_min_max`` uses ``fraction=0.5``.
        """
        half = fraction * abs(self.height_scale)
        return self.height_offset - half, self.height_offset + half

    def in_domain(self, lon: ArrayLike, lat: ArrayLike, h: ArrayLike) -> NDArray[np.bool_]:
        """Boolean mask of ground points inside :attr:`domain` (bounds included)."""
        d = self.domain
        lon_a, lat_a, h_a = np.broadcast_arrays(np.asarray(lon, float), np.asarray(lat, float), np.asarray(h, float))
        return (
            (lon_a >= d.lon_min) & (lon_a <= d.lon_max)
            & (lat_a >= d.lat_min) & (lat_a <= d.lat_max)
            & (h_a >= d.h_min) & (h_a <= d.h_max)
        )  # fmt: skip

    def with_pixel_shift(self, drow: float, dcol: float) -> RationalFunctionModel:
        """Copy with shifted image coordinates: ``row' = row + drow``, ``col' = col + dcol``."""
        return replace(self, row_offset=self.row_offset + drow, col_offset=self.col_offset + dcol)

    # -------------------------------------------------------------- projection
    def _normalise_ground(
        self, lon: FloatArray, lat: FloatArray, h: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        return (
            (lon - self.lon_offset) / self.lon_scale,
            (lat - self.lat_offset) / self.lat_scale,
            (h - self.height_offset) / self.height_scale,
        )

    def normalized_projection(self, x: FloatArray, y: FloatArray, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Normalised (row, col) of normalised (L, P, H); no offsets or scales applied."""
        row_n = evaluate_rpc00b_polynomial(self.row_num, x, y, z) / evaluate_rpc00b_polynomial(self.row_den, x, y, z)
        col_n = evaluate_rpc00b_polynomial(self.col_num, x, y, z) / evaluate_rpc00b_polynomial(self.col_den, x, y, z)
        return row_n, col_n

    def ground_validity(
        self, lon: ArrayLike, lat: ArrayLike, h: ArrayLike, *, margin: float = VALIDITY_MARGIN
    ) -> NDArray[np.bool_]:
        """True where a ground point lies in the RPC's validity domain.

        Inside means every normalised coordinate within ``[-1 - margin, 1 + margin]`` and, when
        the file declares a ground box (:attr:`validity`), inside that box widened by
        ``margin * |scale|`` on each side.  NaN is outside.

        Parameters
        ----------
        lon, lat : array_like
            Degrees, broadcastable.
        h : array_like
            Metres above the ellipsoid.
        margin : float
            Tolerance beyond the domain, in units of the scales (default :data:`VALIDITY_MARGIN`).

        Returns
        -------
        ndarray of bool, broadcast shape.
        """
        lon_a, lat_a, h_a = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (lon, lat, h)))
        limit = 1.0 + margin
        with np.errstate(invalid="ignore"):
            x, y, z = self._normalise_ground(lon_a, lat_a, h_a)
            ok = (np.abs(x) <= limit) & (np.abs(y) <= limit) & (np.abs(z) <= limit)
            box = self.validity or ValidityDomain()
            for value, lo, hi, scale in ((lon_a, box.lon_min, box.lon_max, self.lon_scale),
                                         (lat_a, box.lat_min, box.lat_max, self.lat_scale),
                                         (h_a, box.h_min, box.h_max, self.height_scale)):
                if lo is not None:
                    ok &= value >= lo - margin * abs(scale)
                if hi is not None:
                    ok &= value <= hi + margin * abs(scale)
        return ok

    def image_validity(self, row: ArrayLike, col: ArrayLike, *, margin: float = VALIDITY_MARGIN) -> NDArray[np.bool_]:
        """True where an image point lies in the RPC's validity domain.

        Normalised row and column within ``[-1 - margin, 1 + margin]`` and, when the file gives
        them, inside its image box (:attr:`validity`) and its image (``-0.5 .. size - 0.5``), both
        widened by ``margin * |scale|``.  NaN is outside.
        """
        row_a, col_a = np.broadcast_arrays(np.asarray(row, dtype=np.float64), np.asarray(col, dtype=np.float64))
        limit = 1.0 + margin
        box = self.validity or ValidityDomain()
        with np.errstate(invalid="ignore"):
            ok = (np.abs((row_a - self.row_offset) / self.row_scale) <= limit) & (
                np.abs((col_a - self.col_offset) / self.col_scale) <= limit)
            size = self.image_size or (None, None)
            for value, lo, hi, n, scale in ((row_a, box.row_min, box.row_max, size[0], self.row_scale),
                                            (col_a, box.col_min, box.col_max, size[1], self.col_scale)):
                pad = margin * abs(scale)
                if lo is not None:
                    ok &= value >= lo - pad
                if hi is not None:
                    ok &= value <= hi + pad
                if n is not None:
                    ok &= (value >= -0.5 - pad) & (value <= n - 0.5 + pad)
        return ok

    @overload
    def projection(self, lon: ArrayLike, lat: ArrayLike, h: ArrayLike, *, backend: str = "auto",
                   return_valid: Literal[False] = False) -> tuple[FloatArray, FloatArray]: ...
    @overload
    def projection(self, lon: ArrayLike, lat: ArrayLike, h: ArrayLike, *, backend: str = "auto",
                   return_valid: Literal[True]) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]: ...
    def projection(
        self, lon: ArrayLike, lat: ArrayLike, h: ArrayLike, *, backend: str = "auto", return_valid: bool = False
    ) -> tuple[FloatArray, FloatArray] | tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Ground to image.

        Parameters
        ----------
        lon, lat : array_like
            Degrees (WGS84), any broadcastable shapes.
        h : array_like
            Metres above the ellipsoid.
        backend : {"auto", "numba", "numpy"}
            ``"auto"``: one compiled loop (normalisation, four polynomials, divisions and
            denormalisation fused per point; ``prange`` on both cores from 200,000 points) when numba
            is available, else numpy.  Both perform the same floating-point operations in the same
            order (bit-identical results where measured; the tests allow 1e-12 px).

        return_valid : bool
            Also return the validity flags: :meth:`ground_validity` of the input and
            :meth:`image_validity` of the result (a point far outside the scene gets a number
            from the polynomials, but it is an extrapolation, flagged False).

        Returns
        -------
        row, col : ndarray
            0-based pixel-centre image coordinates, broadcast shape of the inputs.
        valid : ndarray of bool
            Only with ``return_valid=True``.

        Raises
        ------
        InputError
            A ValueError: an input contains NaN or an infinity, or (:attr:`geodetic` models) a
            latitude beyond +-90 degrees (the message names it).

        Notes
        -----
        Without ``return_valid`` points outside :attr:`domain` are evaluated (extrapolated) without
        warning; use :meth:`ground_validity` to mask them.
        """
        result = self._projection_compiled(lon, lat, h) if _use_numba(backend) else None
        if result is None:
            lon_a = _as_float_array(lon, "lon")
            lat_a = _as_float_array(lat, "lat")
            h_a = _as_float_array(h, "h")
            x, y, z = self._normalise_ground(lon_a, lat_a, h_a)
            row_n, col_n = self.normalized_projection(x, y, z)
            result = (row_n * self.row_scale + self.row_offset, col_n * self.col_scale + self.col_offset)
        row, col = result
        with np.errstate(invalid="ignore", over="ignore"):
            finite = np.isfinite(np.add.reduce(row, axis=None) + np.add.reduce(col, axis=None))
        if not finite:  # an infinite input (NaN was refused above), or the polynomials overflowed
            for value, name in ((lon, "lon"), (lat, "lat"), (h, "h")):
                _as_float_array(value, name)
        lat_abs = np.abs(np.asarray(lat, dtype=np.float64)) if self.geodetic else np.zeros(0)
        if lat_abs.size and np.max(lat_abs) > 90.0:
            k = int(np.argmax(lat_abs.ravel()))
            raise InputError(f"lat must be within [-90, 90] degrees, got {np.asarray(lat, float).ravel()[k]:g}")
        if return_valid:
            return row, col, self.ground_validity(lon, lat, h) & self.image_validity(row, col)
        return row, col

    def _projection_compiled(
        self, lon: ArrayLike, lat: ArrayLike, h: ArrayLike
    ) -> tuple[FloatArray, FloatArray] | None:
        """:meth:`projection` by the compiled loop; None (use numpy) when the shapes do not broadcast."""
        arrays = [np.asarray(v, dtype=np.float64) for v in (lon, lat, h)]
        try:
            shape = np.broadcast_shapes(*(a.shape for a in arrays))
        except ValueError:
            return None  # the numpy path raises its own error (after its NaN checks)
        flat = [a.ravel() if a.shape == shape else np.broadcast_to(a, shape).ravel() for a in arrays]
        norm = (
            self.lon_offset, self.lon_scale, self.lat_offset, self.lat_scale, self.height_offset,
            self.height_scale, self.row_offset, self.row_scale, self.col_offset, self.col_scale,
        )  # fmt: skip
        row, col, nan_counts = _kernels.project(flat[0], flat[1], flat[2],
                                                (self.row_num, self.row_den, self.col_num, self.col_den), norm)
        if any(nan_counts):  # the numpy path's error, naming the first argument with NaN
            for value, name in zip(arrays, ("lon", "lat", "h"), strict=True):
                _as_float_array(value, name)
        if shape == ():
            return row[0], col[0]
        return row.reshape(shape), col.reshape(shape)

    def inverse_localization(self, row: ArrayLike, col: ArrayLike, h: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Evaluate the file's image-to-ground functions (approximate; DIMAP only).

        Returns
        -------
        lon, lat : ndarray
            Degrees; the vendor's approximation of the inverse, not the exact inverse of
            :meth:`projection` (use :meth:`localization` for that).
        """
        if self.inverse is None:
            raise ValueError("this model has no image-to-ground coefficients")
        row_a = _as_float_array(row, "row")
        col_a = _as_float_array(col, "col")
        h_a = _as_float_array(h, "h")
        return self._inverse_normalized(
            (col_a - self.col_offset) / self.col_scale,
            (row_a - self.row_offset) / self.row_scale,
            (h_a - self.height_offset) / self.height_scale,
            normalized_output=False,
        )

    def _inverse_normalized(
        self, col_n: FloatArray, row_n: FloatArray, z: FloatArray, *, normalized_output: bool
    ) -> tuple[FloatArray, FloatArray]:
        inv = self.inverse
        assert inv is not None
        x_n = evaluate_rpc00b_polynomial(inv.lon_num, col_n, row_n, z) / evaluate_rpc00b_polynomial(
            inv.lon_den, col_n, row_n, z
        )
        y_n = evaluate_rpc00b_polynomial(inv.lat_num, col_n, row_n, z) / evaluate_rpc00b_polynomial(
            inv.lat_den, col_n, row_n, z
        )
        if normalized_output:
            return x_n, y_n
        return x_n * self.lon_scale + self.lon_offset, y_n * self.lat_scale + self.lat_offset

    # ------------------------------------------------------------ localisation
    def _residual_and_jacobian(
        self, x: FloatArray, y: FloatArray, z: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """Pixel (row, col) and their derivatives w.r.t. normalised x (L) and y (P)."""
        rn, rn_x, rn_y = _rpc00b_polynomial_and_gradient(self.row_num, x, y, z)
        rd, rd_x, rd_y = _rpc00b_polynomial_and_gradient(self.row_den, x, y, z)
        cn, cn_x, cn_y = _rpc00b_polynomial_and_gradient(self.col_num, x, y, z)
        cd, cd_x, cd_y = _rpc00b_polynomial_and_gradient(self.col_den, x, y, z)
        row = rn / rd * self.row_scale + self.row_offset
        col = cn / cd * self.col_scale + self.col_offset
        row_x = (rn_x * rd - rn * rd_x) / (rd * rd) * self.row_scale
        row_y = (rn_y * rd - rn * rd_y) / (rd * rd) * self.row_scale
        col_x = (cn_x * cd - cn * cd_x) / (cd * cd) * self.col_scale
        col_y = (cn_y * cd - cn * cd_y) / (cd * cd) * self.col_scale
        return row, col, row_x, row_y, col_x, col_y

    @overload
    def localization(self, row: ArrayLike, col: ArrayLike, h: ArrayLike, *, tol: float = ..., max_iter: int = ...,
                     residual_tol_px: float = ..., raise_on_failure: bool = ...,
                     return_valid: Literal[False] = False) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]: ...
    @overload
    def localization(self, row: ArrayLike, col: ArrayLike, h: ArrayLike, *, tol: float = ..., max_iter: int = ...,
                     residual_tol_px: float = ..., raise_on_failure: bool = ...,
                     return_valid: Literal[True],
                     ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], NDArray[np.bool_]]: ...
    @np.errstate(invalid="ignore", over="ignore", divide="ignore")
    def localization(
        self,
        row: ArrayLike,
        col: ArrayLike,
        h: ArrayLike,
        *,
        tol: float = 1e-10,
        max_iter: int = 50,
        residual_tol_px: float = 1e-6,
        raise_on_failure: bool = False,
        return_valid: bool = False,
    ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]] | tuple[FloatArray, FloatArray, NDArray[np.bool_],
                                                                  NDArray[np.bool_]]:
        """Image to ground at given heights: exact inverse of :meth:`projection` by Newton.

        Newton iterations on the normalised (L, P) with the analytic Jacobian of the projection,
        started from the file's inverse model when present, else from (L, P) = (0, 0); a step
        that does not decrease the pixel residual is halved (up to 30 times).

        Parameters
        ----------
        row, col : array_like
            0-based pixel-centre image coordinates, broadcastable.
        h : array_like
            Heights, metres above the ellipsoid.
        tol : float
            Convergence when the last step is below ``tol`` degrees in longitude and latitude.
        max_iter : int
            Maximum Newton iterations.
        residual_tol_px : float
            A converged point must also re-project within this many pixels of (row, col).
        raise_on_failure : bool
            Raise :class:`ConvergenceError` when any point fails.
        return_valid : bool
            Also return validity flags: converged, and inside the validity domain
            (:meth:`image_validity` of the input, :meth:`ground_validity` of the solution).

        Returns
        -------
        lon, lat : ndarray
            Degrees, broadcast shape; NaN where not converged.
        converged : ndarray of bool
            Same shape.  Never True for a solution beyond :data:`LOCALIZATION_LIMIT` normalised
            units of longitude or latitude (e.g. row -1e6): the polynomials are meaningless there.
        valid : ndarray of bool
            Only with ``return_valid=True``.

        Raises
        ------
        ValueError
            If an input contains NaN.
        ConvergenceError
            With ``raise_on_failure=True``, naming how many points failed.
        """
        row_a = _as_float_array(row, "row")
        col_a = _as_float_array(col, "col")
        h_a = _as_float_array(h, "h")
        row_a, col_a, h_a = np.broadcast_arrays(row_a, col_a, h_a)
        shape = row_a.shape
        target_row = row_a.ravel().copy()
        target_col = col_a.ravel().copy()
        z = (h_a.ravel() - self.height_offset) / self.height_scale

        if self.inverse is not None:
            x, y = self._inverse_normalized(
                (target_col - self.col_offset) / self.col_scale,
                (target_row - self.row_offset) / self.row_scale,
                z,
                normalized_output=True,
            )
            bad_start = ~(np.isfinite(x) & np.isfinite(y))
            x = np.where(bad_start, 0.0, x)
            y = np.where(bad_start, 0.0, y)
        else:
            x = np.zeros_like(z)
            y = np.zeros_like(z)

        tol_x = tol / abs(self.lon_scale)
        tol_y = tol / abs(self.lat_scale)
        converged = np.zeros(z.shape, dtype=bool)
        active = np.arange(z.size)
        for _ in range(max_iter):
            if active.size == 0:
                break
            xa, ya, za = x[active], y[active], z[active]
            r, c, r_x, r_y, c_x, c_y = self._residual_and_jacobian(xa, ya, za)
            e_r = target_row[active] - r
            e_c = target_col[active] - c
            det = r_x * c_y - r_y * c_x
            with np.errstate(divide="ignore", invalid="ignore"):
                dx = (c_y * e_r - r_y * e_c) / det
                dy = (-c_x * e_r + r_x * e_c) / det
            err0 = np.hypot(e_r, e_c)
            step = np.ones_like(xa)
            # backtracking: halve the step while the residual grows (vectorised)
            for _halving in range(30):
                r1, c1 = self._pixel(xa + step * dx, ya + step * dy, za)
                err1 = np.hypot(target_row[active] - r1, target_col[active] - c1)
                worse = ~(err1 <= err0) & (err0 > 0)
                if not worse.any():
                    break
                step = np.where(worse, step * 0.5, step)
            sx = step * dx
            sy = step * dy
            x[active] = xa + sx
            y[active] = ya + sy
            finite = np.isfinite(sx) & np.isfinite(sy)
            done = finite & (np.abs(sx) <= tol_x) & (np.abs(sy) <= tol_y)
            converged[active[done]] = True
            failed = ~finite
            x[active[failed]] = np.nan
            active = active[~done & ~failed]

        lon = x * self.lon_scale + self.lon_offset
        lat = y * self.lat_scale + self.lat_offset
        ok = converged & np.isfinite(lon) & np.isfinite(lat)
        # far outside the ground domain the polynomials are meaningless: never "converged" there
        ok &= (np.abs(x) <= LOCALIZATION_LIMIT) & (np.abs(y) <= LOCALIZATION_LIMIT)
        if ok.any():
            r_chk, c_chk = self._pixel(x[ok], y[ok], z[ok])
            resid = np.hypot(r_chk - target_row[ok], c_chk - target_col[ok])
            ok_idx = np.flatnonzero(ok)
            ok[ok_idx[~(resid <= residual_tol_px)]] = False
        lon = np.where(ok, lon, np.nan).reshape(shape)
        lat = np.where(ok, lat, np.nan).reshape(shape)
        ok = ok.reshape(shape)
        if raise_on_failure and not ok.all():
            n_failed = int((~ok).sum())
            raise ConvergenceError(f"localization did not converge for {n_failed} of {ok.size} point(s)")
        if return_valid:
            valid = ok & self.image_validity(row_a, col_a) & self.ground_validity(lon, lat, h_a)
            return lon, lat, ok, valid
        return lon, lat, ok

    def localization_strict(
        self, row: ArrayLike, col: ArrayLike, h: ArrayLike, **kwargs: Any
    ) -> tuple[FloatArray, FloatArray]:
        """:meth:`localization` that raises :class:`ConvergenceError` on any failure."""
        lon, lat, _ = self.localization(row, col, h, raise_on_failure=True, **kwargs)
        return lon, lat

    def _pixel(self, x: FloatArray, y: FloatArray, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        row_n, col_n = self.normalized_projection(x, y, z)
        return row_n * self.row_scale + self.row_offset, col_n * self.col_scale + self.col_offset
