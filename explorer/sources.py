"""The image a command works on: one source, resolved and validated before any work (or server) starts.

``pushbroom explore`` and ``pushbroom bench`` take exactly one of ``--preset ID``, ``--scene scene.json``,
``--rpc FILE [--dem DEM] [--as-mpc]``, ``--dimap FILE [--dem DEM]``, ``--dg FILE [--dem DEM]`` or
``--isd FILE``; ``stereo`` and ``explore --pair`` read each image's file the same way (:func:`load_sensor`).
:func:`load_source` turns it into a :class:`Source` whose ``scene`` is the sensor itself, the truth every number
is measured against (docs/dev/architecture.md, the one Sensor path):

* ``--scene``: :func:`explorer.real.linescan.load_scene` (MPC or rigorous line-scan JSON);
* ``--rpc``: the RPC itself (:class:`explorer.rpc.sensor.RPCSensor`, localising on a plane at the RPC's height
  offset or on ``--dem``).  An RPC has no scanlines: the search methods are unavailable on it
  (:func:`explorer.methods.unavailable_reason`), the learned ones run on it.  ``as_mpc`` (``--as-mpc``) asks for
  the MPC of its space resection instead (:func:`explorer.real.from_rpc.scene_from_rpc`, the papers' pipeline,
  degree 3 -- agile Pleiades / SPOT need it for sub-pixel agreement, see ``docs/real_images.md``; with ``--dem``
  the GCP heights and the terrain come from the DEM): every method runs on it, and it is labelled a stand-in
  everywhere (the label, ``truth``), with the RPC against it as the stand-in map;
* ``--dimap`` / ``--dg``: the rigorous line-scan model of the metadata
  (:func:`explorer.real.dimap.rigorous_scene_from_dimap`, :func:`explorer.real.worldview.rigorous_scene_from_dg`),
  its vendor RPC the stand-in; ``--dem`` resamples the DEM onto the scene's local frame as its terrain;
* ``--isd``: the USGS CSM line-scan camera (:func:`explorer.real.csm_sensor.csm_scene`), an MPC fitted to it the
  stand-in.

Every problem is an :mod:`explorer.errors` error naming the input -- an unknown or wrongly
cased preset (with the right spelling suggested), a missing or unreadable file, a DEM that
does not cover the image footprint -- so the command fails with one line before it prints a
URL.  No viser, no plotly here.
"""

from __future__ import annotations

import difflib
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from explorer.errors import InputError, SceneFileError
from explorer.sensor import StandIn, has_line_geometry

SOURCE_KINDS = ("preset", "scene", "rpc", "dimap", "dg", "isd")
"""The source options of ``pushbroom explore`` (``--<kind>``)."""
SENSOR_KINDS = ("auto", "rpc", "scene", "dimap", "dg", "isd")
"""What :func:`load_sensor` reads a file as (``stereo --left-kind``); ``auto``: :func:`sensor_kind`."""
DEM_KINDS = ("rpc", "dimap", "dg")
"""Sources that take ``--dem``."""
ADJUSTED_KINDS = ("dimap", "dg", "isd")
"""Sources that take ``--adjusted`` (the sidecar of a refined line scanner, ``pushbroom refine``)."""
MPC_DEGREE = 3
"""Degree of the MPC fitted to an RPC (``scene from-rpc --degree 3``) or to a rigorous DIMAP / DG model
(as ``scene from-dimap --degree``)."""
COVERAGE_GRID = 21
"""Image points per side checked against the DEM."""
MIN_DEM_COVERAGE = 0.5
"""Least fraction of the image grid a ``--dimap`` / ``--dg`` DEM must cover (less is refused with the figure)."""


@dataclass
class Source:
    """A resolved explorer source.

    Attributes
    ----------
    kind : str
        One of :data:`SOURCE_KINDS`.
    label : str
        What the GUI calls it (the scene dropdown entry): the preset id, or the file name
        and the sensor.
    scene : Scene or None
        The loaded scene; None for a preset (built by the model with the GUI's controls).
    path, dem : str or None
        The files it came from.
    info : dict
        JSON-ready description (sensor, fit residuals, ...), written into the export.
    report : object or None
        The fit report of a file source (resection or MPC fit), with ``summary()`` for the terminal.
    stand_in : StandIn or None
        The model a user might measure against instead of the sensor (the MPC fit of a CSM camera, the vendor
        RPC of a rigorous DIMAP / DG model): its error against the sensor is the *stand-in map*.
    """

    kind: str
    label: str
    scene: Any = None
    path: str | None = None
    dem: str | None = None
    info: dict = field(default_factory=dict)
    report: Any = None
    stand_in: StandIn | None = None
    _display: Any = field(default=None, repr=False, compare=False)

    @property
    def preset(self) -> str | None:
        """The preset id of a preset source, else None."""
        return self.label if self.kind == "preset" else None

    def display_scene(self) -> Any:
        """The scene the 3D view draws (orbit, scanline planes, lines of sight): the sensor itself where it has
        line geometry; for one without (an RPC) an MPC fitted to it by :func:`display_scene_of` (built on first
        use), a drawing aid only -- every number stays the sensor's own."""
        if self.scene is None or has_line_geometry(self.scene):
            return self.scene
        if self._display is None:
            self._display = display_scene_of(self.scene)
        return self._display

    def to_dict(self) -> dict:
        """JSON-ready: kind, label, files and info."""
        return {"kind": self.kind, "label": self.label, "path": self.path, "dem": self.dem, **self.info}


def stand_in_truth(info: dict | None) -> str | None:
    """What every residual is measured against when the truth is a stand-in (``--as-mpc``: the MPC resected
    from the RPC), for the maps' titles; None when the truth is the sensor itself."""
    return "the STAND-IN MPC (--as-mpc)" if info and info.get("stand_in_model") is True else None


def table_coverage_text(tables: dict | None) -> str:
    """The sentence every front end shows for an ISD whose ephemeris tables do not cover every line
    (``Source.info["table_coverage"]``), e.g. "ephemeris tables cover 83.3 % of the lines (0-2347): the other
    lines are flagged, not extrapolated, and carry no check points"; "" when they cover every line."""
    if not tables:
        return ""
    spans = ", ".join(f"{a:.0f}-{b:.0f}" for a, b in tables["lines"])
    return (f"ephemeris tables cover {100 * tables['fraction']:.1f} % of the lines ({spans}): the other lines are "
            "flagged, not extrapolated, and carry no check points")


DISPLAY_LINE_PERIOD_S = 1e-4
"""Line period given to the MPC drawn for a sensor without scanlines (an RPC has no time; the drawing needs one)."""


def display_scene_of(sensor: Any) -> Any:
    """An MPC scene fitted to a sensor without line geometry (an RPC), in the sensor's own frame and on its terrain,
    for the 3D view only: its orbit, scanline planes and lines of sight are those of the MPC that best reproduces
    the sensor's lines of sight (:func:`explorer.real.mpc_fit.mpc_scene_from_sensor`, degree 3, over the terrain's
    heights +-250 m; on the Pleiades RPC of the tests 0.0008 px RMS from the RPC).  Its ``metadata["display_only"]``
    says so."""
    from explorer.geometry.exterior import LineTiming
    from explorer.real.mpc_fit import mpc_scene_from_sensor

    lo, hi = float(sensor.terrain.min_height) - 250.0, float(sensor.terrain.max_height) + 250.0
    scene, _ = mpc_scene_from_sensor(sensor, height_range=(lo, hi), degree=MPC_DEGREE, n=100, layers=2, n_check=0,
                                     timing=LineTiming(DISPLAY_LINE_PERIOD_S, (sensor.n_rows - 1) / 2.0),
                                     terrain=sensor.terrain,
                                     metadata={"display_only": "drawn for a sensor without scanlines; every number "
                                                               "is the sensor's own"})
    return scene


# ------------------------------------------------------------------ validation
def resolve_preset(name: str) -> str:
    """The preset id ``name`` names exactly.

    Raises
    ------
    InputError
        For an unknown id, suggesting the right case (``wsu`` -> ``WSU``) or the closest ids.
    """
    from explorer.presets import preset_ids

    ids = preset_ids()
    if name in ids:
        return name
    same_case = [i for i in ids if i.lower() == str(name).lower()]
    if same_case:
        raise InputError(f"unknown preset {name!r}: preset ids are case-sensitive; did you mean {same_case[0]!r}?")
    close = difflib.get_close_matches(str(name), ids, n=3, cutoff=0.5)
    hint = f"did you mean {' or '.join(repr(c) for c in close)}? " if close else ""
    raise InputError(f"unknown preset {name!r}; {hint}presets: {', '.join(ids)}")


def readable_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a Path if it is a readable regular file, else :class:`InputError` naming it."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{what} {str(path)!r}: no such file")
    if p.is_dir():
        raise InputError(f"{what} {str(path)!r} is a directory, not a file")
    if not os.access(p, os.R_OK):
        raise InputError(f"{what} {str(path)!r} is not readable (permission denied)")
    return p


def check_dem_covers(scene: Any, dem_path: str, n: int = COVERAGE_GRID) -> None:
    """Raise :class:`InputError` unless the scene's terrain has a height under every point of an
    ``n`` x ``n`` image grid (the image footprint, pixel edges included)."""
    rows = np.linspace(-0.5, scene.n_rows - 0.5, n)
    cols = np.linspace(-0.5, scene.n_columns - 0.5, n)
    rr, cc = np.repeat(rows, n), np.tile(cols, n)
    g = scene.image_to_ground(rr, cc, height=scene.terrain.mean_height)  # (Terrain: the mean of its heights)
    z = scene.terrain.height(g[:, 0], g[:, 1])
    missing = int((~np.isfinite(z)).sum())
    if missing:
        lon, lat, _ = scene.frame.enu_to_geodetic(g) if scene.frame is not None else (g[:, 0], g[:, 1], None)
        raise InputError(
            f"DEM {dem_path!r} does not cover the image footprint: no height at {missing} of {n * n} image "
            f"points (footprint lon {np.min(lon):.4f}..{np.max(lon):.4f}, lat {np.min(lat):.4f}..{np.max(lat):.4f})")


def _dem_terrain(scene: Any, dem_path: str, dem_datum: str | None = None) -> tuple[Any, dict]:
    """``scene`` with the DEM resampled onto its local frame over the footprint (+5 %), and the DEM's coverage.

    A DEM that covers at least :data:`MIN_DEM_COVERAGE` of the image is used: the SCOPs and SCPs are simulated
    where it has heights (the lines of sight that miss it are flagged and dropped, never given a height it does
    not have), and the covered fraction is stated (``coverage["fraction"]``: of an ``n`` x ``n`` image grid,
    pixel edges included).  Less is refused with the figure.
    """
    from explorer.real.from_rpc import load_dem, terrain_from_dem
    from explorer.terrain_io import datum_statement

    height_source = load_dem(dem_path, dem_datum)
    lo_h, hi_h = float(height_source.min), float(height_source.max)
    n = COVERAGE_GRID
    rows = np.linspace(-0.5, scene.n_rows - 0.5, n)
    cols = np.linspace(-0.5, scene.n_columns - 0.5, n)
    g = scene.image_to_ground(np.repeat(rows, n), np.tile(cols, n), height=0.5 * (lo_h + hi_h))
    lon, lat, _ = scene.frame.enu_to_geodetic(g)
    covered = np.isfinite(np.asarray(height_source.height(lon, lat), dtype=np.float64))
    fraction = float(np.mean(covered))
    where = f"footprint lon {np.min(lon):.4f}..{np.max(lon):.4f}, lat {np.min(lat):.4f}..{np.max(lat):.4f}"
    if fraction < MIN_DEM_COVERAGE:
        raise InputError(
            f"DEM {dem_path!r} covers too little of the image footprint: heights at {int(covered.sum())} of {n * n} "
            f"image points ({100 * fraction:.1f} %, at least {100 * MIN_DEM_COVERAGE:.0f} % needed; {where})")
    corners = np.vstack([scene.footprint(lo_h), scene.footprint(hi_h)])
    lo, hi = corners[:, :2].min(0), corners[:, :2].max(0)
    pad = 0.05 * (hi - lo)
    terrain = terrain_from_dem(height_source, scene.frame, (lo[0] - pad[0], hi[0] + pad[0], lo[1] - pad[1],
                                                            hi[1] + pad[1]))
    if not np.isfinite(terrain.heights).any():
        raise InputError(f"DEM {dem_path!r} does not cover the image footprint at all ({where})")
    coverage = {"fraction": fraction, "grid_points": n * n, "covered_points": int(covered.sum()),
                "datum": datum_statement(height_source),
                "note": "SCOPs and SCPs are simulated where the DEM has heights; lines of sight that miss it "
                        "are flagged and left out"}
    return scene.with_terrain(terrain), coverage


def _dimap_sensor(path: Path) -> str:
    head = path.read_bytes()[:20000].decode("utf-8", "replace")
    m = re.search(r"<DATASET_NAME>DS_([A-Z]+)(\d?[A-Z]?)_", head)
    names = {"PHR": "Pleiades", "SPOT": "SPOT"}
    if m:
        return f"{names.get(m.group(1), m.group(1))} {m.group(2)}".strip()
    return "DIMAP"


# ---------------------------------------------------------------------- loading
def load_source(
    kind: str, value: str, *, dem: str | None = None, dem_datum: str | None = None, degree: int = MPC_DEGREE,
    n_gcps: int = 100, as_mpc: bool = False, stand_in: bool = True, adjusted: str | None = None,
) -> Source:
    """Resolve and load one explorer source (see the module docstring).

    Parameters
    ----------
    kind : str
        One of :data:`SOURCE_KINDS`.
    value : str
        The preset id or the file.
    dem : str, optional
        DEM (GeoTIFF or SRTM ``.hgt``) for ``rpc`` / ``dimap`` / ``dg``, read by
        :func:`explorer.terrain_io.read_dem_above_ellipsoid` (the one DEM reader of every command).
    dem_datum : {"ellipsoid", "egm96"} or None
        The DEM's vertical datum when the file declares none (``--dem-datum``; None: the default of
        ``docs/conventions.md#dem-heights``).
    degree : int
        Degree of the MPC polynomials fitted to an RPC or a rigorous model (default 3).
    n_gcps : int
        About this many GCPs per height layer for the resection of an RPC (default 100).
    as_mpc : bool
        ``rpc`` only (``--as-mpc``): the MPC resected from the RPC instead of the RPC itself (a stand-in, labelled
        so; every method runs on it).
    stand_in : bool
        Also build the stand-in model of the sensor (the MPC fit of a CSM camera, the vendor RPC of a rigorous
        model); False: the sensor alone (:func:`load_sensor`).
    adjusted : str, optional
        ``dimap`` / ``dg`` / ``isd`` (``explore --adjusted``): the sidecar ``adjusted_model.json`` that
        ``pushbroom refine`` wrote for this file; the source is then the adjusted sensor
        (:func:`explorer.refine.line_adjust.apply_sidecar`: the same class, the corrected tables), every map
        measured against it.  The file's SHA-256 must be the one the sidecar records and its kind the
        sidecar's (:func:`explorer.refine.line_adjust.read_sidecar`).

    Raises
    ------
    InputError
        Unknown preset (with a suggestion), missing / unreadable file, ``--dem`` with a kind
        that takes none, a DEM not covering the footprint.
    SceneFileError, RPCFormatError
        A file that is not what its option says (from the readers).
    """
    if kind not in SOURCE_KINDS:
        raise InputError(f"unknown source kind {kind!r}; one of {', '.join(SOURCE_KINDS)}")
    if dem is not None and kind not in DEM_KINDS:
        raise InputError(f"--dem goes with --rpc, --dimap or --dg, not --{kind}")
    if as_mpc and kind != "rpc":
        raise InputError(f"--as-mpc goes with --rpc (the MPC resected from an RPC), not --{kind}")
    if adjusted is not None and kind not in ADJUSTED_KINDS:
        raise InputError(f"--adjusted goes with --dimap, --dg or --isd (a refined line scanner's sidecar), not "
                         f"--{kind}: an adjusted RPC or scene is a file of its own (pass it as --rpc / --scene)")
    if kind == "preset":
        return Source("preset", resolve_preset(value))
    path = readable_file(value, {"scene": "scene file", "rpc": "RPC file", "dimap": "DIMAP file",
                                 "dg": "DigitalGlobe XML", "isd": "ISD file"}[kind])
    if dem is not None:
        readable_file(dem, "DEM")
    info: dict[str, Any] = {}
    report: Any = None
    scene: Any  # the Sensor: a Scene, a rigorous or CSM line-scan model, an RPC
    stand_in_model: StandIn | None = None
    if kind == "scene":
        from explorer.real.linescan import load_scene

        try:
            scene = load_scene(path)
        except (KeyError, ValueError, TypeError) as exc:
            if isinstance(exc, SceneFileError):
                raise
            raise SceneFileError(f"scene file {str(path)!r}: {exc}") from exc
        sensor = str(scene.metadata.get("source", "scene")) if isinstance(scene.metadata, dict) else "scene"
        info.update(sensor=sensor, model=type(scene).__name__)
    elif kind == "rpc" and as_mpc:
        from explorer.real.from_rpc import scene_from_rpc

        try:
            scene, report = scene_from_rpc(path, dem=dem, dem_datum=dem_datum, degree=degree, n_gcps=n_gcps,
                                           n_check=400, seed=0)
        except ValueError as exc:
            if dem is None or isinstance(exc, (InputError, SceneFileError)):  # (RPCFormatError is a SceneFileError)
                raise
            raise InputError(f"--rpc {str(path)!r} with DEM {dem!r}: {exc}") from exc
        sensor = f"RPC {report.info.get('rpc_format', '')}".strip()
        info.update(sensor=sensor,
                    model=f"STAND-IN: the MPC (degree {degree}) resected from the RPC (--as-mpc; a stand-in: every "
                          "method runs on it and is measured against it, not against the RPC)",
                    stand_in_model=True, resection=report.to_dict())
        from explorer.rpc import read_rpc
        from explorer.rpc.sensor import RPCSensor

        # what the stand-in costs, as a map: the RPC itself against the MPC the methods run on
        stand_in_model = StandIn("the RPC itself, against the MPC resected from it (on which the methods run)",
                                 RPCSensor(read_rpc(path), frame=scene.frame, name="RPC"), scene.frame)
    elif kind == "rpc":
        from explorer.rpc import read_rpc
        from explorer.rpc.sensor import RPCSensor

        rpc = read_rpc(path)
        scene = RPCSensor(rpc, name=path.name)  # the truth: the RPC itself (no scanlines)
        info.update(sensor=f"RPC {rpc.source_format}",
                    model="the RPC itself (rational function model; it has no scanlines: the search methods are "
                          "unavailable, --as-mpc runs them on its resected MPC, a stand-in)")
        if rpc.metadata.get("validity_note"):  # a declared domain that cannot be the model's (read as stated)
            info.update(validity_note=rpc.metadata["validity_note"])
    elif kind in ("dimap", "dg"):
        if kind == "dimap":
            from explorer.real.dimap import rigorous_scene_from_dimap

            rigorous, _ = rigorous_scene_from_dimap(path)
            sensor = _dimap_sensor(path) + " DIMAP"
        else:
            from explorer.real.worldview import read_dg_metadata, rigorous_scene_from_dg

            rigorous = rigorous_scene_from_dg(path)
            sensor = str(read_dg_metadata(path).get("sat_id", "DigitalGlobe")) + " DG"
        info.update(sensor=sensor, model=f"rigorous line-scan model of the {kind.upper()} metadata")
        if adjusted is not None:
            rigorous = _adjusted(rigorous, kind, path, adjusted, info)
        scene = rigorous  # the truth: the rigorous model itself (its line geometry runs every search method)
        if rigorous.rpc is not None and stand_in:
            from explorer.rpc.sensor import RPCSensor

            stand_in_model = StandIn("vendor RPC of the same image", RPCSensor(rigorous.rpc, frame=rigorous.frame,
                                                                        name="vendor RPC"), rigorous.frame)
    else:  # isd
        from explorer.real.csm_camera import read_isd
        from explorer.real.csm_scene import scene_from_camera
        from explorer.real.csm_sensor import csm_scene

        camera = read_isd(path)
        scene = csm_scene(camera)  # the truth: the camera itself (usgscsm's model)
        info.update(sensor=f"CSM {camera.metadata.get('sensor') or 'line scan'}",
                    model="USGS CSM line-scan camera (usgscsm's model)", body=scene.body.to_dict())
        if adjusted is not None:
            scene = _adjusted(scene, kind, path, adjusted, info)
            camera = scene.camera  # (its stand-in is fitted to the adjusted camera)
        if camera.covered_fraction() < 1.0:  # lines outside the ephemeris tables: flagged, measured nowhere
            info.update(table_coverage={"fraction": camera.covered_fraction(),
                                        "lines": camera.covered_line_ranges()})
        if stand_in:
            mpc = scene_from_camera(camera, degree=degree, n_check=0)
            stand_in_model = StandIn(f"MPC degree {degree} fitted to the CSM camera", mpc, scene.frame)
    if dem is not None and (kind in ("dimap", "dg") or (kind == "rpc" and not as_mpc)):
        scene, coverage = _dem_terrain(scene, dem, dem_datum)
        info.update(dem_coverage=coverage, dem_datum=coverage["datum"])
    elif dem is not None:
        check_dem_covers(scene, dem)
        if report is not None and "dem_datum" in report.info:
            info.update(dem_datum=report.info["dem_datum"])
    from explorer.scene import Scene
    from explorer.scene_checks import check_scene_physics

    if isinstance(scene, Scene):  # the physical checks of a scene file, on the scene built here (an RPC itself
        # is checked by its reader, RationalFunctionModel.validate; docs/validation.md)
        check_scene_physics(scene, str(path) if dem is None else f"{path} with DEM {dem}")
    label = f"{path.name} ({info['sensor']}" + (", resected MPC: a stand-in)" if as_mpc else
                                              ", adjusted)" if adjusted is not None else ")")
    info.update(image_rows=int(scene.n_rows), image_columns=int(scene.n_columns), truth=info["model"])
    if stand_in_model is not None:
        info.update(stand_in=stand_in_model.label)
    return Source(kind, label, scene, str(path), dem, info, report, stand_in_model)


def _adjusted(sensor: Any, kind: str, path: Path, sidecar: str, info: dict[str, Any]) -> Any:
    """``sensor`` (read from ``path``) adjusted by the refinement ``sidecar`` (its hash and kind checked); what
    was applied recorded in ``info`` (``adjusted``, and the ``model`` text says so)."""
    from explorer.refine.line_adjust import apply_sidecar, read_sidecar

    side = readable_file(sidecar, "adjusted-model sidecar")
    d, _ = read_sidecar(side, path, kind)
    adjusted = apply_sidecar(sensor, d, str(side))
    model = str(d["correction"].get("model", "?")) if isinstance(d.get("correction"), dict) else "?"
    info.update(model=f"{info['model']}, adjusted by {side.name} (the {model} correction of 'pushbroom refine')",
                adjusted={"sidecar": str(side), "correction": model, "base_file": path.name,
                          "base_sha256": d.get("base_sha256"),
                          "parameters": {str(p.get("name")): p.get("value") for p in d.get("parameters", [])
                                         if isinstance(p, dict)}})
    return adjusted


def sidecar_source(sidecar: str) -> tuple[str, str]:
    """(kind, base file) of a refinement sidecar given alone (``explore --adjusted SIDECAR``): its recorded source
    kind and the base file it names, beside it (its hash is checked when the source loads).

    Raises
    ------
    SceneFileError
        Not a sidecar, no base file named or not there, or not the file the adjustment was made on.
    """
    from explorer.refine.line_adjust import read_sidecar

    d, base = read_sidecar(readable_file(sidecar, "adjusted-model sidecar"))
    kind = str(d.get("source_kind"))
    if kind not in ADJUSTED_KINDS:
        raise SceneFileError(f"{sidecar}: unknown source kind {kind!r} in the sidecar (dimap, dg or isd)")
    return kind, str(base)


def sensor_kind(path: str | os.PathLike, kind: str = "auto") -> str:
    """What :func:`load_sensor` reads ``path`` as: ``kind`` itself, or for ``"auto"`` an ISD (a ``.json`` holding
    ``instrument_pointing``), a scene (any other ``.json``) or an RPC (anything else).

    Raises
    ------
    InputError
        A kind not in :data:`SENSOR_KINDS`.
    """
    if kind not in SENSOR_KINDS:
        raise InputError(f"unknown sensor kind {kind!r}; one of {', '.join(SENSOR_KINDS)}")
    if kind != "auto":
        return kind
    if Path(path).suffix.lower() != ".json":
        return "rpc"
    from explorer.io_input import load_json_file

    data = load_json_file(path, "JSON file")
    return "isd" if isinstance(data, dict) and "instrument_pointing" in data else "scene"


def load_sensor(path: str | os.PathLike, kind: str = "auto") -> Any:
    """The sensor of one image geometry file, the model itself and nothing else (``stereo``, ``explore --pair``):
    :func:`load_source` of :func:`sensor_kind` without its stand-in -- an RPC file is the RPC
    (:class:`~explorer.rpc.sensor.RPCSensor`), a DIMAP / DG file given as such the rigorous model, an ISD the
    CSM camera, a scene JSON the scene."""
    resolved = sensor_kind(path, kind)
    return load_source(resolved, str(path), stand_in=False).scene


def source_from_args(args: Any, **options: Any) -> Source:
    """The one source of parsed ``explore`` arguments (attributes named as :data:`SOURCE_KINDS`;
    none given: the default preset).

    ``--adjusted SIDECAR`` with ``--dimap`` / ``--dg`` / ``--isd FILE``: that file adjusted by the sidecar; alone:
    the file the sidecar names, beside it (:func:`sidecar_source`); either way its SHA-256 checked.

    Raises
    ------
    InputError
        Two sources, or ``--dem`` without a source that takes it.
    """
    given = [(k, getattr(args, k)) for k in SOURCE_KINDS if getattr(args, k, None) is not None]
    if len(given) > 1:
        raise InputError("give one source: " + " and ".join(f"--{k}" for k, _ in given) + " were both given")
    adjusted = getattr(args, "adjusted", None)
    if adjusted is not None:
        if not given:  # the sidecar alone: its base file beside it, by the name it records
            given = [sidecar_source(adjusted)]
        options = {**options, "adjusted": adjusted}
    dem = getattr(args, "dem", None)
    dem_datum = getattr(args, "dem_datum", None)
    as_mpc = bool(getattr(args, "as_mpc", False))
    if as_mpc and (not given or given[0][0] != "rpc"):
        raise InputError("--as-mpc goes with --rpc (the MPC resected from an RPC)")
    if not given:
        if dem is not None:
            raise InputError("--dem goes with --rpc, --dimap or --dg")
        if dem_datum is not None:
            raise InputError("--dem-datum goes with --dem")
        from explorer.presets import default_preset_id

        return load_source("preset", default_preset_id())
    kind, value = given[0]
    if dem_datum is not None and dem is None:
        raise InputError("--dem-datum goes with --dem")
    if as_mpc:
        options = {**options, "as_mpc": True}
    return load_source(kind, value, dem=dem, dem_datum=dem_datum, **options)


__all__ = ["ADJUSTED_KINDS", "DEM_KINDS", "DISPLAY_LINE_PERIOD_S", "SENSOR_KINDS", "SOURCE_KINDS", "Source",
           "check_dem_covers", "display_scene_of", "load_sensor", "load_source", "readable_file", "resolve_preset",
           "sensor_kind", "sidecar_source", "source_from_args", "stand_in_truth", "table_coverage_text"]
