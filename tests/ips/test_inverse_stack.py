"""The closed-form inverses of the learning's small normal matrices (``inverse_stack``) against
LAPACK's."""

from __future__ import annotations

import numpy as np
import pytest

from omnical.ips.solve._kernels import inverse_stack


@pytest.mark.parametrize("k", [2, 3])
def test_inverses_agree_with_lapack_and_singular_ones_are_filled(k: int) -> None:
    rng = np.random.default_rng(k)
    j = rng.normal(size=(500, 6, k))
    normal = np.einsum("fmi,fmj->fij", j, j)  # symmetric positive definite
    normal[7] = np.outer(j[7, 0], j[7, 0])  # rank one: singular
    normal[8] = 0.0
    inverse, good = inverse_stack(normal, np.nan)
    assert good.tolist() == [i not in (7, 8) for i in range(500)]
    want = np.linalg.inv(normal[good])
    np.testing.assert_allclose(inverse[good], want, rtol=1e-10, atol=0.0)
    assert np.isnan(inverse[~good]).all()
    assert np.array_equal(inverse, np.swapaxes(inverse, 1, 2), equal_nan=True)
    zero, _ = inverse_stack(normal, 0.0)
    assert (zero[~good] == 0.0).all()
