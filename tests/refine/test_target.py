"""What a refinement adjusts: the sensor itself where it is refinable, else an MPC stand-in, labelled, with its
distance from the sensor at the points measured (closed form: a truth timed 2 rows later is 2 px away)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from explorer.errors import InputError  # noqa: E402
from explorer.presets import build_scene  # noqa: E402
from explorer.refine.points_io import PointTable  # noqa: E402
from explorer.refine.target import RefineTarget, refine_target  # noqa: E402
from explorer.rpc.sensor import RPCSensor  # noqa: E402
from explorer.scene import Scene  # noqa: E402
from tests.refine.cases import pleiades  # noqa: E402

ORBITAL = Path(__file__).resolve().parents[1] / "data" / "usgscsm" / "orbitalLineScan.json"


def _table(scene, n=12, seed=0, sensor=None):
    rng = np.random.default_rng(seed)
    g = scene.image_to_ground(rng.uniform(0, scene.n_rows - 1, n), rng.uniform(0, scene.n_columns - 1, n))
    row, col = (sensor or scene).ground_to_image(g)
    lon, lat, h = scene.frame.enu_to_geodetic(g)
    return PointTable([f"p{i}" for i in range(n)], row, col, lon, lat, h)


def test_an_mpc_scene_is_refined_itself():
    scene = build_scene("WSU")
    target = refine_target(scene)
    assert target.model is scene and not target.is_stand_in and target.stand_in_error_px(_table(scene)) is None


def test_stand_in_error_is_the_distance_at_the_points():
    scene = build_scene("WSU")
    later = replace(scene, timing=replace(scene.timing, reference_row=scene.timing.reference_row - 2.0))
    # the truth images every ground point 2 rows later (t = (row - ref) * period): the stand-in is 2 px off
    target = RefineTarget(scene, "a stand-in", later)
    table = _table(scene, n=20)
    assert target.stand_in_error_px(table, None) == pytest.approx(2.0, abs=1e-6)
    assert target.stand_in_error_px(None) is None


def only_rpcs_and_mpc_scenes(model) -> bool:
    """What was refinable before the rigorous / CSM adapters: an RPC or an MPC scene."""
    from explorer.rpc.model import RationalFunctionModel
    from explorer.sensor import has_polynomial_exterior

    return isinstance(model, RationalFunctionModel) or (isinstance(model, Scene) and has_polynomial_exterior(model))


def test_a_csm_camera_is_refined_itself_or_through_its_mpc_stand_in(monkeypatch):
    from explorer.real.csm_camera import read_isd
    from explorer.real.csm_sensor import csm_scene
    from explorer.refine import target as target_module
    from explorer.refine.images import image_adapter

    camera = csm_scene(read_isd(ORBITAL))
    direct = refine_target(camera, what="the CSM camera")  # the camera itself once it is refinable
    image_adapter(direct.model)
    assert (direct.model is camera) == (not direct.is_stand_in)
    monkeypatch.setattr(target_module, "_refinable", only_rpcs_and_mpc_scenes)  # the stand-in path
    target = refine_target(camera, what="the CSM camera")
    assert target.is_stand_in and target.truth is camera and isinstance(target.model, Scene)
    assert target.label == "an MPC degree 3 fitted to the CSM camera (a stand-in)"
    f, g = target.model.frame, camera.frame  # the same ENU frame (to rounding): its trajectory is in the camera's
    assert (f.lat0_deg, f.lon0_deg, f.h0_m) == pytest.approx((g.lat0_deg, g.lon0_deg, g.h0_m), abs=1e-12)
    assert f.body == g.body
    table = _table(camera, sensor=camera)
    err = target.stand_in_error_px(table)
    row, col = target.model.ground_to_image(camera.frame.geodetic_to_enu(table.lon, table.lat, table.h))
    assert err == pytest.approx(max(np.abs(row - table.row).max(), np.abs(col - table.col).max()), rel=1e-9)
    # a refinable stand-in the source already has is taken as it is
    again = refine_target(camera, stand_ins=[target.model], what="the CSM camera")
    assert again.model is target.model and again.label == "the MPC fitted to the CSM camera (a stand-in)"


def test_a_sensor_without_scanlines_that_is_not_refinable_is_refused():
    scene = build_scene("WSU")
    with pytest.raises(InputError, match="no scanlines"):
        refine_target(RPCSensor(pleiades(), frame=scene.frame))
