"""RPC00B building blocks: the 20-term polynomial and its monomials, the image-to-ground (DIMAP)
functions, the declared validity box, input checks and the limits the model applies.

Split from :mod:`explorer.rpc.model` (which re-exports every name); conventions there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from explorer.errors import InputError
from explorer.rpc import _kernels
from explorer.rpc._kernels import horner_rpc00b

FloatArray = NDArray[np.float64]

#: Human-readable names of the 20 RPC00B monomials, in file order (L = longitude, P = latitude,
#: H = height, all normalised). Same order as NITF RPC00B, GDAL and rpcm.
RPC00B_TERMS: tuple[str, ...] = (
    "1", "L", "P", "H", "LP", "LH", "PH", "L2", "P2", "H2",
    "PLH", "L3", "LP2", "LH2", "L2P", "P3", "PH2", "L2H", "P2H", "H3",
)  # fmt: skip


class HeightSource(Protocol):
    """Anything with a vectorised ``height(lon, lat)`` returning NaN where unknown."""

    def height(self, lon: ArrayLike, lat: ArrayLike) -> FloatArray: ...


def _as_float_array(value: ArrayLike, name: str) -> FloatArray:
    """float64 array of ``value``; :class:`InputError` (a ValueError) naming ``name`` on NaN or infinity."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} is not numeric ({exc})") from None
    if array.size and np.isfinite(np.add.reduce(array, axis=None)):
        return array  # a NaN or an infinity makes the sum non-finite (overflowing sums are checked below)
    if np.isnan(array).any():
        raise InputError(f"{name} contains NaN ({int(np.isnan(array).sum())} value(s))")
    if np.isinf(array).any():
        raise InputError(f"{name} contains infinite values ({int(np.isinf(array).sum())} value(s))")
    return array


#: Points farther than this beyond the normalisation domain (in units of the scale: ``|u| > 1 +
#: VALIDITY_MARGIN`` for any normalised coordinate), or outside the box the file declares widened by
#: the same fraction of the scale, are flagged invalid by ``projection(..., return_valid=True)``,
#: ``localization(..., return_valid=True)`` and :meth:`RationalFunctionModel.ground_validity`.
VALIDITY_MARGIN = 0.1

#: :meth:`RationalFunctionModel.localization` never reports a point converged when its solution lies
#: beyond ``LOCALIZATION_LIMIT`` normalised longitude or latitude units (the polynomials are
#: meaningless there and Newton lands anywhere, e.g. for row -1e6).  Image coordinates are not
#: limited: some vendors (PlanetScope) normalise the ground over a box 9 times the image.
LOCALIZATION_LIMIT = 2.0

#: Normalised RPC00B coefficients are O(1) (numerator terms of a few units, denominators starting
#: with 1); larger magnitudes are corrupt files (overflow in the cubic terms).
MAX_COEFFICIENT = 1e6

# names of the fields in RPC00B files, for messages
_FILE_KEYS = {
    "row_num": "LINE_NUM_COEFF", "row_den": "LINE_DEN_COEFF", "col_num": "SAMP_NUM_COEFF",
    "col_den": "SAMP_DEN_COEFF", "row": "LINE", "col": "SAMP", "lat": "LAT", "lon": "LONG", "height": "HEIGHT",
}  # fmt: skip

# 7 x 7 x 7 nodes of the normalised cube [-1, 1]^3, where the denominators must not vanish
_CUBE = np.stack(np.meshgrid(*(np.linspace(-1.0, 1.0, 7),) * 3, indexing="ij"), axis=0).reshape(3, -1)


def _use_numba(backend: str) -> bool:
    if backend not in ("auto", "numba", "numpy"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'numpy', got {backend!r}")
    if backend == "numba" and not _kernels.NUMBA_AVAILABLE:
        raise RuntimeError("backend='numba' requested but numba is not available")
    return _kernels.NUMBA_AVAILABLE and backend != "numpy"


def evaluate_rpc00b_polynomial(coefficients: ArrayLike, x: FloatArray, y: FloatArray, z: FloatArray) -> FloatArray:
    """Evaluate a cubic RPC00B polynomial with a Horner-like grouping.

    Parameters
    ----------
    coefficients : array_like, shape (20,)
        Coefficients in RPC00B order (see :data:`RPC00B_TERMS`), where ``x`` plays the role of
        ``L`` (normalised longitude), ``y`` of ``P`` (normalised latitude), ``z`` of ``H``.
    x, y, z : ndarray
        Normalised coordinates, broadcastable to a common shape.

    Returns
    -------
    ndarray
        Polynomial values, broadcast shape of ``x, y, z``.
    """
    # the same function is compiled for the numba path of projection (explorer/rpc/_kernels.py)
    return horner_rpc00b(np.asarray(coefficients, dtype=np.float64), x, y, z)


def _rpc00b_polynomial_and_gradient(
    coefficients: FloatArray, x: FloatArray, y: FloatArray, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Value and partial derivatives d/dx, d/dy of an RPC00B polynomial (same conventions)."""
    c = coefficients
    value = evaluate_rpc00b_polynomial(c, x, y, z)
    d_dx = (
        c[1]
        + y * (c[4] + c[10] * z + c[12] * y)
        + z * (c[5] + c[13] * z)
        + 2.0 * x * (c[7] + c[14] * y + c[17] * z)
        + 3.0 * c[11] * x * x
    )
    d_dy = (
        c[2]
        + z * (c[6] + c[16] * z)
        + 2.0 * y * (c[8] + c[18] * z)
        + 3.0 * c[15] * y * y
        + x * (c[4] + c[10] * z + 2.0 * c[12] * y)
        + c[14] * x * x
    )
    return value, d_dx, d_dy


def rpc00b_monomials(x: ArrayLike, y: ArrayLike, z: ArrayLike) -> FloatArray:
    """The 20 RPC00B monomials of normalised coordinates.

    Parameters
    ----------
    x, y, z : array_like, shape (N,)
        Normalised ``L`` (longitude), ``P`` (latitude) and ``H`` (height).

    Returns
    -------
    ndarray, shape (N, 20)
        Column ``k`` is the k-th monomial of :data:`RPC00B_TERMS`.
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    z = np.asarray(z, dtype=np.float64).ravel()
    one = np.ones_like(x)
    return np.stack(
        [
            one, x, y, z, x * y, x * z, y * z, x * x, y * y, z * z,
            x * y * z, x**3, x * y * y, x * z * z, x * x * y, y**3, y * z * z, x * x * z,
            y * y * z, z**3,
        ],
        axis=1,
    )  # fmt: skip


@dataclass(frozen=True)
class InverseRFM:
    """Image-to-ground rational functions (DIMAP "Direct_Model"), RPC00B monomial order.

    The monomials are taken of the normalised column (role of ``L``), normalised row (role of
    ``P``) and normalised height (``H``), as in DIMAP v2 and rpcm. Row/column normalisation uses
    the offsets and scales of the owning :class:`RationalFunctionModel` (0-based centre).
    """

    lon_num: FloatArray
    lon_den: FloatArray
    lat_num: FloatArray
    lat_den: FloatArray


@dataclass(frozen=True)
class ValidityDomain:
    """Box where the model is declared valid (degrees, metres, 0-based pixel-centre rows/cols).

    Any bound may be ``None`` when the source does not give it.
    """

    lon_min: float | None = None
    lon_max: float | None = None
    lat_min: float | None = None
    lat_max: float | None = None
    h_min: float | None = None
    h_max: float | None = None
    row_min: float | None = None
    row_max: float | None = None
    col_min: float | None = None
    col_max: float | None = None
