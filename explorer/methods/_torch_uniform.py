"""torch's seeded uniform draws without torch: the same float64 values as ``torch.rand(..., generator=g,
dtype=torch.float64)`` on a CPU generator ``g = torch.Generator().manual_seed(seed)``, from numpy's Mersenne
Twister.

The networks' first weights (``mlp``, ``ann``, ``bpnn``, ``nn-rfm``: Nguyen-Widrow and uniform starts) were drawn
by torch's CPU generator.  Training them without torch (:mod:`explorer.methods._lm_compiled`) must start from the
same weights, bit for bit, and without importing torch (about 1.3 s, twice per export: the command and its sweep
worker).  torch's CPU generator is the standard MT19937 (``init_genrand`` of the seed's low 32 bits; torch's
``at::mt19937``); a float64 uniform takes two 32-bit outputs ``hi``, ``lo`` as the 64-bit word ``hi << 32 | lo``
and keeps its low 53 bits times ``2**-53`` (torch's ``uniform_real_distribution<double>`` over ``random64()``),
drawn serially in the tensor's row-major order.  numpy's legacy ``RandomState`` seeds MT19937 the same way and its
``MT19937`` bit generator yields the raw 32-bit outputs.  tests/methods/test_torch_uniform.py compares with torch
itself (seeds below and above 2**32, several calls in a row, 1-D and 2-D shapes).
"""

from __future__ import annotations

import numpy as np

__all__ = ["TorchUniform"]

_LOW53 = np.uint64((1 << 53) - 1)


class TorchUniform:
    """A stream of float64 uniforms in [0, 1) equal to those of a seeded torch CPU generator.

    Parameters
    ----------
    seed : int
        As ``torch.Generator().manual_seed(seed)`` (any non-negative int below 2**64; torch, too, uses its low 32
        bits).

    Examples
    --------
    >>> u = TorchUniform(0)
    >>> a = u.rand(3)        # torch.rand(3, generator=g, dtype=torch.float64)
    >>> b = u.rand((2, 4))   # the next torch.rand(2, 4, generator=g, dtype=torch.float64)
    """

    def __init__(self, seed: int) -> None:
        seed = int(seed)
        if seed < 0 or seed >= 2**64:
            raise ValueError(f"seed must lie in [0, 2**64), got {seed}")
        key = np.random.RandomState(seed & 0xFFFFFFFF).get_state()[1]  # type: ignore[index]  # init_genrand(low 32 bits), as torch
        self._bits = np.random.MT19937(0)
        self._bits.state = {"bit_generator": "MT19937", "state": {"key": key, "pos": 624}}

    def rand(self, shape: int | tuple[int, ...]) -> np.ndarray:
        """The next uniforms in [0, 1), float64 array of ``shape`` (an int: 1-D), drawn in row-major order."""
        dims = (int(shape),) if np.ndim(shape) == 0 else tuple(int(s) for s in shape)  # type: ignore[arg-type, union-attr]
        n = int(np.prod(dims, dtype=np.int64))
        raw = self._bits.random_raw(2 * n)  # uint64 holding 32-bit outputs
        words = (raw[0::2] << np.uint64(32)) | raw[1::2]
        return ((words & _LOW53).astype(np.float64) * 2.0**-53).reshape(dims)
