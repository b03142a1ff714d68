"""
The session's last stage: the Allan accumulator and what feeds it.

:class:`AccumulatorFeed` owns the accumulator, takes the still rows the sample gate
keeps and hands them on in as few calls as it can.
"""

import json

import numpy as np

from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.errors import InputError
from imu_allan.pipeline.fills import filled
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, SessionConfig
from imu_allan.pipeline.thermal import ThermalFeed

#: Still runs at least this long reach the accumulator as they are, shorter ones joined.
_DIRECT_ROWS = 4096


class AccumulatorFeed:
    """
    The accumulator of a session, and the still rows on their way to it.

    Parameters
    ----------
    config : SessionConfig
        Its ``exact_max_m``.
    stats : HygieneStats
        ``n_used`` counts the rows queued here.

    """

    def __init__(self, config: SessionConfig, stats: HygieneStats):
        self.config = config
        self.stats = stats
        self.acc: AllanAccumulator | None = None
        self.rate_hz = 0.0
        self._queued: list[np.ndarray] = []
        self._filled: list[np.ndarray | None] = []
        self._stamps: list[np.ndarray | None] = []
        #: The temperature's sums (pipeline/thermal.py); None without a temperature.
        self.thermal: ThermalFeed | None = None

    def start(self, rate_hz: float) -> None:
        """Start a new, empty accumulator at ``rate_hz`` [Hz]."""
        kwargs = {'exact_max_m': self.config.exact_max_m} if self.config.exact_max_m else {}
        self.acc = AllanAccumulator(N_AXES, rate_hz, **kwargs)
        self.rate_hz = rate_hz
        if self.thermal is not None:
            self.thermal.start(rate_hz)

    def set_rate(self, rate_hz: float) -> None:
        """Follow a refined rate estimate [Hz]."""
        if self.acc is not None and rate_hz != self.rate_hz:
            self.acc.rate_hz = rate_hz
        self.rate_hz = rate_hz
        if self.thermal is not None:
            self.thermal.set_rate(rate_hz)

    def queue(self, samples: np.ndarray, stamp_ns: np.ndarray | None = None,
              counted: bool = False) -> None:
        """
        Take still rows (n, 6) and their stamps (n,) [ns]; on at :meth:`pass_on`.

        Rows that fill a short gap (:mod:`imu_allan.pipeline.fills`) reach it marked
        as missing and do not count as used; ``counted``: the rows already count as
        used (held for the settling judgement).
        """
        fill = filled(samples)
        self._queued.append(samples)
        self._filled.append(fill)
        self._stamps.append(stamp_ns)
        if not counted:
            self.stats.n_used += samples.shape[0] - (0 if fill is None else int(fill.sum()))

    def pass_on(self) -> None:
        """Hand the queued rows to the accumulator, in order."""
        # Long runs go as they are (the accumulator copies them anyway); short ones,
        # window by window while the IMU moved now and then, are joined into one call.
        if not self._queued:
            return
        assert self.acc is not None
        short: list = []
        marks: list = []
        stamps: list = []
        for piece, fill, t in zip(self._queued + [None], self._filled + [None],
                                  self._stamps + [None]):
            if piece is not None and piece.shape[0] < _DIRECT_ROWS:
                short.append(piece)
                marks.append(fill)
                stamps.append(t)
                continue
            if short:
                self._add(short, marks, stamps)
                short, marks, stamps = [], [], []
            if piece is not None:
                self._add([piece], [fill], [t])
        self._queued, self._filled, self._stamps = [], [], []

    def _add(self, pieces: list, marks: list, stamps: list) -> None:
        """Hand pieces of rows, joined, and their fill marks to the accumulator."""
        assert self.acc is not None
        rows = pieces[0] if len(pieces) == 1 else np.concatenate(pieces)
        missing = None
        if any(m is not None for m in marks):
            missing = np.concatenate([np.zeros(p.shape[0], bool) if m is None else m
                                      for p, m in zip(pieces, marks)])
        self.acc.add(rows, missing=missing)
        if self.thermal is not None:
            if any(t is None for t in stamps):
                raise InputError('a still run reached the thermal sums without its stamps')
            self.thermal.add(rows, np.concatenate(stamps), missing)

    def break_segment(self) -> None:
        """End the contiguous segment: no Allan term spans what comes next."""
        self.pass_on()
        if self.acc is not None:
            self.acc.break_segment()
        if self.thermal is not None:
            self.thermal.break_segment()

    def restart(self) -> None:
        """Discard everything accumulated so far and start empty."""
        self._queued, self._filled, self._stamps = [], [], []
        self.stats.n_used = 0
        self.start(self.rate_hz)

    def close(self) -> None:
        """End the recording: hand the queued rows on."""
        self.pass_on()
        if self.thermal is not None:
            self.thermal.flush()

    def state(self) -> dict:
        """Return the accumulator's state as arrays (its own file's keys, prefixed)."""
        self.pass_on()
        assert self.acc is not None
        acc_meta, acc_arrays = self.acc.to_state()
        arrays = {f'acc__{k}': v for k, v in acc_arrays.items()}
        arrays['acc__meta'] = np.array(json.dumps(acc_meta))
        return arrays if self.thermal is None else {**arrays, **self.thermal.state()}

    def restore(self, arrays: dict, rate_hz: float) -> None:
        """Take the accumulator saved by :meth:`state`; InputError when it is invalid."""
        acc_arrays = {k[5:]: v for k, v in arrays.items() if k.startswith('acc__')}
        if 'meta' not in acc_arrays:
            raise InputError('the accumulator state is missing')
        try:
            meta = json.loads(str(acc_arrays.pop('meta')))
        except ValueError:
            raise InputError('the accumulator metadata is not JSON') from None
        acc = AllanAccumulator.from_state(meta, acc_arrays)
        if acc.n_axes != N_AXES or not abs(acc.rate_hz / rate_hz - 1) < 1e-9:
            raise InputError('the accumulator does not match the stamp clock')
        self.acc, self.rate_hz = acc, rate_hz
        self.thermal = ThermalFeed.restore(self.config, arrays)
