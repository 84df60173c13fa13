"""``linescan.lagrange_position_from`` (the perspective centre interpolated about each Lagrange window's tangent
line) against the same Lagrange interpolation evaluated in extended precision (long double), on tables of
planetary size."""

from __future__ import annotations

import numpy as np
import pytest

from explorer.real.linescan import Ephemeris, lagrange_interpolate, lagrange_position_from

LD = np.longdouble
pytestmark = pytest.mark.skipif(np.finfo(np.longdouble).eps >= 1e-18, reason="needs an extended-precision long double")

ORIGIN = np.array([5466757.16006709, 212873.06757501, 3267708.52439563])


def _trajectory(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A cubic orbit-like path (ECEF metres, 7,000 km from the centre, 7.5 km/s) and its velocity at times (N,)."""
    c0 = np.array([5447304.949, 277507.888, 4502106.749])
    c1, c2, c3 = np.array([-4521.3, 1520.7, 5813.2]), np.array([-3.1, 0.4, -4.2]), np.array([1.3e-3, -2.1e-4, 9e-4])
    t = t[:, None]
    return c0 + t * (c1 + t * (c2 + t * c3)), c1 + t * (2 * c2 + t * 3 * c3)


def _lagrange_long_double(ts: np.ndarray, values: np.ndarray, t: np.ndarray, order: int) -> np.ndarray:
    """The windowed Lagrange interpolation of :func:`lagrange_interpolate` (same windows) in long double."""
    n = ts.size
    m = min(order, n)
    start = np.clip(np.searchsorted(ts, t) - m // 2, 0, n - m)
    out = np.zeros((t.size, values.shape[1]), dtype=LD)
    tl = t.astype(LD)
    for j in range(m):
        w = np.ones(t.size, dtype=LD)
        for k in range(m):
            if k != j:
                w *= (tl - ts[start + k].astype(LD)) / (ts[start + j].astype(LD) - ts[start + k].astype(LD))
        out += w[:, None] * values[start + j].astype(LD)
    return out


@pytest.mark.parametrize("table, t", [
    (np.arange(-123.85458467, 150.0, 30.0), np.linspace(-1.4, 1.4, 2001)),  # Pleiades-like: 10 samples 30 s apart
    (np.linspace(0.0, 20.0, 41), np.array([-0.3, 0.0, 0.01, 7.77, 19.99, 20.0, 20.5])),  # across windows and ends
])
def test_position_from_equals_long_double_lagrange(table, t):
    pos, vel = _trajectory(table)
    truth = _lagrange_long_double(table, pos, t, 8) - ORIGIN.astype(LD)
    ours = lagrange_position_from(table, pos, vel, t, ORIGIN, order=8)
    plain = lagrange_interpolate(table, pos, t, order=8) - ORIGIN
    err_ours = float(np.max(np.abs(ours.astype(LD) - truth)))
    err_plain = float(np.max(np.abs(plain.astype(LD) - truth)))
    scale = float(np.max(np.abs(truth)))
    assert err_ours < 4 * np.spacing(scale)  # the round-off of the ~1,000 km result, not of 7,000 km positions
    assert err_plain > 2 * err_ours  # what summing ECEF positions costs (why the rigorous residual wobbled)
    fixed, moving = lagrange_position_from(table, pos, vel, t, ORIGIN, order=8, parts=True)
    assert np.array_equal(fixed + moving, ours)
    eph = Ephemeris(table, pos, vel, order=8)
    assert np.array_equal(eph.position_from(t, ORIGIN), ours)


def test_the_fixed_part_is_constant_within_a_window():
    table = np.arange(-123.85458467, 150.0, 30.0)
    pos, vel = _trajectory(table)
    t = np.linspace(-1.4, 1.4, 101)
    fixed, moving = lagrange_position_from(table, pos, vel, t, ORIGIN, order=8, parts=True)
    assert np.all(fixed == fixed[0]) and np.max(np.abs(moving)) < 2e5  # the motion from the window's middle sample
