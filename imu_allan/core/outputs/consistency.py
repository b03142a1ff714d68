"""
Consistency of a random-walk bias filter on a static record: NEES and NIS.

The consumers of the Allan values (Kalibr, OpenVINS, VINS, most EKFs) model an axis as
white noise of density N plus a bias random walk of density K.  This module runs that
model as a scalar Kalman filter on a still record and asks whether the covariance it
reports matches its errors (Bar-Shalom, Li, Kirubarajan, *Estimation with Applications
to Tracking and Navigation*, 2001, sections 5.4-5.5):

* the record is cut into blocks of ``block_s``; each block mean z_k measures the bias
  with white noise of variance R = N^2 / block_s (IEEE Std 952 C.1: the AVAR of white
  noise at tau = block_s is N^2 / tau);
* the bias is a random walk, b_k = b_(k-1) + w_k with Var w_k = Q = K^2 block_s;
* NIS_k = nu_k^2 / S_k with the innovation nu_k = z_k - b_k|k-1 and S_k = P_k|k-1 + R
  needs no truth (real records); NEES_k = (b_k|k - b_k)^2 / P_k|k needs the true block
  bias (simulated records).

For a consistent filter both are chi-square with 1 degree of freedom, so their mean
over M steps lies in [chi2_0.025(M) / M, chi2_0.975(M) / M] with 95 % probability
(steps treated as independent).  Above the interval the filter is over-confident
(its covariance is too small for its errors), below it conservative.
"""

import math
from typing import NamedTuple

import numpy as np
from scipy.stats import chi2

from imu_allan.errors import InputError


class Consistency(NamedTuple):
    """
    NEES / NIS summary of one filter run.

    Attributes
    ----------
    n_steps : int
        Blocks scored (after the burn-in).
    block_s : float
        Block length [s].
    mean_nis : float
        Mean normalised innovation squared [-].
    mean_nees : float or None
        Mean normalised estimation error squared [-]; None without a truth.
    bounds : tuple of float
        95 % interval of the mean of n_steps chi-square(1) values [-].
    verdict : str
        'over-confident', 'consistent' or 'conservative': from the NEES when there is a
        truth, else from the NIS.

    """

    n_steps: int
    block_s: float
    mean_nis: float
    mean_nees: float | None
    bounds: tuple
    verdict: str


def block_means(y, rate_hz: float, block_s: float) -> np.ndarray:
    """
    Means of consecutive blocks of ``block_s`` (a partial last block is dropped).

    Parameters
    ----------
    y : array_like
        Shape (n,), samples at ``rate_hz``.
    rate_hz : float
        Sample rate [Hz].
    block_s : float
        Block length [s], at least one sample.

    Returns
    -------
    np.ndarray
        Shape (n // m,), block means, m = round(block_s rate_hz).

    """
    m = int(round(block_s * rate_hz))
    if m < 1:
        raise InputError(f'block of {block_s} s is shorter than one sample at {rate_hz} Hz')
    y = np.asarray(y, dtype=np.float64)
    k = y.size // m
    return y[:k * m].reshape(k, m).mean(axis=1)


def verdict(mean: float, bounds: tuple) -> str:
    """Return 'over-confident', 'conservative' or 'consistent' for a mean NEES / NIS."""
    if mean > bounds[1]:
        return 'over-confident'
    if mean < bounds[0]:
        return 'conservative'
    return 'consistent'


def random_walk_filter(y, rate_hz: float, N: float, K: float, block_s: float = 1.0,
                       truth=None, burn_in_s: float = 0.0) -> Consistency:
    """
    Run the white + random-walk bias filter on one axis and score it (module docstring).

    Parameters
    ----------
    y : array_like
        Shape (n,), the static record of one axis at ``rate_hz`` [unit].
    rate_hz : float
        Sample rate [Hz].
    N : float
        White-noise density the filter assumes [unit*s^0.5], > 0.
    K : float
        Random-walk density the filter assumes [unit/s^0.5], > 0.
    block_s : float
        Block length [s].
    truth : array_like, optional
        Shape (n,), the true bias at each sample [unit] (simulation); its block means
        are the true states.
    burn_in_s : float
        Time at the start that is filtered but not scored [s] (the filter starts from
        the first block with covariance R).

    Returns
    -------
    Consistency

    """
    if not (N > 0 and K > 0 and math.isfinite(N) and math.isfinite(K)):
        raise InputError(f'the filter needs positive N and K, got {N!r}, {K!r}')
    z = block_means(y, rate_hz, block_s)
    b_true = None if truth is None else block_means(truth, rate_hz, block_s)
    r, q = N ** 2 / block_s, K ** 2 * block_s
    x, p = z[0], r
    nis, nees = [], []
    skip = int(math.ceil(burn_in_s / block_s))
    for k in range(1, z.size):
        p_pred = p + q
        s = p_pred + r
        nu = z[k] - x
        gain = p_pred / s
        x = x + gain * nu
        p = (1.0 - gain) * p_pred
        if k > skip:
            nis.append(nu * nu / s)
            if b_true is not None:
                nees.append((x - b_true[k]) ** 2 / p)
    m = len(nis)
    if m < 10:
        raise InputError(f'only {m} blocks to score: the record is too short for the filter')
    bounds = (float(chi2.ppf(0.025, m) / m), float(chi2.ppf(0.975, m) / m))
    mean_nis = float(np.mean(nis))
    mean_nees = float(np.mean(nees)) if nees else None
    judged = mean_nees if mean_nees is not None else mean_nis
    return Consistency(n_steps=m, block_s=float(block_s), mean_nis=mean_nis,
                       mean_nees=mean_nees, bounds=bounds, verdict=verdict(judged, bounds))
