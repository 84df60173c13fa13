"""Levenberg-Marquardt bundle adjustment against closed forms: linear least squares, robust weights, errors."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from explorer.errors import InputError  # noqa: E402
from explorer.refine.adjust import refine_images  # noqa: E402
from explorer.refine.bundle import metres_per_degree, robust_weights  # noqa: E402
from explorer.refine.points_io import PointTable  # noqa: E402
from tests.refine.cases import TRUE_AFFINE, pleiades, simulate_points  # noqa: E402


def test_affine_to_fixed_ground_is_linear_least_squares():
    """With the ground fixed the affine correction is linear: the adjustment equals numpy's lstsq, its
    covariance sigma0^2 (A^T A)^-1 sigma^2 and sigma0 the residual norm over the redundancy."""
    rpc = pleiades()
    pts = simulate_points(rpc, 25, noise_px=0.4, seed=11)
    sigma = 0.5
    ref = refine_images([rpc], model="affine", control=pts, sigma_px=sigma, loss="linear")
    r0, c0 = rpc.projection(pts.lon, pts.lat, pts.h)
    design = np.column_stack([np.ones_like(r0), r0, c0])
    p_row, res_row = np.linalg.lstsq(design, pts.row - r0, rcond=None)[:2]
    p_col, res_col = np.linalg.lstsq(design, pts.col - c0, rcond=None)[:2]
    want = np.concatenate([p_row, p_col])
    np.testing.assert_allclose(ref.parameters, want, rtol=1e-9, atol=1e-12)
    redundancy = 2 * 25 - 6
    sigma0 = np.sqrt((res_row[0] + res_col[0]) / sigma**2 / redundancy)
    assert ref.result.redundancy == redundancy
    assert ref.result.sigma0 == pytest.approx(sigma0, rel=1e-9)
    cov = sigma0**2 * sigma**2 * np.linalg.inv(design.T @ design)
    np.testing.assert_allclose(ref.result.parameter_covariance[:3, :3], cov, rtol=1e-6)
    np.testing.assert_allclose(ref.result.parameter_covariance[3:, 3:], cov, rtol=1e-6)
    assert np.allclose(ref.result.parameter_covariance[:3, 3:], 0.0, atol=1e-6 * np.abs(cov).max())
    assert abs(ref.result.parameter_correlation[0, 1]) <= 1.0


def test_shift_sigma_is_sigma0_over_root_n():
    rpc = pleiades()
    n = 30
    pts = simulate_points(rpc, n, model="shift", params=np.array([2.5, -1.0]), noise_px=0.3, seed=4)
    ref = refine_images([rpc], model="shift", control=pts, sigma_px=0.3)
    r0, c0 = rpc.projection(pts.lon, pts.lat, pts.h)
    d = np.stack([pts.row - r0, pts.col - c0], axis=1)
    np.testing.assert_allclose(ref.parameters, d.mean(axis=0), atol=1e-10)
    sigma0 = np.sqrt(np.sum((d - d.mean(axis=0)) ** 2) / 0.3**2 / (2 * n - 2))
    assert ref.result.sigma0 == pytest.approx(sigma0, rel=1e-9)
    np.testing.assert_allclose(ref.result.parameter_sigma, sigma0 * 0.3 / np.sqrt(n), rtol=1e-8)


@pytest.mark.parametrize("loss", ["huber", "cauchy"])
def test_gross_errors_are_flagged_and_do_not_bias(loss):
    rpc = pleiades()
    pts = simulate_points(rpc, 40, noise_px=0.3, seed=21)
    bad = [3, 17, 30]
    pts.row[bad] += np.array([25.0, -40.0, 12.0])
    ref = refine_images([rpc], model="affine", control=pts, sigma_px=0.3, loss=loss)
    assert np.flatnonzero(ref.result.outlier).tolist() == bad
    z = (ref.parameters - TRUE_AFFINE) / ref.result.parameter_sigma
    assert np.all(np.abs(z) < 3.0), z
    clean = refine_images([rpc], model="affine", control=PointTable(
        [pts.ids[i] for i in range(40) if i not in bad], np.delete(pts.row, bad), np.delete(pts.col, bad),
        np.delete(pts.lon, bad), np.delete(pts.lat, bad), np.delete(pts.h, bad)), sigma_px=0.3, loss="linear")
    np.testing.assert_allclose(ref.parameters, clean.parameters, rtol=1e-8, atol=1e-10)


def test_robust_weights_closed_forms():
    s = np.array([0.0, 0.5, 1.5, 3.0, 30.0])
    w, rho = robust_weights(s, "huber", 1.5)
    np.testing.assert_allclose(w, [1, 1, 1, 0.5, 0.05])
    np.testing.assert_allclose(rho, [0, 0.125, 1.125, 1.5 * 3 - 1.125, 1.5 * 30 - 1.125])
    w, rho = robust_weights(s, "cauchy", 2.0)
    np.testing.assert_allclose(w, 1 / (1 + (s / 2) ** 2))
    np.testing.assert_allclose(rho, 2.0 * np.log1p((s / 2) ** 2))
    with pytest.raises(InputError, match="unknown robust loss"):
        robust_weights(s, "tukey", 1.0)


def test_metres_per_degree_against_pyproj():
    pyproj = pytest.importorskip("pyproj")
    geod = pyproj.Geod(ellps="WGS84")
    lat = np.array([0.0, 22.0, 43.7, 80.0])
    m_lon, m_lat = metres_per_degree(lat, np.zeros(4))
    for k, phi in enumerate(lat):
        d_lon = geod.inv(0.0, phi, 1e-5, phi)[2] / 1e-5
        d_lat = geod.inv(0.0, phi - 5e-6, 0.0, phi + 5e-6)[2] / 1e-5
        assert m_lon[k] == pytest.approx(d_lon, rel=1e-8)
        assert m_lat[k] == pytest.approx(d_lat, rel=1e-8)


def test_degenerate_and_too_few_points_are_one_line_errors():
    rpc = pleiades()
    pts = simulate_points(rpc, 12, seed=2)
    with pytest.raises(InputError, match="too few control points: the affine model has 6 parameters"):
        refine_images([rpc], model="affine", control=PointTable(pts.ids[:3], pts.row[:3], pts.col[:3],
                                                              pts.lon[:3], pts.lat[:3], pts.h[:3]))
    # every point on one image column: row_per_col cannot be told from the shift
    g = np.stack([pts.lon, pts.lat, pts.h], axis=1)
    r, c = rpc.projection(g[:, 0], g[:, 1], g[:, 2])
    lon, lat = rpc.localization(r, np.full_like(c, 20000.0), g[:, 2])[:2]
    row, col = rpc.projection(lon, lat, g[:, 2])
    line = PointTable(pts.ids, row, col, lon, lat, g[:, 2])
    with pytest.raises(InputError, match="degenerate configuration.*(row_per_col|row_shift)"):
        refine_images([rpc], model="affine", control=line)
    refine_images([rpc], model="shift", control=line)  # a shift is determined by these points


def test_bad_sigmas_and_models():
    rpc = pleiades()
    pts = simulate_points(rpc, 12, seed=2)
    for kwargs, message in (({"sigma_px": 0.0}, "pixel sigma"), ({"sigma_ground_m": -1.0}, "ground sigma"),
                            ({"model": "attitude"}, "attitude models need a rigorous"),
                            ({"loss": "l1"}, "unknown robust loss"), ({"loss_scale": 0.0}, "loss scale")):
        with pytest.raises(InputError, match=message):
            refine_images([rpc], control=pts, **kwargs)


def test_a_model_too_poor_for_the_bias_flags_nothing_and_says_so():
    """A shift fitted to an affine bias leaves residuals of several px for a stated 0.3 px: the outlier test
    scales with the robust a posteriori sigma, so no point is flagged and sigma0 tells the misfit."""
    rpc = pleiades()
    pts = simulate_points(rpc, 30, noise_px=0.3, seed=8)
    ref = refine_images([rpc], model="shift", control=pts, sigma_px=0.3, loss="linear")
    assert not ref.result.outlier.any()
    assert ref.result.sigma0 > 5.0
    pts.row[5] += 200.0  # a blunder far beyond the misfit is still caught
    ref = refine_images([rpc], model="shift", control=pts, sigma_px=0.3)
    assert np.flatnonzero(ref.result.outlier).tolist() == [5]


def test_ground_sigma_is_the_generalised_least_squares_of_the_effective_covariance():
    """GCPs whose ground is known to 2 m: eliminating each ground point (the Schur complement) must give the
    generalised least squares of the shift with the effective covariance sigma^2 I + J S_g J^T of each point
    (J the pixel / metre Jacobian of the projection, by central differences here)."""
    from explorer.refine.bundle import metres_per_degree

    rpc = pleiades()
    n, sigma, sigma_g = 25, 0.3, 2.0
    pts = simulate_points(rpc, n, model="shift", params=np.array([2.0, -1.0]), noise_px=sigma, seed=12)
    rng = np.random.default_rng(13)
    m_lon, m_lat = metres_per_degree(pts.lat, pts.h)
    noisy = PointTable(pts.ids, pts.row, pts.col, pts.lon + rng.normal(0, sigma_g, n) / m_lon,
                       pts.lat + rng.normal(0, sigma_g, n) / m_lat, pts.h + rng.normal(0, sigma_g, n))
    ref = refine_images([rpc], model="shift", control=noisy, sigma_px=sigma, sigma_ground_m=sigma_g, loss="linear")
    r0, c0 = rpc.projection(noisy.lon, noisy.lat, noisy.h)
    jac = np.empty((n, 2, 3))
    for axis, step in enumerate((0.5 / m_lon, 0.5 / m_lat, np.full(n, 0.5))):
        d = [np.zeros(n), np.zeros(n), np.zeros(n)]
        d[axis] = step
        rp, cp = rpc.projection(noisy.lon + d[0], noisy.lat + d[1], noisy.h + d[2])
        rm, cm = rpc.projection(noisy.lon - d[0], noisy.lat - d[1], noisy.h - d[2])
        jac[:, 0, axis], jac[:, 1, axis] = (rp - rm) / 1.0, (cp - cm) / 1.0
    cov = sigma**2 * np.eye(2) + sigma_g**2 * jac @ jac.transpose(0, 2, 1)
    w = np.linalg.inv(cov)
    d = np.stack([noisy.row - r0, noisy.col - c0], axis=1)
    normal = w.sum(axis=0)
    shift = np.linalg.solve(normal, np.einsum("nij,nj->i", w, d))
    np.testing.assert_allclose(ref.parameters, shift, atol=1e-4)
    e = d - shift
    sigma0 = np.sqrt(np.einsum("ni,nij,nj->", e, w, e) / (2 * n - 2))
    assert ref.result.sigma0 == pytest.approx(sigma0, rel=1e-3)
    np.testing.assert_allclose(ref.result.parameter_covariance, sigma0**2 * np.linalg.inv(normal), rtol=1e-3)
