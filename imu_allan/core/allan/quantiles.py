"""
Chi-square and F distribution functions from scipy.special.

The same values as scipy.stats' chi2.ppf, chi2.sf and f.ppf (checked in test_model.py),
without importing scipy.stats, which costs about a second of start-up; scipy.special
itself (0.25 s) is imported on first use by the fit, which calls these thousands of
times.  The Allan curve's bounds take their two quantiles per tau from
:mod:`imu_allan.core.allan.chi2` (numpy alone), so ``imu-allan adev`` imports no scipy.
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
