"""
Held samples: the Allan variance of a zero-order-held white sequence, and where to fit.

A driver or logger that publishes faster than its sensor updates repeats each update
(a zero-order hold).  When every update of a white sequence of variance ``s^2`` is held
for ``k`` samples, the held sequence's average over ``m`` samples (``m >= k``) weighs
the updates at its two ends by their share in it, and the overlapping Allan variance
at cluster size ``m`` (samples) is the white one times ``1 - (k^2 - 1) / (2 k m)``.
This follows from summing the squared weights of the difference of two adjacent
averages over the ``k`` phases of the hold; it matches a simulation of 2,000,000
samples for k = 2, 3, 5 and 10 within its scatter (test/test_allan.py).  In time: the
bias is about ``T_u / (2 tau)`` (``T_u`` the update period), so it reaches well above
the update period (4-5 % of the variance at ten update periods): the fit starts where it
is at most 10 % and takes the curve corrected by the closed form.  Cutting instead
until the bias is lost in the estimates' random error left the accelerometers of the
ADIS16405 too few white taus to fit (docs/input_gate.md).
"""

import numpy as np

#: The fit starts at the first tau whose hold bias is at most this share of its Allan
#: variance: there the closed form corrects it (exact for white noise, which dominates
#: the shortest taus; the other terms are smooth over an update and not held down).
MAX_BIAS = 0.1


def hold_bias(m: np.ndarray, samples_per_update: float) -> np.ndarray:
    """
    Relative bias of the overlapping Allan variance of a held white sequence.

    Parameters
    ----------
    m : np.ndarray
        Shape (k,), cluster sizes [samples].
    samples_per_update : float
        Mean samples per update (1 / (1 - held share)), >= 1.

    Returns
    -------
    np.ndarray
        Shape (k,): ``(k^2 - 1) / (2 k m)`` (the held variance is the white one times
        one minus this), capped at 1 where ``m`` is below the hold.

    """
    k = float(samples_per_update)
    return np.minimum((k * k - 1.0) / (2.0 * k * np.asarray(m, dtype=np.float64)), 1.0)


def held_fit_curve(tau_s: np.ndarray, avar: np.ndarray, rate_hz: float,
                   held_share: float, keep: int = 3) -> tuple[int, np.ndarray]:
    """
    Return the part of a held axis' Allan curve to fit, corrected for the hold.

    Parameters
    ----------
    tau_s : np.ndarray
        Shape (k,), averaging times [s], shortest first.
    avar : np.ndarray
        Shape (k,), measured Allan variance [unit^2].
    rate_hz : float
        Sample rate of the (held) stream [Hz].
    held_share : float
        Share of the samples that repeat the one before (0 <= share < 1).
    keep : int
        Fewest taus left to fit [taus].

    Returns
    -------
    first : int
        The first tau whose hold bias (:func:`hold_bias`) is at most :data:`MAX_BIAS`
        (0 when nothing is held; never more than leaves ``keep`` taus).
    avar : np.ndarray
        Shape (k - first,): the Allan variance from there, divided by one minus the
        bias [unit^2].

    """
    tau = np.asarray(tau_s, dtype=np.float64)
    avar = np.asarray(avar, dtype=np.float64)
    if not 0 < held_share < 1 or tau.size <= keep:
        return 0, avar
    bias = hold_bias(tau * rate_hz, 1.0 / (1.0 - held_share))
    ok = bias <= MAX_BIAS
    first = min(int(np.argmax(ok)) if ok.any() else tau.size, tau.size - keep)
    return first, avar[first:] / np.maximum(1.0 - bias[first:], 1.0 - MAX_BIAS)
