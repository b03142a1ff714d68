"""
What IMU drivers do to the samples before anyone sees them: low-pass and decimate.

Used to build the validation cases of filtered sensors (test_trust.py,
bench/trust_power.py): a phone or a driver that averages a fast MEMS output down to a
low rate bends the shortest taus of the Allan curve.
"""

import math

import numpy as np
from scipy import signal

from imu_allan.errors import InputError

#: Filters :func:`driver_filtered` applies.
DRIVER_FILTERS = ('filtfilt', 'one_pole')


def driver_filtered(y: np.ndarray, rate_hz: float, kind: str, cutoff_hz: float,
                    factor: int) -> tuple[np.ndarray, float]:
    """
    Low-pass filter and decimate samples as a driver does.

    Parameters
    ----------
    y : np.ndarray
        Shape (n,), samples [unit] at ``rate_hz``.
    rate_hz : float
        Their rate [Hz].
    kind : str
        'filtfilt': a 2nd-order Butterworth run forward and backward (zero phase);
        'one_pole': y_k = y_{k-1} + a (x_k - y_{k-1}), a = 1 - exp(-2 pi f_c / rate).
    cutoff_hz : float
        Cut-off frequency f_c [Hz], below rate_hz / 2.
    factor : int
        Decimation factor (every factor-th filtered sample is kept).

    Returns
    -------
    y : np.ndarray
        Shape (n // factor,) approximately, the filtered, decimated samples [unit].
    rate_hz : float
        Their rate, rate_hz / factor [Hz].

    Raises
    ------
    InputError
        An unknown kind, a cut-off outside (0, rate_hz / 2) or a factor below 1.

    """
    if kind not in DRIVER_FILTERS:
        raise InputError(f'unknown driver filter {kind!r}; known: {", ".join(DRIVER_FILTERS)}')
    if not 0.0 < cutoff_hz < rate_hz / 2.0:
        raise InputError(f'cut-off must lie in (0, {rate_hz / 2.0:g}) Hz, got {cutoff_hz!r}')
    if int(factor) != factor or factor < 1:
        raise InputError(f'decimation factor must be an integer >= 1, got {factor!r}')
    y = np.asarray(y, dtype=np.float64)
    if kind == 'filtfilt':
        b, a = signal.butter(2, cutoff_hz / (rate_hz / 2.0))
        out = signal.filtfilt(b, a, y)
    else:
        alpha = 1.0 - math.exp(-2.0 * math.pi * cutoff_hz / rate_hz)
        out = signal.lfilter([alpha], [1.0, alpha - 1.0], y, zi=[y[0] * (1.0 - alpha)])[0]
    return out[::int(factor)], rate_hz / int(factor)
