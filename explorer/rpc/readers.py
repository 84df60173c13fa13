"""Readers of RPC files into :class:`~explorer.rpc.model.RationalFunctionModel`.

Every reader returns a model in the package's single pixel convention: 0-based rows/columns,
integer = pixel centre (see ``docs/conventions.md`` and the per-format table in ``docs/rpc.md``).
1-based formats (DIMAP v2 ``RPC_*.XML``, DIMAP v1.4 ``PHRDIMAP_*.XML``) have 1 subtracted from
their line/sample offsets at read time, as rpcm and shareloc do.

:func:`read_rpc` chooses the reader from the file's content (magic bytes, XML root element,
key names), not only from its extension.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np

from explorer.errors import InputError, SceneFileError
from explorer.io_input import check_input_file, read_input_text
from explorer.rpc.model import InverseRFM, RationalFunctionModel, ValidityDomain

__all__ = [
    "RPCFormatError",
    "read_dimap_v1",
    "read_dimap_v2",
    "read_dg_rpb",
    "read_dg_xml",
    "read_gdal_vrt",
    "read_ossim_geom",
    "read_rpc",
    "read_rpc00b_text",
    "read_rpc_from_raster",
]

_SCALAR_KEYS = (
    "LINE_OFF", "SAMP_OFF", "LAT_OFF", "LONG_OFF", "HEIGHT_OFF",
    "LINE_SCALE", "SAMP_SCALE", "LAT_SCALE", "LONG_SCALE", "HEIGHT_SCALE",
)  # fmt: skip
_COEFF_KEYS = ("LINE_NUM_COEFF", "LINE_DEN_COEFF", "SAMP_NUM_COEFF", "SAMP_DEN_COEFF")


#: Largest RPC file read (DIMAP v1.4 metadata files are ~1 MB).
MAX_RPC_BYTES = 64 * 1024**2


class RPCFormatError(SceneFileError):
    """A file is not a supported RPC, or is incomplete; the message names the file and the fault."""


def _fail(path: str | Path, what: str) -> RPCFormatError:
    return RPCFormatError(f"{Path(path).name}: {what}")


def _to_float(path: str | Path, key: str, text: str) -> float:
    try:
        return float(text.strip().rstrip(";"))
    except ValueError:
        raise _fail(path, f"{key} is not a number: {text.strip()[:40]!r}") from None


def _to_size(path: str | Path, key: str, text: object) -> int:
    """A positive image dimension (pixels) from a file field, or :class:`RPCFormatError` naming it."""
    value = _to_float(path, key, str(text))
    if not (np.isfinite(value) and 0 < value < 1e9 and value == int(value)):
        raise _fail(path, f"{key} is not a positive whole number of pixels: {str(text).strip()[:40]!r}")
    return int(value)


def _from_dict(
    path: str | Path,
    values: Mapping[str, Any],
    *,
    source_format: str,
    one_based: bool = False,
    **extra: Any,
) -> RationalFunctionModel:
    """Build a model from RPC00B keys (scalars and 20-vectors), checking completeness."""
    for key in _SCALAR_KEYS + _COEFF_KEYS:
        if key not in values:
            raise _fail(path, f"missing {key}")
    scalars = {k: _to_float(path, k, str(values[k])) for k in _SCALAR_KEYS}
    coeffs = {}
    for key in _COEFF_KEYS:
        vec = np.asarray(values[key], dtype=np.float64).reshape(-1)
        if vec.size != 20:
            raise _fail(path, f"{key} has {vec.size} coefficients, expected 20")
        coeffs[key] = vec
    shift = 1.0 if one_based else 0.0
    try:
        return _model(path, coeffs, scalars, shift, source_format, extra)
    except InputError as exc:  # offsets, scales, coefficients or validity box out of range
        raise _fail(path, str(exc)) from None


def _model(path: str | Path, coeffs: dict, scalars: dict, shift: float, source_format: str,
           extra: dict) -> RationalFunctionModel:
    """The model, validated (:meth:`RationalFunctionModel.validate`: :class:`InputError` naming the field)."""
    model = RationalFunctionModel(
        row_num=coeffs["LINE_NUM_COEFF"],
        row_den=coeffs["LINE_DEN_COEFF"],
        col_num=coeffs["SAMP_NUM_COEFF"],
        col_den=coeffs["SAMP_DEN_COEFF"],
        row_offset=scalars["LINE_OFF"] - shift,
        col_offset=scalars["SAMP_OFF"] - shift,
        lat_offset=scalars["LAT_OFF"],
        lon_offset=scalars["LONG_OFF"],
        height_offset=scalars["HEIGHT_OFF"],
        row_scale=scalars["LINE_SCALE"],
        col_scale=scalars["SAMP_SCALE"],
        lat_scale=scalars["LAT_SCALE"],
        lon_scale=scalars["LONG_SCALE"],
        height_scale=scalars["HEIGHT_SCALE"],
        source_format=source_format,
        source_path=str(path),
        **extra,
    )
    return model.validate()


def _collect_indexed(
    path: str | Path, raw: Mapping[str, str], prefix: str, first_index: int, width: int = 0
) -> np.ndarray:
    values = []
    for i in range(first_index, first_index + 20):
        key = f"{prefix}_{i:0{width}d}" if width else f"{prefix}_{i}"
        if key not in raw:
            raise _fail(path, f"missing {key}")
        values.append(_to_float(path, key, raw[key]))
    return np.asarray(values)


def _read_text(path: str | Path) -> str:
    """The file's text (:func:`explorer.io_input.read_input_text`: regular file, BOM / UTF-8 / UTF-16 /
    Latin-1, binary refused), or :class:`RPCFormatError` naming the file."""
    try:
        return read_input_text(path, "RPC file", max_bytes=MAX_RPC_BYTES)
    except SceneFileError as exc:
        raise _fail(path, str(exc).removeprefix(f"{path}: ")) from None


def _key_value_lines(path: str | Path, text: str, pattern: re.Pattern[str], used: Callable[[str], bool],
                     fold_case: bool = False) -> dict[str, str]:
    """``{key: value}`` of the ``key: value`` lines of ``text``, refusing what makes the file ambiguous or cut.

    A key given twice with different values is refused (which one is meant?); so is a file that ends inside
    the value of a key ``used`` by the model without a final newline (a truncated file: ``1.2345E-0`` is a
    number too).
    """
    raw: dict[str, str] = {}
    for line in text.splitlines():
        match = pattern.match(line)
        if not match:
            continue
        key = match.group(1).upper() if fold_case else match.group(1).strip()
        value = match.group(2).strip()
        if key in raw and raw[key].split()[:1] != value.split()[:1] and used(key):
            raise _fail(path, f"{key} is given twice with different values ({raw[key][:30]!r}, {value[:30]!r})")
        raw[key] = value
    tail = text.rstrip("\r\n\t ").splitlines()[-1:] if not text.endswith(("\n", "\r")) else []
    if tail:
        match = pattern.match(tail[0])
        if match and used(match.group(1).upper() if fold_case else match.group(1).strip()):
            raise _fail(path, f"ends inside the value of {match.group(1).strip()} without a final newline: "
                              "the file looks truncated")
    return raw


def _no_21st(path: str | Path, raw: Mapping[str, str], prefix: str, first_index: int, width: int = 0) -> None:
    """Refuse a coefficient past the 20 of an RPC00B polynomial (a 21st term is not RPC00B)."""
    last = first_index + 20
    key = f"{prefix}_{last:0{width}d}" if width else f"{prefix}_{last}"
    if key in raw:
        raise _fail(path, f"has a 21st coefficient {key}: an RPC00B polynomial has exactly 20")


_XML_DECLARATION = re.compile(r"^\s*<\?xml[^>]*\?>", re.S)


def _parse_xml(path: str | Path, root_tag: str, kind: str = "") -> ElementTree.Element:
    """The root element of an XML file, which must be ``<root_tag>`` (``kind`` names the format in the error).

    The text is decoded by :func:`_read_text` (any byte-order mark, UTF-8, UTF-16, Latin-1), so a file whose
    declaration names another encoding than its bytes still reads when its content is valid."""
    text = _XML_DECLARATION.sub("", _read_text(path), count=1)
    try:
        root = ElementTree.fromstring(text)
    except (ElementTree.ParseError, LookupError, ValueError, RecursionError) as exc:
        raise _fail(path, f"is not well-formed XML ({type(exc).__name__}: {str(exc)[:80]})") from None
    if root.tag != root_tag:
        raise _fail(path, f"root element <{root.tag}> is not {kind + ' ' if kind else ''}<{root_tag}>")
    return root


def _xml_node(
    path: str | Path, parent: ElementTree.Element, xpath: str, what: str | None = None
) -> ElementTree.Element:
    """The element at ``xpath`` below ``parent``; the error says ``missing <what>`` (default the path)."""
    node = parent.find(xpath)
    if node is None:
        raise _fail(path, f"missing {what or xpath}")
    return node


# --------------------------------------------------------------------------- text formats
_KEY_VALUE = re.compile(r"^\s*([A-Za-z][A-Za-z0-9_]*)\s*[:=]\s*(.*?)\s*$")


def read_rpc00b_text(path: str | Path) -> RationalFunctionModel:
    """RPC00B key/value text: ``_RPC.TXT``, ``_rpc.txt``, IKONOS, PlanetScope, GDAL ``md_*``.

    Lines ``KEY: value [unit]`` with ``LINE_NUM_COEFF_1`` .. ``SAMP_DEN_COEFF_20`` (or whole
    20-value ``LINE_NUM_COEFF`` lines as GDAL writes in metadata). Extended IKONOS files with
    ``LON_NUM_COEFF_*``/``LAT_NUM_COEFF_*`` also get the image-to-ground functions.
    0-based pixel-centre convention: taken as is.
    """
    raw = _key_value_lines(path, _read_text(path), _KEY_VALUE, _used_rpc00b_key, fold_case=True)
    for key in _COEFF_KEYS + _INVERSE_KEYS:
        _no_21st(path, raw, key, 1)
    values: dict[str, Any] = {}
    for key in _SCALAR_KEYS:
        if key in raw:
            values[key] = raw[key].split()[0] if raw[key].split() else ""
    for key in _COEFF_KEYS:
        if key in raw and len(raw[key].split()) == 20:
            values[key] = [_to_float(path, key, t) for t in raw[key].split()]
        else:
            values[key] = _collect_indexed(
                path, {k: v.split()[0] for k, v in raw.items() if v.split()}, key, 1
            )
    inverse = None
    if "LON_NUM_COEFF_1" in raw:
        flat = {k: v.split()[0] for k, v in raw.items() if v.split()}
        inverse = InverseRFM(
            lon_num=_collect_indexed(path, flat, "LON_NUM_COEFF", 1),
            lon_den=_collect_indexed(path, flat, "LON_DEN_COEFF", 1),
            lat_num=_collect_indexed(path, flat, "LAT_NUM_COEFF", 1),
            lat_den=_collect_indexed(path, flat, "LAT_DEN_COEFF", 1),
        )
    meta = {k: raw[k].split()[0] for k in ("ERR_BIAS", "ERR_RAND") if k in raw and raw[k]}
    return _from_dict(path, values, source_format="rpc00b_txt", inverse=inverse, metadata=meta)


_INVERSE_KEYS = ("LON_NUM_COEFF", "LON_DEN_COEFF", "LAT_NUM_COEFF", "LAT_DEN_COEFF")


def _used_rpc00b_key(key: str) -> bool:
    return key in _SCALAR_KEYS or key.startswith(_COEFF_KEYS + _INVERSE_KEYS)


_RPB_LIST = re.compile(r"(\w+)\s*=\s*\(([^)]*)\)", re.S)
_RPB_SCALAR = re.compile(r"(\w+)\s*=\s*([^;()]+);")
_RPB_NAMES = {
    "lineOffset": "LINE_OFF", "sampOffset": "SAMP_OFF", "latOffset": "LAT_OFF",
    "longOffset": "LONG_OFF", "heightOffset": "HEIGHT_OFF", "lineScale": "LINE_SCALE",
    "sampScale": "SAMP_SCALE", "latScale": "LAT_SCALE", "longScale": "LONG_SCALE",
    "heightScale": "HEIGHT_SCALE", "lineNumCoef": "LINE_NUM_COEFF",
    "lineDenCoef": "LINE_DEN_COEFF", "sampNumCoef": "SAMP_NUM_COEFF",
    "sampDenCoef": "SAMP_DEN_COEFF",
}  # fmt: skip


def read_dg_rpb(path: str | Path) -> RationalFunctionModel:
    """DigitalGlobe/Maxar ``.RPB`` (``key = value;`` groups, coefficient lists in parentheses).

    0-based pixel-centre convention: taken as is.
    """
    text = _read_text(path)
    if "BEGIN_GROUP" not in text:
        raise _fail(path, "no BEGIN_GROUP = IMAGE block: not a DigitalGlobe RPB")
    values: dict[str, Any] = {}
    for name, body in _RPB_LIST.findall(text):
        if name in _RPB_NAMES:
            tokens = [t for t in re.split(r"[\s,]+", body) if t]
            values[_RPB_NAMES[name]] = [_to_float(path, name, t) for t in tokens]
    for name, value in _RPB_SCALAR.findall(text):
        if name in _RPB_NAMES and _RPB_NAMES[name] in _SCALAR_KEYS:
            values[_RPB_NAMES[name]] = value
    missing = [n for n, k in _RPB_NAMES.items() if k not in values]
    if missing:
        raise _fail(path, f"missing {missing[0]} ({_RPB_NAMES[missing[0]]})")
    meta = {}
    for name, value in _RPB_SCALAR.findall(text):
        if name in ("satId", "bandId", "SpecId", "errBias", "errRand"):
            meta[name] = value.strip().strip('"')
    return _from_dict(path, values, source_format="dg_rpb", metadata=meta)


_OSSIM_LINE = re.compile(r"^([^:]+):(.*)$")


def read_ossim_geom(path: str | Path) -> RationalFunctionModel:
    """OSSIM keyword list ``.geom`` (``line_num_coeff_00`` .. ``samp_den_coeff_19``).

    Only ``polynomial_format: B`` (RPC00B order) is accepted. OSSIM RPC models are 0-based
    pixel-centre: taken as is.
    """
    raw = _key_value_lines(path, _read_text(path), _OSSIM_LINE,
                           lambda k: k.upper() in _SCALAR_KEYS or k.upper().startswith(_COEFF_KEYS))
    if "line_num_coeff_00" not in raw and "type" not in raw:
        raise _fail(path, "no OSSIM keyword list with RPC coefficients")
    if "type" not in raw:  # OSSIM writes it with every projection (ossimRpcModel, ossimPleiadesModel, ...)
        raise _fail(path, "missing type (the OSSIM projection type): the keyword list is incomplete or truncated")
    for key in _COEFF_KEYS:
        _no_21st(path, raw, key.lower(), 0, width=2)
    poly_format = raw.get("polynomial_format", "B").strip().upper()
    if poly_format != "B":
        raise _fail(path, f"polynomial_format {poly_format} is not supported (only B, RPC00B)")
    values: dict[str, Any] = {}
    for key in _SCALAR_KEYS:
        if key.lower() not in raw:
            raise _fail(path, f"missing {key.lower()}")
        values[key] = raw[key.lower()]
    for key in _COEFF_KEYS:
        values[key] = _collect_indexed(path, raw, key.lower(), 0, width=2)
    image_size = None
    if "number_lines" in raw and "number_samples" in raw:
        image_size = (_to_size(path, "number_lines", raw["number_lines"]),
                      _to_size(path, "number_samples", raw["number_samples"]))
    meta = {k: raw[k] for k in ("type", "sensor", "image_id") if k in raw}
    return _from_dict(
        path, values, source_format="ossim_geom", image_size=image_size, metadata=meta
    )


# ---------------------------------------------------------------------------- XML formats
def _xml_text(path: str | Path, node: ElementTree.Element | None, tag: str) -> str:
    found = None if node is None else node.find(tag)
    if found is None or found.text is None:
        raise _fail(path, f"missing {tag}")
    return found.text


def _xml_coeffs(
    path: str | Path, node: ElementTree.Element | None, prefix: str
) -> np.ndarray:
    if node is not None and node.find(f"{prefix}_21") is not None:
        raise _fail(path, f"has a 21st coefficient {prefix}_21: an RPC00B polynomial has exactly 20")
    return np.asarray(
        [_to_float(path, f"{prefix}_{i}", _xml_text(path, node, f"{prefix}_{i}")) for i in
         range(1, 21)]
    )


def _dimap_v2_from_root(path: str | Path, root: ElementTree.Element) -> RationalFunctionModel:
    fmt = root.find("Metadata_Identification/METADATA_FORMAT")
    version = (fmt.get("version") if fmt is not None else None) or "2"
    if float(version.split(".")[0]) >= 3:
        raise _fail(path, f"DIMAP v{version} RPC is not supported (only v2)")
    rfm = _xml_node(path, root, "Rational_Function_Model/Global_RFM")
    direct = rfm.find("Direct_Model")  # image -> ground
    inverse = _xml_node(path, rfm, "Inverse_Model", "Inverse_Model (ground-to-image coefficients)")
    validity = _xml_node(path, rfm, "RFM_Validity", "RFM_Validity (offsets and scales)")
    values: dict[str, Any] = {k: _xml_text(path, validity, k) for k in _SCALAR_KEYS}
    for key in _COEFF_KEYS:
        values[key] = _xml_coeffs(path, inverse, key)
    image_to_ground = None
    if direct is not None:
        image_to_ground = InverseRFM(
            lon_num=_xml_coeffs(path, direct, "SAMP_NUM_COEFF"),
            lon_den=_xml_coeffs(path, direct, "SAMP_DEN_COEFF"),
            lat_num=_xml_coeffs(path, direct, "LINE_NUM_COEFF"),
            lat_den=_xml_coeffs(path, direct, "LINE_DEN_COEFF"),
        )
    domain, size = _dimap_validity(path, validity)
    profile = root.find("Metadata_Identification/METADATA_PROFILE")
    meta = {"dimap_version": version, "profile": None if profile is None else profile.text}
    domain, note = _reconcile_ground_domain(path, domain, values)
    if note:
        meta["validity_note"] = note
    return _from_dict(
        path, values, source_format="dimap_v2", one_based=True, inverse=image_to_ground,
        validity=domain, image_size=size, metadata=meta,
    )  # fmt: skip


def _dimap_validity(
    path: str | Path, validity: ElementTree.Element
) -> tuple[ValidityDomain, tuple[int, int] | None]:
    image_dom = validity.find("Direct_Model_Validity_Domain")
    ground_dom = validity.find("Inverse_Model_Validity_Domain")
    kwargs: dict[str, float] = {}
    size = None
    if image_dom is not None:
        first_row = _to_float(path, "FIRST_ROW", _xml_text(path, image_dom, "FIRST_ROW"))
        first_col = _to_float(path, "FIRST_COL", _xml_text(path, image_dom, "FIRST_COL"))
        last_row = _to_float(path, "LAST_ROW", _xml_text(path, image_dom, "LAST_ROW"))
        last_col = _to_float(path, "LAST_COL", _xml_text(path, image_dom, "LAST_COL"))
        kwargs.update(row_min=first_row - 1, row_max=last_row - 1,
                      col_min=first_col - 1, col_max=last_col - 1)  # fmt: skip
        size = (_to_size(path, "LAST_ROW - FIRST_ROW + 1", last_row - first_row + 1),
                _to_size(path, "LAST_COL - FIRST_COL + 1", last_col - first_col + 1))
    if ground_dom is not None:
        kwargs.update(
            lon_min=_to_float(path, "FIRST_LON", _xml_text(path, ground_dom, "FIRST_LON")),
            lat_min=_to_float(path, "FIRST_LAT", _xml_text(path, ground_dom, "FIRST_LAT")),
            lon_max=_to_float(path, "LAST_LON", _xml_text(path, ground_dom, "LAST_LON")),
            lat_max=_to_float(path, "LAST_LAT", _xml_text(path, ground_dom, "LAST_LAT")),
        )
    return ValidityDomain(**kwargs), size


def _reconcile_ground_domain(path: str | Path, domain: ValidityDomain,
                             values: Mapping[str, Any]) -> tuple[ValidityDomain, str | None]:
    """The declared ground validity box, checked against the model's own centre (``LONG_OFF``, ``LAT_OFF``).

    A box that does not contain the centre cannot be the model's domain: every ground point would be
    declared invalid.  Some SPOT 6/7 files (rpcm's ``rpc_SPOT6.xml``) write ``FIRST_LON``/``LAST_LON``
    with latitudes and ``FIRST_LAT``/``LAST_LAT`` with longitudes: when the swapped box contains the
    centre it is read swapped; otherwise the declared box is dropped (the domain is then offset +- scale,
    :attr:`RationalFunctionModel.domain`).  Either way the returned note says what was done.
    """
    declared_bounds = (domain.lon_min, domain.lon_max, domain.lat_min, domain.lat_max)
    if any(b is None for b in declared_bounds):
        return domain, None
    bounds = [float(b) for b in declared_bounds if b is not None]
    lon_off = _to_float(path, "LONG_OFF", str(values["LONG_OFF"]))
    lat_off = _to_float(path, "LAT_OFF", str(values["LAT_OFF"]))
    lon_lo, lon_hi = sorted(bounds[:2])
    lat_lo, lat_hi = sorted(bounds[2:])

    def contains(lo: float, hi: float, v: float) -> bool:
        return lo <= v <= hi

    if contains(lon_lo, lon_hi, lon_off) and contains(lat_lo, lat_hi, lat_off):
        return domain, None
    declared = (f"the declared ground validity box (FIRST_LON/LAST_LON {lon_lo:g}..{lon_hi:g}, FIRST_LAT/"
                f"LAST_LAT {lat_lo:g}..{lat_hi:g}) does not contain the model's centre (LONG_OFF {lon_off:g}, "
                f"LAT_OFF {lat_off:g})")
    if contains(lat_lo, lat_hi, lon_off) and contains(lon_lo, lon_hi, lat_off):
        return replace(domain, lon_min=lat_lo, lon_max=lat_hi, lat_min=lon_lo, lat_max=lon_hi), (
            f"{declared}; its longitudes and latitudes are swapped in the file and are read swapped "
            f"(longitude {lat_lo:g}..{lat_hi:g}, latitude {lon_lo:g}..{lon_hi:g})")
    return replace(domain, lon_min=None, lon_max=None, lat_min=None, lat_max=None), (
        f"{declared}; it is not used (the domain is LONG_OFF/LAT_OFF +- LONG_SCALE/LAT_SCALE)")


def read_dimap_v2(path: str | Path) -> RationalFunctionModel:
    """Pleiades/SPOT 6-7 DIMAP v2 ``RPC_*.XML`` (and rpcm's ``rpc_PLEIADES.xml``/``rpc_SPOT6.xml``).

    ``Inverse_Model`` is ground-to-image (the projection), ``Direct_Model`` image-to-ground
    (kept as :class:`~explorer.rpc.model.InverseRFM`). DIMAP is 1-based: 1 is subtracted from
    ``LINE_OFF``/``SAMP_OFF`` and from the ``FIRST/LAST_ROW/COL`` validity bounds.
    """
    return _dimap_v2_from_root(path, _parse_xml(path, "Dimap_Document", "a DIMAP v2"))


def read_dimap_v1(path: str | Path) -> RationalFunctionModel:
    """Pleiades DIMAP v1.4 ``PHRDIMAP_*.XML``: the ``Geoposition/Rational_Sensor_Model`` block.

    ``F_ROW``/``F_COL`` hold 20 numerator then 20 denominator coefficients (ground-to-image),
    ``F_LON``/``F_LAT`` the image-to-ground ones; ``RFM_Validity/<Axis>/A`` is the scale and
    ``B`` the offset. 1-based like DIMAP v2: 1 is subtracted from the row/col offsets.
    """
    root = _parse_xml(path, "PHR_Dimap_Document")
    rfm = _xml_node(path, root, ".//Rational_Sensor_Model/Global_RFM", "Rational_Sensor_Model/Global_RFM")

    def forty(tag: str, model: str) -> tuple[np.ndarray, np.ndarray]:
        text = _xml_text(path, rfm.find(model), tag)
        tokens = text.split()
        if len(tokens) != 40:
            raise _fail(path, f"{tag} has {len(tokens)} coefficients, expected 40")
        values = np.asarray([_to_float(path, tag, t) for t in tokens])
        return values[:20], values[20:]

    row_num, row_den = forty("F_ROW", "Inverse_Model")
    col_num, col_den = forty("F_COL", "Inverse_Model")
    lon_num, lon_den = forty("F_LON", "Direct_Model")
    lat_num, lat_den = forty("F_LAT", "Direct_Model")
    validity = _xml_node(path, rfm, "RFM_Validity")
    ab = {}
    for axis in ("Lon", "Lat", "Alt", "Col", "Row"):
        node = validity.find(axis)
        ab[axis] = (
            _to_float(path, f"{axis}/A", _xml_text(path, node, "A")),
            _to_float(path, f"{axis}/B", _xml_text(path, node, "B")),
        )
    domain, size = _dimap_validity(path, validity)
    values = {
        "LINE_OFF": ab["Row"][1], "SAMP_OFF": ab["Col"][1], "LAT_OFF": ab["Lat"][1],
        "LONG_OFF": ab["Lon"][1], "HEIGHT_OFF": ab["Alt"][1], "LINE_SCALE": ab["Row"][0],
        "SAMP_SCALE": ab["Col"][0], "LAT_SCALE": ab["Lat"][0], "LONG_SCALE": ab["Lon"][0],
        "HEIGHT_SCALE": ab["Alt"][0], "LINE_NUM_COEFF": row_num, "LINE_DEN_COEFF": row_den,
        "SAMP_NUM_COEFF": col_num, "SAMP_DEN_COEFF": col_den,
    }  # fmt: skip
    profile = root.find("Metadata_Identification/METADATA_PROFILE")
    meta = {"dimap_version": None if profile is None else profile.get("version")}
    return _from_dict(
        path, values, source_format="dimap_v1.4", one_based=True,
        inverse=InverseRFM(lon_num=lon_num, lon_den=lon_den, lat_num=lat_num, lat_den=lat_den),
        validity=domain, image_size=size, metadata=meta,
    )  # fmt: skip


_DG_XML_NAMES = {
    "LINEOFFSET": "LINE_OFF", "SAMPOFFSET": "SAMP_OFF", "LATOFFSET": "LAT_OFF",
    "LONGOFFSET": "LONG_OFF", "HEIGHTOFFSET": "HEIGHT_OFF", "LINESCALE": "LINE_SCALE",
    "SAMPSCALE": "SAMP_SCALE", "LATSCALE": "LAT_SCALE", "LONGSCALE": "LONG_SCALE",
    "HEIGHTSCALE": "HEIGHT_SCALE",
}  # fmt: skip


def read_dg_xml(path: str | Path) -> RationalFunctionModel:
    """DigitalGlobe/Maxar ``.XML`` (``<isd>``): the ``RPB/IMAGE`` block. 0-based pixel centre."""
    root = _parse_xml(path, "isd", "a DigitalGlobe")
    image = _xml_node(path, root, "RPB/IMAGE", "RPB/IMAGE block")
    values: dict[str, Any] = {k: _xml_text(path, image, tag) for tag, k in _DG_XML_NAMES.items()}
    for tag, key in (("LINENUMCOEF", "LINE_NUM_COEFF"), ("LINEDENCOEF", "LINE_DEN_COEFF"),
                     ("SAMPNUMCOEF", "SAMP_NUM_COEFF"), ("SAMPDENCOEF", "SAMP_DEN_COEFF")):
        text = _xml_text(path, image, f"{tag}List/{tag}")
        values[key] = [_to_float(path, tag, t) for t in text.split()]
    size = None
    rows, cols = root.find("IMD/NUMROWS"), root.find("IMD/NUMCOLUMNS")
    if rows is not None and cols is not None and rows.text and cols.text:
        size = (_to_size(path, "IMD/NUMROWS", rows.text), _to_size(path, "IMD/NUMCOLUMNS", cols.text))
    sat = root.find("RPB/SATID")
    meta = {"satId": None if sat is None else sat.text}
    return _from_dict(path, values, source_format="dg_xml", image_size=size, metadata=meta)


def read_gdal_vrt(path: str | Path) -> RationalFunctionModel:
    """GDAL VRT ``<Metadata domain="RPC">`` (``MDI`` keys as in GDAL's RPC metadata domain).

    0-based pixel-centre convention (RPC00B): taken as is. The VRT's raster size is stored in
    ``metadata["raster_size"]`` (it may be a crop of the image the RPC describes).
    """
    root = _parse_xml(path, "VRTDataset")
    domain = next((m for m in root.iter("Metadata") if m.get("domain") == "RPC"), None)
    if domain is None:
        raise _fail(path, 'no <Metadata domain="RPC"> block')
    raw = {mdi.get("key", ""): (mdi.text or "") for mdi in domain.iter("MDI")}
    values: dict[str, Any] = {k: raw[k] for k in _SCALAR_KEYS if k in raw}
    for key in _COEFF_KEYS:
        if key in raw:
            values[key] = [_to_float(path, key, t) for t in raw[key].split()]
    meta = {}
    if root.get("rasterXSize") and root.get("rasterYSize"):
        meta["raster_size"] = (_to_size(path, "rasterYSize", root.get("rasterYSize", 0)),
                               _to_size(path, "rasterXSize", root.get("rasterXSize", 0)))
    return _from_dict(path, values, source_format="gdal_vrt", metadata=meta)


def read_rpc_from_raster(path: str | Path) -> RationalFunctionModel:
    """RPC tags of a raster (GeoTIFF RPC tag, NITF RPC00B TRE, ...) via ``rasterio``'s ``rpcs``.

    GDAL exposes them in the RPC00B 0-based pixel-centre convention: taken as is.
    """
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioIOError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            dataset = rasterio.open(path)
        with dataset:
            rpcs = dataset.rpcs
            size = (dataset.height, dataset.width)
    except RasterioIOError as exc:
        raise _fail(path, f"cannot be opened as a raster ({exc})") from None
    if rpcs is None:
        raise _fail(path, "raster has no RPC metadata")
    d = rpcs.to_dict()
    values = {
        "LINE_OFF": d["line_off"], "SAMP_OFF": d["samp_off"], "LAT_OFF": d["lat_off"],
        "LONG_OFF": d["long_off"], "HEIGHT_OFF": d["height_off"],
        "LINE_SCALE": d["line_scale"], "SAMP_SCALE": d["samp_scale"],
        "LAT_SCALE": d["lat_scale"], "LONG_SCALE": d["long_scale"],
        "HEIGHT_SCALE": d["height_scale"], "LINE_NUM_COEFF": d["line_num_coeff"],
        "LINE_DEN_COEFF": d["line_den_coeff"], "SAMP_NUM_COEFF": d["samp_num_coeff"],
        "SAMP_DEN_COEFF": d["samp_den_coeff"],
    }  # fmt: skip
    meta = {"err_bias": d.get("err_bias"), "err_rand": d.get("err_rand")}
    return _from_dict(path, values, source_format="raster_rpc", image_size=size, metadata=meta)


# ------------------------------------------------------------------------------ dispatch
def detect_format(path: str | Path) -> str:
    """Name of the reader that :func:`read_rpc` would use for ``path`` (from its content).

    Raises
    ------
    RPCFormatError
        If the content is not a supported RPC format.
    """
    path = Path(path)
    try:
        check_input_file(path, "RPC file")  # a FIFO or a device is refused before it is opened
        with open(path, "rb") as handle:
            head = handle.read(4096)
    except SceneFileError as exc:
        raise _fail(path, str(exc).removeprefix(f"{path}: ")) from None
    except OSError as exc:
        raise _fail(path, f"cannot be read ({exc.strerror})") from exc
    if not head:
        raise _fail(path, "is empty")
    if head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+", b"NITF", b"NSIF"):
        return "raster"
    text = _read_text(path)[:4096]
    stripped = text.lstrip(" \t\r\n")
    if stripped.startswith("<"):
        match = re.search(r"<([A-Za-z_][\w.-]*)[\s>/]", re.sub(r"<[?!][^>]*>", "", stripped))
        root = match.group(1) if match else ""
        if root == "Dimap_Document":
            return "dimap_v2"
        if root == "PHR_Dimap_Document":
            return "dimap_v1.4"
        if root == "isd":
            return "dg_xml"
        if root == "VRTDataset":
            if path.suffix.lower() != ".vrt":
                raise _fail(
                    path,
                    "is a GDAL VRT (<VRTDataset>) but not named .vrt; an .xml RPC file must be "
                    "DIMAP or DigitalGlobe XML (as in rpcm). Call read_gdal_vrt() to read it "
                    "deliberately.",
                )
            return "gdal_vrt"
        raise _fail(path, f"XML root <{root or '?'}> is not a supported RPC format")
    if "BEGIN_GROUP" in text or re.search(r"lineNumCoef\s*=", text):
        return "dg_rpb"
    if re.search(r"^\s*(line|samp)_(num|den)_coeff_\d\d\s*:", text, re.M) or re.search(
        r"^\s*(type|polynomial_format|line_off)\s*:", text, re.M
    ):
        return "ossim_geom"
    if re.search(r"^\s*(LINE_OFF|SAMP_OFF|LINE_NUM_COEFF(_1)?)\s*:", text, re.M | re.I):
        return "rpc00b_txt"
    raise _fail(path, "content is not a recognised RPC format")


_READERS: dict[str, Callable[[str | Path], RationalFunctionModel]] = {
    "raster": read_rpc_from_raster,
    "dimap_v2": read_dimap_v2,
    "dimap_v1.4": read_dimap_v1,
    "dg_xml": read_dg_xml,
    "gdal_vrt": read_gdal_vrt,
    "dg_rpb": read_dg_rpb,
    "ossim_geom": read_ossim_geom,
    "rpc00b_txt": read_rpc00b_text,
}


def read_rpc(path: str | Path) -> RationalFunctionModel:
    """Read any supported RPC file, choosing the reader from the content (:func:`detect_format`).

    Returns
    -------
    RationalFunctionModel
        0-based pixel-centre convention whatever the file's convention.

    Raises
    ------
    RPCFormatError
        Unsupported content, a truncated file or a missing coefficient (message names the file
        and the fault, e.g. ``"x_RPC.TXT: missing LINE_NUM_COEFF_12"``).
    """
    reader = _READERS[detect_format(path)]
    try:
        return reader(path)
    except (ValueError, TypeError, KeyError, IndexError, OverflowError, AttributeError) as exc:
        if isinstance(exc, RPCFormatError | InputError):
            raise
        # a malformed field the reader does not check by name: still the file's fault, named
        raise _fail(path, f"malformed {reader.__name__.removeprefix('read_')} content "
                          f"({type(exc).__name__}: {exc})") from None
