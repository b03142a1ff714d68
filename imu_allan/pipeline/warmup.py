"""
The warm-up hold of a session: the first still rows of a run wait to be judged.

A sensor just switched on has not settled (:mod:`imu_allan.core.allan.settling`).
:class:`WarmupGate` stands between the sample gate and the accumulator feed: it holds
the still rows at the start of the record, and again after the sensor restarted (the
stamp clock restarted, or the stamps stopped for :data:`RESTART_GAP_S`), until it has
``warmup_window_s`` of them (at most :data:`MAX_HELD_ROWS`).  It then finds where the
output settled, leaves the rows before that out, says so in one warning, and passes
the rest on; from there on rows go straight through.  A window that is all transient
is left out whole and the next one judged (what the transient still needs is cut
there at least), at most :data:`MAX_WINDOWS` in a row.  A record that ends, or a curve
that is needed, before the window is full is judged on what there is, and keeps at
least :data:`KEEP_SHARE` of it.  Motion the motion gate saw in the time left out was
the settling output (its still reference lags a fast transient): it leaves the motion
counters and warnings, and the warning says so.

The rows held count as used (``n_used``) until they are left out.  The window is
judged on exactly its first rows, so the cut does not depend on how the record was
cut into blocks, and the rows held are part of the checkpoint.
"""

import math

import numpy as np

from imu_allan import AXES
from imu_allan.core.allan.settling import find_settling, Settling, Transient
from imu_allan.errors import InputError
from imu_allan.pipeline.fills import filled
from imu_allan.pipeline.hygiene import HygieneStats, N_AXES, NS, SessionConfig, WarningLog

#: Most rows held [rows]: 50 MB of samples (17 min at 1 kHz).
MAX_HELD_ROWS = 2 ** 20
#: Stamps that stop this long may hide a power cycle: a new window follows [s].
RESTART_GAP_S = 60.0
#: A window judged at the end of the record keeps at least this share of its rows.
KEEP_SHARE = 0.25
#: Windows in a row that a transient may take whole; then the rows pass, with a warning.
MAX_WINDOWS = 4
#: The start of the warning that the output was still settling where the cut stops.
STILL_SETTLING = 'still settling'


# Long because it stands in for the feed towards the gates (queue, pass_on,
# break_segment, restart, close) and its held rows and their breaks survive a
# checkpoint; the judgement itself is core.allan.settling.
class WarmupGate:
    """
    Hold the first still rows of each run until the output is judged settled.

    Parameters
    ----------
    config : SessionConfig
        Its ``warmup_window_s`` (0: nothing is held).
    stats : HygieneStats
        ``n_used``, ``n_warmup``, ``warmup_s`` and ``warmup_axes``.
    warn : WarningLog
        Where the warning goes.
    feed : imu_allan.pipeline.feed.AccumulatorFeed
        Where the rows go.

    """

    def __init__(self, config: SessionConfig, stats: HygieneStats, warn: WarningLog, feed):
        self.config = config
        self.stats = stats
        self._warn = warn
        self.feed = feed
        #: Rows are held now.
        self.holding = config.warmup_window_s > 0
        self._rows: list[np.ndarray] = []
        # Their stamps [ns] (the thermal sums need them), None where a caller gave none.
        self._stamps: list[np.ndarray | None] = []
        self._n = 0
        self._used = 0                 # of them real rows (fills left out)
        # Held-row offsets before which the segment breaks.
        self._breaks: list[int] = []
        self._windows = 0              # windows of this run left out whole
        self._run_start_s: float = 0.0  # where the run starts in the record [s]
        self._last_ns: int | None = None
        self._elapsed_ns = 0            # the record's time so far, by its stamps
        self._restarts = 0
        # The motion counters while the window fills: [held rows, episodes, samples
        # dropped, re-anchors] at the window's start, then at each change.  A settling
        # output drifts faster than the motion gate's still reference follows.
        self._marks: list[list[int]] = [[0, 0, 0, 0]] if self.holding else []
        self._explained = 0             # of the window's episodes, the settling output's
        # The transients of the window left out whole before this one, in its time.
        self._whole: Settling | None = None

    # ------------------------------------------------------------ the runs
    def follow(self, stamp_ns: np.ndarray) -> None:
        """
        Open a new window when this run starts after a sensor restart.

        Call with each gap-free run of the stamp clock before its rows are gated: a
        clock restart, or stamps that stopped for ``RESTART_GAP_S`` (also across a
        resume from a checkpoint), may be a power cycle.
        """
        restarted = self.stats.n_clock_restarts != self._restarts
        gap = (self._last_ns is not None and not restarted
               and stamp_ns[0] - self._last_ns >= RESTART_GAP_S * NS)
        if self._last_ns is not None and not restarted:
            self._elapsed_ns += int(stamp_ns[0]) - self._last_ns   # (a restart's is unknown)
        if (restarted or gap) and self.config.warmup_window_s > 0:
            if self.holding:
                self._judge(final=True)
            self.holding = True
            self._windows = 0
            self._run_start_s = self._elapsed_ns / NS
            self._marks, self._explained = [[0, *self._counters()]], 0
        self._restarts = self.stats.n_clock_restarts
        self._last_ns = int(stamp_ns[-1])
        self._elapsed_ns += int(stamp_ns[-1]) - int(stamp_ns[0])

    @property
    def held_rows(self) -> int:
        """Return the rows held now."""
        return self._n

    @property
    def held_used(self) -> int:
        """Return the rows held now that count as used (``n_used``; fills do not)."""
        return self._used

    def window_rows(self) -> int:
        """Return the rows a window holds at the feed's rate (0 before it is known)."""
        rate = self.feed.rate_hz
        if rate <= 0:
            return 0
        return max(1, min(int(round(self.config.warmup_window_s * rate)), MAX_HELD_ROWS))

    # ------------------------------------------------ the feed's interface
    def queue(self, samples: np.ndarray, stamp_ns: np.ndarray | None = None) -> None:
        """Take still rows (n, 6), stamps (n,) [ns]: held while the window fills."""
        if not self.holding:
            self.feed.queue(samples, stamp_ns)
            return
        if self._marks and self._counters() != self._marks[-1][1:]:
            self._marks.append([self._n, *self._counters()])
        self._used += _real(samples)
        self.stats.n_used += _real(samples)
        self._rows.append(samples.copy())     # the caller may reuse its array
        self._stamps.append(None if stamp_ns is None else np.array(stamp_ns, np.int64))
        self._n += samples.shape[0]
        window = self.window_rows()
        while self.holding and window and self._n >= window:
            self._judge(final=False)

    def pass_on(self) -> None:
        """Hand what is not held to the accumulator."""
        self.feed.pass_on()

    def break_segment(self) -> None:
        """End the contiguous segment: also between held rows."""
        if self.holding:
            if self._n and (not self._breaks or self._breaks[-1] != self._n):
                self._breaks.append(self._n)
            return
        self.feed.break_segment()

    def restart(self) -> None:
        """Discard everything so far (motion restart): the held rows too."""
        self._rows, self._n, self._used, self._breaks = [], 0, 0, []
        self._stamps = []
        if self._marks:
            self._marks = [[0, *self._counters()]]
        self.feed.restart()

    def close(self) -> None:
        """End the recording: judge the rows held on what there is; hand all on."""
        if self.holding:
            self._judge(final=True)
        self.feed.close()

    def judge_now(self) -> None:
        """Judge the first window now on what there is (a curve is needed, none exists)."""
        if self.holding and (self.feed.acc is None or self.feed.acc.n_samples == 0):
            self._judge(final=True)

    # ------------------------------------------------------------- judging
    def _judge(self, final: bool) -> None:
        """
        Judge the window (its first ``window_rows`` rows; all held rows when ``final``).

        Leave the rows before the settled point out, pass the rest of the window on;
        rows beyond the window are judged next when the window was all transient.
        """
        rate = self.feed.rate_hz
        if not self._n or rate <= 0:
            self.holding = self.holding and not final
            return
        rows = np.concatenate(self._rows) if len(self._rows) > 1 else self._rows[0]
        given = [t for t in self._stamps if t is not None]
        stamps: np.ndarray | None = (np.concatenate(given) if len(given) == len(self._stamps)
                                     else None)
        n = self._n if final else min(self._n, self.window_rows())
        keep = 0 if not final else int(math.ceil(KEEP_SHARE * n))
        found = _with(find_settling(rows[:n], rate), self._whole, n - keep)
        whole = not final and found.needed_rows > n and self._windows + 1 < MAX_WINDOWS
        cut = n if whole else found.cut_rows
        self._leave_out(rows[:cut], found, whole)
        rest = rows[cut:]
        rest_ns = None if stamps is None else stamps[cut:]
        breaks = [b - cut for b in self._breaks if b > cut]
        self._rows, self._n, self._used, self._breaks = [], 0, 0, []
        self._stamps = []
        if whole:
            # The next window starts here and is judged on its own first rows; what
            # this one's transients still need is cut there at least.
            self._windows += 1
            self._whole = _shifted(found, n)
            if rest.shape[0]:
                self._rows, self._n, self._used = [rest.copy()], rest.shape[0], _real(rest)
                self._stamps = [None if rest_ns is None else rest_ns.copy()]
            self._breaks = breaks
            return
        self.holding = False
        self._marks, self._whole = [], None
        if cut and self.feed.acc is not None and self.feed.acc.n_samples:
            self.feed.break_segment()       # the rows kept do not join the earlier ones
        self._hand_on(rest, breaks, rest_ns)

    def _hand_on(self, rows: np.ndarray, breaks: list, stamp_ns: np.ndarray | None) -> None:
        """Pass rows (and stamps) on to the feed, breaking the segment at ``breaks``."""
        start = 0
        for b in breaks + [rows.shape[0]]:
            if b > start:
                self.feed.queue(rows[start:b],
                                None if stamp_ns is None else stamp_ns[start:b], counted=True)
            if b < rows.shape[0]:
                self.feed.break_segment()
            start = b
        self.feed.pass_on()

    def _leave_out(self, rows: np.ndarray, found: Settling, whole: bool) -> None:
        """Count the rows left out; warn with the axes, sizes, time and what to do."""
        if not rows.shape[0]:
            return
        real = _real(rows)
        s = self.stats
        s.n_used -= real
        s.n_warmup += real
        dropped = self._explain_motion(rows.shape[0])
        cut_s = (rows.shape[0] + dropped) / self.feed.rate_hz
        s.warmup_s = round(s.warmup_s + cut_s, 3)
        axes = [AXES[j] for j in found.axes]
        s.warmup_axes = [a for a in AXES if a in set(s.warmup_axes) | set(axes)]
        if whole:
            return              # said once the run has settled, with the whole time
        before_s = self._windows * self.window_rows() / self.feed.rate_hz
        self._warn('settling', settling_warning(found, self._run_start_s, before_s,
                                                self._explained), once=False)

    def _counters(self) -> list[int]:
        s = self.stats
        return [s.n_motion_events, s.n_motion_dropped, s.n_reanchors]

    def _explain_motion(self, cut: int) -> int:
        """
        Count the motion seen before held row ``cut`` as the output settling.

        Its episodes, samples dropped and re-anchors leave the motion counters (the
        samples dropped join those left out), and when no motion is left, so do the
        motion warnings.  Returns the samples dropped.
        """
        if not self._marks:
            return 0
        k = max(i for i, m in enumerate(self._marks) if m[0] <= cut)
        base = self._marks[0][1:]
        d = [a - b for a, b in zip(self._marks[k][1:], base)]
        s = self.stats
        s.n_motion_events -= d[0]
        s.n_motion_dropped -= d[1]
        s.n_reanchors -= d[2]
        s.n_warmup += d[1]
        self._explained += d[0]
        self._marks = [[0, *base]] + [[m[0] - cut] + [a - b for a, b in zip(m[1:], d)]
                                      for m in self._marks[k + 1:]]
        if d[0] and not s.n_motion_events and not s.n_reanchors:
            self._warn.forget('motion', 'reanchor', 'resume')
        return d[1]

    # ---------------------------------------------------------- checkpoint
    def state(self) -> tuple[dict, dict]:
        """Return (JSON-able state, arrays) of the hold."""
        rows = (np.concatenate(self._rows) if self._rows
                else np.empty((0, N_AXES)))
        return ({'holding': self.holding, 'windows': self._windows,
                 'run_start_s': self._run_start_s, 'last_ns': self._last_ns,
                 'elapsed_ns': self._elapsed_ns, 'restarts': self._restarts,
                 'marks': [list(m) for m in self._marks], 'explained': self._explained,
                 'whole': None if self._whole is None else [
                     self._whole.rows, self._whole.cut_rows, self._whole.rate_hz,
                     self._whole.needed_rows, [list(t) for t in self._whole.transients]]},
                {'warmup_rows': rows, 'warmup_breaks': np.asarray(self._breaks, np.int64),
                 'warmup_stamps': self._held_stamps()})

    def _held_stamps(self) -> np.ndarray:
        """Return the held rows' stamps (n,) [ns], or none (0,) where some were not given."""
        given = [t for t in self._stamps if t is not None]
        if not given or len(given) != len(self._stamps):
            return np.empty(0, np.int64)
        return np.concatenate(given)

    def restore(self, meta, arrays: dict) -> None:
        """Take the state of :meth:`state` (None: saved before the hold existed)."""
        if meta is None:            # an older checkpoint: its rows were all passed on
            self.holding = False
            return
        if not isinstance(meta, dict) or set(meta) != set(self.state()[0]):
            raise InputError('the warm-up hold state is incomplete')
        rows, breaks = arrays.get('warmup_rows'), arrays.get('warmup_breaks')
        if (rows is None or rows.ndim != 2 or rows.shape[1] != N_AXES
                or not np.isfinite(rows).all()):
            raise InputError('the rows of the warm-up hold are invalid')
        if (breaks is None or breaks.ndim != 1 or breaks.dtype.kind not in 'iu'
                or (breaks.size and (breaks.min() < 1 or breaks.max() > rows.shape[0]
                                     or (np.diff(breaks) <= 0).any()))):
            raise InputError('the breaks between the rows of the warm-up hold are invalid')
        if meta['last_ns'] is not None and not isinstance(meta['last_ns'], int):
            raise InputError('the last stamp of the warm-up hold is invalid')
        if not isinstance(meta['elapsed_ns'], int) or meta['elapsed_ns'] < 0:
            raise InputError('the time of the warm-up hold is invalid')
        marks, explained = meta['marks'], meta['explained']
        if (not isinstance(marks, list)
                or not all(isinstance(m, list) and len(m) == 4
                           and all(isinstance(v, int) and v >= 0 for v in m) for m in marks)
                or (marks and marks[0][0] != 0)
                or any(b[0] < a[0] for a, b in zip(marks, marks[1:]))
                or not isinstance(explained, int) or explained < 0):
            raise InputError('the motion counts of the warm-up hold are invalid')
        windows, start, restarts = meta['windows'], meta['run_start_s'], meta['restarts']
        if (not isinstance(windows, int) or not 0 <= windows < MAX_WINDOWS
                or not isinstance(restarts, int) or restarts < 0
                or not isinstance(start, (int, float)) or not math.isfinite(start)
                or start < 0 or not isinstance(meta['holding'], bool)
                or (rows.shape[0] and not meta['holding'])):
            raise InputError('the warm-up hold counters are invalid')
        self.holding, self._windows = meta['holding'], windows
        self._run_start_s, self._restarts = float(start), restarts
        self._last_ns, self._elapsed_ns = meta['last_ns'], meta['elapsed_ns']
        self._marks, self._explained = [list(m) for m in marks], explained
        self._whole = _settling(meta['whole'])
        self._rows = [rows.astype(np.float64)] if rows.shape[0] else []
        stamps = arrays.get('warmup_stamps')
        ok = (stamps is not None and stamps.ndim == 1 and stamps.dtype.kind in 'iu'
              and stamps.shape[0] == rows.shape[0] and rows.shape[0] > 0)
        self._stamps = ([stamps.astype(np.int64) if ok and stamps is not None else None]
                        if rows.shape[0] else [])
        self._n, self._used = rows.shape[0], _real(rows)
        self._breaks = [int(b) for b in breaks]


def settling_warning(found: Settling, run_start_s: float, before_s: float = 0.0,
                     motion: int = 0) -> str:
    """
    Return the one line that says what was left out, why, and what to do.

    Parameters
    ----------
    found : Settling
        The judgement of the window.
    run_start_s : float
        Where the run started in the record [s] (0: the record's start).
    before_s : float
        Time of the windows before it left out whole [s].
    motion : int
        Motion episodes the motion gate saw in the time left out.

    """
    sizes = []
    for j in found.axes:
        a = max((t for t in found.transients if t.axis == j), key=lambda t: abs(t.amplitude))
        sizes.append(f'{AXES[j]} {_quoted(j, a.amplitude)} (time constant '
                     f'{_minutes(a.tau_s)})')
    start = run_start_s <= 0
    where = ('at the start of the record' if start else
             f'after the sensor restarted at {_minutes(run_start_s)} into the record')
    total_s = found.cut_s + before_s
    wait_min = math.ceil((found.needed_rows / found.rate_hz + before_s) / 60)
    text = (f'the output was settling after power-on {where}: {"; ".join(sizes)}; the '
            f'first {_minutes(total_s)} {"of the record" if start else "after it"} are '
            'left out')
    if motion:
        text += (f' (the {motion} motion episode{"s" if motion > 1 else ""} seen then '
                 f'{"were" if motion > 1 else "was"} the output settling)')
    if found.capped:
        left = ', '.join(f'{AXES[j]} {_quoted(j, found.left_at_cut(j))}' for j in found.axes
                         if abs(found.left_at_cut(j)) > 0)
        text += (f'; {STILL_SETTLING} after them ({left} to go): the long-tau noise '
                 'numbers (B, K) of those axes may be too high')
    return text + (f'. Let the IMU settle for {wait_min} min after power-on before '
                   'recording, as the Allan variance procedure asks')


def _with(found: Settling, before: Settling | None, cap: int) -> Settling:
    """
    Return ``found`` with the transients of the window before, capped at ``cap`` rows.

    ``before`` (:func:`_shifted`) is in this window's time: what it still needs is cut
    here too, whether or not this window shows it.
    """
    needed = max(found.needed_rows, before.needed_rows) if before else found.needed_rows
    transients = (before.transients if before else ()) + found.transients
    return Settling(found.rows, min(needed, cap), found.rate_hz, transients, needed)


def _shifted(found: Settling, rows: int) -> Settling:
    """Return ``found`` in the time of the window that starts ``rows`` later."""
    t_s = rows / found.rate_hz
    return Settling(0, 0, found.rate_hz,
                    tuple(t._replace(start_s=t.start_s - t_s, settled_s=t.settled_s - t_s)
                          for t in found.transients), max(found.needed_rows - rows, 0))


def _settling(saved) -> Settling | None:
    """Return the Settling of :meth:`WarmupGate.state` (None for none); InputError."""
    if saved is None:
        return None
    try:
        rows, cut, rate, needed, transients = saved
        found = Settling(int(rows), int(cut), float(rate),
                         tuple(Transient(int(t[0]), *map(float, t[1:])) for t in transients),
                         int(needed))
    except (TypeError, ValueError) as exc:
        raise InputError(f'the window the warm-up hold left out is invalid: {exc}') from None
    if not (found.rate_hz > 0 and math.isfinite(found.rate_hz) and found.needed_rows >= 0
            and all(0 <= t.axis < N_AXES and t.tau_s > 0 and t.wander > 0
                    for t in found.transients)):
        raise InputError('the window the warm-up hold left out is invalid')
    return found


def _real(rows: np.ndarray) -> int:
    """Return the rows of (n, 6) that are samples, not fills of a short gap."""
    fill = filled(rows)
    return rows.shape[0] - (0 if fill is None else int(fill.sum()))


def _quoted(j: int, value: float) -> str:
    """Return a bias change in the units people quote: deg/s or mg."""
    if j < 3:
        return f'{math.degrees(value):+.3g} deg/s'
    return f'{value / 9.80665e-3:+.3g} mg'


def _minutes(t_s: float) -> str:
    return f'{t_s / 60:.1f} min' if t_s < 5940 else f'{t_s / 3600:.2f} h'
