"""The bundle adjustment's sparse structure at 100,000 observations: 50,000 tie points in two images (150,000
ground unknowns) and 8 GCPs, through two affine cameras with different height parallax (a closed-form projector,
so that the test is about the solver's structure, not a sensor's cost).

A normal matrix over all ground points would be 150,012^2 doubles (180 GB): the adjustment has to keep 3 x 3
blocks per point (the Schur complement of explorer/refine/bundle.py).  Checked: the peak of memory traced during
the whole adjustment stays below 1 GB (it is ~0.2 GB: arrays of a few doubles per observation), the known image
shifts are recovered within 3 a-posteriori sigmas; and on a small copy the Schur solution and its covariances
equal the dense least-squares solution (the problem is linear: ``numpy.linalg.lstsq`` and ``(J^T J)^-1``).
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytestmark = pytest.mark.slow

from explorer.refine.bundle import BundleProblem, bundle_adjust  # noqa: E402

N_TIES = 50_000
N_GCPS = 8
SIGMA_PX = 0.3
#: Pixels per degree of longitude / latitude and per metre of height of each image (B looks from the side: its
#: columns move with height), and each image's true shift (row, col) in pixels.
CAMERAS = (np.array([[0.0, -2e5, 0.0], [2e5, 0.0, 0.0]]), np.array([[0.0, -2e5, 0.0], [2e5, 0.0, 0.6]]))
SHIFTS = (np.array([3.0, -2.0]), np.array([-1.5, 4.0]))
LON0, LAT0 = 2.0, 45.0


class AffineCamera:
    """(row, col) = M (lon - lon0, lat - lat0, h) + (row_shift, col_shift) + 5000: torch in, torch out."""

    parameter_names = ("row_shift", "col_shift")

    def __init__(self, m: np.ndarray) -> None:
        self.m = m

    def project(self, lon, lat, h, params):
        m = self.m
        x = (lon - LON0, lat - LAT0, h)
        row = 5000.0 + sum(float(m[0, k]) * x[k] for k in range(3)) + params[:, 0]
        col = 5000.0 + sum(float(m[1, k]) * x[k] for k in range(3)) + params[:, 1]
        return row, col

    def numpy(self, ground: np.ndarray, shift: np.ndarray) -> np.ndarray:
        x = ground - np.array([LON0, LAT0, 0.0])
        return 5000.0 + x @ self.m.T + shift


@pytest.fixture(scope="module")
def solved():
    problem, truth = _problem(N_TIES, 100_000)
    tracemalloc.start()
    try:
        result = bundle_adjust(problem, loss="linear")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return problem, result, truth, peak


def test_memory_stays_per_point(solved):
    problem, result, _, peak = solved
    assert problem.measured.shape[0] == 2 * (N_TIES + N_GCPS) > 100_000
    assert peak < 1e9, f"peak traced memory {peak / 1e9:.2f} GB"
    assert result.ground_covariance_m.shape == (N_TIES + N_GCPS, 3, 3)


def test_shifts_recovered_within_three_sigmas(solved):
    _, result, _, _ = solved
    z = (np.concatenate(result.parameters) - np.concatenate(SHIFTS)) / result.parameter_sigma
    assert np.all(np.abs(z) < 3.0), z
    assert result.sigma0 == pytest.approx(1.0, abs=0.02)


def _problem(n_ties: int, seed: int):
    rng = np.random.default_rng(seed)
    m = n_ties + N_GCPS
    truth = np.stack([LON0 + rng.uniform(-0.02, 0.02, m), LAT0 + rng.uniform(-0.02, 0.02, m),
                      rng.uniform(0.0, 500.0, m)], axis=1)
    cams = [AffineCamera(c) for c in CAMERAS]
    measured = np.concatenate([c.numpy(truth, s) for c, s in zip(cams, SHIFTS, strict=True)])
    measured += rng.normal(0.0, SIGMA_PX, measured.shape)
    start = truth.copy()
    start[N_GCPS:, 2] += 30.0  # tie points start 30 m off their truth (as a localisation on a mean height would)
    sigma_g = np.full((m, 3), np.inf)
    sigma_g[:N_GCPS] = 0.0
    return BundleProblem(projectors=cams, initial_parameters=[np.zeros(2), np.zeros(2)], ground=start,
                         ground_sigma_m=sigma_g, image_index=np.repeat([0, 1], m),
                         point_index=np.tile(np.arange(m), 2), measured=measured, sigma_px=SIGMA_PX), truth


def test_schur_solution_equals_the_dense_least_squares():
    """On a small copy (8 GCPs, 300 ties; the cameras are affine, so the problem is linear) the whole dense
    least-squares system -- 4 shifts and 900 ground offsets in metres, ``numpy.linalg.lstsq`` and ``(J^T J)^-1``
    -- gives the same parameters, sigma0, parameter covariance and ground covariance blocks."""
    from explorer.refine.bundle import metres_per_degree

    problem, _ = _problem(300, 7)
    result = bundle_adjust(problem, loss="linear")
    m = problem.ground.shape[0]
    free = np.arange(N_GCPS, m)
    m_lon, m_lat = metres_per_degree(problem.ground[:, 1], problem.ground[:, 2])
    n_obs = problem.measured.shape[0]
    jac = np.zeros((2 * n_obs, 4 + 3 * free.size))
    rhs = np.zeros(2 * n_obs)
    for i in range(n_obs):  # (a small dense reference: 616 observations)
        k, j = problem.image_index[i], problem.point_index[i]
        cam = CAMERAS[k]
        model = AffineCamera(cam).numpy(problem.ground[j][None], np.zeros(2))[0]
        for c in range(2):
            jac[2 * i + c, 2 * k + c] = 1.0
            if j >= N_GCPS:
                col = 4 + 3 * (j - N_GCPS)
                jac[2 * i + c, col:col + 3] = cam[c] / np.array([m_lon[j], m_lat[j], 1.0])
            rhs[2 * i + c] = problem.measured[i, c] - model[c]
    x, *_ = np.linalg.lstsq(jac, rhs, rcond=None)
    redundancy = jac.shape[0] - jac.shape[1]
    sigma0 = np.sqrt(np.sum((rhs - jac @ x) ** 2) / SIGMA_PX**2 / redundancy)
    cov = sigma0**2 * SIGMA_PX**2 * np.linalg.inv(jac.T @ jac)
    assert result.redundancy == redundancy
    assert result.sigma0 == pytest.approx(sigma0, rel=1e-6)
    np.testing.assert_allclose(np.concatenate(result.parameters), x[:4], rtol=0, atol=1e-6)
    np.testing.assert_allclose(result.parameter_covariance, cov[:4, :4], rtol=1e-6, atol=1e-12)
    blocks = np.stack([cov[4 + 3 * q:7 + 3 * q, 4 + 3 * q:7 + 3 * q] for q in range(free.size)])
    np.testing.assert_allclose(result.ground_covariance_m[free], blocks, rtol=1e-6, atol=1e-12)
