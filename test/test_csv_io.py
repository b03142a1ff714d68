"""CSV reading and writing: contract header, other layouts, and bad input."""

import gzip

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pytest

from imu_allan import AXES
from imu_allan.errors import InputError
from imu_allan.io.csv_io import read_csv, write_csv


def _record(n=500, rate=100.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate + 12.5
    y = rng.standard_normal((n, 6)) * 1e-3 + [0, 0, 0, 0, 0, 9.80665]
    return t, y


@pytest.mark.parametrize('name', ['rec.csv', 'rec.csv.gz'])
def test_write_read_round_trip(tmp_path, name):
    t, y = _record()
    path = tmp_path / name
    write_csv(path, t, y, AXES)
    if name.endswith('.gz'):
        with gzip.open(path, 'rt') as f:
            assert f.readline().strip() == 't,' + ','.join(AXES)
    data = read_csv(path)
    assert data.columns == AXES
    assert_array_equal(data.samples, y)  # 17 significant digits: exact
    assert_allclose(data.t_s, t, atol=1e-9)
    assert_allclose(data.rate_hz, 100.0, rtol=1e-9)
    assert data.samples.flags.c_contiguous and data.samples.dtype == np.float64


def test_extra_columns_ignored_unless_requested(tmp_path):
    t, y = _record(50)
    path = tmp_path / 'x.csv'
    temp = np.linspace(20, 21, 50)
    write_csv(path, t, np.column_stack([y, temp]), list(AXES) + ['temperature'])
    assert read_csv(path).samples.shape == (50, 6)
    data = read_csv(path, columns=['temperature', 'gyro_z'])
    assert data.columns == ('temperature', 'gyro_z')
    assert_array_equal(data.samples, np.column_stack([temp, y[:, 2]]))


def test_any_header_and_rate_override(tmp_path):
    path = tmp_path / 'h.csv'
    path.write_text('time,a,b\r\n0,1,2\r\n0.5,3,4\r\n1.0,5,6\r\n')
    data = read_csv(path)
    assert data.columns == ('a', 'b') and data.rate_hz == 2.0
    assert_array_equal(data.t_s, [0, 0.5, 1.0])
    assert read_csv(path, columns=['b'], rate_hz=7.0).rate_hz == 7.0


def test_headerless_one_column_with_comments(tmp_path):
    path = tmp_path / 'f.txt'
    path.write_text('# a frequency record\n# 1 s gate\n10000000.1\n10000000.3\n'
                    '# mid-file comment\n9999999.9\n')
    data = read_csv(path, rate_hz=1.0)
    assert data.t_s is None and data.columns == ('value',)
    assert_allclose(data.samples[:, 0], [10000000.1, 10000000.3, 9999999.9])
    with pytest.raises(InputError, match='give the sample rate'):
        read_csv(path)


def test_real_recordings(shared_dir):
    adis = read_csv(shared_dir / 'realdata/adis16405/adis16405_run1.csv.gz')
    assert adis.samples.shape == (1_000_000, 6)
    assert_allclose(adis.rate_hz, 100.0, rtol=1e-6)
    assert_allclose(adis.t_s[[0, -1]], [0.0, 9999.99])
    mpu = read_csv(shared_dir / 'realdata/mpu6050_irregular/mpu6050_static_11min.csv.gz',
                   columns=['gyro_x', 'temperature'])
    assert mpu.samples.shape == (65067, 2)
    # About 4.5 deg/s of gyro x bias (realdata README).
    assert_allclose(np.degrees(mpu.samples[:, 0].mean()), 4.5, atol=0.3)


@pytest.mark.parametrize('content, pattern', [
    ('', 'empty'),
    ('\n\n  \n', 'empty'),
    ('# only a comment\n', 'empty'),
    ('t,gyro_x\n', 'no data rows'),
    ('t,gyro_x\n0,1\n0.01,abc\n0.02,3\n', r'row 3: .abc. in column gyro_x is not a number'),
    ('t,gyro_x\n0,1\n0.01,2\n0.02,nan\n', r'row 4: column gyro_x is nan'),
    ('t,gyro_x\n0,1\n0.01,\n', r'row 3: .\(empty\). in column gyro_x'),
    ('t,gyro_x\n0,1\n0.01,2,5\n', r'row 3: expected 2 fields, found 3'),
    ('t,gyro_x\n0,1\n0,2\n0,3\n', 'does not increase'),
    ('t,gyro_x,gyro_x\n0,1,2\n', 'repeated column'),
])
def test_bad_input_names_file_and_row(tmp_path, content, pattern):
    path = tmp_path / 'bad.csv'
    path.write_text(content)
    with pytest.raises(InputError, match=pattern) as info:
        read_csv(path, columns=['gyro_x'])
    msg = str(info.value)
    assert msg.startswith(str(path)) and '\n' not in msg


def test_coarse_time_steps_give_the_rate_of_the_count(tmp_path):
    # A 400 Hz IMU whose t is in 10 ms ticks: four rows per step, median step 0.  It
    # was refused ('does not increase'); the count over the span is the rate (analyze's
    # tick clock rebuilds the stamps); a t that stands or runs back is refused.
    t, y = _record(n=4000, rate=400.0)
    path = tmp_path / 'ticks.csv'
    write_csv(path, np.floor(t * 100.0) / 100.0, y, AXES)
    data = read_csv(path)
    assert_allclose(data.rate_hz, 400.0, rtol=1e-3)
    write_csv(path, np.floor(t[::-1] * 100.0) / 100.0, y, AXES)
    with pytest.raises(InputError, match='does not increase'):
        read_csv(path)


def test_missing_file_and_columns(tmp_path):
    with pytest.raises(InputError, match='no such file'):
        read_csv(tmp_path / 'nope.csv')
    path = tmp_path / 'c.csv'
    path.write_text('t,gyro_x\n0,1\n1,2\n')
    with pytest.raises(InputError, match=r'accel_z not in the header t, gyro_x'):
        read_csv(path, columns=['gyro_x', 'accel_z'])
    gz = tmp_path / 'broken.csv.gz'
    gz.write_bytes(b'not gzip at all')
    with pytest.raises(InputError, match='cannot read'):
        read_csv(gz)


def test_write_rejects_mismatched_shapes(tmp_path):
    with pytest.raises(InputError, match='do not match'):
        write_csv(tmp_path / 'w.csv', np.arange(3.0), np.zeros((4, 6)), AXES)


def test_a_spreadsheet_export_with_byte_order_mark_and_crlf_reads_whole(tmp_path):
    # Excel's "CSV UTF-8" starts with a byte order mark and ends lines with CRLF: the
    # header must still be found, and in a file without header no row may be lost.
    with_header = tmp_path / 'excel.csv'
    with_header.write_bytes(b'\xef\xbb\xbft,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z\r\n'
                            + b''.join(f'{k / 100},{k},2,3,4,5,6\r\n'.encode()
                                       for k in range(5)))
    data = read_csv(with_header)
    assert_allclose(data.t_s, np.arange(5) / 100, rtol=0, atol=1e-12)
    assert_allclose(data.samples[:, 0], np.arange(5), rtol=0, atol=0)
    bare = tmp_path / 'bare.csv'
    bare.write_bytes(b'\xef\xbb\xbf1.5\r\n2.5\r\n3.5\r\n')
    assert_allclose(read_csv(bare, rate_hz=10.0).samples[:, 0], [1.5, 2.5, 3.5], rtol=0,
                    atol=0)
