"""Control, check and tie point files of the refinement (CSV).

- Control and check points: columns ``id,lon,lat,h,row,col`` -- geodetic degrees and metres on the body's
  ellipsoid, pixels in the convention of ``docs/conventions.md`` (0-based, integer = pixel centre, as
  rpcm's RPCs).  With several images an ``image`` column names the image of each measurement (its
  position in ``--images``, from 0, or its file name); a point measured in several images has one row
  per image and the same id.
- Tie points: columns ``id,image,row,col`` (ground unknown); a tie point needs rows in two images or more.

Other columns are ignored.  Every fault is an :class:`~explorer.errors.InputError` naming the file, line
and column.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from explorer.errors import InputError
from explorer.io_input import read_csv_table

__all__ = ["PointTable", "read_points_csv"]

CONTROL_COLUMNS = ("id", "lon", "lat", "h", "row", "col")
TIE_COLUMNS = ("id", "image", "row", "col")


@dataclass
class PointTable:
    """Measured image points with optional ground coordinates.

    Attributes
    ----------
    ids : list of str, (N,)
    row, col : ndarray (N,), pixels
    lon, lat, h : ndarray (N,) or None (tie points), degrees, degrees, metres
    image : list of str or None, (N,)
        The ``image`` column as written, when the file has one.
    path : str
    """

    ids: list[str]
    row: np.ndarray
    col: np.ndarray
    lon: np.ndarray | None = None
    lat: np.ndarray | None = None
    h: np.ndarray | None = None
    image: list[str] | None = None
    path: str = "<memory>"

    def __len__(self) -> int:
        return len(self.ids)

    @property
    def has_ground(self) -> bool:
        return self.lon is not None


def read_points_csv(path: str | os.PathLike[str], columns: Sequence[str] = CONTROL_COLUMNS) -> PointTable:
    """Read a control/check (``id,lon,lat,h,row,col``) or tie (``id,image,row,col``) CSV file.

    Raises
    ------
    InputError
        Unreadable file, no rows, a missing column, a value that is not a finite number, a latitude
        beyond 90 degrees, an id repeated within one image.
    """
    name = os.fspath(path)
    # regular file only, any text encoding (a UTF-8 BOM, UTF-16, Latin-1), binary refused, a file cut inside its
    # last value (no final newline) or a row with another number of fields refused: explorer.io_input
    header, body, lines = read_csv_table(name, "CSV of points")
    records = [{k: v.strip() for k, v in zip(header, row, strict=True)} for row in body]
    missing = [c for c in columns if c not in header]
    if missing:
        raise InputError(f"{name}: missing column(s) {', '.join(missing)} (has {', '.join(header)}; "
                         f"expected {','.join(columns)})")
    numbers: dict[str, np.ndarray] = {}
    for c in columns:
        if c in ("id", "image"):
            continue
        values = np.empty(len(records))
        for i, record in enumerate(records):
            text = record[c]
            try:
                values[i] = float(text)
            except ValueError:
                values[i] = np.nan
            if not np.isfinite(values[i]):
                raise InputError(f"{name}: line {lines[i]}, column {c!r}: {text!r} is not a finite number")
        numbers[c] = values
    if "lat" in numbers and (np.abs(numbers["lat"]) > 90.0).any():
        i = int(np.argmax(np.abs(numbers["lat"])))
        raise InputError(f"{name}: line {lines[i]}, column 'lat': {numbers['lat'][i]:g} is beyond 90 degrees")
    ids = [r["id"] for r in records]
    if any(not i for i in ids):
        raise InputError(f"{name}: line {lines[ids.index('')]}: empty id")
    image = [r["image"] for r in records] if "image" in header else None
    keys = list(zip(ids, image or [""] * len(ids), strict=True))
    if len(set(keys)) != len(keys):
        seen: set[tuple[str, str]] = set()
        for i, k in enumerate(keys):
            if k in seen:
                raise InputError(f"{name}: line {lines[i]}: id {k[0]!r} appears twice"
                                 + (f" in image {k[1]!r}" if image else ""))
            seen.add(k)
    return PointTable(ids=ids, row=numbers["row"], col=numbers["col"], lon=numbers.get("lon"),
                      lat=numbers.get("lat"), h=numbers.get("h"), image=image, path=name)
