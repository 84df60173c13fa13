"""A pushbroom scene: camera (interior orientation) + MPC orbit and attitude +
line timing + terrain + local frame, with image -> ground and the collinearity
residual that every best-scanline method solves.  Saves to and loads from JSON
exactly.  Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar, Literal, overload

import numpy as np
from numpy.typing import ArrayLike

from explorer.errors import ExplorerError, SceneFileError, as_points, check_finite
from explorer.geometry.bracket import bracket_best_scanline
from explorer.geometry.collinearity import ideal_focal_plane
from explorer.geometry.exterior import ExteriorOrientation, LineTiming
from explorer.geometry.frames import Ellipsoid, LocalFrame
from explorer.geometry.interior import InteriorOrientation
from explorer.geometry.terrain import (
    FlatTerrain,
    GridDEM,
    Terrain,
    intersect_heights,
    terrain_from_dict,
)
from explorer.io_atomic import write_text_atomic
from explorer.io_input import load_json_file
from explorer.scene_checks import check_scene_physics
from explorer.sensor import Localization, Projection, inside_image

SCENE_FILE_VERSION = 1
RIGOROUS_SCENE_FORMAT = "pushbroom-explorer rigorous line-scan scene"
HeightArg = np.ndarray | float | None  # heights of image_to_ground: plane(s) Z = height, or the terrain
CHUNK = 1 << 18  # points per block in per-point matrix work (bounds memory to ~50 MB)


def _chunked(n: int, fn: Callable[[slice], tuple[np.ndarray, ...]], widths: tuple[int, ...]):
    """Run ``fn`` over slices of length CHUNK and stitch its outputs (each (n,) or (n, w))."""
    if n <= CHUNK:
        return fn(slice(0, n))
    outs = [np.empty((n,) if w == 0 else (n, w)) for w in widths]
    for start in range(0, n, CHUNK):
        sl = slice(start, min(start + CHUNK, n))
        for o, r in zip(outs, fn(sl), strict=True):
            o[sl] = r
    return tuple(outs)


@dataclass
class Scene:
    """Everything needed to map between the image and the ground.

    Parameters
    ----------
    name : str
    interior : InteriorOrientation
    exterior : ExteriorOrientation
    timing : LineTiming
    n_rows : int
        Number of scanlines.
    terrain : Terrain
        :class:`~explorer.geometry.terrain.FlatTerrain`, :class:`~explorer.geometry.terrain.GridDEM` or any
        other :class:`~explorer.geometry.terrain.Terrain`.
    frame : LocalFrame
        Where the local ENU frame sits on the WGS84 ellipsoid.
    metadata : dict
        Free-form provenance (preset id, sensor, region, table GSD, perturbations).
    """

    name: str
    interior: InteriorOrientation
    exterior: ExteriorOrientation
    timing: LineTiming
    n_rows: int
    terrain: Terrain = field(default_factory=FlatTerrain)
    frame: LocalFrame = field(default_factory=lambda: LocalFrame(0.0, 0.0, 0.0))
    metadata: dict = field(default_factory=dict)

    #: Capability: the exterior orientation is MPC polynomials of time (+ jitter), so the compiled
    #: collinearity kernels (:mod:`explorer.geometry.kernels`) can pack this scene.
    has_polynomial_exterior: ClassVar[bool] = True
    #: Capability (:class:`explorer.sensor.LineGeometrySensor`): physical scanlines.
    has_line_geometry: ClassVar[bool] = True

    # ------------------------------------------------------------------ image
    @property
    def body(self) -> Ellipsoid:
        """The body the frame sits on (``frame.body``)."""
        return self.frame.body

    @property
    def n_columns(self) -> int:
        return self.interior.n_columns

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns)."""
        return (self.n_rows, self.n_columns)

    @property
    def pixel_size_m(self) -> float:
        """Detector pitch, metres: focal-plane metres per pixel."""
        return self.interior.detector_pitch_m

    def scanline_time(self, row: ArrayLike) -> np.ndarray:
        """Row (N,) -> exposure time (N,), seconds."""
        return self.timing.scanline_time(row)

    def row_at_time(self, t: np.ndarray) -> np.ndarray:
        """Exposure time (N,) seconds -> row (N,)."""
        return self.timing.row_at_time(t)

    def inside_image(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """True where (row, col) lies on the image, pixel edges included: -0.5 <= row <= rows - 0.5."""
        return inside_image(row, col, self.n_rows, self.n_columns)

    # ------------------------------------------------------------ line geometry
    def line_time(self, row: np.ndarray) -> np.ndarray:
        """Exposure time (N,) of rows (N,), seconds on the sensor's clock (:class:`~explorer.sensor.LineGeometrySensor`;
        here :meth:`scanline_time`)."""
        return self.scanline_time(np.atleast_1d(np.asarray(row, dtype=np.float64)))

    def perspective_centre(self, t: np.ndarray) -> np.ndarray:
        """Perspective centres (N, 3), local ENU metres, at times (N,) seconds."""
        return self.exterior.position(np.atleast_1d(np.asarray(t, dtype=np.float64)))

    def attitude(self, t: np.ndarray) -> np.ndarray:
        """Camera -> local ENU rotations (N, 3, 3) at times (N,) seconds."""
        return self.exterior.rotation(np.atleast_1d(np.asarray(t, dtype=np.float64)))

    def look_direction(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """Unit lines of sight (N, 3), local ENU, of detector ``col`` at the time of ``row`` (:meth:`rays`)."""
        return self.rays(row, col)[1]

    # ------------------------------------------------------------ collinearity
    def focal_plane(self, ground: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Measured focal-plane coordinates of ground points seen at times t.

        Parameters
        ----------
        ground : ndarray, shape (N, 3)
            Local ENU metres.
        t : ndarray, shape (N,) or scalar
            Scanline times, seconds.

        Returns
        -------
        x, y : ndarray, shape (N,)
            Along- and across-track focal-plane coordinates (distorted), metres.
        """
        ground = np.asarray(ground, dtype=np.float64)
        t = np.broadcast_to(np.asarray(t, dtype=np.float64), ground.shape[:1])

        def block(sl: slice) -> tuple[np.ndarray, np.ndarray]:
            tt = t[sl]
            x, y = ideal_focal_plane(
                ground[sl], self.exterior.position(tt), self.exterior.rotation(tt),
                self.interior.focal_length_m,
            )
            return self.interior.distort(x, y)

        return _chunked(ground.shape[0], block, (0, 0))

    def along_track_residual(self, ground: np.ndarray, t: np.ndarray) -> np.ndarray:
        """``x(t) - x_detector(y(t))`` (N,), metres: zero at the best scanline.

        Divide by :attr:`pixel_size_m` for pixels.  One call is one collinearity
        evaluation per point.
        """
        x, y = self.focal_plane(ground, t)
        return x - self.interior.detector_x(y)

    def column_at_time(self, ground: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Image column (N,) of ground points (N, 3) seen at scanline times t (N,)."""
        _, y = self.focal_plane(ground, t)
        return self.interior.y_to_column(y)

    def column_at_row(self, ground: np.ndarray, row: np.ndarray) -> np.ndarray:
        """Image column (N,) of ground points at (fractional) rows (N,)."""
        return self.column_at_time(ground, self.scanline_time(row))

    # ------------------------------------------------------------ image->ground
    def rays(self, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lines of sight of image points.

        Parameters
        ----------
        row, col : ndarray, shape (N,)

        Returns
        -------
        origin : ndarray, shape (N, 3)
            Perspective centres, metres.
        direction : ndarray, shape (N, 3)
            Unit directions in the local frame.
        """
        row = check_finite(np.atleast_1d(row), "row")
        col = check_finite(np.atleast_1d(col), "col")
        row, col = np.broadcast_arrays(row, col)
        t = self.scanline_time(row)
        xd, yd = self.interior.detector_focal_plane(col)
        x, y = self.interior.undistort(xd, yd)

        def block(sl: slice) -> tuple[np.ndarray, np.ndarray]:
            tt = t[sl]
            v = np.stack([x[sl], y[sl], np.full(tt.shape, -self.interior.focal_length_m)], axis=-1)
            d = np.einsum("nij,nj->ni", self.exterior.rotation(tt), v)
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            return self.exterior.position(tt), d

        return _chunked(row.shape[0], block, (3, 3))

    @overload
    def image_to_ground(self, row: np.ndarray, col: np.ndarray, terrain: Terrain | None = None, *,
                        height: HeightArg = None, return_flags: Literal[False] = False) -> np.ndarray: ...
    @overload
    def image_to_ground(self, row: np.ndarray, col: np.ndarray, terrain: Terrain | None = None, *,
                        height: HeightArg = None, return_flags: Literal[True]) -> tuple[np.ndarray, np.ndarray]: ...
    def image_to_ground(
        self,
        row: np.ndarray,
        col: np.ndarray,
        terrain: Terrain | None = None,
        *,
        height: np.ndarray | float | None = None,
        return_flags: bool = False,
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Intersect lines of sight with the terrain.

        On a DEM the first intersection from the sensor is found by the compiled cell walk of
        :mod:`explorer.geometry.dem_intersection` (exact on the bilinear surface).

        Parameters
        ----------
        row, col : ndarray, shape (N,)
            Image coordinates (0-based, pixel centre).
        terrain : Terrain, optional
            Defaults to the scene's terrain.
        height : float or ndarray (N,), optional
            Intersect with the plane(s) Z = height instead (exact).
        return_flags : bool
            Also return a flag per point (int8; ``explorer.geometry.dem_intersection``: 0 OK, 1 outside
            the DEM, 2 no-data, 3 no intersection).

        Returns
        -------
        ndarray, shape (N, 3)
            Ground points, metres; NaN rows where a DEM is missed (outside or no-data).
        flags : ndarray of int8, shape (N,)
            With ``return_flags``.
        """
        points, flags = self.intersect_terrain(row, col, terrain, height=height)
        return (points, flags) if return_flags else points

    def localize(
        self, row: np.ndarray, col: np.ndarray, *, height: np.ndarray | float | None = None
    ) -> Localization:
        """Ground points and flags (:class:`explorer.sensor.Localization`) on the plane(s) ``Z = height``
        or the scene's terrain (first hit on a DEM)."""
        return Localization(*self.intersect_terrain(row, col, height=height))

    def intersect_terrain(
        self, row: np.ndarray, col: np.ndarray, terrain: Terrain | None = None, *,
        height: np.ndarray | float | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Ground points (N, 3) and flags (N,) int8 of :meth:`image_to_ground` (the part a sensor model
        with other lines of sight overrides, e.g. :class:`explorer.real.linescan.RigorousLineScanScene`)."""
        origin, direction = self.rays(row, col)
        if height is not None:
            return intersect_heights(origin, direction, check_finite(np.asarray(height, dtype=np.float64), "height"))
        return (self.terrain if terrain is None else terrain).intersect(origin, direction)

    def footprint(self, height: float | None = None) -> np.ndarray:
        """Ground corners of the image at a height (default: mean terrain height), shape (4, 3).

        Order: (row 0, col 0), (row 0, last col), (last row, last col), (last row, col 0),
        pixel edges included.
        """
        r1, c1 = self.n_rows - 0.5, self.n_columns - 0.5
        rows = np.array([-0.5, -0.5, r1, r1])
        cols = np.array([-0.5, c1, c1, -0.5])
        h = self.terrain.mean_height if height is None else height
        return self.image_to_ground(rows, cols, height=h)

    def ground_sample_distance(self) -> tuple[float, float]:
        """(along-track, across-track) pixel spacing on the ground at the image centre, metres."""
        rc, cc = (self.n_rows - 1) / 2.0, (self.n_columns - 1) / 2.0
        h = self.terrain.mean_height
        g = self.image_to_ground(
            np.array([rc - 0.5, rc + 0.5, rc, rc]), np.array([cc, cc, cc - 0.5, cc + 0.5]), height=h
        )
        return float(np.linalg.norm(g[1] - g[0])), float(np.linalg.norm(g[3] - g[2]))

    def ground_to_image(
        self, ground: np.ndarray, *, row_guess: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Exact ground -> image of the model (:class:`explorer.sensor.Sensor`): the best scanline and
        its column by bracketing the along-track residual (:func:`explorer.geometry.bracket.bracket_best_scanline`).

        A reference projection independent of the methods under study (vectorised, tens of collinearity
        evaluations per point): use :func:`explorer.methods.create` for speed.

        Parameters
        ----------
        ground : ndarray, shape (N, 3)
            Local ENU metres.
        row_guess : ndarray, shape (N,), optional
            Approximate rows, to start the bracket there.

        Returns
        -------
        row, col : ndarray, shape (N,)
            Fractional image coordinates (0-based, pixel centre); NaN where the residual has no root
            within the image +- a quarter of its height.
        """
        row, col, _ = bracket_best_scanline(self, ground, row_guess=row_guess)
        return row, col

    def project(self, ground: np.ndarray) -> Projection:
        """:meth:`ground_to_image` with the validity flags (:class:`explorer.sensor.Projection`)."""
        row, col = self.ground_to_image(ground)
        return Projection(row, col, self.inside_image(row, col))

    def geodetic_to_image(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`ground_to_image` of geodetic points on the frame's body: longitude, latitude (N,) degrees, height
        (N,) metres above its ellipsoid (:meth:`explorer.sensor.Sensor.geodetic_to_image`; the scene's model is
        defined in the local frame: converted to it once)."""
        return self.ground_to_image(self.frame.geodetic_to_enu(lon, lat, h))

    def project_geodetic(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> Projection:
        """:meth:`project` of geodetic points on the frame's body: longitude, latitude (N,) degrees, height (N,)
        metres above its ellipsoid (:meth:`explorer.sensor.Sensor.project_geodetic`; converted to the local frame
        once)."""
        return self.project(self.frame.geodetic_to_enu(lon, lat, h))

    def time_range(self) -> tuple[float, float]:
        """(earliest, latest) exposure time of the image, seconds: the first and last scanline's outer edges."""
        t = self.scanline_time(np.array([-0.5, self.n_rows - 0.5]))
        return float(np.min(t)), float(np.max(t))

    def with_terrain(self, terrain: Terrain) -> Scene:
        """A copy of the scene on another terrain."""
        return replace(self, terrain=terrain)

    # -------------------------------------------------------------------- JSON
    def to_dict(self) -> dict:
        """JSON-ready dict; ``Scene.from_dict(scene.to_dict())`` is exact."""
        return {
            "format": "pushbroom-explorer scene",
            "version": SCENE_FILE_VERSION,
            "name": self.name,
            "n_rows": self.n_rows,
            "interior": self.interior.to_dict(),
            "exterior": self.exterior.to_dict(),
            "timing": {"line_period_s": self.timing.line_period_s, "reference_row": self.timing.reference_row},
            "terrain": self.terrain.to_dict(),
            "frame": self.frame.to_dict(),
            "metadata": self.metadata,
        }

    @classmethod
    def from_dict(cls, d: dict, source: str = "<dict>") -> Scene:
        """Build a scene from :meth:`to_dict` output; errors name ``source`` and the bad field."""
        if not isinstance(d, dict) or d.get("format") != "pushbroom-explorer scene":
            raise SceneFileError(f"{source}: not a pushbroom-explorer scene file (missing 'format')")
        if d.get("version") != SCENE_FILE_VERSION:
            raise SceneFileError(f"{source}: unsupported scene version {d.get('version')!r}")
        if (where := _non_finite_field({k: v for k, v in d.items() if k != "metadata"})) is not None:
            raise SceneFileError(f"{source}: {where} is not finite; a scene file holds finite numbers only")
        def part(key: str, build: Callable[[], object]) -> Any:
            """``build()``, its errors naming ``source`` and the field ``key`` (and the missing sub-key)."""
            try:
                return build()
            except SceneFileError:
                raise
            except KeyError as exc:
                if isinstance(exc, ExplorerError):  # an unknown name (terrain kind...): its own message
                    raise SceneFileError(f"{source}: field {key!r}: {exc}") from exc
                where = key if exc.args[0] == key.split(".")[0] else f"{key}.{exc.args[0]}"
                raise SceneFileError(f"{source}: missing field {where!r}") from exc
            except (TypeError, ValueError, AttributeError, IndexError, OverflowError) as exc:
                # a field of the wrong type or shape (an object where a number belongs, a short array...)
                raise SceneFileError(f"{source}: field {key!r} is malformed ({type(exc).__name__}: {exc})") from exc

        scene = part("scene", lambda: cls(
            name=part("name", lambda: str(d["name"])),
            interior=part("interior", lambda: InteriorOrientation.from_dict(d["interior"])),
            exterior=part("exterior", lambda: ExteriorOrientation.from_dict(d["exterior"])),
            timing=part("timing", lambda: LineTiming(float(d["timing"]["line_period_s"]),
                                                     float(d["timing"]["reference_row"]))),
            n_rows=part("n_rows", lambda: int(d["n_rows"])),
            terrain=part("terrain", lambda: terrain_from_dict(d["terrain"])),
            frame=part("frame", lambda: LocalFrame.from_dict(d["frame"])),
            metadata=part("metadata", lambda: dict(d.get("metadata", {}))),
        ))
        for what, n in (("n_rows", scene.n_rows), ("interior.n_columns", scene.interior.n_columns)):
            if not 1 <= n <= 10**9:
                raise SceneFileError(f"{source}: {what} = {n} is not an image size (1 .. 1e9)")
        return scene

    def to_json(self) -> str:
        """The scene as JSON; :class:`SceneFileError` naming the field if a number is NaN or infinite.

        NaN or infinite numbers in ``metadata`` (e.g. a report's RMSE without check points) are
        written as ``null``."""
        d = {**self.to_dict(), "metadata": _finite_or_none(self.metadata)}
        try:
            return json.dumps(d, indent=1, allow_nan=False)
        except ValueError:  # a NaN or infinity would be written as the non-JSON NaN / Infinity
            raise SceneFileError(f"scene {self.name!r}: {_non_finite_field(d)} is not finite; "
                                 "a scene file holds finite numbers only") from None

    def save(self, path: str | Path) -> None:
        """Write the scene to a JSON file (atomically: a failed write leaves no file under ``path``)."""
        write_text_atomic(path, self.to_json())

    @classmethod
    def load(cls, path: str | Path) -> Scene:
        """Read a scene JSON file of this class; raises :class:`SceneFileError` on malformed files.

        :func:`explorer.real.load_scene` reads either an MPC scene or a rigorous line-scan scene."""
        path = Path(path)
        d = load_json_file(path, "scene file", parse_constant=_NonFinite)
        if cls is Scene and isinstance(d, dict) and d.get("format") == RIGOROUS_SCENE_FORMAT:
            raise SceneFileError(
                f"{path}: a rigorous line-scan scene; load it with explorer.load_scene (explorer.real.load_scene)"
            )
        scene = cls.from_dict(d, source=str(path))
        check_scene_physics(scene, str(path))  # a physical sensor, above its terrain (docs/validation.md)
        return scene


class _NonFinite(float):
    """``NaN`` / ``Infinity`` / ``-Infinity`` met while parsing a scene file (a float that marks the field)."""


def _finite_or_none(obj: object) -> object:
    """``obj`` with NaN/infinite floats replaced by None (lists, tuples and dicts walked)."""
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    return obj


def _non_finite_field(obj: object, where: str = "") -> str | None:
    """Dotted path of the first NaN/infinite number (or :class:`_NonFinite` marker) in ``obj``, else None."""
    if isinstance(obj, float) and not np.isfinite(obj):
        return f"{where or 'value'} ({obj})"
    if isinstance(obj, int) and not isinstance(obj, bool) and abs(obj) > 1.7976931348623157e308:
        return f"{where or 'value'} (an integer of {len(str(abs(obj)))} digits)"
    if isinstance(obj, np.ndarray) and obj.dtype.kind == "f" and not np.all(np.isfinite(obj)):
        return f"{where} (array with NaN/infinite values)"
    items = obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, (list, tuple)) else ()
    for key, value in items:
        found = _non_finite_field(value, f"{where}[{key}]" if isinstance(key, int) else
                                  f"{where}.{key}" if where else str(key))
        if found is not None:
            return found
    return None


def validate_ground(ground: np.ndarray) -> np.ndarray:
    """Alias of :func:`explorer.errors.as_points` for method implementations."""
    return as_points(ground)


__all__ = ["Scene", "GridDEM", "FlatTerrain", "validate_ground"]
