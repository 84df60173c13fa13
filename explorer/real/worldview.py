"""DigitalGlobe/Maxar (WorldView, QuickBird, GeoEye) XML metadata -> rigorous line-scan scene.

Beyond the papers: the ``<isd>`` XML of a Basic 1B product holds the rigorous model from
which the vendor RPC (``<RPB>``, same file) was fitted:

* ``EPH``: ``EPHEMLIST`` = index, X, Y, Z (ECEF m), VX, VY, VZ (m/s), covariances; sample
  ``i`` (1-based index) at ``STARTTIME + (i - 1) * TIMEINTERVAL`` (UTC);
* ``ATT``: ``ATTLIST`` = index, q1, q2, q3, q4 (q4 scalar), covariances: rotation of the
  body (camera) frame into ECEF, same sampling rule;
* ``GEO``: ``PRINCIPAL_DISTANCE/PD`` (mm), ``DETECTOR_MOUNTING/.../DETECTOR_ARRAY``:
  ``DETORIGINX``, ``DETORIGINY`` (mm), ``DETROTANGLE`` (rad), ``DETPITCH`` (mm);
  ``CAMERA_ATTITUDE`` (QCS1..QCS4, q4 scalar: camera -> body), ``PERSPECTIVE_CENTER``
  (CX, CY, CZ), ``OPTICAL_DISTORTION`` (``POLYORDER -1``: none);
* ``IMD/IMAGE``: ``FIRSTLINETIME``, ``AVGLINERATE`` (lines/s), ``TLCTIME`` + ``TLCLIST``
  (line, seconds) pairs, ``NUMROWS``/``NUMCOLUMNS`` in ``IMD``.

Camera geometry (the convention of NASA Ames Stereo Pipeline's DG model): detector column
``c`` (0-based, pixel centre) looks along ``A (c pitch, 0, 0) + (DETORIGINX, DETORIGINY, 0) +
(0, 0, PD)`` in the camera frame, with ``A`` the rotation by ``DETROTANGLE - 90 deg`` about z
(so with a zero angle the column runs along ``-y``); the camera looks along ``+z``.  In the
package's sensor frame (``docs/conventions.md#frames``): ``y`` along increasing columns,
``z = -z_camera``, ``x = y cross z``; the detector line sits at
``x = DETORIGIN . x_s`` (``along_track_offset_m``) and the principal column is
``-(DETORIGIN . y_s) / pitch``.  Scanline time: ``FIRSTLINETIME + row / AVGLINERATE``
(the TLC list, a single rate, when the file has one, as in ASP).  Results vs the RPC: ``docs/real_images.md``.
"""

from __future__ import annotations

from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from explorer.errors import InputError
from explorer.geometry.exterior import LineTiming
from explorer.geometry.frames import LocalFrame, ecef_to_geodetic
from explorer.geometry.interior import InteriorOrientation
from explorer.geometry.terrain import FlatTerrain
from explorer.io_input import load_xml_file
from explorer.real.linescan import (
    AttitudeTable,
    Ephemeris,
    LineScanExterior,
    RigorousLineScanScene,
    quaternion_to_matrix,
)
from explorer.real.timeutil import parse_utc, seconds_between

__all__ = ["DGMetadata", "read_dg_metadata", "rigorous_scene_from_dg"]


class DGMetadata(dict):
    """Parsed DigitalGlobe XML fields (a dict; keys documented in :func:`read_dg_metadata`)."""


def _text(node: ElementTree.Element | None, tag: str, path: str) -> str:
    if node is None:
        raise InputError(f"{Path(path).name}: missing element for {tag}")
    e = node.find(tag)
    if e is None or e.text is None:
        raise InputError(f"{Path(path).name}: missing {tag}")
    return e.text.strip()


def _child(node: ElementTree.Element, tag: str, path: str) -> ElementTree.Element:
    """``node.find(tag)``; :class:`InputError` naming the file and the tag when it is missing."""
    e = node.find(tag)
    if e is None:
        raise InputError(f"{Path(path).name}: missing {tag}")
    return e


def _list(node: ElementTree.Element, list_tag: str, item: str) -> np.ndarray:
    rows = [[float(v) for v in e.text.split()] for e in node.iter(item) if e.text]
    if not rows:
        raise InputError(f"empty {list_tag}")
    return np.asarray(rows, dtype=np.float64)


def read_dg_metadata(path: str | Path) -> DGMetadata:
    """Read the rigorous-model fields of a DigitalGlobe ``<isd>`` XML.

    Returns
    -------
    DGMetadata
        ``sat_id``, ``rows``, ``columns``, ``first_line_time`` (str), ``line_rate`` (lines/s),
        ``tlc_time`` (str), ``tlc`` ((K, 2) line, seconds), ``scan_direction``,
        ``eph_start`` (str), ``eph_interval`` (s), ``eph`` ((N, 7): index, X, Y, Z, VX, VY, VZ),
        ``att_start``, ``att_interval``, ``att`` ((N, 5): index, q1..q4),
        ``pd_mm``, ``det_origin_mm`` (2,), ``det_rot_rad``, ``det_pitch_mm``,
        ``camera_quaternion`` (q1..q4), ``perspective_center`` (3,), ``distortion_order``.
    """
    path = Path(path)
    root = load_xml_file(path, "DigitalGlobe XML")  # regular file, any text encoding (explorer.io_input)
    missing = [t for t in ("IMD", "EPH", "ATT", "GEO") if root.find(t) is None]
    if missing:
        raise InputError(f"{path.name}: no rigorous model (missing {', '.join(missing)}); use the RPC instead")
    p = str(path)
    imd, eph, att, geo = (_child(root, t, p) for t in ("IMD", "EPH", "ATT", "GEO"))
    image = _child(imd, "IMAGE", p)
    md = DGMetadata()
    md["sat_id"] = _text(image, "SATID", p)
    md["rows"] = int(_text(imd, "NUMROWS", p))
    md["columns"] = int(_text(imd, "NUMCOLUMNS", p))
    md["first_line_time"] = _text(image, "FIRSTLINETIME", p)
    md["line_rate"] = float(_text(image, "AVGLINERATE", p))
    md["scan_direction"] = _text(image, "SCANDIRECTION", p) if image.find("SCANDIRECTION") is not None else "Forward"
    md["tlc_time"] = _text(image, "TLCTIME", p) if image.find("TLCTIME") is not None else md["first_line_time"]
    tlc_list = image.find("TLCLISTList")
    md["tlc"] = _list(tlc_list, "TLCLISTList", "TLCLIST") if tlc_list is not None else np.zeros((0, 2))
    md["eph_start"] = _text(eph, "STARTTIME", p)
    md["eph_interval"] = float(_text(eph, "TIMEINTERVAL", p))
    md["eph"] = _list(eph, "EPHEMLISTList", "EPHEMLIST")[:, :7]
    md["att_start"] = _text(att, "STARTTIME", p)
    md["att_interval"] = float(_text(att, "TIMEINTERVAL", p))
    md["att"] = _list(att, "ATTLISTList", "ATTLIST")[:, :5]
    from explorer.scene_checks import check_orbit_tables

    check_orbit_tables(path.name, md["eph"][:, 1:4], md["att"][:, 1:5])  # above the ground, unit quaternions
    md["pd_mm"] = float(_text(_child(geo, "PRINCIPAL_DISTANCE", p), "PD", p))
    array = _child(geo, ".//DETECTOR_ARRAY", p)
    md["det_origin_mm"] = np.array([float(_text(array, "DETORIGINX", p)), float(_text(array, "DETORIGINY", p))])
    md["det_rot_rad"] = float(_text(array, "DETROTANGLE", p))
    md["det_pitch_mm"] = float(_text(array, "DETPITCH", p))
    cam = _child(geo, "CAMERA_ATTITUDE", p)
    md["camera_quaternion"] = np.array([float(_text(cam, f"QCS{i}", p)) for i in range(1, 5)])
    pcn = _child(geo, "PERSPECTIVE_CENTER", p)
    md["perspective_center"] = np.array([float(_text(pcn, f"C{a}", p)) for a in "XYZ"])
    dist = geo.find("OPTICAL_DISTORTION")
    md["distortion_order"] = int(_text(dist, "POLYORDER", p)) if dist is not None else -1
    return md


def _camera_frame(det_rot: float) -> np.ndarray:
    """Sensor -> camera rotation (3, 3): columns are the package's x, y, z axes in camera axes."""
    a = det_rot - np.pi / 2.0
    y_s = np.array([np.cos(a), np.sin(a), 0.0])  # direction of increasing columns
    z_s = np.array([0.0, 0.0, -1.0])
    x_s = np.cross(y_s, z_s)
    return np.stack([x_s, y_s, z_s], axis=1)


def rigorous_scene_from_dg(
    path: str | Path,
    *,
    aberration: bool = True,
    refraction: bool = True,
    attitude_method: str = "lagrange",
    name: str | None = None,
) -> RigorousLineScanScene:
    """Rigorous line-scan scene from a DigitalGlobe XML with EPH, ATT, GEO and IMD.

    The local ENU frame sits at the image centre localised by the file's RPC at its height
    offset (or at the intersection of the central line of sight with the ellipsoid when the
    file has no RPC).  The vendor RPC is attached as ``scene.rpc`` for comparisons.

    Parameters
    ----------
    path : str or Path
    aberration, refraction : bool
        Corrections of the line of sight (``explorer.real.linescan``); both on by default:
        against the WV1 RPC, without aberration the rows are off by 25 px, without refraction
        the columns by 2 px (``docs/real_images.md``).
    attitude_method : {"lagrange", "slerp"}
    name : str, optional

    Raises
    ------
    InputError
        Missing rigorous fields, optical distortion (not modelled), or a non-uniform line rate.
    """
    path = Path(path)
    md = read_dg_metadata(path)
    if md["distortion_order"] >= 0:
        raise InputError(f"{path.name}: optical distortion polynomials (POLYORDER {md['distortion_order']}) "
                         "are not modelled")
    rows, cols = md["rows"], md["columns"]
    # ---------------------------------------------------------------- timing
    first = parse_utc(md["first_line_time"])
    rate = md["line_rate"]
    tlc = md["tlc"]
    origin, period, t0 = first, 1.0 / rate, 0.0
    if tlc.shape[0] >= 2:
        # ASP's rule: the TLC list (line, seconds from TLCTIME) is the time model; it must be a
        # single rate here (stamps have 1 us resolution, i.e. 0.024 lines at 24 kHz)
        origin = parse_utc(md["tlc_time"])
        period, t0 = np.polyfit(tlc[:, 0], tlc[:, 1], 1)
        dev = np.max(np.abs(t0 + period * tlc[:, 0] - tlc[:, 1])) / period
        if dev > 0.05:
            raise InputError(f"{path.name}: the TLC list is not a uniform line rate ({dev:.3g} lines off)")
        gap = abs(seconds_between(origin, first) - t0) / period
        if gap > 0.1:
            raise InputError(f"{path.name}: FIRSTLINETIME and the TLC list disagree by {gap:.3g} lines")
    if md["scan_direction"].lower() != "forward":
        raise InputError(f"{path.name}: reverse scans are not supported (rows run against time)")
    reference_row = (rows - 1) / 2.0
    line_period = float(period)
    epoch = origin + np.timedelta64(int(round((t0 + reference_row * line_period) * 1e9)), "ns")
    # ---------------------------------------------------------------- samples
    eph, att = md["eph"], md["att"]
    t_eph = seconds_between(epoch, parse_utc(md["eph_start"])) + (eph[:, 0] - 1.0) * md["eph_interval"]
    t_att = seconds_between(epoch, parse_utc(md["att_start"])) + (att[:, 0] - 1.0) * md["att_interval"]
    ephemeris = Ephemeris(t_eph, eph[:, 1:4], eph[:, 4:7])
    q_wxyz = np.column_stack([att[:, 4], att[:, 1:4]])
    attitude = AttitudeTable(t_att, q_wxyz, method=attitude_method)
    # ---------------------------------------------------------------- camera
    pitch = md["det_pitch_mm"] * 1e-3
    focal = md["pd_mm"] * 1e-3
    m = _camera_frame(md["det_rot_rad"])  # sensor -> camera
    det_origin = np.array([md["det_origin_mm"][0], md["det_origin_mm"][1], 0.0]) * 1e-3  # metres
    qc = md["camera_quaternion"]
    camera_to_body = quaternion_to_matrix(np.array([[qc[3], qc[0], qc[1], qc[2]]]))[0]
    interior = InteriorOrientation(
        focal_length_m=focal, detector_pitch_m=pitch, n_columns=cols,
        principal_column=-(det_origin @ m[:, 1]) / pitch, along_track_offset_m=float(det_origin @ m[:, 0]),
    )  # fmt: skip
    # ---------------------------------------------------------------- frame
    from explorer.rpc import read_dg_xml

    try:
        rpc = read_dg_xml(path)
    except ValueError:
        rpc = None
    if rpc is not None:
        lon, lat, ok = rpc.localization((rows - 1) / 2.0, (cols - 1) / 2.0, rpc.height_offset)
        if not ok:
            rpc = None
    if rpc is None:
        s = ephemeris.position(np.zeros(1))[0]
        lon, lat, _ = ecef_to_geodetic(s[None])
        h_ref = 0.0
    else:
        h_ref = rpc.height_offset
    frame = LocalFrame(float(np.ravel(lat)[0]), float(np.ravel(lon)[0]), 0.0)
    exterior = LineScanExterior(ephemeris, attitude, frame, camera_to_body @ m, md["perspective_center"])
    scene = RigorousLineScanScene(
        name=name or path.stem, interior=interior, exterior=exterior,
        timing=LineTiming(line_period, reference_row), n_rows=rows, terrain=FlatTerrain(h_ref), frame=frame,
        metadata={"source": "dg-xml", "file": str(path), "sat_id": md["sat_id"], "rpc_file": str(path)},
        aberration=aberration, refraction=refraction, epoch_utc=str(epoch) + "Z", rpc=rpc,
    )  # fmt: skip
    return scene
