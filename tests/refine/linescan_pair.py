"""Stereo pairs of line scanners with a known truth, for the bundle-adjustment tests.

Image A is a line scanner read from a file of tests/data: the rigorous model of the 2017 Pleiades DIMAP file or
of the WorldView-1 DG file (tests/data/rpc/PROVENANCE.md), or the USGS CSM camera of the MRO CTX ISD
(tests/data/usgscsm).  Image B is a copy of it whose ephemeris is moved ``base_m`` along the orbit (a constant
offset of every position sample in the orbital frame at mid-exposure) and whose attitude is turned (a constant
rotation of every attitude sample, on the sensor side) so that B's central pixel sees the ground A's central
pixel sees: the same ground from 17-22 degrees away (:data:`PAIRS`: 250 km from Pleiades' 700 km, 200 km from
WorldView-1's ~550 km slant range, 100 km from CTX's ~300 km), 80-90 % of A's footprint inside B.  Both are built
with :func:`explorer.refine.line_adjust.adjusted_sensor`, the same class and compiled model as the file's.

The truth: each image biased by known position / attitude offsets (``TRUE_BIAS``); ground points seen by the
biased (true) sensors at random pixels and heights, their pixels measured by them with 0.3 px of seeded Gaussian
noise per coordinate.  The adjustment starts from the unbiased models A and B.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from explorer.refine.line_adjust import adjusted_sensor, correction_for
from explorer.refine.points_io import PointTable
from explorer.sources import load_source

DATA = Path(__file__).resolve().parents[1] / "data"
DIMAP_2017 = DATA / "rpc" / "PHRDIMAP_P1BP--2017030824934340CP.XML"
NOISE_PX = 0.3
BASE_M = 250e3
#: Known biases (along, cross, radial metres; roll, pitch, yaw radians) of images A and B of the Pleiades and
#: WorldView pairs: tens to a hundred pixels each (a pixel is ~1e-6 rad, 0.5-0.7 m).
TRUE_BIAS = (np.array([60.0, -40.0, 25.0, 3e-5, -2e-5, 4e-5]),
             np.array([-90.0, 50.0, -30.0, -4e-5, 3e-5, -2e-5]))
#: The CTX pair's (a pixel is ~2e-5 rad, ~6 m): 20-80 pixels.
TRUE_BIAS_CTX = (np.array([300.0, -200.0, 150.0, 4e-4, -3e-4, 5e-4]),
                 np.array([-250.0, 150.0, -100.0, -3e-4, 2e-4, -4e-4]))
#: kind -> (file, base in metres, biases)
PAIRS = {"dimap": (DIMAP_2017, BASE_M, TRUE_BIAS),
         "dg": (DATA / "rpc" / "rpc_WV1.xml", 200e3, TRUE_BIAS),
         "isd": (DATA / "usgscsm" / "ctxLineScan.json", 100e3, TRUE_BIAS_CTX)}


def load_dimap_2017():
    return load_source("dimap", str(DIMAP_2017), stand_in=False).scene


def load_pair(kind: str):
    """(A, B, biases) of the pair of a kind of :data:`PAIRS`."""
    path, base_m, bias = PAIRS[kind]
    a = load_source(kind, str(path), stand_in=False).scene
    return a, off_nadir_copy(a, base_m), bias


def off_nadir_copy(sensor, base_m: float = BASE_M):
    """The sensor moved ``base_m`` along its orbit and turned back to the ground its central pixel sees.

    The rotation taking the central ray direction from the old centre to the one from the new centre, ``R_fix``
    (local frame), is applied on the sensor side as ``R_delta = R^T R_fix R`` (``R`` the sensor -> frame attitude
    at mid-exposure), written as the correction's roll / pitch / yaw (``R_x R_y R_z``, scipy's intrinsic XYZ)."""
    corr = correction_for(sensor, "position-attitude")
    t0, t1 = sensor.time_range()
    tm = np.array([0.5 * (t0 + t1)])
    centre = sensor.image_to_ground(np.array([0.5 * sensor.n_rows]), np.array([0.5 * sensor.n_columns]))[0]
    s1 = sensor.perspective_centre(tm)[0]
    s2 = adjusted_sensor(sensor, corr, np.array([base_m, 0, 0, 0, 0, 0.0])).perspective_centre(tm)[0]
    u1 = (centre - s1) / np.linalg.norm(centre - s1)
    u2 = (centre - s2) / np.linalg.norm(centre - s2)
    axis = np.cross(u1, u2)
    r_fix = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.arcsin(np.linalg.norm(axis))).as_matrix()
    r = sensor.attitude(tm)[0]
    angles = Rotation.from_matrix(r.T @ r_fix @ r).as_euler("XYZ")
    return adjusted_sensor(sensor, corr, np.array([base_m, 0.0, 0.0, *angles]))


def biased(sensors, bias=TRUE_BIAS, model: str = "position-attitude"):
    """The true sensors: each given sensor with its known bias."""
    return [adjusted_sensor(s, correction_for(s, model), b) for s, b in zip(sensors, bias, strict=True)]


def simulate(truths, frame, n: int, rng: np.random.Generator, prefix: str, *, ground_known: bool,
             noise_px: float = NOISE_PX, margin: float = 0.06) -> PointTable:
    """Ground points seen inside every true sensor (``margin`` off each edge), one row per image: the true
    sensor's pixels + ``noise_px`` Gaussian noise (``image`` "0", "1", ...), ground (lon, lat, h in ``frame``)
    kept when ``ground_known``."""
    first = truths[0]
    picked: list[np.ndarray] = []
    pixels: list[list[np.ndarray]] = [[] for _ in truths]
    while sum(p.shape[0] for p in picked) < n:
        m = 2 * n
        g = first.image_to_ground(rng.uniform(margin, 1 - margin, m) * (first.n_rows - 1),
                                  rng.uniform(margin, 1 - margin, m) * (first.n_columns - 1),
                                  height=rng.uniform(-100.0, 600.0, m))
        ok = np.isfinite(g).all(axis=1)
        rc = []
        for t in truths:
            gt = np.where(ok[:, None], g, 0.0)
            if t.frame is not first.frame:  # (a sensor read from its own file has its own local frame)
                gt = t.frame.geodetic_to_enu(*first.frame.enu_to_geodetic(gt))
            r, c = t.ground_to_image(gt)
            ok &= (np.isfinite(r) & (r >= margin * (t.n_rows - 1)) & (r <= (1 - margin) * (t.n_rows - 1))
                   & (c >= margin * (t.n_columns - 1)) & (c <= (1 - margin) * (t.n_columns - 1)))
            rc.append((r, c))
        picked.append(g[ok])
        for k, (r, c) in enumerate(rc):
            pixels[k].append(np.stack([r[ok], c[ok]], axis=1))
    ground = np.concatenate(picked)[:n]
    lon, lat, h = frame.enu_to_geodetic(ground)
    ids, rows, cols, image = [], [], [], []
    for k in range(len(truths)):
        px = np.concatenate(pixels[k])[:n]
        ids += [f"{prefix}{i}" for i in range(n)]
        rows.append(px[:, 0] + rng.normal(0.0, noise_px, n))
        cols.append(px[:, 1] + rng.normal(0.0, noise_px, n))
        image += [str(k)] * n
    k = len(truths)
    return PointTable(ids, np.concatenate(rows), np.concatenate(cols), np.tile(lon, k) if ground_known else None,
                      np.tile(lat, k) if ground_known else None, np.tile(h, k) if ground_known else None,
                      image=image)
