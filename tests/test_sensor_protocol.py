"""The Sensor protocol is complete and its two entries agree (issue 23).

* Structural completeness: every class of the package (and every test double) that declares itself a sensor --
  a class attribute ``has_line_geometry`` (the flag every :class:`~explorer.sensor.Sensor` carries), or a subclass
  of one that does -- is found by reading the source (no import decides what is listed) and checked member by
  member against the protocol and the capability protocols its flags declare: each method present with the
  protocol's parameters, each data member present (class attribute, property, dataclass field, or set in
  ``__init__``).  ``isinstance`` on a runtime-checkable Protocol only checks that the names exist on an instance;
  this checks the classes themselves and their signatures.
* The geodetic entry (``geodetic_to_image`` / ``project_geodetic``) equals the local ENU entry
  (``ground_to_image`` / ``project``) at the same physical points within 1e-9 px, for every sensor kind, real
  files included (the ENU entry is the independent path: the conversion goes the other way round).
"""

from __future__ import annotations

import ast
import importlib
import inspect
import textwrap
import typing
from pathlib import Path

import numpy as np
import pytest

from explorer.sensor import (
    GeodeticSensor,
    LineCoverageSensor,
    LineGeometrySensor,
    PolynomialExteriorSensor,
    Sensor,
)

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"

#: capability flag -> the protocol it declares
CAPABILITIES = {
    "has_line_geometry": LineGeometrySensor,
    "has_polynomial_exterior": PolynomialExteriorSensor,
    "has_line_coverage": LineCoverageSensor,
    "has_geodetic_projection": GeodeticSensor,
}

#: the protocol's own machinery, not members
_NOT_MEMBERS = {"__init__", "__weakref__", "__dict__", "__module__", "__doc__", "__annotations__", "__parameters__",
                "__orig_bases__", "__subclasshook__", "__abstractmethods__", "__protocol_attrs__",
                "__non_callable_proto_members__", "__callable_proto_members_only__", "__type_params__",
                "__static_attributes__", "__firstlineno__", "__slots__", "__class_getitem__", "__init_subclass__",
                "__qualname__"}


def protocol_members(proto: type) -> dict[str, object]:
    """name -> the protocol's definition (a function, a property, or ``None`` for an annotated attribute), over the
    protocol and the protocols it extends."""
    members: dict[str, object] = {}
    for klass in reversed(proto.__mro__):
        if klass in (object, typing.Protocol, typing.Generic) or not getattr(klass, "_is_protocol", False):
            continue
        for name in getattr(klass, "__annotations__", {}):
            members.setdefault(name, None)
        for name, value in vars(klass).items():
            if name in _NOT_MEMBERS or name.startswith("_abc_") or name.startswith("_is_"):
                continue
            members[name] = value
    return members


def test_the_protocol_has_the_geodetic_entry_and_its_members_are_what_the_docs_say():
    members = protocol_members(Sensor)
    for name in ("ground_to_image", "project", "geodetic_to_image", "project_geodetic", "image_to_ground",
                 "localize", "footprint", "time_range", "frame", "body", "n_rows", "n_columns", "name",
                 "has_line_geometry"):
        assert name in members, name
    assert set(protocol_members(LineGeometrySensor)) - set(members) == {"line_time", "perspective_centre",
                                                                        "attitude", "look_direction"}
    assert set(protocol_members(GeodeticSensor)) - set(members) == {"has_geodetic_projection",
                                                                    "geodetic_localization",
                                                                    "geodetic_localization_on_dem",
                                                                    "image_to_ground_geodetic"}


# ------------------------------------------------------------------------------------------- discovery by source
def _declared_sensor_classes() -> list[tuple[str, str]]:
    """(module, class name) of every module-level class under explorer/ and tests/ that assigns
    ``has_line_geometry`` in its body, or names a class found so in its bases (by simple name), to a fixed point."""
    trees = {}
    for base in ("explorer", "tests"):
        for path in sorted((ROOT / base).rglob("*.py")):
            module = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            trees[module] = ast.parse(path.read_text(encoding="utf-8"))
    found: dict[tuple[str, str], None] = {}
    names: set[str] = set()
    changed = True
    while changed:
        changed = False
        for module, tree in trees.items():
            for node in tree.body:
                if not isinstance(node, ast.ClassDef) or (module, node.name) in found:
                    continue
                if node.name in {"Sensor", "LineGeometrySensor", "PolynomialExteriorSensor", "LineCoverageSensor",
                                 "GeodeticSensor"} and module == "explorer.sensor":
                    continue  # the protocols themselves
                declares = any(
                    (isinstance(st, ast.AnnAssign) and isinstance(st.target, ast.Name)
                     and st.target.id == "has_line_geometry")
                    or (isinstance(st, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "has_line_geometry"
                                                           for t in st.targets))
                    for st in node.body)
                bases = {b.id if isinstance(b, ast.Name) else b.attr if isinstance(b, ast.Attribute) else ""
                         for b in node.bases}
                if declares or bases & names:
                    found[(module, node.name)] = None
                    names.add(node.name)
                    changed = True
    return list(found)


DECLARED = _declared_sensor_classes()


def test_discovery_finds_every_sensor_kind_of_the_package():
    """The scan is not empty-handed: the five kinds and the adapter are among what it finds (a scan that finds
    nothing would pass every check below)."""
    for expected in [("explorer.scene", "Scene"), ("explorer.real.linescan", "RigorousLineScanScene"),
                     ("explorer.real.csm_sensor", "CsmScene"), ("explorer.rpc.sensor", "RPCSensor"),
                     ("explorer.methods.adapter", "MethodSensor"), ("tests.methods.test_base", "AffineSensor")]:
        assert expected in DECLARED, expected


def _data_members_of(cls: type) -> set[str]:
    """Names a class offers as data: class attributes, properties, annotations (dataclass fields included) and
    ``self.<name> = ...`` in any ``__init__`` / ``__post_init__`` of its MRO."""
    out: set[str] = set()
    for klass in cls.__mro__:
        if klass is object:
            continue
        out.update(vars(klass))
        out.update(getattr(klass, "__annotations__", {}))
        for init_name in ("__init__", "__post_init__"):
            fn = vars(klass).get(init_name)
            if fn is None:
                continue
            try:
                tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
            except (OSError, TypeError):
                continue
            for node in ast.walk(tree):
                if (isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store)
                        and isinstance(node.value, ast.Name) and node.value.id == "self"):
                    out.add(node.attr)
    return out


def _missing(cls: type, proto: type) -> list[str]:
    problems = []
    data = _data_members_of(cls)
    for name, spec in protocol_members(proto).items():
        mine = inspect.getattr_static(cls, name, None)
        if inspect.isfunction(spec):
            if not callable(mine):
                problems.append(f"{name}: method missing")
                continue
            want = [p for p in inspect.signature(spec).parameters.values() if p.name != "self"]
            have = inspect.signature(mine).parameters
            for p in want:
                q = have.get(p.name)
                if q is None and not any(v.kind is inspect.Parameter.VAR_POSITIONAL for v in have.values()):
                    problems.append(f"{name}: parameter {p.name!r} missing")
                elif q is not None and p.kind is inspect.Parameter.KEYWORD_ONLY and q.kind not in (
                        inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD):
                    problems.append(f"{name}: {p.name!r} is not a keyword")
            extra = [q for q in have.values() if q.name != "self" and q.name not in {p.name for p in want}
                     and q.default is inspect.Parameter.empty
                     and q.kind not in (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)]
            if extra:
                problems.append(f"{name}: extra required parameters {[q.name for q in extra]}")
        elif name not in data:
            problems.append(f"{name}: attribute missing")
    return problems


@pytest.mark.parametrize("module, name", DECLARED, ids=[f"{m}.{n}" for m, n in DECLARED])
def test_every_declared_sensor_implements_every_member_of_the_protocols_it_declares(module, name):
    cls = getattr(importlib.import_module(module), name)
    protocols = [Sensor] + [proto for flag, proto in CAPABILITIES.items() if getattr(cls, flag, False)]
    problems = {proto.__name__: _missing(cls, proto) for proto in protocols}
    assert not any(problems.values()), f"{module}.{name}: {problems}"


def test_the_structural_check_can_fail():
    """A class lacking the geodetic entry, or with a renamed parameter, is reported (the check is not vacuous)."""

    class NoGeodetic:
        has_line_geometry = False
        name = "x"

        def __init__(self):
            self.frame = self.body = self.n_rows = self.n_columns = None

        def ground_to_image(self, ground): ...
        def project(self, ground): ...
        def image_to_ground(self, row, col, *, height=None): ...
        def localize(self, row, col, *, height=None): ...
        def footprint(self, height=None): ...
        def time_range(self): ...

    assert sorted(_missing(NoGeodetic, Sensor)) == ["geodetic_to_image: method missing",
                                                   "project_geodetic: method missing"]

    class Renamed(NoGeodetic):
        def geodetic_to_image(self, lon, lat, height): ...
        def project_geodetic(self, lon, lat, h, extra): ...

    problems = _missing(Renamed, Sensor)
    assert any("'h' missing" in p for p in problems) and any("extra required" in p for p in problems)


# --------------------------------------------------------------------------------- the two entries agree
#: float64 round-off of one round trip between local ENU and geodetic coordinates on the Earth, metres (bound)
ROUNDOFF_M = 1e-8


def _px_per_metre(sensor, ground: np.ndarray) -> float:
    """Largest image motion (px) per metre of ground motion along any local axis over the points (the sensor's
    own finite differences over 1 m)."""
    r0, c0 = sensor.ground_to_image(ground)
    out = 0.0
    for k in range(3):
        step = ground.copy()
        step[:, k] += 1.0
        r1, c1 = sensor.ground_to_image(step)
        out = max(out, float(np.nanmax(np.fmax(np.abs(r1 - r0), np.abs(c1 - c0)))))
    assert 0.01 < out < 100.0  # metre-class pixels (Earth images) to 100 m pixels (CTX)
    return out


def _check_entries_agree(sensor, ground: np.ndarray, atol_px: float = 1e-9) -> int:
    """The ENU entry (``project`` / ``ground_to_image``) and the geodetic entry (``project_geodetic`` /
    ``geodetic_to_image``) at the same points, given both ways:

    * ENU first: ``ground`` to one entry, its ``frame.enu_to_geodetic`` to the other;
    * geodetic first: those (lon, lat, h) taken as the given points, their ``frame.geodetic_to_enu`` to the
      ENU entry.

    Same flags.  One of the two directions hands the model its own coordinates on both entries (geodetic for an
    RPC, local for a scene, body-fixed for a CSM camera either way) and must agree within ``atol_px``.  In the
    other, one entry sees the point after a float64 round trip through the other coordinates, which moves it by
    up to a few nm (measured 3.4e-9 m: a few ulp of body-fixed coordinates near 6.4e6 m, 9.3e-10 m each, and a
    longitude near 100 degrees holds only 1.6e-9 m per ulp); there they must agree within ``atol_px`` plus
    :data:`ROUNDOFF_M` times the sensor's px per metre (a wrong body or frame moves points by metres).
    Returns the valid count."""
    lon, lat, h = sensor.frame.enu_to_geodetic(ground)
    back = sensor.frame.geodetic_to_enu(lon, lat, h)
    assert np.max(np.linalg.norm(back - ground, axis=1)) < ROUNDOFF_M / 2  # the conversion: exact to round-off
    tol = atol_px + ROUNDOFF_M * _px_per_metre(sensor, ground)
    best = np.inf
    for enu_points in (ground, back):  # ENU first, geodetic first
        enu = sensor.project(enu_points)
        geo = sensor.project_geodetic(lon, lat, h)
        np.testing.assert_array_equal(geo.valid, enu.valid)
        np.testing.assert_array_equal(np.isnan(geo.row), np.isnan(enu.row))
        r_enu, c_enu = sensor.ground_to_image(enu_points)
        r_geo, c_geo = sensor.geodetic_to_image(lon, lat, h)
        np.testing.assert_array_equal(np.isnan(r_geo), np.isnan(r_enu))
        worst = 0.0
        for a, b in ((geo.row, enu.row), (geo.col, enu.col), (r_geo, r_enu), (c_geo, c_enu)):
            d = np.abs(a - b)
            ok = np.isfinite(d)
            assert np.all(d[ok] <= tol), f"{np.max(d[ok]) - tol:.3e} px beyond the conversion round-off"
            worst = max(worst, float(np.max(d[ok], initial=0.0)))
        best = min(best, worst)
    assert best <= atol_px, f"in neither direction within {atol_px} px: {best:.3e}"
    return int(sensor.project(ground).valid.sum())


def _points(sensor, n: int, seed: int, heights: tuple[float, float], margin: float = 0.0) -> np.ndarray:
    """Ground points (n, 3) localised by the sensor at random image points (some off the image when
    ``margin`` > 0) on random local heights."""
    rng = np.random.default_rng(seed)
    row = rng.uniform(-margin * sensor.n_rows, (1 + margin) * sensor.n_rows - 1, n)
    col = rng.uniform(-margin * sensor.n_columns, (1 + margin) * sensor.n_columns - 1, n)
    g = sensor.image_to_ground(row, col, height=rng.uniform(*heights, n))
    return g[np.isfinite(g[:, 0])]


def test_mpc_scene_entries_agree():
    from explorer.presets import build_scene

    scene = build_scene("WSU")
    ground = _points(scene, 300, 1, (-200.0, 800.0), margin=0.05)
    valid = _check_entries_agree(scene, ground)
    assert 0 < valid < ground.shape[0]  # both flags exercised


def test_rigorous_dimap_entries_agree():
    from explorer.sources import load_sensor

    scene = load_sensor(DATA / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML", "dimap")
    ground = _points(scene, 200, 2, (0.0, 600.0), margin=0.02)
    assert _check_entries_agree(scene, ground) > 100


def test_rigorous_worldview_entries_agree():
    from explorer.sources import load_sensor

    scene = load_sensor(DATA / "rpc" / "rpc_WV1.xml", "dg")
    ground = _points(scene, 200, 3, (-100.0, 500.0), margin=0.02)
    assert _check_entries_agree(scene, ground) > 100


@pytest.mark.parametrize("isd", ["ctxLineScan.json", "orbitalLineScan.json"])
def test_csm_camera_entries_agree(isd):
    from explorer.real.csm_camera import read_isd
    from explorer.real.csm_sensor import csm_scene

    scene = csm_scene(read_isd(DATA / "usgscsm" / isd))
    ground = _points(scene, 300, 4, (-300.0, 300.0), margin=0.03)
    assert _check_entries_agree(scene, ground) > 100


@pytest.mark.parametrize("name", ["RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML", "rpc_WV2.xml"])
def test_rpc_entries_agree(name):
    from explorer.rpc import read_rpc
    from explorer.rpc.sensor import RPCSensor

    sensor = RPCSensor(read_rpc(DATA / "rpc" / name))
    ground = _points(sensor, 300, 5, (-100.0, 300.0), margin=0.03)
    valid = _check_entries_agree(sensor, ground)
    assert 0 < valid < ground.shape[0]


@pytest.mark.parametrize("method", ["exact", "lrm"])
def test_method_sensor_entries_agree(method):
    from explorer.methods.adapter import MethodSensor
    from explorer.presets import build_scene

    sensor = MethodSensor.create(build_scene("WSU"), method, scops=30)
    ground = _points(sensor, 200, 6, (-200.0, 600.0))
    assert _check_entries_agree(sensor, ground) > 100


# ------------------------------------------------------------------- geodetic check points of an RPC
@pytest.mark.parametrize("dem", [False, True])
def test_rpc_check_points_keep_the_rpcs_own_geodetic_coordinates_and_the_truth_is_evaluated_on_them(dem):
    """SCPs of an RPC keep the (lon, lat, h) the RPC's localisation found (on planes and on a DEM terrain):
    truth = the RPC's own projection of those very numbers (rpc.projection called here directly), equal to the
    image points they were localised from within the localisation's convergence; the ENU ground is their
    conversion.  The explorer's truth (sensor_truth) is that projection bit for bit."""
    from explorer.app.model import sensor_truth
    from explorer.geometry.terrain import GridDEM
    from explorer.points import image_grid, simulate_points
    from explorer.rpc import read_rpc
    from explorer.rpc.sensor import RPCSensor

    rpc = read_rpc(DATA / "rpc" / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML")
    sensor = RPCSensor(rpc)
    if dem:
        fp = sensor.footprint()
        x0, y0 = fp[:, 0].min() - 500.0, fp[:, 1].min() - 500.0
        dx = (fp[:, 0].max() - x0 + 500.0) / 60
        dy = (fp[:, 1].max() - y0 + 500.0) / 60
        xx, yy = np.meshgrid(np.arange(61) * dx, np.arange(61) * dy)
        heights = sensor.mean_height + 80.0 * np.sin(xx / 900.0) * np.cos(yy / 700.0)
        sensor = sensor.with_terrain(GridDEM(float(x0), float(y0), dx, dy, heights))
    for points in (simulate_points(sensor, 400, kind="scp"), image_grid(sensor, 100, layers=3)):
        assert points.geodetic is not None and points.geodetic.shape == (len(points), 3)
        lon, lat, h = points.geodetic.T
        row, col, valid = rpc.projection(lon, lat, h, return_valid=True)
        assert valid.mean() > 0.9
        assert np.max(np.abs(row - points.row)) < 1e-6 and np.max(np.abs(col - points.col)) < 1e-6
        np.testing.assert_allclose(points.ground, sensor.frame.geodetic_to_enu(lon, lat, h), rtol=0, atol=0)
        truth = sensor_truth(sensor, points)
        keep = valid & (row >= -0.5) & (row <= sensor.n_rows - 0.5) & (col >= -0.5) & (col <= sensor.n_columns - 0.5)
        np.testing.assert_array_equal(truth.row, row[keep])
        np.testing.assert_array_equal(truth.col, col[keep])
        np.testing.assert_array_equal(truth.geodetic, points.geodetic[keep])
        sub = points.subset(np.arange(0, len(points), 3))
        np.testing.assert_array_equal(sub.geodetic, points.geodetic[::3])


def test_check_points_of_a_scene_carry_no_geodetic_coordinates():
    from explorer.points import simulate_points
    from explorer.presets import build_scene

    assert simulate_points(build_scene("WSU"), 50, kind="scp").geodetic is None
