"""UTC time stamps of satellite metadata as ``numpy.datetime64[ns]`` (no leap-second logic).

Metadata times (``2017-05-25T13:37:39.990313Z``, up to 7+ fractional digits) are parsed to
nanoseconds; differences between two stamps of the same time system are exact to 1 ns.  TAI
stamps differ from UTC by ``TAI_UTC`` seconds (37 s since 2017), which the readers state when
they mix systems.  Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["parse_utc", "seconds_between"]


def parse_utc(text: str) -> np.datetime64:
    """Parse an ISO 8601 time (optional trailing ``Z``, any number of fractional digits).

    Fractions beyond nanoseconds are rounded to the nanosecond.
    """
    s = text.strip().rstrip("Z").replace(" ", "T")
    if "." in s:
        head, frac = s.split(".", 1)
        digits = "".join(ch for ch in frac if ch.isdigit())
        ns = int(round(float("0." + digits) * 1e9)) if digits else 0
        return np.datetime64(head, "ns") + np.timedelta64(ns, "ns")
    return np.datetime64(s, "ns")


def seconds_between(start: np.datetime64, end: np.datetime64) -> float:
    """``end - start`` in seconds (float)."""
    return float((end - start) / np.timedelta64(1, "ns")) * 1e-9
