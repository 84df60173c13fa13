"""An RPC model behind the :class:`explorer.sensor.Sensor` interface (local ENU metres).

:class:`RPCSensor` wraps a :class:`~explorer.rpc.RationalFunctionModel` (geodetic longitude, latitude and
ellipsoidal height) with a :class:`~explorer.geometry.frames.LocalFrame`, so that code written for scenes
(projection, localisation, footprints, MPC fitting by resection) runs on an RPC unchanged.  Heights
given to :meth:`RPCSensor.image_to_ground` are local ``Z`` planes, as for a scene: the ellipsoidal
height of each point is found by a few fixed-point steps (``dZ/dh`` is the cosine of the angle between
the local and the ellipsoid normals, 1 to 1e-5 over an image).  Without a height, points are localised on the
sensor's ``terrain`` (a plane at the RPC's height offset unless given, or a DEM resampled on the frame): the
RPC's line of sight between the terrain's lowest and highest heights is cut with the terrain (its first hit from
above), and the point is the RPC's exact localisation at the height of that hit, so ``(ground, row, col)`` is a
pair of the RPC itself.

An RPC has no scanlines (no line geometry): the learned and generalized methods, which need only ground / image
pairs, run on it; the search methods refuse it (:func:`explorer.methods.unavailable_reason`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from explorer.errors import InputError, check_finite
from explorer.geometry.frames import Ellipsoid, LocalFrame
from explorer.geometry.terrain import FlatTerrain, Terrain
from explorer.rpc._kernels import and_inside_image
from explorer.rpc.model import RationalFunctionModel
from explorer.sensor import FLAG_NO_HIT, FLAG_OK, Localization, Projection, inside_image

#: Fixed-point steps of :meth:`RPCSensor.image_to_ground` at most, and the height change that stops them (m).
PLANE_ITERATIONS = 8
PLANE_TOL_M = 1e-9


@dataclass
class RPCSensor:
    """A :class:`explorer.sensor.Sensor` over an RPC.

    Parameters
    ----------
    rpc : RationalFunctionModel
    frame : LocalFrame, optional
        Local frame of the ground coordinates; default: at the RPC's (lat, lon) offsets, on the ellipsoid.
    line_period_s : float, optional
        Scanline period, seconds; an RPC has no time, so :meth:`time_range` needs it.
    name : str
    terrain : Terrain, optional
        Where :meth:`image_to_ground` localises points without a height; default a plane at the RPC's
        height offset (:attr:`mean_height`).
    """

    rpc: RationalFunctionModel
    frame: LocalFrame = field(default=None)  # type: ignore[assignment]  # set in __post_init__
    line_period_s: float | None = None
    name: str = "rpc"
    terrain: Terrain = field(default=None)  # type: ignore[assignment]  # set in __post_init__

    #: An RPC has no physical scanlines (:class:`explorer.sensor.LineGeometrySensor` is not offered):
    #: the search methods need line geometry and are unavailable on it.
    has_line_geometry: ClassVar[bool] = False
    has_polynomial_exterior: ClassVar[bool] = False

    #: Capability: the model is defined on longitude, latitude and ellipsoidal height
    #: (:meth:`geodetic_to_image`, :meth:`geodetic_localization`, :meth:`geodetic_localization_on_dem`), so a
    #: caller with geodetic ground points (orthorectification) skips the round trip through the local frame.
    has_geodetic_projection: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if self.frame is None:
            self.frame = LocalFrame(float(self.rpc.lat_offset), float(self.rpc.lon_offset), 0.0)
        if self.terrain is None:
            self.terrain = FlatTerrain(self.mean_height)

    def with_terrain(self, terrain: Terrain) -> RPCSensor:
        """The same RPC and frame localising on ``terrain`` (local ENU metres of :attr:`frame`)."""
        return RPCSensor(self.rpc, self.frame, self.line_period_s, self.name, terrain)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, columns)."""
        return (self.n_rows, self.n_columns)

    def ground_sample_distance(self) -> tuple[float, float]:
        """(row, column) pixel spacing on the ground at the image centre on the terrain's mean height, metres."""
        rc, cc = (self.n_rows - 1) / 2.0, (self.n_columns - 1) / 2.0
        g = self.image_to_ground(np.array([rc - 0.5, rc + 0.5, rc, rc]), np.array([cc, cc, cc - 0.5, cc + 0.5]),
                                 height=self.terrain.mean_height)
        return float(np.linalg.norm(g[1] - g[0])), float(np.linalg.norm(g[3] - g[2]))

    @property
    def n_rows(self) -> int:
        """Scanlines: the file's image size, else ``2 * row_offset + 1``."""
        size = self.rpc.image_size
        return int(size[0]) if size is not None else int(round(2 * self.rpc.row_offset + 1))

    @property
    def n_columns(self) -> int:
        size = self.rpc.image_size
        return int(size[1]) if size is not None else int(round(2 * self.rpc.col_offset + 1))

    @property
    def body(self) -> Ellipsoid:
        """The body of the frame (an RPC's geodetic coordinates are WGS84)."""
        return self.frame.body

    @property
    def mean_height(self) -> float:
        """The RPC's height offset as a local height at the frame origin, metres."""
        return float(self.rpc.height_offset) - self.frame.h0_m

    def ground_to_image(self, ground: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ground (N, 3), local ENU metres -> (row, col), each (N,), by the RPC's projection."""
        ground = np.atleast_2d(check_finite(ground, "ground"))
        if ground.ndim != 2 or ground.shape[1] != 3:
            raise InputError(f"ground must have shape (N, 3), got {ground.shape}")
        lon, lat, h = self.frame.enu_to_geodetic(ground)
        row, col = self.rpc.projection(lon, lat, h)[:2]
        return row, col

    def project(self, ground: np.ndarray) -> Projection:
        """:meth:`ground_to_image` with validity flags: the RPC's own validity (ground inside its
        normalisation domain, image point inside its image domain) and the point on the image."""
        ground = np.atleast_2d(check_finite(ground, "ground"))
        if ground.ndim != 2 or ground.shape[1] != 3:
            raise InputError(f"ground must have shape (N, 3), got {ground.shape}")
        lon, lat, h = self.frame.enu_to_geodetic(ground)
        row, col, ok = self.rpc.projection(lon, lat, h, return_valid=True)
        return Projection(row, col, ok & inside_image(row, col, self.n_rows, self.n_columns))

    def project_geodetic(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> Projection:
        """:meth:`project` of geodetic points -- longitude, latitude (N,) degrees, ellipsoidal height (N,) metres --
        without the local frame: the RPC's own projection and validity, and the point on the image (the geodetic
        entry point of every sensor; for an RPC the wrapper only, ``benchmarks/sensor_path.py``)."""
        row, col, ok = self.rpc.projection(lon, lat, h, return_valid=True)
        and_inside_image(row, col, ok, self.n_rows, self.n_columns)  # one pass, in place
        return Projection(row, col, ok)

    def localize(
        self, row: np.ndarray, col: np.ndarray, *, height: np.ndarray | float | None = None
    ) -> Localization:
        """:meth:`image_to_ground` with flags: 0 found; on the terrain the DEM's flags (1 outside the DEM,
        2 no-data, 3 no intersection); 3 where the RPC does not localise the point."""
        if height is None:
            return self._on_terrain(row, col)[0]
        ground = self.image_to_ground(row, col, height=height)
        return Localization(ground, np.where(np.isfinite(ground[:, 0]), FLAG_OK, FLAG_NO_HIT).astype(np.int8))

    def image_to_ground_geodetic(
        self, row: np.ndarray, col: np.ndarray, *, height: np.ndarray | float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`image_to_ground` and the geodetic coordinates the RPC's own localisation found there:
        (ground (N, 3) local ENU metres, geodetic (N, 3) longitude, latitude degrees, ellipsoidal height metres),
        NaN rows alike.  The ENU points are converted from the geodetic ones, so a caller that keeps both asks the
        RPC again on the pairs it localised (:meth:`project_geodetic`), without a round trip through ENU."""
        if height is None:
            loc, geodetic = self._on_terrain(row, col)
            return loc.ground, geodetic
        return self._on_planes(row, col, height)

    def _on_terrain(self, row: np.ndarray, col: np.ndarray) -> tuple[Localization, np.ndarray]:
        """First hit of the RPC's lines of sight with :attr:`terrain` (see the module docstring), and the
        geodetic coordinates (N, 3) of the hits (NaN rows where none)."""
        lo, hi = float(self.terrain.min_height), float(self.terrain.max_height)
        if not hi > lo:  # a plane: the exact localisation at its height
            ground, geodetic = self._on_planes(row, col, lo)
            flags = np.where(np.isfinite(ground[:, 0]), FLAG_OK, FLAG_NO_HIT).astype(np.int8)
            return Localization(ground, flags), geodetic
        pad = max(1.0, 0.01 * (hi - lo))
        top = self.image_to_ground(row, col, height=hi + pad)
        bottom = self.image_to_ground(row, col, height=lo - pad)
        ok = np.isfinite(top[:, 0]) & np.isfinite(bottom[:, 0])
        ground = np.full(top.shape, np.nan)
        geodetic = np.full(top.shape, np.nan)
        flags = np.full(top.shape[0], FLAG_NO_HIT, dtype=np.int8)
        hit, hit_flags = self.terrain.intersect(top[ok], bottom[ok] - top[ok])
        flags[ok] = hit_flags
        found = np.flatnonzero(ok)[hit_flags == FLAG_OK]
        if found.size:  # on the RPC's own line of sight at the height of the hit (the chord is within mm of it)
            row_b, col_b = np.broadcast_arrays(np.asarray(row, dtype=np.float64), np.asarray(col, dtype=np.float64))
            exact, exact_geo = self._on_planes(np.atleast_1d(row_b)[found], np.atleast_1d(col_b)[found],
                                               hit[hit_flags == FLAG_OK, 2])
            ground[found] = exact
            geodetic[found] = exact_geo
            flags[found[~np.isfinite(exact[:, 0])]] = FLAG_NO_HIT
        return Localization(ground, flags), geodetic

    def geodetic_to_image(self, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lon, lat) degrees and ellipsoidal heights (N,) metres -> (row, col) (N,), the RPC's projection."""
        row, col = self.rpc.projection(lon, lat, h)[:2]
        return row, col

    def geodetic_localization(
        self, row: np.ndarray, col: np.ndarray, h: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Image points (N,) at ellipsoidal heights (N,) -> (lon, lat, converged), the RPC's exact localisation."""
        lon, lat, ok = self.rpc.localization(row, col, h)[:3]
        return lon, lat, ok

    def geodetic_localization_on_dem(
        self, row: np.ndarray, col: np.ndarray, dem: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Image points (N,) -> (lon, lat, h, found): the first hit on a lon/lat DEM of ellipsoidal heights
        (:func:`explorer.rpc.dem.localization_on_dem`)."""
        from explorer.rpc.dem import localization_on_dem

        return localization_on_dem(self.rpc, row, col, dem)

    def image_to_ground(
        self, row: np.ndarray, col: np.ndarray, *, height: np.ndarray | float | None = None
    ) -> np.ndarray:
        """Image points (N,) -> ground (N, 3), local ENU metres, on the plane(s) ``Z = height``, or on
        :attr:`terrain` without a height (first hit); NaN rows where the RPC does not localise (or misses
        the terrain)."""
        if height is None:
            return self._on_terrain(row, col)[0].ground
        return self._on_planes(row, col, height)[0]

    def _on_planes(
        self, row: np.ndarray, col: np.ndarray, height: np.ndarray | float
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`image_to_ground` on the plane(s) ``Z = height``: (ground (N, 3) local ENU, geodetic (N, 3)
        longitude, latitude, ellipsoidal height of the RPC's localisation), NaN rows where it fails."""
        row = check_finite(np.atleast_1d(np.asarray(row, dtype=np.float64)), "row")
        col = check_finite(np.atleast_1d(np.asarray(col, dtype=np.float64)), "col")
        z = check_finite(np.asarray(height, dtype=np.float64), "height")
        row, col, z = np.broadcast_arrays(row, col, np.asarray(z, dtype=np.float64))
        h = z + self.frame.h0_m
        out = np.full(row.shape + (3,), np.nan)
        ok = np.ones(row.shape, dtype=bool)
        for _ in range(PLANE_ITERATIONS):
            lon, lat, ok = self.rpc.localization(row, col, h)[:3]
            out = self.frame.geodetic_to_enu(lon, lat, h)
            dz = np.where(ok, z - out[:, 2], 0.0)
            h = h + dz
            if not np.max(np.abs(dz), initial=0.0) > PLANE_TOL_M:
                break
        lon, lat, ok = self.rpc.localization(row, col, h)[:3]
        out = self.frame.geodetic_to_enu(lon, lat, h)
        out[~ok] = np.nan
        geodetic = np.stack(np.broadcast_arrays(lon, lat, h), axis=-1).astype(np.float64)
        geodetic[~ok] = np.nan
        return out, geodetic

    def footprint(self, height: float | None = None) -> np.ndarray:
        """Ground corners (4, 3) of the image (pixel edges) on the plane ``Z = height`` (default the terrain's
        mean height)."""
        r1, c1 = self.n_rows - 0.5, self.n_columns - 0.5
        h = self.terrain.mean_height if height is None else height
        return self.image_to_ground(np.array([-0.5, -0.5, r1, r1]), np.array([-0.5, c1, c1, -0.5]), height=h)

    def time_range(self) -> tuple[float, float]:
        """(0.5 line period before row 0, 0.5 after the last row), seconds; needs ``line_period_s``."""
        if self.line_period_s is None:
            raise InputError("an RPC has no time axis: give RPCSensor(line_period_s=...) for time_range()")
        return -0.5 * self.line_period_s, (self.n_rows - 0.5) * self.line_period_s


__all__ = ["RPCSensor"]
