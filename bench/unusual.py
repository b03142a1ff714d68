"""
Valid-but-unusual inputs from a seed, each with its ground truth.

The readers' fuzz campaign (test/test_fuzz_readers.py) damages bytes; the inputs here
are intact and legal but unusual: several IMUs (``header.frame_id``) on one topic,
another message type or a second Imu topic in the bag, split bags listed out of order
or with a file repeated, missing or empty, stamp clocks that tick coarser than the
samples, zero, constant, stepping back or restarting, time in milliseconds, rates from
1 Hz to 4 kHz, values (one 1e154, a NaN, clipping, integer counts, an axis of zeros),
and CSV layouts (columns reordered or extra, CRLF, a BOM, quotes, spaces, gzip,
semicolons).  Bags are written with the reference libraries (MCAP by the mcap package,
sqlite3 and ROS 1 by rosbags, CSV by numpy; payloads by
:func:`imu_allan.io.bag_writer.serialize_imu`, checked against rosbags in
test/test_bag_reader.py); samples are seeded simulations of a known noise model.

Every :class:`Case` states its truth: the white noise N per axis it was simulated with
(None where the case makes it unknowable), the rate and span, the messages of the
chosen source (``n_truth``) and the messages the reference library reads
(:func:`reference_count`), which outcomes are acceptable, and the words a warning naming
its cause contains.  bench/campaign.py runs and judges them.
"""

from dataclasses import dataclass, field, replace
import gzip
from pathlib import Path
import shutil
import sqlite3
from typing import Callable

from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
import numpy as np
from rosbags.rosbag1 import Reader as Ros1Reader, Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin, Writer as Ros2Writer
from rosbags.typesys import get_typestore, Stores
import yaml

IMU = 'sensor_msgs/msg/Imu'
MAG = 'sensor_msgs/msg/MagneticField'
ROS2 = get_typestore(Stores.ROS2_JAZZY)
ROS1 = get_typestore(Stores.ROS1_NOETIC)
T0_NS = 1_700_000_000_000_000_000
#: White noise N of the simulations [rad/s*s^0.5, m/s^2*s^0.5] (the metamorphic bench's
#: model); a second IMU on the same topic has three times as much.
N_GYRO, N_ACCEL = 1.5e-4, 1e-3
#: Receive (log) time after the header stamp [ns].
LATENCY_NS = 1_000_000
CLASSES = ('sources', 'channels', 'split', 'clocks', 'rates', 'values', 'formats')


@dataclass
class Stream:
    """
    Messages of one channel: header stamps, log times, samples and frame_ids.

    Attributes are (n,) int64 header stamps [ns], (n,) int64 log times [ns], (n, 6)
    float64 samples [rad/s, m/s^2], and a frame_id per message (one str for all).
    """

    stamps_ns: np.ndarray
    log_ns: np.ndarray
    samples: np.ndarray
    frames: object = 'imu'
    topic: str = '/imu'
    msgtype: str = IMU


@dataclass
class Case:
    """
    One unusual input and its truth.

    Attributes
    ----------
    name, klass : str
        A unique name and one of :data:`CLASSES`.
    build : callable
        ``build(folder) -> Path``: write the input under a folder; return what
        ``imu-allan analyze`` is given.
    args : list of str
        More options for analyze (``--frame-id``, ``--topic``).
    n_axes : list
        N per axis in AXES order [SI], None where it is unknowable.
    rate_hz, duration_s : float
        The true rate and span of the chosen source.
    n_truth : int
        Messages (rows) of the chosen source in the record, each once.
    allow : tuple of str
        Acceptable outcomes among 'ok', 'warned', 'refused'.
    cause : tuple of str
        Lower-case words of which a warning or error naming the cause has one.
    topic, frame : str or None
        What the reference count selects (None: the Imu topic, every frame).
    loss : bool
        Part of the record is gone (a split file): analysed without a warning naming
        the cause is a silent loss.

    """

    name: str
    klass: str
    build: Callable[[Path], Path]
    n_axes: list
    rate_hz: float
    duration_s: float
    n_truth: int
    allow: tuple = ('ok', 'warned')
    cause: tuple = ()
    args: list = field(default_factory=list)
    topic: str = '/imu'
    frame: str | None = None
    loss: bool = False


# -- samples ---------------------------------------------------------------------------

def simulate(rate_hz: float, n: int, seed: int, scale: float = 1.0) -> np.ndarray:
    """Return (n, 6) samples [rad/s, m/s^2] with N scaled by ``scale``, seeded."""
    from imu_allan.core.noise.simulate import simulate_imu
    from imu_allan.core.noise.values import AxisNoise, NoiseSpec
    gyro = AxisNoise(N=N_GYRO * scale, B=3e-5, T_B=200.0, K=1e-6, bias=0.01)
    accel = AxisNoise(N=N_ACCEL * scale, B=1e-4, T_B=200.0, K=2e-5, bias=0.1)
    axes = {a: (gyro if a.startswith('gyro') else accel) for a in
            ('gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y')}
    axes['accel_z'] = AxisNoise(N=N_ACCEL * scale, B=1e-4, T_B=200.0, K=2e-5, bias=9.80665)
    _, y = simulate_imu(NoiseSpec(name='unusual', axes=axes), rate_hz, n / rate_hz, seed=seed)
    return y[:n]


def truth_n(scale: float = 1.0) -> list:
    """Return the simulated N per axis [SI] at a scale."""
    return [N_GYRO * scale] * 3 + [N_ACCEL * scale] * 3


def grid(rate_hz: float, n: int, rng: np.random.Generator, jitter: float = 0.01) -> np.ndarray:
    """Return (n,) int64 stamps [ns] at a rate with a little jitter (a share of a period)."""
    period_ns = 1e9 / rate_hz
    # Integer addition: T0_NS + a float would round the stamps to 256 ns.
    return T0_NS + np.round(np.arange(n) * period_ns
                            + rng.uniform(0, jitter * period_ns, n)).astype(np.int64)


# -- writers (the reference libraries) -------------------------------------------------

def _payloads(stream: Stream, ros1: bool = False) -> list:
    """Return one bytes payload per message (serialised per run of one frame_id)."""
    from imu_allan.io.bag_writer import serialize_imu
    n = stream.stamps_ns.size
    frames = [stream.frames] * n if isinstance(stream.frames, str) else list(stream.frames)
    out: list = [b''] * n
    for frame in sorted(set(frames)):
        idx = np.flatnonzero(np.array(frames, dtype=object) == frame)
        rows = serialize_imu(stream.stamps_ns[idx], stream.samples[idx], frame, ros1=ros1)
        for k, i in enumerate(idx.tolist()):
            out[i] = rows[k].tobytes()
    return out


def _rows(streams: list, ros1: bool = False) -> list:
    """Return (log_ns, stream index, payload) of every message, in log-time order."""
    rows = []
    for k, s in enumerate(streams):
        rows += [(int(t), k, p) for t, p in zip(s.log_ns.tolist(), _payloads(s, ros1))]
    return sorted(rows, key=lambda r: (r[0], r[1]))


def write_mcap(path: Path, streams: list) -> Path:
    """Write streams as one MCAP file with the mcap library (ros2 profile, zstd chunks)."""
    with open(path, 'wb') as stream:
        writer = McapWriter(stream, chunk_size=256_000)
        writer.start(profile='ros2')
        channels = []
        for s in streams:
            msgdef, _ = ROS2.generate_msgdef(s.msgtype, ros_version=2)
            schema = writer.register_schema(s.msgtype, 'ros2msg', msgdef.encode())
            channels.append(writer.register_channel(s.topic, 'cdr', schema))
        for log_ns, k, payload in _rows(streams):
            writer.add_message(channels[k], max(log_ns, 0), payload, max(log_ns, 0))
        writer.finish()
    return path


def write_sqlite(path: Path, streams: list) -> Path:
    """Write streams as a rosbag2 sqlite3 bag directory with rosbags' writer."""
    with Ros2Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conns = [writer.add_connection(s.topic, s.msgtype, typestore=ROS2) for s in streams]
        for log_ns, k, payload in _rows(streams):
            writer.write(conns[k], max(log_ns, 0), payload)
    return path


def write_db3(path: Path, streams: list) -> Path:
    """Write streams as one .db3 file (rosbags' bag directory, file moved out)."""
    tmp = path.with_name(path.stem + '_bag')
    write_sqlite(tmp, streams)
    shutil.move(str(next(tmp.glob('*.db3'))), path)
    shutil.rmtree(tmp)
    return path


def write_ros1(path: Path, streams: list) -> Path:
    """Write streams as a ROS 1 bag with rosbags' writer."""
    with Ros1Writer(path) as writer:
        conns = [writer.add_connection(s.topic, s.msgtype, typestore=ROS1) for s in streams]
        for log_ns, k, payload in _rows(streams, ros1=True):
            writer.write(conns[k], max(log_ns, 0), payload)
    return path


def write_csv(path: Path, t_s: np.ndarray, samples: np.ndarray, fmt: str = '%.17g') -> Path:
    """Write a CSV (``t,gyro_x..accel_z``) with numpy."""
    table = np.column_stack([t_s, samples])
    np.savetxt(path, table, fmt=fmt, delimiter=',', comments='',
               header='t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z')
    return path


def write(storage: str, folder: Path, streams: list, name: str = 'rec') -> Path:
    """Write streams in a storage ('mcap', 'sqlite3', 'db3', 'ros1' or 'csv'); return it."""
    if storage == 'mcap':
        return write_mcap(folder / f'{name}.mcap', streams)
    if storage == 'sqlite3':
        return write_sqlite(folder / name, streams)
    if storage == 'db3':
        return write_db3(folder / f'{name}.db3', streams)
    if storage == 'ros1':
        return write_ros1(folder / f'{name}.bag', streams)
    s = streams[0]
    return write_csv(folder / f'{name}.csv', (s.stamps_ns - T0_NS) / 1e9, s.samples)


def write_split(folder: Path, storage: str, parts: list, listed: list) -> Path:
    """Write a split bag: part k as ``rec_k.<ext>``; metadata.yaml lists ``listed``."""
    bag = folder / 'split'
    bag.mkdir()
    ext = 'mcap' if storage == 'mcap' else 'db3'
    for k, streams in enumerate(parts):
        if streams is not None:
            (write_mcap if storage == 'mcap' else write_db3)(bag / f'rec_{k}.{ext}', streams)
    (bag / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': {
        'version': 9, 'storage_identifier': storage,
        'relative_file_paths': [f'rec_{k}.{ext}' if isinstance(k, int) else k
                                for k in listed]}}))
    return bag


# -- the reference count ---------------------------------------------------------------

def _frame(raw: bytes, ros1: bool) -> str:
    """Return header.frame_id of a serialised Imu (CDR after 4+8 bytes, ROS 1 after 12)."""
    at = 12
    size = int.from_bytes(raw[at:at + 4], 'little')
    text = raw[at + 4:at + 4 + size]
    return (text if ros1 else text[:-1]).decode()


def _storage_files(path: Path) -> list:
    """Return the storage files of an input: the listed ones present, or the file."""
    if not path.is_dir():
        return [path]
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    return [path / f for f in info['relative_file_paths'] if (path / f).exists()]


def reference_count(path: Path, topic: str = '/imu', frame: str | None = None) -> int:
    """
    Count the Imu messages of a topic (and frame_id) as the reference library reads them.

    mcap's indexed reader, sqlite3 SQL, rosbags' ROS 1 reader or numpy's CSV reader;
    every listed storage file of a split bag that exists is counted (a repeated file
    twice).
    """
    if path.name.endswith(('.csv', '.csv.gz')):
        # The rows: lines with text after the header (the layouts vary too much for
        # one numpy call; the values themselves are the bench's own).
        with (gzip.open(path, 'rt') if path.suffix == '.gz' else open(path)) as f:
            return sum(1 for line in f if line.strip()) - 1
    n = 0
    for file in _storage_files(path):
        if file.suffix == '.mcap':
            with open(file, 'rb') as stream:
                for schema, channel, message in make_reader(stream).iter_messages():
                    if channel.topic == topic and schema.name == IMU:
                        n += frame is None or _frame(message.data, False) == frame
        elif file.suffix == '.db3':
            conn = sqlite3.connect(f'file:{file}?immutable=1', uri=True)
            rows = conn.execute('SELECT m.data FROM messages m JOIN topics t ON '
                                't.id = m.topic_id WHERE t.name = ? AND t.type = ?',
                                (topic, IMU)).fetchall()
            conn.close()
            n += sum(frame is None or _frame(r[0], False) == frame for r in rows)
        else:
            with Ros1Reader(file) as reader:
                conns = [c for c in reader.connections
                         if c.topic == topic and c.msgtype == IMU]
                # (rosbags reads every connection when given none)
                n += sum(frame is None or _frame(raw, True) == frame
                         for _, _, raw in reader.messages(connections=conns)) if conns else 0
    return n


# -- the cases -------------------------------------------------------------------------

def _n_for(length: float, rate_hz: float, seconds: float = 120.0) -> int:
    """Return the samples of a record at a rate: ``length * seconds`` long, 3600-80000."""
    return int(np.clip(rate_hz * seconds * length, 3600, 80_000))


def _plain(rate_hz: float, n: int, seed: int, scale: float = 1.0, **kw) -> Stream:
    """Return one clean Imu stream with log times LATENCY_NS after the stamps."""
    rng = np.random.default_rng([seed, 1])
    stamps = grid(rate_hz, n, rng)
    return Stream(stamps, stamps + LATENCY_NS, simulate(rate_hz, n, seed, scale), **kw)


def _case(name, klass, build, rate_hz, n, **kw) -> Case:
    kw.setdefault('n_axes', truth_n())
    return Case(name=name, klass=klass, build=build, rate_hz=rate_hz,
                duration_s=n / rate_hz, n_truth=n, **kw)


#: frame_ids of several IMUs on one topic: lengths that change the payload's padding.
FRAMES = ['imu_a', 'imu_b1', 'imu_c123']


def _sources(rng: np.random.Generator, seed: int, length: float) -> list:
    storage = str(rng.choice(['mcap', 'sqlite3', 'ros1']))
    rate, n = 100.0, _n_for(length, 100.0)
    k = int(rng.integers(2, 4))
    names = FRAMES[:k]
    pick = int(rng.integers(0, k))

    def several(folder: Path) -> Path:
        streams = []
        for j, name in enumerate(names):
            s = _plain(rate, n, seed + j, scale=1.0 + 2.0 * j, frames=name)
            shift = int(j * 1e9 / rate / k)
            streams.append(Stream(s.stamps_ns + shift, s.log_ns + shift, s.samples, name))
        merged = Stream(*(np.concatenate([getattr(s, a) for s in streams])
                          for a in ('stamps_ns', 'log_ns', 'samples')),
                        frames=sum(([s.frames] * n for s in streams), []))
        return write(storage, folder, [merged])

    half = int(rng.integers(n // 4, 3 * n // 4))

    def change(folder: Path) -> Path:
        s = _plain(rate, n, seed)
        return write(storage, folder, [Stream(s.stamps_ns, s.log_ns, s.samples,
                                              ['imu'] * half + ['imu_link'] * (n - half))])

    def empty(folder: Path) -> Path:
        return write(storage, folder, [_plain(rate, n, seed, frames='')])

    cause = ('frame_id', 'imus')
    return [
        _case(f'{k}_frames_{storage}', 'sources', several, rate, n, allow=('refused',),
              cause=cause, n_axes=[None] * 6),
        _case(f'{k}_frames_{storage}_pick_{names[pick]}', 'sources', several, rate, n,
              n_axes=truth_n(1.0 + 2.0 * pick), args=['--frame-id', names[pick]],
              frame=names[pick]),
        _case(f'frame_change_{storage}', 'sources', change, rate, n, cause=cause,
              allow=('warned', 'refused')),
        Case(f'frame_change_{storage}_pick_second', 'sources', change, truth_n(), rate,
             (n - half) / rate, n - half, args=['--frame-id', 'imu_link'], frame='imu_link'),
        _case(f'empty_frame_{storage}', 'sources', empty, rate, n),
    ]


def _channels(rng: np.random.Generator, seed: int, length: float) -> list:
    storage = str(rng.choice(['mcap', 'sqlite3', 'db3']))
    rate, n = 100.0, _n_for(length, 100.0)

    def other_type(folder: Path) -> Path:
        s = _plain(rate, n, seed)
        mag = Stream(s.stamps_ns, s.log_ns + 1, s.samples, msgtype=MAG)
        return write(storage, folder, [s, mag])

    def two_topics(folder: Path) -> Path:
        b = _plain(rate, n, seed + 1, scale=3.0, topic='/imu2')
        return write(storage, folder, [_plain(rate, n, seed), b])

    def other_topic(folder: Path) -> Path:
        s = _plain(rate, n, seed)
        mag = Stream(s.stamps_ns[::10], s.log_ns[::10] + 1, s.samples[::10], topic='/mag',
                     msgtype=MAG)
        return write(storage, folder, [s, mag])

    return [
        _case(f'other_type_on_imu_topic_{storage}', 'channels', other_type, rate, n,
              cause=('type', 'skipped')),
        _case(f'two_imu_topics_{storage}', 'channels', two_topics, rate, n,
              allow=('refused',), cause=('topic',), n_axes=[None] * 6),
        _case(f'two_imu_topics_{storage}_pick', 'channels', two_topics, rate, n,
              args=['--topic', '/imu2'], topic='/imu2', n_axes=truth_n(3.0)),
        _case(f'mag_topic_beside_{storage}', 'channels', other_topic, rate, n),
    ]


def _split(rng: np.random.Generator, seed: int, length: float) -> list:
    storage = str(rng.choice(['mcap', 'sqlite3']))
    ext = 'mcap' if storage == 'mcap' else 'db3'
    rate = float(rng.choice([100.0, 400.0]))
    n = _n_for(length, rate, 90.0)
    cuts = np.sort(rng.choice(np.arange(n // 10, n - n // 10), 2, replace=False))
    bounds = list(zip([0, *cuts.tolist()], [*cuts.tolist(), n]))
    order = [int(x) for x in rng.permutation(3)]
    if order == [0, 1, 2]:
        order = [2, 0, 1]
    dup = int(rng.integers(0, 3))

    def parts():
        s = _plain(rate, n, seed)
        return [[Stream(s.stamps_ns[a:b], s.log_ns[a:b], s.samples[a:b])] for a, b in bounds]

    def shuffled(folder: Path) -> Path:
        return write_split(folder, storage, parts(), order)

    def repeated(folder: Path) -> Path:
        bag = write_split(folder, storage, parts(), order + [f'copy.{ext}'])
        shutil.copyfile(bag / f'rec_{dup}.{ext}', bag / f'copy.{ext}')
        return bag

    def missing_listed(folder: Path) -> Path:
        return write_split(folder, storage, parts(), order + [f'gone.{ext}'])

    def missing_part(folder: Path) -> Path:
        bag = write_split(folder, storage, parts(), order)
        (bag / f'rec_1.{ext}').unlink()
        return bag

    def empty_part(folder: Path) -> Path:
        empty = Stream(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 6)))
        return write_split(folder, storage, parts() + [[empty]], order + [3])

    lost = bounds[1][1] - bounds[1][0]
    return [
        _case(f'split_{storage}_order_{"".join(map(str, order))}', 'split', shuffled, rate, n),
        _case(f'split_{storage}_file_{dup}_twice', 'split', repeated, rate, n,
              cause=('repeats', 'once')),
        _case(f'split_{storage}_listed_file_missing', 'split', missing_listed, rate, n,
              cause=('missing',), allow=('warned',), loss=True),
        Case(f'split_{storage}_middle_file_missing', 'split', missing_part, truth_n(), rate,
             n / rate, n - lost, cause=('missing', 'gap'), allow=('warned', 'refused'),
             loss=True),
        _case(f'split_{storage}_empty_file', 'split', empty_part, rate, n),
    ]


#: (rate [Hz], stamp tick [ns]) of coarse stamp clocks.
TICKS = [(4000.0, 1_000_000), (2000.0, 1_000_000), (800.0, 1_000_000), (300.0, 1_000_000),
         (1000.0, 1_000_000), (150.0, 10_000_000), (400.0, 10_000_000), (250.0, 4_000_000)]


def _clocks(rng: np.random.Generator, seed: int, length: float) -> list:
    storage = str(rng.choice(['mcap', 'sqlite3', 'ros1', 'csv']))
    bag = str(rng.choice(['mcap', 'sqlite3', 'ros1']))
    rate_t, tick = TICKS[int(rng.integers(0, len(TICKS)))]
    n_t = _n_for(length, rate_t, 30.0)
    rate, n = 100.0, _n_for(length, 100.0)
    at = int(rng.integers(n // 4, 3 * n // 4))
    back_ns = int(float(rng.choice([0.05, 0.5, 3.0])) * 1e9)

    def with_stamps(stamps_ns, store=storage, r=rate, m=n, log=False):
        def build(folder: Path) -> Path:
            s = _plain(r, m, seed)
            stamps = stamps_ns(s.stamps_ns)
            return write(store, folder, [Stream(stamps, stamps if log else s.log_ns,
                                                s.samples)])
        return build

    def coarse(stamps):
        return stamps // tick * tick

    def back(stamps):
        return np.where(np.arange(stamps.size) < at, stamps, stamps - back_ns)

    def restart(stamps):
        return np.where(np.arange(stamps.size) < at, stamps,
                        stamps - stamps[at] + 3_000_000_000)

    unit, per_s = [('ms', 1e3), ('us', 1e6), ('ns', 1e9)][int(rng.integers(0, 3))]
    rate_e = float(rng.choice([100.0, 1000.0, 4000.0]))
    n_e = _n_for(length, rate_e, 30.0)

    def csv_unit(folder: Path) -> Path:
        s = _plain(rate, n, seed)
        return write_csv(folder / f'rec_{unit}.csv', (s.stamps_ns - T0_NS) / 1e9 * per_s,
                         s.samples)

    def csv_epoch(folder: Path) -> Path:
        # Seconds since 1970 in %.17g: float64 keeps 0.24 us at 1.7e9 s.
        s = _plain(rate_e, n_e, seed)
        return write_csv(folder / 'rec_epoch.csv', s.stamps_ns / 1e9, s.samples)

    def rate_change(folder: Path) -> Path:
        a, b = _plain(100.0, n // 2, seed), _plain(200.0, n, seed + 1)
        shift = a.stamps_ns[-1] + 10_000_000 - b.stamps_ns[0]
        return write(storage, folder, [Stream(np.r_[a.stamps_ns, b.stamps_ns + shift],
                                              np.r_[a.log_ns, b.log_ns + shift],
                                              np.r_[a.samples, b.samples])])

    def csv_epoch_int(folder: Path) -> Path:
        # Integer ms, us or ns since 1970 in t (a logger's clock), read as seconds.
        s = _plain(rate, n, seed)
        ticks = s.stamps_ns // int(1e9 / per_s) if unit != 'ns' else s.stamps_ns
        return write_csv(folder / f'rec_epoch_{unit}.csv', ticks, s.samples)

    stamp = ('stamp', 'clock', 'time')
    return [
        _case(f'ticks_{rate_t:g}hz_{tick / 1e6:g}ms_{storage}', 'clocks',
              with_stamps(coarse, r=rate_t, m=n_t), rate_t, n_t, cause=stamp + ('tick',)),
        _case(f'zero_stamps_{bag}', 'clocks', with_stamps(np.zeros_like, bag), rate, n,
              cause=stamp),
        _case(f'constant_stamps_{bag}', 'clocks',
              with_stamps(lambda s: np.full_like(s, T0_NS), bag), rate, n, cause=stamp),
        _case(f'stamps_back_{back_ns / 1e9:g}s_once_{storage}', 'clocks', with_stamps(back),
              rate, n, cause=stamp + ('back', 'order', 'restart', 'jump')),
        _case(f'clock_restart_{storage}', 'clocks', with_stamps(restart), rate, n,
              cause=stamp + ('restart',)),
        _case(f'csv_time_in_{unit}', 'clocks', csv_unit, rate, n,
              cause=(unit, 'unit', 'time'), allow=('ok', 'warned', 'refused')),
        _case(f'csv_epoch_time_{rate_e:g}hz', 'clocks', csv_epoch, rate_e, n_e),
        _case(f'csv_integer_{unit}_since_1970', 'clocks', csv_epoch_int, rate, n,
              cause=(unit, 'unit', 'time'), allow=('ok', 'warned', 'refused')),
        _case(f'one_time_stamps_and_log_times_{bag}', 'clocks',
              with_stamps(lambda x: np.full_like(x, T0_NS), bag, log=True), rate, n,
              cause=stamp + ('repeated',), allow=('refused',), n_axes=[None] * 6),
        Case(f'rate_change_100_to_200hz_{storage}', 'clocks', rate_change, truth_n(), 200.0,
             n / 200.0 + (n // 2) / 100.0, n // 2 + n, cause=('rate',)),
    ]


RATES = [1.0, 5.0, 10.0, 50.0, 100.0, 200.0, 333.0, 400.0, 1000.0, 2000.0, 4000.0]


def _rates(rng: np.random.Generator, seed: int, length: float) -> list:
    out = []
    for rate in rng.choice(RATES, 3, replace=False).tolist():
        storage = str(rng.choice(['mcap', 'sqlite3', 'db3', 'ros1', 'csv']))
        n = _n_for(length, rate, 60.0)

        def build(folder: Path, rate=rate, n=n, storage=storage) -> Path:
            return write(storage, folder, [_plain(rate, n, seed)])

        out.append(_case(f'rate_{rate:g}hz_{storage}', 'rates', build, rate, n))
    return out


#: Least significant bits of an integer-count IMU (an MPU-6050 at +-250 deg/s, +-2 g).
GYRO_LSB, ACCEL_LSB = np.pi / 180.0 / 131.0, 9.80665 / 16384.0


def _values(rng: np.random.Generator, seed: int, length: float) -> list:
    storage = str(rng.choice(['mcap', 'sqlite3', 'ros1', 'csv']))
    rate, n = 100.0, _n_for(length, 100.0)
    row, axis = int(rng.integers(0, n)), int(rng.integers(0, 6))
    share = float(rng.choice([0.005, 0.05, 0.3]))
    huge = float(rng.choice([1e154, -1e154, 1e300]))

    def changed(edit):
        def build(folder: Path) -> Path:
            s = _plain(rate, n, seed)
            s.samples = edit(s.samples.copy())
            return write(storage, folder, [s])
        return build

    def one(value):
        def edit(y):
            y[row, axis] = value
            return y
        return edit

    def clip(y):
        # Pinned at the levels a share of the samples exceeds (both sides).
        lo, hi = np.quantile(y[:, axis], [share / 2, 1 - share / 2])
        y[:, axis] = np.clip(y[:, axis], lo, hi)
        return y

    def counts(y):
        return np.round(y / np.r_[[GYRO_LSB] * 3, [ACCEL_LSB] * 3])

    def zero_axis(y):
        y[:, axis] = 0.0
        return y

    cut = [None if j == axis else v for j, v in enumerate(truth_n())]
    return [
        _case(f'value_{huge:g}_{storage}', 'values', changed(one(huge)), rate, n,
              cause=('finite', 'large', 'spike', 'outlier', 'value'),
              allow=('ok', 'warned', 'refused')),
        # A CSV row with a NaN is refused by the CSV contract (docs/limits.md).
        _case(f'value_nan_{storage}', 'values', changed(one(np.nan)), rate, n,
              cause=('nan', 'finite'),
              allow=('ok', 'warned') + (('refused',) if storage == 'csv' else ())),
        _case(f'clipped_{share:g}_axis{axis}_{storage}', 'values', changed(clip), rate, n,
              cause=('clip', 'saturat', 'pinned')),
        _case(f'integer_counts_{storage}', 'values', changed(counts), rate, n,
              cause=('count', 'unit', 'integer', 'scale'), allow=('warned', 'refused')),
        _case(f'zero_axis{axis}_{storage}', 'values', changed(zero_axis), rate, n,
              n_axes=cut, cause=('zero', 'constant', 'frozen', 'stuck', 'signal'),
              allow=('warned', 'refused')),
    ]


#: CSV layouts the readers of other tools write or accept.
LAYOUTS = ['reversed_columns', 'crlf', 'bom', 'extra_columns', 'spaces', 'quoted_header',
           'gzip', 'trailing_blank_lines', 'semicolons']


def _formats(rng: np.random.Generator, seed: int, length: float) -> list:
    rate, n = 100.0, _n_for(length, 100.0)
    out = []
    for layout in rng.choice(LAYOUTS, 3, replace=False).tolist():
        def build(folder: Path, layout=layout) -> Path:
            s = _plain(rate, n, seed)
            names = ['t', 'gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z']
            table = np.column_stack([(s.stamps_ns - T0_NS) / 1e9, s.samples])
            sep, end, head = ',', '\n', ''
            if layout == 'reversed_columns':
                names, table = names[::-1], table[:, ::-1]
            elif layout == 'extra_columns':
                names = names + ['mag_x', 'status']
                table = np.column_stack([table, np.full((n, 1), 0.3), np.ones((n, 1))])
            sep = {'spaces': ', ', 'semicolons': ';'}.get(layout, sep)
            end = '\r\n' if layout == 'crlf' else end
            head = '\ufeff' if layout == 'bom' else head
            header = [f'"{x}"' if layout == 'quoted_header' else x for x in names]
            text = head + sep.join(header) + end + end.join(
                sep.join(f'{v:.17g}' for v in row) for row in table.tolist()) + end
            text += end * 3 if layout == 'trailing_blank_lines' else ''
            if layout == 'gzip':
                path = folder / 'rec.csv.gz'
                with gzip.open(path, 'wt', newline='') as f:
                    f.write(text)
                return path
            path = folder / 'rec.csv'
            path.write_bytes(text.encode())
            return path

        allow = ('refused',) if layout == 'semicolons' else ('ok', 'warned')
        out.append(_case(f'csv_{layout}', 'formats', build, rate, n, allow=allow,
                         cause=('column', 'header'),
                         n_axes=[None] * 6 if layout == 'semicolons' else truth_n()))
    return out


BUILDERS = {'sources': _sources, 'channels': _channels, 'split': _split, 'clocks': _clocks,
            'rates': _rates, 'values': _values, 'formats': _formats}


def cases(seed: int, rounds: int = 1, classes=CLASSES, length: float = 1.0) -> list:
    """
    Return the cases of ``rounds`` draws of every class, from a seed.

    Parameters
    ----------
    seed : int
        Seed of the draws (storages, rates, positions, sizes) and of the simulations.
    rounds : int
        Draws per class; each round draws new parameters.
    classes : sequence of str
        Which of :data:`CLASSES`.
    length : float
        Record lengths as a share of the bench's (2 min at 100 Hz; at least 3600 samples).

    Returns
    -------
    list of Case
        Unique names (a name drawn again has its round appended).

    """
    out: dict = {}
    for r in range(rounds):
        for k, klass in enumerate(classes):
            rng = np.random.default_rng([seed, r, CLASSES.index(klass)])
            for case in BUILDERS[klass](rng, seed * 1000 + r * 10 + k, length):
                name = case.name if case.name not in out else f'{case.name}_r{r}'
                out[name] = replace(case, name=name)
    return list(out.values())
