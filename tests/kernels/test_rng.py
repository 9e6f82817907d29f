"""The host side of the counter-based random numbers: the table of normal quantiles."""

import statistics

import numpy as np
import pytest

from roshan.kernels import rng


@pytest.mark.parametrize("n", [1, 7, 1000, rng.TABLE_SIZE])
def test_exact_quantiles_are_statistics_inv_cdf_bit_for_bit(n):
    nd = statistics.NormalDist()
    want = np.array([nd.inv_cdf((k + 0.5) / n) for k in range(n)])
    got = rng.exact_quantiles(n)
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, want)


def test_normal_tables_are_shuffled_quantiles_one_per_seed():
    a, b = rng.normal_quantiles(1, 2)
    assert a.dtype == np.float32 and a.shape == (rng.TABLE_SIZE,)
    np.testing.assert_array_equal(np.sort(a), np.sort(b))
    assert not np.array_equal(a, b)
    np.testing.assert_array_equal(np.sort(a), rng.exact_quantiles(rng.TABLE_SIZE).astype(np.float32))
    assert abs(float(a.mean())) < 1e-6 and abs(float(a.std()) - 1.0) < 1e-3

