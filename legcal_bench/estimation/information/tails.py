"""The tails of the chi-square and F distributions the tests read, from scipy.special:
the functions scipy.stats's `chi2` and `f` evaluate (`chdtrc`, `gammaincinv`, `fdtrc`),
without importing scipy.stats, which costs a process ~0.4 s at scipy 1.17 (its
functions' docstrings parsed at import). tests/estimation/test_tails.py holds each to
scipy.stats's."""

from __future__ import annotations

import numpy as np
from scipy.special import chdtr, chdtrc, fdtrc, gammaincinv


def chi2_sf(x, dof):
    """P(X > x) for X chi-square with `dof` degrees of freedom (`scipy.stats.chi2.sf`)."""
    return chdtrc(dof, x)


def chi2_logsf(x, dof):
    """log P(X > x), -inf where it underflows, as `scipy.stats.chi2.logsf` computes it:
    log1p of the lower tail up to the median, the log of the upper one beyond."""
    x, dof = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(dof, dtype=float))
    upper = x > chi2_ppf(0.5, dof)
    with np.errstate(divide="ignore"):
        out = np.where(upper, np.log(chdtrc(dof, x)), np.log1p(-chdtr(dof, x)))
    return out[()] if out.ndim == 0 else out


def chi2_ppf(q, dof):
    """The `q` quantile of the chi-square with `dof` degrees of freedom (`scipy.stats.chi2.ppf`)."""
    return 2.0 * gammaincinv(np.asarray(dof) / 2.0, q)


def f_sf(x, dfn, dfd):
    """P(X > x) for X F-distributed with (`dfn`, `dfd`) degrees of freedom (`scipy.stats.f.sf`)."""
    return fdtrc(dfn, dfd, x)
