"""
The session's last stage: the Allan accumulator and what feeds it.

:class:`AccumulatorFeed` owns the accumulator, takes the still rows the sample gate
keeps and hands them on in as few calls as it can.  Offline, one input on two cores,
the accumulator works on a thread of its own (:class:`BackgroundAccumulator`): while it
sums one run of still samples (numpy, outside the GIL), the session already checks the
next block.  It receives the same calls in the same order as inline, so its sums are
bit-identical.
"""

import json
import queue
import threading
import weakref

import numpy as np

from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.errors import InputError
from imu_allan.pipeline.fills import filled
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, SessionConfig

#: Calls waiting for the accumulator at most (each holds one run of samples).
_DEPTH = 8
_STOP = ('stop', None)
#: Still runs at least this long reach the accumulator as they are, shorter ones joined.
_DIRECT_ROWS = 4096


class AccumulatorFeed:
    """
    The accumulator of a session, and the still rows on their way to it.

    Parameters
    ----------
    config : SessionConfig
        Its ``exact_max_m`` and ``background_accumulator``.
    stats : HygieneStats
        ``n_used`` counts the rows queued here.

    """

    def __init__(self, config: SessionConfig, stats: HygieneStats):
        self.config = config
        self.stats = stats
        self.acc: AllanAccumulator | BackgroundAccumulator | None = None
        self.rate_hz = 0.0
        self._queued: list[np.ndarray] = []
        self._filled: list[np.ndarray | None] = []

    def start(self, rate_hz: float) -> None:
        """Start a new, empty accumulator at ``rate_hz`` [Hz]."""
        kwargs = {'exact_max_m': self.config.exact_max_m} if self.config.exact_max_m else {}
        acc = AllanAccumulator(N_AXES, rate_hz, **kwargs)
        self.acc = BackgroundAccumulator(acc) if self.config.background_accumulator else acc
        self.rate_hz = rate_hz

    def set_rate(self, rate_hz: float) -> None:
        """Follow a refined rate estimate [Hz]."""
        if self.acc is not None and rate_hz != self.rate_hz:
            self.acc.rate_hz = rate_hz
        self.rate_hz = rate_hz

    def queue(self, samples: np.ndarray) -> None:
        """
        Take still rows (n, 6); they reach the accumulator at :meth:`pass_on`.

        Rows that fill a short gap (:mod:`imu_allan.pipeline.fills`) reach it marked
        as missing and do not count as used.
        """
        fill = filled(samples)
        self._queued.append(samples)
        self._filled.append(fill)
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
        for piece, fill in zip(self._queued + [None], self._filled + [None]):
            if piece is not None and piece.shape[0] < _DIRECT_ROWS:
                short.append(piece)
                marks.append(fill)
                continue
            if short:
                self._add(short, marks)
                short, marks = [], []
            if piece is not None:
                self._add([piece], [fill])
        self._queued, self._filled = [], []

    def _add(self, pieces: list, marks: list) -> None:
        """Hand pieces of rows, joined, and their fill marks to the accumulator."""
        assert self.acc is not None
        rows = pieces[0] if len(pieces) == 1 else np.concatenate(pieces)
        if all(m is None for m in marks):
            self.acc.add(rows)
            return
        missing = np.concatenate([np.zeros(p.shape[0], bool) if m is None else m
                                  for p, m in zip(pieces, marks)])
        self.acc.add(rows, missing=missing)

    def break_segment(self) -> None:
        """End the contiguous segment: no Allan term spans what comes next."""
        self.pass_on()
        if self.acc is not None:
            self.acc.break_segment()

    def restart(self) -> None:
        """Discard everything accumulated so far and start empty."""
        self._queued, self._filled = [], []
        self.stats.n_used = 0
        self.start(self.rate_hz)

    def close(self) -> None:
        """End the recording: a background thread stops, later calls run inline."""
        self.pass_on()
        if isinstance(self.acc, BackgroundAccumulator):
            self.acc = self.acc.close()

    def state(self) -> dict:
        """Return the accumulator's state as arrays (its own file's keys, prefixed)."""
        self.pass_on()
        assert self.acc is not None
        acc_meta, acc_arrays = self.acc.to_state()
        arrays = {f'acc__{k}': v for k, v in acc_arrays.items()}
        arrays['acc__meta'] = np.array(json.dumps(acc_meta))
        return arrays

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


class BackgroundAccumulator:
    """
    Run an :class:`AllanAccumulator`'s ``add`` and ``break_segment`` on a worker thread.

    Both return at once; every other attribute (``curve``, ``n_samples``, ``to_state``,
    setting ``rate_hz`` ...) first waits until the queued calls are done, so a reader
    always sees the accumulator as if the calls had run inline.  The arrays handed to
    ``add`` must not be changed afterwards (the session never changes a block in place).
    An error of the worker is raised by the next call.

    Parameters
    ----------
    acc : AllanAccumulator
        The accumulator to feed.

    """

    def __init__(self, acc: AllanAccumulator):
        calls: queue.Queue = queue.Queue(maxsize=_DEPTH)
        errors: list = []
        worker = threading.Thread(target=_work, args=(acc, calls, errors), daemon=True,
                                  name='imu-allan-accumulator')
        worker.start()
        # The worker must not keep this object alive: the finaliser stops it (unless
        # close() did).
        weakref.finalize(self, _stop, calls, worker)
        object.__setattr__(self, '_acc', acc)
        object.__setattr__(self, '_calls', calls)
        object.__setattr__(self, '_errors', errors)
        object.__setattr__(self, '_worker', worker)

    def _raise(self) -> None:
        if self._errors:
            raise self._errors.pop(0)

    def add(self, samples, missing=None) -> None:
        """Queue a block of samples (see :meth:`AllanAccumulator.add`)."""
        self._raise()
        self._calls.put(('add', (samples, missing)))

    def break_segment(self) -> None:
        """Queue the end of the current segment (see :meth:`AllanAccumulator.break_segment`)."""
        self._raise()
        self._calls.put(('break', None))

    def sync(self) -> AllanAccumulator:
        """Wait until every queued call is done; return the accumulator."""
        self._calls.join()
        self._raise()
        return self._acc

    def close(self) -> AllanAccumulator:
        """Wait for the queued calls, stop the worker thread; return the accumulator."""
        acc = self.sync()
        self._calls.put(_STOP)
        self._worker.join()
        return acc

    def __getattr__(self, name: str):
        return getattr(self.sync(), name)

    def __setattr__(self, name: str, value) -> None:
        setattr(self.sync(), name, value)


def _stop(calls: queue.Queue, worker: threading.Thread) -> None:
    if worker.is_alive():
        calls.put(_STOP)


def _work(acc: AllanAccumulator, calls: queue.Queue, errors: list) -> None:
    """Carry out the queued calls in order until told to stop."""
    while True:
        kind, samples = calls.get()
        try:
            if kind == 'stop':
                return
            if not errors:      # after an error the rest is dropped, as inline
                if kind == 'add':
                    acc.add(*samples)
                else:
                    acc.break_segment()
        except Exception as exc:  # noqa: B902 - handed to the feeding thread
            errors.append(exc)
        finally:
            calls.task_done()
