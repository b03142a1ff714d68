"""
Messages lost on irregular stamps: the spread of the message counts per window.

On regular stamps a lost message leaves a step of two periods, and the stamp clock
counts it (:mod:`imu_allan.pipeline.clock`).  Irregular (host arrival) stamps show no
such step: a host that reads a sensor's buffer in bursts stamps most messages a few
milliseconds apart and waits far longer between bursts, and a lost message is one fewer
in a burst.
The samples are taken as evenly spaced at the mean rate of the messages that arrived,
so a share p lost lowers the rate by p and N reads high by sqrt(1 / (1 - p)): the
MPU-6050 record with 10 % lost at random gave N 1.05-1.09 times the clean record's on
every axis, intervals disjoint, no warning (docs/robustness.md).

Where they were lost cannot be seen, but that they were can: the messages of a sensor
sampling at its own rate arrive in every window of :data:`~imu_allan.core.rules.
LOST_WINDOW_S` in nearly the same number (a read burst more or less), while messages
lost independently with probability p make the count binomial, its variance over its
mean (the Fano factor) p more, and lost in runs many times p.  :class:`LostWatch`
counts the messages per window (windows from the first stamp on; one with a break of
the segment in it is left out) and warns, on irregular stamps, once the Fano factor
over at least :data:`~imu_allan.core.rules.LOST_MIN_WINDOWS` windows exceeds
:data:`~imu_allan.core.rules.LOST_FANO`.
"""

import math

import numpy as np

from imu_allan.core.rules import LOST_FANO, LOST_MIN_WINDOWS, LOST_WINDOW_S
from imu_allan.errors import InputError
from imu_allan.pipeline.hygiene import HygieneStats, NS, WarningLog


class LostWatch:
    """
    Count the messages per window of irregular stamps; warn when messages were lost.

    Parameters
    ----------
    stats : HygieneStats
        Its ``irregular_stamps`` decides whether the counts are judged.
    warn : WarningLog
        Where the warning goes.

    """

    def __init__(self, stats: HygieneStats, warn: WarningLog):
        self.stats = stats
        self._warn = warn
        self.window_ns = int(LOST_WINDOW_S * NS)
        # First stamp (the windows' origin), the open window: index, count, broken.
        self.origin_ns: int | None = None
        self.index = 0
        self.count = 0
        self.broken = False
        # Closed whole windows: their number, the sum of the counts and of their squares.
        self.sums = np.zeros(3)

    def take(self, stamp_ns: np.ndarray) -> None:
        """Count a gap-free run's stamps (n,) [ns], in increasing order."""
        if not stamp_ns.size:
            return
        if self.origin_ns is None or stamp_ns[0] < self.origin_ns + self.index * self.window_ns:
            # The first stamps, or a clock that restarted: windows from here on.
            self.origin_ns, self.index, self.count = int(stamp_ns[0]), 0, 0
        idx = (stamp_ns - self.origin_ns) // self.window_ns
        ends = np.flatnonzero(np.diff(idx)) + 1
        starts = np.concatenate(([0], ends))
        counts = np.diff(np.concatenate((starts, [idx.size])))
        closed = False
        for i, c in zip(idx[starts], counts):
            if i != self.index:
                closed |= self._close(int(i))
            self.count += int(c)
        if closed:
            self._judge()

    def end_segment(self) -> None:
        """Leave the open window out: the segment breaks in it."""
        self.broken = True

    def _close(self, index: int) -> bool:
        """Close the open window, open window ``index``; return whether one was counted."""
        whole = not self.broken and index == self.index + 1
        if whole:
            self.sums += (1.0, self.count, float(self.count) ** 2)
        self.index, self.count, self.broken = index, 0, False
        return whole

    @property
    def fano(self) -> float:
        """Return the variance of the counts over their mean (NaN before two windows)."""
        n, s1, s2 = self.sums
        if n < 2 or s1 <= 0:
            return math.nan
        mean = s1 / n
        return float((s2 - n * mean * mean) / (n - 1) / mean)

    def _judge(self) -> None:
        f = self.fano
        if (not self.stats.irregular_stamps or self.sums[0] < LOST_MIN_WINDOWS
                or not f > LOST_FANO):
            return
        if f < 0.5:
            share = (f'about {100 * f:.0f} % of them were lost one by one (fewer if in '
                     f'runs), and N reads high by up to {100 * (1 / math.sqrt(1 - f) - 1):.1f}'
                     ' %')
        else:
            share = 'messages were lost in runs, and N reads high by about half the share lost'
        first = 'lost' not in self._warn.text
        self._warn.tally('lost', f'messages lost: on these irregular stamps the number of '
                         f'messages per {LOST_WINDOW_S:g} s varies {f:.2g} times its mean (a '
                         'sensor read at its own rate: under 0.03), as if '
                         f'{share}; irregular stamps cannot show where, so the rate is the '
                         "mean rate of the messages that arrived. Record the sensor's own "
                         'stamps or a sequence counter, or make the link lossless (reliable '
                         'QoS, a lower rate)', 1 if first else 0)

    # ------------------------------------------------------------- checkpoint
    def state(self) -> dict:
        """Return the arrays of the counts."""
        origin = -1 if self.origin_ns is None else self.origin_ns
        return {'lost_open': np.array([origin, self.index, self.count, int(self.broken)],
                                      dtype=np.int64),
                'lost_sums': self.sums.copy()}

    def restore(self, arrays: dict) -> None:
        """Take the arrays of :meth:`state` (none saved: a checkpoint from before)."""
        opened, sums = arrays.get('lost_open'), arrays.get('lost_sums')
        if opened is None and sums is None:
            return
        if (opened is None or sums is None or opened.shape != (4,) or sums.shape != (3,)
                or (opened[1:] < 0).any() or opened[3] > 1 or (sums < 0).any()):
            raise InputError('the message counts are invalid')
        self.origin_ns = None if opened[0] < 0 else int(opened[0])
        self.index, self.count = int(opened[1]), int(opened[2])
        self.broken, self.sums = bool(opened[3]), sums.astype(np.float64)
