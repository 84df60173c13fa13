"""Compiled RPC00B projection: one numba loop per call (ground to image), ``prange`` for large inputs.

The loop fuses, per point, the normalisation of (lon, lat, h), the four cubic polynomials, the two
divisions and the denormalisation, with the *same floating-point operations in the same order* as
the numpy path of :meth:`explorer.rpc.model.RationalFunctionModel.projection`: the polynomial is the
very function :func:`horner_rpc00b` (compiled here, called on arrays by the numpy path), scales are
divided (not multiplied by a reciprocal) and ``fastmath`` is off, so LLVM does not contract to FMA or
reassociate.  The two paths therefore agree bit for bit on the same machine (the tests allow 1e-12 px).

The same pass counts the NaN inputs (a ``prange`` reduction), so the caller can raise the numpy
path's ``ValueError`` without three extra passes over the inputs.

numba missing, or ``EXPLORER_DISABLE_NUMBA=1``: :data:`NUMBA_AVAILABLE` is False and the model uses
its numpy path.
"""

from __future__ import annotations

import math

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, njit, prange, serial_twin


def horner_rpc00b(c, x, y, z):
    """Cubic RPC00B polynomial, Horner-like grouping (``c`` in RPC00B order; x = L, y = P, z = H).

    Valid for scalars (compiled by numba) and for numpy arrays (the numpy path): both backends
    perform the same operations in the same order.
    """
    a0 = (
        c[0]
        + y * (c[2] + z * (c[6] + c[16] * z) + y * (c[8] + c[18] * z + c[15] * y))
        + z * (c[3] + z * (c[9] + c[19] * z))
    )
    a1 = c[1] + y * (c[4] + c[10] * z + c[12] * y) + z * (c[5] + c[13] * z)
    a2 = c[7] + c[14] * y + c[17] * z
    return a0 + x * (a1 + x * (a2 + c[11] * x))


#: Below this many points :func:`project` runs the serial loop.  Measured on the shared 2-core VM while
#: another process kept one core busy: the serial loop does 200,000 points in 1.6 ms (8 ns a point,
#: vectorised), while any ``prange`` call took at least 8 ms (the second thread waits for a scheduler slice);
#: on an idle machine waking the thread costs tens of microseconds.
PARALLEL_MIN_POINTS = 200_000


def _point_py(lo, la, hh, row_num, row_den, col_num, col_den, norm):
    """(row, col) of one ground point: the numpy path's operations, in its order (scalars)."""
    lon_off, lon_scale, lat_off, lat_scale, h_off, h_scale, row_off, row_scale, col_off, col_scale = norm
    x = (lo - lon_off) / lon_scale
    y = (la - lat_off) / lat_scale
    z = (hh - h_off) / h_scale
    row_n = _horner(row_num, x, y, z) / _horner(row_den, x, y, z)
    col_n = _horner(col_num, x, y, z) / _horner(col_den, x, y, z)
    return row_n * row_scale + row_off, col_n * col_scale + col_off


if NUMBA_AVAILABLE:
    _horner = njit(cache=True, fastmath=False, inline="always")(horner_rpc00b)
    _point = njit(cache=True, fastmath=False, inline="always", error_model="numpy")(_point_py)


def _project_loop_py(lon, lat, h, row_num, row_den, col_num, col_den, norm, row_out, col_out):
    """The per-point loop (compiled twice below: ``prange`` parallel, and serial where it is ``range``)."""
    n_lon = 0
    n_lat = 0
    n_h = 0
    for i in prange(lon.shape[0]):
        lo = lon[i]
        la = lat[i]
        hh = h[i]
        n_lon += math.isnan(lo)
        n_lat += math.isnan(la)
        n_h += math.isnan(hh)
        row_out[i], col_out[i] = _point(lo, la, hh, row_num, row_den, col_num, col_den, norm)
    return n_lon, n_lat, n_h


if NUMBA_AVAILABLE:
    # Coefficients (4 x 20) and norm (lon_off, lon_scale, lat_off, lat_scale, h_off, h_scale, row_off,
    # row_scale, col_off, col_scale) are tuples of floats: constants in registers, LLVM vectorises the loop.
    _project_parallel = njit(parallel=True, fastmath=False, cache=True, error_model="numpy")(_project_loop_py)
    _project_serial = njit(parallel=False, fastmath=False, cache=True, error_model="numpy")(
        serial_twin(_project_loop_py))


def project(
    lon: np.ndarray,
    lat: np.ndarray,
    h: np.ndarray,
    coefficients: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    norm: tuple[float, ...],
    parallel: bool | None = None,
) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int]]:
    """Run the compiled loop on 1-D contiguous float64 arrays of one length.

    ``coefficients``: row_num, row_den, col_num, col_den (20 each); ``norm``: lon_offset, lon_scale,
    lat_offset, lat_scale, height_offset, height_scale, row_offset, row_scale, col_offset, col_scale.
    ``parallel``: the ``prange`` loop (True), the serial one (False, same operations, same results), or
    by size (None: parallel from :data:`PARALLEL_MIN_POINTS` points).
    Returns ``row, col`` and the NaN counts of ``lon, lat, h``.
    """
    n = lon.shape[0]
    row = np.empty(n)
    col = np.empty(n)
    tuples = [tuple(float(v) for v in c) for c in coefficients]
    if parallel is None:
        parallel = n >= PARALLEL_MIN_POINTS
    kernel = _project_parallel if parallel else _project_serial
    counts = kernel(lon, lat, h, *tuples, tuple(float(v) for v in norm), row, col)
    return row, col, (int(counts[0]), int(counts[1]), int(counts[2]))


def _and_inside_image_py(row, col, valid, n_rows, n_columns):
    """``valid &= (row, col) on an n_rows x n_columns image, pixel edges included`` in one pass (NaN: outside)."""
    r1 = n_rows - 0.5
    c1 = n_columns - 0.5
    for i in range(row.shape[0]):
        r = row[i]
        c = col[i]
        valid[i] = valid[i] & (r >= -0.5) & (r <= r1) & (c >= -0.5) & (c <= c1)  # branch-free: vectorised


if NUMBA_AVAILABLE:
    _and_inside_image = njit(cache=True, fastmath=False, error_model="numpy")(_and_inside_image_py)


def and_inside_image(row: np.ndarray, col: np.ndarray, valid: np.ndarray, n_rows: int, n_columns: int) -> None:
    """``valid &= explorer.sensor.inside_image(row, col, n_rows, n_columns)`` in place: one compiled pass over 1-D
    float64 ``row``, ``col`` and bool ``valid`` of one length (numpy without numba)."""
    if NUMBA_AVAILABLE and row.ndim == col.ndim == valid.ndim == 1 and row.dtype == col.dtype == np.float64 \
            and valid.dtype == np.bool_ and row.flags.c_contiguous and col.flags.c_contiguous:
        _and_inside_image(row, col, valid, float(n_rows), float(n_columns))
        return
    valid &= (row >= -0.5) & (row <= n_rows - 0.5) & (col >= -0.5) & (col <= n_columns - 0.5)
