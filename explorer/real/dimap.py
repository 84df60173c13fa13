"""Pleiades DIMAP v1.4 datastrip metadata (``PHRDIMAP_*.XML``) -> rigorous line-scan scene.

Beyond the papers.  What the file holds (read by :func:`read_dimap_v1_geometry`):

* ``Data_Strip/Ephemeris/Point_List/Point``: ``LOCATION_VALUES`` (ECEF m),
  ``VELOCITY_VALUES`` (m/s), ``UTC_TIME`` -- 30 s apart over a few minutes;
* ``Data_Strip/Satellite_Attitudes/Corrected_Attitudes/WGS84_Attitudes_List``: ``UTC_TIME``
  and ``Q_VALUES`` -- unit quaternions, **scalar first**, rotating the satellite body frame into
  ECEF (determined from the data: with this reading the body ``+z`` axis points at the image
  centre within 0.1 deg; the other readings point away from the Earth) -- 8 Hz;
  (``Accurate``/``Raw`` attitudes are TAI-stamped inertial quaternions and are not used);
* ``Time_Stamp``: raw ``PA_LINE_PERIOD`` (ms), ``ORIGIN_TIME`` per array, ``TAI_UTC``;
  ``UTC_Acquisition_Range``; ``Raster_Dimensions``; the vendor RPC (``Global_RFM``, 1-based
  in the file, read by ``explorer.rpc.read_dimap_v1``).

What it does *not* hold: the product's "perfect sensor" -- its line period, the time of its
reference line and the look angles of its detectors are in the product's own DIMAP v2
``DIM_*.XML`` (``Geometric_Data/Refined_Model``), and the raw detector look directions are in
the ``*_VIEWING_DIRECTIONS`` GIPP files the datastrip only names.  So the interior
orientation and the product timing are **calibrated against the RPC of the same file**
(:func:`rigorous_scene_from_dimap`): with the rigorous ephemeris and attitude fixed, a
least-squares fit of

* the epoch (time of the centre row) and the line period,
* the look-angle polynomials of the column: across track ``y(col)`` (principal column, pitch,
  ``column_polynomial``) and along track ``x(y)`` (``along_track_offset_m``,
  ``line_curvature``), degree ``look_angle_degree``,

on a 3D grid of RPC control points.  The fitted line period is checked against the nominal
product line period (0.0735 ms) and the epoch reported relative to ``ORIGIN_TIME``.  Anything the low-order
interior cannot absorb -- errors of orbit or attitude interpolation, time tagging,
aberration handling -- shows up as residuals against independent check points.  Results:
``docs/real_images.md``.  Conventions: ``docs/conventions.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
from scipy.optimize import least_squares

from explorer.errors import InputError
from explorer.geometry.exterior import LineTiming
from explorer.geometry.frames import LocalFrame
from explorer.geometry.interior import InteriorOrientation
from explorer.geometry.terrain import FlatTerrain
from explorer.io_input import load_xml_file
from explorer.real.linescan import AttitudeTable, Ephemeris, LineScanExterior, RigorousLineScanScene
from explorer.real.timeutil import parse_utc, seconds_between

__all__ = ["DimapCalibration", "read_dimap_v1_geometry", "rigorous_scene_from_dimap"]

PLEIADES_FOCAL_LENGTH_M = 12.905  # nominal; only focal/pitch matters, the pitch is calibrated
#: Line period of Pleiades primary (sensor) products, stated by their metadata (e.g. the OSSIM
#: ``support_data.line_period: 0.0735`` ms of tests/data/rpc/PHR1B_*.geom).
PLEIADES_PRODUCT_LINE_PERIOD_S = 0.0735e-3


def _float_list(e: ElementTree.Element | None) -> list[float]:
    if e is None or e.text is None:
        raise InputError("missing value")
    return [float(v) for v in e.text.split()]


def read_dimap_v1_geometry(path: str | Path) -> dict:
    """Read the rigorous-model fields of a Pleiades DIMAP v1.4 datastrip file.

    Returns
    -------
    dict
        ``rows``, ``columns``, ``eph_times`` (list of str, UTC), ``eph_position`` (N, 3),
        ``eph_velocity`` (N, 3), ``att_times`` (UTC), ``att_quaternion`` (M, 4, as in the file),
        ``line_period_raw_s``, ``origin_time`` (UTC str), ``acquisition_start``/``_end``,
        ``row_size_m`` (raw ground sampling along track), ``resolution_m`` (product),
        ``tai_utc_s``.
    """
    path = Path(path)
    root = load_xml_file(path, "DIMAP file")  # regular file, any text encoding (explorer.io_input)
    if root.tag != "PHR_Dimap_Document":
        raise InputError(f"{path.name}: not a Pleiades DIMAP v1.4 document (root {root.tag!r})")
    points = root.findall(".//Data_Strip/Ephemeris/Point_List/Point")
    atts = root.findall(".//Corrected_Attitudes/WGS84_Attitudes_List/WGS84_Attitudes")
    if len(points) < 2 or len(atts) < 2:
        raise InputError(f"{path.name}: no ephemeris Point_List or WGS84 corrected attitudes")

    def child(node: ElementTree.Element, tag: str) -> ElementTree.Element:
        e = node.find(tag)
        if e is None:
            raise InputError(f"{path.name}: missing {tag}")
        return e

    def text(tag: str, node: ElementTree.Element = root) -> str:
        e = child(node, tag)
        if e.text is None:
            raise InputError(f"{path.name}: missing {tag}")
        return e.text.strip()

    out = {
        "rows": int(text(".//Raster_Dimensions/NROWS")),
        "columns": int(text(".//Raster_Dimensions/NCOLS")),
        "eph_times": [text("UTC_TIME", p) for p in points],
        "eph_position": np.array([_float_list(child(p, "LOCATION_VALUES")) for p in points]),
        "eph_velocity": np.array([_float_list(child(p, "VELOCITY_VALUES")) for p in points]),
        "att_times": [text("UTC_TIME", a) for a in atts],
        "att_quaternion": np.array([_float_list(child(a, "Q_VALUES")) for a in atts]),
        "line_period_raw_s": float(text(".//Time_Stamp/PA_LINE_PERIOD")) * 1e-3,
        "origin_time": text(".//Time_Stamp//ORIGIN_TIME"),
        "acquisition_start": text(".//UTC_Acquisition_Range/START"),
        "acquisition_end": text(".//UTC_Acquisition_Range/END"),
        "row_size_m": float(text(".//Located_Geometric_Header/Raw_Sampling/ROW_SIZE")),
        "resolution_m": float(text(".//THEORETICAL_RESOLUTION")),
        "tai_utc_s": float(text(".//TAI_UTC")),
    }
    for key in ("LOCATION_VALUES", "VELOCITY_VALUES"):
        unit = child(points[0], key).get("unit")
        if unit not in (None, "m", "m/s"):
            raise InputError(f"{path.name}: {key} in {unit!r}, expected m and m/s")
    from explorer.scene_checks import check_orbit_tables

    check_orbit_tables(path.name, out["eph_position"], out["att_quaternion"])  # above the ground, unit quaternions
    return out


@dataclass
class DimapCalibration:
    """Interior orientation and timing calibrated on the RPC (see the module docstring).

    Attributes
    ----------
    rmse_px, max_px : float
        Control-point residuals (true ground -> image projection).
    check_rmse_px, check_max_px : float
        Independent check points (offset grid, random heights in the RPC's range).
    epoch_minus_origin_s : float
        Calibrated time of row 0 minus the file's ``ORIGIN_TIME``.
    line_period_s, line_period_expected_s : float
        Calibrated product line period and the nominal Pleiades product line period (0.0735 ms).
    sensor_to_body : ndarray, shape (3, 3)
        Axes found from the data (package sensor axes in body axes).
    info : dict
    """

    rmse_px: float
    max_px: float
    check_rmse_px: float
    check_max_px: float
    epoch_minus_origin_s: float
    line_period_s: float
    line_period_expected_s: float
    sensor_to_body: np.ndarray
    n_gcps: int
    nfev: int
    info: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "rmse_px": self.rmse_px, "max_px": self.max_px, "check_rmse_px": self.check_rmse_px,
            "check_max_px": self.check_max_px, "epoch_minus_origin_s": self.epoch_minus_origin_s,
            "line_period_s": self.line_period_s, "line_period_expected_s": self.line_period_expected_s,
            "sensor_to_body": self.sensor_to_body.tolist(), "n_gcps": self.n_gcps, "nfev": self.nfev, **self.info,
        }  # fmt: skip

    def summary(self) -> str:
        return "\n".join([
            f"DIMAP interior/timing calibrated on the RPC ({self.n_gcps} control points, {self.nfev} evaluations):",
            f"  control RMSE {self.rmse_px:.4f} px (max {self.max_px:.4f}); check RMSE {self.check_rmse_px:.4f} px"
            f" (max {self.check_max_px:.4f})",
            f"  row 0 at ORIGIN_TIME {self.epoch_minus_origin_s * 1e3:+.4f} ms; line period "
            f"{self.line_period_s * 1e3:.7f} ms (nominal product line period "
            f"{self.line_period_expected_s * 1e3:.4f} ms)",
        ])  # fmt: skip


def _nearest_axes(v: np.ndarray) -> np.ndarray:
    """Signed unit axis (3,) nearest to v."""
    k = int(np.argmax(np.abs(v)))
    out = np.zeros(3)
    out[k] = np.sign(v[k])
    return out


def rigorous_scene_from_dimap(
    path: str | Path,
    *,
    aberration: bool = False,
    refraction: bool = False,
    look_angle_degree: int = 3,
    attitude_method: str = "lagrange",
    attitude_smoothing: int | None = 3,
    n_gcps: int = 150,
    layers: int = 3,
    n_check: int = 400,
    seed: int = 0,
    name: str | None = None,
    control_rows: tuple[float, float] | None = None,
) -> tuple[RigorousLineScanScene, DimapCalibration]:
    """Rigorous Pleiades scene: DIMAP ephemeris and attitude, interior calibrated on its RPC.

    Parameters
    ----------
    path : str or Path
        ``PHRDIMAP_*.XML`` (DIMAP v1.4 datastrip with a ``Global_RFM``).
    aberration, refraction : bool
        Line-of-sight corrections (``explorer.real.linescan``).  Default off: the vendor RPC
        is reproduced to 0.005 px without them and to 0.03 px with aberration (the corrected
        attitudes and calibrated viewing directions already hold the apparent line of sight;
        ``docs/real_images.md``).
    look_angle_degree : int
        Degree of the across- and along-track look-angle polynomials of the column (>= 1).
    attitude_method : {"lagrange", "slerp"}
    attitude_smoothing : int or None
        Replace the quaternion samples by a least-squares polynomial of this degree in time
        (default 3): the product is resampled to a "perfect sensor" whose attitude is smooth;
        with the raw 8 Hz samples the model disagrees with the RPC by 1.8 px RMS (time-only
        oscillations), with the cubic 0.03 px (``docs/real_images.md``).  None keeps the samples.
    n_gcps, layers : int
        Control points: about ``n_gcps`` image points on ``layers`` heights over the RPC's range.
    n_check : int
        Independent check points (offset grid, random heights).
    seed : int
    name : str, optional
    control_rows : (float, float), optional
        Calibrate on the control points with rows in ``[first, last]`` only (default: the whole image).
        The rows outside are then a hold-out: there only the DIMAP ephemeris and attitude carry the
        model, and its agreement with the RPC tests them (notebook 08).

    Returns
    -------
    scene : RigorousLineScanScene
        With ``scene.rpc`` the file's RPC.
    calibration : DimapCalibration
    """
    from explorer.real.from_rpc import check_points_from_rpc, gcps_from_rpc
    from explorer.real.resection import image_residuals
    from explorer.rpc import read_dimap_v1

    path = Path(path)
    md = read_dimap_v1_geometry(path)
    rpc = read_dimap_v1(path)
    rows, cols = md["rows"], md["columns"]
    if look_angle_degree < 1:
        raise InputError("look_angle_degree must be >= 1")
    origin = parse_utc(md["origin_time"])
    t_eph = np.array([seconds_between(origin, parse_utc(s)) for s in md["eph_times"]])
    t_att = np.array([seconds_between(origin, parse_utc(s)) for s in md["att_times"]])
    # frame at the image centre
    lon_c, lat_c, ok = rpc.localization((rows - 1) / 2.0, (cols - 1) / 2.0, rpc.height_offset)
    if not ok:
        raise InputError(f"{path.name}: the RPC does not localise the image centre")
    frame = LocalFrame(float(lat_c), float(lon_c), 0.0)
    eph0 = Ephemeris(t_eph, md["eph_position"], md["eph_velocity"])
    att0 = AttitudeTable(t_att, md["att_quaternion"], method=attitude_method)  # scalar first
    if attitude_smoothing is not None:
        att0 = att0.smoothed(attitude_smoothing)

    # ---- body axes from the data: boresight and column direction at the image centre
    probe_r = np.array([(rows - 1) / 2.0] * 3)
    probe_c = np.array([(cols - 1) / 2.0, 0.0, cols - 1.0])
    plon, plat, _ = rpc.localization(probe_r, probe_c, np.full(3, rpc.height_offset))
    from explorer.geometry.frames import geodetic_to_ecef

    pts = geodetic_to_ecef(plon, plat, np.full(3, rpc.height_offset))
    # time when the centre is seen: the attitude sample nearest the acquisition middle
    t_mid = 0.5 * (seconds_between(origin, parse_utc(md["acquisition_start"]))
                   + seconds_between(origin, parse_utc(md["acquisition_end"])))
    rb = att0.rotation(np.array([t_mid]))[0]  # body -> ECEF
    s_mid = eph0.position(np.array([t_mid]))[0]
    look = (pts[0] - s_mid) / np.linalg.norm(pts[0] - s_mid)
    boresight = _nearest_axes(rb.T @ look)
    if float(rb.T @ look @ boresight) < np.cos(np.radians(10.0)):
        raise InputError(f"{path.name}: no body axis points at the image centre (quaternion convention?)")
    span = rb.T @ (pts[2] - pts[1])
    span -= (span @ boresight) * boresight
    y_s = _nearest_axes(span)
    z_s = -boresight
    x_s = np.cross(y_s, z_s)
    sensor_to_body = np.stack([x_s, y_s, z_s], axis=1)
    exterior0 = LineScanExterior(eph0, att0, frame, sensor_to_body)

    # ---- control and check points from the RPC
    heights = np.linspace(*rpc.height_range(1.0), max(layers, 2))
    g_row, g_col, g_lon, g_lat, g_h = gcps_from_rpc(rpc, n_gcps, heights=heights)
    if control_rows is not None:
        first, last = (float(v) for v in control_rows)
        if not (np.isfinite(first) and np.isfinite(last) and first <= last):
            raise InputError(f"control_rows must be finite (first, last) with first <= last, got {control_rows}")
        keep = (g_row >= first) & (g_row <= last)
        if int(keep.sum()) < 20:
            raise InputError(f"control_rows {control_rows} hold {int(keep.sum())} control points; at least 20 "
                             "are needed (widen the rows or raise n_gcps)")
        g_row, g_col, g_lon, g_lat, g_h = g_row[keep], g_col[keep], g_lon[keep], g_lat[keep], g_h[keep]
    ground = frame.geodetic_to_enu(g_lon, g_lat, g_h)

    # ---- initial timing: times at which the centre row's points cross the detector plane
    f = PLEIADES_FOCAL_LENGTH_M

    def crossing_time(p_enu: np.ndarray, t0: float) -> float:
        t = t0
        for _ in range(30):
            ts = np.array([t, t + 1e-3])
            v = np.einsum("nji,nj->ni", exterior0.rotation(ts), p_enu[None] - exterior0.position(ts))
            x = v[:, 0] / -v[:, 2]
            step = -x[0] * 1e-3 / (x[1] - x[0])
            t += step
            if abs(step) < 1e-9:
                break
        return t

    dr = max(1.0, rows / 10.0)
    tr = np.array([(rows - 1) / 2.0 - dr, (rows - 1) / 2.0 + dr])
    tlon, tlat, _ = rpc.localization(tr, np.full(2, (cols - 1) / 2.0), np.full(2, rpc.height_offset))
    tp = frame.geodetic_to_enu(tlon, tlat, np.full(2, rpc.height_offset))
    ta, tb = crossing_time(tp[0], t_mid), crossing_time(tp[1], t_mid)
    period0 = (tb - ta) / (tr[1] - tr[0])
    if not period0 > 0:
        raise InputError(f"{path.name}: rows do not advance with time (reverse scan?)")
    t_centre0 = 0.5 * (ta + tb)
    # across track: angle per column at the centre
    v_c = frame.ecef_to_enu(pts)
    tm = np.array([t_centre0] * 3)
    vs = np.einsum("nji,nj->ni", exterior0.rotation(tm), v_c - exterior0.position(tm))
    tan_y = vs[:, 1] / -vs[:, 2]
    pitch0 = f * (tan_y[2] - tan_y[1]) / (probe_c[2] - probe_c[1])
    pc0 = probe_c[0] - f * tan_y[0] / pitch0
    reference_row = (rows - 1) / 2.0

    deg = look_angle_degree
    half = max(cols / 2.0, 1.0)

    def build(p: np.ndarray) -> RigorousLineScanScene:
        dt0, log_period, dpc, log_pitch = p[:4]
        a_terms = p[4 : 4 + deg - 1] / half ** np.arange(2, deg + 1)  # 1 px at the edge each
        x0 = p[4 + deg - 1] * pitch0
        ycoef = p[4 + deg :]  # x_det(y) = x0 + sum c_k y^k, c_k scaled so 1 unit = 1 px at the edge
        ymax = half * pitch0
        curv = tuple(float(ycoef[k - 1] * pitch0 / ymax**k) for k in range(1, deg + 1))
        t_centre = t_centre0 + dt0
        ext = LineScanExterior(
            replace(eph0, time_s=eph0.time_s - t_centre), replace(att0, time_s=att0.time_s - t_centre),
            frame, sensor_to_body,
        )  # fmt: skip
        interior = InteriorOrientation(
            f, pitch0 * np.exp(log_pitch), cols, principal_column=pc0 + dpc, along_track_offset_m=x0,
            line_curvature=curv, column_polynomial=tuple(float(a) for a in a_terms),
        )  # fmt: skip
        return RigorousLineScanScene(
            name or path.stem, interior, ext, LineTiming(period0 * np.exp(log_period), reference_row), rows,
            FlatTerrain(rpc.height_offset), frame, {}, aberration=aberration, refraction=refraction,
        )  # fmt: skip

    def residuals(p: np.ndarray) -> np.ndarray:
        sc = build(p)
        x, y = sc.focal_plane(ground, sc.scanline_time(g_row))
        pitch = sc.interior.detector_pitch_m
        return np.concatenate([(x - sc.interior.detector_x(y)) / pitch, (y - sc.interior.column_to_y(g_col)) / pitch])

    p0 = np.zeros(4 + (deg - 1) + 1 + deg)
    sol = least_squares(residuals, p0, method="lm", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    nfev = int(sol.nfev)
    for _ in range(3):  # restart while it still improves (fresh damping)
        again = least_squares(residuals, sol.x, method="lm", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15)
        nfev += int(again.nfev)
        better = again.cost < sol.cost * (1 - 1e-6)
        if again.cost <= sol.cost:
            sol = again
        if not better:
            break
    scene = build(sol.x)
    epoch = origin + np.timedelta64(int(round((t_centre0 + sol.x[0]) * 1e9)), "ns")
    scene.epoch_utc = str(epoch) + "Z"
    scene.rpc = rpc
    scene.metadata = {"source": "dimap-v1.4", "file": str(path), "rpc_file": str(path),
                      "calibrated": "interior orientation and timing on the RPC"}
    drow, dcol = image_residuals(scene, ground, g_row, g_col)
    d = np.hypot(drow, dcol)
    k_row, k_col, k_lon, k_lat, k_h = check_points_from_rpc(rpc, n_check, seed=seed)
    krow, kcol = image_residuals(scene, frame.geodetic_to_enu(k_lon, k_lat, k_h), k_row, k_col)
    dk = np.hypot(krow, kcol)
    t_row0 = float(scene.scanline_time(np.array([0.0]))[0]) + (t_centre0 + sol.x[0])
    expected = PLEIADES_PRODUCT_LINE_PERIOD_S
    calib = DimapCalibration(
        rmse_px=float(np.sqrt(np.mean(d**2))), max_px=float(d.max()),
        check_rmse_px=float(np.sqrt(np.mean(dk**2))), check_max_px=float(dk.max()),
        epoch_minus_origin_s=t_row0, line_period_s=scene.timing.line_period_s,
        line_period_expected_s=expected, sensor_to_body=sensor_to_body, n_gcps=int(g_row.size), nfev=nfev,
        info={"principal_column": scene.interior.principal_column,
              "detector_pitch_m": scene.interior.detector_pitch_m,
              "column_polynomial": list(scene.interior.column_polynomial),
              "along_track_offset_m": scene.interior.along_track_offset_m,
              "line_curvature": list(scene.interior.line_curvature),
              "look_angle_degree": deg, "aberration": aberration, "refraction": refraction,
              "attitude_smoothing": attitude_smoothing},
    )  # fmt: skip
    return scene, calib
