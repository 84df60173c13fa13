"""Bundle adjustment of the public Pleiades stereo pair (shareloc, tests/data/rpc/PROVENANCE.md): both images
biased by known affines, tie points and a few GCPs; triangulated check points against the propagated error."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from explorer.errors import InputError  # noqa: E402
from explorer.refine.adjust import refine_images  # noqa: E402
from explorer.refine.points_io import PointTable  # noqa: E402
from explorer.rpc import read_rpc  # noqa: E402
from tests.refine.cases import PAIR, TRUE_PAIR, simulate_pair_points  # noqa: E402

NOISE = 0.3


@pytest.fixture(scope="module")
def pair():
    rpcs = [read_rpc(p) for p in PAIR]
    rng = np.random.default_rng(2026)
    ties = simulate_pair_points(rpcs, 300, ground_known=False, prefix="t", rng=rng)
    gcps = simulate_pair_points(rpcs, 6, ground_known=True, prefix="g", rng=rng)
    check = simulate_pair_points(rpcs, 60, ground_known=True, prefix="c", rng=rng)
    ref = refine_images(rpcs, model="affine", control=gcps, ties=ties, check=check, sigma_px=NOISE,
                      names=[p.name for p in PAIR])
    return rpcs, ties, gcps, check, ref


def test_triangulated_check_points_within_the_propagated_error(pair):
    *_, ref = pair
    ground = ref.report()["check_ground"]
    assert ground["n"] == 60
    assert ground["rmse_3d_m"] <= 1.5 * ground["predicted_rmse_3d_m"]
    # the propagated error is that of 0.3 px measurements (0.5 m pixels): tens of centimetres, not metres
    assert 0.1 < ground["predicted_rmse_3d_m"] < 2.0


def test_both_biases_recovered_within_three_sigmas(pair):
    ref = pair[-1]
    z = (ref.parameters - np.concatenate(TRUE_PAIR)) / ref.result.parameter_sigma
    assert np.all(np.abs(z) < 3.0), dict(zip(ref.parameter_names, z, strict=True))
    rep = ref.report()
    assert rep["check_rmse_px_before"] > 2.0
    # pixels of the surveyed check ground by the adjusted models: the noise plus the propagated parameter error
    # (6 GCPs fix the datum), sigma^2 + J cov J^T per coordinate with J = (1, row, col) of the affine
    rpcs, _, _, check, _ = pair
    cov = ref.result.parameter_covariance
    var = []
    for k, rpc in enumerate(rpcs):
        sel = np.asarray([i == str(k) for i in check.image])
        r, c = rpc.projection(check.lon[sel], check.lat[sel], check.h[sel])
        jac = np.stack([np.ones_like(r), r, c], axis=1)
        for axis in range(2):
            block = cov[6 * k + 3 * axis: 6 * k + 3 * axis + 3, 6 * k + 3 * axis: 6 * k + 3 * axis + 3]
            var.append(NOISE**2 + np.einsum("ni,ij,nj->n", jac, block, jac))
    predicted = np.sqrt(np.mean(np.concatenate(var)))
    assert NOISE <= rep["check_rmse_px"] <= 1.5 * predicted, (rep["check_rmse_px"], predicted)
    assert ref.result.sigma0 == pytest.approx(1.0, abs=0.15)
    assert rep["parameters"][0]["image"] == PAIR[0].name


def test_ground_cost_grows_linearly_in_points(pair):
    """The Schur complement keeps a 3 x 3 block per point: the ground covariance has one per point."""
    rpcs, ties, gcps, check, ref = pair
    assert ref.result.ground_covariance_m.shape == (6 + 300 + 60, 3, 3)


def test_tie_point_in_one_image_is_an_error(pair):
    rpcs, ties, gcps, *_ = pair
    # t0 in both images, t1 .. t9 in the second only
    one = PointTable(ties.ids[:1] + ties.ids[300:310], np.r_[ties.row[:1], ties.row[300:310]],
                     np.r_[ties.col[:1], ties.col[300:310]], image=[ties.image[0]] + ties.image[300:310])
    with pytest.raises(InputError, match="tie point 't1' is measured in one image only"):
        refine_images(rpcs, model="affine", control=gcps, ties=one)
    with pytest.raises(InputError, match="an 'image' column is needed with several images"):
        refine_images(rpcs, model="shift", control=PointTable(gcps.ids, gcps.row, gcps.col, gcps.lon, gcps.lat,
                                                            gcps.h))


def test_a_sensor_that_is_not_refinable_is_named():
    """Each image of a bundle is adapted on its own: one that no adapter refines is refused naming it."""
    rpcs = [read_rpc(p) for p in PAIR]
    rng = np.random.default_rng(3)
    gcps = simulate_pair_points(rpcs, 6, ground_known=True, prefix="g", rng=rng)
    with pytest.raises(InputError, match=r"^image right: cannot refine a dict: an RPC model, an MPC scene"):
        refine_images([rpcs[0], {"not": "a sensor"}], control=gcps, names=["left", "right"])
    with pytest.raises(InputError, match="3 image name"):
        refine_images(rpcs, control=gcps, names=["left", "right", "third"])
