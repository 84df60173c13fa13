"""What a method needs, declared on its class (``needs_line_geometry``), against what a sensor offers; and the
learned methods on a sensor without scanlines (an RPC), their column from the pairs (issue 23).

Independent truths: a sensor whose image coordinates are affine in the ground (closed form: ``lrm``'s row and the
column model are exact), and the RPC's own projection (``RationalFunctionModel.projection`` of the geodetic
coordinates) for the learned methods on a real Pleiades RPC.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import pytest

from explorer.errors import MethodUnavailableError
from explorer.geometry.frames import LocalFrame
from explorer.geometry.terrain import FlatTerrain
from explorer.methods import available, create, registry, unavailable_reason
from explorer.points import simulate_points
from explorer.presets import build_scene
from explorer.rpc import read_rpc
from explorer.rpc.sensor import RPCSensor
from explorer.sensor import Localization, Projection, Sensor, inside_image
from tests.rpc.conftest import RPC_DIR

PAIRS_ONLY = ("lrm", "prm", "mlp", "ann", "ogp", "rfm", "bpnn", "nn-rfm")
"""The issue's learned and generalized methods: they need only ground / image pairs."""


@dataclass
class AffineSensor:
    """A sensor without scanlines whose row and column are affine functions of local ENU (closed form)."""

    row_coef: np.ndarray  # (r0, a_x, a_y, a_z)
    col_coef: np.ndarray
    n_rows: int = 3000
    n_columns: int = 2000
    name: str = "affine"
    frame: LocalFrame = field(default_factory=lambda: LocalFrame(45.0, 5.0, 0.0))
    terrain: FlatTerrain = field(default_factory=lambda: FlatTerrain(200.0))
    has_line_geometry: ClassVar[bool] = False

    @property
    def body(self):
        return self.frame.body

    @property
    def shape(self):
        return (self.n_rows, self.n_columns)

    def ground_to_image(self, ground):
        g = np.atleast_2d(ground)
        return self.row_coef[0] + g @ self.row_coef[1:], self.col_coef[0] + g @ self.col_coef[1:]

    def project(self, ground):
        r, c = self.ground_to_image(ground)
        return Projection(r, c, inside_image(r, c, self.n_rows, self.n_columns))

    def geodetic_to_image(self, lon, lat, h):
        return self.ground_to_image(self.frame.geodetic_to_enu(lon, lat, h))

    def project_geodetic(self, lon, lat, h):
        return self.project(self.frame.geodetic_to_enu(lon, lat, h))

    def image_to_ground(self, row, col, *, height=None):
        z = np.broadcast_to(self.terrain.height_m if height is None else np.asarray(height, float), np.shape(row))
        a = np.array([self.row_coef[1:3], self.col_coef[1:3]])
        rhs = np.stack([row - self.row_coef[0] - self.row_coef[3] * z, col - self.col_coef[0] - self.col_coef[3] * z])
        xy = np.linalg.solve(a, rhs)
        return np.column_stack([xy[0], xy[1], z])

    def localize(self, row, col, *, height=None):
        g = self.image_to_ground(row, col, height=height)
        return Localization(g, np.zeros(len(g), np.int8))

    def footprint(self, height=None):
        r1, c1 = self.n_rows - 0.5, self.n_columns - 0.5
        return self.image_to_ground(np.array([-0.5, -0.5, r1, r1]), np.array([-0.5, c1, c1, -0.5]), height=height)

    def time_range(self):
        raise NotImplementedError("no time axis")

    def ground_sample_distance(self):
        return (2.0, 2.0)


@pytest.fixture(scope="module")
def affine():
    # 2 m pixels, rows along a track turned 10 degrees from north, a little height parallax on both axes
    a = np.deg2rad(10.0)
    return AffineSensor(np.array([1500.0, 0.5 * np.sin(a), 0.5 * np.cos(a), 0.02]),
                        np.array([1000.0, 0.5 * np.cos(a), -0.5 * np.sin(a), -0.03]))


@pytest.fixture(scope="module")
def pleiades():
    return RPCSensor(read_rpc(RPC_DIR / "RPC_PHR1B_P_201709281038045_SEN_PRG_FC_178608-001.XML"), name="PHR RPC")


def test_every_method_declares_whether_it_needs_scanlines():
    reg = registry()
    for name, cls in reg.items():
        assert cls.needs_line_geometry is (cls.family == "search"), name
    assert {n for n, c in reg.items() if not c.needs_line_geometry} >= set(PAIRS_ONLY)


def test_search_methods_are_unavailable_on_an_rpc_with_the_reason(pleiades):
    scene = build_scene("WSU")
    for name in available():
        assert unavailable_reason(name, scene) is None
        reason = unavailable_reason(name, pleiades)
        if name in PAIRS_ONLY:
            assert reason is None, name
            continue
        assert reason is not None and name in reason and "--as-mpc" in reason and "PHR RPC" in reason
        with pytest.raises(MethodUnavailableError, match="has none"):
            create(name, pleiades)
        with pytest.raises(MethodUnavailableError):  # also when the class is built directly
            registry()[name](pleiades)


def test_closed_form_sensor_without_scanlines_lrm_is_exact(affine):
    assert isinstance(affine, Sensor)
    scops = simulate_points(affine, 30, kind="scop")
    assert np.isnan(scops.time).all()  # no scanlines, no time
    scps = simulate_points(affine, 2000, kind="scp")
    r_true, c_true = affine.ground_to_image(scps.ground)
    for name in ("lrm", "prm", "rfm"):
        m = create(name, affine).fit(scops)
        res = m.ground_to_image(scps.ground)
        assert res.valid.all(), name
        assert np.max(np.abs(res.row - r_true)) < 1e-8 and np.max(np.abs(res.col - c_true)) < 1e-8, name
        assert np.all(res.ce_evaluations == 0)
    info = create("lrm", affine).fit(scops).fit_info["column_model"]
    assert info["degree"] == 3 and info["train_max_px"] < 1e-8  # 30 SCOPs, 10 coefficients: 3 per coefficient


def test_column_model_degree_follows_the_scop_count(affine):
    for n, degree in ((4, 1), (10, 1), (12, 2), (19, 2), (20, 3)):
        info = create("lrm", affine).fit(simulate_points(affine, n, kind="scop")).fit_info["column_model"]
        assert info["degree"] == degree, n


def test_learned_methods_on_an_rpc_give_row_and_column_of_the_rpc_itself(pleiades):
    """100 SCOPs on the RPC's height plane; truth: the RPC's projection of the check points' geodetic
    coordinates.  Bars from the measured errors (issue 23, Pleiades 22,940 x 40,000 px)."""
    scops = simulate_points(pleiades, 100, kind="scop")
    scps = simulate_points(pleiades, 5000, kind="scp")
    r_true, c_true = pleiades.rpc.projection(*pleiades.frame.enu_to_geodetic(scps.ground))
    assert np.max(np.abs(r_true - scps.row)) < 1e-6 and np.max(np.abs(c_true - scps.col)) < 1e-6
    bars = {"lrm": 20.0, "prm": 2.0, "ann": 0.05, "ogp": 0.01, "rfm": 1e-3}  # row, px (measured 17, 1.5, 0.016 ...)
    for name, row_bar in bars.items():
        m = create(name, pleiades).fit(scops)
        res = m.ground_to_image(scps.ground)
        assert res.valid.all(), name
        assert np.max(np.abs(res.row - r_true)) < row_bar, name
        col_bar = 1e-4 if name == "rfm" else 0.01  # the RFM's own column; the cubic column model (0.0057 px)
        assert np.max(np.abs(res.col - c_true)) < col_bar, name
        assert ("column_model" in m.fit_info) is (m.column_source == "collinearity"), name


def test_on_a_scene_the_column_still_comes_from_the_collinearity():
    scene = build_scene("WSU")
    scops = simulate_points(scene, 100, kind="scop")
    m = create("lrm", scene).fit(scops)
    assert "column_model" not in m.fit_info
    res = m.ground_to_image(scops.ground[:10])
    assert np.all(res.ce_evaluations == 1)


def test_the_column_model_between_height_layers():
    """SCOPs on 3 height layers (as ortho fits a learned method): the column model's power of Z stays below the
    layer count, so between the layers it is the RPC's column too (a cubic in Z was 3 px off 18 m from a layer).
    Truth: the RPC's own localisation of random pixels at heights between and beyond the layers."""
    import dataclasses

    from explorer.methods.adapter import MethodSensor

    rpc = read_rpc(RPC_DIR / "PHRDIMAP_P1BP--2018122638935449CP.XML")
    sensor = RPCSensor(dataclasses.replace(rpc, image_size=(600, 600)))
    h = float(rpc.height_offset)
    m = MethodSensor.create(sensor, "lrm", height_range=(h - 100, h + 100), scops=100).method
    assert m.fit_info["column_model"]["height_degree"] == 2
    rng = np.random.default_rng(0)
    row, col = rng.uniform(0, 599, 3000), rng.uniform(0, 599, 3000)
    for dz in (0.0, -18.0, -60.0, 90.0, 130.0):
        ground = sensor.image_to_ground(row, col, height=h + dz)
        res = m.ground_to_image(ground)
        assert np.max(np.abs(res.col - col)) < 1e-4, dz  # measured 1.4e-6 px within the layers
