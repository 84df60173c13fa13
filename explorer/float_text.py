"""float64 numbers as text bytes, exactly as Python's ``"%.17g" % v`` writes them, in a compiled kernel.

17 significant digits correctly rounded from the number's exact binary value (round half to even on an exact
tie), trailing zeros and a trailing point removed, the exponent form (``1e-05``, ``1.5e+20``) when the decimal
exponent is below -4 or at least 17, ``-0`` for negative zero; a non-finite number is written as nothing (an
empty CSV field).

Exactness: a double is ``m 2^e`` (``m`` < 2^53); its 17 digits are ``floor(m 2^e / 10^s)`` with ``s = k - 16``
and ``k`` its decimal exponent. The kernel computes ``floor(2 m 2^e / 10^s)`` in multi-limb integer
arithmetic (32-bit limbs in uint64: multiplications by ``5^j`` (j <= 13, < 2^32), shifts, and divisions by
``5^j``; ``floor(floor(x/a)/b) = floor(x/(ab))``), keeping a sticky flag for any non-zero remainder: the last
bit of that quotient is the half, the sticky flag tells a tie from a larger remainder. No floating-point
arithmetic decides a digit (``log10`` only guesses ``k``, which the integer result checks and corrects).

Without numba (:data:`explorer._numba.NUMBA_AVAILABLE` false) the callers keep Python's own formatting.
"""

from __future__ import annotations

import math

import numpy as np

from explorer._numba import NUMBA_AVAILABLE, kernel

_MASK32 = np.uint64(0xFFFFFFFF)
_LIMBS = 48  # the largest intermediate (a subnormal's m 5^341) has < 850 bits: 27 limbs
_P10_16 = np.uint64(10**16)
_P10_17 = np.uint64(10**17)
MAX_FIELD_BYTES = 24
"""The longest text of one number (``-2.2250738585072014e-308``: 24 bytes)."""


@kernel()
def _mul_small(a: np.ndarray, n: int, f: np.uint64) -> int:
    """``a[:n] *= f`` (``f`` < 2^32); the new limb count."""
    carry = np.uint64(0)
    for i in range(n):
        t = a[i] * f + carry
        a[i] = t & np.uint64(0xFFFFFFFF)
        carry = t >> np.uint64(32)
    if carry != np.uint64(0):
        a[n] = carry
        n += 1
    return n


@kernel()
def _div_small(a: np.ndarray, n: int, d: np.uint64) -> tuple[int, bool]:
    """``a[:n] //= d`` (``d`` < 2^32); the new limb count and whether the remainder is non-zero."""
    rem = np.uint64(0)
    for i in range(n - 1, -1, -1):
        cur = (rem << np.uint64(32)) | a[i]
        a[i] = cur // d
        rem = cur - a[i] * d
    while n > 0 and a[n - 1] == np.uint64(0):
        n -= 1
    return n, rem != np.uint64(0)


@kernel()
def _shift_left(a: np.ndarray, n: int, s: int) -> int:
    """``a[:n] <<= s`` (s >= 0); the new limb count."""
    words, bits = s // 32, s % 32
    if bits:
        carry = np.uint64(0)
        for i in range(n):
            t = (a[i] << np.uint64(bits)) | carry
            a[i] = t & np.uint64(0xFFFFFFFF)
            carry = t >> np.uint64(32)
        if carry != np.uint64(0):
            a[n] = carry
            n += 1
    if words:
        for i in range(n - 1, -1, -1):
            a[i + words] = a[i]
        for i in range(words):
            a[i] = np.uint64(0)
        n += words
    return n


@kernel()
def _shift_right(a: np.ndarray, n: int, s: int) -> tuple[int, bool]:
    """``a[:n] >>= s`` (s >= 0); the new limb count and whether a non-zero bit was shifted out."""
    words, bits = s // 32, s % 32
    lost = False
    if words >= n:
        for i in range(n):
            if a[i] != np.uint64(0):
                lost = True
            a[i] = np.uint64(0)
        return 0, lost
    for i in range(words):
        if a[i] != np.uint64(0):
            lost = True
    if bits and (a[words] & ((np.uint64(1) << np.uint64(bits)) - np.uint64(1))) != np.uint64(0):
        lost = True
    m = n - words
    for i in range(m):
        lo = a[i + words] >> np.uint64(bits)
        hi = np.uint64(0)
        if bits and i + words + 1 < n:
            hi = (a[i + words + 1] << np.uint64(32 - bits)) & np.uint64(0xFFFFFFFF)
        a[i] = lo | hi
    for i in range(m, n):
        a[i] = np.uint64(0)
    while m > 0 and a[m - 1] == np.uint64(0):
        m -= 1
    return m, lost


@kernel()
def _digits17(m: np.uint64, e: int, k: int, a: np.ndarray) -> tuple[np.uint64, int]:
    """The 17 significant digits (an integer in [10^16, 10^17)) of ``m 2^e`` > 0, correctly rounded (half to
    even), and its decimal exponent; ``k`` is a guess of the exponent (off by at most a few), ``a`` scratch
    limbs."""
    while True:  # no clearing: every operation reads only the limbs below its count, which it has written
        a[0] = m & np.uint64(0xFFFFFFFF)
        a[1] = m >> np.uint64(32)
        n = 2 if a[1] != np.uint64(0) else 1
        s = k - 16
        t = -s
        while t >= 13:
            n = _mul_small(a, n, np.uint64(1220703125))
            t -= 13
        if t > 0:
            n = _mul_small(a, n, np.uint64(5 ** t))
        sh = e - s + 1  # + 1: the quotient's last bit is the half
        if sh > 0:
            n = _shift_left(a, n, sh)
        sticky = False
        t = s
        while t >= 13:
            n, r = _div_small(a, n, np.uint64(1220703125))
            sticky = sticky or r
            t -= 13
        if t > 0:
            n, r = _div_small(a, n, np.uint64(5 ** t))
            sticky = sticky or r
        if sh < 0:
            n, r = _shift_right(a, n, -sh)
            sticky = sticky or r
        if n > 2:
            k += 1
            continue
        q2 = a[0] | (a[1] << np.uint64(32))
        q = q2 >> np.uint64(1)
        if q >= _P10_17:
            k += 1
            continue
        if q < _P10_16:
            k -= 1
            continue
        if (q2 & np.uint64(1)) and (sticky or (q & np.uint64(1))):
            q += np.uint64(1)
            if q == _P10_17:
                q = _P10_16
                k += 1
        return q, k


@kernel()
def write_g17(out: np.ndarray, pos: int, v: float, a: np.ndarray, d: np.ndarray) -> int:
    """Write ``"%.17g" % v`` (nothing for a non-finite ``v``) into ``out`` at ``pos``; the position after it.

    ``a`` (uint64, >= 48) and ``d`` (uint8, >= 17) are scratch.
    """
    if not math.isfinite(v):
        return pos
    if math.copysign(1.0, v) < 0.0:
        out[pos] = 45  # -
        pos += 1
        v = -v
    if v == 0.0:
        out[pos] = 48
        return pos + 1
    mant, ex = math.frexp(v)  # v = mant 2^ex, 0.5 <= mant < 1 (also a subnormal: mant 2^53 is an integer)
    m = np.uint64(math.ldexp(mant, 53))
    e = ex - 53
    q, k = _digits17(m, e, int(math.floor(math.log10(v))), a)
    hi, lo = q // np.uint64(100000000), q % np.uint64(100000000)  # 9 and 8 digits: 32-bit divisions
    lo32, hi32 = np.uint32(lo), np.uint32(hi)
    for i in range(16, 8, -1):
        d[i] = np.uint8(lo32 % np.uint32(10))
        lo32 //= np.uint32(10)
    for i in range(8, -1, -1):
        d[i] = np.uint8(hi32 % np.uint32(10))
        hi32 //= np.uint32(10)
    nd = 17
    while nd > 1 and d[nd - 1] == 0:
        nd -= 1
    if -4 <= k < 17:
        if k >= 0:
            for i in range(k + 1):
                out[pos] = 48 + d[i]
                pos += 1
            if nd > k + 1:
                out[pos] = 46  # .
                pos += 1
                for i in range(k + 1, nd):
                    out[pos] = 48 + d[i]
                    pos += 1
        else:
            out[pos] = 48
            out[pos + 1] = 46
            pos += 2
            for _ in range(-k - 1):
                out[pos] = 48
                pos += 1
            for i in range(nd):
                out[pos] = 48 + d[i]
                pos += 1
        return pos
    out[pos] = 48 + d[0]
    pos += 1
    if nd > 1:
        out[pos] = 46
        pos += 1
        for i in range(1, nd):
            out[pos] = 48 + d[i]
            pos += 1
    out[pos] = 101  # e
    out[pos + 1] = 45 if k < 0 else 43
    pos += 2
    x = -k if k < 0 else k
    if x >= 100:
        out[pos] = 48 + x // 100
        pos += 1
    out[pos] = 48 + (x // 10) % 10
    out[pos + 1] = 48 + x % 10
    return pos + 2


@kernel()
def write_int(out: np.ndarray, pos: int, v: int, d: np.ndarray) -> int:
    """Write ``"%d" % v`` into ``out`` at ``pos``; the position after it. ``d`` (uint8, >= 20) is scratch."""
    if v < 0:
        out[pos] = 45
        pos += 1
        u = np.uint64(-(v + 1)) + np.uint64(1)  # also the most negative int64
    else:
        u = np.uint64(v)
    nd = 0
    while True:
        d[nd] = np.uint8(u % np.uint64(10))
        u //= np.uint64(10)
        nd += 1
        if u == np.uint64(0):
            break
    for i in range(nd - 1, -1, -1):
        out[pos] = 48 + d[i]
        pos += 1
    return pos


@kernel()
def _g17_array(values: np.ndarray, out: np.ndarray, ends: np.ndarray) -> None:
    a = np.zeros(_LIMBS, np.uint64)
    d = np.zeros(24, np.uint8)
    pos = 0
    for i in range(values.size):
        pos = write_g17(out, pos, values[i], a, d)
        ends[i] = pos


@kernel()
def csv_lines(out: np.ndarray, pos: int, shared: np.ndarray, n_head: int, prefixes: np.ndarray,
              prefix_ends: np.ndarray, line_ends: np.ndarray, index: np.ndarray, point: np.ndarray,
              first: np.ndarray, second: np.ndarray, label: np.ndarray, labels: np.ndarray,
              label_ends: np.ndarray) -> int:
    """Write CSV lines into ``out`` from ``pos``; the position after the last one.

    Line ``j`` of group ``g`` (``line_ends[g-1] <= j < line_ends[g]``) is ``prefixes[g] index[j] "," head
    "," first[j] "," second[j] labels[label[j]] tail "\n"``, where ``head`` is the point ``p = point[j]``'s
    first ``n_head`` shared numbers joined by ``","`` and ``tail`` the rest of ``shared[p]``; numbers as
    ``"%.17g"`` (:func:`write_g17`), the index as ``"%d"``. The shared numbers are formatted once per point.
    ``prefixes`` / ``labels`` are the concatenated byte strings, ``prefix_ends`` / ``label_ends`` where each ends.
    ``out`` must be large enough (:data:`MAX_FIELD_BYTES` per number).
    """
    a = np.zeros(_LIMBS, np.uint64)
    d = np.zeros(24, np.uint8)
    n_points, n_cols = shared.shape
    text = np.empty(n_points * n_cols * (MAX_FIELD_BYTES + 1) + 1, np.uint8)
    head_end = np.empty(n_points, np.int64)
    tail_end = np.empty(n_points, np.int64)
    at = 0
    for p in range(n_points):
        for c in range(n_cols):
            if c == n_head:
                head_end[p] = at
            elif c > 0:
                text[at] = 44
                at += 1
            at = write_g17(text, at, shared[p, c], a, d)
        if n_head >= n_cols:
            head_end[p] = at
        tail_end[p] = at
    start = 0
    for g in range(line_ends.size):
        p0 = prefix_ends[g - 1] if g > 0 else 0
        p1 = prefix_ends[g]
        for j in range(start, line_ends[g]):
            for i in range(p0, p1):
                out[pos] = prefixes[i]
                pos += 1
            pos = write_int(out, pos, index[j], d)
            out[pos] = 44
            pos += 1
            q = point[j]
            h0 = tail_end[q - 1] if q > 0 else 0
            for i in range(h0, head_end[q]):
                out[pos] = text[i]
                pos += 1
            out[pos] = 44
            pos = write_g17(out, pos + 1, first[j], a, d)
            out[pos] = 44
            pos = write_g17(out, pos + 1, second[j], a, d)
            s = label[j]
            for i in range(label_ends[s - 1] if s > 0 else 0, label_ends[s]):
                out[pos] = labels[i]
                pos += 1
            for i in range(head_end[q], tail_end[q]):
                out[pos] = text[i]
                pos += 1
            out[pos] = 10
            pos += 1
        start = line_ends[g]
    return pos


def g17_texts(values: np.ndarray) -> list[str]:
    """``["%.17g" % v for v in values]`` (``""`` for a non-finite number) by the compiled kernel.

    Parameters
    ----------
    values : (N,) float64

    Returns
    -------
    list of str
        One text per number.
    """
    if not NUMBA_AVAILABLE:
        return [("%.17g" % v) if np.isfinite(v) else ""  # noqa: UP031 - the format this module reproduces
                for v in np.asarray(values, dtype=np.float64).tolist()]
    v = np.ascontiguousarray(values, dtype=np.float64).ravel()
    out = np.empty(v.size * MAX_FIELD_BYTES, np.uint8)
    ends = np.empty(v.size, np.int64)
    _g17_array(v, out, ends)
    text = out[: int(ends[-1]) if v.size else 0].tobytes().decode("ascii")
    starts = np.concatenate([[0], ends[:-1]]).tolist() if v.size else []
    return [text[s:e] for s, e in zip(starts, ends.tolist(), strict=True)]


__all__ = ["MAX_FIELD_BYTES", "csv_lines", "g17_texts", "write_g17", "write_int"]
