"""
The node's services: ~/reset, ~/save and ~/diagnose, and the diagnosis itself.

:class:`NodeServices` is a plain object the node owns; it is given the node's input
(:class:`~imu_allan.ros.live.LiveInput`), logger and the few node actions it needs (save
the result files, forget the last result, publish a diagnosis) as callables.  A
diagnosis takes seconds to minutes, so the service starts it on a worker thread and
answers at once; the summary follows on ~/diagnosis.
"""

import threading
from typing import Callable

from imu_allan.core.allan.raw import RawKeeper
from imu_allan.core.diagnose.engine import diagnose_session
from imu_allan.errors import InputError
from imu_allan.ros.live import LiveInput


class NodeServices:
    """
    Service callbacks and the diagnosis of one node.

    Parameters
    ----------
    live : LiveInput
        The node's input side (reset, processed and snapshotted here).
    logger : object
        Has ``info`` and ``warning`` taking one string (the node's logger).
    source : str
        The Imu topic, named in the diagnosis.
    save : callable
        ``save() -> list of Path``: write the result files (raises InputError or OSError).
    forget : callable
        ``forget()``: drop the node's last result and statuses (after a reset).
    publish_diagnosis : callable
        ``publish_diagnosis(text)``: publish a diagnosis summary on ~/diagnosis.

    """

    def __init__(self, live: LiveInput, logger, source: str, save: Callable[[], list],
                 forget: Callable[[], None], publish_diagnosis: Callable[[str], None]):
        self.live, self.log, self.source = live, logger, source
        self._save, self._forget, self._publish_diagnosis = save, forget, publish_diagnosis
        self.diagnose_thread: threading.Thread | None = None

    def on_reset(self, request, response):
        """~/reset: a new session, no checkpoint left to resume from, no last result."""
        self.live.reset()
        self._forget()
        response.success = True
        response.message = 'accumulator reset: a new characterisation starts now'
        self.log.info(response.message)
        return response

    def on_save(self, request, response):
        """~/save: write the result files; the message lists them or says why not."""
        try:
            paths = self._save()
        except (InputError, OSError) as exc:
            response.success, response.message = False, str(exc)
        else:
            response.success = True
            response.message = 'wrote ' + ', '.join(str(p) for p in paths)
        return response

    def on_diagnose(self, request, response):
        """~/diagnose: start a diagnosis on a worker thread; answer at once."""
        # A diagnosis takes seconds to minutes (refits and re-simulations): it runs on a
        # worker thread so the executor keeps taking input.
        if self.diagnose_thread is not None and self.diagnose_thread.is_alive():
            response.success = False
            response.message = 'a diagnosis is already running; its summary will be ' \
                'published on ~/diagnosis'
            return response
        self.live.process()
        view, raw = self.live.snapshot()
        if view.curve(bounds=False) is None:
            response.success = False
            response.message = 'not enough data for any Allan deviation yet'
            return response
        self.diagnose_thread = threading.Thread(target=self._diagnose_and_log,
                                                args=(view, raw), name='imu_allan_diagnose',
                                                daemon=True)
        self.diagnose_thread.start()
        response.success = True
        response.message = (f'diagnosing {view.stats.n_used:,} samples in the background; '
                            'the summary will be published on ~/diagnosis')
        return response

    def _diagnose_and_log(self, view, raw) -> None:
        try:
            self.diagnose(view, raw)
        except InputError as exc:
            self.log.warning(f'diagnosis failed: {exc}')

    def diagnose(self, view=None, raw: RawKeeper | None = None) -> str:
        """
        Diagnose the data so far (imu_allan.core.diagnose); publish the summary on ~/diagnosis.

        Runs in the caller's thread (the ~/diagnose service runs it on a worker thread).
        A sinusoid is checked in the periodogram of the block-averaged samples the node
        keeps (``diagnose_raw_samples`` rows; with 0, from the Allan curve alone).

        Parameters
        ----------
        view : optional
            A snapshot of the session (default: one taken now, with the raw samples).
        raw : RawKeeper, optional
            A snapshot of the kept samples, taken with ``view``.

        Returns
        -------
        str
            One line per axis: the gap between model and data and what is missing.

        Raises
        ------
        InputError
            If there is not enough data for any Allan deviation yet.

        """
        if view is None:
            self.live.process()
            view, raw = self.live.snapshot()
        result = diagnose_session(view, raw, source=self.source)
        if result is None:
            raise InputError('not enough data for any Allan deviation yet')
        text = '\n'.join(result.summary_lines())
        self._publish_diagnosis(text)
        self.log.info('diagnosis:\n' + text)
        return text
