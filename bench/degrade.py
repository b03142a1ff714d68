"""
Degrade a clean IMU record the ways real drivers and first days do.

One small, seeded, pure function per degradation class, registered in
:data:`DEGRADATIONS` with the sizes the metamorphic bench (``bench/metamorphic.py``)
sweeps.  Each takes a :class:`Record` (stamps, samples, optional temperature) and one
size, and returns the degraded :class:`Record`; it never changes its input.  The classes,
what a driver does to produce each and where that is reported, are the taxonomy of
docs/robustness.md.

Conventions: ``t_s`` (n,) [s], ``samples`` (n, 6) in ``imu_allan.AXES`` order [rad/s,
m/s^2], ``temp_c`` (n,) [deg C] or None.  A degradation that writes values in other
units says so in ``Record.units`` (the ``--units`` a user who knew would declare); the
bench analyses the record without it (the unit check must name the mistake) and, for
the classes marked ``declared``, with it (the converted record must agree).
"""

from dataclasses import dataclass
import math
from typing import Callable, NamedTuple

import numpy as np

G_M_S2 = 9.80665
DEG_RAD = math.pi / 180.0


class Record(NamedTuple):
    """
    A six-axis record.

    Attributes
    ----------
    t_s : np.ndarray
        Shape (n,), stamps [s] (as a CSV ``t`` column holds them).
    samples : np.ndarray
        Shape (n, 6), rates and specific forces [rad/s, m/s^2] unless ``units`` says.
    temp_c : np.ndarray or None
        Shape (n,), sensor temperature [deg C]; None when the input carries none.
    units : str
        The ``--units`` declaration that converts the record to SI ('' when SI).

    """

    t_s: np.ndarray
    samples: np.ndarray
    temp_c: np.ndarray | None = None
    units: str = ''


@dataclass(frozen=True)
class Degradation:
    """
    One degradation class of the taxonomy.

    Attributes
    ----------
    name : str
        Short name (bench option ``--degradations``).
    apply : callable
        ``apply(record, size, rng) -> Record``; pure: the input is not modified.
    sizes : tuple of float
        The sizes the bench sweeps, smallest first.
    size_unit : str
        What a size means ('%', 's', 'x', ...).
    cause : tuple of str
        Lower-case words a warning naming this cause contains (any one suffices).
    what : str
        One line: what the driver or the first day does.
    declared : bool
        Also analyse with ``Record.units`` declared (unit mistakes).

    """

    name: str
    apply: Callable[[Record, float, np.random.Generator], Record]
    sizes: tuple
    size_unit: str
    cause: tuple
    what: str
    declared: bool = False


def _rate_hz(t_s: np.ndarray) -> float:
    """Return the mean sample rate of the first 10,000 stamps [Hz] (bursty stamps too)."""
    t = t_s[:10_000]
    return (t.size - 1) / float(t[-1] - t[0])


def _keep(rec: Record, keep: np.ndarray) -> Record:
    """Return the rows where keep is True (stamps, values and temperature alike)."""
    return rec._replace(t_s=rec.t_s[keep], samples=rec.samples[keep],
                        temp_c=None if rec.temp_c is None else rec.temp_c[keep])


def _take(rec: Record, index: np.ndarray) -> Record:
    """Return the rows at index (a permutation, repetition or selection)."""
    return rec._replace(t_s=rec.t_s[index], samples=rec.samples[index],
                        temp_c=None if rec.temp_c is None else rec.temp_c[index])


# --- message loss ------------------------------------------------------------------------

def drop_random(rec: Record, pct: float, rng: np.random.Generator) -> Record:
    """Lose pct % of the messages independently (best-effort QoS, a loaded host)."""
    return _keep(rec, rng.random(rec.t_s.size) >= pct / 100.0)


def drop_bursts(rec: Record, pct: float, rng: np.random.Generator) -> Record:
    """
    Lose pct % of the messages in bursts (a serial/USB buffer overrun).

    Burst lengths are geometric with mean 20 messages; burst starts are uniform.
    """
    n = rec.t_s.size
    lost = np.zeros(n, dtype=bool)
    target = int(round(n * pct / 100.0))
    while lost.sum() < target:
        k = int(rng.integers(0, n))
        lost[k:k + int(rng.geometric(1.0 / 20.0))] = True
    return _keep(rec, ~lost)


def gaps(rec: Record, gap_s: float, rng: np.random.Generator) -> Record:
    """Lose three stretches of gap_s seconds each (a driver restart, a full disk)."""
    t = rec.t_s
    span = t[-1] - t[0]
    keep = np.ones(t.size, dtype=bool)
    for frac in (0.25, 0.5, 0.75):
        start = t[0] + frac * span + rng.uniform(-0.05, 0.05) * span
        keep &= ~((t >= start) & (t < start + gap_s))
    return _keep(rec, keep)


# --- held, duplicated, reordered messages ----------------------------------------------------

def hold(rec: Record, k: float, rng: np.random.Generator) -> Record:
    """
    Publish k times faster than the sensor updates (a driver's zero-order hold).

    The sensor's update is the mean of its k samples (its own decimation filter, so
    the white-noise density is unchanged); the driver polls every original stamp and
    republishes the latest update.  Non-integer k: the polls jitter by +-0.3 periods,
    so each update is held a varying number of times.
    """
    y = rec.samples
    ends = np.floor(np.arange(k, y.shape[0] + 1e-9, k)).astype(np.int64)
    starts = np.concatenate(([0], ends[:-1]))
    sums = np.concatenate((np.zeros((1, y.shape[1])), np.cumsum(y, axis=0)))
    means = (sums[ends] - sums[starts]) / (ends - starts)[:, None]
    n = int(ends[-1])
    jitter = 0.0 if float(k).is_integer() else 0.3
    polled = np.arange(n) + rng.uniform(-jitter, jitter, n)
    j = np.searchsorted(ends, polled, side='right') - 1
    ok = j >= 0
    out = _take(rec, np.arange(n)[ok])
    return out._replace(samples=means[j[ok]])


def interpolate(rec: Record, k: float, rng: np.random.Generator) -> Record:
    """
    Interpolate the accelerometer linearly onto the gyro's stamps (united IMU streams).

    realsense-ros' ``unite_imu_method: linear_interpolation`` publishes one message per
    gyro sample, the accelerometer (updating k times slower: 400 Hz gyro and 250 Hz
    accel is k = 1.6, 200 and 63 Hz about 3.2) interpolated between its two updates
    around it.  Each update is the mean of the record over its k sample periods (the
    sensor's own decimation; a fractional k weighs the samples at a window's ends by
    their share, so every update weighs the same time and the density is unchanged),
    stamped at its window's middle; the gyro is kept.
    """
    y = rec.samples.copy()
    n = y.shape[0]
    edges = np.arange(0.0, n + 1e-9, k)
    sums = np.concatenate((np.zeros((1, 3)), np.cumsum(y[:, 3:], axis=0)))
    t_u = np.interp(0.5 * (edges[:-1] + edges[1:]) - 0.5, np.arange(n), rec.t_s)
    inside = (rec.t_s >= t_u[0]) & (rec.t_s <= t_u[-1])
    for j in range(3):
        means = np.diff(np.interp(edges, np.arange(n + 1), sums[:, j])) / k
        y[:, 3 + j] = np.interp(rec.t_s, t_u, means)
    return _keep(rec._replace(samples=y), inside)


def duplicate(rec: Record, pct: float, rng: np.random.Generator) -> Record:
    """Publish pct % of the messages twice, same stamp and values (a driver race)."""
    n = rec.t_s.size
    reps = 1 + (rng.random(n) < pct / 100.0).astype(np.int64)
    return _take(rec, np.repeat(np.arange(n), reps))


def reorder(rec: Record, pct: float, rng: np.random.Generator) -> Record:
    """Swap pct % of the messages with their successor (a multi-threaded publisher)."""
    n = rec.t_s.size
    index = np.arange(n)
    for k in np.flatnonzero(rng.random(n - 1) < pct / 100.0):
        index[k], index[k + 1] = index[k + 1], index[k]
    return _take(rec, index)


# --- time stamps --------------------------------------------------------------------------

def arrival_jitter(rec: Record, periods: float, rng: np.random.Generator) -> Record:
    """
    Stamp each message when the host received it (header.stamp = now()).

    Latency is exponential with a mean of ``periods`` sample periods; the host reads
    a queue in order, so a stamp is never earlier than the one before it.
    """
    dt = 1.0 / _rate_hz(rec.t_s)
    late = rec.t_s + rng.exponential(periods * dt, rec.t_s.size)
    return rec._replace(t_s=np.maximum.accumulate(late))


def stamp_quantum(rec: Record, quantum_ms: float, rng: np.random.Generator) -> Record:
    """Round the stamps down to a clock of quantum_ms milliseconds (a 1 kHz tick ...)."""
    q = quantum_ms / 1000.0
    return rec._replace(t_s=np.floor(rec.t_s / q) * q)


def clock_jump(rec: Record, jump_s: float, rng: np.random.Generator) -> Record:
    """Step the clock by jump_s seconds mid-record, no sample lost (NTP, a time reset)."""
    k = rec.t_s.size // 2 + int(rng.integers(-rec.t_s.size // 10, rec.t_s.size // 10))
    t = rec.t_s.copy()
    t[k:] += jump_s
    return rec._replace(t_s=t)


def clock_jump_back(rec: Record, jump_s: float, rng: np.random.Generator) -> Record:
    """Step the clock back by jump_s seconds mid-record (a sensor time reset)."""
    return clock_jump(rec, -jump_s, rng)


def rate_drift(rec: Record, ppm: float, rng: np.random.Generator) -> Record:
    """Stamp with a host clock whose rate is off by ppm parts per million."""
    return rec._replace(t_s=rec.t_s[0] + (rec.t_s - rec.t_s[0]) * (1.0 + ppm * 1e-6))


# --- values -------------------------------------------------------------------------------

def _sigma(rec: Record) -> np.ndarray:
    """(6,) robust per-sample noise sd [unit] from the first differences."""
    d = np.diff(rec.samples[:100_000], axis=0)
    mad = np.median(np.abs(d - np.median(d, axis=0)), axis=0)
    return 1.4826 * mad / math.sqrt(2.0) + 1e-12


def spikes(rec: Record, pct: float, rng: np.random.Generator) -> Record:
    """Corrupt pct % of the messages on one random axis by 20-200 sigma (bus errors)."""
    y = rec.samples.copy()
    sig = _sigma(rec)
    rows = np.flatnonzero(rng.random(y.shape[0]) < pct / 100.0)
    cols = rng.integers(0, 6, rows.size)
    y[rows, cols] += rng.choice((-1.0, 1.0), rows.size) * rng.uniform(20, 200, rows.size) \
        * sig[cols]
    return rec._replace(samples=y)


def zero_rows(rec: Record, pct: float, rng: np.random.Generator) -> Record:
    """Zero the gyro or the accel fields of pct % of the messages (incomplete packets)."""
    y = rec.samples.copy()
    rows = np.flatnonzero(rng.random(y.shape[0]) < pct / 100.0)
    gyro = rng.random(rows.size) < 0.5
    y[rows[gyro], :3] = 0.0
    y[rows[~gyro], 3:] = 0.0
    return rec._replace(samples=y)


def frozen(rec: Record, seconds: float, rng: np.random.Generator) -> Record:
    """Repeat the last value of every axis for ``seconds`` mid-record (a stuck read)."""
    y = rec.samples.copy()
    n = int(seconds * _rate_hz(rec.t_s))
    k = int(rng.integers(y.shape[0] // 4, y.shape[0] // 2))
    y[k:k + n] = y[k - 1]
    return rec._replace(samples=y)


def coarse_grid(rec: Record, sds: float, rng: np.random.Generator) -> Record:
    """Round every axis to a grid of ``sds`` sds of one sample (a logger's few digits)."""
    step = sds * _sigma(rec)
    return rec._replace(samples=np.round(rec.samples / step) * step)


def knocks(rec: Record, count: float, rng: np.random.Generator) -> Record:
    """Add one-second knocks, ``count`` of them (a door, a footstep: 0.5 rad/s, 2 m/s^2)."""
    y = rec.samples.copy()
    rate = _rate_hz(rec.t_s)
    m = max(int(rate), 2)
    shape = np.sin(np.linspace(0.0, 4 * math.pi, m)) * np.hanning(m)
    for _ in range(int(count)):
        k = int(rng.integers(0, y.shape[0] - m))
        y[k:k + m, :3] += 0.5 * shape[:, None] * rng.uniform(-1, 1, 3)
        y[k:k + m, 3:] += 2.0 * shape[:, None] * rng.uniform(-1, 1, 3)
    return rec._replace(samples=y)


def _settling(rec: Record, level: float, shape: np.ndarray) -> Record:
    """Add level * shape (n,) to the gyro [0.1 deg/s] and accel [20 mg] biases, signed."""
    y = rec.samples.copy()
    sign = np.array([1, -1, 1, -1, 1, -1], dtype=np.float64)
    y[:, :3] += level * 0.1 * DEG_RAD * shape[:, None] * sign[:3]
    y[:, 3:] += level * 0.02 * G_M_S2 * shape[:, None] * sign[3:]
    return rec._replace(samples=y)


def warmup_exp(rec: Record, minutes: float, rng: np.random.Generator) -> Record:
    """Add a bias settling exponentially after power-on: time constant minutes / 3."""
    age = rec.t_s - rec.t_s[0]
    return _settling(rec, 1.0, np.exp(-age / (minutes * 60.0 / 3.0)))


def warmup_ramp(rec: Record, minutes: float, rng: np.random.Generator) -> Record:
    """Add a bias falling linearly to its still value over the first ``minutes``."""
    age = rec.t_s - rec.t_s[0]
    return _settling(rec, 1.0, np.clip(1.0 - age / (minutes * 60.0), 0.0, None))


def warmup_overshoot(rec: Record, minutes: float, rng: np.random.Generator) -> Record:
    """Add a heater loop settling with a damped oscillation over the first ``minutes``."""
    age = rec.t_s - rec.t_s[0]
    span = minutes * 60.0
    return _settling(rec, 1.0, np.exp(-3 * age / span) * np.cos(2 * math.pi * age / (span / 2)))


def restart(rec: Record, minutes: float, rng: np.random.Generator) -> Record:
    """Restart the sensor mid-record: a new bias offset, then a fresh settling transient."""
    age = rec.t_s - rec.t_s[0]
    t0 = 0.5 * age[-1]
    after = age >= t0
    shape = np.where(after, 0.3 + np.exp(-(age - t0) / (minutes * 60.0 / 3.0)), 0.0)
    return _settling(rec, 1.0, shape)


def _temperature(rec: Record, swing_c: float) -> np.ndarray:
    """(n,) a 40-minute HVAC cycle of +-swing_c around 25 C plus a slow warming."""
    age = rec.t_s - rec.t_s[0]
    return 25.0 + swing_c * (np.sin(2 * math.pi * age / 2400.0)
                             + 0.5 * (1.0 - np.exp(-age / 3600.0)))


def _thermal(rec: Record, swing_c: float, keep_temp: bool) -> Record:
    """Add a bias of 0.01 deg/s/C and 1 mg/C (signed per axis) following the temperature."""
    temp = _temperature(rec, swing_c)
    y = rec.samples.copy()
    sign = np.array([1, -1, 1, 1, -1, 1], dtype=np.float64)
    d = (temp - 25.0)[:, None]
    y[:, :3] += 0.01 * DEG_RAD * d * sign[:3]
    y[:, 3:] += 1e-3 * G_M_S2 * d * sign[3:]
    return rec._replace(samples=y, temp_c=temp if keep_temp else None)


def thermal_with_temp(rec: Record, swing_c: float, rng: np.random.Generator) -> Record:
    """Add a temperature-driven bias, the temperature in the input (a CSV column)."""
    return _thermal(rec, swing_c, True)


def thermal_no_temp(rec: Record, swing_c: float, rng: np.random.Generator) -> Record:
    """Add the same temperature-driven bias, the temperature not in the input."""
    return _thermal(rec, swing_c, False)


# --- units, length, rate ---------------------------------------------------------------------

def _prefix(rec: Record, minutes: float) -> Record:
    """Keep the first ``minutes`` (the whole record when minutes <= 0 or longer)."""
    if minutes <= 0:
        return rec
    return _keep(rec, rec.t_s - rec.t_s[0] < minutes * 60.0)


def gyro_deg(rec: Record, minutes: float, rng: np.random.Generator) -> Record:
    """Gyro in deg/s (a driver skipping REP 103's conversion); size: record length."""
    out = _prefix(rec, minutes)
    y = out.samples.copy()
    y[:, :3] /= DEG_RAD
    return out._replace(samples=y, units='gyro=deg/s')


def accel_g(rec: Record, minutes: float, rng: np.random.Generator) -> Record:
    """Accelerations in g (Livox, Hesai, many BNO055 wrappers); size: record length."""
    out = _prefix(rec, minutes)
    y = out.samples.copy()
    y[:, 3:] /= G_M_S2
    return out._replace(samples=y, units='accel=g')


def accel_mg(rec: Record, minutes: float, rng: np.random.Generator) -> Record:
    """Accelerations in mg (raw register scale of many MEMS parts); size: record length."""
    out = _prefix(rec, minutes)
    y = out.samples.copy()
    y[:, 3:] /= G_M_S2 / 1000.0
    return out._replace(samples=y, units='accel=mg')


def stamps_ms(rec: Record, minutes: float, rng: np.random.Generator) -> Record:
    """Stamps written in milliseconds (a logger's millis()); size: record length."""
    out = _prefix(rec, minutes)
    return out._replace(t_s=out.t_s * 1000.0, units='time=ms')


def first_minutes(rec: Record, minutes: float, rng: np.random.Generator) -> Record:
    """Keep the first ``minutes`` alone (a first day's short record)."""
    return _prefix(rec, minutes)


def low_rate(rec: Record, rate_hz: float, rng: np.random.Generator) -> Record:
    """
    Configure the sensor at ``rate_hz``: block means of the record (its own filter).

    No-op (the record itself) when rate_hz is not below the record's rate.
    """
    k = int(round(_rate_hz(rec.t_s) / rate_hz))
    if k <= 1:
        return rec
    n = rec.t_s.size // k * k
    y = rec.samples[:n].reshape(-1, k, 6).mean(axis=1)
    temp = None if rec.temp_c is None else rec.temp_c[:n].reshape(-1, k).mean(axis=1)
    return rec._replace(t_s=rec.t_s[:n:k], samples=y, temp_c=temp)


# --- combinations -----------------------------------------------------------------------------

def drop_and_gap(rec: Record, pct: float, rng: np.random.Generator) -> Record:
    """Drop pct % at random plus one 30 s hiccup (issue 35's first example)."""
    return gaps(drop_random(rec, pct, rng), 30.0, rng)


def hold_and_drop(rec: Record, k: float, rng: np.random.Generator) -> Record:
    """Hold k times and drop 2 % of the messages in bursts."""
    return drop_bursts(hold(rec, k, rng), 2.0, rng)


def warmup_and_thermal(rec: Record, minutes: float, rng: np.random.Generator) -> Record:
    """Add a settling transient of ``minutes`` and a +-2 C thermal bias, no temperature."""
    return warmup_exp(thermal_no_temp(rec, 2.0, rng), minutes, rng)


def jitter_dup_drop(rec: Record, pct: float, rng: np.random.Generator) -> Record:
    """Host stamps (1 period latency) with pct % duplicated and pct % dropped."""
    return arrival_jitter(duplicate(drop_random(rec, pct, rng), pct, rng), 1.0, rng)


_GAP = ('gap of', 'gaps of', 'missing', 'messages lost', 'samples lost', 'were lost')
_STAMP = ('stamp', 'clock', 'irregular', 'jitter', 'order', 'backward', 'rate')
_SETTLE = ('settl', 'warm', 'transient', 'drift', 'start')
_THERMAL = ('temperature', 'thermal', 'drift')
_SHORT = ('short', 'longer record')
_UNIT = ('unit', '--units')


def _d(name, fn, sizes, unit, cause, declared=False) -> Degradation:
    return Degradation(name, fn, tuple(sizes), unit, tuple(cause),
                       (fn.__doc__ or '').strip().splitlines()[0], declared)


#: Every degradation class, in the order of docs/robustness.md's taxonomy.
DEGRADATIONS = {d.name: d for d in (
    _d('drop_random', drop_random, (0.5, 2.0, 10.0), '%', _GAP),
    _d('drop_bursts', drop_bursts, (0.5, 2.0, 10.0), '%', _GAP),
    _d('gaps', gaps, (2.0, 30.0, 300.0), 's', _GAP),
    _d('hold', hold, (2.0, 3.0, 5.0), 'x', ('held', 'repeat', 'hold', 'update rate')),
    _d('poll', hold, (1.5, 1.9, 3.6), 'x', ('held', 'repeat', 'hold', 'update rate')),
    _d('interpolate', interpolate, (1.6, 2.0, 3.2), 'x',
       ('interpolates', 'interpolated between', 'linear_interpolation')),
    _d('duplicate', duplicate, (0.5, 2.0, 10.0), '%', ('duplicate', 'repeat') + _STAMP),
    _d('reorder', reorder, (0.1, 1.0, 5.0), '%', ('order', 'backward') + _STAMP),
    _d('arrival_jitter', arrival_jitter, (0.2, 1.0, 5.0), 'periods', _STAMP),
    _d('stamp_quantum', stamp_quantum, (1.0, 4.0, 8.0), 'ms', _STAMP),
    _d('clock_jump', clock_jump, (0.5, 5.0, 60.0), 's', _STAMP + _GAP),
    _d('clock_jump_back', clock_jump_back, (0.1, 1.0, 10.0), 's', _STAMP),
    _d('rate_drift', rate_drift, (100.0, 1000.0, 10000.0), 'ppm', _STAMP),
    _d('spikes', spikes, (0.001, 0.01, 0.1), '%', ('spike', 'outlier')),
    _d('zero_rows', zero_rows, (0.1, 1.0, 10.0), '%', ('spike', 'outlier', 'zero')),
    _d('frozen', frozen, (3.0, 30.0, 300.0), 's', ('frozen', 'repeat', 'stuck', 'constant')),
    _d('coarse_grid', coarse_grid, (0.5, 2.0, 8.0), 'sd', ('resolution', 'grid', 'round')),
    _d('knocks', knocks, (1.0, 5.0, 20.0), 'count', ('motion', 'still', 'stationary')),
    _d('warmup_exp', warmup_exp, (5.0, 10.0, 30.0), 'min', _SETTLE),
    _d('warmup_ramp', warmup_ramp, (5.0, 10.0, 30.0), 'min', _SETTLE),
    _d('warmup_overshoot', warmup_overshoot, (5.0, 10.0, 30.0), 'min', _SETTLE),
    _d('restart', restart, (2.0, 5.0, 10.0), 'min', _SETTLE + ('restart', 'level', 'step')),
    _d('thermal_with_temp', thermal_with_temp, (0.5, 2.0, 5.0), 'C', _THERMAL),
    _d('thermal_no_temp', thermal_no_temp, (0.5, 2.0, 5.0), 'C', _THERMAL),
    _d('gyro_deg', gyro_deg, (2.0, 20.0, 0.0), 'min (0: all)', _UNIT, declared=True),
    _d('accel_g', accel_g, (2.0, 20.0, 0.0), 'min (0: all)', _UNIT, declared=True),
    _d('accel_mg', accel_mg, (2.0, 20.0, 0.0), 'min (0: all)', _UNIT, declared=True),
    _d('stamps_ms', stamps_ms, (2.0, 20.0, 0.0), 'min (0: all)', _UNIT, declared=True),
    _d('first_minutes', first_minutes, (2.0, 10.0, 30.0), 'min', _SHORT),
    _d('low_rate', low_rate, (10.0, 4.0, 1.0), 'Hz', ('rate', 'short', 'longer record')),
    _d('drop_and_gap', drop_and_gap, (0.5, 2.0, 10.0), '%', _GAP),
    _d('hold_and_drop', hold_and_drop, (2.0, 3.0, 5.0), 'x', _GAP + ('held', 'repeat')),
    _d('warmup_and_thermal', warmup_and_thermal, (5.0, 10.0, 30.0), 'min',
       _SETTLE + _THERMAL),
    _d('jitter_dup_drop', jitter_dup_drop, (0.5, 2.0, 10.0), '%', _GAP + _STAMP),
)}


def degrade(rec: Record, name: str, size: float, seed: int = 0) -> Record:
    """
    Apply one registered degradation with a seeded generator.

    Parameters
    ----------
    rec : Record
        The clean record.
    name : str
        A key of :data:`DEGRADATIONS`.
    size : float
        Its size (the class' ``size_unit``).
    seed : int
        Seed of ``np.random.default_rng``; the same seed gives the same record.

    Returns
    -------
    Record

    """
    rng = np.random.default_rng([seed, sum(map(ord, name)), int(round(size * 1000))])
    return DEGRADATIONS[name].apply(rec, size, rng)
