"""
The node's services: ~/reset, ~/save and ~/diagnose, and the diagnosis itself.

A mixin of :class:`imu_allan.ros.node.ImuAllanNode`, whose input
(:class:`~imu_allan.ros.live.LiveInput`), publishers and logger it uses.  A diagnosis
takes seconds to minutes, so the service starts it on a worker thread and answers at
once; the summary follows on ~/diagnosis.
"""

import threading
import time

from std_msgs.msg import String

from imu_allan.core.diagnose import diagnose_session, RawKeeper
from imu_allan.errors import InputError


class _Services:
    """Service callbacks and the diagnosis of :class:`~imu_allan.ros.node.ImuAllanNode`."""

    def _on_reset(self, request, response):
        self.live.reset()
        self.collection_stopped = False
        self._plans, self._plan_mark = {}, time.monotonic()
        self._last_result = None
        self._axis_statuses = []
        response.success = True
        response.message = 'accumulator reset: a new characterisation starts now'
        self.get_logger().info(response.message)
        return response

    def _on_save(self, request, response):
        try:
            paths = self.save()
        except (InputError, OSError) as exc:
            response.success, response.message = False, str(exc)
        else:
            response.success = True
            response.message = 'wrote ' + ', '.join(str(p) for p in paths)
        return response

    def _on_diagnose(self, request, response):
        # A diagnosis takes seconds to minutes (refits and re-simulations): it runs on a
        # worker thread so the executor keeps taking input; the summary follows on
        # ~/diagnosis.
        if self._diagnose_thread is not None and self._diagnose_thread.is_alive():
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
        self._diagnose_thread = threading.Thread(target=self._diagnose_and_log,
                                                 args=(view, raw), name='imu_allan_diagnose',
                                                 daemon=True)
        self._diagnose_thread.start()
        response.success = True
        response.message = (f'diagnosing {view.stats.n_used:,} samples in the background; '
                            'the summary will be published on ~/diagnosis')
        return response

    def _diagnose_and_log(self, view, raw) -> None:
        try:
            self.diagnose(view, raw)
        except InputError as exc:
            self.get_logger().warning(f'diagnosis failed: {exc}')

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
        result = diagnose_session(view, raw, source=self.subscription.topic_name)
        if result is None:
            raise InputError('not enough data for any Allan deviation yet')
        text = '\n'.join(result.summary_lines())
        self.pub_diagnosis.publish(String(data=text))
        self.get_logger().info('diagnosis:\n' + text)
        return text
