"""The arithmetic the kernels share gives its plain-Python readings bit for bit, on any CPU."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core import _kernels
from app.core._kernels import logaddexp, pairwise_sum
from tests.core import reference

SIZES = [0, 1, 7, 8, 9, 15, 16, 17, 127, 128, 129, 255, 256, 1000, 5003]


@pytest.mark.parametrize("n", SIZES)
def test_the_pairwise_sum_adds_in_its_written_order(n: int) -> None:
    rng = np.random.default_rng(n)
    for _ in range(5):  # magnitudes far apart, where the order of the additions shows
        x = rng.normal(size=n) * 10.0 ** rng.uniform(-8, 8, size=n)
        assert pairwise_sum(x, n) == reference.pairwise_sum(x)


def test_the_pairwise_sum_reads_only_the_first_n_and_is_accurate() -> None:
    x = np.concatenate([np.full(1000, 0.1), [1e300]])
    assert pairwise_sum(x, 1000) == pytest.approx(100.0, rel=1e-14)  # a naive loop: 1e-13


@pytest.mark.parametrize(
    ("x", "y"),
    [(0.0, 0.0), (1.0, -np.inf), (-np.inf, -np.inf), (3.0, 2.0), (-1e300, 5.0), (700.0, 700.5)],
)
def test_logaddexp_is_numpys_formula_on_libm(x: float, y: float) -> None:
    if x == y:
        expected = x + math.log(2.0)
    else:
        big, small = max(x, y), min(x, y)
        expected = big + math.log1p(math.exp(small - big))
    assert logaddexp(x, y) == expected


def test_elementwise_exp_and_log_are_libms_on_any_shape_and_layout() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(scale=50.0, size=(7, 13))
    for view in (x, x[:, 1:8], x.T, x[3]):  # contiguous, strided, transposed, one row
        out = _kernels.exp(view)
        assert out.shape == view.shape
        np.testing.assert_array_equal(out, reference.exp(view))
    y = np.abs(x) + 1e-3
    assert _kernels.log(y).tolist() == [[math.log(v) for v in row] for row in y]
    assert _kernels.log(np.array([0.0, 1.0])).tolist() == [-math.inf, 0.0]
