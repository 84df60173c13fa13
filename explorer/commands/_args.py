"""Argument types of the ``pushbroom`` command line: each checks one value when the arguments are parsed,
before any work starts, and names the problem (argparse turns the message into one line and exit status 2).

Only the standard library is imported here, so building the parser stays fast (``pushbroom --help``).
"""

from __future__ import annotations

import argparse
import math
import os
import stat
from collections.abc import Callable
from pathlib import Path

from explorer.commands import parsed_paths
from explorer.io_atomic import file_kind

__all__ = [
    "add_dem_datum_argument",
    "dem_datum",
    "existing_file",
    "finite_float",
    "float_in_range",
    "height_m",
    "pixel_coordinate",
    "random_seed",
    "int_in_range",
    "latitude",
    "method_list",
    "name_text",
    "longitude",
    "non_negative_float",
    "non_negative_int",
    "output_file",
    "port_number",
    "positive_float",
    "positive_int",
    "raster_file",
]


def finite_float(text: str) -> float:
    """A finite number (no NaN, no infinity)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def float_in_range(low: float, high: float, what: str, unit: str = ""):
    """An argument type for finite numbers in ``[low, high]``; the message names ``what``, the bounds, the unit."""

    def parse(text: str) -> float:
        value = finite_float(text)
        if not low <= value <= high:
            suffix = f" {unit}" if unit else ""
            raise argparse.ArgumentTypeError(f"{what} {text!r} is outside {low:g} .. {high:g}{suffix}")
        return value

    parse.__name__ = f"float_in_range_{low:g}_{high:g}"
    return parse


#: Largest synthetic relief (m), attitude-rate and jitter scale factors: beyond them no satellite images.
MAX_RELIEF_M = 10_000.0
MAX_ATTITUDE_RATE_SCALE = 100.0
MAX_JITTER_SCALE = 1000.0


def latitude(text: str) -> float:
    """A latitude in degrees, -90 .. 90."""
    value = finite_float(text)
    if not -90.0 <= value <= 90.0:
        raise argparse.ArgumentTypeError(f"latitude {text!r} is outside -90 .. 90 degrees")
    return value


def longitude(text: str) -> float:
    """A longitude in degrees, -360 .. 360."""
    value = finite_float(text)
    if not -360.0 <= value <= 360.0:
        raise argparse.ArgumentTypeError(f"longitude {text!r} is outside -360 .. 360 degrees")
    return value


def positive_float(text: str) -> float:
    """A finite number > 0."""
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be > 0")
    return value


def non_negative_float(text: str) -> float:
    """A finite number >= 0."""
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 0")
    return value


def height_m(text: str) -> float:
    """A height above the ellipsoid in metres, -12 km .. 100 km (the deepest trench to the edge of space)."""
    value = finite_float(text)
    if not -12_000.0 <= value <= 100_000.0:
        raise argparse.ArgumentTypeError(f"height {text!r} m is outside -12000 .. 100000 m")
    return value


def pixel_coordinate(text: str) -> float:
    """A row or column in pixels, |value| <= 1e9 (no image is larger)."""
    value = finite_float(text)
    if not abs(value) <= 1e9:
        raise argparse.ArgumentTypeError(f"pixel coordinate {text!r} is outside -1e9 .. 1e9")
    return value


def _integer(text: str) -> int:
    if len(text.strip()) > 30:
        raise argparse.ArgumentTypeError(f"{text[:20]!r}... is not an integer of a sensible size")
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None


#: Largest seed (numpy's generators take any integer, but a seed is written in reports and JSON).
MAX_SEED = 2**32 - 1


def random_seed(text: str) -> int:
    """A random seed, an integer 0 .. 2**32 - 1 (the same range for every command)."""
    value = _integer(text)
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"seed {text!r} must be an integer between 0 and {MAX_SEED}")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1 (and at most 10**9: larger counts are a typo, not a request)."""
    value = _integer(text)
    if not 1 <= value <= 10**9:
        raise argparse.ArgumentTypeError(f"{text!r} must be an integer between 1 and 1e9")
    return value


def non_negative_int(text: str) -> int:
    """An integer >= 0 (at most 10**9)."""
    value = _integer(text)
    if not 0 <= value <= 10**9:
        raise argparse.ArgumentTypeError(f"{text!r} must be an integer between 0 and 1e9")
    return value


def int_in_range(low: int, high: int, what: str = "value"):
    """An argument type for integers in ``[low, high]``; the message names ``what`` and the bounds."""

    def parse(text: str) -> int:
        value = _integer(text)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{what} {text!r} must be between {low} and {high}")
        return value

    parse.__name__ = f"int_in_range_{low}_{high}"
    return parse


def name_text(text: str) -> str:
    """A name (a preset id, a list of them): not empty or blank (an empty value is a mistake, not the default)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("is empty; give a name (or leave the option out for the default)")
    return text.strip()


def method_list(text: str) -> str:
    """A comma-separated list of method names (or ``all``): not empty, no empty item, no odd characters.

    Whether each name is registered is checked by the command (that needs the registry, not loaded here).
    """
    items = [t.strip() for t in text.split(",")]
    if not text.strip() or not any(items):
        raise argparse.ArgumentTypeError("the list of methods is empty; name at least one (or 'all')")
    if any(not t for t in items):
        raise argparse.ArgumentTypeError(f"{text!r} has an empty method name between commas")
    bad = [t for t in items if not all(c.isalnum() or c in "_-" for c in t)]
    if bad:
        raise argparse.ArgumentTypeError(f"{bad[0]!r} is not a method name (letters, digits, '_' and '-')")
    return ",".join(items)


def choice_list(choices: tuple[str, ...] | list[str], what: str) -> Callable[[str], list[str]]:
    """A parser of one comma-separated value of ``choices`` per image (``--model attitude,affine``).

    One token, not ``nargs="+"``: a list option written before the positional SOURCE would otherwise take the
    file name as one more item.
    """
    def parse(text: str) -> list[str]:
        items = [t.strip() for t in text.split(",")]
        if not text.strip() or any(not t for t in items):
            raise argparse.ArgumentTypeError(f"{text!r}: give one {what} or a comma-separated list, no empty item")
        bad = [t for t in items if t not in choices]
        if bad:
            raise argparse.ArgumentTypeError(f"{bad[0]!r} is not a {what} (choose from {', '.join(choices)})")
        return items
    return parse


def positive_float_list(text: str) -> list[float]:
    """A comma-separated list of finite numbers > 0 (``--jitter-hz 0.5,1``)."""
    return [positive_float(t) for t in text.split(",")]


def port_number(text: str) -> int:
    """A TCP port, 0 (pick a free one) to 65535."""
    value = _integer(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"port {text!r} is outside 0..65535")
    return value




def existing_file(text: str) -> str:
    """A path to a readable regular file (a FIFO, a device or a socket is refused without being opened)."""
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"no such file: {text!r}")
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a directory, not a file")
    mode = path.stat().st_mode
    if not stat.S_ISREG(mode):
        raise argparse.ArgumentTypeError(f"{text!r} is {file_kind(mode)}, not a regular file")
    if not os.access(path, os.R_OK):
        raise argparse.ArgumentTypeError(f"{text!r} is not readable")
    parsed_paths.INPUTS.append(text)
    return text


def raster_file(text: str) -> str:
    """A readable raster (GeoTIFF, SRTM .hgt, anything GDAL opens)."""
    existing_file(text)
    if text.lower().endswith(".hgt"):
        return text
    import warnings

    from explorer._lazy import import_rasterio

    rasterio = import_rasterio()  # only when a raster argument is given (without boto3: local files only)
    from rasterio.errors import RasterioError

    try:
        with warnings.catch_warnings():  # a raster without georeferencing: the DEM reader says so, in one line
            warnings.simplefilter("ignore")
            ds = rasterio.open(text)
        with ds:
            if ds.count < 1 or ds.width < 1 or ds.height < 1:
                raise argparse.ArgumentTypeError(f"{text!r} has no raster band")
    except RasterioError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a raster GDAL can read") from None
    return text


#: Words ``--dem-datum`` takes (``geoid`` and ``orthometric`` are EGM96): explorer.terrain_io.DEM_DATUMS.
DEM_DATUM_WORDS = {"ellipsoid": "ellipsoid", "egm96": "egm96", "geoid": "egm96", "orthometric": "egm96"}


def dem_datum(text: str) -> str:
    """``ellipsoid`` or ``egm96`` (``geoid`` is EGM96): the vertical datum of a DEM that declares none."""
    key = text.strip().lower()
    if key not in DEM_DATUM_WORDS:
        raise argparse.ArgumentTypeError(f"{text!r} is not ellipsoid or egm96")
    return DEM_DATUM_WORDS[key]


def add_dem_datum_argument(parser: argparse.ArgumentParser) -> None:
    """``--dem-datum ellipsoid|egm96`` (and the former ``--dem-orthometric``, the same as ``egm96``): the one
    vertical-datum option of every command with ``--dem`` (docs/conventions.md#dem-heights)."""
    parser.add_argument(
        "--dem-datum", type=dem_datum, default=None, metavar="{ellipsoid,egm96}",
        help="what a GeoTIFF DEM's heights are measured from when the file does not declare it (default: its "
             "vertical CRS if it has one, else ellipsoid; an SRTM .hgt is EGM96; EGM96 heights get the geoid "
             "height N added)")
    parser.add_argument("--dem-orthometric", dest="dem_datum", action="store_const", const="egm96",
                        help=argparse.SUPPRESS)


def output_file(text: str) -> str:
    """A path a result file can be written to: not a directory, in an existing writable folder."""
    if not text.strip():
        raise argparse.ArgumentTypeError("output path is empty")
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a directory; give a file name")
    if path.exists() and not stat.S_ISREG(path.stat().st_mode):
        raise argparse.ArgumentTypeError(f"{text!r} is {file_kind(path.stat().st_mode)}, not a regular "
                                         "file; refusing to replace it")
    parent = path.parent
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"the folder of {text!r} does not exist")
    if not os.access(parent, os.W_OK):
        raise argparse.ArgumentTypeError(f"the folder of {text!r} is not writable")
    parsed_paths.OUTPUTS.append(text)
    return text
