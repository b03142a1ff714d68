"""
Input plumbing shared by the offline commands: open any input, stream it through a Session.

:func:`open_input` opens a rosbag2 directory, .mcap, .db3, ROS 1 .bag or CSV file as an
:class:`InputSource` of ``(stamp_ns, samples)`` blocks; :func:`stream_input` feeds one
through the :class:`~imu_allan.pipeline.session.Session` the node uses, with reading
ahead on a thread (:class:`~imu_allan.io.progress.Progress` shows how far it got);
:func:`raw_tap` keeps the bounded raw copy the effect search's evidence needs.
"""

from dataclasses import replace
import os
from pathlib import Path
import queue
import stat
import sys
import threading
import time
from typing import Callable, Iterator

import numpy as np

from imu_allan import AXES
from imu_allan.core.noise.unit_check import DeclaredUnits, stamps_ns
from imu_allan.errors import InputError, UnitMistake
from imu_allan.io.progress import Progress
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session
from imu_allan.pipeline.workers import start_workers

CSV_SUFFIXES = ('.csv', '.csv.gz', '.txt', '.txt.gz')
#: Samples handed to the Session at a time for CSV input.
CSV_BLOCK = 65536
#: The CSV column of the temperature [degC] (docs/offline.md, pipeline/thermal.py).
TEMPERATURE_COLUMN = 'temperature'


# --------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------

class InputSource:
    """
    One opened input (bag topic or CSV file) as blocks of stamped six-axis samples.

    Attributes
    ----------
    path : pathlib.Path
        The input.
    label : str
        File name plus topic, for reports.
    kind : str
        'csv', 'mcap', 'sqlite3' or 'ros1'.
    topic : str or None
        The Imu topic read (None for CSV).
    n_messages : int or None
        Samples expected, when known before reading.
    warnings : list of str
        Reader problems (truncation, skipped messages ...); complete after ``blocks()``.

    """

    def __init__(self, path: Path, label: str, kind: str, topic: str | None,
                 n_messages: int | None, blocks: Callable[[], Iterator],
                 warnings: list, close: Callable[[], None] = lambda: None,
                 frame_id: Callable[[], str] = lambda: '',
                 counts: Callable[[], tuple] | None = None):
        self.path, self.label, self.kind, self.topic = path, label, kind, topic
        self.n_messages, self.warnings = n_messages, warnings
        self._blocks, self._close, self._frame_id = blocks, close, frame_id
        self._counts = counts if counts is not None else lambda: (n_messages, 0)
        #: (stamp_ns (n,), temp_c (n,)) of a bag's temperature topic, read whole; None
        #: without one (a CSV's column comes with the blocks).
        self.temperature: tuple | None = None

    @property
    def read_counts(self) -> dict:
        """
        Return what the reader delivered and lost, once ``blocks()`` has been consumed.

        Returns
        -------
        dict
            ``n_read``: messages (rows) delivered; ``n_lost``: messages the input counts
            but could not deliver (damaged, undecodable), None when it states no count;
            ``n_no_orientation``: messages delivered that carry no orientation
            (``orientation_covariance[0] = -1``), None for CSV.

        """
        n_read, n_lost, *rest = self._counts()
        return {'n_read': n_read, 'n_lost': n_lost,
                'n_no_orientation': rest[0] if rest else None}

    @property
    def frame_id(self) -> str:
        """Return header.frame_id of the first message read ('' for CSV or before)."""
        return self._frame_id()

    def blocks(self) -> Iterator[tuple]:
        """
        Yield the samples in order.

        Yields
        ------
        tuple of numpy.ndarray
            stamp_ns (n,) int64 [ns] and samples (n, 6) float64 in AXES order
            [rad/s, m/s^2].

        """
        return self._blocks()

    def close(self) -> None:
        """Release files."""
        self._close()

    def __enter__(self) -> 'InputSource':
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def is_csv(path: Path) -> bool:
    """Return True when the name says CSV (.csv, .txt, optionally .gz)."""
    return path.name.lower().endswith(CSV_SUFFIXES)


def check_path(path: Path) -> None:
    """Raise InputError for a missing path or one that is neither file nor directory."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise InputError(f'{path}: no such file or directory') from None
    except OSError as err:
        raise InputError(f'{path}: cannot access ({err.strerror})') from None
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise InputError(f'{path}: not a regular file or directory')
    if not os.access(path, os.R_OK | (os.X_OK if stat.S_ISDIR(mode) else 0)):
        raise InputError(f'{path}: permission denied')


def _whole_blocks(held: list, final: bool) -> Iterator:
    """Yield CSV_BLOCK rows of held (stamp_ns, samples, temp_c) parts; a rest waits."""
    n = sum(p[0].size for p in held)
    if not n or (n < CSV_BLOCK and not final):
        return
    parts = [np.concatenate([p[i] for p in held]) if p0 is not None else None
             for i, p0 in enumerate(held[0])]
    held.clear()
    whole = n if final else n - n % CSV_BLOCK
    for k in range(0, whole, CSV_BLOCK):
        end = min(k + CSV_BLOCK, whole)
        yield tuple(None if p is None else p[k:end] for p in parts)
    if whole < n:
        held.append(tuple(None if p is None else p[whole:] for p in parts))


def open_input(path, topic: str | None = None, units: DeclaredUnits | None = None,
               frame_id: str | None = None, temperature_topic: str | None = None,
               rate_hz: float = 0.0) -> InputSource:
    """
    Open any supported input for streaming.

    Parameters
    ----------
    path : str or Path
        rosbag2 directory (sqlite3 or MCAP, any metadata version, with or without
        message definitions), ``.mcap``, ``.db3``, ROS 1 ``.bag``, or CSV
        (``t,gyro_x,...,accel_z``, optional ``.gz``).
    topic : str, optional
        Imu topic of a bag; by default its only Imu topic.  Ignored for CSV.
    units : DeclaredUnits, optional
        The units the input is written in (``--units``): the blocks are converted to
        ns, rad/s and m/s^2.
    frame_id : str, optional
        The IMU to read when the topic carries several (header.frame_id); ignored for
        CSV.
    temperature_topic : str, optional
        The sensor_msgs/Temperature topic of a bag; by default its only one, if any
        (:mod:`imu_allan.io.temperature_bag`).  A CSV gives a ``temperature`` column.
    rate_hz : float
        A set sample rate [Hz] (``--rate``; 0: none): a CSV whose t column does not
        step (stamps rounded coarser than the samples) is then read, not refused.

    Returns
    -------
    InputSource
        Close it (or use it as a context manager) when done.

    Raises
    ------
    InputError
        Missing or unreadable path, not a bag or CSV, no (or several) Imu topics, wrong
        message type, bad CSV columns or values: a one-line message.

    """
    path = Path(path)
    check_path(path)
    if is_csv(path):
        from imu_allan.io.csv_io import open_csv
        if path.is_dir():
            raise InputError(f'{path}: is a directory, not a CSV file')
        # Read in blocks: memory bounded whatever the record's length.  A set rate
        # (--rate) reads a CSV whose t does not step (stamps rounded coarser than the
        # samples): the tick clock rebuilds them.
        stream = open_csv(path, columns=list(AXES), optional=[TEMPERATURE_COLUMN],
                          rate_hz=rate_hz if rate_hz > 0 else None)
        with_temp = len(stream.columns) > len(AXES)
        n_read = [0]

        def csv_blocks():
            # Blocks of CSV_BLOCK rows, as the whole file was cut before: the same
            # blocks reach the session, so the same numbers come out.
            held: list = []
            for data in stream.blocks:
                if data.t_s is None:
                    raise InputError(f'{path}: a t column (seconds) is needed for analyze')
                n_read[0] += data.t_s.size
                # The declared time unit applies before nanoseconds (ms since the epoch
                # in ns would overflow int64; undeclared, that is one line).
                scale = units.time_scale(1.0) if units is not None else 1.0
                held.append((stamps_ns(data.t_s, scale),
                             _to_si(data.samples[:, :len(AXES)], units),
                             data.samples[:, len(AXES)] if with_temp else None))
                yield from _whole_blocks(held, final=False)
            yield from _whole_blocks(held, final=True)
        return InputSource(path, path.name, 'csv', None, None, csv_blocks, [],
                           counts=lambda: (n_read[0], 0))
    from imu_allan.io.bag_reader import open_imu
    from imu_allan.io.temperature_bag import read_temperature
    temperature = read_temperature(path, temperature_topic)
    source = open_imu(path, topic, frame_id)
    time_scale = units.time_scale(1e-9) if units is not None else 1.0

    def bag_blocks():
        log_times = None
        for block in source.blocks():
            if log_times is None:
                log_times = _stamps_are_constant(block.stamp_ns, block.recv_ns)
                if log_times:
                    source.warnings.append(
                        f'header.stamp is {block.stamp_ns[0]} ns in every one of the first '
                        f'{block.stamp_ns.size:,} messages on {source.topic} (the publisher '
                        "does not fill it): the bag's log times are used instead (they "
                        'carry the delivery jitter)')
            stamp_ns = block.recv_ns if log_times else block.stamp_ns
            if time_scale != 1.0 and not log_times:   # log times are ns
                stamp_ns = np.round(stamp_ns * time_scale).astype(np.int64)
            yield stamp_ns, _to_si(block.samples, units), None
    label = f'{path.name} {source.topic}' + (f' {frame_id}' if frame_id is not None else '')
    opened = InputSource(path, label, source.storage, source.topic,
                         source.n_messages, bag_blocks, source.warnings, source.close,
                         lambda: source.frame_id,
                         lambda: (source.n_read, source.n_lost, source.n_no_orientation))
    if temperature is not None:
        opened.label += f' (temperature {temperature.topic})'
        stamps = temperature.stamp_ns
        if time_scale != 1.0:
            stamps = np.round(stamps * time_scale).astype(np.int64)
        opened.temperature = (stamps, temperature.temp_c)
    return opened


def _stamps_are_constant(stamp_ns: np.ndarray, recv_ns: np.ndarray) -> bool:
    """Whether header stamps are all one value (0, or constant) while log times move."""
    return (stamp_ns.size >= 3 and bool((stamp_ns == stamp_ns[0]).all())
            and bool((np.diff(recv_ns) > 0).any()))


def _to_si(samples: np.ndarray, units: DeclaredUnits | None) -> np.ndarray:
    """Return (n, 6) samples in rad/s and m/s^2 (the same array when already SI)."""
    if units is None:
        return samples
    scale = units.sample_scale()
    return samples * scale if (scale != 1.0).any() else samples


def stream_input(source: InputSource, config: SessionConfig,
                 on_warning: Callable[[str], None] | None = None,
                 progress: Progress | None = None,
                 tap: Callable[[Session, np.ndarray], None] | None = None,
                 prefetch: bool = True) -> Session:
    """
    Feed every block of an input through a new pipeline Session (the node's object).

    Parameters
    ----------
    source : InputSource
        From :func:`open_input`.
    config : SessionConfig
        Input checks and accumulator settings.
    on_warning : callable, optional
        Gets each session warning as it happens.
    progress : Progress, optional
        Updated with the number of samples read.
    tap : callable, optional
        Called as tap(session, samples) after each block, samples (n, 6) as read.
    prefetch : bool
        Read the next block on a thread while this one is processed (two cores for one
        input); False where every core already runs an input (fleet workers).

    Returns
    -------
    Session
        Flushed; its warnings are the session's own (reader warnings stay in
        ``source.warnings``).

    """
    session = Session(config, on_warning=on_warning)
    if source.temperature is not None:
        session.expect_temperature()
        session.add_temperature(*source.temperature)
    done = 0
    blocks = _prefetch(source.blocks()) if prefetch else source.blocks()
    for stamp_ns, samples, temp_c in blocks:
        session.add(stamp_ns, samples, temp_c)
        if tap is not None:
            tap(session, samples)
        done += stamp_ns.size
        if progress is not None:
            progress.update(done)
    session.flush()
    return session


def _prefetch(blocks: Iterator, depth: int = 2) -> Iterator:
    """
    Yield the items of an iterator that a background thread reads ahead.

    Decoding the next block (numpy, mostly outside the GIL) then overlaps with the
    Session's work on the current one: on two cores reading costs little extra wall
    time.  Exceptions of the reader are raised here, in order.
    """
    done = object()
    slots: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def offer(item) -> bool:
        """Queue an item unless the consumer has stopped (it takes nothing more then)."""
        while not stop.is_set():
            try:
                slots.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce():
        try:
            for item in blocks:
                if not offer((item, None)):
                    return
            offer((done, None))
        except BaseException as exc:  # noqa: B902 - handed over to the consumer
            offer((done, exc))

    worker = threading.Thread(target=produce, daemon=True, name='imu-allan-reader')
    worker.start()
    try:
        while True:
            item, exc = slots.get()
            if exc is not None:
                raise exc
            if item is done:
                return
            yield item
    finally:
        stop.set()
        worker.join()


def raw_tap() -> tuple:
    """
    Make a ``stream_input`` tap that keeps a bounded raw copy for the effect search.

    Returns
    -------
    tuple
        (tap, keeper): the RawKeeper's rate is taken from the session when the analysis
        needs it.

    """
    from imu_allan.core.allan.raw import RawKeeper
    # Every sample from the first on; the rate comes from the session at analysis time.
    keeper = RawKeeper(None, len(AXES))

    def tap(session, samples) -> None:
        keeper.add(samples)     # leaves out the rows that are no readings (NaN ...)
    return tap, keeper


def analyze_input(path: str | Path, topic: str | None, config: SessionConfig,
                  quiet: bool = False, progress: bool | None = None, workers: int = 1,
                  prefetch: bool = True, units: DeclaredUnits | None = None,
                  plan: bool = False, plan_targets: dict | None = None,
                  frame_id: str | None = None, temperature_topic: str | None = None):
    """
    Stream one input through a Session and fit it.

    Parameters
    ----------
    path : str or Path
        The input.
    topic : str or None
        Imu topic of a bag.
    config : SessionConfig
        Session settings.
    quiet : bool
        Do not print warnings on stderr (they are in the result anyway).
    progress : bool, optional
        Show a progress line on stderr for long inputs (default: not ``quiet``).
    plan : bool
        Also plan the record length (:func:`imu_allan.pipeline.analysis.analyze`).
    plan_targets : dict of str to float, optional
        The plan's target relative half-widths by parameter.
    workers : int
        Processes for the axes' effect searches (see
        :func:`imu_allan.pipeline.analysis.analyze`).
    prefetch : bool
        See :func:`stream_input`.
    units : DeclaredUnits, optional
        The units of the input (see :func:`open_input`).
    frame_id : str, optional
        The IMU of a topic that carries several (see :func:`open_input`).
    temperature_topic : str, optional
        The Temperature topic of a bag (see :func:`open_input`).

    Returns
    -------
    tuple
        (AnalysisResult with the recording's first stamp and frame_id, seconds spent).

    """
    from imu_allan.pipeline.analysis import analyze  # the search itself runs in workers

    start = time.monotonic()
    path = Path(path)
    if workers > 1:
        start_workers()     # unless the caller did already: its start-up overlaps the reading

    def warn(text):
        if not quiet:
            print(f'imu-allan: warning: {path.name}: {text}', file=sys.stderr)

    show = (not quiet) if progress is None else progress
    tap, keeper = raw_tap()
    with open_input(path, topic, units, frame_id, temperature_topic,
                    config.rate_hz) as source:
        bar = Progress(path.name, source.n_messages) if show else None
        try:
            try:
                session = stream_input(source, config, on_warning=warn, progress=bar,
                                       tap=tap, prefetch=prefetch)
            except UnitMistake as exc:  # named before any other judgement: no files
                raise UnitMistake(f'{path}: {exc}') from None
            reader_warnings = list(source.warnings)
            for text in reader_warnings:
                warn(text)
            counts = source.read_counts
            if session.stats.n_received == 0:
                raise InputError(f'{path}: no Imu samples in the input'
                                 + (f' ({reader_warnings[0]})' if reader_warnings else ''))
            try:    # too little still data, or mostly spikes: no consumer files
                session.check_usable()
            except InputError as exc:
                raise type(exc)(f'{path}: {exc}') from None
            if bar is not None:
                bar.set_stage('fitting the noise model of')
            result = analyze(session, source=source.label, raw=keeper,
                             topic=source.topic or '', workers=workers, plan=plan,
                             plan_targets=plan_targets)
        finally:
            if bar is not None:
                bar.close()
    if result is None:
        raise InputError(f'{path}: too few usable samples ({session.stats.n_used} of '
                         f'{session.stats.n_received}) for any Allan deviation'
                         + (f' ({session.warnings[0]})' if session.warnings else ''))
    extra = list(reader_warnings)
    for text in result.warnings:    # the analysis' own (unit mistakes), on stderr too
        if text not in session.warnings:
            warn(text)
    stats = session.stats
    if stats.n_motion_events:
        share = stats.n_motion_dropped / max(stats.n_received, 1)
        kept = ('samples kept (on_motion=warn)' if config.on_motion == 'warn' else
                f'{100 * share:.2g}% of the samples dropped')
        if share >= 0.2 or config.on_motion == 'warn':
            extra.append(f'NOT STATIONARY: motion in {stats.n_motion_events} episode(s), '
                         f'{kept}; the numbers rest on {stats.n_used} samples '
                         f'({session.duration_s:.0f} s) and describe a still IMU only if '
                         'those were still')
        else:
            extra.append(f'brief motion or outliers in {stats.n_motion_events} episode(s): '
                         f'{kept}, {stats.n_used} samples used')
        warn(extra[-1])
    result = replace(result, warnings=tuple(extra) + result.warnings,
                     hygiene={**result.hygiene, **counts},
                     start_ns=session.first_stamp_ns, frame_id=source.frame_id)
    return result, time.monotonic() - start
