"""Orthorectification at scale: exact ground -> image per output pixel, on Dask.

Every output pixel of a north-up grid in the scene's UTM zone is a ground point
(easting, northing, terrain height) that needs its best scanline and column; the
source image is then sampled bilinearly there.  The output is a dask array over
output chunks, computed with the threaded scheduler on one machine or on any
dask.distributed cluster; blocks are written to the GeoTIFF in a fixed order so the
file is byte-identical whatever the scheduler.  Pixel convention:
``docs/conventions.md#pixels`` (output pixel (i, j) has its centre at
``x0 + (j + 0.5) gsd, y0 - (i + 0.5) gsd``).
"""

from __future__ import annotations

import os
import weakref
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import dask
import dask.array as da
import numpy as np
import pyproj

from explorer.errors import InputError
from explorer.geometry.dem_intersection import heights_at
from explorer.sensor import GeodeticSensor, has_geodetic_projection
from explorer.terrain_io import height_grid_of

if TYPE_CHECKING:
    from explorer.geometry.terrain import Terrain
    from explorer.sensor import Sensor

NODATA = np.float32(-9999.0)

#: Source pixels per block when rendering a synthetic source (bounds the temporaries to a few hundred MB).
BLOCK_PIXELS = 1 << 21

#: Source pixels the sampler reads at once per point it samples (:meth:`SourceImage.sample_bilinear`).
SAMPLER_PIXELS_PER_POINT = 4

#: Source pixels the sampler may always read at once, however few the points.
SAMPLER_MIN_PIXELS = 1 << 16


# ----------------------------------------------------------------------------- output grid
@dataclass(frozen=True)
class OrthoGrid:
    """North-up output grid.

    Parameters
    ----------
    epsg : int
        Projected CRS (WGS84 / UTM zone).
    x0, y0 : float
        Upper-left corner of pixel (0, 0), metres.
    gsd : float
        Pixel size, metres.
    width, height : int
        Columns and rows of the output.
    """

    epsg: int
    x0: float
    y0: float
    gsd: float
    width: int
    height: int

    @property
    def transform(self) -> tuple[float, float, float, float, float, float]:
        """GDAL geotransform order (a, b, c, d, e, f) as rasterio's ``Affine(a, b, c, d, e, f)``."""
        return (self.gsd, 0.0, self.x0, 0.0, -self.gsd, self.y0)

    def pixel_centres(self, rows: slice, cols: slice) -> tuple[np.ndarray, np.ndarray]:
        """Easting, northing of the pixel centres of a block, each shape (len(rows), len(cols))."""
        j = np.arange(cols.start, cols.stop, dtype=np.float64)
        i = np.arange(rows.start, rows.stop, dtype=np.float64)
        e = self.x0 + (j + 0.5) * self.gsd
        n = self.y0 - (i + 0.5) * self.gsd
        return np.meshgrid(e, n)


def grid_covering(lon: np.ndarray, lat: np.ndarray, gsd: float, epsg: int) -> OrthoGrid:
    """Smallest grid aligned on multiples of ``gsd`` covering the points (lon, lat) (degrees)."""
    to_utm = pyproj.Transformer.from_crs(4326, epsg, always_xy=True)
    e, n = to_utm.transform(np.asarray(lon), np.asarray(lat))
    x0 = np.floor(np.min(e) / gsd) * gsd
    y1 = np.ceil(np.max(n) / gsd) * gsd
    width = int(np.ceil((np.max(e) - x0) / gsd))
    height = int(np.ceil((y1 - np.min(n)) / gsd))
    return OrthoGrid(epsg, float(x0), float(y1), float(gsd), width, height)


# ------------------------------------------------------------------------ ground -> image
# Where the ground point of an output pixel lies: on a constant height above the ellipsoid, on a lon/lat DEM
# (heights above the ellipsoid) or on the sensor's own terrain in its local ENU frame.  Each surface gives
# the ground points of (lon, lat) in the sensor's frame, the ellipsoidal heights there, and the image to
# ground of a sensor on it (to render a synthetic source the way the sensor saw it).


#: Fixed-point steps of :meth:`EllipsoidHeight.image_to_lonlat` at most, and the height change that stops them.
PLANE_ITERATIONS = 10
PLANE_TOL_M = 1e-7


@dataclass(frozen=True)
class EllipsoidHeight:
    """The ground at a constant height above the ellipsoid, metres."""

    height_m: float

    def heights(self, sensor: Sensor, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
        """Ellipsoidal heights (N,) at (lon, lat) (N,) degrees."""
        return np.full(np.shape(lon), float(self.height_m))

    def ground(self, sensor: Sensor, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
        """Ground points (N, 3), local ENU metres of ``sensor.frame``."""
        return sensor.frame.geodetic_to_enu(lon, lat, self.heights(sensor, lon, lat))

    def image_to_lonlat(self, sensor: Sensor, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image points -> (lon, lat) degrees on this height (NaN where the line of sight does not reach it)."""
        if isinstance(sensor, GeodeticSensor) and has_geodetic_projection(sensor):
            lon, lat, _ = sensor.geodetic_localization(row, col, np.full(np.shape(row), float(self.height_m)))
            return lon, lat
        # local planes Z = z with z moved until the ellipsoidal height is the one asked (dZ/dh ~ 1)
        frame = sensor.frame
        z = np.full(np.shape(row), float(self.height_m) - frame.h0_m)
        for _ in range(PLANE_ITERATIONS):
            g = sensor.image_to_ground(row, col, height=z)
            lon, lat, h = frame.enu_to_geodetic(g)
            dz = np.where(np.isfinite(h), float(self.height_m) - h, 0.0)
            z = z + dz
            if not np.max(np.abs(dz), initial=0.0) > PLANE_TOL_M:
                break
        lon, lat, _ = frame.enu_to_geodetic(sensor.image_to_ground(row, col, height=z))
        return lon, lat

    def height_range(self) -> tuple[float, float]:
        """(lowest, highest) ellipsoidal height, metres."""
        return float(self.height_m), float(self.height_m)


class DEMHeights:
    """The ground on a lon/lat DEM with heights above the ellipsoid (:class:`~explorer.terrain_io.GeoDEM` on the
    ellipsoid, :class:`~explorer.terrain_io.EllipsoidalDEM`, or any object with ``height(lon, lat)``, ``min`` and
    ``max``); a gridded DEM is sampled by the compiled bilinear lookup of the DEM kernel."""

    def __init__(self, dem: Any) -> None:
        self.dem = dem
        self._grid = height_grid_of(dem)

    def heights(self, sensor: Sensor, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
        if self._grid is not None:
            return heights_at(self._grid, lon, lat).reshape(np.shape(lon))
        return np.asarray(self.dem.height(lon, lat), dtype=np.float64)

    def ground(self, sensor: Sensor, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
        return sensor.frame.geodetic_to_enu(lon, lat, self.heights(sensor, lon, lat))

    def image_to_lonlat(self, sensor: Sensor, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First hit of the lines of sight on the DEM (a sensor in geodetic coordinates: an RPC)."""
        if not (isinstance(sensor, GeodeticSensor) and has_geodetic_projection(sensor)):
            raise InputError("a lon/lat DEM is intersected here only by a sensor in geodetic coordinates (an RPC); "
                             "give a scene its DEM as its own terrain (SensorTerrain)")
        lon, lat, _, _ = sensor.geodetic_localization_on_dem(row, col, self.dem)
        return lon, lat

    def height_range(self) -> tuple[float, float]:
        return float(self.dem.min), float(self.dem.max)


@dataclass(frozen=True)
class SensorTerrain:
    """The ground on the sensor's own terrain (local ENU heights of its frame, :class:`Terrain`).

    ``terrain`` must be the terrain the sensor's ``image_to_ground`` intersects by default (a scene's
    ``terrain``), so that the synthetic source and the orthoimage see the same ground.
    """

    terrain: Terrain

    def ground(self, sensor: Sensor, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
        """The point with this lon/lat whose local up equals the terrain height there; NaN off the terrain."""
        frame = sensor.frame
        terrain = self.terrain
        h = np.full(np.shape(lon), terrain.mean_height)
        for _ in range(4):
            p = frame.geodetic_to_enu(lon, lat, h)
            h = h + (terrain.height(p[:, 0], p[:, 1]) - p[:, 2])
        p = frame.geodetic_to_enu(lon, lat, h)
        return np.where(np.isfinite(terrain.height(p[:, 0], p[:, 1]))[:, None], p, np.nan)

    def heights(self, sensor: Sensor, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
        g = self.ground(sensor, lon, lat)
        out = np.full(np.shape(lon), np.nan)
        ok = np.isfinite(g[:, 0])
        if ok.any():
            out[ok] = sensor.frame.enu_to_geodetic(g[ok])[2]
        return out

    def image_to_lonlat(self, sensor: Sensor, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lon, lat, _ = sensor.frame.enu_to_geodetic(sensor.image_to_ground(row, col))
        return lon, lat

    def height_range(self) -> tuple[float, float]:
        """(lowest, highest) local height, metres."""
        return float(self.terrain.min_height), float(self.terrain.max_height)


Surface = EllipsoidHeight | DEMHeights | SensorTerrain


class OrthoGeometry:
    """Ground (lon, lat) on a surface -> image (row, col) of any :class:`~explorer.sensor.Sensor`.

    A sensor declaring ``has_geodetic_projection`` (:class:`~explorer.sensor.GeodeticSensor`, the RPC) is asked in
    longitude, latitude and ellipsoidal height (valid: on the image); any other through its geodetic entry on a
    surface of ellipsoidal heights (:meth:`~explorer.sensor.Sensor.project_geodetic`) and through local ENU ground
    points of its frame on its own terrain (:meth:`~explorer.sensor.Sensor.project`; valid as the sensor says).  A
    best-scanline method is a sensor too (:class:`explorer.methods.adapter.MethodSensor`).

    Parameters
    ----------
    sensor : Sensor
    surface : EllipsoidHeight, DEMHeights or SensorTerrain
    """

    def __init__(self, sensor: Sensor, surface: Surface) -> None:
        self.sensor = sensor
        self.surface = surface
        self.image_shape = (int(sensor.n_rows), int(sensor.n_columns))

    def locate(self, lon: np.ndarray, lat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Image (row, col) (N,) of the ground at (lon, lat) (N,) degrees, and True where it is on the image."""
        row = np.full(lon.shape, np.nan)
        col = np.full(lon.shape, np.nan)
        sensor = self.sensor
        if isinstance(sensor, GeodeticSensor) and has_geodetic_projection(sensor):
            h = self.surface.heights(sensor, lon, lat)
            ok = np.isfinite(h)
            if ok.any():
                row[ok], col[ok] = sensor.geodetic_to_image(lon[ok], lat[ok], h[ok])
            nr, nc = self.image_shape
            return row, col, (row >= -0.5) & (row <= nr - 0.5) & (col >= -0.5) & (col <= nc - 0.5)  # NaN: False
        valid = np.zeros(lon.shape, dtype=bool)
        if not isinstance(self.surface, SensorTerrain):  # geodetic points: the sensor's geodetic entry
            h = self.surface.heights(sensor, lon, lat)
            ok = np.isfinite(h)
            if ok.any():
                row[ok], col[ok], valid[ok] = sensor.project_geodetic(lon[ok], lat[ok], h[ok])
            return row, col, valid
        ground = self.surface.ground(self.sensor, lon, lat)
        ok = np.all(np.isfinite(ground), axis=1)
        if ok.any():
            row[ok], col[ok], valid[ok] = self.sensor.project(ground[ok])  # the sensor's own validity flags
        return row, col, valid

    def image_to_lonlat(self, row: np.ndarray, col: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image points (N,) -> (lon, lat) degrees on the surface (the sensor's own image to ground)."""
        return self.surface.image_to_lonlat(self.sensor, row, col)


# ---------------------------------------------------------------------------- source image
class SourceImage:
    """A single-band source image read by windows (memory-mapped .npy or any rasterio raster)."""

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        if self.path.endswith(".npy"):
            arr = np.load(self.path, mmap_mode="r")
            if arr.ndim != 2:
                raise ValueError(f"{path}: source image must be 2-D, got shape {arr.shape}")
            self.shape = arr.shape
        else:
            import rasterio

            with rasterio.open(self.path) as ds:
                self.shape = (ds.height, ds.width)

    def window(self, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        """Pixels [r0, r1) x [c0, c1) as float64 (clipped to the image by the caller)."""
        if self.path.endswith(".npy"):
            return np.asarray(np.load(self.path, mmap_mode="r")[r0:r1, c0:c1], dtype=np.float64)
        import rasterio
        from rasterio.windows import Window

        with rasterio.open(self.path) as ds:
            return ds.read(1, window=Window(c0, r0, c1 - c0, r1 - r0)).astype(np.float64)

    def _read_rows(self, rows: np.ndarray, c0: int, c1: int) -> np.ndarray:
        """Rows ``rows`` (sorted), columns [c0, c1) of a C-order ``.npy`` source in its own dtype, by plain reads."""
        with open(self.path, "rb") as f:
            major, _minor = np.lib.format.read_magic(f)
            read_header = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
            shape, fortran, dtype = read_header(f)
            if fortran:
                return np.array(np.load(self.path, mmap_mode="r")[rows, c0:c1])
            offset = f.tell()
            width = c1 - c0
            buf = np.empty((rows.size, width), dtype=dtype)
            for k, row in enumerate(rows):
                f.seek(offset + (int(row) * shape[1] + c0) * dtype.itemsize)
                f.readinto(memoryview(buf[k]).cast("B"))
        return buf

    def _read_strip(self, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        """Pixels [r0, r1) x [c0, c1) in the source's own dtype (plain reads for ``.npy``: no mapped pages)."""
        if self.path.endswith(".npy"):
            return self._read_rows(np.arange(r0, r1), c0, c1)
        import rasterio
        from rasterio.windows import Window

        with rasterio.open(self.path) as ds:
            return ds.read(1, window=Window(c0, r0, c1 - c0, r1 - r0))

    def sample_bilinear(self, row: np.ndarray, col: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Bilinear values at (row, col) (pixel centres at integers); NaN where not ``valid``.

        The source is read in strips of rows holding at most :data:`SAMPLER_PIXELS_PER_POINT` source pixels
        per valid point (and at least :data:`SAMPLER_MIN_PIXELS`), each strip's points sampled from it: the
        memory is bounded by the number of points, not by the source area they cover (at an output GSD 8
        times the source's, a 2048 x 2048 block covers 16,000 x 16,000 source pixels: 3 GB read at once).
        """
        out = np.full(row.shape, np.nan)
        if not valid.any():
            return out
        nr, nc = self.shape
        r = np.clip(row[valid], 0.0, nr - 1.0)
        c = np.clip(col[valid], 0.0, nc - 1.0)
        if nr < 2 or nc < 2:  # a single row or column: the whole (thin) window
            r0, c0 = int(np.floor(r.min())), int(np.floor(c.min()))
            r1, c1 = min(int(np.floor(r.max())) + 2, nr), min(int(np.floor(c.max())) + 2, nc)
            win = self.window(r0, r1, c0, c1)
            i = np.minimum(np.floor(r).astype(np.int64), nr - 2) - r0
            j = np.minimum(np.floor(c).astype(np.int64), nc - 2) - c0
            i = np.clip(i, 0, win.shape[0] - 2) if win.shape[0] > 1 else i
            j = np.clip(j, 0, win.shape[1] - 2) if win.shape[1] > 1 else j
            fr = r - (i + r0)
            fc = c - (j + c0)
            out[valid] = (win[i, j] * (1 - fr) * (1 - fc) + win[i, j + 1] * (1 - fr) * fc
                          + win[i + 1, j] * fr * (1 - fc) + win[i + 1, j + 1] * fr * fc)
            return out
        i = np.minimum(np.floor(r).astype(np.int64), nr - 2)  # upper-left neighbour of each point
        j = np.minimum(np.floor(c).astype(np.int64), nc - 2)
        fr = r - i
        fc = c - j
        i_min, i_max = int(i.min()), int(i.max())
        width = int(j.max()) - int(j.min()) + 2
        budget = max(SAMPLER_PIXELS_PER_POINT * r.size, SAMPLER_MIN_PIXELS)
        strip_rows = max(1, budget // width - 1)  # a strip reads strip_rows + 1 source rows
        n_strips = (i_max - i_min) // strip_rows + 1
        values = np.empty(r.size)
        if n_strips == 1:
            groups: list[np.ndarray | slice] = [slice(None)]
        else:  # points grouped by strip (a stable radix sort of small integers)
            strip = (i - i_min) // strip_rows
            order = np.argsort(strip.astype(np.uint16 if n_strips < 1 << 16 else np.int64), kind="stable")
            edges = np.concatenate([[0], np.cumsum(np.bincount(strip, minlength=n_strips))])
            groups = [order[a:b] for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]
        for sel in groups:
            ii, jj = i[sel], j[sel]
            s0, c0 = int(ii.min()), int(jj.min())
            buf = self._read_strip(s0, int(ii.max()) + 2, c0, int(jj.max()) + 2)
            ii = ii - s0
            jj = jj - c0
            a, b = fr[sel], fc[sel]
            # (float32 or integer source values times float64 weights: computed in float64, exactly as from a
            # float64 copy of the source)
            values[sel] = (buf[ii, jj] * (1 - a) * (1 - b) + buf[ii, jj + 1] * (1 - a) * b
                           + buf[ii + 1, jj] * a * (1 - b) + buf[ii + 1, jj + 1] * a * b)
        out[valid] = values
        return out


# ------------------------------------------------------------------------------ rendering
#: Output pixels between the nodes where the map projection is evaluated exactly (see :func:`block_lonlat`).
LONLAT_STEP = 16

#: Largest interpolation error of :func:`block_lonlat` accepted, in output pixels (else every pixel is exact).
LONLAT_TOLERANCE_PX = 1e-4


def block_lonlat(grid: OrthoGrid, rows: slice, cols: slice, step: int = LONLAT_STEP) -> tuple[np.ndarray, np.ndarray]:
    """Longitude and latitude (degrees) of the pixel centres of a block, shape (len(rows), len(cols)).

    The map projection (PROJ) is evaluated exactly every ``step`` pixels (and on the block's last row and
    column) and interpolated bilinearly in between; the interpolation error is measured on the centres of
    the interpolation cells and when it exceeds :data:`LONLAT_TOLERANCE_PX` output pixels the whole block
    is projected pixel by pixel.  (UTM over 16 pixels of 0.5 m: about 1e-6 pixel.)
    """
    to_geo = pyproj.Transformer.from_crs(grid.epsg, 4326, always_xy=True)
    n_r, n_c = rows.stop - rows.start, cols.stop - cols.start
    if step <= 1 or n_r < 2 * step or n_c < 2 * step:
        e, n = grid.pixel_centres(rows, cols)
        lon, lat = to_geo.transform(e, n)
        return np.asarray(lon), np.asarray(lat)
    ri = np.unique(np.append(np.arange(0, n_r, step), n_r - 1))
    ci = np.unique(np.append(np.arange(0, n_c, step), n_c - 1))
    e_n = grid.x0 + (cols.start + ci + 0.5) * grid.gsd
    n_n = grid.y0 - (rows.start + ri + 0.5) * grid.gsd
    node_lon, node_lat = (np.asarray(v) for v in to_geo.transform(*np.meshgrid(e_n, n_n)))

    def interpolate(values: np.ndarray, r: np.ndarray, c: np.ndarray) -> np.ndarray:
        i = np.clip(np.searchsorted(ri, r, side="right") - 1, 0, ri.size - 2)
        j = np.clip(np.searchsorted(ci, c, side="right") - 1, 0, ci.size - 2)
        wr = ((r - ri[i]) / (ri[i + 1] - ri[i]))[:, None]
        wc = ((c - ci[j]) / (ci[j + 1] - ci[j]))[None, :]
        ii, jj = i[:, None], j[None, :]
        return ((1 - wr) * ((1 - wc) * values[ii, jj] + wc * values[ii, jj + 1])
                + wr * ((1 - wc) * values[ii + 1, jj] + wc * values[ii + 1, jj + 1]))

    # the check: exact vs interpolated at the centres of the interpolation cells
    rm = 0.5 * (ri[:-1] + ri[1:])
    cm = 0.5 * (ci[:-1] + ci[1:])
    e_m = grid.x0 + (cols.start + cm + 0.5) * grid.gsd
    n_m = grid.y0 - (rows.start + rm + 0.5) * grid.gsd
    mid_lon, mid_lat = (np.asarray(v) for v in to_geo.transform(*np.meshgrid(e_m, n_m)))
    err_m = np.hypot((interpolate(node_lon, rm, cm) - mid_lon) * 111_320.0 * np.cos(np.radians(mid_lat)),
                     (interpolate(node_lat, rm, cm) - mid_lat) * 110_574.0)
    if not np.all(err_m <= LONLAT_TOLERANCE_PX * grid.gsd):
        e, n = grid.pixel_centres(rows, cols)
        lon, lat = to_geo.transform(e, n)
        return np.asarray(lon), np.asarray(lat)
    r_all = np.arange(n_r, dtype=np.float64)
    c_all = np.arange(n_c, dtype=np.float64)
    return interpolate(node_lon, r_all, c_all), interpolate(node_lat, r_all, c_all)


def render_block(geometry: OrthoGeometry, source: SourceImage, grid: OrthoGrid, rows: slice, cols: slice) -> np.ndarray:
    """Orthoimage block (len(rows), len(cols)) float32; :data:`NODATA` outside the footprint."""
    lon, lat = block_lonlat(grid, rows, cols)
    shape = lon.shape
    row, col, valid = geometry.locate(lon.ravel(), lat.ravel())
    values = source.sample_bilinear(row, col, valid)
    out = np.where(valid & np.isfinite(values), values, NODATA).astype(np.float32)
    return out.reshape(shape)


class BlockRenderer:
    """The function of every output block of one orthoimage: ``render_block`` on one geometry, source and grid.

    With ``--scheduler processes`` dask pickles a task's function for every block; a geometry on a DEM holds the
    DEM's grid (an SRTM tile is 100 MB of float64), so the job would travel to a worker once per block.  Instead
    :func:`process_pool` sends each worker the pickled renderer **once**, when it starts, and while that pool
    runs a renderer pickles as its token only (:func:`_shipped_renderer` finds it in the worker).
    """

    def __init__(self, geometry: OrthoGeometry, source: SourceImage, grid: OrthoGrid) -> None:
        import uuid

        self.geometry, self.source, self.grid = geometry, source, grid
        self.token = uuid.uuid4().hex
        _LIVE_RENDERERS[self.token] = self

    def __call__(self, block_info: dict | None = None) -> np.ndarray:
        assert block_info is not None  # dask passes it to map_blocks functions that accept it
        (r0, r1), (c0, c1) = block_info[None]["array-location"]
        return render_block(self.geometry, self.source, self.grid, slice(r0, r1), slice(c0, c1))

    def __reduce__(self):  # noqa: ANN204 - pickle protocol
        if self.token in _SHIPPED_TOKENS:
            return (_shipped_renderer, (self.token,))
        return (_rebuilt_renderer, (self.geometry, self.source, self.grid, self.token))


#: Renderers of this process (weak: a finished run's job is not kept), and the tokens the running pool's workers
#: hold; in a worker, the renderers it was sent at start.
_LIVE_RENDERERS: weakref.WeakValueDictionary[str, BlockRenderer] = weakref.WeakValueDictionary()
_SHIPPED_TOKENS: set[str] = set()
_WORKER_RENDERERS: dict[str, BlockRenderer] = {}


def _rebuilt_renderer(geometry: OrthoGeometry, source: SourceImage, grid: OrthoGrid, token: str) -> BlockRenderer:
    renderer = BlockRenderer.__new__(BlockRenderer)
    renderer.geometry, renderer.source, renderer.grid, renderer.token = geometry, source, grid, token
    return renderer


def _shipped_renderer(token: str) -> BlockRenderer:
    try:
        return _WORKER_RENDERERS[token]
    except KeyError:  # pragma: no cover - a pool is always made with its renderers
        raise RuntimeError(f"ortho worker {os.getpid()} was not sent renderer {token}") from None


def ortho_dask_array(geometry: OrthoGeometry, source: SourceImage, grid: OrthoGrid, chunk: int = 2048) -> da.Array:
    """The orthoimage as a lazy dask array (float32) over output chunks of ``chunk`` x ``chunk``."""
    return da.map_blocks(BlockRenderer(geometry, source, grid), dtype=np.float32,
                         chunks=da.core.normalize_chunks(chunk, (grid.height, grid.width)),
                         meta=np.empty((0, 0), np.float32))


def process_pool(workers: int) -> ProcessPoolExecutor:
    """One pool of worker processes for a whole ``--scheduler processes`` run, holding the run's job.

    dask's ``processes`` scheduler starts a new pool for every ``compute`` call unless it is given one; each
    new worker imports the package and loads its compiled kernels again (about 2 s a batch of blocks: the
    25x slowdown of issue 25), so the pool is made once and handed to every batch.  The live
    :class:`BlockRenderer` objects (the geometry with its DEM, the source, the grid) are pickled once and sent to
    each worker as it starts; until :func:`release_pool` the tasks carry their token only.  Workers are spawned
    (dask's default context), initialised as dask does, and leave when the run is killed (:func:`_init_worker`).
    """
    import cloudpickle
    from dask.multiprocessing import get_context

    if os.environ.get("PYTHONHASHSEED") in (None, "0"):  # as dask.multiprocessing.get: consistent hashing
        os.environ["PYTHONHASHSEED"] = "6640"
    renderers = dict(_LIVE_RENDERERS.items())
    _SHIPPED_TOKENS.difference_update(renderers)
    payload = cloudpickle.dumps(renderers)  # once, in full
    pool = ProcessPoolExecutor(max(1, workers), mp_context=get_context(), initializer=_init_worker,
                               initargs=(os.getpid(), payload))
    _SHIPPED_TOKENS.update(renderers)
    pool._pushbroom_tokens = set(renderers)  # type: ignore[attr-defined]
    return pool


def release_pool(pool: ProcessPoolExecutor, *, wait: bool) -> None:
    """Shut a :func:`process_pool` down; its renderers pickle in full again."""
    _SHIPPED_TOKENS.difference_update(getattr(pool, "_pushbroom_tokens", ()))
    pool.shutdown(wait=wait, cancel_futures=True)


#: Seconds between a pool worker's checks that the run that started it is alive.
PARENT_POLL_S = 0.2


def _init_worker(parent_pid: int, payload: bytes = b"") -> None:
    """Initialise a pool worker as dask does, receive the run's renderers, and make it leave when its run is gone.

    A worker holds its own end of the pool's queues, so it never sees them close when the run is killed
    (SIGKILL, the out-of-memory killer): left alone it would wait forever, or finish its block, beside the
    next run.  A daemon thread watches the parent's pid and ends the process once it changes.
    """
    import threading
    import time

    from dask.multiprocessing import initialize_worker_process

    initialize_worker_process()
    if payload:
        import cloudpickle

        _WORKER_RENDERERS.update(cloudpickle.loads(payload))

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(0)

    threading.Thread(target=watch, name="pushbroom-parent-watch", daemon=True).start()


def write_orthoimage(
    array: da.Array,
    grid: OrthoGrid,
    out: str | Path,
    *,
    scheduler: str = "threads",
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Compute ``array`` block by block and write a GeoTIFF; blocks are written in row-major
    block order so the file is identical whatever the scheduler.

    Parameters
    ----------
    scheduler : "threads", "processes", "synchronous" or a dask.distributed address ("tcp://host:port")
        or the string "local-cluster:N" to start a LocalCluster of N workers.
    progress : callable(done, total), optional

    Returns
    -------
    dict with the number of blocks and valid pixels.
    """
    import rasterio

    client = None
    if scheduler.startswith("tcp://") or scheduler.startswith("local-cluster"):
        from explorer.errors import require

        distributed = require("distributed", "a dask.distributed scheduler (--scheduler tcp:// or local-cluster)",
                              "cluster")
        Client, LocalCluster = distributed.Client, distributed.LocalCluster

        if scheduler.startswith("local-cluster"):
            n = int(scheduler.split(":")[1]) if ":" in scheduler else 2
            client = Client(LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None))
        else:
            client = Client(scheduler)
    blocks = [(i, j) for i in range(array.numblocks[0]) for j in range(array.numblocks[1])]
    ncpu = 2 if client is None else max(1, len(client.scheduler_info()["workers"]))
    batch = max(1, 2 * ncpu)
    pool = process_pool(ncpu) if scheduler == "processes" else None
    profile = {
        "driver": "GTiff", "dtype": "float32", "count": 1, "width": grid.width, "height": grid.height,
        "crs": f"EPSG:{grid.epsg}", "transform": rasterio.Affine(*grid.transform), "nodata": float(NODATA),
        "tiled": True, "blockxsize": 256, "blockysize": 256,
    }
    row_edges = np.concatenate([[0], np.cumsum(array.chunks[0])])
    col_edges = np.concatenate([[0], np.cumsum(array.chunks[1])])
    valid = 0
    completed = False
    try:
        with rasterio.open(out, "w", **profile) as dst:
            for k in range(0, len(blocks), batch):
                todo = blocks[k:k + batch]
                parts = [array.blocks[i, j] for i, j in todo]
                if client is not None:
                    results = client.gather(client.compute(parts))
                elif pool is not None:
                    results = dask.compute(*parts, scheduler="processes", pool=pool)
                else:
                    results = dask.compute(*parts, scheduler=scheduler)
                for (i, j), res in zip(todo, results, strict=True):
                    window = rasterio.windows.Window(col_edges[j], row_edges[i], res.shape[1], res.shape[0])
                    dst.write(res, 1, window=window)
                    valid += int(np.count_nonzero(res != NODATA))
                if progress is not None:
                    progress(min(k + batch, len(blocks)), len(blocks))
        completed = True
    finally:
        if pool is not None:  # the workers leave with the run (on an error or Ctrl-C without waiting for them)
            release_pool(pool, wait=completed)
        if client is not None:
            cluster = getattr(client, "cluster", None)
            client.close()
            if cluster is not None and scheduler.startswith("local-cluster"):
                cluster.close()
    return {"blocks": len(blocks), "valid_pixels": valid}


# -------------------------------------------------------------------- synthetic ground pattern
@dataclass(frozen=True)
class GroundPattern:
    """A smooth, known radiometric pattern on the ground (UTM metres -> value).

    Sum of oblique sinusoids with wavelengths of several output pixels, so bilinear
    resampling barely blurs it and a shift is measurable to a small fraction of a pixel.
    """

    epsg: int
    wavelengths_m: tuple[float, ...]
    angles_deg: tuple[float, ...]
    origin: tuple[float, float] = (0.0, 0.0)

    def value(self, e: np.ndarray, n: np.ndarray) -> np.ndarray:
        x = np.asarray(e) - self.origin[0]
        y = np.asarray(n) - self.origin[1]
        v = np.full(np.broadcast(x, y).shape, 100.0)
        for lam, ang in zip(self.wavelengths_m, self.angles_deg, strict=True):
            a = np.radians(ang)
            v = v + 20.0 * np.sin(2 * np.pi * (x * np.cos(a) + y * np.sin(a)) / lam)
        return v

    def gradient(self, e: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(e) - self.origin[0]
        y = np.asarray(n) - self.origin[1]
        ge = np.zeros(np.broadcast(x, y).shape)
        gn = np.zeros_like(ge)
        for lam, ang in zip(self.wavelengths_m, self.angles_deg, strict=True):
            a = np.radians(ang)
            c = 20.0 * 2 * np.pi / lam * np.cos(2 * np.pi * (x * np.cos(a) + y * np.sin(a)) / lam)
            ge += c * np.cos(a)
            gn += c * np.sin(a)
        return ge, gn


def default_pattern(epsg: int, gsd: float, origin: tuple[float, float]) -> GroundPattern:
    """Pattern with wavelengths of 17, 29 and 41 output pixels at three orientations."""
    return GroundPattern(epsg, (17.0 * gsd, 29.0 * gsd, 41.0 * gsd), (15.0, 75.0, 130.0), origin)


def lonlat_to_projected(transformer: pyproj.Transformer, lon: np.ndarray, lat: np.ndarray, *,
                        step_deg: float = 5e-4, tolerance_m: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """Map projection of scattered points through PROJ on a lon/lat grid, interpolated bilinearly.

    PROJ runs on the nodes of a ``step_deg`` grid over the points' bounding box (about 50 m) and is
    interpolated in between; the interpolation error is measured at the centres of the grid cells and the
    points are projected one by one by PROJ when it exceeds ``tolerance_m`` (UTM over 50 m: about 1e-5 m).
    NaN points stay NaN.
    """
    lon = np.asarray(lon, np.float64)
    lat = np.asarray(lat, np.float64)
    finite = np.isfinite(lon) & np.isfinite(lat)
    if not finite.any():
        return np.full(lon.shape, np.nan), np.full(lon.shape, np.nan)
    lo0, lo1 = float(lon[finite].min()), float(lon[finite].max())
    la0, la1 = float(lat[finite].min()), float(lat[finite].max())
    n_lon = int(np.ceil((lo1 - lo0) / step_deg)) + 2
    n_lat = int(np.ceil((la1 - la0) / step_deg)) + 2
    if n_lon * n_lat > lon.size // 4 + 16:  # not worth it: project every point
        x, y = transformer.transform(lon, lat)
        return np.asarray(x, np.float64), np.asarray(y, np.float64)
    glon = lo0 + step_deg * np.arange(n_lon)
    glat = la0 + step_deg * np.arange(n_lat)
    gx, gy = (np.asarray(v) for v in transformer.transform(*np.meshgrid(glon, glat)))

    def interpolate(grid: np.ndarray, fj: np.ndarray, fi: np.ndarray) -> np.ndarray:
        j = np.clip(np.floor(fj).astype(np.int64), 0, n_lon - 2)
        i = np.clip(np.floor(fi).astype(np.int64), 0, n_lat - 2)
        a = fj - j
        b = fi - i
        return ((1 - b) * ((1 - a) * grid[i, j] + a * grid[i, j + 1])
                + b * ((1 - a) * grid[i + 1, j] + a * grid[i + 1, j + 1]))

    # the check at the cell centres
    mlon, mlat = np.meshgrid(glon[:-1] + 0.5 * step_deg, glat[:-1] + 0.5 * step_deg)
    mx, my = (np.asarray(v) for v in transformer.transform(mlon, mlat))
    fj_m = (mlon - lo0) / step_deg
    fi_m = (mlat - la0) / step_deg
    err = np.hypot(interpolate(gx, fj_m, fi_m) - mx, interpolate(gy, fj_m, fi_m) - my)
    if not np.all(err <= tolerance_m):
        x, y = transformer.transform(lon, lat)
        return np.asarray(x, np.float64), np.asarray(y, np.float64)
    fj = np.where(finite, (lon - lo0) / step_deg, 0.0)
    fi = np.where(finite, (lat - la0) / step_deg, 0.0)
    x = np.where(finite, interpolate(gx, fj, fi), np.nan)
    y = np.where(finite, interpolate(gy, fj, fi), np.nan)
    return x, y


def render_synthetic_source(
    image_to_lonlat: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    shape: tuple[int, int],
    pattern: GroundPattern,
    path: str | Path,
    *,
    block_rows: int = 256,
) -> Path:
    """Render the pattern as the sensor sees it: every source pixel -> ground -> pattern value.

    Blocks of at most :data:`BLOCK_PIXELS` pixels are rendered and appended to the file in row order (no
    memory map of the whole file is held, so the resident memory stays bounded by the block, whatever the
    image size).  Ground to map coordinates: :func:`lonlat_to_projected`.

    Parameters
    ----------
    image_to_lonlat : callable(row (N,), col (N,)) -> (lon, lat)
        The sensor's image -> ground on the terrain (degrees); NaN where not located.
    shape : (rows, cols)
    path : .npy file, float32 (NaN where a pixel's line of sight was not located).
    """
    path = Path(path)
    to_utm = pyproj.Transformer.from_crs(4326, pattern.epsg, always_xy=True)
    cols = np.arange(shape[1], dtype=np.float64)
    block_rows = max(1, min(block_rows, BLOCK_PIXELS // max(1, shape[1])))  # bounded memory per block
    header = {"descr": np.lib.format.dtype_to_descr(np.dtype(np.float32)), "fortran_order": False,
              "shape": (int(shape[0]), int(shape[1]))}
    with open(path, "wb") as f:
        np.lib.format.write_array_header_1_0(f, header)
        for r0 in range(0, shape[0], block_rows):
            r1 = min(r0 + block_rows, shape[0])
            rr, cc = np.meshgrid(np.arange(r0, r1, dtype=np.float64), cols, indexing="ij")
            lon, lat = image_to_lonlat(rr.ravel(), cc.ravel())
            e, n = lonlat_to_projected(to_utm, lon, lat)
            f.write(pattern.value(e, n).astype(np.float32).tobytes())
    return path


def _image_rows(image: Any, i0: int, n: int, width: int) -> np.ndarray:
    """Rows [i0, i0 + n) of an array or of band 1 of an open rasterio dataset (read as a window)."""
    if isinstance(image, np.ndarray):
        return image[i0:i0 + n]
    from rasterio.windows import Window

    return image.read(1, window=Window(0, i0, width, n))


def _geolocation_shifts(ortho: Any, grid: OrthoGrid, pattern: GroundPattern, block: int, reference: Any) -> list:
    """Per-tile shifts (e, n) in output pixels, :func:`measure_geolocation` with ``block`` x ``block`` tiles."""
    shifts = []
    for i0 in range(0, grid.height - block + 1, block):
        strip = _image_rows(ortho, i0, block, grid.width)
        ref_strip = None if reference is None else _image_rows(reference, i0, block, grid.width)
        for j0 in range(0, grid.width - block + 1, block):
            o = strip[:, j0:j0 + block].astype(np.float64)
            ok = o != NODATA
            if ref_strip is not None:
                ref = ref_strip[:, j0:j0 + block].astype(np.float64)
                ok &= ref != NODATA
            if ok.mean() < 0.99:
                continue
            e, n = grid.pixel_centres(slice(i0, i0 + block), slice(j0, j0 + block))
            ge, gn = pattern.gradient(e, n)
            base = pattern.value(e, n) if reference is None else ref
            diff = (o - base)[ok]
            a = -np.column_stack([ge[ok], gn[ok]])
            d, *_ = np.linalg.lstsq(a, diff, rcond=None)
            shifts.append(d / grid.gsd)
    return shifts


#: Tile sizes :func:`measure_geolocation` tries, largest first, when none is given (output pixels).
GEOLOCATION_TILES = (64, 32, 16, 8)

#: Tiles a measurement should have before a smaller tile size is tried.
GEOLOCATION_MIN_TILES = 4


def measure_geolocation(
    ortho: Any, grid: OrthoGrid, pattern: GroundPattern, *, block: int | None = None, reference: Any = None
) -> dict:
    """Geolocation error of an orthoimage of ``pattern`` by least-squares matching.

    With ``reference`` (another orthoimage of the same pattern on the same grid) the shift
    between the two images is measured instead of the shift against the pattern.  ``ortho`` and
    ``reference`` are arrays (grid.height, grid.width) or open rasterio datasets; a dataset is read
    ``block`` rows at a time (memory in a strip of tiles, not in the image).

    ``block=None`` takes the largest of :data:`GEOLOCATION_TILES` giving at least
    :data:`GEOLOCATION_MIN_TILES` tiles fully inside the footprint (a coarse output grid has few large
    tiles), else the size giving the most.

    In each ``block`` x ``block`` tile the shift d (metres) minimising
    ``|ortho(p) - pattern(p - d)|`` is solved from the linearised model
    ``ortho - pattern = -grad(pattern) . d``; returned in output pixels.

    Returns
    -------
    dict with ``mean_shift_px`` (e, n), ``rms_px``, ``max_px`` over tiles, ``n_tiles`` and ``tile_px``.

    Raises
    ------
    InputError
        No tile lies fully inside the footprint, even of the smallest size.
    """
    sizes = GEOLOCATION_TILES if block is None else (int(block),)
    best: tuple[int, list] = (sizes[0], [])
    for size in sizes:
        shifts = _geolocation_shifts(ortho, grid, pattern, size, reference)
        if len(shifts) > len(best[1]):
            best = (size, shifts)
        if len(shifts) >= GEOLOCATION_MIN_TILES:
            break
    size, shifts = best
    if not shifts:
        raise InputError(f"no tile of {sizes[-1]} x {sizes[-1]} output pixels lies fully inside the footprint "
                         f"({grid.width} x {grid.height} pixels of {grid.gsd:g} m): nothing to measure the "
                         "geolocation on")
    s = np.array(shifts)
    norm = np.hypot(s[:, 0], s[:, 1])
    return {"mean_shift_px": s.mean(axis=0).tolist(), "rms_px": float(np.sqrt(np.mean(norm**2))),
            "max_px": float(norm.max()), "n_tiles": int(len(s)), "tile_px": int(size)}


def gdal_rpc_orthoimage(source: np.ndarray, rpc: Any, grid: OrthoGrid, dem_path: str | Path | None = None,
                        height: float | None = None) -> np.ndarray:
    """The same orthoimage by GDAL's RPC warper (rasterio), the peer this module is checked against.

    Parameters
    ----------
    source : ndarray, shape (rows, cols)
        Source image in the RPC's pixel grid (0-based pixel centres; GDAL applies its own half-pixel shift).
    rpc : RationalFunctionModel
    grid : OrthoGrid
    dem_path : path, optional
        DEM GDAL reads (``RPC_DEM``), heights above the ellipsoid; else the constant ``height``.

    Returns
    -------
    ndarray (grid.height, grid.width) float32, :data:`NODATA` outside.
    """
    import rasterio
    from rasterio.rpc import RPC
    from rasterio.warp import Resampling, reproject

    g_rpc = RPC(height_off=rpc.height_offset, height_scale=rpc.height_scale, lat_off=rpc.lat_offset,
                lat_scale=rpc.lat_scale, line_den_coeff=list(rpc.row_den), line_num_coeff=list(rpc.row_num),
                line_off=rpc.row_offset, line_scale=rpc.row_scale, long_off=rpc.lon_offset,
                long_scale=rpc.lon_scale, samp_den_coeff=list(rpc.col_den), samp_num_coeff=list(rpc.col_num),
                samp_off=rpc.col_offset, samp_scale=rpc.col_scale)
    options = {"RPC_DEM": str(dem_path)} if dem_path is not None else {"RPC_HEIGHT": float(height or 0.0)}
    out = np.full((grid.height, grid.width), NODATA, np.float32)
    reproject(np.asarray(source, np.float32), out, rpcs=g_rpc, src_crs="EPSG:4326", dst_crs=f"EPSG:{grid.epsg}",
              dst_transform=rasterio.Affine(*grid.transform), resampling=Resampling.bilinear,
              dst_nodata=float(NODATA), tolerance=0, **options)
    return out
