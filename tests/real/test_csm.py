"""USGS CSM line-scan cameras (explorer.real.csm) against usgscsm's asserted values, closed forms and
round trips.  Truths: the numbers usgscsm's tests assert on its fixtures (tests/data/usgscsm), a
straight fly-by over a sphere written in closed form here, and the distortion formulas as usgscsm
states them (written here in numpy)."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from explorer.errors import SceneFileError
from explorer.real.csm import camera_from_isd, read_isd

DATA = Path(__file__).resolve().parents[1] / "data" / "usgscsm"


@pytest.fixture(scope="module")
def const_velocity():
    return read_isd(DATA / "constVelocityLineScan.json")


@pytest.fixture(scope="module")
def orbital():
    return read_isd(DATA / "orbitalLineScan.json")


@pytest.fixture(scope="module")
def ctx():
    return read_isd(DATA / "ctxLineScan.json")


# ----------------------------------------------------------------------------- usgscsm's values
def test_const_velocity_centre_matches_usgscsm(const_velocity):
    g = const_velocity.image_to_ground([8.0], [8.0], 0.0)
    assert g.hit[0]
    np.testing.assert_allclose(g.ground[0], [9.99999500000, 0.0, 0.00999999500], rtol=0, atol=1e-10)


def test_const_velocity_off_body_is_flagged_on_the_ray(const_velocity):
    """usgscsm returns (0.0479..., -7.9996..., 16.00005) for (0, 4), a point off the 10 m sphere; we flag
    the miss, and usgscsm's point lies on our line of sight (same ray, different policy)."""
    g = const_velocity.image_to_ground([0.0], [4.0], 0.0)
    assert not g.hit[0] and np.all(np.isnan(g.ground[0]))
    centre, look = const_velocity.rays([0.0], [4.0])
    upstream = np.array([0.04799688020, -7.99961602495, 16.00004799688])
    d = upstream - centre[0]
    assert np.linalg.norm(d - np.dot(d, look[0]) * look[0]) < 1e-8
    assert np.linalg.norm(upstream) > 10.0 + 1.0  # not on the body


def test_orbital_centre_and_height(orbital):
    g = orbital.image_to_ground([8.5], [8.0], 0.0)
    np.testing.assert_allclose(g.ground[0], [999999.67004351015, 0.0, -812.35021438796923], rtol=0, atol=1e-6)
    g100 = orbital.image_to_ground([8.5], [8.0], 100.0)
    assert abs(np.linalg.norm(g100.ground[0]) - 1000100.0) < 1e-6


@pytest.mark.parametrize("height", [0.0, 100.0, 4900.0])
def test_orbital_round_trip(orbital, height):
    lines = np.linspace(0.5, 15.5, 31)
    samples = np.tile([0.5, 8.0, 15.5], 11)[:31]
    g = orbital.image_to_ground(lines, samples, height)
    r = orbital.ground_to_image(g.ground)
    assert np.all(r.valid)
    assert np.max(np.abs(r.line - lines)) <= 1e-6
    assert np.max(np.abs(r.sample - samples)) <= 1e-6


def test_ctx_round_trip_whole_image(ctx):
    rng = np.random.default_rng(7)
    n = 4000
    lines = np.concatenate([rng.uniform(0, ctx.n_lines, n), [0.0, 0.0, ctx.n_lines, ctx.n_lines]])
    samples = np.concatenate([rng.uniform(0, ctx.n_samples, n), [0.0, ctx.n_samples, 0.0, ctx.n_samples]])
    heights = np.concatenate([rng.uniform(-1000, 1000, n), np.zeros(4)])
    g = ctx.image_to_ground(lines, samples, heights)
    assert g.hit.all()
    r = ctx.ground_to_image(g.ground)
    assert r.valid.sum() >= n  # corners sit on the image edge
    assert np.max(np.abs(r.line - lines)) <= 1e-6
    assert np.max(np.abs(r.sample - samples)) <= 1e-6
    # the residual usgscsm minimises vanishes at the returned line
    res, _ = ctx.detector_residual(g.ground, r.line)
    assert np.max(np.abs(res)) < 1e-8


def test_ctx_reads_mars(ctx):
    assert ctx.semi_major_m == 3396190.0 and ctx.semi_minor_m == 3376200.0
    assert ctx.distortion_name == "radial" and ctx.n_lines == 11264 and ctx.n_samples == 5000


# ----------------------------------------------------------------------------- closed-form fly-by
R_KM, H_KM, V_KM_S, F_MM, PITCH_MM = 1000.0, 50.0, 2.0, 100.0, 0.01


def flyby_isd(*, unit="km", rates=None, line_summing=1, sample_summing=1, start_sample=0.0, order=None,
              j2000_rotation_deg=0.0, distortion=None, body_fixed=False, velocities=True, flip_signs=False,
              detector_rotation_deg=0.0, focal2pixel=None) -> dict:
    """A camera flying straight along x at altitude H over a sphere, looking straight down.

    ``detector_rotation_deg`` turns the camera by that angle about its boresight (its x axis points at
    that angle from the flight) and the focal2pixel matrix by the same angle, so that the detector line
    stays across the flight: at 90 degrees the samples run along the focal plane's x axis.
    ``focal2pixel`` (lines, samples) replaces that matrix."""
    scale = 1.0 if unit == "km" else 1000.0
    times = np.linspace(-2.0, 2.0, 41)
    pos = np.stack([V_KM_S * times, 0 * times, np.full_like(times, R_KM + H_KM)], axis=1)
    a = np.radians(j2000_rotation_deg)
    # body rotation: J2000 -> body is a rotation by +a about z (quaternion w, x, y, z)
    qb = [np.cos(a / 2), 0.0, 0.0, np.sin(a / 2)]
    rz_inv = np.array([[np.cos(a), np.sin(a), 0], [-np.sin(a), np.cos(a), 0], [0, 0, 1]])
    pos_j2000 = pos if body_fixed else pos @ rz_inv.T  # so that the body-fixed positions are the line above
    # pointing (J2000 -> sensor) makes the camera axes equal to the body axes
    th = np.radians(detector_rotation_deg)
    qp = [np.cos((a - th) / 2), 0.0, 0.0, np.sin((a - th) / 2)]  # camera -> body = R_z(th)
    c, s = np.cos(th) / PITCH_MM, np.sin(th) / PITCH_MM
    f2p_lines, f2p_samples = focal2pixel or ([0.0, c, -s], [0.0, s, c])
    isd = {
        "name_model": "USGS_ASTRO_LINE_SCANNER_SENSOR_MODEL",
        "image_lines": 400, "image_samples": 200,
        "center_ephemeris_time": 500.0, "starting_ephemeris_time": 499.0,
        "line_scan_rate": rates or [[0.5, -1.0, 0.005]],
        "detector_sample_summing": sample_summing, "detector_line_summing": line_summing,
        "focal2pixel_lines": list(f2p_lines), "focal2pixel_samples": list(f2p_samples),
        "focal_length_model": {"focal_length": F_MM},
        "detector_center": {"line": 0.0, "sample": 100.0},
        "starting_detector_line": 0.0, "starting_detector_sample": start_sample,
        "optical_distortion": distortion or {"radial": {"coefficients": [0.0, 0.0, 0.0]}},
        "radii": {"semimajor": R_KM * scale, "semiminor": R_KM * scale, "unit": unit},
        "reference_height": {"maxheight": 1000, "minheight": -1000, "unit": "m"},
        "instrument_position": {"unit": unit, "positions": (pos_j2000 * scale).tolist(),
                                "velocities": (np.gradient(pos_j2000, times, axis=0) * scale).tolist(),
                                "ephemeris_times": (times + 500.0).tolist(), "reference_frame": 1},
        "instrument_pointing": {"quaternions": [qp] * 41, "ephemeris_times": (times + 500.0).tolist(),
                                "reference_frame": 1},
        "body_rotation": {"quaternions": [qb] * 41, "ephemeris_times": (times + 500.0).tolist(),
                          "time_dependent_frames": [10099, 1], "reference_frame": 1},
    }
    if order is not None:
        isd["interpolation_order"] = order
    if body_fixed:  # positions already in the body frame (ALE's reference_frame = the body's frame code)
        isd["instrument_position"]["reference_frame"] = 10099
    if not velocities:
        del isd["instrument_position"]["velocities"]
    if flip_signs:  # q and -q are the same rotation: every other sample negated
        for table in ("instrument_pointing", "body_rotation"):
            isd[table]["quaternions"] = [[-v for v in q] if k % 2 else q
                                         for k, q in enumerate(isd[table]["quaternions"])]
    return isd


def flyby_truth_time(line: np.ndarray, rates) -> np.ndarray:
    rates = np.asarray(rates or [[0.5, -1.0, 0.005]])
    k = np.clip(np.searchsorted(rates[:, 0], line, side="right") - 1, 0, None)
    return rates[k, 1] + rates[k, 2] * (line - rates[k, 0] + 0.5)


def assert_flyby_round_trip(cam, lines: np.ndarray, samples: np.ndarray, h: np.ndarray, xb: np.ndarray,
                            yb: np.ndarray, focal_mm: float) -> None:
    """The fly-by's closed form for a detector whose undistorted body-frame focal-plane position of each image
    point is ``(xb, yb)`` mm: the line of sight ``(-xb, -yb, -f)`` from the centre at the line's time hits the
    sphere ``R + h``; ``image_to_ground`` must give that point to 1e-6 m and ``ground_to_image`` the image point
    back to 1e-7 px."""
    n = len(lines)
    d = np.stack([-xb, -yb, -np.full(n, focal_mm)], axis=1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = flyby_truth_time(lines, None)
    centre = np.stack([V_KM_S * t * 1000.0, np.zeros(n), np.full(n, (R_KM + H_KM) * 1000.0)], axis=1)
    b = np.sum(centre * d, axis=1)
    c = np.sum(centre * centre, axis=1) - (R_KM * 1000.0 + h) ** 2
    truth = centre + (-b - np.sqrt(b * b - c))[:, None] * d
    g = cam.image_to_ground(lines, samples, h)
    assert g.hit.all()
    np.testing.assert_allclose(g.ground, truth, rtol=0, atol=1e-6)
    r = cam.ground_to_image(truth)
    assert r.valid.all()
    np.testing.assert_allclose(r.line, lines, rtol=0, atol=1e-7)
    np.testing.assert_allclose(r.sample, samples, rtol=0, atol=1e-7)


def flyby_ground(line, sample, h_m, rates=None, sample_summing=1, start_sample=0.0, radial=None):
    """Closed form: time -> x; the detector direction (0, -y, -f) hits the sphere R + h (y undistorted by
    usgscsm's radial removal ``y (1 - k0 - k1 y^2 - k2 y^4)`` on the detector line x = 0)."""
    t = flyby_truth_time(line, rates)
    x = V_KM_S * t * 1000.0
    y_mm = (sample * sample_summing + start_sample - 100.0) * PITCH_MM
    if radial is not None:
        k0, k1, k2 = radial
        y_mm = y_mm * (1 - k0 - k1 * y_mm**2 - k2 * y_mm**4)
    d = np.stack([np.zeros_like(y_mm), -y_mm, -np.full_like(y_mm, F_MM)], axis=1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    s = np.stack([x, np.zeros_like(x), np.full_like(x, (R_KM + H_KM) * 1000.0)], axis=1)
    r = R_KM * 1000.0 + h_m
    b = np.sum(s * d, axis=1)
    c = np.sum(s * s, axis=1) - r * r
    lam = -b - np.sqrt(b * b - c)
    return s + lam[:, None] * d


VARIANTS = {
    "km": {},
    "metres": {"unit": "m"},
    "two-rates": {"rates": [[0.5, -1.0, 0.005], [200.5, -1.0 + 0.005 * 200, 0.0025]]},
    "summing": {"sample_summing": 2, "line_summing": 2, "start_sample": 10.0},
    "order-4": {"order": 4},
    "j2000-rotated": {"j2000_rotation_deg": 30.0},
    "body-fixed-positions": {"j2000_rotation_deg": 30.0, "body_fixed": True},
    "no-velocities": {"velocities": False, "order": 6},
    "quaternion-signs": {"j2000_rotation_deg": 50.0, "flip_signs": True},
    "radial-distortion": {"distortion": {"radial": {"coefficients": [-0.007, 3e-4, 2e-6]}}},
    "detector-along-x": {"detector_rotation_deg": 90.0},
    "detector-rotated-30": {"detector_rotation_deg": 30.0, "j2000_rotation_deg": 40.0},
    "detector-rotated-200-summing": {"detector_rotation_deg": 200.0, "sample_summing": 2, "line_summing": 2,
                                     "start_sample": 10.0},
}


@pytest.mark.parametrize("variant", sorted(VARIANTS))
@pytest.mark.parametrize("interpolation", ["usgscsm", "tables"])
def test_flyby_closed_form(variant, interpolation):
    kw = VARIANTS[variant]
    cam = camera_from_isd(flyby_isd(**kw), source=variant, interpolation=interpolation)
    rng = np.random.default_rng(3)
    n = 500
    lines = rng.uniform(0, 400, n)
    n_samples = 200 if kw.get("sample_summing", 1) == 1 else 90
    samples = rng.uniform(0, n_samples, n)
    h = rng.uniform(-500, 3000, n)
    radial = kw["distortion"]["radial"]["coefficients"] if "distortion" in kw else None
    truth = flyby_ground(lines, samples, h, kw.get("rates"), kw.get("sample_summing", 1), kw.get("start_sample", 0.0),
                         radial)
    g = cam.image_to_ground(lines, samples, h)
    assert g.hit.all()
    np.testing.assert_allclose(g.ground, truth, rtol=0, atol=1e-6)
    r = cam.ground_to_image(truth)
    # closed-form inverse: the ground's x gives the time, its (y, z) the across-track angle
    np.testing.assert_allclose(r.line, lines, rtol=0, atol=1e-7)
    np.testing.assert_allclose(r.sample, samples, rtol=0, atol=1e-7)


def test_affine_focal2pixel_closed_form():
    """Any focal2pixel matrix: offsets, unequal scales and a shear, the samples along the focal plane's x
    axis (the camera turned by 90 degrees about its boresight).  Truth: the focal-plane point of each
    (line, sample) solved from the 2 x 2 system in numpy, turned into the body frame and its ray
    (-x, -y, -f) intersected with the sphere in closed form."""
    fl = [0.4, 0.3, -1.0 / PITCH_MM]
    fs = [-2.0, 1.05 / PITCH_MM, 0.02 / PITCH_MM]
    cam = camera_from_isd(flyby_isd(detector_rotation_deg=90.0, focal2pixel=(fl, fs)), source="affine")
    rng = np.random.default_rng(5)
    n = 400
    lines, samples, h = rng.uniform(0, 400, n), rng.uniform(0, 190, n), rng.uniform(-500, 2500, n)
    # focal plane (camera axes) of each image point: fl . (1, x, y) + centre_line - start_line = 0 (the
    # detector line), fs . (1, x, y) + centre_sample = sample
    m = np.array([[fl[1], fl[2]], [fs[1], fs[2]]])
    rhs = np.stack([np.full(n, -fl[0]), samples - 100.0 - fs[0]])
    xc, yc = np.linalg.solve(m, rhs)
    xb, yb = -yc, xc  # camera -> body: R_z(90 deg)
    assert_flyby_round_trip(cam, lines, samples, h, xb, yb, F_MM)


def test_flyby_miss_and_behind_are_flagged():
    cam = camera_from_isd(flyby_isd(), source="flyby")
    # a ray far across track misses the sphere when the detector looks beyond the limb: tilt it by
    # placing the sample far outside the array
    g = cam.image_to_ground([200.0], [1e6], 0.0)
    assert not g.hit[0] and np.isnan(g.ground[0]).all()
    # a point above the camera is behind it
    r = cam.ground_to_image(np.array([[0.0, 0.0, (R_KM + 2 * H_KM) * 1000.0]]))
    assert not r.valid[0] and r.status[0] == 1 and np.isnan(r.line[0])


# ----------------------------------------------------------------------------- distortion models
def _radial_remove(c, x, y):
    rr = x * x + y * y
    dr = c[0] + rr * (c[1] + rr * c[2])
    return x * (1 - dr), y * (1 - dr)


def _transverse_apply(c, x, y):
    f = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y, x**3, x * x * y, x * y * y, y**3])
    return np.asarray(c[:10]) @ f, np.asarray(c[10:]) @ f


def _kaguya_remove(c, x, y):
    r = np.hypot(x, y)
    return (x + c[1] + c[2] * r + c[3] * r**2 + c[4] * r**3 + c[0],
            y + c[6] + c[7] * r + c[8] * r**2 + c[9] * r**3 + c[5])


MODELS = {
    "radial": ({"radial": {"coefficients": [-0.0073, 2.8e-5, 1.3e-8]}}, [-0.0073, 2.8e-5, 1.3e-8], _radial_remove,
               True),
    "transverse": ({"transverse": {"x": [1e-4, 1.0, 2e-4, 1e-5, 0, 2e-6, 1e-7], "y": [2e-4, 1e-4, 1.0, 0, 3e-6]}},
                   [1e-4, 1.0, 2e-4, 1e-5, 0, 2e-6, 1e-7, 0, 0, 0, 2e-4, 1e-4, 1.0, 0, 3e-6, 0, 0, 0, 0, 0],
                   _transverse_apply, False),
    "kaguyalism": ({"kaguyalism": {"x": [1e-4, 2e-4, 1e-6, 1e-8], "y": [-1e-4, 1e-4, 2e-6, 0],
                                   "boresight_x": 0.01, "boresight_y": -0.02}},
                   [0.01, 1e-4, 2e-4, 1e-6, 1e-8, -0.02, -1e-4, 1e-4, 2e-6, 0], _kaguya_remove, True),
    "lrolrocnac": ({"lrolrocnac": {"coefficients": [1.8e-5]}}, [1.8e-5],
                   lambda c, x, y: (x, y / (1 + c[0] * y * y)), True),
    "dawnfc": ({"dawnfc": {"coefficients": [9.2e-6]}}, [9.2e-6],
               lambda c, x, y: (x * (1 + c[0] * (x * x + y * y)), y * (1 + c[0] * (x * x + y * y))), False),
}


def _cahvor_remove(c, x, y):
    sx, sy = x - c[3], y - c[4]
    dr = c[0] + (sx * sx + sy * sy) * (c[1] + (sx * sx + sy * sy) * c[2])
    return sx * (1 - dr) + c[3], sy * (1 - dr) + c[4]


def _lunar_orbiter_remove(c, x, y):
    """ISIS LoHighDistortionMap::SetFocalPlane, restated (c: px, py, x0, y0, k0, k1)."""
    pf = 1 + c[0] * x + c[1] * y
    pcx, pcy = x * pf, y * pf
    dx, dy = pcx - c[2], pcy - c[3]
    dr = c[4] + c[5] * (dx * dx + dy * dy)
    return pcx - dr * dx, pcy - dr * dy


def _radtan_apply(c, x, y):
    """usgscsm computeRadTanDistortion (OpenCV's model) on x / f, y / f (c: k1, k2, p1, p2, k3, f)."""
    k1, k2, p1, p2, k3, f = c
    u, v = x / f, y / f
    r2 = u * u + v * v
    rad = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    return ((u * rad + 2 * p1 * u * v + p2 * (r2 + 2 * u * u)) * f,
            (v * rad + p1 * (r2 + 2 * v * v) + 2 * p2 * u * v) * f)


def _legendre_remove(c, x, y):
    """ISIS NewHorizonsMvicTdiCameraDistortionMap::SetFocalPlane with numpy's Legendre series: x scaled to
    s = -x / half, s += sum_k a_k P_i(s) P_j(0) over ISIS's term order, back to -s half; y unchanged."""
    half, a = c[0], np.asarray(c[1:])
    order = [(0, 1), (1, 0), (0, 2), (1, 1), (2, 0), (0, 3), (1, 2), (2, 1), (3, 0), (0, 4), (1, 3), (2, 2), (3, 1),
             (4, 0), (0, 5), (1, 4), (2, 3), (3, 2), (4, 1), (5, 0)]
    s = -x / half
    p = [np.polynomial.legendre.legval(s, np.eye(6)[n]) for n in range(6)]
    q = [float(np.polynomial.legendre.legval(0.0, np.eye(6)[n])) for n in range(6)]
    d = sum(a[k] * p[i] * q[j] for k, (i, j) in enumerate(order))
    return -(s + d) * half, y


def _themis_ir_remove(c, x, y):
    """ISIS ThemisIrDistortionMap::SetFocalPlane (c: k, alpha1, alpha2)."""
    k, a1, a2 = c
    return x / k, 2 * y / (1 + a1 + np.sqrt((1 + a1) ** 2 + 4 * a2 * y))


LEGENDRE_X = [2e-3, -1.5e-3, 8e-4, 1e-4, -6e-4, 2e-5, 3e-4, -1e-4, 2.5e-4, 1e-4, 5e-5, -8e-5, 4e-5, 1.2e-4, 1e-5,
              -3e-5, 2e-5, 6e-5, -2e-5, 7e-5]
MODELS.update({
    "cahvor": ({"cahvor": {"coefficients": [-0.0021, 3.1e-5, 2e-8, 0.12, -0.08]}},
               [-0.0021, 3.1e-5, 2e-8, 0.12, -0.08], _cahvor_remove, True),
    "lunarorbiter": ({"lunarorbiter": {"perspective_x": 2e-4, "perspective_y": -3e-4, "center_point_x": 0.1,
                                       "center_point_y": -0.05, "coefficients": [1.5e-4, -2e-6]}},
                     [2e-4, -3e-4, 0.1, -0.05, 1.5e-4, -2e-6], _lunar_orbiter_remove, True),
    "radtan": ({"radtan": {"coefficients": [0.031, -0.056, 1.3e-3, -1.7e-4, 2.9e-3]}},
               [0.031, -0.056, 1.3e-3, -1.7e-4, 2.9e-3, F_MM], _radtan_apply, False),
    "kplo_shadowcam": ({"kplo_shadowcam": {"coefficients": [-1.741e-05]}}, [-1.741e-05],
                       lambda c, x, y: (x, y * (1 + c[0] * y * y)), True),
    # MVIC's detector runs along the focal plane's x axis: the camera turned by 90 degrees, half = 100 px x 0.01 mm
    "legendre": ({"legendre": {"x_coefficients": LEGENDRE_X, "y_coefficients": [0.0] * 20}}, [1.0, *LEGENDRE_X],
                 _legendre_remove, True),
    "themisir": ({"themisir": {"p_k": 0.993290, "p_alpha1": 0.00447623, "p_alpha2": 0.00107556}},
                 [0.993290, 0.00447623, 0.00107556], _themis_ir_remove, True),
})
MODEL_CAMERA = {"legendre": {"detector_rotation_deg": 90.0}}
MODEL_RANGE = {"legendre": 1.0}  # ISIS's Legendre map is defined over the detector, |x| <= half


@pytest.mark.parametrize("model", sorted(MODELS))
def test_distortion_models(model):
    spec, coef, closed, closed_removes = MODELS[model]
    cam = camera_from_isd(flyby_isd(distortion=spec, **MODEL_CAMERA.get(model, {})), source=model)
    np.testing.assert_allclose(cam.distortion_coefficients, coef, rtol=1e-15, atol=0)
    rng = np.random.default_rng(1)
    span = MODEL_RANGE.get(model, 8.0)
    x, y = rng.uniform(-span, span, 300), rng.uniform(-8, 8, 300)
    fx, fy = closed(coef, x, y)
    if closed_removes:
        ux, uy = cam.remove_distortion(x, y)
        bx, by = cam.apply_distortion(fx, fy)
    else:
        ux, uy = cam.apply_distortion(x, y)
        bx, by = cam.remove_distortion(fx, fy)
    np.testing.assert_allclose(ux, fx, rtol=0, atol=1e-12)
    np.testing.assert_allclose(uy, fy, rtol=0, atol=1e-12)
    np.testing.assert_allclose(bx, x, rtol=0, atol=1e-11)
    np.testing.assert_allclose(by, y, rtol=0, atol=1e-11)
    # the camera with this distortion round-trips image -> ground -> image
    lines, samples = rng.uniform(0, 400, 200), rng.uniform(0, 200, 200)
    g = cam.image_to_ground(lines, samples, 0.0)
    r = cam.ground_to_image(g.ground[g.hit])
    assert np.max(np.abs(r.line - lines[g.hit])) <= 1e-6
    assert np.max(np.abs(r.sample - samples[g.hit])) <= 1e-6


def test_radtan_matches_usgscsm():
    """usgscsm's DistortionTests RadTanInversionTest: (5, 6) mm with f = 1000 mm distorts to
    (5.0000006007539586, 6.0000016383447505) (asserted there to 1e-8), and back."""
    isd = flyby_isd(distortion={"radtan": {"coefficients": [0.000031, -0.000056, 1.3e-5, -1.7e-6, 2.9e-8]}})
    isd["focal_length_model"]["focal_length"] = 1000.0
    cam = camera_from_isd(isd, source="radtan")
    dx, dy = cam.apply_distortion([5.0], [6.0])
    assert abs(dx[0] - 5.0000006007539586) < 1e-8 and abs(dy[0] - 6.0000016383447505) < 1e-8
    ux, uy = cam.remove_distortion(dx, dy)
    assert abs(ux[0] - 5.0) < 1e-12 and abs(uy[0] - 6.0) < 1e-12


def test_kplo_shadowcam_matches_usgscsm():
    """usgscsm's KploShadowCam tests (coefficient of the ShadowCam IK, -1.741e-5): removal at the detector's
    left edge, -18.69 mm, is closed form (1e-10); y round trips at +-0.5 .. 18 mm (1e-8); x passes through."""
    cam = camera_from_isd(flyby_isd(distortion={"kplo_shadowcam": {"coefficients": [-1.741e-05]}}), source="kplo")
    ux, uy = cam.remove_distortion([0.0], [-18.69])
    assert ux[0] == 0.0 and abs(uy[0] - (-18.69 * (1.0 + (-1.741e-05) * 18.69 * 18.69))) < 1e-10
    ys = np.array([-18.0, -5.0, -0.5, 0.5, 5.0, 18.0])
    dx, dy = cam.apply_distortion(np.zeros(6), ys)
    bx, by = cam.remove_distortion(dx, dy)
    np.testing.assert_allclose(by, ys, rtol=0, atol=1e-8)
    assert np.all(bx == 0.0)
    assert cam.remove_distortion([3.7], [-10.0])[0][0] == 3.7


@pytest.mark.parametrize("offset", [0.0, 1.0])
def test_cahvor_matches_usgscsm(offset):
    """usgscsm's RemoveDistortionCahvorTest / InverseDistortionCahvorTest: zero radial terms leave (4, 0) at
    (4, 0) whatever the offset."""
    spec = {"cahvor": {"coefficients": [0.0, 0.0, 0.0, offset, offset]}}
    cam = camera_from_isd(flyby_isd(distortion=spec), source="cahvor")
    for fn in (cam.remove_distortion, cam.apply_distortion):
        x, y = fn([4.0], [0.0])
        assert abs(x[0] - 4.0) < 1e-8 and abs(y[0]) < 1e-8


def test_lunarorbiter_block_as_ale_writes_it():
    """ALE's Lunar Orbiter 3 ISD (DOI-USGS/ale tests/pytests/data/isds/lohighcamera_isd.json) carries the
    perspective factors and the point of symmetry only (no k): read as such, the removal is ISIS's perspective
    correction x (1 + px x + py y), the radial term zero."""
    spec = {"lunarorbiter": {"perspective_x": -3e-06, "perspective_y": 8e-07, "center_point_x": -1.11,
                             "center_point_y": 0.3}}
    cam = camera_from_isd(flyby_isd(distortion=spec), source="lo3")
    np.testing.assert_array_equal(cam.distortion_coefficients, [-3e-06, 8e-07, -1.11, 0.3, 0.0, 0.0])
    x, y = np.linspace(-40, 40, 9), np.linspace(30, -30, 9)
    ux, uy = cam.remove_distortion(x, y)
    pf = 1 + -3e-06 * x + 8e-07 * y
    np.testing.assert_allclose(ux, x * pf, rtol=0, atol=1e-13)
    np.testing.assert_allclose(uy, y * pf, rtol=0, atol=1e-13)


@pytest.mark.parametrize("band", range(1, 11))
def test_themis_ir_apply_is_isis_forward_map(band):
    """ISIS ThemisIrDistortionMap::SetUndistortedFocalPlane is closed form: x k(band), y (1 + alpha1) +
    alpha2 y^2, with ISIS's published k of each band; our application (Newton on ISIS's removal) gives it."""
    k = [0.996005, 0.995358, 0.994260, 0.993290, 0.992389, 0.991474, 0.990505, 0.989611, 0.988653, 0.9877][band - 1]
    a1, a2 = 0.00447623, 0.00107556
    spec = {"themisir": {"p_k": k, "p_alpha1": a1, "p_alpha2": a2}}  # the keys ALE writes (its THEMIS IR ISD)
    cam = camera_from_isd(flyby_isd(distortion=spec), source="themis")
    ux, uy = np.linspace(-9.6, 9.6, 25), np.linspace(-1.5, 1.5, 25)
    dx, dy = cam.apply_distortion(ux, uy)
    np.testing.assert_allclose(dx, ux * k, rtol=0, atol=1e-12)
    np.testing.assert_allclose(dy, uy + a1 * uy + a2 * uy * uy, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ({"radtan": {"coefficients": [1e-5, 0, 0, 0]}}, "optical_distortion.radtan.coefficients"),
        ({"cahvor": {"coefficients": [1e-5, 0, 0]}}, "optical_distortion.cahvor.coefficients"),
        ({"legendre": {"x_coefficients": [0.0] * 19, "y_coefficients": [0.0] * 20}},
         "optical_distortion.legendre.x_coefficients"),
        ({"lunarorbiter": {"perspective_x": 0.0, "center_point_x": 0.0, "center_point_y": 0.0,
                           "coefficients": [1e-4]}}, "optical_distortion.lunarorbiter.perspective_y"),
        ({"lunarorbiter": {"perspective_x": 0.0, "perspective_y": 0.0, "center_point_x": 0.0,
                           "center_point_y": 0.0, "odk": [1e-4]}}, "optical_distortion.lunarorbiter.*odk"),
        ({"themisir": {"p_k": -1.0, "p_alpha1": 0.0, "p_alpha2": 0.0}}, "optical_distortion.themisir.p_k"),
        ({"themisir": {"p_k": 0.99, "p_alpha1": 0.0}}, "optical_distortion.themisir.p_alpha2"),
        ({"kplo_shadowcam": {"coefficients": [1e-5, 2e-5]}}, "optical_distortion.kplo_shadowcam.coefficients"),
    ],
)
def test_malformed_distortion_names_the_key(spec, match):
    with pytest.raises(SceneFileError, match=match) as exc:
        camera_from_isd(flyby_isd(distortion=spec), source="bad.json")
    assert "\n" not in str(exc.value)


# ----------------------------------------------------------------------------- errors
def test_unsupported_distortion_is_named():
    with pytest.raises(SceneFileError, match="'cassis' is not supported") as exc:
        camera_from_isd(flyby_isd(distortion={"cassis": {"coefficients": [1, 2]}}), source="x.json")
    assert str(exc.value).startswith("x.json: ") and "\n" not in str(exc.value)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda d: d.pop("focal2pixel_lines"), "focal2pixel_lines"),
        (lambda d: d["instrument_position"].pop("positions"), "instrument_position.positions"),
        (lambda d: d["instrument_position"]["positions"][3].__setitem__(1, float("nan")), "NaN"),
        (lambda d: d["radii"].__setitem__("unit", "miles"), "radii.unit"),
        (lambda d: d["focal_length_model"].__setitem__("focal_length", -5), "focal_length"),
        (lambda d: d["line_scan_rate"].__setitem__(0, [0.5, 1.0]), "line_scan_rate"),
        (lambda d: d.__setitem__("interpolation_method", "hermite"), "interpolation_method"),
    ],
)
def test_malformed_isd_names_the_key(edit, match):
    isd = copy.deepcopy(flyby_isd())
    edit(isd)
    with pytest.raises(SceneFileError, match=match):
        camera_from_isd(isd, source="bad.json")


def test_not_json(tmp_path):
    p = tmp_path / "x.json"
    p.write_text("{not json")
    with pytest.raises(SceneFileError, match="not valid JSON"):
        read_isd(p)
    p.write_text(json.dumps([1, 2]))
    with pytest.raises(SceneFileError, match="JSON object"):
        read_isd(p)


def test_line_time_two_rates_closed_form():
    rates = VARIANTS["two-rates"]["rates"]
    cam = camera_from_isd(flyby_isd(rates=rates), source="two-rates")
    lines = np.array([0.0, 0.5, 100.0, 200.4, 200.5, 200.6, 399.5, 400.0])
    np.testing.assert_allclose(cam.line_time(lines), flyby_truth_time(lines, rates), rtol=0, atol=1e-12)
    # usgscsm's map steps back by half a line of the rate change at 200.5 (each rate row times its line's
    # start, the formula its centre): the inverse is unique away from the last half line before it
    unique = lines != 200.4
    np.testing.assert_allclose(cam.time_line(cam.line_time(lines[unique])), lines[unique], rtol=0, atol=1e-9)
    assert cam.line_time(np.array([200.4]))[0] > cam.line_time(np.array([200.5]))[0]
