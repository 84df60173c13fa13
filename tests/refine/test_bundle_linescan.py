"""Bundle adjustment of line scanners with tie points and a few GCPs: the issue's stereo acceptance check on pairs
with a known truth (tests/refine/linescan_pair.py: the rigorous models of the 2017 Pleiades DIMAP and WorldView-1
DG files and the CSM camera of the MRO CTX ISD, each with a copy moved along its orbit and turned back to the same
ground, 17-22 degrees of convergence), both images biased by known position and attitude offsets, 300 tie points,
8 GCPs and 60 check points simulated by the true sensors with 0.3 px of seeded noise.

Truths: the known biases (recovered within 3 a-posteriori sigmas); the surveyed ground of the check points
(their triangulation within 1.5x the error propagated from the adjusted covariance,
``sigma0^2 (V^-1 + V^-1 W^T S^-1 W V^-1)`` per point, see explorer/refine/bundle.py); the noise itself (sigma0 ~ 1).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from explorer.errors import InputError  # noqa: E402
from explorer.refine.adjust import refine_images  # noqa: E402
from explorer.refine.points_io import PointTable  # noqa: E402
from tests.refine.linescan_pair import NOISE_PX, biased, load_pair, simulate  # noqa: E402

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module", params=["dimap", "dg", "isd"])
def pair(request):
    a, b, bias = load_pair(request.param)
    truths = biased([a, b], bias)
    rng = np.random.default_rng(2811)
    ties = simulate(truths, a.frame, 300, rng, "t", ground_known=False)
    gcps = simulate(truths, a.frame, 8, rng, "g", ground_known=True)
    check = simulate(truths, a.frame, 60, rng, "c", ground_known=True)
    ref = refine_images([a, b], model="position-attitude", control=gcps, ties=ties, check=check, sigma_px=NOISE_PX,
                        names=["A", "B"])
    return a, b, truths, ties, gcps, check, ref, bias


def test_the_pair_is_a_stereo_pair(pair):
    """B sees A's ground from 17-22 degrees away: the central ray directions differ by that angle."""
    a, b, *_ = pair
    t0, t1 = a.time_range()
    tm = np.array([0.5 * (t0 + t1)])
    g = a.image_to_ground(np.array([0.5 * a.n_rows]), np.array([0.5 * a.n_columns]))[0]
    u = [(g - s.perspective_centre(tm)[0]) / np.linalg.norm(g - s.perspective_centre(tm)[0]) for s in (a, b)]
    assert 17.0 < np.degrees(np.arccos(u[0] @ u[1])) < 22.0
    row, col = b.ground_to_image(g[None])  # (the CSM camera's boresight is ~40 columns off its middle)
    assert abs(row[0] - 0.5 * b.n_rows) < 0.01 * b.n_rows and abs(col[0] - 0.5 * b.n_columns) < 0.01 * b.n_columns


def _ground_sample_distance(sensor) -> float:
    """Metres between the ground of two neighbouring pixels in the image's middle."""
    g = sensor.image_to_ground(np.full(2, 0.5 * sensor.n_rows), 0.5 * sensor.n_columns + np.array([0.0, 1.0]))
    return float(np.linalg.norm(g[1] - g[0]))


def test_triangulated_check_points_within_the_propagated_error(pair):
    a, *_, ref, _ = pair
    ground = ref.report()["check_ground"]
    assert ground["n"] == 60
    assert ground["rmse_3d_m"] <= 1.5 * ground["predicted_rmse_3d_m"], ground
    # per axis too (the height is the weak one of a 0.36 base / height)
    assert np.all(np.asarray(ground["rmse_enu_m"]) <= 1.5 * np.asarray(ground["predicted_rmse_enu_m"])), ground
    # 0.3 px at ~20 degrees of convergence: a pixel or so (mostly in height), not tens of pixels
    gsd = _ground_sample_distance(a)
    assert 0.1 * gsd < ground["predicted_rmse_3d_m"] < 5.0 * gsd, (ground, gsd)


def test_both_biases_recovered_within_three_sigmas(pair):
    """Each of the 12 within 3 a-posteriori sigmas; jointly, the truth's Mahalanobis distance is a chi-square(12)
    draw (below its 99.9 % quantile) while no bias at all is rejected by far: along-track position and pitch, cross-
    track position and roll are nearly collinear for a narrow field of view (correlations ~1), so single parameters
    carry large sigmas and the joint test is the sharp one."""
    from scipy.stats import chi2

    *_, ref, bias = pair
    sigma = ref.result.parameter_sigma
    truth = np.concatenate(bias)
    z = (ref.parameters - truth) / sigma
    assert np.all(np.abs(z) < 3.0), dict(zip(ref.parameter_names, np.round(z, 2), strict=True))
    inverse = np.linalg.inv(ref.result.parameter_covariance)
    d = ref.parameters - truth
    assert d @ inverse @ d < chi2.ppf(0.999, 12)
    assert ref.parameters @ inverse @ ref.parameters > 100 * chi2.ppf(0.999, 12)
    assert ref.result.sigma0 == pytest.approx(1.0, abs=0.15)
    assert not ref.result.outlier.any()
    rep = ref.report()
    assert rep["check_rmse_px_before"] > 10.0  # the biases move the images by tens of pixels
    assert rep["tie_rmse_px"] < 1.2 * NOISE_PX
    assert [p["image"] for p in rep["parameters"]] == ["A"] * 6 + ["B"] * 6
    assert rep["parameters"][0]["name"] == "A:along_m"


def test_one_block_per_ground_point(pair):
    """The Schur complement keeps a 3 x 3 block per ground point (8 GCPs fixed, 300 ties, 60 checks)."""
    *_, ref, _ = pair
    assert ref.result.ground_covariance_m.shape == (8 + 300 + 60, 3, 3)
    assert ref.result.parameter_covariance.shape == (12, 12)


@pytest.mark.parametrize("pair", ["dimap"], indirect=True)
def test_mixed_models_per_image(pair):
    """One model per image: A position-attitude (6), B attitude (3; its position bias then goes into the angles
    and the ground, so only the parameter bookkeeping is checked here)."""
    a, b, truths, ties, gcps, check, *_ = pair
    ref = refine_images([a, b], model=["position-attitude", "attitude"], control=gcps, ties=ties,
                        sigma_px=NOISE_PX, names=["A", "B"])
    assert ref.models == ["position-attitude", "attitude"] and ref.model == "position-attitude,attitude"
    assert [p.size for p in ref.result.parameters] == [6, 3]
    table = ref.parameter_table()
    assert [p["image"] for p in table] == ["A"] * 6 + ["B"] * 3
    assert ref.report()["images"][1]["model"] == "attitude"


@pytest.mark.parametrize("pair", ["dimap"], indirect=True)
def test_bad_input_is_one_line(pair):
    a, b, truths, ties, gcps, check, *_ = pair
    one = PointTable(ties.ids[:1] + ties.ids[300:305], np.r_[ties.row[:1], ties.row[300:305]],
                     np.r_[ties.col[:1], ties.col[300:305]], image=[ties.image[0]] + ties.image[300:305])
    with pytest.raises(InputError, match="tie point 't1' is measured in one image only"):
        refine_images([a, b], model="attitude", control=gcps, ties=one)
    unknown = PointTable(ties.ids, ties.row, ties.col, image=["0"] * 300 + ["C"] * 300)
    with pytest.raises(InputError, match="image 'C' is not one of the images"):
        refine_images([a, b], model="attitude", control=gcps, ties=unknown, names=["A", "B"])
    with pytest.raises(InputError, match="3 correction models for 2 images"):
        refine_images([a, b], model=["attitude"] * 3, control=gcps, ties=ties)
    with pytest.raises(InputError, match="image B: unknown rigorous line-scan model correction model 'affine'"):
        refine_images([a, b], model=["attitude", "affine"], control=gcps, ties=ties, names=["A", "B"])


@pytest.mark.parametrize("pair", ["dimap"], indirect=True)
def test_panels_of_a_line_scanner_pair(pair):
    """``refine --images`` writes panels.html unless --no-panels: every image's residual vectors and removed field,
    the parameter table, and a trajectory per line scanner."""
    from explorer.panels.refine import correction_field, refinement_html

    *_, ref, _ = pair
    html = refinement_html(ref)
    for name in ("A: residuals", "B: residuals", "A: the field the position-attitude adjustment removed",
                 "B:along_m", "A: trajectory moved by", "B: trajectory moved by"):
        assert name in html, name
    # B's removed field: the adjusted model minus the original at the ground of each pixel -- the bias seen from B
    # (tens of pixels), finite over the image
    _, _, field = correction_field(ref, 1, n=5)
    assert np.isfinite(field).all() and np.abs(field).max() > 10.0
