"""Reading input files safely: the one place every reader gets its bytes, text and JSON from.

The rules (``docs/validation.md``):

- an input is a **regular file**: a FIFO, a device (``/dev/null``, ``/dev/zero``, a terminal), a socket or a
  folder is refused by its kind *before* it is opened, so a reader never blocks on a pipe nor reads forever;
- a text input is at most :data:`MAX_TEXT_BYTES` (real metadata files are kilobytes to a few megabytes);
- text is decoded by its byte-order mark (UTF-8, UTF-16 LE/BE, UTF-32 LE/BE), then as UTF-8, then as
  UTF-16 without a mark when every other byte is NUL, then as Latin-1 (every byte a character, so a
  Windows-1252 or ISO-8859-1 file with valid content reads fine); what still holds NUL bytes or mostly
  control characters is binary and refused;
- JSON is nested at most :data:`MAX_JSON_DEPTH` deep and holds no number literal longer than
  :data:`MAX_NUMBER_DIGITS` characters (a 5,000-digit literal is refused by name, never cast);
- a CSV of points has a header naming its columns (spaces and case ignored) and, in every row, a finite
  number in each needed column within its physical range (:data:`COLUMN_RANGES`: latitudes -90 .. 90,
  longitudes -360 .. 360, heights -12 km .. 100 km, pixel coordinates within +-1e9); the message gives the
  line and the column;
- every file read is noted (:func:`explorer.io_atomic.note_input`) so that the command line never writes an
  output over it.

Every refusal is a :class:`~explorer.errors.SceneFileError` whose message starts with the file name.
"""

from __future__ import annotations

import codecs
import json
import os
import re
import stat
from pathlib import Path
from typing import Any

from explorer.errors import SceneFileError
from explorer.io_atomic import file_kind, note_input
from explorer.memory import check_allocation

__all__ = [
    "COLUMN_RANGES",
    "MAX_JSON_DEPTH",
    "MAX_NUMBER_DIGITS",
    "MAX_TEXT_BYTES",
    "check_input_file",
    "decode_text",
    "file_kind",
    "load_json_file",
    "load_xml_file",
    "loads_json",
    "read_input_bytes",
    "read_csv_table",
    "read_input_text",
    "read_points_csv",
]

#: Largest text input read (bytes): real RPC, ISD, scene and CSV files are far smaller.
MAX_TEXT_BYTES = 512 * 1024**2
#: Deepest JSON nesting accepted (scene files and ISDs are at most ~6 levels deep).
MAX_JSON_DEPTH = 64
#: Longest JSON number literal accepted (a float64 needs at most ~25 characters).
MAX_NUMBER_DIGITS = 100

_BOMS = (
    (codecs.BOM_UTF32_LE, "utf-32-le"),
    (codecs.BOM_UTF32_BE, "utf-32-be"),
    (codecs.BOM_UTF8, "utf-8"),
    (codecs.BOM_UTF16_LE, "utf-16-le"),
    (codecs.BOM_UTF16_BE, "utf-16-be"),
)


def check_input_file(path: str | os.PathLike[str], what: str = "input") -> Path:
    """Check that ``path`` is an existing, readable regular file without opening it.

    Parameters
    ----------
    path : path-like
        The input file.
    what : str
        What the file is for (``"RPC file"``), used in the messages.

    Returns
    -------
    pathlib.Path

    Raises
    ------
    SceneFileError
        Missing, a directory, a FIFO, a device or a socket, or not readable.
    """
    target = Path(path)
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        raise SceneFileError(f"{target}: no such file ({what})") from None
    except OSError as exc:
        raise SceneFileError(f"{target}: cannot be read ({exc.strerror})") from None
    if not stat.S_ISREG(mode):
        raise SceneFileError(f"{target}: is {file_kind(mode)}, not a regular file ({what})")
    if not os.access(target, os.R_OK):
        raise SceneFileError(f"{target}: is not readable (permission denied)")
    note_input(target)  # the command line refuses to write an output over it
    return target


def read_input_bytes(path: str | os.PathLike[str], what: str = "input", max_bytes: int = MAX_TEXT_BYTES) -> bytes:
    """The bytes of a regular input file of at most ``max_bytes`` (:func:`check_input_file` first)."""
    target = check_input_file(path, what)
    try:
        size = target.stat().st_size
        if size > max_bytes:
            raise SceneFileError(f"{target}: {size / 1024**2:.0f} MiB is too large for a {what} "
                                 f"(at most {max_bytes / 1024**2:.0f} MiB)")
        with open(target, "rb") as handle:
            data = handle.read(max_bytes + 1)
    except OSError as exc:
        raise SceneFileError(f"{target}: cannot be read ({exc.strerror})") from None
    if len(data) > max_bytes:
        raise SceneFileError(f"{target}: too large for a {what} (at most {max_bytes / 1024**2:.0f} MiB)")
    return data


def _looks_utf16(data: bytes) -> str | None:
    """``"utf-16-le"``/``"utf-16-be"`` when the bytes look like BOM-less UTF-16 text (ASCII with NUL halves)."""
    if len(data) < 4 or len(data) % 2:
        return None
    sample = data[:4096]
    even, odd = sample[0::2], sample[1::2]
    if odd.count(0) > 0.9 * len(odd) and even.count(0) < 0.1 * len(even):
        return "utf-16-le"
    if even.count(0) > 0.9 * len(even) and odd.count(0) < 0.1 * len(odd):
        return "utf-16-be"
    return None


_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")


def decode_text(data: bytes, path: str | os.PathLike[str], what: str = "input") -> str:
    """Decode the bytes of a text file (BOM, UTF-8, BOM-less UTF-16, Latin-1), refusing binary content.

    Raises
    ------
    SceneFileError
        Empty, undecodable in the encoding its byte-order mark declares, or binary.
    """
    name = str(path)
    if not data.strip():
        raise SceneFileError(f"{name}: is empty ({what})")
    encoding = next((enc for bom, enc in _BOMS if data.startswith(bom)), None)
    if encoding is not None:
        body = data[len(next(b for b, e in _BOMS if e == encoding)):]
        try:
            text = body.decode(encoding)
        except UnicodeDecodeError as exc:
            raise SceneFileError(f"{name}: starts with a {encoding.upper()} byte-order mark but is not "
                                 f"{encoding.upper()} text (byte {exc.start})") from None
    elif (utf16 := _looks_utf16(data)) is not None:  # before UTF-8: NUL bytes are valid UTF-8
        try:
            text = data.decode(utf16)
        except UnicodeDecodeError:
            raise SceneFileError(f"{name}: looks like UTF-16 text without a byte-order mark but is not "
                                 f"valid {utf16.upper()}") from None
    else:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            text = data.decode("latin-1")  # every byte is a character: ISO-8859-1 / Windows-1252 files
    if "\x00" in text or len(_CONTROL.findall(text[:65536])) > 0.05 * min(len(text), 65536):
        raise SceneFileError(f"{name}: is binary, not a text {what}")
    return text


def read_input_text(path: str | os.PathLike[str], what: str = "input", max_bytes: int = MAX_TEXT_BYTES) -> str:
    """The decoded text of a regular input file (:func:`read_input_bytes`, :func:`decode_text`)."""
    return decode_text(read_input_bytes(path, what, max_bytes), path, what)


def _json_depth_exceeds(text: str, limit: int) -> bool:
    """True if brackets nest deeper than ``limit`` outside strings (a linear scan, no recursion)."""
    if text.count("[") + text.count("{") <= limit:
        return False
    depth, in_string, escaped = 0, False, False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            if depth > limit:
                return True
        elif ch in "]}":
            depth -= 1
    return False


class _LongNumber(ValueError):
    pass


def _parse_int(text: str) -> int:
    if len(text) > MAX_NUMBER_DIGITS:
        raise _LongNumber(text)
    return int(text)


def _parse_float(text: str) -> float:
    if len(text) > MAX_NUMBER_DIGITS:
        raise _LongNumber(text)
    return float(text)


def loads_json(text: str, source: str, what: str = "JSON file", parse_constant: Any = None) -> Any:
    """Parse JSON text with the depth and number-length limits; errors name ``source``.

    Parameters
    ----------
    text : str
        The JSON text.
    source : str
        The file name used in messages.
    what : str
        What the file is.
    parse_constant : callable, optional
        Passed to :func:`json.loads` for ``NaN`` / ``Infinity`` (default: Python floats).
    """
    if _json_depth_exceeds(text, MAX_JSON_DEPTH):
        raise SceneFileError(f"{source}: JSON nested deeper than {MAX_JSON_DEPTH} levels (refused as {what})")
    kwargs: dict[str, Any] = {"parse_int": _parse_int, "parse_float": _parse_float}
    if parse_constant is not None:
        kwargs["parse_constant"] = parse_constant
    try:
        return json.loads(text, **kwargs)
    except _LongNumber as exc:
        literal = str(exc)
        raise SceneFileError(f"{source}: a number literal of {len(literal)} characters ({literal[:12]}...) "
                             f"(refused as {what})") from None
    except json.JSONDecodeError as exc:
        raise SceneFileError(f"{source}: not valid JSON ({exc})") from None
    except (RecursionError, ValueError) as exc:
        raise SceneFileError(f"{source}: not valid JSON ({type(exc).__name__})") from None


#: Peak memory per byte of text while parsing it (Python objects of JSON values, lists of CSV fields).
PARSE_BYTES_PER_CHAR = 16


def load_json_file(path: str | os.PathLike[str], what: str = "JSON file", parse_constant: Any = None) -> Any:
    """Read and parse a JSON input file under every rule of this module (see :func:`loads_json`)."""
    text = read_input_text(path, what)
    check_allocation(len(text) * PARSE_BYTES_PER_CHAR, f"{what} {path} ({len(text) / 1024**2:.0f} MiB of text)",
                     "use a smaller file")
    return loads_json(text, str(path), what, parse_constant)


#: Physical range of the point columns a CSV may hold (inclusive), with the unit for the messages.
COLUMN_RANGES: dict[str, tuple[float, float, str]] = {
    "lat": (-90.0, 90.0, "degrees"), "lon": (-360.0, 360.0, "degrees"), "h": (-12_000.0, 100_000.0, "m"),
    "row": (-1e9, 1e9, "px"), "col": (-1e9, 1e9, "px"),
}


def read_points_csv(path: str | os.PathLike[str], columns: tuple[str, ...] | list[str],
                    what: str = "CSV of points") -> tuple[list[dict[str, str]], dict[str, Any]]:
    """The rows of a CSV file of points and its ``columns`` as float64 arrays, checked.

    Parameters
    ----------
    path : path-like
        The CSV file (any encoding :func:`decode_text` reads; a UTF-8 byte-order mark is fine).
    columns : sequence of str
        The columns needed; each value must be a finite number within :data:`COLUMN_RANGES` (when the
        column is listed there).
    what : str
        What the file is, for the messages.

    Returns
    -------
    rows : list of dict
        Every data row, keyed by the (stripped) header names.
    arrays : dict of str to ndarray, shape (N,)
        The needed columns.

    Raises
    ------
    InputError
        Naming the file, and the line and column of the first bad value.
    """
    import numpy as np

    from explorer.errors import InputError

    header, body, lines = read_csv_table(path, what)
    lower = [h.lower() for h in header]
    missing = [c for c in columns if c.lower() not in lower]
    if missing:
        raise InputError(f"{path}: missing column(s) {', '.join(missing)} (has {', '.join(header)})")
    rows = [dict(zip(header, row, strict=True)) for row in body]
    table = [header, *body]
    arrays = {}
    for c in columns:
        k = lower.index(c.lower())
        texts = [row[k].strip() for row in table[1:]]
        try:
            values = np.asarray(texts, dtype=np.float64)
        except (TypeError, ValueError):
            i = next(i for i, t in enumerate(texts) if not _is_float(t))
            raise InputError(f"{path}: line {lines[i]}, column {c!r}: {texts[i][:40]!r} is not a finite "
                             "number") from None
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            i = int(bad[0])
            raise InputError(f"{path}: line {lines[i]}, column {c!r}: {texts[i][:40]!r} is not a finite number")
        if c.lower() in COLUMN_RANGES:
            low, high, unit = COLUMN_RANGES[c.lower()]
            out = np.flatnonzero((values < low) | (values > high))
            if out.size:
                i = int(out[0])
                raise InputError(f"{path}: line {lines[i]}, column {c!r}: {texts[i][:40]} is outside {low:g} .. "
                                 f"{high:g} {unit}")
        arrays[c] = values
    return rows, arrays


def read_csv_table(path: str | os.PathLike[str],
                   what: str = "CSV file") -> tuple[list[str], list[list[str]], list[int]]:
    """A CSV file's header (stripped), data rows and their line numbers, checked to be complete.

    The file must **end in a newline** (CSV writers end the last record with one; a file that does not may
    have been cut inside its last value -- ``123.45`` cut to ``12`` is still a number -- so it is refused,
    naming its last line), must not end inside a quoted field, and every data row has the header's number of
    fields.  Blank lines are skipped; line numbers are the file's own (1 = the header line).

    Raises
    ------
    InputError
        Naming the file and the line.
    """
    import csv
    import io

    from explorer.errors import InputError

    text = read_input_text(path, what)
    check_allocation(len(text) * PARSE_BYTES_PER_CHAR, f"{what} {path} ({len(text) / 1024**2:.0f} MiB of text)",
                     "split it into smaller files")
    if text.strip() and not text.endswith(("\n", "\r")):
        last = len(text.splitlines())
        tail = text.splitlines()[-1][-40:]
        raise InputError(f"{path}: line {last} ({tail!r}) does not end in a newline: the file may be cut inside "
                         "its last value (end it with a newline if it is complete)")
    reader = csv.reader(io.StringIO(text, newline=""), strict=True)
    table: list[list[str]] = []
    lines: list[int] = []
    try:
        for row in reader:
            if any(cell.strip() for cell in row):
                table.append(row)
                lines.append(reader.line_num)
    except csv.Error as exc:
        raise InputError(f"{path}: line {reader.line_num}: malformed CSV ({exc})") from None
    if not table:
        raise InputError(f"{path}: empty CSV (no header)")
    header = [h.strip() for h in table[0]]
    if len(table) < 2:
        raise InputError(f"{path}: no data rows")
    for row, line in zip(table[1:], lines[1:], strict=True):
        if len(row) != len(header):
            raise InputError(f"{path}: line {line} has {len(row)} fields, the header {len(header)}")
    return header, table[1:], lines[1:]


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


_XML_DECLARATION = re.compile(r"^\s*<\?xml[^>]*\?>", re.S)


def load_xml_file(path: str | os.PathLike[str], what: str = "XML file") -> Any:
    """The root element of an XML input file, decoded by :func:`decode_text` (any BOM, UTF-8, UTF-16,
    Latin-1: a declaration naming another encoding than the bytes does not matter) and parsed.

    Raises
    ------
    SceneFileError
        Not a regular file, binary, or not well-formed XML (the message names the file and why).
    """
    from xml.etree import ElementTree

    text = _XML_DECLARATION.sub("", read_input_text(path, what), count=1)
    try:
        return ElementTree.fromstring(text)
    except (ElementTree.ParseError, LookupError, ValueError, RecursionError) as exc:
        raise SceneFileError(f"{path}: is not well-formed XML ({type(exc).__name__}: {str(exc)[:80]})") from None
