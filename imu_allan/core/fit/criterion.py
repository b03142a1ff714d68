"""
Model selection: one criterion, the penalised GLS chi-square, and why its penalty varies.

Every choice between noise models in the package compares J + penalty x p: J the GLS
chi-square of the Allan curve at the model's covariance of it (where two models weight
the curve differently, -2 ln L, that is J plus the log-determinant of the covariance),
p the number of fitted parameters.  The penalty says what the choice claims:

* **Keeping a term of the base model** (:func:`imu_allan.core.fit.fit_axis`, over every
  subset of quantization, white noise, bias instability and random walk): 2 per
  parameter (AIC, Akaike 1974).  These terms are the paper's model of every MEMS IMU
  (Maia et al., sec. 2); leaving out one that is there biases every other parameter,
  while keeping a weak one only widens its interval, and its parameter is then reported
  as a bound.  The lighter penalty errs on the side of keeping.
* **Claiming an effect beyond the base model** (the effect search,
  :mod:`imu_allan.core.search`): ln(k) per parameter for k fitted taus (BIC, Schwarz
  1978), plus the margin :data:`DELTA_MIN`.  A named effect (a sinusoid, a ramp, a second
  Gauss-Markov process) is something a user acts on; BIC's penalty grows with the
  evidence a curve can hold, and the margin keeps clean axes clean where Sigma is only
  approximately right (bench/search_power.py: no false effect on 78 clean axes).
* **Rivals** (:mod:`imu_allan.core.search.choice`): models within :data:`DELTA_MIN` of
  the chosen one on the claim criterion fit about equally well.
* **"Cannot tell"** (:meth:`imu_allan.core.search.run._Run.undecided`): an effect that
  would pass the keep criterion but not the claim criterion is reported as evidence
  the record cannot settle, with the record length that would.

The thresholds (:data:`KEEP_PENALTY`, :data:`DELTA_MIN`) live in :mod:`imu_allan.core.rules`.
"""

import math


def claim_penalty(n_taus: int) -> float:
    """
    Return BIC's penalty per parameter for a curve of ``n_taus`` fitted taus.

    Parameters
    ----------
    n_taus : int
        The number of fitted taus k (the curve's data points).

    Returns
    -------
    float
        ln(k) [-].

    """
    return math.log(max(int(n_taus), 1))


def criterion(j: float, n_params: int, penalty: float) -> float:
    """
    Return the penalised criterion J + penalty x p of a fitted model.

    Parameters
    ----------
    j : float
        GLS chi-square (or -2 ln L) of the model [-].
    n_params : int
        Fitted parameters p.
    penalty : float
        Per parameter: :data:`KEEP_PENALTY` or :func:`claim_penalty`.

    Returns
    -------
    float
        The criterion; the smaller, the better supported.

    """
    return float(j) + penalty * int(n_params)
