"""Compiled per-point passes shared by the methods: image-footprint flags and the inference of the
learned models (polynomial regression, sigmoid MLP) on millions of ground points.

Each pass is one numba ``prange`` loop over blocks of ``BLOCK`` points: a block's normalised
features, their powers or a network layer's activations live in small block buffers (L1/L2
cache), and the inner loops run over the points of the block (vectorised by LLVM).  The same
arithmetic as the numpy / torch paths (feature scaling ``(value - offset) / scale``, powers by
repeated multiplication, logistic sigmoid ``1 / (1 + exp(-a))``), so the results agree with them
to round-off (summation order only).  Without numba (``EXPLORER_DISABLE_NUMBA=1``) the callers keep
their numpy / torch paths; only :func:`inside_flags` has a numpy twin here.

Conventions (pixel centres, the image footprint ``-0.5 <= row <= rows - 0.5``):
``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, njit, prange

BLOCK = 2048  # points per block buffer


@njit(parallel=True, fastmath=False, cache=True)
def _inside_nb(row, col, row_hi, col_hi, mask, out):  # pragma: no cover - compiled
    n = row.shape[0]
    use_mask = mask.shape[0] == n
    for i in prange(n):
        r = row[i]
        c = col[i]
        ok = (r >= -0.5) & (r <= row_hi) & (c >= -0.5) & (c <= col_hi)
        if use_mask:
            ok = ok & mask[i]
        out[i] = ok


def inside_flags(
    row: np.ndarray, col: np.ndarray, n_rows: int, n_columns: int, mask: np.ndarray | None = None
) -> np.ndarray:
    """True where (row, col) lies on the image, pixel edges included (NaN is outside).

    Parameters
    ----------
    row, col : ndarray, shape (N,)
        Fractional image coordinates (0-based pixel centres).
    n_rows, n_columns : int
        Image size.
    mask : ndarray of bool, shape (N,), optional
        Further condition and-ed in (e.g. the training domain of a learned model).

    Returns
    -------
    ndarray of bool, shape (N,)
        Same as :meth:`explorer.scene.Scene.inside_image` (and ``mask``).
    """
    row = np.ascontiguousarray(row, dtype=np.float64)
    col = np.ascontiguousarray(col, dtype=np.float64)
    if not NUMBA_AVAILABLE:
        out = (row >= -0.5) & (row <= n_rows - 0.5) & (col >= -0.5) & (col <= n_columns - 0.5)
        return out if mask is None else out & mask
    out = np.empty(row.shape[0], dtype=np.bool_)
    m = np.zeros(0, dtype=np.bool_) if mask is None else np.ascontiguousarray(mask, dtype=np.bool_)
    _inside_nb(row, col, float(n_rows - 0.5), float(n_columns - 0.5), m, out)
    return out


# ------------------------------------------------------------------------------------ features
@njit(inline="always", fastmath=False, cache=True)
def _block_features(
    ground, s, m, cols, offset, scale, limit, check_height, mean_height, height_tol, feat, ok_out
):  # pragma: no cover - compiled
    """Normalised features of points ``s .. s+m`` into ``feat`` (3, m) and the domain flags."""
    nd = cols.shape[0]
    for k in range(m):
        i = s + k
        good = True
        for d in range(nd):
            v = (ground[i, cols[d]] - offset[d]) / scale[d]
            feat[d, k] = v
            good = good & (abs(v) <= limit)
        for d in range(nd, 3):
            feat[d, k] = 0.0
        if check_height:
            good = good & (abs(ground[i, 2] - mean_height) <= height_tol)
        ok_out[i] = good


@njit(parallel=True, fastmath=False, cache=True)
def _polynomial_nb(
    ground, cols, offset, scale, limit, check_height, mean_height, height_tol, exponents, coef, out, ok_out
):  # pragma: no cover - compiled
    n = ground.shape[0]
    n_terms = exponents.shape[0]
    n_out = coef.shape[1]
    max_deg = 0
    for j in range(n_terms):
        for d in range(3):
            max_deg = max(max_deg, exponents[j, d])
    n_blocks = (n + BLOCK - 1) // BLOCK
    for b in prange(n_blocks):
        s = b * BLOCK
        m = min(n, s + BLOCK) - s
        feat = np.empty((3, m))
        _block_features(ground, s, m, cols, offset, scale, limit, check_height, mean_height, height_tol, feat, ok_out)
        pw = np.empty((3, max_deg + 1, m))
        for d in range(3):
            for k in range(m):
                pw[d, 0, k] = 1.0
            for p in range(1, max_deg + 1):
                for k in range(m):
                    pw[d, p, k] = pw[d, p - 1, k] * feat[d, k] if p > 1 else feat[d, k]
        acc = np.empty(m)
        for o in range(n_out):
            for k in range(m):
                acc[k] = 0.0
            for j in range(n_terms):
                c = coef[j, o]
                e0 = exponents[j, 0]
                e1 = exponents[j, 1]
                e2 = exponents[j, 2]
                for k in range(m):
                    acc[k] += c * (pw[0, e0, k] * pw[1, e1, k] * pw[2, e2, k])
            for k in range(m):
                out[o, s + k] = acc[k]


# exp(x) = 2^n exp(r), n = round(x / ln 2), |r| <= ln(2) / 2, Cody-Waite reduction with ln 2 split in
# two parts and a degree-13 Taylor polynomial (truncation < 2e-17 relative): about 1 ulp, like libm,
# but plain arithmetic, so that LLVM vectorises the loop (libm's exp is a scalar call).
_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_EXP_TAYLOR = tuple(1.0 / float(np.prod(np.arange(1, k + 1))) for k in range(14))  # 1/k!, k = 0..13
_EXP_MAX = 708.0
_EXP_BIAS = 1023.0 + 2.0**52
_EXP_BIAS_BITS = 0x4330000000000000  # float64 bits of 2^52


@njit(inline="always", fastmath=False, cache=True)
def _exp_block(x, m, biased):  # pragma: no cover - compiled
    """``x[:m] = exp(x[:m])`` in place, vectorisable; arguments are clamped to +-708 (no overflow)."""
    c = _EXP_TAYLOR
    for k in range(m):
        v = min(max(x[k], -_EXP_MAX), _EXP_MAX)
        n = np.floor(v * _LOG2E + 0.5)
        r = (v - n * _LN2_HI) - n * _LN2_LO
        p = c[13]
        for j in range(12, -1, -1):  # Horner; constant trip count, unrolled by LLVM
            p = p * r + c[j]
        x[k] = p
        biased[k] = n + _EXP_BIAS  # the integer n + 1023 sits in the low mantissa bits
    ints = biased.view(np.int64)
    for k in range(m):
        ints[k] = (ints[k] - _EXP_BIAS_BITS) << 52  # 2^n as float64 bits (vectorisable integer ops)
    scale = biased.view(np.float64)
    for k in range(m):
        x[k] = x[k] * scale[k]


@njit(parallel=True, fastmath=False, cache=True)
def _mlp_nb(
    ground, cols, offset, scale, limit, check_height, mean_height, height_tol, theta, sizes, t_scale, t_offset,
    out, ok_out,
):  # pragma: no cover - compiled
    n = ground.shape[0]
    n_layers = sizes.shape[0] - 1
    width = 3
    for q in range(sizes.shape[0]):
        width = max(width, sizes[q])
    n_blocks = (n + BLOCK - 1) // BLOCK
    for b in prange(n_blocks):
        s = b * BLOCK
        m = min(n, s + BLOCK) - s
        a = np.empty((width, m))
        h = np.empty((width, m))
        e = np.empty(m)
        biased = np.empty(m)
        _block_features(ground, s, m, cols, offset, scale, limit, check_height, mean_height, height_tol, a, ok_out)
        pos = 0
        for layer in range(n_layers):
            n_in = sizes[layer]
            n_o = sizes[layer + 1]
            bias0 = pos + n_o * n_in
            for o in range(n_o):
                bo = theta[bias0 + o]
                for k in range(m):
                    h[o, k] = 0.0
                for i in range(n_in):
                    w = theta[pos + o * n_in + i]
                    for k in range(m):
                        h[o, k] += a[i, k] * w
                if layer < n_layers - 1:
                    for k in range(m):
                        e[k] = -(h[o, k] + bo)
                    _exp_block(e, m, biased)
                    for k in range(m):
                        h[o, k] = 1.0 / (1.0 + e[k])
                else:
                    for k in range(m):
                        h[o, k] = h[o, k] + bo
            pos = bias0 + n_o
            a, h = h, a
        for k in range(m):
            out[s + k] = a[0, k] * t_scale + t_offset


def _feature_args(features) -> tuple:
    """Positional feature/domain arguments of the kernels from a :class:`GroundFeatures`."""
    sc = features.scaler
    return (
        np.asarray(features.columns, dtype=np.int64),
        np.ascontiguousarray(sc.offset, dtype=np.float64),
        np.ascontiguousarray(sc.scale, dtype=np.float64),
        1.0 + features.domain_margin,
        not features.use_height,
        float(features.mean_height),
        float(features.height_tolerance_m),
    )


def polynomial_predict(features, ground: np.ndarray, exponents: np.ndarray, coef: np.ndarray):
    """Polynomials of the normalised features of ground points, and the training-domain flags.

    Parameters
    ----------
    features : explorer.methods._features.GroundFeatures
        Scaling, feature columns and domain check of the fitted model.
    ground : ndarray, shape (N, 3)
        Local ENU metres.
    exponents : ndarray of int, shape (P, D)
        Monomial exponents of the D features (D <= 3).
    coef : ndarray, shape (P, K)
        Coefficients of K polynomials sharing the monomials.

    Returns
    -------
    values : ndarray, shape (K, N)
    in_domain : ndarray of bool, shape (N,)
    """
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    exp3 = np.zeros((exponents.shape[0], 3), dtype=np.int64)
    exp3[:, : exponents.shape[1]] = exponents
    coef = np.ascontiguousarray(np.asarray(coef, dtype=np.float64).reshape(exponents.shape[0], -1))
    n = ground.shape[0]
    out = np.empty((coef.shape[1], n))
    ok = np.empty(n, dtype=np.bool_)
    _polynomial_nb(ground, *_feature_args(features), exp3, coef, out, ok)
    return out, ok


def mlp_predict(features, ground: np.ndarray, theta: np.ndarray, sizes, target_scale: float, target_offset: float):
    """A sigmoid MLP (:class:`explorer.methods._lm.SigmoidMLP` layout) on the normalised features.

    Parameters
    ----------
    features : explorer.methods._features.GroundFeatures
    ground : ndarray, shape (N, 3)
        Local ENU metres.
    theta : ndarray, shape (P,)
        Flat parameters, layer by layer ``W (out, in)`` row-major then ``b (out,)``.
    sizes : sequence of int
        ``(n_inputs, hidden..., 1)``.
    target_scale, target_offset : float
        ``target = output * target_scale + target_offset``.

    Returns
    -------
    values : ndarray, shape (N,)
    in_domain : ndarray of bool, shape (N,)
    """
    ground = np.ascontiguousarray(ground, dtype=np.float64)
    n = ground.shape[0]
    out = np.empty(n)
    ok = np.empty(n, dtype=np.bool_)
    _mlp_nb(
        ground, *_feature_args(features), np.ascontiguousarray(theta, dtype=np.float64),
        np.asarray(sizes, dtype=np.int64), float(target_scale), float(target_offset), out, ok,
    )
    return out, ok
