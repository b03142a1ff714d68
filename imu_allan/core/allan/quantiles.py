"""
Chi-square and F distribution functions: the one place the package takes them from.

The same values as scipy.stats' chi2.ppf, chi2.sf and f.ppf (checked in test_model.py),
from scipy.special, imported on first use: the Allan curve's bounds, the fit and the
search all call these, and scipy.stats' own import is a large share of a short
command's start-up.
"""

import numpy as np


def chi2_ppf(q, df):
    """
    Return the chi-square quantile: x with P(X <= x) = q for X ~ chi2(df).

    Parameters
    ----------
    q : float or array_like
        Probability, shape broadcast with ``df``.
    df : float or array_like
        Degrees of freedom (real, > 0).

    Returns
    -------
    float or np.ndarray
        The quantile, broadcast shape.

    """
    from scipy.special import chdtri

    return chdtri(df, 1.0 - np.asarray(q, dtype=np.float64))


def chi2_sf(x, df):
    """Return P(X > x) for X ~ chi2(df) (the p-value of a chi-square statistic)."""
    from scipy.special import chdtrc

    return chdtrc(df, x)


def f_ppf(q, dfn, dfd):
    """Return the F quantile: x with P(F <= x) = q for F ~ F(dfn, dfd)."""
    from scipy.special import fdtri

    return fdtri(dfn, dfd, q)
