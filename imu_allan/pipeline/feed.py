"""
An Allan accumulator that works on a thread of its own, fed by the session's checks.

Offline, one input on two cores: while the accumulator sums one run of still samples
(numpy, outside the GIL), the session already checks the next block.  The accumulator
receives the same calls in the same order as inline, so its sums are bit-identical.
"""

import queue
import threading
import weakref

from imu_allan.core.allan.accumulator import AllanAccumulator

#: Calls waiting for the accumulator at most (each holds one run of samples).
_DEPTH = 8
_STOP = ('stop', None)


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

    def add(self, samples) -> None:
        """Queue a block of samples (see :meth:`AllanAccumulator.add`)."""
        self._raise()
        self._calls.put(('add', samples))

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
                    acc.add(samples)
                else:
                    acc.break_segment()
        except Exception as exc:  # noqa: B902 - handed to the feeding thread
            errors.append(exc)
        finally:
            calls.task_done()
