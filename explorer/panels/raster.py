"""Residual fields as rasters: check-point residuals aggregated per image cell (numpy only).

A residual map is an image of the residual *field*, not a scatter of points: every point falls in one
cell of a grid laid over the image, and a cell shows an aggregate of the residuals of its points --

* ``"mean"``: the signed mean (a field that is constant by construction maps to that constant in every
  cell that holds a point, whatever the layout of the points);
* ``"max |residual|"``: the signed residual of largest magnitude in the cell (the worst point).

Cells without a point have no value (NaN: drawn transparent and counted in the legend).  The cell grid
follows the check points' own grid when they are one (``PointSet.grid_shape``, as
:func:`explorer.points.simulate_points` makes them): cell edges lie halfway between grid nodes and a
cell holds exactly ``f x f`` nodes (the last row / column of cells fewer), ``f`` the smallest integer
keeping the number of cells at most ``max_cells``.  So no cell is empty because of the drawing and no
stripe or moire comes from cells holding different numbers of points.  Conventions (pixel centres,
row/column): ``docs/conventions.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

AGGREGATES = ("mean", "max |residual|")
"""How a map cell aggregates the residuals of its check points."""
MAX_CELLS = 15_000
"""Default upper bound of the cells of one map (50,000 grid SCPs: 2 x 2 nodes per cell)."""
MAX_FIGURE_CELLS = 150_000
"""Upper bound of the cells of all the maps of one figure: with many maps each gets fewer cells (a coarser
block of grid nodes, the same for every map), so the export's ``panels.html`` stays under 5 MB with every
method checked (14 methods and a stand-in, row and column: 30 maps of at most 5,000 cells)."""


@dataclass(frozen=True)
class CellGrid:
    """Cells over an image: ``row_edges`` (R + 1,) and ``col_edges`` (C + 1,), image pixel coordinates
    (pixel centres at integers, so the image spans -0.5 .. n - 0.5)."""

    row_edges: np.ndarray
    col_edges: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return len(self.row_edges) - 1, len(self.col_edges) - 1

    @property
    def row_centres(self) -> np.ndarray:
        return 0.5 * (self.row_edges[1:] + self.row_edges[:-1])

    @property
    def col_centres(self) -> np.ndarray:
        return 0.5 * (self.col_edges[1:] + self.col_edges[:-1])

    def cell_of(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """Flat cell index (N,) of image points (row-major; points on the image edge go to the edge cell)."""
        nr, nc = self.shape
        i = np.clip(np.searchsorted(self.row_edges, row, side="right") - 1, 0, nr - 1)
        j = np.clip(np.searchsorted(self.col_edges, col, side="right") - 1, 0, nc - 1)
        return i * nc + j


def _edges(n_nodes: int, factor: int, n_pixels: int) -> np.ndarray:
    """Edges of cells holding ``factor`` consecutive nodes of a cell-centred grid of ``n_nodes`` over
    ``n_pixels`` pixels (node k at ``(k + 0.5) n_pixels / n_nodes - 0.5``)."""
    k = np.minimum(np.arange(math.ceil(n_nodes / factor) + 1) * factor, n_nodes)
    return k * (n_pixels / n_nodes) - 0.5


def cell_grid(image_shape: tuple[int, int], n_points: int, grid: tuple[int, int] | None = None,
              max_cells: int = MAX_CELLS) -> CellGrid:
    """The cells of a residual map.

    Parameters
    ----------
    image_shape : (int, int)
        Image rows and columns.
    n_points : int
        Check points to draw (sets the resolution when ``grid`` is not given: about 4 per cell).
    grid : (int, int), optional
        (rows, columns) of the check points' cell-centred grid: cells then hold whole blocks of
        nodes (see the module docstring).
    max_cells : int
        At most this many cells.

    Returns
    -------
    CellGrid
    """
    n_rows, n_cols = int(image_shape[0]), int(image_shape[1])
    if grid is None or grid[0] < 1 or grid[1] < 1:
        n = max(1, int(n_points) // 4)
        gr = max(1, int(round(math.sqrt(n * n_rows / max(n_cols, 1)))))
        gc = max(1, int(round(n / gr)))
    else:
        gr, gc = int(grid[0]), int(grid[1])
    f = 1
    while math.ceil(gr / f) * math.ceil(gc / f) > max_cells:
        f += 1
    return CellGrid(_edges(gr, f, n_rows), _edges(gc, f, n_cols))


@dataclass
class CellField:
    """A residual field aggregated on a :class:`CellGrid`.

    Attributes
    ----------
    value : ndarray (R, C)
        The aggregate (pixels); NaN where the cell holds no valid point.
    count : ndarray of int (R, C)
        Valid points per cell.
    worst_index : ndarray of int (R, C)
        Index (into the caller's point arrays, e.g. the SCP index) of the point of largest |residual| in
        the cell; -1 where there is none.
    """

    grid: CellGrid
    value: np.ndarray
    count: np.ndarray
    worst_index: np.ndarray


def aggregate(grid: CellGrid, row: np.ndarray | None, col: np.ndarray | None, values: np.ndarray,
              index: np.ndarray, how: str = "mean", cell: np.ndarray | None = None) -> CellField:
    """Aggregate residuals at image points per cell (vectorised; NaN values are ignored).

    Parameters
    ----------
    grid : CellGrid
    row, col : ndarray (N,)
        Image position of each point.
    values : ndarray (N,)
        Residuals, pixels.
    index : ndarray of int (N,)
        Each point's index to report as the cell's worst point.
    how : {"mean", "max |residual|"}
    cell : ndarray of int (N,), optional
        ``grid.cell_of(row, col)`` when the caller has it already (``row`` and ``col`` are then not used): the
        maps of one figure share their check points and cells.

    Returns
    -------
    CellField
    """
    if how not in AGGREGATES:
        raise ValueError(f"aggregate must be one of {AGGREGATES}, got {how!r}")
    nr, nc = grid.shape
    v = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(v)
    cell = grid.cell_of(np.asarray(row)[ok], np.asarray(col)[ok]) if cell is None else np.asarray(cell)[ok]
    v, idx = v[ok], np.asarray(index)[ok]
    count = np.bincount(cell, minlength=nr * nc)
    value = np.full(nr * nc, np.nan)
    worst = np.full(nr * nc, -1, dtype=np.int64)
    if v.size:
        pick = _worst_points(cell, np.abs(v), idx, nr * nc)
        worst[cell[pick]] = idx[pick]
        if how == "mean":
            # shifted by the cell's worst value: exact for a constant field (every v - ref is 0) and
            # free of cancellation when the residuals are large and nearly equal
            ref = np.zeros(nr * nc)
            ref[cell[pick]] = v[pick]
            sums = np.bincount(cell, weights=v - ref[cell], minlength=nr * nc)
            has = count > 0
            value[has] = ref[has] + sums[has] / count[has]
        else:
            value[cell[pick]] = v[pick]
    return CellField(grid, value.reshape(nr, nc), count.reshape(nr, nc), worst.reshape(nr, nc))


def _worst_points(cell: np.ndarray, magnitude: np.ndarray, index: np.ndarray, n_cells: int) -> np.ndarray:
    """Position (into the point arrays, (K,) for the K occupied cells in ascending cell order) of each cell's worst
    point: the largest ``magnitude``, among equals the largest ``index``, among those the last point given.

    The ordering of a lexicographic sort by (cell, magnitude, index), taking each cell's last, done with one stable
    sort of the cell numbers (a radix sort of 16-bit numbers below 65,536 cells) and per-cell maxima: a third of the
    cost of that sort of 50,000 points."""
    small = np.uint16 if n_cells <= 1 << 16 else np.int64
    order = np.argsort(cell.astype(small), kind="stable")  # grouped by cell, each cell's points in the given order
    sorted_cell = cell[order]
    starts = np.flatnonzero(np.r_[True, sorted_cell[1:] != sorted_cell[:-1]])
    group = np.repeat(np.arange(starts.size), np.diff(np.r_[starts, sorted_cell.size]))
    mag, idx = magnitude[order], index[order]
    top = mag == np.maximum.reduceat(mag, starts)[group]
    top_index = np.maximum.reduceat(np.where(top, idx, idx.min()), starts)[group]
    return np.maximum.reduceat(np.where(top & (idx == top_index), order, -1), starts)


def occupied(grid: CellGrid, row: np.ndarray | None, col: np.ndarray | None,
             cell: np.ndarray | None = None) -> np.ndarray:
    """Points per cell (R, C) of image points (any status); ``cell``: their ``grid.cell_of(row, col)`` if known."""
    nr, nc = grid.shape
    if cell is None:
        cell = grid.cell_of(np.asarray(row), np.asarray(col))
    return np.bincount(cell, minlength=nr * nc).reshape(nr, nc)


__all__ = ["AGGREGATES", "MAX_CELLS", "MAX_FIGURE_CELLS", "CellField", "CellGrid", "aggregate", "cell_grid", "occupied"]
