"""
The node's input side without ROS: buffer, decode, session, resume and snapshots.

:class:`LiveInput` holds everything between the subscription callback and the fit: the
buffer of serialized messages (the callback only appends), their vectorised decoding,
the pipeline :class:`~imu_allan.pipeline.session.Session`, the resume from a checkpoint
(and its rate check), the block-averaged raw copy for the effect search's evidence, and
consistent snapshots for fits on a worker thread.  It imports no rclpy, so it can be
driven and tested with plain bytes; :class:`~imu_allan.ros.node.ImuAllanNode` adds the
parameters, topics, services and timers.

The checkpoint can never stop the node: one that cannot be read, or whose values make no
sense, is set aside as ``checkpoint.npz.bad-<time>`` with a warning and the node starts
fresh; ``~/reset`` deletes it; a payload that is not an Imu message is counted and
dropped alone.
"""

from collections import deque
import copy
import math
import os
from pathlib import Path
import threading
import time
from types import SimpleNamespace

import numpy as np

from imu_allan import AXES
from imu_allan.core.allan.edf import confidence_bounds
from imu_allan.core.allan.raw import RawKeeper
from imu_allan.errors import InputError, UnitMistake
from imu_allan.io.imu_cdr import decode_imu_payloads, payload_frames
from imu_allan.io.temperature_cdr import decode_temperatures
from imu_allan.pipeline.analysis import CONFIDENCE
from imu_allan.pipeline.session import Session
from imu_allan.ros.params import session_config

CHECKPOINT = 'checkpoint.npz'
#: Samples a resumed session waits for before it compares their rate with the checkpoint.
_RESUME_CHECK_SAMPLES = 50
#: The timer hands the pipeline at least this many messages (or whatever is there after
#: _MAX_HOLD_S): its rate-change check needs 50 stamp steps in one block.
_MIN_BLOCK = 64
_MAX_HOLD_S = 2.0


class SessionView:
    """
    A frozen view of a session for :func:`~imu_allan.pipeline.analysis.analyze`.

    Taken under the input lock in milliseconds (the Allan curve without its confidence
    bounds, plus the counters), so that the fit, which takes seconds, runs without
    holding up the input.
    """

    def __init__(self, session: Session):
        self._curve = session.curve(confidence=CONFIDENCE, bounds=False)
        self._stretches = session.stretches()
        self.stats = copy.deepcopy(session.stats)
        # Rows held for the warm-up judgement after a restart are not in the curve yet.
        self.stats.n_used -= session.warmup.held_used
        self.config = session.config
        self.rate_hz = session.rate_hz
        self.duration_s = self.stats.n_used / self.rate_hz if self.rate_hz > 0 else 0.0
        self.warnings = session.warnings
        #: Why the data cannot be analysed yet (too little still data), or None.
        self.still_problem = session.still_problem
        # With a temperature, copies of both accumulators: the thermal analysis reads
        # them (pipeline/thermal_report.py) while the input goes on.
        thermal = session.feed.thermal
        self.feed = SimpleNamespace(
            thermal=copy.deepcopy(thermal),
            acc=None if thermal is None else copy.deepcopy(session.feed.acc))

    def stretches(self):
        """Return the stretches taken with the snapshot (core/allan/stretches.py)."""
        return self._stretches

    def curve(self, confidence: float = CONFIDENCE, bounds: bool = True):
        """Return the Allan curve taken with the snapshot (bounds computed on request)."""
        if self._curve is None or not bounds:
            return self._curve
        lo, hi = confidence_bounds(self._curve.avar, self._curve.edf, confidence)
        return self._curve._replace(adev_lo=lo, adev_hi=hi, confidence=float(confidence))


# Long by design: buffer, decode, resume and snapshots share one lock and one session;
# each step is a short method.
class LiveInput:
    """
    Buffer, decode and accumulate serialized sensor_msgs/Imu messages as they arrive.

    Parameters
    ----------
    values : dict
        The node's parameter values (:data:`imu_allan.ros.params.PARAMS`); read, and
        changes seen, at every use.
    output_dir : Path
        Where the checkpoint lives.
    logger : object
        Has ``info``, ``warning`` and ``error`` taking one string (an rclpy logger or a
        :class:`logging.Logger`).

    """

    def __init__(self, values: dict, output_dir: Path, logger):
        self.values, self.output_dir, self.log = values, Path(output_dir), logger
        # lock guards the session; process_lock keeps blocks in stamp order when process
        # runs from the timer and from a service or save on another thread.
        self.lock = threading.Lock()
        self.process_lock = threading.Lock()
        self.buffer: deque = deque()
        #: Serialized sensor_msgs/Temperature messages (the temperature_topic parameter).
        self.temperatures: deque = deque(maxlen=values['max_buffer_messages'])
        self.n_bad_temperatures = 0
        self.n_received = 0
        self.n_buffer_dropped = 0
        self.n_undecodable = 0
        #: header.frame_id of the IMU analysed: the frame_id parameter, else the first
        #: seen ('' before any); messages of other frame_ids are counted and dropped.
        self.frame_id = values['frame_id']
        #: Messages seen per frame_id (decodable ones).
        self.frame_counts: dict[str, int] = {}
        self.last_rx: float | None = None
        self._last_handover = time.monotonic()
        self._resume_hold: list | None = None   # blocks held until the resume is judged
        # Block-averaged copy of the samples for the effect search's periodogram, and
        # the session it belongs to (a new session starts a new copy).
        self._raw: tuple[Session, RawKeeper] | None = None
        # The session whose unit mistake was logged (logged once per session).
        self._unit_logged: Session | None = None
        self.session = self._new_session(resume=values['resume'])

    @property
    def checkpoint_path(self) -> Path:
        """Return the checkpoint file in output_dir."""
        return self.output_dir / CHECKPOINT

    # ------------------------------------------------------------- input
    def append(self, raw: bytes) -> None:
        """Take one serialized message (the only per-message work)."""
        self.n_received += 1
        self.last_rx = time.monotonic()
        self.buffer.append(raw)

    def append_temperature(self, raw: bytes) -> None:
        """Take one serialized sensor_msgs/Temperature message."""
        self.temperatures.append(raw)

    def due(self) -> bool:
        """Whether the buffer should be handed to the pipeline now."""
        return (len(self.buffer) >= _MIN_BLOCK
                or time.monotonic() - self._last_handover >= _MAX_HOLD_S)

    def process(self) -> None:
        """Decode the buffered messages and add them to the session, in stamp order."""
        self._last_handover = time.monotonic()
        with self.process_lock:
            self._process_locked()

    def _take_buffer(self) -> list:
        n = len(self.buffer)
        limit = self.values['max_buffer_messages']
        if n > limit:
            for _ in range(n - limit):
                self.buffer.popleft()
            self.n_buffer_dropped += n - limit
            self.log.warning(f'{n - limit} messages dropped by a full buffer '
                             f'(max_buffer_messages = {limit})')
            n = limit
        return [self.buffer.popleft() for _ in range(n)]

    def _process_locked(self) -> None:
        raws = self._take_buffer()
        temps = [self.temperatures.popleft() for _ in range(len(self.temperatures))]
        if temps:
            t_ns, temp_c, bad = decode_temperatures(temps)
            self.n_bad_temperatures += bad
            with self.lock:
                self.session.add_temperature(t_ns, temp_c)
        if not raws:
            return
        stamp_ns, samples = self._decode(raws)
        with self.lock:
            if self._resume_hold is not None:
                stamp_ns, samples = self._check_resume(stamp_ns, samples)
            if stamp_ns.size:
                try:
                    self.session.add(stamp_ns, samples)
                except UnitMistake as exc:
                    # Nothing of this session is used or published; said once per session.
                    if self._unit_logged is not self.session:
                        self._unit_logged = self.session
                        self.log.error(f'{exc}; nothing is published (fix the units of the '
                                       'driver, then ~/reset)')
                    return
                self.session.release()      # live: no row waits for a whole spike chunk
                self._keep_raw(samples)

    def _decode(self, raws: list) -> tuple[np.ndarray, np.ndarray]:
        """Decode a batch; a payload that is not an Imu message is dropped alone."""
        lengths = np.fromiter(map(len, raws), np.int64, len(raws))
        starts = np.zeros(lengths.size, np.int64)
        np.cumsum(lengths[:-1], out=starts[1:])
        u8 = np.frombuffer(b''.join(raws), np.uint8)
        stamp_ns, samples, ok = decode_imu_payloads(u8, starts, lengths, 'cdr')
        keep = self._one_source(u8, starts, lengths, ok)
        if ok.all():
            return (stamp_ns, samples) if keep is None else (stamp_ns[keep], samples[keep])
        bad = int(ok.size - np.count_nonzero(ok))
        before = self.n_undecodable
        self.n_undecodable += bad
        # Logged when the count passes 1, 2, 4, 8 ...: visible without flooding the log.
        if self.n_undecodable.bit_length() > before.bit_length():
            self.log.warning(f'{bad} of {ok.size} messages are not CDR sensor_msgs/msg/Imu: '
                             f'dropped ({self.n_undecodable} so far)')
        if keep is not None:
            ok &= keep
        return stamp_ns[ok], samples[ok]

    def _one_source(self, u8: np.ndarray, starts: np.ndarray, lengths: np.ndarray,
                    ok: np.ndarray) -> np.ndarray | None:
        """
        Return (n,) bool, the messages of the IMU analysed, or None for all of them.

        Two IMUs on one topic (told apart by header.frame_id) are never merged: the
        node keeps the frame_id parameter's, else the first frame_id it sees, counts
        the others and names each in one warning.
        """
        good = np.flatnonzero(ok)
        names, index = payload_frames(u8, starts[good], lengths[good], 'cdr')
        if not names:
            return None
        sizes = [good.size] if index is None else np.bincount(
            index, minlength=len(names)).tolist()
        if not self.frame_id:
            self.frame_id = names[0]
            self.log.info(f'analysing the IMU of frame_id {self.frame_id!r}')
        for name, size in zip(names, sizes):
            if name != self.frame_id and name not in self.frame_counts:
                chosen = ('the frame_id parameter' if self.values['frame_id'] else
                          'the first seen; set the frame_id parameter to choose')
                self.log.warning(f'messages of another IMU on the topic (frame_id {name!r}) '
                                 f'are dropped: this node analyses frame_id '
                                 f'{self.frame_id!r} ({chosen}); one node per IMU')
            self.frame_counts[name] = self.frame_counts.get(name, 0) + size
        if index is None:
            return None if names[0] == self.frame_id else np.zeros(ok.size, bool)
        keep = np.zeros(ok.size, bool)
        if self.frame_id in names:
            keep[good] = index == names.index(self.frame_id)
        return keep

    def _keep_raw(self, samples: np.ndarray) -> None:
        rows = self.values['diagnose_raw_samples']
        if rows < 2:
            return
        if self._raw is None or self._raw[0] is not self.session:
            # The rate is known after a few blocks; the copy keeps every sample anyway.
            self._raw = (self.session, RawKeeper(None, len(AXES), rows))
        self._raw[1].add(samples)     # leaves out the rows that are no readings (NaN ...)

    # ----------------------------------------------------- session, resume
    def _new_session(self, resume: bool) -> Session:
        config = session_config(self.values)
        path = self.checkpoint_path
        self._remove_stale_temporaries()
        if resume and path.exists():
            try:
                session = Session.load_state(path, config, on_warning=self.log.warning)
                _check_restored(session)
            # Whatever reading a damaged file raises (BadZipFile, EOFError, KeyError,
            # ZeroDivisionError, InputError ...): the node starts fresh, it never dies.
            except Exception as exc:  # noqa: B902
                self._set_aside(f'the checkpoint cannot be used ({_one_line(exc)})', 'bad')
            else:
                # Samples after the last checkpoint are lost: no Allan term may span them,
                # and the step to the first new stamp is not a step of the sensor clock.
                # The samples the checkpoint held for the motion check count from here.
                session.break_segment()
                session.last_stamp_ns = None
                self.log.info(
                    f'resumed from {path}: {session.stats.n_used} samples, '
                    f'{session.duration_s / 3600:.3f} h at {session.rate_hz:.2f} Hz, '
                    'split from the new samples'
                    + ('' if config.rate_hz > 0 else
                       '; the rate of the incoming data is checked against it'))
                if config.rate_hz <= 0:
                    self._resume_hold = []
                return self._with_temperature(session)
        elif resume:
            self.log.info(f'resume requested but {path} does not exist: starting fresh')
        return self._with_temperature(Session(config, on_warning=self.log.warning))

    def _with_temperature(self, session: Session) -> Session:
        """Have the rows wait for a temperature when the temperature_topic parameter is set."""
        if self.values['temperature_topic'] and not session.expect_temperature():
            self.log.warning('the checkpoint holds no temperature: the thermal analysis is '
                             'off until ~/reset')
        return session

    def _set_aside(self, why: str, tag: str) -> None:
        """Rename the checkpoint to checkpoint.npz.<tag>-<time>[.k]; never overwrite one."""
        path = self.checkpoint_path
        base = f'{path.name}.{tag}-{time.strftime("%Y%m%dT%H%M%S")}'
        kept = path.with_name(base)
        k = 1
        while kept.exists():
            kept = path.with_name(f'{base}.{k}')
            k += 1
        try:
            os.replace(path, kept)
        except OSError as exc:
            self.log.warning(f'not resuming: {why}; starting fresh (could not set the old '
                             f'checkpoint aside: {exc.strerror or exc}; it will be overwritten)')
            return
        self.log.warning(f'not resuming: {why}; starting fresh, old state kept as {kept}')

    def _remove_stale_temporaries(self) -> None:
        """Delete the temporary files of checkpoints a killed process left half written."""
        # write_atomic writes .checkpoint.npz.<random>.tmp and renames it: the checkpoint
        # itself is always whole, but a SIGKILL during a save leaves the temporary file.
        try:
            stale = list(self.output_dir.glob(f'.{CHECKPOINT}.*.tmp'))
        except OSError:
            return
        for tmp in stale:
            try:
                tmp.unlink()
            except OSError:
                continue
            self.log.info(f'removed {tmp}, left by a save that was interrupted')

    def _check_resume(self, stamp_ns: np.ndarray, samples: np.ndarray) -> tuple:
        """Hold the first samples after a resume; compare their rate with the checkpoint."""
        held = self._resume_hold if self._resume_hold is not None else []
        held.append((stamp_ns, samples))
        t = np.concatenate([b[0] for b in held])
        if t.size < _RESUME_CHECK_SAMPLES:
            return t[:0], samples[:0]
        y = np.concatenate([b[1] for b in held])
        self._resume_hold = None
        # Judged as the session judges stamps: a reader that has just started often
        # misses messages, and a gap must not pass for another rate.
        rate = self.session.stamp_rate_hz(t)
        saved = self.session.rate_hz
        if rate <= 0 or abs(rate / saved - 1) > self.values['rate_tolerance']:
            self._set_aside(f'the checkpoint was taken at {saved:.3f} Hz but the data now '
                            f'arrive at {rate:.3f} Hz', 'other-rate')
            self.session = Session(session_config(self.values), on_warning=self.log.warning)
        else:
            self.log.info(f'resume confirmed: incoming rate {rate:.3f} Hz matches the '
                          f'checkpoint ({saved:.3f} Hz); continuing')
        return t, y

    def reset(self) -> None:
        """Drop the buffer, delete the checkpoint and start a new session (no resume)."""
        with self.process_lock, self.lock:
            self._take_buffer()
            # A restart with resume must not bring the reset data back.
            try:
                self.checkpoint_path.unlink(missing_ok=True)
            except OSError as exc:
                self.log.error(f'could not delete {self.checkpoint_path} on reset: {exc}')
            self.session = self._new_session(resume=False)
            self._resume_hold = None
            self.frame_id = self.values['frame_id']     # '' locks on again

    # ------------------------------------------------- snapshots, checkpoints
    def view(self) -> SessionView:
        """Return a session view without the kept samples (for a picture of the curve)."""
        with self.lock:
            return SessionView(self.session)

    def snapshot(self) -> tuple:
        """Return (session view, copy of its kept samples or None), taken together."""
        with self.lock:
            # A fit is due: the rows held at the start are judged on what there is.
            self.session.judge_settling()
            raw = None
            if self._raw is not None and self._raw[0] is self.session:
                raw = copy.deepcopy(self._raw[1])
                raw.rate_hz = raw.rate_hz or (self.session.rate_hz or None)
            return SessionView(self.session), raw

    def checkpoint(self, flush: bool = False) -> bool:
        """
        Write the session's state to the checkpoint file (atomically).

        Parameters
        ----------
        flush : bool
            Process the buffer and flush the session first, and write only when a curve
            exists (the final save).

        Returns
        -------
        bool
            Whether a checkpoint was written.

        """
        if flush:
            self.process()
        with self.lock:
            if flush:
                self.session.flush()
                if self.session.curve() is None:
                    return False
            self.session.save_state(self.checkpoint_path)
        return True


def _one_line(exc: BaseException) -> str:
    """Return an exception as one short line: its type (unless InputError) and first line."""
    text = str(exc).strip().splitlines()
    if isinstance(exc, InputError) and text:
        return text[0][:200]
    return f'{type(exc).__name__}: {text[0][:200]}' if text else type(exc).__name__


_INT = (int, np.integer)


def _check_restored(session: Session) -> None:
    """
    Refuse a restored session whose values cannot come from a real recording.

    Raises
    ------
    InputError
        A rate that is not a finite positive number, negative or inconsistent
        counters, stamps that are not integers in order, or an Allan curve that cannot
        be computed from the restored sums.

    """
    rate = session.rate_hz
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and 0 < rate <= 1e9):
        raise InputError(f'rate {rate!r} Hz')
    stats = session.stats
    for name, value in vars(stats).items():
        if name.startswith('n_') and not (isinstance(value, _INT) and value >= 0):
            raise InputError(f'counter {name} = {value!r}')
    if stats.n_used > stats.n_received:
        raise InputError(f'{stats.n_used} samples used of {stats.n_received} received')
    first, last = session.first_stamp_ns, session.last_stamp_ns
    for name, value in (('first stamp', first), ('last stamp', last)):
        if value is not None and not isinstance(value, _INT):
            raise InputError(f'{name} {value!r}')
    if first is not None and last is not None and last < first:
        raise InputError(f'last stamp {last} before the first {first}')
    if not math.isfinite(session.duration_s):
        raise InputError(f'duration {session.duration_s!r} s')
    curve = session.curve(bounds=False)
    if curve is None:
        return
    if not np.isfinite(curve.avar).all():
        raise InputError('its Allan sums give non-finite variances')
    if not math.isclose(curve.rate_hz, rate, rel_tol=1e-9):
        raise InputError(f'its accumulator runs at {curve.rate_hz!r} Hz, the session at '
                         f'{rate!r} Hz')
