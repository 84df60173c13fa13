"""Terrain in the local ENU frame: the :class:`Terrain` interface, a constant height plane
(:class:`FlatTerrain`), a regular-grid DEM (:class:`GridDEM`, bilinear, explicit no-data) and a seeded
synthetic relief generator.  Heights are the local ``up`` coordinate in metres
(``docs/conventions.md#frames``).

Every image-to-ground path intersects its lines of sight through :meth:`Terrain.intersect` (the first hit
from the sensor, with a flag per ray, ``docs/conventions.md#validity``) and samples heights through
:meth:`Terrain.height`; no caller branches on the terrain's type.  A new kind of terrain implements the
protocol (``isinstance(obj, Terrain)`` checks the members exist).
"""

from __future__ import annotations

import base64
from dataclasses import dataclass, field
from typing import Literal, Protocol, overload, runtime_checkable

import numpy as np

from explorer.errors import InputError
from explorer.geometry.dem_intersection import NO_INTERSECTION, OK, HeightGrid, intersect_rays


@runtime_checkable
class Terrain(Protocol):
    """A terrain surface ``Z = h(X, Y)`` in local ENU metres: heights, bounds and the first hit of rays.

    Implemented by :class:`FlatTerrain` and :class:`GridDEM`.
    """

    @property
    def min_height(self) -> float:
        """Lowest height, metres."""
        ...

    @property
    def max_height(self) -> float:
        """Highest height, metres (equal to :attr:`min_height` for a terrain of one height)."""
        ...

    @property
    def mean_height(self) -> float:
        """Mean height, metres (the reference height of footprints and ground sample distances)."""
        ...

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Height (N,) at (x, y) (N,) metres; NaN where the terrain is unknown (outside, no-data)."""
        ...

    def intersect(self, origin: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First intersection of rays with the surface from their origins.

        Parameters
        ----------
        origin, direction : ndarray, shape (N, 3)
            Ray origins (above the terrain) and directions (need not be unit), metres.

        Returns
        -------
        points : ndarray, shape (N, 3)
            Ground points, metres; NaN rows where the flag is not OK.
        flags : ndarray of int8, shape (N,)
            :mod:`explorer.geometry.dem_intersection` flags: 0 OK, 1 outside the DEM, 2 no-data,
            3 no intersection.
        """
        ...

    def to_dict(self) -> dict:
        """JSON-ready description (:func:`terrain_from_dict` is the inverse)."""
        ...


def intersect_heights(
    origin: np.ndarray, direction: np.ndarray, height: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """Rays against the plane(s) ``Z = height`` (one height, or one per ray): points (N, 3) and flags (N,)
    int8 as :meth:`Terrain.intersect` (:data:`~explorer.geometry.dem_intersection.NO_INTERSECTION` where the
    ray does not reach its plane going forward)."""
    points = intersect_plane(origin, direction, height)
    return points, np.where(np.isfinite(points[:, 0]), OK, NO_INTERSECTION).astype(np.int8)


@dataclass(frozen=True)
class FlatTerrain:
    """A horizontal plane ``Z = height_m`` (the papers' mean height)."""

    height_m: float = 0.0

    @property
    def min_height(self) -> float:
        return self.height_m

    max_height = mean_height = min_height  # a plane: one height

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Height (N,) at (x, y) (N,), metres."""
        return np.full(np.broadcast(np.asarray(x), np.asarray(y)).shape, self.height_m)

    def intersect(self, origin: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact intersection with the plane (:meth:`Terrain.intersect`)."""
        return intersect_heights(origin, direction, self.height_m)

    def to_dict(self) -> dict:
        return {"kind": "flat", "height_m": self.height_m}


@dataclass
class GridDEM:
    """Regular grid of heights with bilinear interpolation.

    Node ``heights[i, j]`` lies at ``(x0 + j dx, y0 + i dy)`` (local ENU metres).
    Cells touching a no-data node (NaN, or ``nodata``) and points outside the grid
    give NaN from :meth:`height`, never an extrapolated value.

    Parameters
    ----------
    x0, y0 : float
        Coordinates of node (0, 0), metres.
    dx, dy : float
        Node spacing, metres (positive).
    heights : ndarray, shape (ny, nx)
    nodata : float or None
    source : dict
        How the grid was made (``{"kind": "synthetic", ...}`` regenerates it from
        the seed; otherwise the heights are stored in the scene file).
    """

    x0: float
    y0: float
    dx: float
    dy: float
    heights: np.ndarray
    nodata: float | None = None
    source: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        h = np.array(self.heights, dtype=np.float64)
        if h.ndim != 2 or min(h.shape) < 2:
            raise ValueError(f"DEM heights must be a 2D grid of at least 2x2, got {h.shape}")
        if not (self.dx > 0 and self.dy > 0):
            raise ValueError("DEM spacing dx, dy must be positive")
        if self.nodata is not None:
            h[h == self.nodata] = np.nan
        self.heights = h
        finite = h[np.isfinite(h)]
        if finite.size == 0:
            raise ValueError("DEM has no valid height")
        self._min = float(finite.min())
        self._max = float(finite.max())

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the node grid, metres."""
        ny, nx = self.heights.shape
        return (self.x0, self.x0 + (nx - 1) * self.dx, self.y0, self.y0 + (ny - 1) * self.dy)

    @property
    def min_height(self) -> float:
        return self._min

    @property
    def max_height(self) -> float:
        return self._max

    @property
    def mean_height(self) -> float:
        return float(np.nanmean(self.heights))

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Bilinear height (N,) at (x, y) (N,) metres; NaN outside the grid or near no-data."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        ny, nx = self.heights.shape
        u = (x - self.x0) / self.dx
        v = (y - self.y0) / self.dy
        inside = (u >= 0) & (u <= nx - 1) & (v >= 0) & (v <= ny - 1)
        j = np.clip(np.floor(np.where(inside, u, 0.0)).astype(np.int64), 0, nx - 2)
        i = np.clip(np.floor(np.where(inside, v, 0.0)).astype(np.int64), 0, ny - 2)
        fu = u - j
        fv = v - i
        h = self.heights
        z = (
            h[i, j] * (1 - fu) * (1 - fv)
            + h[i, j + 1] * fu * (1 - fv)
            + h[i + 1, j] * (1 - fu) * fv
            + h[i + 1, j + 1] * fu * fv
        )
        return np.where(inside, z, np.nan)

    def height_grid(self) -> HeightGrid:
        """The grid in the compiled kernel's layout (built once; the heights must not change afterwards)."""
        cached = self.__dict__.get("_height_grid")
        if cached is None or cached.heights.shape != self.heights.shape:
            cached = HeightGrid.from_array(self.heights, self.x0, self.y0, self.dx, self.dy)
            self.__dict__["_height_grid"] = cached
        return cached

    def intersect(self, origin: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact first intersection with the bilinear surface (:meth:`Terrain.intersect`; the compiled cell walk
        of :mod:`explorer.geometry.dem_intersection`)."""
        return intersect_rays(origin, direction, self.height_grid())

    def to_dict(self) -> dict:
        d = {
            "kind": "grid",
            "x0": self.x0,
            "y0": self.y0,
            "dx": self.dx,
            "dy": self.dy,
            "nodata": self.nodata,
            "source": self.source,
        }
        if self.source.get("kind") != "synthetic":
            d["shape"] = list(self.heights.shape)
            d["heights_f64_b64"] = base64.b64encode(
                np.ascontiguousarray(self.heights, dtype="<f8").tobytes()
            ).decode("ascii")
        return d


#: Largest synthetic relief grid (nodes) :func:`synthetic_relief` builds: 4096 x 4096 (134 MB of float64).
MAX_SYNTHETIC_NODES = 4096 * 4096


def synthetic_relief(
    extent: tuple[float, float, float, float],
    amplitude_m: float,
    seed: int,
    *,
    base_height_m: float = 0.0,
    cell_m: float | None = None,
    correlation_cells: float = 6.0,
) -> GridDEM:
    """Seeded smooth random relief.

    Gaussian-filtered white noise on a grid covering ``extent``, scaled so that
    ``max |h - base_height_m| == amplitude_m``.

    Parameters
    ----------
    extent : (xmin, xmax, ymin, ymax)
        Area to cover, metres (the grid is padded by two cells).
    amplitude_m : float
        Largest departure from ``base_height_m``, metres.
    seed : int
        Random seed; the same arguments give the same grid.
    cell_m : float, optional
        Node spacing; default gives about 128 cells across the larger side.
    correlation_cells : float
        Gaussian filter sigma in cells (hill size).
    """
    xmin, xmax, ymin, ymax = (float(v) for v in extent)
    if cell_m is None:
        cell_m = max(xmax - xmin, ymax - ymin) / 128.0
    # bounded work: a scene file must not be able to ask for a giant grid (issue 18 fuzzing)
    if not (np.isfinite([xmin, xmax, ymin, ymax, amplitude_m, base_height_m]).all() and xmax >= xmin
            and ymax >= ymin and np.isfinite(cell_m) and cell_m > 0):
        raise InputError(f"synthetic relief: extent {extent}, amplitude {amplitude_m}, base {base_height_m} and "
                         f"cell {cell_m} must be finite, the extent ordered and the cell positive")
    nodes = ((xmax - xmin) / cell_m + 6) * ((ymax - ymin) / cell_m + 6)
    if nodes > MAX_SYNTHETIC_NODES or not 0 < correlation_cells <= 1000:
        raise InputError(f"synthetic relief of {nodes:.3g} nodes (limit {MAX_SYNTHETIC_NODES:,}) or correlation "
                         f"{correlation_cells} cells (limit (0, 1000]): cell_m {cell_m} is too small for the extent")
    nx = int(np.ceil((xmax - xmin) / cell_m)) + 5
    ny = int(np.ceil((ymax - ymin) / cell_m)) + 5
    from scipy.ndimage import gaussian_filter  # here: scipy.ndimage is 0.1-0.3 s to import, only this needs it

    rng = np.random.default_rng(seed)
    noise = gaussian_filter(rng.standard_normal((ny, nx)), correlation_cells, mode="reflect")
    noise -= noise.mean()
    peak = np.abs(noise).max()
    h = base_height_m + (amplitude_m * noise / peak if peak > 0 and amplitude_m != 0 else 0.0 * noise)
    source = {
        "kind": "synthetic",
        "extent": [xmin, xmax, ymin, ymax],
        "amplitude_m": float(amplitude_m),
        "seed": int(seed),
        "base_height_m": float(base_height_m),
        "cell_m": float(cell_m),
        "correlation_cells": float(correlation_cells),
    }
    return GridDEM(xmin - 2 * cell_m, ymin - 2 * cell_m, cell_m, cell_m, h, None, source)


def mountain_heights(shape: tuple[int, int], low_m: float, high_m: float, seed: int) -> np.ndarray:
    """Seeded rough terrain with a mountain, like an SRTM tile of a massif: heights (ny, nx), metres.

    Power-law (fractal) relief -- Fourier amplitudes falling as 1/k^2 with random phases -- plus a Gaussian
    mountain in the middle, scaled to ``low_m``..``high_m``.  For benchmarks and tests of the DEM search: slopes
    at every scale, many cells crossed by an oblique line of sight.

    Parameters
    ----------
    shape : (int, int)
        Nodes (rows, columns).
    low_m, high_m : float
        Lowest and highest height, metres.
    seed : int
        The same arguments give the same grid.
    """
    ny, nx = shape
    rng = np.random.default_rng(seed)
    k = np.hypot(np.fft.rfftfreq(nx)[None, :], np.fft.fftfreq(ny)[:, None])
    k[0, 0] = 1.0
    spectrum = (rng.normal(size=k.shape) + 1j * rng.normal(size=k.shape)) * k ** -2.0
    spectrum[0, 0] = 0.0
    z = np.fft.irfft2(spectrum, s=(ny, nx))
    yy, xx = np.mgrid[0:ny, 0:nx]
    mountain = np.exp(-(((xx - 0.5 * nx) / (0.25 * nx)) ** 2 + ((yy - 0.5 * ny) / (0.25 * ny)) ** 2))
    z = 0.5 * (z - z.min()) / np.ptp(z) + mountain
    return low_m + (z - z.min()) / np.ptp(z) * (high_m - low_m)


def terrain_from_dict(d: dict) -> FlatTerrain | GridDEM:
    """Inverse of ``to_dict`` of either terrain kind."""
    kind = d.get("kind")
    if kind == "flat":
        return FlatTerrain(float(d["height_m"]))
    if kind == "grid":
        src = d.get("source", {})
        if src.get("kind") == "synthetic":
            return synthetic_relief(
                tuple(src["extent"]), src["amplitude_m"], src["seed"],
                base_height_m=src["base_height_m"], cell_m=src["cell_m"],
                correlation_cells=src["correlation_cells"],
            )
        raw = base64.b64decode(d["heights_f64_b64"])
        heights = np.frombuffer(raw, dtype="<f8").reshape(d["shape"]).copy()
        return GridDEM(d["x0"], d["y0"], d["dx"], d["dy"], heights, d.get("nodata"), src)
    raise ValueError(f"unknown terrain kind {kind!r} (expected 'flat' or 'grid')")


def intersect_plane(origin: np.ndarray, direction: np.ndarray, height: np.ndarray | float) -> np.ndarray:
    """Exact intersection of rays with the plane Z = height.

    Parameters
    ----------
    origin, direction : ndarray, shape (N, 3)
    height : float or ndarray (N,)

    Returns
    -------
    ndarray, shape (N, 3); NaN rows for rays that do not reach the plane going forward.
    """
    lam = (np.asarray(height, dtype=np.float64) - origin[:, 2]) / direction[:, 2]
    lam = np.where(lam > 0, lam, np.nan)
    return origin + lam[:, None] * direction


@overload
def intersect_dem(origin: np.ndarray, direction: np.ndarray, dem: GridDEM, *,
                  return_flags: Literal[False] = False) -> np.ndarray: ...
@overload
def intersect_dem(origin: np.ndarray, direction: np.ndarray, dem: GridDEM, *,
                  return_flags: Literal[True]) -> tuple[np.ndarray, np.ndarray]: ...
def intersect_dem(
    origin: np.ndarray,
    direction: np.ndarray,
    dem: GridDEM,
    *,
    return_flags: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Exact first intersection of rays with the bilinear DEM surface (compiled kernel).

    The ray is walked cell by cell from the plane Z = max height down to Z = min height and, in each cell
    that may hold a hit, the bilinear patch is intersected exactly (a quadratic), so no ridge is skipped
    however thin; see :mod:`explorer.geometry.dem_intersection`.

    Parameters
    ----------
    origin, direction : ndarray, shape (N, 3)
        Ray origins (above the terrain) and directions (pointing down), metres.
    dem : GridDEM
    return_flags : bool
        Also return the per-ray flag (OK, OUTSIDE_DEM, NODATA, NO_INTERSECTION).

    Returns
    -------
    ndarray, shape (N, 3)
        Ground points; NaN rows where the ray leaves the DEM, meets no-data first or misses it.
    flags : ndarray of int8, shape (N,)
        With ``return_flags``.
    """
    points, flags = intersect_rays(origin, direction, dem.height_grid())
    return (points, flags) if return_flags else points
