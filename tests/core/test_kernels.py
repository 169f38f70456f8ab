"""The arithmetic the kernels share gives numpy's numbers bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from app.core._kernels import logaddexp, numpy_sum


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 15, 16, 17, 127, 128, 129, 255, 256, 1000, 5003])
def test_numpy_sum_adds_in_numpys_pairwise_order(n: int) -> None:
    rng = np.random.default_rng(n)
    for _ in range(5):  # magnitudes far apart, where the order of the additions shows
        x = rng.normal(size=n) * 10.0 ** rng.uniform(-8, 8, size=n)
        assert numpy_sum(x, n) == x.sum()


@pytest.mark.parametrize(("x", "y"), [(0.0, 0.0), (1.0, -np.inf), (-np.inf, -np.inf),
                                      (3.0, 2.0), (-1e300, 5.0), (700.0, 700.5)])
def test_logaddexp_is_numpys(x: float, y: float) -> None:
    assert logaddexp(x, y) == np.logaddexp(x, y)
