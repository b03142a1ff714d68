"""
The bounded raw copy beside the Allan accumulator, for the effect search's evidence.

:class:`RawKeeper` keeps block averages of the samples as they stream by (the node, the
offline reader and the diagnosis keep one); :func:`raw_evidence` hands them to the
time-domain tests of :mod:`imu_allan.core.search.evidence`.  numpy only: the offline reader
imports it before the fit's scipy is loaded.
"""

import math

import numpy as np

from imu_allan import AXES
from imu_allan.errors import InputError

#: Rows the raw copy keeps before it averages pairs: the one policy of the node and of
#: ``imu-allan analyze`` (48 MB for six axes), so both search the same evidence.  A
#: 2.8 h record at 100 Hz fits whole; a copy halved to 25 Hz (the node's former 262,144
#: rows) could no longer confirm the ADIS16405's 20 Hz line, and the node then reported
#: gyro_z as not trusted where ``analyze`` trusted it.
RAW_ROWS = 1 << 20


#: Magnitude from which a finite value is no reading [rad/s or m/s^2]: far beyond any
#: sensor, and where the squares and fourth powers of the evidence's sums could
#: overflow float64 (max 1.8e308): a Cholesky solve then ends in 'array must not contain
#: infs or NaNs'.  The session replaces such a value as a spike.
MAX_ABS_VALUE = 1e60


def reading_rows(samples: np.ndarray) -> np.ndarray | None:
    """
    Return which rows hold readings: finite values below :data:`MAX_ABS_VALUE`.

    Parameters
    ----------
    samples : numpy.ndarray
        (n, n_axes) samples [rad/s, m/s^2].

    Returns
    -------
    numpy.ndarray or None
        (n,) bool, True for a row of readings; None when every row is one (the usual
        case, answered by three reductions without a copy).

    """
    if samples.size == 0 or (np.isfinite(samples).all() and samples.max() < MAX_ABS_VALUE
                             and samples.min() > -MAX_ABS_VALUE):
        return None
    return (np.abs(np.nan_to_num(samples, nan=np.inf)) < MAX_ABS_VALUE).all(axis=1)


class RawKeeper:
    """
    A bounded copy of the raw samples for the periodogram check (block averages).

    Samples are appended as they arrive; when more than ``max_samples`` rows are held,
    neighbouring pairs are averaged (the decimation factor doubles).  Averaging is a
    low-pass filter (sinc response), harmless for the slow sinusoids the Allan curve
    can see.  Memory: at most ``max_samples`` x n_axes x 8 bytes.

    Parameters
    ----------
    rate_hz : float or None
        Rate of the incoming samples [Hz]; None until the stream's rate is known (set
        ``rate_hz`` then: the copy keeps every sample from the first on).
    n_axes : int
        Columns per sample.
    max_samples : int
        Rows kept at most (even).

    """

    def __init__(self, rate_hz: float | None, n_axes: int = len(AXES),
                 max_samples: int = RAW_ROWS):
        if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
            raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
        self.rate_hz = None if rate_hz is None else float(rate_hz)
        self.max_samples = max(int(max_samples) // 2 * 2, 2)
        self.factor = 1
        self._data = np.empty((self.max_samples, n_axes))
        self._n = 0
        self._carry = np.empty((0, n_axes))

    def add(self, samples) -> None:
        """
        Append samples; rows that are no readings (:func:`reading_rows`) are left out.

        The session drops NaN rows and replaces huge values as spikes, with warnings;
        here they would only poison the block averages.

        Parameters
        ----------
        samples : array_like
            Shape (n, n_axes), in the keeper's units.

        """
        y = np.asarray(samples, dtype=np.float64).reshape(-1, self._data.shape[1])
        rows = reading_rows(y)
        if rows is not None:
            y = y[rows]
        if self._carry.size:
            y = np.vstack([self._carry, y])
        usable = y.shape[0] // self.factor * self.factor
        self._carry = y[usable:].copy()
        blocks = _means(y[:usable], self.factor)
        while blocks.shape[0]:
            room = self.max_samples - self._n
            take = min(room, blocks.shape[0])
            self._data[self._n:self._n + take] = blocks[:take]
            self._n += take
            blocks = blocks[take:]
            if self._n == self.max_samples:
                half = _means(self._data[:self._n], 2)
                self._n = half.shape[0]
                self._data[:self._n] = half
                self.factor *= 2
                if blocks.shape[0]:
                    odd = blocks.shape[0] % 2
                    if odd:
                        self._carry = np.vstack(
                            [np.repeat(blocks[-1:], self.factor // 2, axis=0), self._carry])
                    blocks = _means(blocks[:blocks.shape[0] - odd], 2)

    @property
    def samples(self) -> np.ndarray:
        """Shape (n, n_axes): the kept (block-averaged) samples."""
        return self._data[:self._n].copy()

    @property
    def kept_rate_hz(self) -> float:
        """Rate of the kept samples [Hz] (``rate_hz`` must be known by now)."""
        if self.rate_hz is None:
            raise InputError('the rate of the kept samples is not known yet')
        return self.rate_hz / self.factor


def _means(y: np.ndarray, factor: int) -> np.ndarray:
    """
    Return the means of ``factor`` consecutive rows (a power of two).

    Strided sums, not ``reshape(...).mean(axis=1)``'s pairwise ones: the same
    additions in the same order (row 0 + row 1 + ...; a power of two divides exactly).

    Parameters
    ----------
    y : np.ndarray
        Shape (n, n_axes), n a multiple of ``factor``.
    factor : int
        Rows per mean.

    Returns
    -------
    np.ndarray
        Shape (n // factor, n_axes): ``y`` itself when factor is 1, else a new array.

    """
    if factor == 1:
        return y
    out = np.add(y[0::factor], y[1::factor])
    for k in range(2, factor):
        out += y[k::factor]
    out *= 1.0 / factor
    return out


def raw_evidence(raw: RawKeeper | None, session_rate_hz: float | None) -> tuple:
    """
    Return (kept samples, their rate [Hz]) for the evidence tests, or (None, None).

    A copy started before the stream's rate was known takes the session's
    (``session_rate_hz``, None when unknown); fewer than 16 kept rows say nothing and
    are not used.
    """
    rate = (raw.rate_hz or session_rate_hz) if raw is not None else None
    if raw is None or not rate:
        return None, None
    samples = raw.samples
    if samples.shape[0] < 16:
        return None, None
    return samples, float(rate) / raw.factor
