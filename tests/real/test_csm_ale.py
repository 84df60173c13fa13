"""Line-scan ISDs as ALE writes them for instruments usgscsm's fixtures do not cover.

* New Horizons MVIC TDI (tests/data/ale/nhmvic_tdi_isd.json, ALE's own test ISD, public domain): the
  ``legendre`` distortion with MVIC's published coefficient set (INS-98900_DISTORTION_COEF_X of the New
  Horizons kernels, in the file's naif_keywords), a detector whose samples run along the focal plane's -x
  axis, Jupiter's radii.  Truths: numpy's Legendre series (numpy.polynomial.legendre) for ISIS's
  NewHorizonsMvicTdiCameraDistortionMap, ISIS's half detector (32.5 mm), the file's own keys; the camera
  round-trips image -> ground -> image on the planet.
* Mars Odyssey THEMIS IR: the interior of ALE's THEMIS IR test ISD (DOI-USGS/ale
  tests/pytests/data/isds/themisir_isd.json: focal length 203.9213 mm, focal2pixel 20 px/mm with samples along
  x, starting detector sample 160.5, ``themisir`` p_k 0.996005, p_alpha1 0.00447623, p_alpha2 0.00107556) on a
  fly-by over a sphere built here, against the closed form: the focal-plane point of each pixel, ISIS's
  ThemisIrDistortionMap removal, the ray through the sphere.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from explorer.real.csm import camera_from_isd, read_isd
from tests.real.test_csm import F_MM, assert_flyby_round_trip, flyby_isd

MVIC = Path(__file__).resolve().parents[1] / "data" / "ale" / "nhmvic_tdi_isd.json"
ISIS_TERMS = [(0, 1), (1, 0), (0, 2), (1, 1), (2, 0), (0, 3), (1, 2), (2, 1), (3, 0), (0, 4), (1, 3), (2, 2), (3, 1),
              (4, 0), (0, 5), (1, 4), (2, 3), (3, 2), (4, 1), (5, 0)]


@pytest.fixture(scope="module")
def mvic():
    return read_isd(MVIC)


def test_mvic_reads_ales_legendre_model(mvic):
    data = json.loads(MVIC.read_text())
    published = data["naif_keywords"]["INS-98900_DISTORTION_COEF_X"]
    assert data["optical_distortion"]["legendre"]["x_coefficients"] == published
    assert mvic.distortion_name == "legendre"
    # ISIS: "half of detector in x is 32.5 mm" = 0.5 x 5000 samples x 0.013 mm
    assert mvic.distortion_coefficients[0] == pytest.approx(32.5, rel=1e-12)
    np.testing.assert_array_equal(mvic.distortion_coefficients[1:], published)


def test_mvic_distortion_is_isis_legendre_series(mvic):
    """ISIS's TDI map with MVIC's published coefficients: s = -x / 32.5, s += sum a_k P_i(s) P_j(0), x_u = -32.5 s
    (numpy's Legendre polynomials), y unchanged; and the application inverts it on the detector."""
    a = np.asarray(json.loads(MVIC.read_text())["optical_distortion"]["legendre"]["x_coefficients"])
    x = np.linspace(-32.5, 32.5, 201)
    y = np.linspace(-0.4, 0.4, 201)
    s = -x / 32.5
    legendre = np.polynomial.legendre.legval
    d = sum(a[k] * legendre(s, np.eye(6)[i]) * legendre(0.0, np.eye(6)[j]) for k, (i, j) in enumerate(ISIS_TERMS))
    ux, uy = mvic.remove_distortion(x, y)
    np.testing.assert_allclose(ux, -(s + d) * 32.5, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(uy, y)
    bx, by = mvic.apply_distortion(ux, uy)
    np.testing.assert_allclose(bx, x, rtol=0, atol=1e-11)
    np.testing.assert_allclose(by, y, rtol=0, atol=1e-12)
    assert np.max(np.abs(ux - x)) > 0.01  # the model moves points by tens of microns: the check is not vacuous


def test_mvic_round_trip_on_jupiter(mvic):
    rng = np.random.default_rng(4)
    lines, samples = rng.uniform(0, 400, 3000), rng.uniform(0, 5000, 3000)
    g = mvic.image_to_ground(lines, samples, rng.uniform(-1000, 1000, 3000))
    assert 0.1 < g.hit.mean() < 0.9  # Jupiter fills part of the 5.7 degree field from 2.3 million km
    r = mvic.ground_to_image(g.ground[g.hit])
    assert r.valid.all()
    assert np.max(np.abs(r.line - lines[g.hit])) < 1e-6
    assert np.max(np.abs(r.sample - samples[g.hit])) < 1e-6
    assert np.all(np.isnan(g.ground[~g.hit]))


# ---------------------------------------------------------------------------------------------- THEMIS IR
THEMIS_F_MM, THEMIS_K, THEMIS_A1, THEMIS_A2 = 203.9213, 0.996005, 0.00447623, 0.00107556


def themis_ir_isd() -> dict:
    isd = flyby_isd(detector_rotation_deg=90.0, focal2pixel=([0.0, 0.0, 20.0], [0.0, 20.0, 0.0]),
                    distortion={"themisir": {"p_alpha1": THEMIS_A1, "p_alpha2": THEMIS_A2, "p_k": THEMIS_K}})
    isd["image_samples"] = 320
    isd["focal_length_model"]["focal_length"] = THEMIS_F_MM
    isd["detector_center"] = {"line": 0, "sample": 0}
    isd["starting_detector_sample"] = 160.5
    return isd


def test_themis_ir_interior_closed_form():
    cam = camera_from_isd(themis_ir_isd(), source="themis_ir")
    assert F_MM != THEMIS_F_MM  # the fly-by's own focal length is replaced
    rng = np.random.default_rng(8)
    n = 400
    lines, samples, h = rng.uniform(0, 400, n), rng.uniform(0, 320, n), rng.uniform(-500, 2500, n)
    # focal plane: 20 y = 0 (the detector line), 20 x = sample + 160.5; ISIS removal: x / k, y 2y / (1 + a1 + ...)
    xd, yd = (samples + 160.5) / 20.0, np.zeros(n)
    xu = xd / THEMIS_K
    yu = 2 * yd / (1 + THEMIS_A1 + np.sqrt((1 + THEMIS_A1) ** 2 + 4 * THEMIS_A2 * yd))
    xb, yb = -yu, xu  # camera -> body: R_z(90 deg)
    assert_flyby_round_trip(cam, lines, samples, h, xb, yb, THEMIS_F_MM)
