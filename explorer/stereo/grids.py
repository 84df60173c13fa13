"""Epipolar resampling grids of a pair, as shareloc (CNES, ``shareloc.geofunctions.rectification``) and the
Orfeo ToolBox (``StereoRectificationGridGenerator``) make them: :func:`epipolar_grids`, :func:`write_grids`.

The epipolar geometry is followed through the left image as shareloc does: at a left position the local
epipolar direction is the left-image trace of the right pixel that sees the same ground point at the grid's
height, moved +-``elevation_offset`` metres in height (colocalisation right -> left at those heights).  The
grid starts at the upper-left corner of the box holding the left image and the right image's corners
(colocalised into the left image), walks one column of nodes across the epipolar lines (the local normal),
then from every node of it along the local epipolar direction, ``step`` pixels a node; each left node's right
position is its exact colocalisation at the grid's height.  So every node's left and right positions see one
ground point at that height.

Coordinates: this module and :class:`EpipolarGrids` use the package's pixels (0-based, integer = centre,
``docs/conventions.md#pixels``).  The files written by :func:`write_grids` use shareloc's/OTB's: a pixel's
centre at ``index + 0.5`` in both the sensor and the epipolar images, grid node ``(i, j)`` at epipolar
``(y, x) = (i * step, j * step)`` (geotransform origin ``-step / 2``, pixel size ``step``), band 1 the column
(x) displacement and band 2 the row (y) displacement ``sensor - epipolar`` (band 3: the height, as shareloc).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from explorer.errors import InputError
from explorer.sensor import Sensor
from explorer.stereo.sensors import as_sensor, localise_geodetic, mean_height, project_geodetic

#: shareloc's default height offset of the local epipolar direction (metres either side of the grid's height).
ELEVATION_OFFSET_M = 50.0


@dataclass(frozen=True)
class EpipolarGrids:
    """Left and right epipolar resampling grids of a pair at one height.

    Attributes
    ----------
    left_rows, left_cols, right_rows, right_cols : ndarray, shape (R, C)
        Sensor position of each node (package pixels, 0-based centre) in the left and the right image.
    step : float
        Node spacing in epipolar pixels.
    epipolar_size : (int, int)
        Epipolar image size, rows x columns.
    height : float
        Ellipsoidal height of the grids, metres (on a DEM: the mean of the nodes' heights).
    angles : ndarray, shape (R, C)
        Local epipolar direction in the left image at each node (radians from the column axis towards rows).
    baseline_ratios : ndarray, shape (R, C)
        Local disparity per metre of height at each node (left pixels per metre; shareloc's "baseline ratio").
    ground : ndarray, shape (R, C, 3)
        The node's ground point: lon, lat (degrees), height (m; the grid's height, or the DEM's under the
        node's left position).
    """

    left_rows: np.ndarray
    left_cols: np.ndarray
    right_rows: np.ndarray
    right_cols: np.ndarray
    step: float
    epipolar_size: tuple[int, int]
    height: float
    angles: np.ndarray
    baseline_ratios: np.ndarray
    ground: np.ndarray = field(repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        """Nodes, rows x columns."""
        return (int(self.left_rows.shape[0]), int(self.left_rows.shape[1]))

    @property
    def mean_baseline_ratio(self) -> float:
        """Mean disparity per metre of height over the nodes, pixels per metre (shareloc's value)."""
        return float(np.nanmean(self.baseline_ratios))

    @property
    def disparity_to_height_ratio(self) -> float:
        """Metres of height per pixel of disparity (``1 / mean_baseline_ratio``, CARS's ``disp_to_alt_ratio``)."""
        return 1.0 / self.mean_baseline_ratio

    def node_positions(self) -> tuple[np.ndarray, np.ndarray]:
        """Epipolar (row, col) of every node, package pixels (0-based centre), each (R, C)."""
        i, j = np.meshgrid(np.arange(self.shape[0]), np.arange(self.shape[1]), indexing="ij")
        return i * self.step - 0.5, j * self.step - 0.5

    def to_sensor(self, side: str, epi_rows: np.ndarray, epi_cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sensor positions of epipolar positions by bilinear interpolation of the grid (as a stereo tool reads it).

        Parameters
        ----------
        side : {"left", "right"}
        epi_rows, epi_cols : ndarray
            Epipolar positions, package pixels; NaN outside the grid.
        """
        rows, cols = self._grid(side)
        u = (np.asarray(epi_rows, dtype=np.float64) + 0.5) / self.step
        v = (np.asarray(epi_cols, dtype=np.float64) + 0.5) / self.step
        return _bilinear(rows, u, v), _bilinear(cols, u, v)

    def to_epipolar(self, side: str, rows: np.ndarray, cols: np.ndarray, iterations: int = 20
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Epipolar positions of sensor positions: the inverse of :meth:`to_sensor` (Newton on the bilinear grid,
        to 1e-9 px); NaN where it leaves the grid."""
        rows = np.asarray(rows, dtype=np.float64)
        cols = np.asarray(cols, dtype=np.float64)
        grid_r, grid_c = self._grid(side)
        # start: the nearest node's affine neighbourhood
        u = np.full(rows.shape, self.shape[0] / 2.0)
        v = np.full(rows.shape, self.shape[1] / 2.0)
        h = 1e-3
        for _ in range(iterations):
            r0, c0 = _bilinear(grid_r, u, v), _bilinear(grid_c, u, v)
            ru = (_bilinear(grid_r, u + h, v) - _bilinear(grid_r, u - h, v)) / (2 * h)
            rv = (_bilinear(grid_r, u, v + h) - _bilinear(grid_r, u, v - h)) / (2 * h)
            cu = (_bilinear(grid_c, u + h, v) - _bilinear(grid_c, u - h, v)) / (2 * h)
            cv = (_bilinear(grid_c, u, v + h) - _bilinear(grid_c, u, v - h)) / (2 * h)
            er, ec = rows - r0, cols - c0
            det = ru * cv - rv * cu
            with np.errstate(invalid="ignore", divide="ignore"):
                du = (cv * er - rv * ec) / det
                dv = (-cu * er + ru * ec) / det
            u = np.clip(u + du, 0.0, self.shape[0] - 1.0)
            v = np.clip(v + dv, 0.0, self.shape[1] - 1.0)
            if np.nanmax(np.abs(np.concatenate([np.ravel(du), np.ravel(dv)])), initial=0.0) * self.step < 1e-10:
                break
        r0, c0 = _bilinear(grid_r, u, v), _bilinear(grid_c, u, v)
        miss = ~(np.hypot(r0 - rows, c0 - cols) < 1e-6)
        er_, ec_ = u * self.step - 0.5, v * self.step - 0.5
        return np.where(miss, np.nan, er_), np.where(miss, np.nan, ec_)

    def _grid(self, side: str) -> tuple[np.ndarray, np.ndarray]:
        if side == "left":
            return self.left_rows, self.left_cols
        if side == "right":
            return self.right_rows, self.right_cols
        raise InputError(f"side must be 'left' or 'right', got {side!r}")

    def displacement(self, side: str) -> tuple[np.ndarray, np.ndarray]:
        """(column, row) displacement ``sensor - epipolar`` of each node, pixels (OTB's bands 1 and 2)."""
        rows, cols = self._grid(side)
        er, ec = self.node_positions()
        return cols - ec, rows - er


def _bilinear(grid: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of ``grid`` (R, C) at fractional node indices; NaN outside."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    n_r, n_c = grid.shape
    inside = (u >= 0) & (u <= n_r - 1) & (v >= 0) & (v <= n_c - 1)
    uu = np.clip(np.where(inside, u, 0.0), 0, n_r - 1)
    vv = np.clip(np.where(inside, v, 0.0), 0, n_c - 1)
    i0 = np.minimum(np.floor(uu).astype(np.int64), n_r - 2)
    j0 = np.minimum(np.floor(vv).astype(np.int64), n_c - 2)
    fu = uu - i0
    fv = vv - j0
    out = (grid[i0, j0] * (1 - fu) * (1 - fv) + grid[i0 + 1, j0] * fu * (1 - fv) + grid[i0, j0 + 1] * (1 - fu) * fv
           + grid[i0 + 1, j0 + 1] * fu * fv)
    return np.where(inside, out, np.nan)


def _coloc(src: Sensor, dst: Sensor, row: np.ndarray, col: np.ndarray, h: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels of ``src`` at ellipsoidal heights -> pixels of ``dst`` seeing the same ground point, and the
    geodetic ground points (N, 3) lon, lat, h (NaN where a localisation fails)."""
    lon, lat, _ = localise_geodetic(src, row, col, h)
    r, c = project_geodetic(dst, lon, lat, h)
    return r, c, np.column_stack([lon, lat, np.broadcast_to(h, lon.shape)])


def local_epipolar(left: Sensor, right: Sensor, row: np.ndarray, col: np.ndarray, height: float | np.ndarray,
                   offset_m: float = ELEVATION_OFFSET_M) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                                  np.ndarray]:
    """Local epipolar direction at left pixels (shareloc's ``compute_local_epipolar_line``).

    Returns
    -------
    angle : ndarray
        Direction in the left image, radians from the column axis towards rows.
    ratio : ndarray
        Left-image length of the local epipolar segment per metre of height (px / m).
    right_row, right_col : ndarray
        Colocalisation of the pixels in the right image at ``height``.
    ground : ndarray, shape (N, 3)
        Ground points at ``height``: lon (degrees), lat (degrees), height (m).
    """
    row = np.asarray(row, dtype=np.float64).ravel()
    col = np.asarray(col, dtype=np.float64).ravel()
    h = np.broadcast_to(np.asarray(height, dtype=np.float64), row.shape).copy()
    rr, rc, ground = _coloc(left, right, row, col, h)
    s_r, s_c, _ = _coloc(right, left, rr, rc, h - offset_m)
    e_r, e_c, _ = _coloc(right, left, rr, rc, h + offset_m)
    angle = np.arctan2(e_r - s_r, e_c - s_c)
    ratio = np.hypot(e_r - s_r, e_c - s_c) / (2.0 * offset_m)
    return angle, ratio, rr, rc, ground


#: Peak memory per grid node of :func:`epipolar_grids` (positions, angles, ratios, ground points and the
#: temporaries of one column of nodes), bytes.
GRID_BYTES_PER_NODE = 200


def epipolar_grids(left: Any, right: Any, *, height: float | None = None, dem: Any = None, step: float = 30.0,
                   elevation_offset_m: float = ELEVATION_OFFSET_M, margin: int = 0) -> EpipolarGrids:
    """Left and right epipolar resampling grids of a pair at an ellipsoidal height (shareloc's scheme).

    Parameters
    ----------
    left, right : Sensor or RationalFunctionModel
    height : float, optional
        Ellipsoidal height of the grids, metres; default: the mean of the two sensors' scene heights.
    dem : DEM, optional
        Instead of one height, each node at the height of the DEM under its left position (as shareloc with a
        DTM; :func:`explorer.rpc.dem.localization_on_dem`: ellipsoidal heights, e.g.
        :class:`explorer.terrain_io.EllipsoidalDEM`).  Needs an RPC left image; the epipolar image size takes
        the right corners at the DEM's lowest and highest heights.
    step : float
        Grid step, epipolar pixels (> 0).
    elevation_offset_m : float
        Height either side of ``height`` that defines the local epipolar direction (shareloc: 50 m).
    margin : int
        Extra nodes on every side.

    Returns
    -------
    EpipolarGrids

    Raises
    ------
    InputError
        A non-positive or non-finite step, offset or a non-finite height; a pair whose colocalisation fails at
        the left image's origin (the images do not overlap at that height).
    """
    left_s = as_sensor(left, "left")
    right_s = as_sensor(right, "right")
    if not (np.isfinite(step) and step > 0):
        raise InputError(f"step must be a positive number of pixels, got {step}")
    if not (np.isfinite(elevation_offset_m) and elevation_offset_m > 0):
        raise InputError(f"elevation_offset_m must be positive, got {elevation_offset_m}")
    if int(margin) < 0:
        raise InputError(f"margin must be >= 0, got {margin}")
    h = 0.5 * (mean_height(left_s) + mean_height(right_s)) if height is None else float(height)
    if not np.isfinite(h):
        raise InputError(f"height must be finite, got {height}")
    node_height = _dem_heights(left_s, dem) if dem is not None else None
    corner_heights = [h]
    if node_height is not None:
        h_origin = node_height(np.array([0.0]), np.array([0.0]))[0]
        h_low, h_high = _dem_range(dem)
        corner_heights = [h_low, h_high]
        if not np.isfinite(h_origin):
            raise InputError("the DEM does not cover the left image's origin")
        h = float(h_origin)
    step = float(step)
    # shareloc's prepare_rectification, in package pixels (its physical point = ours + 0.5)
    _check_overlap(left_s, right_s, h)
    origin = np.array([0.0, 0.0])  # shareloc: physical (0.5, 0.5) of index (0, 0), our (0, 0)
    alpha, _, _, _, _ = local_epipolar(left_s, right_s, origin[:1], origin[1:], h, elevation_offset_m)
    if not np.isfinite(alpha[0]):
        raise InputError(f"the epipolar direction at the left image's origin is undefined at height {h:g} m "
                         "(a localisation failed: do the images overlap?)")
    a = float(alpha[0])
    along = np.array([np.sin(a), np.cos(a)])  # (row, col)
    ortho = np.array([np.cos(a), -np.sin(a)])
    # shareloc's image corners: indices (0, 0), (rows, 0), (rows, cols), (0, cols), physical = index + 0.5
    def corners(sensor: Sensor) -> tuple[np.ndarray, np.ndarray]:
        return (np.array([0.0, sensor.n_rows, sensor.n_rows, 0.0]),
                np.array([0.0, 0.0, sensor.n_columns, sensor.n_columns]))

    left_r, left_c = corners(left_s)
    pts_list = [np.column_stack([left_r, left_c])]
    for hc in corner_heights:
        lr_c, lc_c, _ = _coloc(right_s, left_s, *corners(right_s), np.full(4, hc))
        pts_list.append(np.column_stack([lr_c, lc_c]))
    pts = np.concatenate(pts_list)
    if not np.isfinite(pts).all():
        raise InputError(f"the right image's corners do not localise at height {h:g} m")
    rel = pts - origin
    x = rel @ along
    y = rel @ ortho
    minx, maxx, miny, maxy = x.min(), x.max(), y.min(), y.max()
    size = (int(np.ceil(maxy - miny)), int(np.ceil(maxx - minx)))
    minx -= margin * step
    miny -= margin * step
    start = origin + along * minx + ortho * miny
    n_rows_grid = int(size[0] / step + 2) + 2 * int(margin)
    n_cols_grid = int(size[1] / step + 2) + 2 * int(margin)
    from explorer.memory import check_allocation

    # before the first node is walked: a step of 0.001 px on a 40,000 px image asks for 1.6e15 nodes
    check_allocation(float(n_rows_grid) * n_cols_grid * GRID_BYTES_PER_NODE,
                     f"step {step:g} px ({n_rows_grid:,} x {n_cols_grid:,} grid nodes)", "raise --step")

    def walk(points: np.ndarray, angles: np.ndarray, axis: int) -> np.ndarray:
        direction = angles + (np.pi / 2 if axis == 0 else 0.0)
        return points + step * np.stack([np.sin(direction), np.cos(direction)], axis=-1)

    # first column of nodes: across the epipolar lines
    col_pts = np.empty((n_rows_grid, 2))
    col_pts[0] = start
    col_ang = np.empty(n_rows_grid)

    def heights_at(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return np.full(rows.shape, h) if node_height is None else node_height(rows, cols)

    ang, _, _, _, _ = local_epipolar(left_s, right_s, start[:1], start[1:], heights_at(start[:1], start[1:]),
                                     elevation_offset_m)
    col_ang[0] = ang[0]
    for i in range(1, n_rows_grid):
        col_pts[i] = walk(col_pts[i - 1], col_ang[i - 1:i], 0)[0]
        ang, _, _, _, _ = local_epipolar(left_s, right_s, col_pts[i, :1], col_pts[i, 1:],
                                         heights_at(col_pts[i, :1], col_pts[i, 1:]), elevation_offset_m)
        col_ang[i] = ang[0] if np.isfinite(ang[0]) else col_ang[i - 1]
    # then every row along the epipolar direction, all rows at once
    left_pos = np.empty((n_rows_grid, n_cols_grid, 2))
    right_pos = np.empty((n_rows_grid, n_cols_grid, 2))
    angles = np.empty((n_rows_grid, n_cols_grid))
    ratios = np.empty((n_rows_grid, n_cols_grid))
    ground = np.empty((n_rows_grid, n_cols_grid, 3))
    current = col_pts
    for j in range(n_cols_grid):
        if j > 0:
            current = walk(current, angles[:, j - 1], 1)
        ang, ratio, rr, rc, g = local_epipolar(left_s, right_s, current[:, 0], current[:, 1],
                                               heights_at(current[:, 0], current[:, 1]), elevation_offset_m)
        if j > 0:  # a node off the DEM keeps its neighbour's direction (its positions are NaN)
            ang = np.where(np.isfinite(ang), ang, angles[:, j - 1])
        left_pos[:, j] = current
        right_pos[:, j, 0] = rr
        right_pos[:, j, 1] = rc
        angles[:, j] = ang
        ratios[:, j] = ratio
        ground[:, j] = g
    grid_height = h if node_height is None else float(np.nanmean(ground[..., 2]))
    return EpipolarGrids(left_pos[..., 0], left_pos[..., 1], right_pos[..., 0], right_pos[..., 1], step, size,
                         grid_height, angles, ratios, ground)


def _check_overlap(left: Sensor, right: Sensor, h: float, n: int = 7) -> None:
    """Raise :class:`InputError` unless some of an n x n sample of left pixels is seen by the right image."""
    from explorer.stereo.sensors import inside_image

    rr, cc = np.meshgrid(np.linspace(0, left.n_rows - 1, n), np.linspace(0, left.n_columns - 1, n), indexing="ij")
    r, c, _ = _coloc(left, right, rr.ravel(), cc.ravel(), np.full(rr.size, h))
    if not np.any(inside_image(right, r, c)):
        raise InputError(f"the images do not overlap at height {h:g} m: no left pixel of a {n} x {n} sample "
                         "is seen by the right image")


def _dem_heights(left: Sensor, dem: Any) -> Any:
    """Function (rows, cols) -> ellipsoidal height of the DEM under left pixels (NaN off the DEM)."""
    from explorer.rpc.dem import localization_on_dem
    from explorer.stereo.sensors import rpc_model

    model = rpc_model(left)
    if model is None:
        raise InputError("grids on a DEM need an RPC left image (give --height for other sensors)")

    def heights(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        _, _, hh, ok = localization_on_dem(model, np.asarray(rows, dtype=np.float64),
                                           np.asarray(cols, dtype=np.float64), dem)
        return np.where(ok, hh, np.nan)

    return heights


def _dem_range(dem: Any) -> tuple[float, float]:
    """Lowest and highest ellipsoidal height of a DEM (its grid's finite values)."""
    lo, hi = getattr(dem, "min", None), getattr(dem, "max", None)
    lo, hi = (lo() if callable(lo) else lo), (hi() if callable(hi) else hi)
    if lo is None or hi is None or not (np.isfinite(lo) and np.isfinite(hi)):
        raise InputError(f"cannot read the height range of the DEM ({type(dem).__name__})")
    return float(lo), float(hi)


def write_grids(grids: EpipolarGrids, out_dir: str | Path, *, prefix: str = "") -> dict[str, Path]:
    """Write the two grids as GeoTIFF in OTB's convention and a JSON summary.

    Files: ``<prefix>left_epipolar_grid.tif``, ``<prefix>right_epipolar_grid.tif`` (float64, band 1 column
    displacement, band 2 row displacement, band 3 height; geotransform ``(-step/2, step, 0, -step/2, 0, step)``;
    pixel-corner convention of shareloc/OTB, see the module docstring) and ``<prefix>grids.json`` (epipolar
    image size, step, height, mean baseline ratio, disparity-to-height ratio).

    Returns
    -------
    dict
        ``{"left": path, "right": path, "summary": path}``.
    """
    import json

    import rasterio
    from affine import Affine

    from explorer.io_atomic import atomic_path

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {str(out)!r} is a file, not a folder")
    out.mkdir(parents=True, exist_ok=True)
    transform = Affine(grids.step, 0.0, -grids.step / 2.0, 0.0, grids.step, -grids.step / 2.0)
    paths: dict[str, Path] = {}
    for side in ("left", "right"):
        dx, dy = grids.displacement(side)
        path = out / f"{prefix}{side}_epipolar_grid.tif"
        with atomic_path(path) as tmp, rasterio.open(
            tmp, "w", driver="GTiff", dtype="float64", width=grids.shape[1], height=grids.shape[0], count=3,
            transform=transform,
        ) as ds:
            ds.write(dx, 1)
            ds.write(dy, 2)
            ds.write(grids.ground[..., 2], 3)
            ds.set_band_description(1, "column displacement (sensor - epipolar), px")
            ds.set_band_description(2, "row displacement (sensor - epipolar), px")
            ds.set_band_description(3, "height above the ellipsoid, m")
        paths[side] = path
    lon, lat = grids.ground[..., 0], grids.ground[..., 1]
    summary = {
        "epipolar_size": {"rows": grids.epipolar_size[0], "columns": grids.epipolar_size[1]},
        "grid_size": {"rows": grids.shape[0], "columns": grids.shape[1]},
        "step_px": grids.step,
        "height_m": grids.height,
        "mean_baseline_ratio_px_per_m": grids.mean_baseline_ratio,
        "disparity_to_height_ratio_m_per_px": grids.disparity_to_height_ratio,
        "lon_range_deg": [float(np.nanmin(lon)), float(np.nanmax(lon))],
        "lat_range_deg": [float(np.nanmin(lat)), float(np.nanmax(lat))],
        "convention": "OTB/shareloc: band 1 col displacement, band 2 row displacement (sensor - epipolar), "
                      "pixel centre at index + 0.5, node (i, j) at epipolar (i*step, j*step)",
    }
    spath = out / f"{prefix}grids.json"
    with atomic_path(spath) as tmp:
        Path(tmp).write_text(json.dumps(summary, indent=2) + "\n")
    paths["summary"] = spath
    return paths


__all__ = ["ELEVATION_OFFSET_M", "EpipolarGrids", "epipolar_grids", "local_epipolar", "write_grids"]
