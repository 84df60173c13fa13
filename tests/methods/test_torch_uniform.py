"""explorer.methods._torch_uniform.TorchUniform against torch itself: the same float64 uniforms, bit for bit, as
``torch.rand(..., generator=torch.Generator().manual_seed(seed), dtype=torch.float64)`` for several calls in a row,
1-D and 2-D shapes, and seeds below and above 2**32 (torch uses the low 32 bits)."""

from __future__ import annotations

import numpy as np
import pytest

from explorer.methods._torch_uniform import TorchUniform

torch = pytest.importorskip("torch")


@pytest.mark.parametrize("seed", [0, 1, 12345, 2**32 - 1, 2**32 + 5, 2**40 + 7, 2**62 - 3])
def test_the_draws_equal_torch_rand_bit_for_bit(seed):
    gen = torch.Generator().manual_seed(seed)
    ours = TorchUniform(seed)
    for shape in [3, 17, 1, (4, 5), 0, 5000, (7, 3)]:
        expected = torch.rand(shape, generator=gen, dtype=torch.float64).numpy()
        got = ours.rand(shape)
        assert got.shape == expected.shape
        assert got.dtype == np.float64
        np.testing.assert_array_equal(got, expected)


def test_a_seed_outside_torchs_range_is_refused():
    with pytest.raises(ValueError, match="seed"):
        TorchUniform(-1)
    with pytest.raises(ValueError, match="seed"):
        TorchUniform(2**64)


def test_the_draws_lie_in_the_unit_interval_and_differ_by_seed():
    a, b = TorchUniform(3).rand(10_000), TorchUniform(4).rand(10_000)
    assert a.min() >= 0.0 and a.max() < 1.0
    assert not np.array_equal(a, b)
    assert abs(a.mean() - 0.5) < 0.01  # 10,000 uniforms: sd of the mean 0.0029
