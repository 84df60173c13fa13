"""Simulated control points (SCOPs) and check points (SCPs), as in the papers.

A regular grid in image space is mapped to the ground through the rigorous model
(mean-height plane, DEM, or several height layers for 3D grids).  Each point
carries its image row/column, ground coordinates and exact scanline time.
Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from explorer.errors import InputError
from explorer.geometry.dem_intersection import OK
from explorer.io_atomic import atomic_path
from explorer.memory import check_allocation
from explorer.scene import Scene
from explorer.sensor import has_geodetic_projection, has_line_geometry, has_polynomial_exterior


@dataclass
class PointSet:
    """Points with known image and ground coordinates.

    Attributes
    ----------
    row, col : ndarray, shape (N,)
        Exact image coordinates (0-based, pixel centre).
    ground : ndarray, shape (N, 3)
        Local ENU metres.
    time : ndarray, shape (N,)
        Exact scanline time, seconds (NaN on a sensor without scanlines, an RPC: :func:`scanline_times`).
    grid_shape : tuple of int
        (rows, cols, layers) of the generating grid.
    """

    row: np.ndarray
    col: np.ndarray
    ground: np.ndarray
    time: np.ndarray
    grid_shape: tuple[int, int, int] = (0, 0, 1)
    geodetic: np.ndarray | None = None
    """(N, 3) longitude, latitude (degrees), ellipsoidal height (metres) as a sensor defined on them (an RPC,
    :class:`explorer.sensor.GeodeticSensor`) localised the points -- ``ground`` is converted from them -- so its
    truth is evaluated on them (:meth:`explorer.sensor.Sensor.project_geodetic`); None for other sensors."""

    def __len__(self) -> int:
        return int(self.row.shape[0])

    @property
    def n(self) -> int:
        return len(self)

    def subset(self, index: np.ndarray) -> PointSet:
        """Points selected by an integer or boolean index."""
        return PointSet(self.row[index], self.col[index], self.ground[index], self.time[index], self.grid_shape,
                        None if self.geodetic is None else self.geodetic[index])

    def split(self, fraction: float, seed: int) -> tuple[PointSet, PointSet]:
        """Seeded random split into (first, second) with ``round(fraction * N)`` points in the first."""
        rng = np.random.default_rng(seed)
        perm = rng.permutation(len(self))
        k = int(round(fraction * len(self)))
        return self.subset(np.sort(perm[:k])), self.subset(np.sort(perm[k:]))

    def sample(self, n: int, seed: int) -> PointSet:
        """Seeded random subsample of ``min(n, N)`` points (order kept)."""
        if n >= len(self):
            return self
        rng = np.random.default_rng(seed)
        return self.subset(np.sort(rng.choice(len(self), size=n, replace=False)))

    def save_npz(self, path: str | Path, scene: Scene | None = None) -> None:
        """Write arrays ``row``, ``col``, ``ground``, ``time`` (and ``scene_json``) to an .npz file.

        The file is written atomically under exactly ``path`` (no ``.npz`` is appended).
        """
        arrays: dict[str, Any] = {"row": self.row, "col": self.col, "ground": self.ground, "time": self.time,
                  "grid_shape": np.array(self.grid_shape)}
        if self.geodetic is not None:
            arrays["geodetic"] = self.geodetic
        if scene is not None:
            arrays["scene_json"] = np.array(scene.to_json())
        with atomic_path(path) as tmp, open(tmp, "wb") as handle:
            np.savez(handle, **arrays)

    @classmethod
    def load_npz(cls, path: str | Path) -> PointSet:
        """Inverse of :meth:`save_npz` (the scene, if any, via ``Scene.from_dict(json.loads(...))``)."""
        with np.load(path) as z:
            rows, cols, layers = (int(v) for v in z["grid_shape"])
            geodetic = z["geodetic"] if "geodetic" in z.files else None
            return cls(z["row"], z["col"], z["ground"], z["time"], (rows, cols, layers), geodetic)


def grid_shape_for(n: int, n_rows: int, n_columns: int) -> tuple[int, int]:
    """Grid (rows, cols) of about ``n`` nodes with the image's aspect ratio (each >= 2)."""
    if n < 4:
        raise InputError(f"a grid needs at least 4 points, got n={n}")
    gr = max(2, int(round(np.sqrt(n * n_rows / n_columns))))
    gc = max(2, int(round(n / gr)))
    return gr, gc


#: Peak memory of :func:`image_grid` per point (measured: ~100 bytes on a flat or DEM terrain; twice that as margin).
BYTES_PER_POINT = 200


def row_counts(n: int, n_grid_rows: int) -> np.ndarray:
    """How many of ``n`` points each of ``n_grid_rows`` grid rows holds so that they sum to exactly ``n``:
    ``floor((k + 1) n / g) - floor(k n / g)``, which differ by at most one and spread the longer rows
    evenly (every row of a ``g x (n / g)`` grid when ``g`` divides ``n``)."""
    k = np.arange(n_grid_rows + 1, dtype=np.int64)
    return np.diff((k * int(n)) // int(n_grid_rows))


def image_grid(
    scene: Scene,
    n: int,
    *,
    layers: int = 1,
    height_range: tuple[float, float] | None = None,
    cell_centred: bool = False,
    jitter_px: float = 0.0,
    seed: int = 0,
) -> PointSet:
    """Regular image grid of about ``n`` points per layer mapped to the ground.

    Parameters
    ----------
    scene : Scene
    n : int
        Target number of points per layer; the exact count is ``len(result)``.
    layers : int
        1: intersect with the scene terrain (plane or DEM).  >1: a 3D grid, the same
        image grid intersected with ``layers`` horizontal planes spanning ``height_range``.
    height_range : (float, float), optional
        Lowest and highest layer, metres; default the terrain's min/max, widened to
        +-500 m around the mean height when the terrain is flat.
    cell_centred : bool
        False: nodes span the image from the first to the last pixel centre (SCOPs), exactly ``n``
        of them per layer: the grid rows hold ``n / rows`` rounded up or down (:func:`row_counts`),
        each row spread from the first to the last column, so the corners are always nodes.
        True: nodes at the centres of ``grid_shape_for(n)`` equal cells (SCPs; about ``n``), so
        SCP and SCOP grids differ.
    jitter_px : float
        Uniform random offset of each node, in +- pixels (seeded); 0 keeps the grid regular.
    seed : int

    Returns
    -------
    PointSet
        Points whose ray misses a DEM (outside or no-data) are dropped, and the count says so.
    """
    if layers < 1:
        raise InputError(f"layers must be >= 1, got {layers}")
    check_allocation(float(n) * layers * BYTES_PER_POINT, f"a grid of {n} points x {layers} layer(s)",
                     "ask for fewer points or layers")
    gr, gc = grid_shape_for(n, scene.n_rows, scene.n_columns)
    if not cell_centred and gr * gc != n:
        # the chosen count exactly: rows of gc or gc +- 1 nodes, each spanning the image's columns
        counts = row_counts(n, gr)
        rows = np.linspace(0.0, scene.n_rows - 1.0, gr)
        rr = np.repeat(rows, counts)
        cc = np.concatenate([np.linspace(0.0, scene.n_columns - 1.0, int(c)) if c > 1
                             else np.array([(scene.n_columns - 1.0) / 2.0]) for c in counts])
        return _ragged_grid(scene, rr, cc, (gr, int(counts.max()), layers), layers, height_range, jitter_px, seed)
    if cell_centred:
        rows = (np.arange(gr) + 0.5) * scene.n_rows / gr - 0.5
        cols = (np.arange(gc) + 0.5) * scene.n_columns / gc - 0.5
    else:
        rows = np.linspace(0.0, scene.n_rows - 1.0, gr)
        cols = np.linspace(0.0, scene.n_columns - 1.0, gc)
    rr = np.repeat(rows, gc)
    cc = np.tile(cols, gr)
    if jitter_px:
        rng = np.random.default_rng(seed)
        rr = np.clip(rr + rng.uniform(-jitter_px, jitter_px, rr.shape), -0.5, scene.n_rows - 0.5)
        cc = np.clip(cc + rng.uniform(-jitter_px, jitter_px, cc.shape), -0.5, scene.n_columns - 0.5)
    if layers == 1 and not jitter_px and _lines_of_sight_are_the_scenes(scene):
        # a regular grid: orientation once per grid row, then the terrain's own first hit
        origin, direction = _grid_rays(scene, rows, cols)
        ground, flags = scene.terrain.intersect(origin, direction)
        ok = flags == OK
        return PointSet(rr[ok], cc[ok], ground[ok], scanline_times(scene, rr[ok]), (gr, gc, 1))
    if layers == 1:
        ground, geodetic = _to_ground(scene, rr, cc)
        ok = np.isfinite(ground[:, 0])
        return PointSet(rr[ok], cc[ok], ground[ok], scanline_times(scene, rr[ok]), (gr, gc, 1), _kept(geodetic, ok))
    return _layers(scene, rr, cc, (gr, gc, layers), layers, height_range)


def _to_ground(scene: Any, rr: np.ndarray, cc: np.ndarray, height: float | None = None
               ) -> tuple[np.ndarray, np.ndarray | None]:
    """The sensor's own image to ground (N, 3) and, for a sensor defined on geodetic coordinates (an RPC:
    :func:`explorer.sensor.has_geodetic_projection`), the (lon, lat, h) (N, 3) its localisation found, else None."""
    if has_geodetic_projection(scene):
        ground, geodetic = scene.image_to_ground_geodetic(rr, cc, height=height)
        return ground, geodetic
    return scene.image_to_ground(rr, cc, height=height), None


def _kept(geodetic: np.ndarray | None, ok: np.ndarray) -> np.ndarray | None:
    return None if geodetic is None else geodetic[ok]


def _ragged_grid(scene: Scene, rr: np.ndarray, cc: np.ndarray, shape: tuple[int, int, int], layers: int,
                 height_range: tuple[float, float] | None, jitter_px: float, seed: int) -> PointSet:
    """Points at image positions ``rr``, ``cc`` (N,) on the terrain (or on ``layers`` planes)."""
    if jitter_px:
        rng = np.random.default_rng(seed)
        rr = np.clip(rr + rng.uniform(-jitter_px, jitter_px, rr.shape), -0.5, scene.n_rows - 0.5)
        cc = np.clip(cc + rng.uniform(-jitter_px, jitter_px, cc.shape), -0.5, scene.n_columns - 0.5)
    if layers == 1:
        ground, geodetic = _to_ground(scene, rr, cc)
        ok = np.isfinite(ground[:, 0])
        return PointSet(rr[ok], cc[ok], ground[ok], scanline_times(scene, rr[ok]), shape, _kept(geodetic, ok))
    return _layers(scene, rr, cc, shape, layers, height_range)


def _layers(scene: Scene, rr: np.ndarray, cc: np.ndarray, shape: tuple[int, int, int], layers: int,
            height_range: tuple[float, float] | None) -> PointSet:
    """The image positions' lines of sight cut by ``layers`` horizontal planes over ``height_range``."""
    if height_range is None:
        lo, hi = scene.terrain.min_height, scene.terrain.max_height
        if hi - lo < 1.0:
            lo, hi = lo - 500.0, hi + 500.0
        height_range = (lo, hi)
    heights = np.linspace(height_range[0], height_range[1], layers)
    geodetic: np.ndarray | None = None
    if _lines_of_sight_are_the_scenes(scene):  # one set of lines of sight for every layer
        origin, direction = scene.rays(rr, cc)
        parts = []
        for h in heights:
            lam = (h - origin[:, 2]) / direction[:, 2]
            parts.append(origin + lam[:, None] * direction)
    else:  # lines of sight that depend on the height (aberration, refraction): the model's own, per layer
        both = [_to_ground(scene, rr, cc, height=float(h)) for h in heights]
        parts = [g for g, _ in both]
        if all(geo is not None for _, geo in both):
            geodetic = np.concatenate([geo for _, geo in both])  # type: ignore[misc]
    ground = np.concatenate(parts)
    r3, c3 = np.tile(rr, layers), np.tile(cc, layers)
    # image points the sensor flags (NaN: a ray that misses the body, a line outside a CSM camera's
    # ephemeris tables) are dropped, as on one layer
    ok = np.isfinite(ground).all(axis=1)
    return PointSet(r3[ok], c3[ok], ground[ok], scanline_times(scene, r3[ok]), shape, _kept(geodetic, ok))


def _grid_rays(scene: Scene, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lines of sight of a regular grid: orientation once per grid row, broadcast over the columns.

    Returns origins and (unnormalised) directions, each (len(rows) * len(cols), 3), row-major.
    """
    t = scanline_times(scene, rows)
    centres = scene.exterior.position(t)  # (gr, 3)
    rot = scene.exterior.rotation(t)  # (gr, 3, 3)
    xd, yd = scene.interior.detector_focal_plane(cols)
    x, y = scene.interior.undistort(xd, yd)
    v = np.stack([x, y, np.full_like(x, -scene.interior.focal_length_m)], axis=-1)  # (gc, 3)
    direction = np.empty((rows.size, cols.size, 3))
    for k in range(3):
        direction[:, :, k] = rot[:, k, :] @ v.T
    origin = np.broadcast_to(centres[:, None, :], direction.shape).reshape(-1, 3)
    return origin, direction.reshape(-1, 3)


def scanline_times(sensor: Any, rows: np.ndarray) -> np.ndarray:
    """Exposure times (N,) of rows (N,), seconds, on a sensor with scanlines
    (:func:`explorer.sensor.has_line_geometry`); NaN on one without (an RPC has no time axis)."""
    rows = np.asarray(rows, dtype=np.float64)
    if has_line_geometry(sensor):
        return np.asarray(sensor.scanline_time(rows), dtype=np.float64)
    return np.full(rows.shape, np.nan)


def _lines_of_sight_are_the_scenes(scene: Any) -> bool:
    """True where ``scene`` declares MPC polynomials as its exterior orientation
    (:func:`explorer.sensor.has_polynomial_exterior`): its lines of sight are then :class:`Scene`'s collinearity
    of the polynomials and the interior orientation (what the compiled kernels pack too), so :func:`_grid_rays`
    is its geometry.  A model with other exterior orientations or corrected lines of sight (ephemeris tables,
    aberration, refraction: :class:`explorer.real.linescan.RigorousLineScanScene`, a CSM camera, an RPC) goes
    through its own ``image_to_ground``."""
    return has_polynomial_exterior(scene)


def simulate_points(
    scene: Scene, n: int, *, layers: int = 1, kind: str = "scop", seed: int = 0
) -> PointSet:
    """SCOPs (``kind='scop'``: grid through the image corners) or SCPs (``'scp'``: cell-centred grid)."""
    if kind not in ("scop", "scp"):
        raise InputError(f"kind must be 'scop' or 'scp', got {kind!r}")
    points = image_grid(scene, n, layers=layers, cell_centred=(kind == "scp"), seed=seed)
    if kind == "scop" and layers == 1 and 0 < len(points) < n:
        points = _scops_where_the_terrain_is(scene, n, points)
    return points


SCOP_GRID_TRIES = 12
"""Denser grids :func:`_scops_where_the_terrain_is` tries before it reports fewer SCOPs than asked."""


def _scops_where_the_terrain_is(scene: Scene, n: int, first: PointSet) -> PointSet:
    """Exactly ``n`` SCOPs where the terrain has heights (a DEM covering part of the image).

    The grid of ``n`` nodes lost the nodes over the DEM's holes or past its edge.  A denser grid, in
    steps of the coverage found, is laid until at least ``n`` nodes land on the terrain; the surplus is
    thinned evenly along the grid's row-major order (deterministic: the same SCOPs on every run).
    Where no grid of up to :data:`SCOP_GRID_TRIES` densifications reaches ``n``, the densest is returned
    (its count says so).
    """
    best, m = first, n
    for _ in range(SCOP_GRID_TRIES):
        if len(best) >= n:
            break
        m = max(m + 1, int(math.ceil(m * n / max(len(best), 1))))
        best = image_grid(scene, m, cell_centred=False)
    if len(best) <= n:
        return best
    keep = np.unique(np.round(np.linspace(0, len(best) - 1, n)).astype(np.int64))
    return PointSet(best.row[keep], best.col[keep], best.ground[keep], best.time[keep], (0, 0, 1))
