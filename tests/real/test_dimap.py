"""Pleiades DIMAP v1.4 rigorous model (ephemeris, WGS84 attitudes) with the interior orientation
and product timing calibrated on the file's RPC, checked on independent points.

Measured (docs/real_images.md): 2018 scene 0.0004 px RMS (max 0.0008), 2017 scene 0.0045 px;
the calibrated line period is the nominal 0.0735 ms of Pleiades products in both.  With the
raw 8 Hz attitude samples instead of their cubic fit the model disagrees by 1.8 px RMS, only as
a function of time: the product is resampled to a "perfect sensor" with a smooth attitude."""

import numpy as np
import pytest

from explorer.geometry.frames import geodetic_to_ecef
from explorer.real.compare import compare_with_rpc
from explorer.real.dimap import read_dimap_v1_geometry, rigorous_scene_from_dimap
from explorer.real.linescan import quaternion_to_matrix
from explorer.real.timeutil import parse_utc, seconds_between
from explorer.rpc import read_rpc
from explorer.scene import Scene

from .conftest import PHR_2017, PHR_2018


def test_reader_and_quaternion_convention():
    md = read_dimap_v1_geometry(PHR_2017)
    assert (md["rows"], md["columns"]) == (49826, 39951)
    assert md["eph_position"].shape == (10, 3) and md["att_quaternion"].shape == (35, 4)
    assert md["line_period_raw_s"] == pytest.approx(0.1034063389e-3)
    np.testing.assert_allclose(np.linalg.norm(md["att_quaternion"], axis=1), 1.0, atol=1e-9)
    # scalar-first quaternions rotating body -> ECEF: body +z looks at the image centre
    rpc = read_rpc(PHR_2017)
    lon, lat, _ = rpc.localization(24912.5, 19975.0, rpc.height_offset)
    ground = geodetic_to_ecef(lon, lat, rpc.height_offset)
    k = 17
    t_k = parse_utc(md["att_times"][k])
    t_eph = np.array([seconds_between(t_k, parse_utc(s)) for s in md["eph_times"]])
    j = int(np.argmin(np.abs(t_eph)))
    sat = md["eph_position"][j] + md["eph_velocity"][j] * (-t_eph[j])  # straight-line step (< 30 s)
    look = (ground - sat) / np.linalg.norm(ground - sat)
    body = quaternion_to_matrix(md["att_quaternion"][k][None])[0].T @ look
    assert body[2] > np.cos(np.radians(1.0))


@pytest.mark.parametrize(("path", "bound"), [(PHR_2018, 0.002), (PHR_2017, 0.01)])
def test_calibrated_rigorous_model_reproduces_the_rpc(path, bound):
    scene, cal = rigorous_scene_from_dimap(path, n_gcps=100, n_check=300)
    assert cal.rmse_px < bound and cal.check_rmse_px < bound
    assert cal.line_period_s == pytest.approx(0.0735e-3, rel=2e-5)
    assert 0.0 < cal.epoch_minus_origin_s < 0.1  # row 0 a few hundred lines after ORIGIN_TIME
    cmp = compare_with_rpc(scene, n=200, layers=3, refit=False)
    assert cmp.rms_px < bound and cmp.max_px < 3 * bound


def test_raw_attitude_samples_disagree_as_a_function_of_time_only():
    scene, cal = rigorous_scene_from_dimap(PHR_2018, attitude_smoothing=None, n_gcps=80, n_check=100)
    assert cal.check_rmse_px > 1.0
    rows = np.linspace(0, scene.n_rows - 1, 15)
    cols = np.linspace(0, scene.n_columns - 1, 7)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    g = scene.image_to_ground(rr.ravel(), cc.ravel(), height=scene.rpc.height_offset)
    lon, lat, h = scene.frame.enu_to_geodetic(g)
    r, c = scene.rpc.projection(lon, lat, h)
    dr = (r - rr.ravel()).reshape(rr.shape)
    dc = (c - cc.ravel()).reshape(rr.shape)
    profile = np.hypot(dr.mean(axis=1), dc.mean(axis=1))  # per row (time)
    spread = np.hypot(dr.std(axis=1), dc.std(axis=1))  # across the swath
    assert profile.max() > 1.0  # large along time ...
    assert spread.max() < 0.1 * profile.max()  # ... nearly constant across the swath


def test_aberration_is_not_in_the_vendor_model():
    scene, cal = rigorous_scene_from_dimap(PHR_2018, aberration=True, n_gcps=80, n_check=200)
    assert 0.01 < cal.check_rmse_px < 0.08  # measured 0.033, vs 0.0004 without


def test_conversion_to_mpc_and_json(tmp_path):
    scene, _ = rigorous_scene_from_dimap(PHR_2018, n_gcps=80, n_check=50)
    mpc, report = scene.to_mpc_scene(degree=3, n=80, n_check=200)
    assert report.rmse_px < 0.005 and report.check_rmse_px < 0.005  # measured 0.0007 / 0.0006
    mpc.save(tmp_path / "phr.json")
    assert Scene.load(tmp_path / "phr.json").n_rows == 38248


def test_calibrated_on_the_top_half_it_agrees_with_the_rpc_on_the_held_out_bottom_half():
    """The interior is fitted to RPC points of rows 0..N/2 only; on the other rows only the DIMAP ephemeris and
    attitude carry the model, and the vendor RPC (CNES's fit to its own rigorous model) checks them there."""
    n_rows = read_dimap_v1_geometry(PHR_2018)["rows"]
    half = (n_rows - 1) / 2.0
    full, cal_full = rigorous_scene_from_dimap(PHR_2018, n_gcps=200, n_check=50)
    scene, cal = rigorous_scene_from_dimap(PHR_2018, n_gcps=200, n_check=50, control_rows=(0.0, half))
    assert cal.n_gcps < 0.6 * cal_full.n_gcps  # only the top half's control points were used
    rr, cc = np.meshgrid(np.linspace(half + 1, n_rows - 1, 9), np.linspace(0, scene.n_columns - 1, 9), indexing="ij")
    g = scene.image_to_ground(rr.ravel(), cc.ravel(), height=scene.rpc.height_offset)
    lon, lat, h = scene.frame.enu_to_geodetic(g)
    r, c = scene.rpc.projection(lon, lat, h)
    d = np.hypot(r - rr.ravel(), c - cc.ravel())
    assert np.sqrt(np.mean(d**2)) < 0.002 and d.max() < 0.005
    assert cal.line_period_s == pytest.approx(0.0735e-3, rel=1e-6)  # never given to the fit


@pytest.mark.parametrize("rows", [(100.0, 50.0), (0.0, np.nan), (5.0, 10.0)])
def test_control_rows_without_enough_points_or_malformed_is_an_input_error(rows):
    from explorer.errors import InputError

    with pytest.raises(InputError, match="control_rows"):
        rigorous_scene_from_dimap(PHR_2018, n_gcps=50, n_check=10, control_rows=rows)
