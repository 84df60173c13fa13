"""The sigmoid networks' own back-propagated Jacobian (SigmoidMLP.per_sample_jacobian) against torch's automatic
differentiation (vmap of jacrev, the Jacobian levenberg_marquardt used before) and a central difference."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from explorer.methods._lm import SigmoidMLP  # noqa: E402


@pytest.mark.parametrize(("n_in", "hidden"), [(3, (10,)), (4, (7, 5)), (1, (1,)), (3, (20, 3, 4))])
def test_back_propagated_jacobian_equals_autograd(n_in, hidden):
    net = SigmoidMLP(n_in, hidden)
    gen = torch.Generator().manual_seed(3)
    theta = net.init_params(gen) + 0.3 * torch.randn(net.n_params, generator=gen, dtype=torch.float64)
    x = torch.randn(64, n_in, generator=gen, dtype=torch.float64) * 2.0
    mine = net.per_sample_jacobian(theta, x)
    auto = torch.func.vmap(torch.func.jacrev(lambda th, xi: net.forward(th, xi[None, :])[0]), in_dims=(None, 0))(
        theta, x)
    assert mine.shape == auto.shape == (64, net.n_params)
    np.testing.assert_allclose(mine.numpy(), auto.numpy(), rtol=1e-12, atol=1e-14)
    # and a central difference of the forward pass (independent of both)
    h = 1e-6
    for p in range(0, net.n_params, max(1, net.n_params // 7)):
        e = torch.zeros(net.n_params, dtype=torch.float64)
        e[p] = h
        fd = (net.forward(theta + e, x) - net.forward(theta - e, x)) / (2 * h)
        np.testing.assert_allclose(mine[:, p].numpy(), fd.numpy(), rtol=1e-6, atol=1e-8)
