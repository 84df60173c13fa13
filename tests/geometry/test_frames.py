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
