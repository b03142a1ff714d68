"""The temperature: its column, the thermal sums, the coefficient and the compensated curve."""

import json

import numpy as np
from numpy.testing import assert_allclose
import pytest

from conftest import T0_NS
from imu_allan import AXES
from imu_allan.core.allan.accumulator import AllanAccumulator
from imu_allan.core.allan.thermal import allan_covariance, compensated_avar
from imu_allan.core.search.thermal import thermal_regression
from imu_allan.io.csv_io import read_csv, write_csv
from imu_allan.io.inputs import analyze_input
from imu_allan.io.report import summary_text
from imu_allan.pipeline.hygiene import SessionConfig
from imu_allan.pipeline.session import Session
from imu_allan.pipeline.thermal import BLOCK_ROWS, ThermalFeed
from imu_allan.pipeline.thermal_report import thermal_axes, thermal_lines

RATE_HZ = 10.0
#: The temperature's cycle [s] (short: the records of these tests are short).
PERIOD_S = 600.0
#: Truth of the simulated records: gyro_x and accel_x follow the temperature.
COEF = np.array([1e-4, 0.0, 0.0, 2e-3, 0.0, 0.0])


def record(seed: int, hours: float, rate_hz: float = RATE_HZ) -> tuple:
    """Return (stamp_ns, samples (n, 6), temp_c): white + random walk, a thermal cycle."""
    rng = np.random.default_rng(seed)
    n = int(hours * 3600 * rate_hz)
    dt = 1.0 / rate_hz
    t_s = np.arange(n) * dt
    temp = 25.0 + 5.0 * np.sin(2 * np.pi * t_s / PERIOD_S)
    white = np.array([1e-3] * 3 + [5e-3] * 3)
    walk = np.array([1e-6] * 3 + [1e-5] * 3)
    y = (rng.normal(size=(n, 6)) * white / np.sqrt(dt)
         + np.cumsum(rng.normal(size=(n, 6)) * walk * np.sqrt(dt), axis=0))
    y[:, 5] += 9.81
    y += COEF * (temp - 25.0)[:, None]
    return T0_NS + np.round(t_s * 1e9).astype(np.int64), y, temp


def session_of(stamp_ns, y, temp, block: int = 7919) -> Session:
    s = Session(SessionConfig())
    for k in range(0, stamp_ns.size, block):
        s.add(stamp_ns[k:k + block], y[k:k + block],
              None if temp is None else temp[k:k + block])
    s.flush()
    return s


def test_compensated_curve_streams_as_the_batch_curve_of_the_compensated_samples():
    t, y, temp = record(1, 0.5)
    s = session_of(t, y, temp)
    curve = s.curve(bounds=False)
    tcurve = s.feed.thermal.acc.curve(bounds=False)
    avar_t, acov = allan_covariance(curve.avar, tcurve.avar)
    comp = compensated_avar(curve.avar, avar_t, acov, COEF)
    batch = AllanAccumulator(6, RATE_HZ)
    batch.add(y - COEF * temp[:, None])
    # Exact for the estimates (polarisation): equal to rounding.
    assert_allclose(comp, batch.curve(bounds=False).avar, rtol=1e-7)


def test_block_means_are_the_means_of_the_rows_whatever_the_blocks():
    feed = ThermalFeed(SessionConfig())
    feed.start(RATE_HZ)
    track_ns = np.arange(5) * 10**9 * 1000
    feed.add_temperature(track_ns, np.arange(5.0))
    rng = np.random.default_rng(2)
    n = 3 * BLOCK_ROWS + 77
    rows = rng.normal(size=(n, 6))
    stamps = np.arange(n, dtype=np.int64) * 10**8
    at = 0
    for size in rng.integers(1, 5000, size=200):
        if at >= n:
            break
        feed.add(rows[at:at + size], stamps[at:at + size], None)
        at += size
    means, rate = feed.block_means()
    f = n // means.shape[0]
    assert f == 4 and rate == RATE_HZ / 4
    assert_allclose(means[:, :6], rows[:means.shape[0] * f].reshape(-1, f, 6).mean(axis=1),
                    rtol=1e-12, atol=1e-12)
    temp = np.interp(stamps[:means.shape[0] * f], track_ns, np.arange(5.0))
    assert_allclose(means[:, 6], temp.reshape(-1, f).mean(axis=1), rtol=1e-12)


def test_regression_recovers_the_coefficient_within_its_interval():
    t, y, temp = record(3, 0.5)
    terms = [('white', 1e-6, ()), ('random_walk', 1e-12, ())]
    found = thermal_regression(y[:, 0], temp, RATE_HZ, terms)
    assert found.significant and found.ci95[0] <= COEF[0] <= found.ci95[1]
    assert found.ci95[1] - found.ci95[0] < 0.3 * COEF[0]
    none = thermal_regression(y[:, 1], temp, RATE_HZ, terms)
    assert none.ci95[0] <= 0.0 <= none.ci95[1] and not none.significant
    flat = thermal_regression(y[:, 1], np.full(temp.size, 25.0), RATE_HZ, terms)
    assert np.isnan(flat.value) and 'did not change' in flat.reason


def test_csv_temperature_column_gives_coefficient_compensated_fit_and_warning(tmp_path):
    t, y, temp = record(4, 0.4)
    path = tmp_path / 'warm.csv'
    write_csv(path, (t - T0_NS) * 1e-9, np.column_stack([y, temp]),
              list(AXES) + ['temperature'])
    assert read_csv(path, columns=list(AXES), optional=['temperature']).columns[-1] \
        == 'temperature'
    result, _ = analyze_input(path, None, SessionConfig(), quiet=True)
    for j, axis in enumerate(AXES):
        c = result.thermal[axis].coefficient
        assert c.ci95[0] <= COEF[j] <= c.ci95[1], axis
        assert c.significant == (COEF[j] != 0), axis
    hot = [w for w in result.warnings if w.startswith('thermal drift on')]
    assert {w.split()[3].rstrip(':') for w in hot} <= {'gyro_x', 'accel_x'}
    assert 'accel_x' in ' '.join(hot)
    entry = json.loads(json.dumps(result.to_json()))['axes']['accel_x']['thermal']
    assert entry['coefficient']['unit'] == 'm/s^2/degC'
    assert entry['compensated']['params']['N']['kind'] == 'estimate'
    assert 'thermal coefficient c of the bias' in summary_text(result)


def test_without_temperature_nothing_changes():
    t, y, temp = record(5, 0.15)
    plain = session_of(t, y, None)
    warm = session_of(t, y, temp)
    assert plain.feed.thermal is None and 'thermal__meta' not in plain.feed.state()
    curve = plain.curve()
    assert_allclose(warm.curve().avar, curve.avar, rtol=0, atol=0)
    assert thermal_axes(plain, curve, {}, (None, None), None, 1) == ({}, ())
    assert thermal_lines({}) == []


def test_late_temperature_is_left_out_with_a_warning():
    t, y, temp = record(6, 0.5)
    # No warm-up hold: the first rows reach the accumulator at once (held rows would
    # wait, and a temperature arriving while they wait is in time).
    s = Session(SessionConfig(warmup_window_s=0.0))
    s.add(t[:9000], y[:9000])
    s.release()
    assert s.curve() is not None    # rows accumulated: a temperature now comes too late
    s.add(t[9000:], y[9000:], temp[9000:])
    s.flush()
    assert s.feed.thermal is None
    assert any('temperature came after' in w for w in s.warnings)


def test_rows_wait_for_the_first_temperature():
    t, y, temp = record(7, 0.2)
    direct = session_of(t, y, temp)
    s = Session(SessionConfig())
    assert s.expect_temperature()
    s.add(t[:5000], y[:5000])
    s.add_temperature(t[::50], temp[::50])   # a slower topic, arriving later
    s.add(t[5000:], y[5000:])
    s.flush()
    a = direct.feed.thermal.acc.curve(bounds=False).avar
    b = s.feed.thermal.acc.curve(bounds=False).avar
    # The temperature read at 0.2 Hz and interpolated: the same curve at long taus.
    assert_allclose(b[-8:, 0], a[-8:, 0], rtol=1e-3)


def test_checkpoint_keeps_the_thermal_sums(tmp_path):
    t, y, temp = record(8, 0.2)
    whole = session_of(t, y, temp)
    half = t.size // 2
    first = Session(SessionConfig())
    first.add(t[:half], y[:half], temp[:half])
    first.save_state(tmp_path / 'state.npz')
    resumed = Session.load_state(tmp_path / 'state.npz')
    assert resumed.feed.thermal is not None
    resumed.add(t[half:], y[half:], temp[half:])
    resumed.flush()
    assert_allclose(resumed.feed.thermal.acc.curve(bounds=False).avar,
                    whole.feed.thermal.acc.curve(bounds=False).avar, rtol=1e-9)
    assert_allclose(resumed.feed.thermal.block_means()[0], whole.feed.thermal.block_means()[0],
                    rtol=1e-9)


@pytest.mark.parametrize('bad', [{'thermal__sums': np.zeros((BLOCK_ROWS + 1, 7))}])
def test_damaged_thermal_state_is_one_error(bad, tmp_path):
    t, y, temp = record(9, 0.05)
    s = session_of(t, y, temp)
    arrays = {**s.feed.state(), **bad}
    from imu_allan.errors import InputError
    with pytest.raises(InputError):
        ThermalFeed.restore(SessionConfig(), arrays)


def write_bag_with_temperature(path, stamp_ns, y, temp, topics=('/imu/temperature',),
                               every: int = 10) -> None:
    """Write a rosbag2 (sqlite3) with /imu/data and Temperature topics (every 10th stamp)."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import get_typestore, Stores

    from imu_allan.io.bag_writer import serialize_imu

    store = get_typestore(Stores.ROS2_JAZZY)
    Temperature = store.types['sensor_msgs/msg/Temperature']
    Header = store.types['std_msgs/msg/Header']
    Time = store.types['builtin_interfaces/msg/Time']
    rows = serialize_imu(stamp_ns, y)
    with Writer(path, version=9) as bag:
        imu = bag.add_connection('/imu/data', 'sensor_msgs/msg/Imu', typestore=store)
        temps = [bag.add_connection(t, 'sensor_msgs/msg/Temperature', typestore=store)
                 for t in topics]
        for k in range(stamp_ns.size):
            t = int(stamp_ns[k])
            bag.write(imu, t, rows[k].tobytes())
            if k % every == 0:
                msg = Temperature(Header(Time(t // 10**9, t % 10**9), 'imu_link'),
                                  float(temp[k]), 0.0)
                for conn in temps:
                    bag.write(conn, t, store.serialize_cdr(msg, conn.msgtype))


def test_bag_temperature_topic_is_read_and_interpolated(tmp_path):
    from imu_allan.errors import InputError
    from imu_allan.io.inputs import open_input, stream_input

    t, y, temp = record(10, 0.1)
    write_bag_with_temperature(tmp_path / 'bag', t, y, temp)
    with open_input(tmp_path / 'bag') as source:
        assert source.label.endswith('(temperature /imu/temperature)')
        from_bag = stream_input(source, SessionConfig())
    direct = session_of(t, y, temp)
    # Read at a tenth of the rate and interpolated: the same thermal curve at long taus.
    a = direct.feed.thermal.acc.curve(bounds=False).avar
    b = from_bag.feed.thermal.acc.curve(bounds=False).avar
    assert_allclose(b[-10:], a[-10:], rtol=1e-3)
    write_bag_with_temperature(tmp_path / 'two', t[:2000], y[:2000], temp[:2000],
                               topics=('/a/temperature', '/b/temperature'))
    with pytest.raises(InputError, match='2 Temperature topics'):
        open_input(tmp_path / 'two')
    with open_input(tmp_path / 'two', temperature_topic='/b/temperature') as source:
        assert source.temperature is not None
    with pytest.raises(InputError, match='not in the bag'):
        open_input(tmp_path / 'two', temperature_topic='/c')


def temperature_cdr(stamp_ns: int, temp_c: float, frame_id: str = 'imu_link') -> bytes:
    """Serialize one sensor_msgs/msg/Temperature (CDR, little-endian) by hand."""
    import struct
    name = frame_id.encode() + b'\0'
    body = struct.pack('<iII', stamp_ns // 10**9, stamp_ns % 10**9, len(name)) + name
    body += b'\0' * (-len(body) % 8)
    return b'\0\x01\0\0' + body + struct.pack('<dd', temp_c, 0.0)


def test_live_input_reads_the_temperature_topic_as_analyze_reads_the_column(tmp_path):
    import logging

    from imu_allan.io.bag_writer import serialize_imu
    from imu_allan.io.temperature_cdr import decode_temperatures
    from imu_allan.ros.live import LiveInput
    from imu_allan.ros.params import PARAMS

    t, y, temp = record(11, 0.2)
    got = decode_temperatures([temperature_cdr(int(t[3]), 21.5), b'\0\x01\0\0junk'])
    assert got[0].tolist() == [int(t[3])] and got[1].tolist() == [21.5] and got[2] == 1
    values = dict({p.name: p.default for p in PARAMS}, temperature_topic='/imu/temperature')
    live = LiveInput(values, tmp_path, logging.getLogger('thermal'))
    rows = serialize_imu(t, y)
    for k0 in range(0, t.size, 1000):
        for k in range(k0, min(k0 + 1000, t.size)):
            live.append(rows[k].tobytes())
            if k % 10 == 0:
                live.append_temperature(temperature_cdr(int(t[k]), float(temp[k])))
        live.process()
    live.session.flush()
    offline = session_of(t[:], y, np.where(np.arange(t.size) % 10 == 0, temp, np.nan))
    terms = [('white', 1e-6, ()), ('random_walk', 1e-12, ())]
    found = []
    for s in (live.session, offline):
        means, rate = s.feed.thermal.block_means()
        found.append(thermal_regression(means[:, 0], means[:, -1], rate, terms))
    assert_allclose(found[0].value, found[1].value, rtol=1e-9)
    assert_allclose(found[0].ci95, found[1].ci95, rtol=1e-9)


def test_node_snapshot_carries_the_thermal_sums():
    from imu_allan.ros.live import SessionView

    t, y, temp = record(12, 0.1)
    s = session_of(t, y, temp)
    view = SessionView(s)
    assert view.feed.thermal is not s.feed.thermal
    assert_allclose(view.feed.thermal.block_means()[0], s.feed.thermal.block_means()[0])
    assert view.feed.acc.n_samples == s.feed.acc.n_samples
    assert SessionView(session_of(t, y, None)).feed.thermal is None


def test_node_analysis_of_its_snapshot_gives_the_coefficient_analyze_gives():
    from imu_allan.pipeline.analysis import analyze
    from imu_allan.ros.live import SessionView

    t, y, temp = record(13, 0.25)
    s = session_of(t, y, temp)
    node = analyze(SessionView(s))
    offline = analyze(s)
    for axis in ('gyro_x', 'accel_x', 'gyro_y'):
        a, b = node.thermal[axis].coefficient, offline.thermal[axis].coefficient
        assert a.significant == b.significant == (axis != 'gyro_y')
        assert_allclose(a.ci95, b.ci95, rtol=1e-9)
