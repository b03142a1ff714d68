"""Opening inputs: header stamps that carry no time fall back to the bag's log times."""

import sqlite3
import struct

import numpy as np
from numpy.testing import assert_allclose
import pytest

from conftest import still_imu
from imu_allan.io.bag_writer import write_imu_bag
from imu_allan.io.inputs import open_input, stream_input
from imu_allan.pipeline.hygiene import SessionConfig


def _bag_with_stamps(path, stamp_of) -> tuple:
    """Write a 100 Hz db3 bag, then set each header.stamp to stamp_of(i) [ns]."""
    t, y = still_imu(6000, seed=4)
    write_imu_bag(path, t, y)
    with sqlite3.connect(path) as db:
        rows = db.execute('SELECT id, data FROM messages ORDER BY id').fetchall()
        patched = []
        for i, (rowid, data) in enumerate(rows):
            sec, nsec = divmod(int(stamp_of(i)), 10**9)
            # CDR: 4-byte encapsulation header, then stamp.sec int32, stamp.nanosec uint32.
            patched.append((data[:4] + struct.pack('<iI', sec, nsec) + data[12:], rowid))
        db.executemany('UPDATE messages SET data = ? WHERE id = ?', patched)
    return t, y


@pytest.mark.parametrize('stamp', [0, 1_700_000_000_123_456_789])
def test_constant_header_stamps_fall_back_to_log_times(tmp_path, stamp):
    bag = tmp_path / 'zero.db3'
    t, y = _bag_with_stamps(bag, lambda i: stamp)
    with open_input(bag) as source:
        session = stream_input(source, SessionConfig(), prefetch=False)
        warnings = list(source.warnings)
    assert session.stats.n_used == t.size and session.stats.n_duplicate == 0
    assert_allclose(session.rate_hz, 100.0, rtol=1e-9)
    session.check_usable()      # before: 'not enough still data'
    assert any("the bag's log times are used instead" in w for w in warnings)


def test_header_stamps_that_move_are_used_as_they_are(tmp_path):
    bag = tmp_path / 'slow.db3'
    # Stamps at 50 Hz while the log times say 100 Hz: the header is believed.
    t, _ = _bag_with_stamps(bag, lambda i: 1_700_000_000_000_000_000 + i * 20_000_000)
    with open_input(bag) as source:
        session = stream_input(source, SessionConfig(), prefetch=False)
        assert not any('log times' in w for w in source.warnings)
    assert_allclose(session.rate_hz, 50.0, rtol=1e-9)
    assert np.isfinite(session.curve().avar).all()


def test_a_csv_whose_t_does_not_step_is_read_at_its_count_or_a_set_rate(tmp_path):
    # 100 Hz stamped in 0.1 s ticks: the median step is 0.  It was refused ('give the
    # rate'); the rate is the count's over the span, or --rate's, and the tick clock
    # rebuilds the stamps either way (bench/unusual_campaign.py found the refusal).
    from imu_allan import AXES
    from imu_allan.errors import InputError
    from imu_allan.io.csv_io import write_csv
    from imu_allan.io.inputs import analyze_input

    stamps, y = still_imu(30_000, seed=4)
    t_s = np.floor((stamps - stamps[0]) / 1e8) * 0.1
    path = tmp_path / 'ticks.csv'
    write_csv(path, t_s, y, AXES)
    for rate_hz in (0.0, 100.0):
        result, _ = analyze_input(path, None, SessionConfig(rate_hz=rate_hz), quiet=True,
                                  progress=False)
        # Without --rate: the count over the span, within a tick over 300 s.
        assert result.n_samples == 30_000
        assert result.rate_hz == pytest.approx(100.0, rel=1e-9 if rate_hz else 0.1 / 300)
        assert any(w.startswith('coarse stamps') for w in result.warnings)
        # White noise of sd 1e-3 per sample at 100 Hz: N = 1e-4 (within 3 %).
        assert_allclose(result.fits['gyro_x'].optimised['N'].value, 1e-4, rtol=0.03)
    # A t that stands still is refused with the way out.
    write_csv(path, np.zeros_like(t_s), y, AXES)
    with pytest.raises(InputError, match=r'give the rate \(--rate HZ\)'):
        open_input(path)


def test_a_bag_whose_stamps_and_log_times_are_one_value_is_one_line(tmp_path):
    # Header stamps and log times all one value: no row passes the clock, and the unit
    # check had no first rows to judge (a ValueError traceback before; found by the
    # unusual-input campaign's probes).
    from imu_allan.errors import NotEnoughStillData
    from imu_allan.io.inputs import analyze_input
    stamps, y = still_imu(3000, seed=5)
    path = tmp_path / 'one_time.mcap'
    write_imu_bag(path, np.full_like(stamps, stamps[0]), y)
    with pytest.raises(NotEnoughStillData, match='not enough still data: only 0.0 s'):
        analyze_input(path, None, SessionConfig(), quiet=True, progress=False)
