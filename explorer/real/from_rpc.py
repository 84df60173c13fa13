"""A pushbroom :class:`~explorer.scene.Scene` from a real image's RPC: the papers' pipeline.

Ahooei Nezhad et al. (2024, Remote Sensing 16:2787, Sec. 2.1-2.3) take real images with RPC
files, obtain ground control points through the RPC (heights from a DEM), and solve the MPC
model by space resection before simulating points.  :func:`scene_from_rpc` does the same:

1. a regular grid of image points (GCPs) is localised through the RPC, at DEM heights
   (:func:`~explorer.rpc.dem.localization_on_dem`; an orthometric DEM is
   converted to ellipsoidal heights with EGM96 so that DEM and RPC share the ellipsoid datum),
   at the RPC's height offset, or on several height layers over the RPC's validity range;
2. lon/lat/h are converted to a local ENU frame at the image centre
   (:class:`~explorer.geometry.frames.LocalFrame`);
3. initial values: the line of sight of the image centre is the direction joining its
   RPC localisations at two heights; the satellite sits on it at the preset's altitude (or
   700 km); the along-track axis follows the ground direction of increasing rows, the
   across-track axis that of increasing columns; the detector pitch follows from the RPC's
   ground sample distance and the focal length (preset) or the focal length from the pitch;
4. MPC space resection by Levenberg-Marquardt (:func:`explorer.real.resection.resect`);
5. residuals on the GCPs and on independent check points (a grid offset by half a cell at
   random heights within the RPC's validity range), by true ground -> image projection.

Conventions: ``docs/conventions.md``; RPC pixel conventions: ``docs/rpc.md``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from explorer.errors import InputError
from explorer.geometry.exterior import ExteriorOrientation, LineTiming
from explorer.geometry.frames import LocalFrame, ecef_to_geodetic
from explorer.geometry.interior import InteriorOrientation
from explorer.geometry.rotations import opk_from_rotation
from explorer.geometry.terrain import FlatTerrain, GridDEM, Terrain
from explorer.real.resection import ResectionReport, image_residuals, mpc_from_lines_of_sight, resect
from explorer.rpc import RationalFunctionModel, read_rpc
from explorer.rpc.dem import localization_on_dem
from explorer.scene import Scene

__all__ = [
    "DEFAULT_ALTITUDE_M",
    "GM_EARTH",
    "check_points_from_rpc",
    "gcps_from_rpc",
    "initial_scene_from_footprint",
    "initial_scene_from_rpc",
    "load_dem",
    "rpc_image_size",
    "scene_from_rpc",
]

GM_EARTH = 3.986004418e14  # m^3 s^-2
DEFAULT_ALTITUDE_M = 700_000.0
DEFAULT_PITCH_M = 1.0e-5  # detector pitch used when the focal length is estimated without a preset


# --------------------------------------------------------------------------- inputs
def rpc_image_size(rpc: RationalFunctionModel) -> tuple[int, int]:
    """(rows, columns) of the image an RPC describes: the file's size, else ``2 * offset + 1``."""
    if rpc.image_size is not None:
        return int(rpc.image_size[0]), int(rpc.image_size[1])
    return int(round(2 * rpc.row_offset + 1)), int(round(2 * rpc.col_offset + 1))


def load_dem(dem: Any, datum: str | None = None) -> Any:
    """A height source with ellipsoidal heights for :func:`~explorer.rpc.dem.localization_on_dem`.

    Parameters
    ----------
    dem : str, Path, GeoDEM or object with ``height(lon, lat)``
        A GeoTIFF or SRTM ``.hgt`` path (read by :func:`explorer.terrain_io.read_dem_above_ellipsoid`, the
        one DEM reader of every command), or a loaded DEM.
    datum : {"ellipsoid", "egm96"} or None
        What the heights are measured from when the file does not declare it (``"geoid"`` = ``"egm96"``;
        None: :data:`explorer.terrain_io.DEFAULT_DEM_DATUM`, see ``docs/conventions.md#dem-heights``).
        Geoid heights are converted with the EGM96 grid (``terrain_io.EllipsoidalDEM``).
    """
    from explorer.terrain_io import (
        DEFAULT_DEM_DATUM,
        EllipsoidalDEM,
        GeoDEM,
        Geoid,
        normalise_dem_datum,
        read_dem_above_ellipsoid,
    )

    datum = normalise_dem_datum(datum)
    if isinstance(dem, (str, Path)):
        path = Path(dem)
        if not path.is_file():
            raise InputError(f"DEM not found (or not a file): {path}")
        return read_dem_above_ellipsoid(path, datum=datum)
    if isinstance(dem, GeoDEM):
        reference = dem.vertical_reference if dem.vertical_reference != "unknown" else (datum or DEFAULT_DEM_DATUM)
        if reference in ("egm96", "geoid"):
            return EllipsoidalDEM(dem, Geoid.egm96())
    return dem


def _grid(n: int, rows: int, cols: int, offset: bool) -> tuple[np.ndarray, np.ndarray]:
    """Regular image grid of about n nodes with the image's aspect ratio (0-based centres)."""
    gr = max(2, int(round(np.sqrt(n * rows / cols))))
    gc = max(2, int(round(n / gr)))
    if offset:
        r = (np.arange(gr) + 0.5) * rows / gr - 0.5
        c = (np.arange(gc) + 0.5) * cols / gc - 0.5
    else:
        r = np.linspace(0.0, rows - 1.0, gr)
        c = np.linspace(0.0, cols - 1.0, gc)
    return np.repeat(r, gc), np.tile(c, gr)


def gcps_from_rpc(
    rpc: RationalFunctionModel,
    n: int,
    *,
    dem: Any = None,
    heights: np.ndarray | None = None,
    offset_grid: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Image grid localised through the RPC.

    Parameters
    ----------
    rpc : RationalFunctionModel
    n : int
        About ``n`` image points per height layer (a regular grid spanning the image).
    dem : height source, optional
        Ellipsoidal heights (see :func:`load_dem`); the grid is intersected with it.
    heights : ndarray, optional
        Height layers (metres above the ellipsoid) used when no DEM is given: each image point
        is localised on every layer.  Default: the RPC's height offset.
    offset_grid : bool
        Nodes at cell centres (check points) instead of spanning the image corners.

    Returns
    -------
    row, col, lon, lat, h : ndarray, shape (M,)
        Points that localised (DEM misses and non-converged points are dropped).
    """
    rows, cols = rpc_image_size(rpc)
    r, c = _grid(n, rows, cols, offset_grid)
    if dem is not None:
        lon, lat, h, ok = localization_on_dem(rpc, r, c, dem)
        return r[ok], c[ok], lon[ok], lat[ok], h[ok]
    hs = np.atleast_1d(np.asarray([rpc.height_offset] if heights is None else heights, dtype=np.float64))
    rr = np.tile(r, hs.size)
    cc = np.tile(c, hs.size)
    hh = np.repeat(hs, r.size)
    lon, lat, ok = rpc.localization(rr, cc, hh)
    return rr[ok], cc[ok], lon[ok], lat[ok], hh[ok]


def check_points_from_rpc(
    rpc: RationalFunctionModel, n: int, *, seed: int = 0, height_range: tuple[float, float] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Independent check points: a cell-centred grid at random heights (uniform, seeded).

    ``height_range`` defaults to the RPC's validity range ``height_offset +- |height_scale|``.
    Returns ``row, col, lon, lat, h`` of the points that localised.
    """
    rows, cols = rpc_image_size(rpc)
    r, c = _grid(n, rows, cols, True)
    lo, hi = rpc.height_range(1.0) if height_range is None else height_range
    h = np.random.default_rng(seed).uniform(lo, hi, r.size)
    lon, lat, ok = rpc.localization(r, c, h)
    return r[ok], c[ok], lon[ok], lat[ok], h[ok]


# --------------------------------------------------------------------------- initial values
def _point_at_altitude(frame: LocalFrame, p: np.ndarray, u: np.ndarray, altitude: float) -> np.ndarray:
    """The point ``p + rho u`` (ENU) whose ellipsoidal height is ``altitude`` (secant on rho)."""

    def height(rho: float) -> float:
        return float(frame.enu_to_geodetic((p + rho * u)[None])[2][0])

    r0, r1 = altitude, altitude * 1.2
    h0, h1 = height(r0) - altitude, height(r1) - altitude
    for _ in range(30):
        if h1 == h0:
            break
        r0, r1 = r1, r1 - h1 * (r1 - r0) / (h1 - h0)
        h0, h1 = h1, height(r1) - altitude
        if abs(h1) < 1e-6:
            break
    return p + r1 * u


def initial_scene_from_footprint(
    rpc: RationalFunctionModel,
    *,
    frame: LocalFrame | None = None,
    reference_height: float | None = None,
    altitude_m: float = DEFAULT_ALTITUDE_M,
    focal_length_m: float | None = None,
    detector_pitch_m: float | None = None,
    terrain: Terrain | None = None,
    name: str = "rpc",
) -> Scene:
    """MPC scene approximating an RPC from its ground footprint (simple initial values).

    Parameters
    ----------
    rpc : RationalFunctionModel
    frame : LocalFrame, optional
        Default: at the image centre localised at ``reference_height``, ``h0 = 0``.
    reference_height : float, optional
        Ellipsoidal height of the scene (default: the RPC's height offset).
    altitude_m : float
        Satellite altitude above the ellipsoid, metres.
    focal_length_m : float, optional
        Fixed focal length; the detector pitch then follows from the RPC's across-track GSD.
        Without it the pitch is ``detector_pitch_m`` (default 10 um) and the focal length
        follows from the GSD.
    detector_pitch_m : float, optional
    terrain : FlatTerrain or GridDEM, optional
        Default: flat at ``reference_height``.

    Notes
    -----
    * Line of sight: the centre pixel localised at two heights ``h0 +- dh`` gives two ground
      points on its ray; their difference is the look direction (the RPC's own 3D geometry).
    * Velocity: circular-orbit speed ``sqrt(GM / r)`` along the ground direction of increasing
      rows (projected perpendicular to the radial); acceleration ``-GM / r^2`` radial.
    * Line period: the time the satellite's sub-point needs to cover one row on the ground.
    * Attitude: ``z`` along the line of sight (away from the ground), ``y`` along increasing
      columns, ``x = y cross z`` (along track); constant (rates zero).
    """
    rows, cols = rpc_image_size(rpc)
    rc, cc = (rows - 1) / 2.0, (cols - 1) / 2.0
    h0 = rpc.height_offset if reference_height is None else float(reference_height)
    if frame is None:
        lon_c, lat_c, _ = rpc.localization(rc, cc, h0)
        frame = LocalFrame(float(lat_c), float(lon_c), 0.0)
    dh = max(0.5 * abs(rpc.height_scale), 50.0)
    d_row = max(1.0, rows / 20.0)
    d_col = max(1.0, cols / 20.0)
    r_in = np.array([rc, rc, rc, rc + d_row, rc - d_row, rc, rc])
    c_in = np.array([cc, cc, cc, cc, cc, cc + d_col, cc - d_col])
    h_in = np.array([h0, h0 - dh, h0 + dh, h0, h0, h0, h0])
    lon, lat, ok = rpc.localization(r_in, c_in, h_in)
    if not ok.all():
        raise InputError("the RPC does not localise the image centre; cannot build initial values")
    pts = frame.geodetic_to_enu(lon, lat, h_in)
    centre = pts[0]
    u = pts[2] - pts[1]
    u /= np.linalg.norm(u)  # from the ground towards the satellite
    sat = _point_at_altitude(frame, centre, u, altitude_m)
    rho = float(np.linalg.norm(sat - centre))
    g_row = (pts[3] - pts[4]) / (2 * d_row)  # ground metres per row
    g_col = (pts[5] - pts[6]) / (2 * d_col)
    # sensor axes
    y_ax = g_col - (g_col @ u) * u
    y_ax /= np.linalg.norm(y_ax)
    x_ax = np.cross(y_ax, u)
    if x_ax @ g_row <= 0:
        raise InputError(
            "columns increase to the right of the direction of increasing rows: a mirrored image "
            "cannot be represented with the package's sensor frame (docs/conventions.md#frames)"
        )
    r0 = np.stack([x_ax, y_ax, u], axis=1)
    # orbit
    earth_centre = frame.ecef_to_enu(np.zeros((1, 3)))[0]
    radial = sat - earth_centre
    r_orbit = float(np.linalg.norm(radial))
    radial /= r_orbit
    v_dir = g_row - (g_row @ radial) * radial
    v_dir /= np.linalg.norm(v_dir)
    speed = float(np.sqrt(GM_EARTH / r_orbit))
    earth_radius = float(np.linalg.norm(centre - earth_centre))
    ground_speed = speed * earth_radius / r_orbit
    line_period = float(np.linalg.norm(g_row)) / ground_speed
    pos = np.stack([sat, speed * v_dir, -0.5 * GM_EARTH / r_orbit**2 * radial], axis=1)
    att = np.array(opk_from_rotation(r0), dtype=np.float64).reshape(3, 1)
    # interior: angle subtended by one column at the satellite
    ifov = float(np.linalg.norm(g_col - (g_col @ u) * u)) / rho
    if focal_length_m is not None:
        f = float(focal_length_m)
        pitch = f * ifov
    else:
        pitch = DEFAULT_PITCH_M if detector_pitch_m is None else float(detector_pitch_m)
        f = pitch / ifov
    interior = InteriorOrientation(f, pitch, cols)
    timing = LineTiming(line_period, rc)
    terrain = FlatTerrain(h0) if terrain is None else terrain
    lat_deg = ecef_to_geodetic(frame.enu_to_ecef(sat[None]))[1][0]
    off_nadir = float(np.degrees(np.arccos(np.clip(u @ radial, -1.0, 1.0))))
    metadata = {
        "initial": {"altitude_m": altitude_m, "slant_range_m": rho, "off_nadir_deg": off_nadir,
                    "satellite_lat_deg": float(lat_deg), "line_period_s": line_period,
                    "ground_speed_m_s": ground_speed},
    }  # fmt: skip
    return Scene(name, interior, ExteriorOrientation(pos, att, []), timing, rows, terrain, frame, metadata)


def initial_scene_from_rpc(
    rpc: RationalFunctionModel,
    *,
    frame: LocalFrame,
    degree: int = 2,
    focal_length_m: float | None = None,
    detector_pitch_m: float | None = None,
    altitude_m: float = DEFAULT_ALTITUDE_M,
    n_sample_rows: int = 11,
    n_sample_columns: int = 9,
    column_terms: int = 0,
    reference_height: float | None = None,
    name: str = "rpc",
) -> tuple[Scene, dict]:
    """Initial values of the resection from the RPC's lines of sight.

    A ``n_sample_rows x n_sample_columns`` image grid is localised at the two ends of the RPC's
    height range (``height_offset -+ |height_scale|``); each pair of points is a line of sight
    and :func:`explorer.real.resection.mpc_from_lines_of_sight` intersects them row by row
    (perspective centres, attitude, ``f / pitch``).  Falls back to
    :func:`initial_scene_from_footprint` (preset or 700 km altitude, look direction of the
    image centre) when the intersection is implausible (altitude outside 150..50000 km).

    Returns
    -------
    scene : Scene
    info : dict
        ``initial_method`` ("lines-of-sight" or "footprint") and the numbers of
        :func:`mpc_from_lines_of_sight`.
    """
    rows, cols = rpc_image_size(rpc)
    h_lo, h_hi = rpc.height_range(1.0)
    r = np.linspace(0.0, rows - 1.0, max(n_sample_rows, degree + 1))
    c = np.linspace(0.0, cols - 1.0, max(n_sample_columns, 3))
    rr, cc = np.meshgrid(r, c, indexing="ij")
    lon_lo, lat_lo, ok_lo = rpc.localization(rr, cc, np.full(rr.shape, h_lo))
    lon_hi, lat_hi, ok_hi = rpc.localization(rr, cc, np.full(rr.shape, h_hi))
    h0 = rpc.height_offset if reference_height is None else float(reference_height)
    info: dict = {}
    if ok_lo.all() and ok_hi.all():
        low = frame.geodetic_to_enu(lon_lo.ravel(), lat_lo.ravel(), np.full(rr.size, h_lo)).reshape(rr.shape + (3,))
        high = frame.geodetic_to_enu(lon_hi.ravel(), lat_hi.ravel(), np.full(rr.size, h_hi)).reshape(rr.shape + (3,))
        try:
            scene, info = mpc_from_lines_of_sight(
                r, c, low, high, n_rows=rows, n_columns=cols, frame=frame, degree=degree,
                focal_length_m=focal_length_m, column_terms=column_terms,
                detector_pitch_m=DEFAULT_PITCH_M if detector_pitch_m is None else detector_pitch_m,
                terrain=FlatTerrain(h0), name=name,
            )  # fmt: skip
            if 150e3 < info["altitude_m"] < 5e7:
                info["initial_method"] = "lines-of-sight"
                return scene, info
        except InputError as exc:
            if "mirrored" in str(exc):
                raise
            info = {"lines_of_sight_error": str(exc)}
        except np.linalg.LinAlgError as exc:
            info = {"lines_of_sight_error": str(exc)}
    scene = initial_scene_from_footprint(
        rpc, frame=frame, reference_height=h0, altitude_m=altitude_m, focal_length_m=focal_length_m,
        detector_pitch_m=detector_pitch_m, name=name,
    )  # fmt: skip
    info["initial_method"] = "footprint"
    return scene, info


# --------------------------------------------------------------------------- DEM terrain
def terrain_from_dem(dem: Any, frame: LocalFrame, extent: tuple[float, float, float, float],
                     cell_m: float | None = None, max_nodes: int = 256) -> GridDEM:
    """Resample an ellipsoidal height source onto a local ENU grid covering ``extent``.

    Node ``(x, y)``: the ENU height ``z`` is solved so that the geodetic height of ``(x, y, z)``
    equals the DEM height at its lon/lat (three fixed-point iterations, < 1 mm).  Nodes where
    the DEM is undefined are NaN (no-data), never extrapolated.
    """
    xmin, xmax, ymin, ymax = extent
    span = max(xmax - xmin, ymax - ymin)
    if cell_m is None:
        cell_m = span / (max_nodes - 1)
    nx = int(np.ceil((xmax - xmin) / cell_m)) + 1
    ny = int(np.ceil((ymax - ymin) / cell_m)) + 1
    gx, gy = np.meshgrid(xmin + cell_m * np.arange(nx), ymin + cell_m * np.arange(ny))
    x, y = gx.ravel(), gy.ravel()
    z = np.zeros_like(x)
    for _ in range(4):
        lon, lat, h = frame.enu_to_geodetic(np.stack([x, y, z], axis=1))
        hd = np.asarray(dem.height(lon, lat), dtype=np.float64)
        z = z + np.where(np.isfinite(hd), hd - h, 0.0)
    z = np.where(np.isfinite(hd), z, np.nan)
    return GridDEM(xmin, ymin, cell_m, cell_m, z.reshape(ny, nx), None, {"kind": "dem", "cell_m": cell_m})


# --------------------------------------------------------------------------- pipeline
def scene_from_rpc(
    path: str | Path | RationalFunctionModel,
    dem: Any = None,
    n_gcps: int = 100,
    preset: str | None = None,
    *,
    layers: int = 3,
    dem_datum: str | None = None,
    estimate_focal: bool | None = None,
    altitude_m: float | None = None,
    degree: int = 2,
    column_terms: int = 0,
    n_check: int = 400,
    seed: int = 0,
    method: str = "lm",
    prior_scale: float = 10.0,
    random_starts: int = 0,
    name: str | None = None,
) -> tuple[Scene, ResectionReport]:
    """Fit an MPC :class:`Scene` to a real image's RPC by space resection.

    Parameters
    ----------
    path : str, Path or RationalFunctionModel
        RPC file (any format :func:`explorer.rpc.read_rpc` reads) or a model.
    dem : path or height source, optional
        DEM for the GCP heights and the scene terrain (see :func:`load_dem`); without it the
        GCPs lie on ``layers`` height planes and the terrain is flat at the height offset.
    n_gcps : int
        About this many GCPs per height layer, on a regular image grid.
    preset : str, optional
        Preset id giving the focal length and the satellite altitude (interior orientation
        fixed); without it the focal length is estimated.
    layers : int
        Number of height layers of the GCP grid when no DEM is given, spanning the RPC's
        validity range ``height_offset +- |height_scale|`` (1: the height offset only, the
        papers' "mean height"; with a DEM the GCPs are on the terrain).
    dem_datum : {"ellipsoid", "egm96"} or None
        Vertical datum of a GeoTIFF DEM that declares none (RPC heights are ellipsoidal; None: the default of
        ``docs/conventions.md#dem-heights``, see :func:`load_dem`).
    estimate_focal : bool, optional
        Default: True without a preset, False with one.
    altitude_m : float, optional
        Satellite altitude for the initial values (default: the preset's, else 700 km).
    degree : int
        Degree of the MPC polynomials (the papers: 2; agile Pleiades/SPOT acquisitions need 3 for
        sub-pixel agreement, see ``docs/real_images.md``).
    column_terms : int
        Non-uniform detector spacing terms to estimate (0: evenly spaced, the papers' camera;
        1: products resampled to a uniform ground spacing across track, e.g. IKONOS Geo).
    n_check : int
        About this many check points (cell-centred grid at random heights); 0 to skip.
    seed : int
        Seed of the check-point heights.
    method : {"lm", "trf"}
    prior_scale : float
        Weak priors of the resection (:func:`explorer.real.resection.resect`): every unknown is
        tied to its lines-of-sight initial value with ``prior_scale`` times
        :data:`~explorer.real.resection.PRIOR_SIGMA` (default 10: 10 km per position
        coefficient, 10 mrad of attitude, 10 % of focal length).  They make the least-squares
        problem well posed where the control points leave directions nearly free (GCPs on a
        flat DEM, an RPC the MPC model cannot follow), so every machine reaches the same
        minimum; where the points do see every direction they change the result by less than
        2e-5 px (measured on the test RPCs).  0 disables them.
    random_starts : int
        Extra seeded starts of the resection (``seed``), for a multi-start check.
    name : str, optional
        Scene name (default: the file stem).

    Returns
    -------
    scene : Scene
        MPC scene in a local ENU frame at the image centre; ``metadata["rpc"]`` records the
        source and the fit.
    report : ResectionReport
        GCP and check-point residuals (pixels, true ground -> image projection).
    """
    for what, value, lo, hi in (("n_gcps", n_gcps, 4, 1_000_000), ("layers", layers, 1, 100),
                                ("n_check", n_check, 0, 1_000_000), ("degree", degree, 0, 10),
                                ("column_terms", column_terms, 0, 10)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
            raise InputError(f"{what} must be a whole number in [{lo}, {hi:,}], got {value!r}")
    if not (np.isfinite(prior_scale) and prior_scale >= 0):
        raise InputError(f"prior_scale must be finite and >= 0, got {prior_scale!r}")
    rpc = path if isinstance(path, RationalFunctionModel) else read_rpc(path)
    src = rpc.source_path or (str(path) if not isinstance(path, RationalFunctionModel) else "<model>")
    if name is None:
        name = Path(src).stem if src != "<model>" else "rpc"
    spec = None
    if preset is not None:
        from explorer.presets import preset_spec

        spec = preset_spec(preset)
    if estimate_focal is None:
        estimate_focal = spec is None
    if altitude_m is None:
        altitude_m = float(spec["altitude_m"]) if spec is not None else DEFAULT_ALTITUDE_M
    height_source = load_dem(dem, dem_datum) if dem is not None else None

    # GCPs
    if height_source is not None:
        heights = None
    elif layers <= 1:
        heights = np.array([rpc.height_offset])
    else:
        heights = np.linspace(*rpc.height_range(1.0), layers)
    g_row, g_col, g_lon, g_lat, g_h = gcps_from_rpc(rpc, n_gcps, dem=height_source, heights=heights)
    if g_row.size < 10:
        raise InputError(f"only {g_row.size} GCPs localised (DEM coverage?); need at least 10")
    h_ref = float(np.mean(g_h)) if height_source is not None else rpc.height_offset

    rows, cols = rpc_image_size(rpc)
    lon_c, lat_c, ok = rpc.localization((rows - 1) / 2.0, (cols - 1) / 2.0, h_ref)
    if not ok:
        raise InputError("the RPC does not localise the image centre")
    frame = LocalFrame(float(lat_c), float(lon_c), 0.0)
    ground = frame.geodetic_to_enu(g_lon, g_lat, g_h)

    scene0, init_info = initial_scene_from_rpc(
        rpc, frame=frame, degree=degree, column_terms=column_terms, reference_height=h_ref, altitude_m=altitude_m,
        focal_length_m=None if spec is None else float(spec["focal_length_m"]),
        detector_pitch_m=None if spec is None else float(spec["native_detector_pitch_m"]),
        name=name,
    )  # fmt: skip
    scene, report = resect(scene0, g_row, g_col, ground, degree=degree, estimate_focal=estimate_focal,
                           column_terms=column_terms, method=method, prior_scale=prior_scale,
                           random_starts=random_starts, seed=seed)

    # terrain
    if height_source is not None:
        corners = np.vstack([scene.footprint(float(np.min(g_h))), scene.footprint(float(np.max(g_h)))])
        lo, hi = corners[:, :2].min(0), corners[:, :2].max(0)
        pad = 0.05 * (hi - lo)
        terrain = terrain_from_dem(height_source, frame, (lo[0] - pad[0], hi[0] + pad[0], lo[1] - pad[1],
                                                          hi[1] + pad[1]))
        scene = scene.with_terrain(terrain)

    # check points
    if n_check:
        c_row, c_col, c_lon, c_lat, c_h = check_points_from_rpc(rpc, n_check, seed=seed)
        drow, dcol = image_residuals(scene, frame.geodetic_to_enu(c_lon, c_lat, c_h), c_row, c_col)
        report = report.with_check(drow, dcol)

    s0 = scene.exterior.position(np.zeros(1))
    _, _, alt = frame.enu_to_geodetic(s0)
    report.info.update({
        "rpc_file": src, "rpc_format": rpc.source_format, "image_rows": rows, "image_columns": cols,
        "gcp_heights": "dem" if heights is None else f"{len(heights)} layer(s)",
        "gcp_height_min_m": float(np.min(g_h)), "gcp_height_max_m": float(np.max(g_h)),
        "altitude_at_centre_m": float(alt[0]), "line_period_s": scene.timing.line_period_s,
        "preset": preset or "", "initial_method": init_info["initial_method"],
        "initial_altitude_m": float(init_info.get("altitude_m", altitude_m)),
    })  # fmt: skip
    if height_source is not None:
        from explorer.terrain_io import datum_statement

        report.info["dem_datum"] = datum_statement(height_source)
    scene.metadata = {
        **scene.metadata,
        "source": "rpc-resection",
        "rpc": report.to_dict(),
    }
    return scene, report
