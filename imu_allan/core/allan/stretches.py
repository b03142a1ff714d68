"""
Did the noise level change during the record?  The Allan sums of its stretches.

The intervals of a fit are statistical: they say how well the record's *average* noise
is known, assuming the noise was the same all along.  Real sensors break that (the
ADIS16405 accelerometers' N, read at 0.08 s, wanders by 1.6-4.6 % sd between the
5.5-minute stretches of still runs, far beyond chance; a fan or a pump nearby does too),
and a first ten minutes then disagree with the hour by more than both intervals.

:class:`StretchSums` keeps the exact taus' sums of squared second differences
(:mod:`imu_allan.core.allan.accumulator`) per consecutive stretch of the record, in
bounded memory: at most :data:`MAX_STRETCHES` stretches, adjacent pairs merged (and
the stretch length doubled) when they are full, so the node's state never grows.
:func:`level_change` tests whether one tau's AVAR is the same in every stretch
(Cochran's Q on the log AVARs, each with variance 2 / edf; Cochran 1954) and
estimates how much it wanders beyond chance (the method-of-moments between-stretch
variance of DerSimonian and Laird 1986).
"""

import math
from typing import NamedTuple

import numpy as np

from imu_allan.core.allan.edf import edf_overlapping
from imu_allan.core.allan.quantiles import chi2_sf
from imu_allan.errors import InputError

#: Stretches kept; when full, adjacent pairs merge and the stretch length doubles.
MAX_STRETCHES = 64
#: Samples in a stretch at the start (32768: 5.5 min at 100 Hz, 33 s at 1 kHz).
FIRST_STRETCH_ROWS = 32768
#: A stretch needs this many degrees of freedom at the tested tau to take part.
MIN_STRETCH_EDF = 50.0
#: Stretches needed for a test.
MIN_STRETCHES = 4


class StretchSums:
    """
    Per-stretch sums and term counts of the exact taus, in bounded memory.

    Parameters
    ----------
    k0 : int
        Number of exact cluster sizes (the accumulator's level 0).
    n_axes : int
        Number of axes.

    """

    def __init__(self, k0: int, n_axes: int):
        self.rows_target = FIRST_STRETCH_ROWS
        self.sums = np.zeros((MAX_STRETCHES, k0, n_axes))
        self.counts = np.zeros((MAX_STRETCHES, k0), dtype=np.int64)
        self.rows = np.zeros(MAX_STRETCHES, dtype=np.int64)
        self.n = 0

    def add(self, sums: np.ndarray, counts: np.ndarray, rows: int) -> None:
        """
        Add one processed chunk: sums (k0, n_axes) and counts (k0,) of ``rows`` samples.

        A chunk goes into the last stretch until that holds ``rows_target`` samples.
        """
        if self.n == 0 or self.rows[self.n - 1] >= self.rows_target:
            if self.n == MAX_STRETCHES:
                self._merge()
            if self.n == 0 or self.rows[self.n - 1] >= self.rows_target:
                self.n += 1
        i = self.n - 1
        self.sums[i] += sums
        self.counts[i] += counts
        self.rows[i] += rows

    def _merge(self) -> None:
        """Merge adjacent pairs of stretches; the stretch length doubles."""
        half = MAX_STRETCHES // 2
        for arr in (self.sums, self.counts, self.rows):
            arr[:half] = arr[0::2] + arr[1::2]
            arr[half:] = 0
        self.n = half
        self.rows_target *= 2

    def state(self) -> tuple[dict, dict]:
        """Return the metadata and arrays of a checkpoint."""
        meta = {'stretch_target': self.rows_target, 'n_stretches': self.n}
        arrays = {'stretch_sums': self.sums[:self.n].copy(),
                  'stretch_counts': self.counts[:self.n].copy(),
                  'stretch_rows': self.rows[:self.n].copy()}
        return meta, arrays

    def restore(self, meta: dict, arrays: dict) -> None:
        """
        Restore :meth:`state` (a checkpoint written before stretches were kept: none).

        Raises
        ------
        InputError
            Arrays that do not fit the accumulator, or negative values.

        """
        if 'stretch_sums' not in arrays:
            return
        n, target = int(meta['n_stretches']), int(meta['stretch_target'])
        k0, a = self.sums.shape[1:]
        expect = {'stretch_sums': (n, k0, a), 'stretch_counts': (n, k0), 'stretch_rows': (n,)}
        for key, shape in expect.items():
            arr = arrays[key]
            if (arr.shape != shape or arr.dtype.kind not in 'fi'
                    or not np.isfinite(arr).all() or (arr < 0).any()):
                raise InputError(f'array {key!r} has shape {arr.shape}, expected {shape} '
                                 'of finite values >= 0')
        if not 0 <= n <= MAX_STRETCHES or target < FIRST_STRETCH_ROWS:
            raise InputError('inconsistent stretch counters')
        self.n, self.rows_target = n, target
        self.sums[:n] = arrays['stretch_sums']
        self.counts[:n] = arrays['stretch_counts']
        self.rows[:n] = arrays['stretch_rows']


class Stretches(NamedTuple):
    """
    The Allan variance of each stretch of a record at the exact taus.

    Attributes
    ----------
    m : np.ndarray
        Shape (k,), cluster sizes [samples].
    tau_s : np.ndarray
        Shape (k,), averaging times [s].
    avar : np.ndarray
        Shape (s, k, n_axes), each stretch's overlapping AVAR [unit^2]; NaN without terms.
    n_terms : np.ndarray
        Shape (s, k), the second differences summed in each.
    rows : np.ndarray
        Shape (s,), samples in each stretch.

    """

    m: np.ndarray
    tau_s: np.ndarray
    avar: np.ndarray
    n_terms: np.ndarray
    rows: np.ndarray


def stretch_view(acc_sums: StretchSums, m: np.ndarray, rate_hz: float) -> Stretches:
    """Return the AVAR of each stretch (m (k,) the exact cluster sizes [samples])."""
    n = acc_sums.n
    counts = acc_sums.counts[:n]
    with np.errstate(invalid='ignore', divide='ignore'):
        avar = acc_sums.sums[:n] / (2.0 * m.astype(float) ** 2 * counts)[:, :, None]
    avar[counts == 0] = np.nan
    return Stretches(m.copy(), m / rate_hz, avar, counts.copy(), acc_sums.rows[:n].copy())


class LevelChange(NamedTuple):
    """
    How much one tau's AVAR wandered between the stretches of a record.

    Attributes
    ----------
    tau_s : float
        The tau tested [s].
    n_stretches : int
        Stretches that took part.
    p_value : float
        Cochran's Q test that every stretch has the same AVAR (chi-square, s - 1 dof).
    sd_log_avar : float
        Between-stretch standard deviation of ln AVAR beyond chance (DerSimonian and
        Laird's moment estimate; 0 when the spread is within chance).
    ratio_range : tuple of float
        (lowest, highest) stretch AVAR over the pooled one.

    """

    tau_s: float
    n_stretches: int
    p_value: float
    sd_log_avar: float
    ratio_range: tuple


def level_change(stretches: Stretches, k: int, axis: int) -> LevelChange | None:
    """
    Test whether the AVAR at tau index ``k`` of one axis changed between stretches.

    Each stretch's ln AVAR is taken as normal with variance 2 / edf (the chi-square
    law of the Allan variance, NIST SP 1065 sec. 5.3, at large edf), edf that of
    white noise at its cluster size and terms (Greenhall's algorithm).

    Parameters
    ----------
    stretches : Stretches
        The record's stretches.
    k : int
        Index into ``stretches.m``: a tau where white noise rules the curve.
    axis : int
        Column.

    Returns
    -------
    LevelChange or None
        None when fewer than :data:`MIN_STRETCHES` stretches have
        :data:`MIN_STRETCH_EDF` degrees of freedom there.

    """
    m = int(stretches.m[k])
    terms = stretches.n_terms[:, k]
    avar = stretches.avar[:, k, axis]
    edf = np.where(terms > 0, edf_overlapping(0, m, np.maximum(terms, 1) + 2 * m - 1), 0.0)
    use = (edf >= MIN_STRETCH_EDF) & np.isfinite(avar) & (avar > 0)
    if use.sum() < MIN_STRETCHES:
        return None
    log_avar, w = np.log(avar[use]), edf[use] / 2.0
    mean = float(np.sum(w * log_avar) / w.sum())
    q = float(np.sum(w * (log_avar - mean) ** 2))
    s = int(use.sum())
    # DerSimonian and Laird (1986): the excess of Q over its expectation s - 1.
    tau2 = max(0.0, (q - (s - 1)) / (w.sum() - np.sum(w ** 2) / w.sum()))
    pooled = float(np.sum(avar[use] * terms[use]) / terms[use].sum())
    ratio = avar[use] / pooled
    return LevelChange(float(stretches.tau_s[k]), s, float(chi2_sf(q, s - 1)),
                       math.sqrt(tau2), (float(ratio.min()), float(ratio.max())))
