"""Exact ``%.17g`` text of float64 numbers by the compiled kernel (explorer/float_text.py) and ``residuals.csv``
written by it (explorer.app.export.residuals_csv).

Independent truth: CPython's own ``"%.17g" % v`` (David Gay's correctly rounded dtoa) for every number, and for
the CSV the export's previous pure-Python implementation, kept in the module as its numba-less fallback
(:func:`_reference_csv`; its numbers are CPython's own ``"%.17g" %``, as the tests above take them).
"""

from __future__ import annotations

from decimal import Decimal
from types import SimpleNamespace

import numpy as np
import pytest

from explorer._numba import NUMBA_AVAILABLE
from explorer.app import export
from explorer.app.export import residuals_csv
from explorer.app.model import STATUS_NAMES
from explorer.float_text import MAX_FIELD_BYTES, g17_texts

#: without numba ``g17_texts`` is Python's own formatting: nothing to compare (the CSV tests run either way)
needs_kernel = pytest.mark.skipif(not NUMBA_AVAILABLE, reason="the kernel needs numba (without it: Python's own)")


def _python(values: np.ndarray) -> list[str]:
    return [("%.17g" % v) if np.isfinite(v) else ""  # noqa: UP031 - CPython's %-format is the truth
            for v in np.asarray(values, dtype=np.float64).tolist()]


def _assert_as_python(values) -> None:
    values = np.asarray(values, dtype=np.float64)
    got, want = g17_texts(values), _python(values)
    bad = [(v, g, w) for v, g, w in zip(values.tolist(), got, want, strict=True) if g != w]
    assert not bad, f"{len(bad)} of {values.size} differ from CPython, e.g. (value, kernel, CPython): {bad[:5]}"
    assert max(map(len, got), default=0) <= MAX_FIELD_BYTES


@needs_kernel
def test_random_bit_patterns_over_the_whole_exponent_range():
    """Two million doubles from uniformly random 64-bit patterns: every exponent, sign, subnormals, inf, NaN."""
    bits = np.random.default_rng(20261126).integers(0, 2**64, 2_000_000, dtype=np.uint64, endpoint=False)
    values = bits.view(np.float64)
    assert (~np.isfinite(values)).any() and (np.abs(values[np.isfinite(values)]) < 2.2250738585072014e-308).any()
    _assert_as_python(values)


@needs_kernel
def test_values_near_the_residual_scales():
    rng = np.random.default_rng(5)
    n = 500_000
    _assert_as_python(rng.normal(0, 1, n) * 10.0 ** rng.uniform(-14, 8, n))


@needs_kernel
def test_powers_of_ten_and_two_with_their_neighbours():
    values = []
    for k in range(-324, 309):
        x = float(f"1e{k}")
        values += [x, np.nextafter(x, 0), np.nextafter(x, np.inf)]
    for k in range(-1074, 1024):
        x = 2.0**k
        values += [x, np.nextafter(x, 0), np.nextafter(x, np.inf)]
    v = np.array(values)
    v = v[np.isfinite(v)]
    _assert_as_python(np.concatenate([v, -v]))


@needs_kernel
def test_exact_ties_round_half_to_even():
    """Numbers whose exact decimal value has 18 significant digits ending in 5: a tie at 17 digits, rounded to
    the even 17th digit (both directions occur)."""
    rng = np.random.default_rng(11)
    ties = []
    for p in range(1, 70):
        odd = rng.integers(1, 2**52, 4000) | 1
        for x in (odd.astype(np.float64) * 2.0**-p).tolist():
            digits = Decimal(x).as_tuple().digits  # the exact binary value in decimal
            if len(digits) == 18 and digits[-1] == 5:
                ties.append(x)
    ties_arr = np.array(ties)
    assert ties_arr.size > 1000
    evens = [int(Decimal(x).as_tuple().digits[16]) % 2 == 0 for x in ties]
    assert 0 < sum(evens) < len(evens)  # ties whose 17th digit is even (kept) and odd (rounded up)
    _assert_as_python(np.concatenate([ties_arr, -ties_arr]))


@needs_kernel
def test_special_values_boundaries_and_short_numbers():
    tiny, big = 5e-324, 1.7976931348623157e308
    values = [0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, tiny, -tiny, big, -big, 2.2250738585072014e-308,
              2.225073858507201e-308, 0.1, 0.2, 0.3, 1 / 3, 2 / 3, 0.5, 1.0, 9.5, 10.0, 100.0, 1e15, 1e16, 1e17, 1e18,
              9999999999999998.0, 99999999999999984.0, 1e-4, 9.9999999999999991e-5, 1e-5, 0.00012345, 123456789.0,
              2.0**53, 2.0**53 + 2, 2.0**63, 2.0**64, 1e22, 1e23, 5e-310, 4.9406564584124654e-324]
    values += list(range(-1000, 1001)) + [float(10**k - 1) for k in range(1, 18)] + [float(10**k + 1)
                                                                                      for k in range(1, 16)]
    _assert_as_python(values)
    rng = np.random.default_rng(2)
    few = rng.uniform(-1e4, 1e4, 100_000)
    _assert_as_python(np.concatenate([np.round(few[d::8], d) for d in range(8)]))  # few digits
    _assert_as_python(rng.integers(-(2**62), 2**62, 100_000).astype(np.float64))  # integers
    _assert_as_python(rng.integers(0, 2**52, 100_000, dtype=np.uint64).view(np.float64))  # subnormals


# ------------------------------------------------------------------------------------- residuals.csv
def _reference_csv(evaluations, status, scps, body_fixed=None, native_pixels=False) -> bytes:
    """``residuals_csv`` as it was before the kernel (commit 6c4bba2): the module's numba-less fallback, which is
    that code (Python's own ``%.17g`` / ``%d`` per field; the fallback's checks of its inputs come first)."""
    return export._residuals_csv_python(evaluations, status, scps, body_fixed, native_pixels)


class _Points(SimpleNamespace):
    def __len__(self) -> int:
        return len(self.row)


def test_synthetic_maps_with_nan_residuals_empty_evaluations_and_odd_names():
    rng = np.random.default_rng(0)
    n = 3000
    scps = _Points(row=rng.uniform(-10, 4e4, n), col=rng.uniform(0, 4e4, n))
    scps.row[[3, 9]] = [np.nan, -0.0]
    xyz = rng.normal(0, 6.4e6, (n, 3))
    xyz[5] = [np.inf, np.nan, 0.0]
    evs, status = {}, {}
    for k, name in enumerate(["lrm", "empty", "nr", "stand-in", "odd%name é", "one"]):
        size = {"empty": 0, "one": 1}.get(name, 500 + 400 * k)
        idx = np.sort(rng.choice(n, size, replace=False))
        r = rng.normal(0, 1, size) * 10.0 ** rng.uniform(-13, 4, size)
        c = rng.integers(0, 2**64, size, dtype=np.uint64).view(np.float64)  # any double at all
        r[::7] = np.nan
        c[::11] = -np.inf
        evs[name] = SimpleNamespace(evaluated_index=idx, residual_row=r, residual_col=c)
        status[name] = rng.integers(0, len(STATUS_NAMES), size).astype(np.int8)
    evs["all-nan"] = SimpleNamespace(evaluated_index=np.arange(n)[::-3], residual_row=np.full(1000, np.nan),
                                     residual_col=np.full(1000, np.nan))
    status["all-nan"] = np.full(1000, 1, np.int8)
    for native in (False, True):
        for xyz_or_none in (xyz, None):
            assert residuals_csv(evs, status, scps, xyz_or_none, native) == _reference_csv(
                evs, status, scps, xyz_or_none, native)
    empty = {"a": SimpleNamespace(evaluated_index=np.zeros(0, np.int64), residual_row=np.zeros(0),
                                  residual_col=np.zeros(0))}
    assert residuals_csv(empty, {"a": np.zeros(0, np.int8)}, scps, xyz) == _reference_csv(
        empty, {"a": np.zeros(0, np.int8)}, scps, xyz)
    assert residuals_csv({}, {}, scps, xyz) == _reference_csv({}, {}, scps, xyz)


def test_mismatched_lengths_and_statuses_are_errors():
    scps = _Points(row=np.arange(4.0), col=np.arange(4.0))
    ev = SimpleNamespace(evaluated_index=np.arange(3), residual_row=np.zeros(3), residual_col=np.zeros(2))
    with pytest.raises(ValueError, match="3 evaluated points but 2 column residuals"):
        residuals_csv({"m": ev}, {"m": np.zeros(3, np.int8)}, scps)
    ev.residual_col = np.zeros(3)
    with pytest.raises(IndexError, match="status"):
        residuals_csv({"m": ev}, {"m": np.array([0, 9, 0], np.int8)}, scps)


@pytest.mark.parametrize("source", [["--preset", "WSU", "--methods", "lrm,prm,nr,exact"],
                                    ["--isd", "tests/data/usgscsm/orbitalLineScan.json", "--methods", "lrm,nr"]],
                         ids=["preset", "isd-native-pixels"])
def test_real_exports_write_the_reference_bytes(source, tmp_path, monkeypatch, capsys):
    """The maps a real export writes (the preset; an ISD, whose CSV has the native ``line, sample`` columns),
    captured on their way to ``residuals_csv``: the kernel's bytes are the reference's, and the file is them."""
    from explorer.cli import main

    calls = []
    kernel = export.residuals_csv

    def spy(*args, **kwargs):
        calls.append((args, kwargs))
        return kernel(*args, **kwargs)

    monkeypatch.setattr(export, "residuals_csv", spy)
    out = tmp_path / "e"
    assert main(["explore", *source, "--scops", "50", "--scps", "3000", "--seed", "3", "--no-sweep",
                 "--export", str(out)]) == 0, capsys.readouterr().err
    (args, kwargs), = calls
    native = args[4] if len(args) > 4 else kwargs.get("native_pixels", False)
    assert native == ("--isd" in source)
    reference = _reference_csv(*args, **kwargs)
    assert (out / "residuals.csv").read_bytes() == reference
    assert reference.count(b"\n") > 3000 * 2
