import numpy as np
import pyproj
import pytest

from explorer.geometry.frames import LocalFrame, ecef_to_geodetic, geodetic_to_ecef

TO_ECEF = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)


@pytest.fixture
def geodetic_points():
    rng = np.random.default_rng(1)
    lon = rng.uniform(-180, 180, 500)
    lat = rng.uniform(-89.9, 89.9, 500)
    h = rng.uniform(-500, 900_000, 500)
    return lon, lat, h


def test_geodetic_to_ecef_matches_pyproj(geodetic_points):
    lon, lat, h = geodetic_points
    ours = geodetic_to_ecef(lon, lat, h)
    x, y, z = TO_ECEF.transform(lon, lat, h)
    assert np.max(np.abs(ours - np.stack([x, y, z], axis=1))) < 1e-3


def test_ecef_to_geodetic_matches_pyproj(geodetic_points):
    lon, lat, h = geodetic_points
    x, y, z = TO_ECEF.transform(lon, lat, h)
    lon2, lat2, h2 = ecef_to_geodetic(np.stack([x, y, z], axis=1))
    # 1 mm on the ground: 1e-3 m / 6.4e6 m ~ 9e-9 deg
    assert np.max(np.abs(lon2 - lon) * np.cos(np.radians(lat))) < 9e-9
    assert np.max(np.abs(lat2 - lat)) < 9e-9
    assert np.max(np.abs(h2 - h)) < 1e-3


def test_local_frame_against_pyproj_topocentric():
    frame = LocalFrame(32.72, -117.16, 0.0)
    enu = np.array([[0.0, 0.0, 0.0], [1000.0, -2500.0, 60.0], [-3e5, 2e5, 7.7e5]])
    lon, lat, h = frame.enu_to_geodetic(enu)
    topo = pyproj.Transformer.from_pipeline(
        "+proj=pipeline +step +proj=cart +ellps=WGS84 "
        "+step +proj=topocentric +ellps=WGS84 +lon_0=-117.16 +lat_0=32.72 +h_0=0"
    )
    e, n, u = topo.transform(lon, lat, h)
    assert np.max(np.abs(np.stack([e, n, u], axis=1) - enu)) < 1e-3
    back = frame.geodetic_to_enu(lon, lat, h)
    assert np.max(np.abs(back - enu)) < 1e-6


def test_utm_zone():
    assert LocalFrame(32.72, -117.16).utm_epsg() == 32611
    assert LocalFrame(-33.84, 151.20).utm_epsg() == 32756


# ------------------------------------------------------------------ other bodies (Ellipsoid)
@pytest.mark.parametrize("body_name", ["MARS", "MOON"])
def test_other_body_geodetic_matches_pyproj(geodetic_points, body_name):
    from explorer.geometry import frames

    body = getattr(frames, body_name)
    lon, lat, h = geodetic_points
    geod = {"proj": "longlat", "a": body.a_m, "b": body.b_m, "no_defs": True}
    cart = {"proj": "geocent", "a": body.a_m, "b": body.b_m, "units": "m", "no_defs": True}
    to_xyz = pyproj.Transformer.from_crs(pyproj.CRS(geod), pyproj.CRS(cart), always_xy=True)
    x, y, z = to_xyz.transform(lon, lat, h)
    ours = geodetic_to_ecef(lon, lat, h, body)
    assert np.max(np.abs(ours - np.stack([x, y, z], axis=1))) < 1e-3
    lon2, lat2, h2 = ecef_to_geodetic(np.stack([x, y, z], axis=1), body)
    assert np.max(np.abs(lat2 - lat)) < 1e-8
    assert np.max(np.abs(h2 - h)) < 1e-3


def test_local_frame_on_mars_round_trip_and_serialisation():
    from explorer.geometry.frames import MARS, WGS84, Ellipsoid

    frame = LocalFrame(-4.5, 137.4, -4500.0, MARS)
    enu = np.array([[0.0, 0.0, 0.0], [1000.0, -2500.0, 60.0], [-3e4, 2e4, 2.5e5]])
    lon, lat, h = frame.enu_to_geodetic(enu)
    assert abs(lat[0] + 4.5) < 1e-12 and abs(lon[0] - 137.4) < 1e-12 and abs(h[0] + 4500.0) < 1e-6
    assert np.max(np.abs(frame.geodetic_to_enu(lon, lat, h) - enu)) < 1e-6
    # the origin sits on Mars' ellipsoid, not the Earth's: |ECEF| is about Mars' radius
    assert abs(np.linalg.norm(frame.origin_ecef) - 3.3937e6) < 3e3
    again = LocalFrame.from_dict(frame.to_dict())
    assert again == frame and again.body == MARS
    earth = LocalFrame(10.0, 20.0, 5.0)
    assert "body" not in earth.to_dict() and LocalFrame.from_dict(earth.to_dict()).body == WGS84
    with pytest.raises(ValueError, match="UTM"):
        frame.utm_epsg()
    with pytest.raises(ValueError, match="positive"):
        Ellipsoid("bad", -1.0, 1.0)
