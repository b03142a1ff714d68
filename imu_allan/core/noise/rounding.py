"""
What rounding to a grid (a sensor's LSB, the digits a logger writes) does to white noise.

Rounding a value to a grid of step q adds an error that, where the noise of one sample
is at least about q / 2, is uniform over one step, independent of the value and white:
variance q^2 / 12 per sample (Widrow and Kollar, *Quantization Noise*, Cambridge 2008,
ch. 4-5; Sheppard's correction).  The white noise of rounded samples is then
N_rounded^2 = N^2 + q^2 / (12 f_s), so the recorded N reads high by
1 / sqrt(1 - q^2 / (12 sigma^2)) for sigma^2 = N_rounded^2 f_s, the recorded variance of
one sample.  Where the noise is below about q / 2 the error follows the value instead:
most samples sit on one level and the recorded N reads high or low by any amount.
"""

import math
from typing import NamedTuple


class Rounding(NamedTuple):
    """
    The effect of a value grid on the white noise of one axis.

    Attributes
    ----------
    quantum : float
        The grid step [unit].
    ratio : float
        ``quantum`` over the recorded sd of one sample (N sqrt(f_s)).
    n_raise : float
        How much the grid raises N, as a share (0.04: 4 % high); inf where the error
        is no longer additive noise (a share of the variance of 1 or more).

    """

    quantum: float
    ratio: float
    n_raise: float


def rounding_effect(quantum: float, n_white: float, rate_hz: float) -> Rounding:
    """
    Return what a grid of step ``quantum`` does to the white noise ``n_white``.

    Parameters
    ----------
    quantum : float
        The grid step [unit].
    n_white : float
        The white noise of the recorded values [unit s^0.5].
    rate_hz : float
        Their sample rate [Hz].

    Returns
    -------
    Rounding
        With ratio inf where ``n_white`` is 0.

    """
    sigma = n_white * math.sqrt(rate_hz)
    if not sigma > 0:
        return Rounding(quantum, math.inf, math.inf)
    share = quantum * quantum / (12.0 * sigma * sigma)
    raise_ = 1.0 / math.sqrt(1.0 - share) - 1.0 if share < 1.0 else math.inf
    return Rounding(quantum, quantum / sigma, raise_)
