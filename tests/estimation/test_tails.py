"""The chi-square and F tails from scipy.special (`estimation.information.tails`) are
scipy.stats's, including where the tail underflows."""

import numpy as np
import pytest
from scipy import stats

from legcal_bench.estimation.information import tails

X = np.array([0.0, 0.3, 1.0, 7.5, 40.0, 300.0, 5e3, 2e5])


@pytest.mark.parametrize("dof", [1, 2, 5, 37, 1200])
def test_chi2_tails_and_quantile_are_scipy_stats(dof):
    np.testing.assert_array_equal(tails.chi2_sf(X, dof), stats.chi2.sf(X, dof))
    np.testing.assert_array_equal(tails.chi2_logsf(X, dof), stats.chi2.logsf(X, dof))
    q = np.array([0.01, 0.5, 0.95, 0.999])
    np.testing.assert_allclose(tails.chi2_ppf(q, dof), stats.chi2.ppf(q, dof), rtol=1e-14)
    assert tails.chi2_logsf(1e7, dof) == -np.inf  # underflowed, as scipy.stats says


@pytest.mark.parametrize("dfn,dfd", [(1, 10), (4, 4000), (30, 77)])
def test_f_tail_is_scipy_stats(dfn, dfd):
    np.testing.assert_array_equal(tails.f_sf(X / 10, dfn, dfd), stats.f.sf(X / 10, dfn, dfd))
