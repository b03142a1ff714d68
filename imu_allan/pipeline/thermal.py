"""
The temperature beside the samples: its track, and the thermal sums of the kept rows.

A record that gives a temperature (a CSV ``temperature`` column, a
``sensor_msgs/Temperature`` topic) hands it to the session as ``(stamp_ns, temp_c)``
pairs (:meth:`ThermalFeed.add_temperature`); the accumulator feed hands over every
row it accumulates, with its stamp (:meth:`ThermalFeed.add`), so the thermal sums hold
exactly the rows of the Allan curve: the temperature interpolated at each row's stamp
(linear, held at the ends), then

* a second accumulator of the columns ``T`` and ``y_i + s T``
  (:func:`imu_allan.core.allan.thermal.thermal_columns`): the Allan covariance of each
  axis with T at every tau of the curve, and so the curve of the compensated axis;
* block means of the rows and T (at most :data:`BLOCK_ROWS` blocks, pairs merged when
  full): the thermal regression of :mod:`imu_allan.core.search.thermal`.

Rows before the first temperature wait (at most :data:`WAIT_S` of rows; beyond, the
thermal analysis is off, with a warning).  A record without temperature never makes
one: its outputs are those of a session without this module.
"""

import json

import numpy as np

from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.core.allan.thermal import thermal_columns
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import N_AXES, SessionConfig

#: Blocks of rows the regression's copy keeps (pairs are merged when it is full).
BLOCK_ROWS = 8192
#: Rows wait this long [s of samples] for the first temperature before the thermal
#: analysis is given up (a temperature topic that never publishes).
WAIT_S = 600.0


# Long because it mirrors the accumulator feed step for step (start, rate, rows, breaks,
# restart, checkpoint) and keeps the rows that wait for a reading; each method is short.
class ThermalFeed:
    """
    The temperature track and the thermal sums of one session.

    Parameters
    ----------
    config : SessionConfig
        Its ``exact_max_m`` (the thermal accumulator's taus equal the main one's).

    """

    def __init__(self, config: SessionConfig):
        self.config = config
        self.acc: AllanAccumulator | None = None
        self.rate_hz = 0.0
        #: Why the thermal analysis is off ('' while it is on).
        self.off_reason = ''
        self._t0: int | None = None
        self._track_ns = np.empty(0, np.int64)
        self._track_c = np.empty(0)
        self._wait: list = []
        self._wait_rows = 0
        cols = N_AXES + 1
        self._sums = np.zeros((BLOCK_ROWS, cols))
        self._n_blocks = 0
        self._part = np.zeros(cols)
        self._part_n = 0
        self._factor = 1

    # ------------------------------------------------------------------ input
    def add_temperature(self, stamp_ns, temp_c) -> None:
        """
        Append temperature readings; non-finite ones are left out.

        Parameters
        ----------
        stamp_ns : array_like
            Shape (n,), stamps [ns] (int64).
        temp_c : array_like
            Shape (n,), temperatures [degC].

        """
        t = np.asarray(stamp_ns, dtype=np.int64).reshape(-1)
        c = np.asarray(temp_c, dtype=np.float64).reshape(-1)
        if t.size != c.size:
            raise InputError(f'temperatures need one stamp each: {t.size} stamps, '
                             f'{c.size} values')
        ok = np.isfinite(c)
        t, c = t[ok], c[ok]
        if not t.size:
            return
        if self._track_ns.size and t[0] <= self._track_ns[-1]:
            # Stamps that go back (a clock restart, a bag out of order): merge in order.
            t = np.concatenate((self._track_ns, t))
            c = np.concatenate((self._track_c, c))
            order = np.argsort(t, kind='stable')
            t, c = t[order], c[order]
        else:
            t = np.concatenate((self._track_ns, t))
            c = np.concatenate((self._track_c, c))
        self._track_ns, self._track_c = t, c
        if self._t0 is None:
            self._t0 = int(t[0])
        self._release(int(t[-1]))

    def _release(self, until_ns: int | None) -> None:
        """Take the waiting rows up to ``until_ns`` [ns] (None: all, the last value held)."""
        if self.acc is None:
            return
        while self._wait:
            item = self._wait[0]
            if item is None:
                self._wait.pop(0)
                self.acc.break_segment()
                continue
            rows, stamps, missing = item
            n = (stamps.size if until_ns is None
                 else int(np.searchsorted(stamps, until_ns, 'right')))
            if n:
                self._take(rows[:n], stamps[:n], None if missing is None else missing[:n])
                self._wait_rows -= n
            if n < stamps.size:
                self._wait[0] = (rows[n:], stamps[n:], None if missing is None else missing[n:])
                return
            self._wait.pop(0)

    @property
    def has_temperature(self) -> bool:
        """Return True once a temperature reading came in."""
        return self._t0 is not None

    def temperature_at(self, stamp_ns: np.ndarray) -> np.ndarray:
        """Return the temperature at each stamp [degC], shape of ``stamp_ns``."""
        assert self._t0 is not None
        return np.interp((np.asarray(stamp_ns) - self._t0).astype(np.float64),
                         (self._track_ns - self._t0).astype(np.float64), self._track_c)

    # ------------------------------------------------------------- the rows
    def start(self, rate_hz: float) -> None:
        """Start empty at ``rate_hz`` [Hz] (the main accumulator starts with it)."""
        kwargs = {'exact_max_m': self.config.exact_max_m} if self.config.exact_max_m else {}
        self.acc = AllanAccumulator(N_AXES + 1, rate_hz, **kwargs)
        self.rate_hz = rate_hz
        self._wait, self._wait_rows = [], 0
        self._sums[:] = 0.0
        self._n_blocks, self._part_n, self._factor = 0, 0, 1
        self._part[:] = 0.0

    def set_rate(self, rate_hz: float) -> None:
        """Follow a refined rate estimate [Hz]."""
        if self.acc is not None and rate_hz != self.rate_hz:
            self.acc.rate_hz = rate_hz
        self.rate_hz = rate_hz

    def add(self, rows: np.ndarray, stamp_ns: np.ndarray, missing: np.ndarray | None) -> None:
        """Take the rows (n, 6) the main accumulator took, their stamps and fill marks."""
        if self.acc is None or self.off_reason:
            return
        # Rows after the last reading wait for the next (a topic's reading comes later).
        if not self._wait and self.has_temperature and stamp_ns[-1] <= self._track_ns[-1]:
            self._take(rows, stamp_ns, missing)
            return
        self._wait.append((rows.copy(), stamp_ns.copy(),
                           None if missing is None else missing.copy()))
        self._wait_rows += rows.shape[0]
        if self.has_temperature:
            self._release(int(self._track_ns[-1]))
        if self._wait_rows > WAIT_S * max(self.rate_hz, 1.0):
            if self.has_temperature:     # the topic went quiet: its last value is held
                self._release(None)
                return
            self.off_reason = (f'no temperature came with the first {WAIT_S:g} s of '
                               'samples: the thermal analysis is off')
            self._wait, self._wait_rows = [], 0

    def flush(self) -> None:
        """Take the rows still waiting, the last temperature held (the end of the data)."""
        if self.has_temperature:
            self._release(None)

    def _take(self, rows: np.ndarray, stamp_ns: np.ndarray,
              missing: np.ndarray | None) -> None:
        assert self.acc is not None
        cols = thermal_columns(rows, self.temperature_at(stamp_ns))
        self.acc.add(cols, missing=missing)
        self._keep_means(np.concatenate((rows, cols[:, :1]), axis=1))
        # Rows come in stamp order: readings before this block's first are not needed.
        first = int(np.searchsorted(self._track_ns, stamp_ns[0])) - 1
        if first > 0:
            self._track_ns, self._track_c = self._track_ns[first:], self._track_c[first:]

    def _keep_means(self, cols: np.ndarray) -> None:
        """Add rows (n, 7) to the block sums; merge pairs when the blocks are full."""
        f = self._factor
        if self._part_n:
            take = min(f - self._part_n, cols.shape[0])
            self._part += cols[:take].sum(axis=0)
            self._part_n += take
            cols = cols[take:]
            if self._part_n < f:
                return
            self._push(self._part[None].copy())
            self._part[:], self._part_n = 0.0, 0
        f = self._factor
        whole = cols.shape[0] // f * f
        if whole:
            self._push(cols[:whole].reshape(-1, f, cols.shape[1]).sum(axis=1))
        rest = cols[whole:]
        if rest.shape[0]:
            self._part += rest.sum(axis=0)
            self._part_n += rest.shape[0]

    def _push(self, sums: np.ndarray) -> None:
        while sums.shape[0]:
            take = min(BLOCK_ROWS - self._n_blocks, sums.shape[0])
            self._sums[self._n_blocks:self._n_blocks + take] = sums[:take]
            self._n_blocks += take
            sums = sums[take:]
            if self._n_blocks == BLOCK_ROWS:
                self._sums[:BLOCK_ROWS // 2] = self._sums[0::2] + self._sums[1::2]
                self._sums[BLOCK_ROWS // 2:] = 0.0
                self._n_blocks = BLOCK_ROWS // 2
                self._factor *= 2
                if sums.shape[0] % 2:
                    self._part += sums[-1]
                    self._part_n += self._factor // 2
                    sums = sums[:-1]
                sums = sums[0::2] + sums[1::2]

    def block_means(self) -> tuple[np.ndarray, float]:
        """Return the block means (n, 7: the axes, then T [degC]) and their rate [Hz]."""
        return self._sums[:self._n_blocks] / self._factor, self.rate_hz / self._factor

    def break_segment(self) -> None:
        """End the contiguous segment (the main accumulator's break)."""
        if self.acc is None:
            return
        if self._wait:
            self._wait.append(None)
        else:
            self.acc.break_segment()

    def restart(self) -> None:
        """Discard the rows taken so far (the main accumulator restarted)."""
        if self.acc is not None:
            self.start(self.rate_hz)

    # ------------------------------------------------------------- checkpoint
    def state(self) -> dict:
        """Return the state as arrays, prefixed ``thermal__`` (waiting rows taken first)."""
        assert self.acc is not None
        self.flush()
        acc_meta, acc_arrays = self.acc.to_state()
        meta = {'acc': acc_meta, 'off_reason': self.off_reason, 't0': self._t0,
                'n_blocks': self._n_blocks, 'part_n': self._part_n,
                'factor': self._factor, 'rate_hz': self.rate_hz}
        arrays = {f'thermal__acc__{k}': v for k, v in acc_arrays.items()}
        arrays.update({'thermal__meta': np.array(json.dumps(meta)),
                       'thermal__track_ns': self._track_ns, 'thermal__track_c': self._track_c,
                       'thermal__sums': self._sums[:self._n_blocks],
                       'thermal__part': self._part})
        return arrays

    @classmethod
    def restore(cls, config: SessionConfig, arrays: dict) -> 'ThermalFeed | None':
        """Return the feed saved by :meth:`state` (None when none was); InputError if bad."""
        if 'thermal__meta' not in arrays:
            return None
        try:
            meta = json.loads(str(arrays['thermal__meta']))
            acc = AllanAccumulator.from_state(
                meta['acc'], {k[len('thermal__acc__'):]: v for k, v in arrays.items()
                              if k.startswith('thermal__acc__')})
            feed = cls(config)
            feed.acc, feed.rate_hz = acc, float(meta['rate_hz'])
            feed.off_reason = str(meta['off_reason'])
            feed._t0 = None if meta['t0'] is None else int(meta['t0'])
            feed._track_ns = np.asarray(arrays['thermal__track_ns'], dtype=np.int64)
            feed._track_c = np.asarray(arrays['thermal__track_c'], dtype=np.float64)
            n = int(meta['n_blocks'])
            feed._sums[:n] = arrays['thermal__sums']
            feed._n_blocks, feed._part_n = n, int(meta['part_n'])
            feed._part[:] = arrays['thermal__part']
            feed._factor = int(meta['factor'])
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f'the thermal state is invalid: {exc}') from None
        if (acc.n_axes != N_AXES + 1 or feed._track_ns.shape != feed._track_c.shape
                or not 0 <= n <= BLOCK_ROWS or feed._factor < 1):
            raise InputError('the thermal state is inconsistent')
        return feed
