"""DEM readers (GeoTIFF via rasterio, SRTM ``.hgt``) and the EGM96 geoid (GTX grid).

Ground coordinates are longitude/latitude in degrees; heights in metres. A DEM's vertical
reference is recorded (``"ellipsoid"``, ``"egm96"`` or ``"unknown"``); RPC models need heights
above the ellipsoid, see :meth:`Geoid.orthometric_to_ellipsoidal`. Image pixel conventions
(0-based, integer = pixel centre) are in ``docs/conventions.md`` and ``docs/rpc.md``.

Grid convention: a DEM value belongs to the **centre of its raster cell** (GDAL "PixelIsArea"
geotransform: node ``(i, j)`` is at ``transform * (j + 0.5, i + 0.5)``). Interpolation is
bilinear between node centres; outside the node grid, or where a needed node is nodata, the
height is NaN and the validity mask is False.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from explorer._resources import assets_dir
from explorer.errors import InputError
from explorer.geometry.dem_intersection import HeightGrid
from explorer.io_input import check_input_file
from explorer.memory import check_allocation

__all__ = [
    "DEFAULT_ASSETS_DIR",
    "DEFAULT_DEM_DATUM",
    "DEM_DATUMS",
    "GeoDEM",
    "datum_statement",
    "declared_vertical_datum",
    "normalise_dem_datum",
    "Geoid",
    "read_dem_above_ellipsoid",
    "read_geotiff_dem",
    "height_grid_of",
    "read_hgt",
    "require_coverage",
]

FloatArray = NDArray[np.float64]

#: Folder of the DEM/geoid assets shipped with the package (the checkout's ``assets/dem``).
DEFAULT_ASSETS_DIR = assets_dir("dem")

#: SRTM's void value, used as no-data when a file has no no-data tag.
SRTM_NODATA = -32768.0

_SNAP = 1e-9  # fractional indices this close to an integer are snapped to it (node exactness)


def _snap(index: FloatArray) -> FloatArray:
    nearest = np.round(index)
    return np.where(np.abs(index - nearest) < _SNAP, nearest, index)


def _bilinear(
    grid: FloatArray, fi: FloatArray, fj: FloatArray, *, wrap_columns: bool = False
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Bilinear interpolation at fractional (row, col) indices; NaN + False where undefined.

    A neighbour with zero weight does not contribute (so a node value is returned exactly even
    next to nodata).
    """
    n_rows, n_cols = grid.shape
    fi = _snap(fi)
    fj = _snap(fj)
    if wrap_columns:
        fj = np.mod(fj, n_cols)
        inside = (fi >= 0) & (fi <= n_rows - 1)
    else:
        inside = (fi >= 0) & (fi <= n_rows - 1) & (fj >= 0) & (fj <= n_cols - 1)
    fi_c = np.where(inside, fi, 0.0)
    fj_c = np.where(inside, fj, 0.0)
    i0 = np.minimum(np.floor(fi_c).astype(np.int64), n_rows - 1)
    j0 = np.floor(fj_c).astype(np.int64)
    j0 = np.mod(j0, n_cols) if wrap_columns else np.minimum(j0, n_cols - 1)
    wi = fi_c - i0
    wj = fj_c - j0
    i1 = np.minimum(i0 + 1, n_rows - 1)
    j1 = np.mod(j0 + 1, n_cols) if wrap_columns else np.minimum(j0 + 1, n_cols - 1)
    total = np.zeros(fi_c.shape)
    valid = inside.copy()
    for ii, jj, w in (
        (i0, j0, (1 - wi) * (1 - wj)),
        (i0, j1, (1 - wi) * wj),
        (i1, j0, wi * (1 - wj)),
        (i1, j1, wi * wj),
    ):
        value = grid[ii, jj]
        used = w > 0
        valid &= ~used | np.isfinite(value)
        total += np.where(used, w * np.where(np.isfinite(value), value, 0.0), 0.0)
    return np.where(valid, total, np.nan), valid


@dataclass(frozen=True)
class GeoDEM:
    """A gridded DEM in a geographic (lon/lat) or projected CRS.

    Attributes
    ----------
    heights : ndarray, shape (n_rows, n_cols)
        Metres; NaN where nodata.
    transform : (a, b, c, d, e, f)
        GDAL-style affine geotransform of cell corners: ``x = c + a * col + b * row``,
        ``y = f + d * col + e * row`` (rasterio ``Affine`` order). Rotation terms must be 0.
    crs : str
        The file's CRS (WKT or authority string); the shareloc DEMs are lon/lat degrees.
    vertical_reference : str
        ``"ellipsoid"``, ``"egm96"`` (orthometric) or ``"unknown"``.
    source_path : str or None
    vertical_reference_source : str
        How :attr:`vertical_reference` was decided (the file's vertical CRS, the ``.hgt`` format, the caller,
        the default for a file that declares none): stated beside the results
        (``docs/conventions.md#dem-heights``).
    """

    heights: FloatArray
    transform: tuple[float, float, float, float, float, float]
    crs: str = ""
    vertical_reference: str = "unknown"
    source_path: str | None = None
    vertical_reference_source: str = ""

    def __post_init__(self) -> None:
        a, b, _, d, e, _ = self.transform
        if b != 0 or d != 0:
            raise ValueError("rotated geotransforms are not supported")
        if a == 0 or e == 0:
            raise ValueError("geotransform pixel size must be non-zero")
        object.__setattr__(self, "heights", np.asarray(self.heights, dtype=np.float64))

    @property
    def shape(self) -> tuple[int, int]:
        """(n_rows, n_cols)."""
        return self.heights.shape  # type: ignore[return-value]

    def node_coordinates(self, i: ArrayLike, j: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(x, y) = (lon, lat) of node (row ``i``, column ``j``), i.e. of the cell centre."""
        a, _, c, _, e, f = self.transform
        return c + (np.asarray(j, float) + 0.5) * a, f + (np.asarray(i, float) + 0.5) * e

    def fractional_index(self, x: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Fractional (row, col) node indices of (x, y)."""
        a, _, c, _, e, f = self.transform
        return (np.asarray(y, float) - f) / e - 0.5, (np.asarray(x, float) - c) / a - 0.5

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of the node grid: where :meth:`height` is defined."""
        n_rows, n_cols = self.shape
        x0, y0 = self.node_coordinates(0, 0)
        x1, y1 = self.node_coordinates(n_rows - 1, n_cols - 1)
        return (float(min(x0, x1)), float(min(y0, y1)), float(max(x0, x1)), float(max(y0, y1)))

    @property
    def min(self) -> float:
        """Lowest valid height (metres)."""
        return float(np.nanmin(self.heights))

    @property
    def max(self) -> float:
        """Highest valid height (metres)."""
        return float(np.nanmax(self.heights))

    def height_and_mask(
        self, x: ArrayLike, y: ArrayLike
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Bilinear height and validity mask at (x, y) (lon/lat for geographic DEMs).

        Returns
        -------
        height : ndarray
            Broadcast shape of x, y; NaN where the mask is False.
        valid : ndarray of bool
            False outside :attr:`bounds`, for NaN input, or next to nodata.
        """
        xa, ya = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        fi, fj = self.fractional_index(xa, ya)
        finite = np.isfinite(fi) & np.isfinite(fj)
        h, valid = _bilinear(
            self.heights, np.where(finite, fi, -1.0), np.where(finite, fj, -1.0)
        )
        return h, valid & finite

    def height(self, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """Bilinear height (metres), NaN where undefined (see :meth:`height_and_mask`)."""
        return self.height_and_mask(x, y)[0]

    @property
    def is_geographic(self) -> bool:
        """True when the CRS is longitude/latitude (or not stated: then assumed lon/lat degrees)."""
        return _crs_is_geographic(self.crs)

    def height_grid(self) -> HeightGrid:
        """The grid in the compiled kernel's layout (cached): see :mod:`explorer.geometry.dem_intersection`.

        Raises
        ------
        InputError
            If the DEM is in a projected CRS (read it with ``read_geotiff_dem``, which reprojects).
        """
        cached = self.__dict__.get("_height_grid")
        if cached is None:
            if not self.is_geographic:
                raise InputError(f"DEM {self.source_path or ''} is in a projected CRS ({self.crs[:60]}); "
                                 "read it with read_geotiff_dem(..., to_geographic=True) to use it with an RPC")
            cached = _grid_of(self.heights, self.transform)
            object.__setattr__(self, "_height_grid", cached)
        return cached


#: What a DEM's heights may be measured from: the WGS84 ellipsoid, or the EGM96 geoid (converted, ``h = H + N``).
DEM_DATUMS = ("ellipsoid", "egm96")
#: The vertical datum of a GeoTIFF that declares none (GDAL's ``RPC_DEM`` convention; docs/conventions.md).
DEFAULT_DEM_DATUM = "ellipsoid"
_DATUM_ALIASES = {"ellipsoid": "ellipsoid", "ellipsoidal": "ellipsoid", "wgs84": "ellipsoid",
                  "egm96": "egm96", "geoid": "egm96", "orthometric": "egm96"}


def normalise_dem_datum(datum: str | None) -> str | None:
    """``"ellipsoid"``, ``"egm96"`` or None (the file decides) from a user's word (``geoid`` = ``egm96``).

    Raises
    ------
    InputError
        For any other word.
    """
    if datum is None:
        return None
    key = str(datum).strip().lower()
    if key not in _DATUM_ALIASES:
        raise InputError(f"DEM datum {datum!r} is not one of {', '.join(DEM_DATUMS)}")
    return _DATUM_ALIASES[key]


def declared_vertical_datum(crs_wkt: str, path: str | Path) -> tuple[str, str] | None:
    """The vertical datum a raster's CRS declares: ``("ellipsoid" | "egm96", name)``, or None when it declares none.

    A compound CRS with a vertical part (``EPSG:4326+5773``, GeoTIFF's VerticalCSTypeGeoKey) names it; a 3D
    geographic CRS (``EPSG:4979``) has ellipsoidal heights.

    Raises
    ------
    InputError
        A vertical datum other than EGM96 (EGM2008, NAVD88, ...: no grid for it is shipped) or heights not in
        metres: the heights cannot be made ellipsoidal, so they are refused rather than used as they are.
    """
    if not crs_wkt:
        return None
    try:
        from pyproj import CRS

        crs = CRS.from_user_input(crs_wkt)
    except Exception:  # noqa: BLE001 - a CRS PROJ cannot parse declares nothing it can read
        return None
    vertical = None
    if crs.is_compound:
        vertical = next((sub for sub in crs.sub_crs_list if sub.is_vertical), None)
    elif crs.is_vertical:
        vertical = crs
    if vertical is None:
        if crs.is_geographic and len(crs.axis_info) == 3:
            return "ellipsoid", crs.name
        return None
    name = vertical.name
    unit = vertical.axis_info[0].unit_conversion_factor if vertical.axis_info else 1.0
    if unit != 1.0:
        raise InputError(f"DEM {path}: its vertical CRS {name!r} has heights in "
                         f"{vertical.axis_info[0].unit_name}, not metres: convert it (gdal_translate -scale)")
    datum_name = vertical.datum.name if vertical.datum is not None else ""
    if vertical.to_epsg() == 5773 or "EGM96" in (name + datum_name).upper().replace(" ", ""):
        return "egm96", name
    raise InputError(f"DEM {path}: heights above {name!r} (its vertical CRS): only ellipsoidal or EGM96 heights "
                     "can be used (convert it to heights above the WGS84 ellipsoid, EPSG:4979)")


def datum_statement(dem: object) -> str:
    """One sentence saying what a DEM's heights were taken as and why (for reports, the GUI, the export)."""
    inner = getattr(dem, "dem", dem)
    reference = getattr(inner, "vertical_reference", "unknown")
    source = getattr(inner, "vertical_reference_source", "") or "given"
    if reference == "egm96":
        return f"heights above the EGM96 geoid ({source}), converted to ellipsoidal with the EGM96 grid"
    if reference == "ellipsoid":
        return f"heights above the WGS84 ellipsoid ({source})"
    return f"heights of unknown vertical datum ({source})"


#: Peak bytes per DEM cell while reading (the band in its type, the float64 copy, the mask, the filled grid).
DEM_BYTES_PER_CELL = 32


def read_geotiff_dem(
    path: str | Path, *, band: int = 1, vertical_reference: str = "unknown", to_geographic: bool = True
) -> GeoDEM:
    """Read a single-band DEM raster with rasterio (any CRS GDAL reads).

    No-data: the file's nodata value or GDAL mask; without either, the SRTM convention (-32768) when
    the file holds that value.  Both become NaN.  Values are cell-centre heights.

    Parameters
    ----------
    path : path-like
    band : int
        1-based band index.
    vertical_reference : str
        What the heights are measured from, when the file does not say (``"ellipsoid"``, ``"egm96"`` or
        ``"unknown"``).  A file that declares its vertical datum (:func:`declared_vertical_datum`) is read as it
        declares; a caller's different choice is refused as a contradiction.
    to_geographic : bool
        A DEM in a projected CRS (UTM...) is reprojected on read to WGS84 longitude/latitude at about its
        own resolution, bilinear (no-data cells stay no-data: a node next to one is NaN), so that the
        lines of sight of an RPC (which live in longitude/latitude) are walked on it directly.

    Raises
    ------
    InputError
        If the file cannot be read as a raster, or the band does not exist.
    """
    import warnings

    from explorer._lazy import import_rasterio

    rasterio = import_rasterio()  # without boto3 (local files only)
    from rasterio._err import CPLE_BaseError
    from rasterio.errors import NotGeoreferencedWarning, RasterioError, RasterioIOError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", NotGeoreferencedWarning)
            dataset = rasterio.open(path)
    except NotGeoreferencedWarning:
        raise InputError(f"DEM {path} is not georeferenced (no geotransform): cannot place its heights") from None
    except RasterioIOError as exc:
        raise InputError(f"cannot read DEM {path}: {exc}") from exc

    try:  # a file that opens but cannot be read, or a CRS PROJ cannot transform (issue 18 fuzzing)
        with dataset:
            if not 1 <= band <= dataset.count:
                raise InputError(f"DEM {path} has {dataset.count} band(s), band {band} requested")
            check_allocation(float(dataset.width) * dataset.height * DEM_BYTES_PER_CELL,
                             f"DEM {path} ({dataset.width} x {dataset.height} cells)",
                             "crop or resample it to the image area first (gdal_translate -projwin / -tr)")
            data = dataset.read(band, masked=True).astype(np.float64)
            heights = np.ma.filled(data, np.nan)
            if dataset.nodata is None and not np.ma.is_masked(data):
                heights[heights == SRTM_NODATA] = np.nan  # SRTM voids in a file without a no-data tag
            transform = tuple(dataset.transform)[:6]
            crs = dataset.crs.to_string() if dataset.crs else ""
            declared = declared_vertical_datum(dataset.crs.to_wkt(), path) if dataset.crs else None
            if to_geographic and dataset.crs is not None and not dataset.crs.is_geographic:
                heights, transform, crs = _reproject_to_lonlat(heights, dataset.transform,
                                                               _horizontal_crs(dataset.crs),
                                                               dataset.width, dataset.height)
    except InputError:
        raise
    except (RasterioError, CPLE_BaseError, ValueError, OverflowError) as exc:
        raise InputError(f"cannot read DEM {path}: {exc}") from None
    if b_or_d_nonzero(transform):
        raise InputError(f"DEM {path}: rotated geotransforms are not supported")
    heights[~np.isfinite(heights)] = np.nan  # infinite heights are no-data, never numbers
    low, high = DEM_HEIGHT_RANGE_M
    with np.errstate(invalid="ignore"):
        outside = (heights < low) | (heights > high)
    if outside.any():
        i, j = (int(v) for v in np.argwhere(outside)[0])
        raise InputError(f"DEM {path}: height {heights[i, j]:.6g} m at row {i}, column {j} is outside {low:g} .. "
                         f"{high:g} m: not a terrain height (an undeclared no-data value, other units?)")
    reference, reference_source = vertical_reference, "given" if vertical_reference != "unknown" else ""
    if declared is not None:
        if vertical_reference not in ("unknown", declared[0]):
            raise InputError(f"DEM {path}: its vertical CRS {declared[1]!r} says heights above the "
                             f"{_DATUM_WORDS[declared[0]]}, but {_DATUM_WORDS[vertical_reference]} was asked "
                             "(--dem-datum): leave the option out, or fix the file's CRS")
        reference, reference_source = declared[0], f"the file's vertical CRS {declared[1]!r}"
    try:
        return GeoDEM(
            heights=heights,
            transform=transform,  # type: ignore[arg-type]
            crs=crs,
            vertical_reference=reference,
            source_path=str(path),
            vertical_reference_source=reference_source,
        )
    except ValueError as exc:  # zero pixel size, non-finite transform
        raise InputError(f"DEM {path}: {exc}") from None


_DATUM_WORDS = {"ellipsoid": "WGS84 ellipsoid", "egm96": "EGM96 geoid", "geoid": "EGM96 geoid",
                "unknown": "unknown datum"}


def _horizontal_crs(crs):
    """The horizontal part of a compound CRS (a projected DEM with a vertical datum), else ``crs`` itself."""
    from pyproj import CRS

    parsed = CRS.from_user_input(crs.to_wkt())
    if parsed.is_compound:
        horizontal = next((sub for sub in parsed.sub_crs_list if not sub.is_vertical), None)
        if horizontal is not None:
            return horizontal.to_wkt()
    return crs


def b_or_d_nonzero(transform: tuple[float, ...]) -> bool:
    """True when an affine geotransform (rasterio order) has rotation terms."""
    return transform[1] != 0 or transform[3] != 0


def _reproject_to_lonlat(heights: FloatArray, transform, crs, width: int, height: int):
    """Resample a projected DEM onto a WGS84 lon/lat grid of about its resolution.

    Each lon/lat node is transformed exactly (PROJ) into the DEM's CRS and the DEM is interpolated there
    bilinearly between its cell centres (NaN next to no-data, NaN outside), row block by row block.  (GDAL's
    warper was not used: its bilinear kernel moved a plane by centimetres.)  Returns heights, transform, crs.
    """
    from pyproj import Transformer
    from rasterio.warp import calculate_default_transform

    dst_transform, dst_width, dst_height = calculate_default_transform(
        crs, "EPSG:4326", width, height, *_bounds_of(transform, width, height))
    to_src = Transformer.from_crs("EPSG:4326", crs.to_wkt() if hasattr(crs, "to_wkt") else crs, always_xy=True)
    a, _, c, _, e, f = tuple(dst_transform)[:6]
    sa, _, sc, _, se, sf = tuple(transform)[:6]
    lon = c + (np.arange(dst_width) + 0.5) * a
    out = np.empty((dst_height, dst_width))
    rows_per_block = max(1, 4_000_000 // max(dst_width, 1))
    for i0 in range(0, dst_height, rows_per_block):
        i1 = min(dst_height, i0 + rows_per_block)
        lat = f + (np.arange(i0, i1) + 0.5) * e
        glon, glat = np.meshgrid(lon, lat)
        x, y = to_src.transform(glon, glat)
        fi = (np.asarray(y) - sf) / se - 0.5
        fj = (np.asarray(x) - sc) / sa - 0.5
        finite = np.isfinite(fi) & np.isfinite(fj)
        value, _ = _bilinear(heights, np.where(finite, fi, -1.0), np.where(finite, fj, -1.0))
        out[i0:i1] = np.where(finite, value, np.nan)
    return out, tuple(dst_transform)[:6], "EPSG:4326"


def _bounds_of(transform, width: int, height: int) -> tuple[float, float, float, float]:
    from rasterio.transform import array_bounds

    west, south, east, north = array_bounds(height, width, transform)
    return west, south, east, north


def _crs_is_geographic(crs: str) -> bool:
    if not crs:
        return True
    try:
        from pyproj import CRS

        return bool(CRS.from_user_input(crs).is_geographic)
    except Exception:  # noqa: BLE001 - an unparsable CRS string: keep the old behaviour (lon/lat)
        return True


def _grid_of(heights: FloatArray, transform: tuple[float, ...]) -> HeightGrid:
    a, _, c, _, e, f = transform
    return HeightGrid.from_array(heights, c + 0.5 * a, f + 0.5 * e, a, e)


def height_grid_of(dem: object) -> HeightGrid | None:
    """The kernel grid of a DEM object (GeoDEM, EllipsoidalDEM, HeightGrid), or None for other height sources."""
    if isinstance(dem, HeightGrid):
        return dem
    fn = getattr(dem, "height_grid", None)
    return fn() if callable(fn) else None


def require_coverage(grid: HeightGrid, lon: ArrayLike, lat: ArrayLike, what: str = "the footprint",
                     source: str | None = None, *, partial: bool = False) -> None:
    """Raise :class:`InputError` unless every (lon, lat) lies inside the DEM's node grid.

    Parameters
    ----------
    grid : HeightGrid
    lon, lat : array_like
        Degrees, e.g. the image corners on the ground.
    what, source : str
        Named in the message.
    partial : bool
        Accept a DEM that covers part of the points (the rest is flagged point by point); raise only when
        it covers none of them.
    """
    u, v = grid.to_grid(np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64))
    ny, nx = grid.heights.shape
    inside = (u >= 0) & (u <= nx - 1) & (v >= 0) & (v <= ny - 1)
    if not (np.any(inside) if partial else np.all(inside)):
        x1, y1 = grid.x0 + (nx - 1) * grid.dx, grid.y0 + (ny - 1) * grid.dy
        raise InputError(
            f"DEM {source or ''} does not cover {what}: DEM lon [{min(grid.x0, x1):.5f}, {max(grid.x0, x1):.5f}], "
            f"lat [{min(grid.y0, y1):.5f}, {max(grid.y0, y1):.5f}]; needed lon "
            f"[{np.nanmin(lon):.5f}, {np.nanmax(lon):.5f}], lat [{np.nanmin(lat):.5f}, {np.nanmax(lat):.5f}]")


_HGT_NAME = re.compile(r"([NS])(\d{1,2})([EW])(\d{1,3})", re.I)


#: Heights a terrain of the Earth (SRTM) can have: the Dead Sea shore is at -430 m, Everest at 8,849 m.
SRTM_HEIGHT_RANGE_M = (-1_000.0, 9_000.0)
#: Heights any DEM read may hold (m): the deepest ocean trench to above Olympus Mons on Mars.
DEM_HEIGHT_RANGE_M = (-12_000.0, 30_000.0)


def _check_hgt_heights(path: Path, raw: np.ndarray) -> None:
    """Refuse a tile whose samples are not Earth heights (a little-endian tile reads as ~+-30 km heights)."""
    valid = raw[raw != SRTM_NODATA]
    if valid.size == 0:
        return
    low, high = SRTM_HEIGHT_RANGE_M
    outside = float(np.mean((valid < low) | (valid > high)))
    if outside > 0.001:
        swapped = valid.byteswap()
        swapped = swapped[swapped != SRTM_NODATA]
        hint = ""
        if swapped.size and float(np.mean((swapped < low) | (swapped > high))) < 0.001:
            hint = "; its bytes read little-endian give Earth heights: SRTM tiles are big-endian, convert it"
        raise InputError(f"DEM {path}: {100 * outside:.1f} % of the samples are outside {low:g} .. {high:g} m "
                         f"(up to {int(np.max(np.abs(valid.astype(np.int32))))} m): not SRTM heights{hint}")


def read_hgt(path: str | Path) -> GeoDEM:
    """Read an SRTM ``.hgt`` tile (1201x1201 or 3601x3601 big-endian int16, -32768 = nodata).

    The file name gives the south-west corner (``N43E007.hgt``); nodes are at whole fractions
    of a degree from that corner (the first row is the northern edge). Heights are EGM96
    orthometric.
    """
    path = Path(path)
    match = _HGT_NAME.search(path.name)
    if match is None:
        raise InputError(f"DEM {path}: an SRTM .hgt tile is placed by its name, which must look like "
                         "N43E007.hgt (rename it, or convert it to a GeoTIFF)")
    lat0 = int(match.group(2)) * (1 if match.group(1).upper() == "N" else -1)
    lon0 = int(match.group(4)) * (1 if match.group(3).upper() == "E" else -1)
    if not (-90 <= lat0 <= 89 and -180 <= lon0 <= 179):
        raise InputError(f"DEM {path}: tile name {match.group(0)} is not a 1-degree tile on the Earth")
    size = check_input_file(path, "SRTM .hgt DEM").stat().st_size
    if size not in (2 * 1201**2, 2 * 3601**2):
        raise InputError(f"DEM {path}: {size} bytes is not a 1201^2 or 3601^2 SRTM tile of 16-bit samples")
    try:
        raw = np.fromfile(path, dtype=">i2")
    except OSError as exc:
        raise InputError(f"DEM {path}: cannot be read ({exc.strerror})") from None
    side = int(round(np.sqrt(raw.size)))
    _check_hgt_heights(path, raw)
    heights = raw.reshape(side, side).astype(np.float64)
    heights[raw.reshape(side, side) == -32768] = np.nan
    step = 1.0 / (side - 1)
    transform = (step, 0.0, lon0 - 0.5 * step, 0.0, -step, lat0 + 1 + 0.5 * step)
    return GeoDEM(heights, transform, crs="EPSG:4326", vertical_reference="egm96",
                  source_path=str(path), vertical_reference_source="the SRTM .hgt format")


@dataclass(frozen=True)
class Geoid:
    """Geoid undulation grid (e.g. EGM96 15'), bilinear, longitude wrap-around.

    Attributes
    ----------
    undulation : ndarray, shape (n_rows, n_cols)
        Metres; row 0 is the southernmost latitude ``lat0`` (GTX order).
    lat0, lon0, dlat, dlon : float
        Degrees: first node and spacing.
    """

    undulation: FloatArray
    lat0: float
    lon0: float
    dlat: float
    dlon: float

    @classmethod
    def from_gtx(cls, path: str | Path) -> Geoid:
        """Read a GTX file: big-endian header ``lat0, lon0, dlat, dlon`` (float64) and
        ``n_rows, n_cols`` (int32), then ``n_rows * n_cols`` float32 from south to north.
        Values of -88.8888 (the GTX "no data") become NaN."""
        data = Path(path).read_bytes()
        if len(data) < 40:
            raise ValueError(f"{Path(path).name}: too short for a GTX header")
        lat0, lon0, dlat, dlon, n_rows, n_cols = struct.unpack(">4d2i", data[:40])
        expected = 40 + 4 * n_rows * n_cols
        if n_rows <= 0 or n_cols <= 0 or len(data) != expected:
            raise ValueError(
                f"{Path(path).name}: GTX header says {n_rows}x{n_cols}, file has "
                f"{len(data)} bytes (expected {expected})"
            )
        grid = np.frombuffer(data, dtype=">f4", offset=40).astype(np.float64)
        grid = grid.reshape(n_rows, n_cols)
        grid[np.abs(grid + 88.8888) < 1e-3] = np.nan
        return cls(grid, lat0, lon0, dlat, dlon)

    @classmethod
    def egm96(cls, path: str | Path | None = None) -> Geoid:
        """EGM96 15' grid shipped in ``assets/dem/egm96_15.gtx`` (or ``path``)."""
        gtx = Path(path) if path is not None else DEFAULT_ASSETS_DIR / "egm96_15.gtx"
        if not gtx.exists():
            raise FileNotFoundError(f"EGM96 grid not found at {gtx}")
        return cls.from_gtx(gtx)

    @property
    def wraps(self) -> bool:
        """True when the columns cover 360 degrees of longitude."""
        return abs(self.undulation.shape[1] * self.dlon - 360.0) < 1e-9

    def geoid_height(self, lon: ArrayLike, lat: ArrayLike) -> FloatArray:
        """Geoid undulation N (metres above the ellipsoid) at lon/lat degrees, bilinear.

        Longitudes may be given in any 360-degree range. NaN outside the grid's latitudes.
        """
        lon_a, lat_a = np.broadcast_arrays(np.asarray(lon, float), np.asarray(lat, float))
        fi = (lat_a - self.lat0) / self.dlat
        fj = (lon_a - self.lon0) / self.dlon
        finite = np.isfinite(fi) & np.isfinite(fj)
        value, valid = _bilinear(
            self.undulation, np.where(finite, fi, -1.0), np.where(finite, fj, -1.0),
            wrap_columns=self.wraps,
        )  # fmt: skip
        return np.where(valid & finite, value, np.nan)

    def orthometric_to_ellipsoidal(
        self, h: ArrayLike, lon: ArrayLike, lat: ArrayLike
    ) -> FloatArray:
        """Height above the ellipsoid ``h + N(lon, lat)`` from a height above the geoid."""
        return np.asarray(h, float) + self.geoid_height(lon, lat)

    def ellipsoidal_to_orthometric(
        self, h: ArrayLike, lon: ArrayLike, lat: ArrayLike
    ) -> FloatArray:
        """Height above the geoid ``h - N(lon, lat)`` from a height above the ellipsoid."""
        return np.asarray(h, float) - self.geoid_height(lon, lat)


@dataclass(frozen=True)
class EllipsoidalDEM:
    """A DEM whose orthometric heights are converted to ellipsoidal on lookup (``h + N``)."""

    dem: GeoDEM
    geoid: Geoid

    @property
    def min(self) -> float:
        """Lower bound of ellipsoidal heights (DEM min + smallest undulation in its box)."""
        return self.dem.min + float(np.nanmin(self._undulation_samples()))

    @property
    def max(self) -> float:
        """Upper bound of ellipsoidal heights (DEM max + largest undulation in its box)."""
        return self.dem.max + float(np.nanmax(self._undulation_samples()))

    def _undulation_samples(self) -> FloatArray:
        x0, y0, x1, y1 = self.dem.bounds
        gx, gy = np.meshgrid(np.linspace(x0, x1, 9), np.linspace(y0, y1, 9))
        return self.geoid.geoid_height(gx, gy)

    def height(self, lon: ArrayLike, lat: ArrayLike) -> FloatArray:
        """Ellipsoidal height (metres), NaN where the DEM is undefined."""
        return self.geoid.orthometric_to_ellipsoidal(self.dem.height(lon, lat), lon, lat)

    def height_grid(self) -> HeightGrid:
        """The DEM's grid with the undulation added at each node (cached).

        Bilinear interpolation of ``h + N`` between nodes differs from ``bilinear(h) + bilinear(N)`` by the
        undulation's curvature over one DEM cell (below a millimetre for EGM96 and DEM cells up to 1 km).
        """
        cached = self.__dict__.get("_height_grid")
        if cached is None:
            base = self.dem.height_grid()
            ny, nx = base.heights.shape
            lon = base.x0 + base.dx * np.arange(nx)
            lat = base.y0 + base.dy * np.arange(ny)
            glon, glat = np.meshgrid(lon, lat)
            cached = _grid_of(base.heights + self.geoid.geoid_height(glon, glat), self.dem.transform)
            object.__setattr__(self, "_height_grid", cached)
        return cached


def read_dem_above_ellipsoid(
    path: str | Path, *, datum: str | None = None, orthometric: bool = False
) -> GeoDEM | EllipsoidalDEM:
    """A DEM file as heights above the WGS84 ellipsoid: the one DEM reader of every command
    (``docs/conventions.md#dem-heights``).

    The vertical datum is, in this order: the file's own declaration (a GeoTIFF's vertical CRS, e.g.
    ``EPSG:4326+5773`` = EGM96 or ``EPSG:4979`` = ellipsoidal; an SRTM ``.hgt`` tile is EGM96 by its format);
    else ``datum`` (``--dem-datum``); else :data:`DEFAULT_DEM_DATUM` (ellipsoidal, GDAL's ``RPC_DEM``
    convention).  A ``datum`` contradicting the file's declaration is refused.  EGM96 heights are converted
    (``h = H + N``, the EGM96 grid :meth:`Geoid.egm96`).  How the datum was decided is kept
    (:func:`datum_statement`).

    Parameters
    ----------
    path : str or Path
        GeoTIFF (any CRS GDAL reads; projected ones are resampled to longitude/latitude) or SRTM ``.hgt``.
    datum : {"ellipsoid", "egm96"} or None
        The heights' datum when the file declares none (``"geoid"`` is ``"egm96"``).
    orthometric : bool
        Same as ``datum="egm96"`` (the former ``--dem-orthometric``).

    Returns
    -------
    GeoDEM or EllipsoidalDEM
        A height source (``height(lon, lat)``, ``min``, ``max``, ``height_grid()``) of ellipsoidal heights.

    Raises
    ------
    InputError
        An unreadable DEM, a vertical datum other than the two, or a ``datum`` the file contradicts.
    """
    import dataclasses

    path = Path(path)
    datum = normalise_dem_datum(datum)
    if orthometric:
        if datum == "ellipsoid":
            raise InputError("--dem-orthometric and --dem-datum ellipsoid contradict each other")
        datum = "egm96"
    if path.suffix.lower() == ".hgt":
        if datum == "ellipsoid":
            raise InputError(f"DEM {path}: an SRTM .hgt tile holds heights above the EGM96 geoid by its format; "
                             "--dem-datum ellipsoid contradicts it (leave the option out)")
        dem = read_hgt(path)
    else:
        dem = read_geotiff_dem(path, vertical_reference=datum or "unknown")
        if datum is not None and dem.vertical_reference_source == "given":
            dem = dataclasses.replace(dem, vertical_reference_source="--dem-datum")
        if dem.vertical_reference == "unknown":
            dem = dataclasses.replace(
                dem, vertical_reference=DEFAULT_DEM_DATUM,
                vertical_reference_source="the default: the file declares no vertical datum (--dem-datum egm96 "
                                          "if its heights are above the geoid)")
    if dem.vertical_reference == "egm96":
        return EllipsoidalDEM(dem, Geoid.egm96())
    return dem
