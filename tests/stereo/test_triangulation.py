"""explorer.stereo.triangulate against independent truths: rpcm's projections of known ground points into the
public Pleiades pair, and the closed-form collinearity of a synthetic pair in two local frames."""

from __future__ import annotations

import numpy as np
import pytest

from explorer import read_rpc
from explorer.errors import InputError
from explorer.geometry.frames import geodetic_to_ecef
from explorer.rpc.sensor import RPCSensor
from explorer.stereo import Triangulation, triangulate
from explorer.stereo.triangulation import OUTSIDE_DOMAIN, OUTSIDE_LEFT, OUTSIDE_RIGHT, PARALLEL
from tests.stereo.pairs import PHR_PAIRS, closed_form_pixels, rpcm_pair, synthetic_pair

#: Heights of the ground points, metres above WGS84: inside both RPCs' height domains (40 .. 1120 m, 40 .. 1300 m).
HEIGHTS = (60.0, 300.0, 580.0, 900.0, 1100.0)


def _ground_points(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    lon = rng.uniform(7.06, 7.29, n)
    lat = rng.uniform(43.63, 43.72, n)
    h = np.asarray(HEIGHTS)[rng.integers(0, len(HEIGHTS), n)]
    return lon, lat, h


@pytest.mark.parametrize("kind", ["xml", "geom"])
def test_pleiades_pair_recovers_rpcm_projections_within_1mm(kind):
    peer_l, peer_r = rpcm_pair()
    lon, lat, h = _ground_points(3000, seed=1)
    lcol, lrow = peer_l.projection(lon, lat, h)
    rcol, rrow = peer_r.projection(lon, lat, h)
    left, right = (read_rpc(p) for p in PHR_PAIRS[kind])
    out = triangulate(left, right, lrow, lcol, rrow, rcol)
    assert isinstance(out, Triangulation)
    assert out.valid.all(), out.flag_counts()
    truth = geodetic_to_ecef(lon, lat, h)
    assert np.max(np.linalg.norm(out.xyz - truth, axis=1)) < 1e-3
    assert np.max(np.abs(out.height - h)) < 1e-3
    assert np.max(out.ray_distance_m) < 1e-3
    assert np.max(out.reprojection_px) < 1e-6
    np.testing.assert_allclose(geodetic_to_ecef(out.lon, out.lat, out.height), out.xyz, atol=1e-6)


def test_rpc_sensors_and_generic_path_agree_with_rpcm():
    """An RPCSensor in a frame of its own with a non-RPC partner runs the generic path: same truth."""
    peer_l, peer_r = rpcm_pair()
    lon, lat, h = _ground_points(200, seed=2)
    lcol, lrow = peer_l.projection(lon, lat, h)
    rcol, rrow = peer_r.projection(lon, lat, h)
    left, right = (read_rpc(p) for p in PHR_PAIRS["xml"])

    class NotAnRPC:
        """The right RPC behind the plain Sensor interface only (forces the generic path)."""

        def __init__(self, sensor):
            self._s = sensor

        def __getattr__(self, name):
            return getattr(self._s, name)

    from explorer.geometry.frames import LocalFrame

    wrapped = NotAnRPC(RPCSensor(right, frame=LocalFrame(43.7, 7.2, 100.0)))
    out = triangulate(RPCSensor(left), wrapped, lrow, lcol, rrow, rcol)
    assert out.valid.all(), out.flag_counts()
    truth = geodetic_to_ecef(lon, lat, h)
    assert np.max(np.linalg.norm(out.xyz - truth, axis=1)) < 1e-3
    assert np.max(out.ray_distance_m) < 1e-3


def test_synthetic_pair_closed_form_intersection():
    left, right = synthetic_pair()
    rng = np.random.default_rng(3)
    enu = np.column_stack([rng.uniform(-300, 300, 400), rng.uniform(-300, 300, 400), rng.uniform(-100, 800, 400)])
    truth = left.frame.enu_to_ecef(enu)
    lrow, lcol = closed_form_pixels(left, truth)
    rrow, rcol = closed_form_pixels(right, truth)
    out = triangulate(left, right, lrow, lcol, rrow, rcol)
    assert out.valid.all(), out.flag_counts()
    assert np.max(np.linalg.norm(out.xyz - truth, axis=1)) < 1e-3
    assert np.max(out.ray_distance_m) < 1e-3
    # a known miss: shift the right pixel across the epipolar direction by 2 px; the rays then pass at a
    # distance of about 2 px x GSD x sin(convergence) and each image's reprojection error is about 1 px
    rrow2, rcol2 = closed_form_pixels(right, truth)
    moved = triangulate(left, right, lrow, lcol, rrow2 + 2.0, rcol2)
    assert moved.valid.all()
    assert np.min(moved.ray_distance_m) > 0.05
    assert np.max(moved.reprojection_px) < 2.0


def test_flags_parallel_outside_and_domain():
    left, right = (read_rpc(p) for p in PHR_PAIRS["xml"])
    # the same image twice: the two lines of sight coincide
    same = triangulate(left, left, [1000.0], [2000.0], [1000.0], [2000.0])
    assert same.flags[0] & PARALLEL and not same.valid[0] and np.isnan(same.height[0])
    peer_l, peer_r = rpcm_pair()
    lcol, lrow = peer_l.projection(7.18, 43.68, 300.0)
    rcol, rrow = peer_r.projection(7.18, 43.68, 300.0)
    out = triangulate(left, right, [lrow, -3.0, lrow], [lcol, lcol, lcol], [rrow, rrow, rrow + 30000.0],
                      [rcol, rcol, rcol])
    assert out.flags[0] == 0
    assert out.flags[1] & OUTSIDE_LEFT
    assert out.flags[2] & OUTSIDE_RIGHT
    # a point far below the RPCs' height domain
    lcol, lrow = peer_l.projection(7.18, 43.68, -3000.0)
    rcol, rrow = peer_r.projection(7.18, 43.68, -3000.0)
    low = triangulate(left, right, [lrow], [lcol], [rrow], [rcol])
    assert low.flags[0] & OUTSIDE_DOMAIN
    assert "outside RPC domain" in low.flag_counts()


def test_bad_input_is_a_clear_error():
    left, right = (read_rpc(p) for p in PHR_PAIRS["xml"])
    with pytest.raises(InputError, match="left_cols"):
        triangulate(left, right, [1.0], [np.nan], [1.0], [1.0])
    with pytest.raises(InputError, match="length"):
        triangulate(left, right, [1.0, 2.0], [1.0], [1.0], [1.0])
    with pytest.raises(InputError, match="right must be a Sensor"):
        triangulate(left, "right.xml", [1.0], [1.0], [1.0], [1.0])


def test_mixed_pair_rpc_and_mpc_scene():
    """Left: the Pleiades RPC (rpcm projects the truth); right: an MPC scene fitted to the right image's RPC by
    resection, a sensor with an orbit, in its own frame (its own ground to image projects the truth).  The
    generic path, with the perspective-centre (behind) check, recovers the points."""
    from explorer.real.from_rpc import scene_from_rpc

    peer_l, _ = rpcm_pair()
    left = read_rpc(PHR_PAIRS["xml"][0])
    right, _ = scene_from_rpc(PHR_PAIRS["xml"][1], n_gcps=60, n_check=50, seed=0)
    lon, lat, h = _ground_points(300, seed=4)
    lcol, lrow = peer_l.projection(lon, lat, h)
    truth = geodetic_to_ecef(lon, lat, h)
    rrow, rcol = right.ground_to_image(right.frame.ecef_to_enu(truth))
    out = triangulate(left, right, lrow, lcol, rrow, rcol)
    inside = (rrow >= 0) & (rrow <= right.n_rows - 1) & (rcol >= 0) & (rcol <= right.n_columns - 1)
    assert inside.sum() > 250
    assert out.valid[inside].all(), out.flag_counts()
    assert np.max(np.linalg.norm(out.xyz[inside] - truth[inside], axis=1)) < 1e-3
    assert np.max(out.ray_distance_m[inside]) < 1e-3
