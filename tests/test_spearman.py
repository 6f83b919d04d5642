"""The project's Spearman correlation is scipy.stats.spearmanr's, to the bit (it exists only to
keep scipy.stats's import out of the command line)."""

import warnings

import numpy as np
import pytest
from scipy import stats

from calib.analysis.spearman import average_ranks, spearman


@pytest.mark.parametrize("n", [3, 4, 20, 150, 2000])
def test_spearman_equals_scipy(n):
    rng = np.random.default_rng(n)
    for trial in range(40):
        a = rng.normal(size=n)
        b = rng.integers(0, 4, size=n).astype(float) if trial % 2 else rng.normal(size=n)
        if trial == 6:
            b = -a  # rho exactly -1: p 0
        ref = stats.spearmanr(a, b)
        rho, p = spearman(a, b)
        assert rho == ref.statistic or (np.isnan(rho) and np.isnan(ref.statistic))
        assert p == ref.pvalue or (np.isnan(p) and np.isnan(ref.pvalue))
        assert np.array_equal(average_ranks(b), stats.rankdata(b))


def test_constant_input_is_nan_as_in_scipy():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = stats.spearmanr([1.0, 2.0, 3.0], [5.0, 5.0, 5.0])
    rho, p = spearman(np.array([1.0, 2.0, 3.0]), np.array([5.0, 5.0, 5.0]))
    assert np.isnan(ref.statistic) and np.isnan(rho) and np.isnan(p)


def test_ties_take_the_mean_rank():
    assert average_ranks(np.array([3.0, 1.0, 3.0, 2.0])).tolist() == [3.5, 1.0, 3.5, 2.0]
