"""
Unit mistakes named from physics, and the units a user declares for an input.

A still IMU on Earth measures gravity: the magnitude of its mean acceleration is 9.81
m/s^2 whatever its attitude.  Near 1 it was written in g, near 1000 in mg.  A gyro in
deg/s reads 57.3 times its rad/s values, so its white noise and bias come out 57.3
times too large.  A sample rate outside 1 Hz-10 kHz is rarely an IMU: stamps in ms read
as s give a rate 1000 times too low, stamps one nanosecond apart a gigahertz.

:func:`unit_findings` turns these into one-line findings that name the likely mistake
and, where one unit explains it, the ``--units`` declaration that fixes it;
:func:`first_look` judges the first samples of a record (before the motion check, which
would call a deg/s gyro moving); :func:`unit_error` is the one-line refusal of the
findings that name a fix.  :class:`DeclaredUnits` (``--units gyro=deg/s,accel=g,time=ms``,
or a scale per count such as ``gyro=0.05deg/s``) converts an input to SI before the
analysis; a quantity declared there is taken as declared and no longer checked.

The plausibility limits
-----------------------
- Accelerometer: ``ACCEL_NORM_M_S2`` = 8.0-11.6 m/s^2, gravity (9.78-9.83 m/s^2 over the
  Earth's surface) plus 1.8 m/s^2 (about 180 mg) for the zero-g offsets of uncalibrated
  MEMS accelerometers (tens of mg on datasheets, e.g. MPU-6050 +-50 mg per axis).
- Gyro white noise: ``GYRO_WHITE_MAX`` = 3e-3 rad/s/sqrt(Hz) (0.17 deg/s/sqrt(Hz), 10
  deg/sqrt(h)).  MEMS gyro datasheets give 0.004-0.05 deg/s/sqrt(Hz) (7e-5 to 9e-4
  rad/s/sqrt(Hz): MPU-6050 0.005, BMI088 0.014, ADXRS620 0.05), so a rad/s gyro stays
  3x below the limit even at the noisiest, while the same gyros in deg/s read 4e-3 to
  5e-2: above it.  A gyro quieter than 5e-5 rad/s/sqrt(Hz) (tactical and navigation
  grade) read in deg/s stays below the limit: this check cannot see it.
- Gyro white noise that refuses the record: ``GYRO_WHITE_REFUSE`` = 2e-2
  rad/s/sqrt(Hz).  A real gyro is noisier than ``GYRO_WHITE_MAX``: the u-blox C102-F9R,
  5.7e-3 rad/s/sqrt(Hz) (Maia et al. table 2); between the two the mistake is only a
  warning, above (3.5x that gyro) the record is refused as deg/s.  An ADIS16405 in deg/s
  reads 0.036; quieter gyros in deg/s (MPU-6050, BMI088) are refused by their bias, or
  only warned about.
- Gyro bias: ``GYRO_BIAS_MAX`` = 0.5 rad/s (29 deg/s), beyond the zero-rate offsets of
  MEMS gyros (+-20 deg/s for the MPU-6050, the widest on common datasheets) plus the
  Earth's rotation (7.3e-5 rad/s): a still gyro that reads more is in deg/s or moving.
- Rate: ``RATE_HZ`` = 1 Hz-10 kHz, what IMUs deliver (tens of Hz to a few kHz).
- Raw counts: a sensor whose values are all whole numbers, varying, and implausible as
  SI is named as counts (an ADIS16405 gives 0.05 deg/s and 3.33 mg per count).
"""

import math
import re
from typing import NamedTuple

import numpy as np

from imu_allan.errors import InputError, UnitMistake

#: Standard gravity [m/s^2] (the g of accelerometers in g or mg).
G0_M_S2 = 9.80665
#: Plausible magnitude of a still accelerometer's mean [m/s^2].
ACCEL_NORM_M_S2 = (8.0, 11.6)
#: Largest plausible gyro white noise [rad/s/sqrt(Hz)] and still bias [rad/s].
GYRO_WHITE_MAX = 3e-3
GYRO_WHITE_REFUSE = 2e-2
GYRO_BIAS_MAX = 0.5
#: Plausible IMU sample rates [Hz].
RATE_HZ = (1.0, 10_000.0)
#: Share by which a measured rate may pass a bound of RATE_HZ: stamps with jitter give a
#: 1 Hz IMU 0.99999 Hz (the unusual-input campaign, bench/unusual_campaign.py), while a
#: unit mistake is a factor of 1000.
RATE_SLACK = 0.01

#: Largest time [s] int64 nanoseconds hold (the year 2262).
MAX_TIME_S = (2**63 - 1) / 1e9

GYRO_UNITS = {'rad/s': 1.0, 'deg/s': math.pi / 180.0}
ACCEL_UNITS = {'m/s^2': 1.0, 'm/s2': 1.0, 'g': G0_M_S2, 'mg': G0_M_S2 * 1e-3}
#: Time units [s per unit].
TIME_UNITS = {'s': 1.0, 'ms': 1e-3, 'us': 1e-6, 'ns': 1e-9}
_DEG = 180.0 / math.pi
#: Rows :func:`first_look` needs (2 s at 100 Hz: the white noise within about 10 %).
FIRST_LOOK_ROWS = 200
#: Largest variance of a still gyro axis over the white-noise variance of its first
#: differences (1 for white noise, within 1.2 on the still ADIS16405 and MPU-6050
#: records; 27-83 on the gyro axis a driving robot turns).
WHITE_RATIO_MAX = 3.0
#: The SI unit of each quantity (what confirming it declares).
SI_UNITS = {'gyro': 'rad/s', 'accel': 'm/s^2', 'time': 's'}
_SCALED = re.compile(r'^(\d+(?:\.\d*)?(?:e[-+]?\d+)?|\.\d+(?:e[-+]?\d+)?)\*?(.+)$')


def unit_factor(text: str, table: dict) -> float | None:
    """
    Return the SI factor of a unit, optionally scaled per count (``0.05deg/s``).

    Parameters
    ----------
    text : str
        A unit of ``table``, or a positive number followed by one (``*`` between them
        is allowed): the value of one count.
    table : dict of str to float
        Units and their SI factors.

    Returns
    -------
    float or None
        The factor, None when ``text`` is not a unit of ``table``.

    """
    if text in table:
        return table[text]
    match = _SCALED.match(text)
    if not match or match.group(2) not in table:
        return None
    scale = float(match.group(1))
    return scale * table[match.group(2)] if math.isfinite(scale) and scale > 0 else None


class UnitFinding(NamedTuple):
    """
    One unit mistake that physics shows in a record.

    Attributes
    ----------
    quantity : str
        'gyro', 'accel' or 'time'.
    text : str
        One line naming the likely mistake.
    fix : str
        The ``--units`` declaration that would fix it (``gyro=deg/s``), '' when no one
        unit explains the values (then it is only a warning).

    """

    quantity: str
    text: str
    fix: str = ''


class DeclaredUnits(NamedTuple):
    """
    The units an input is written in, as declared with ``--units``.

    Attributes
    ----------
    gyro : str
        'rad/s' or 'deg/s'.
    accel : str
        'm/s^2', 'g' or 'mg'.
    time : str or None
        Unit of the stored times: a CSV's t column, or a bag's header stamps read as
        one integer count; None keeps the format's own (seconds for CSV, ns for bags).
    declared : tuple of str
        The quantities given explicitly (``--units accel=m/s^2`` confirms SI): the unit
        check takes them as declared.

    """

    gyro: str = 'rad/s'
    accel: str = 'm/s^2'
    time: str | None = None
    declared: tuple = ()

    def sample_scale(self) -> np.ndarray:
        """Return the (6,) factors that turn samples into rad/s and m/s^2 (AXES order)."""
        return np.repeat([unit_factor(self.gyro, GYRO_UNITS),
                          unit_factor(self.accel, ACCEL_UNITS)], 3).astype(np.float64)

    def time_scale(self, format_unit_s: float) -> float:
        """Return the factor from the stored times to the format's unit (1 when undeclared)."""
        return 1.0 if self.time is None else TIME_UNITS[self.time] / format_unit_s

    @property
    def is_si(self) -> bool:
        """Return True when nothing is converted."""
        return self.time is None and not (self.sample_scale() != 1.0).any()


def parse_units(text: str | None) -> DeclaredUnits:
    """
    Parse ``--units``: comma-separated ``gyro=deg/s``, ``accel=g``, ``time=ms``.

    A bare unit names its quantity (``deg/s,mg,ms``).  Gyro and accelerometer units may
    carry the value of one count (raw counts: ``gyro=0.05deg/s,accel=3.33mg``).

    Raises
    ------
    InputError
        An unknown quantity or unit, or a quantity given twice.

    """
    given: dict[str, str] = {}
    tables = {'gyro': GYRO_UNITS, 'accel': ACCEL_UNITS, 'time': TIME_UNITS}
    for token in (text or '').split(','):
        token = token.strip().replace(' ', '')
        if not token:
            continue
        key, _, unit = token.rpartition('=')
        scalable = {k: t for k, t in tables.items() if k != 'time'}
        if not key:
            key = next((k for k, t in scalable.items() if unit_factor(unit, t)),
                       'time' if unit in TIME_UNITS else '')
        ok = (unit in TIME_UNITS if key == 'time'
              else key in scalable and unit_factor(unit, scalable[key]) is not None)
        if not ok:
            known = '; '.join(f'{k}={"|".join(t)}' for k, t in tables.items())
            raise InputError(f'--units: cannot read {token!r} (known: {known}; gyro and '
                             'accel also as the value of one count, e.g. gyro=0.05deg/s)')
        if key in given:
            raise InputError(f'--units: {key} given twice')
        given[key] = unit
    return DeclaredUnits(**given, declared=tuple(given))


def unit_warnings(rate_hz: float, means: np.ndarray | None,
                  gyro_white: np.ndarray | None, declared: tuple = ()) -> list[str]:
    """
    Name the unit mistakes that physics shows in a still IMU's record.

    The lines of :func:`unit_findings` (same parameters).

    Returns
    -------
    list of str
        One line per likely mistake (empty when everything is plausible).

    """
    return [f.text for f in unit_findings(rate_hz, means, gyro_white, declared=declared)]


def unit_findings(rate_hz: float, means: np.ndarray | None,
                  gyro_white: np.ndarray | None, counts: tuple = (),
                  declared: tuple = ()) -> list[UnitFinding]:
    """
    Find the unit mistakes that physics shows in a still IMU's record.

    Parameters
    ----------
    rate_hz : float
        Sample rate from the stamps [Hz].
    means : numpy.ndarray or None
        (6,) mean of each axis in AXES order [rad/s, m/s^2]; None skips the gravity and
        bias checks.
    gyro_white : numpy.ndarray or None
        (3,) white noise density N of the gyro axes [rad/s/sqrt(Hz)] (NaN where
        unknown); None skips the noise check.
    counts : tuple of str
        The sensors ('gyro', 'accel') whose values are all whole numbers: named as raw
        counts when their values are implausible.
    declared : tuple of str
        Quantities the user declared (``--units``): not checked.

    Returns
    -------
    list of UnitFinding
        One per likely mistake (empty when everything is plausible).

    """
    out = []
    rate = _rate_warning(rate_hz)
    if rate:
        out.append(UnitFinding('time', *rate))
    if means is not None and np.isfinite(means[3:]).all():
        accel = _accel_warning(float(np.linalg.norm(means[3:])), 'accel' in counts)
        if accel:
            out.append(UnitFinding('accel', *accel))
    gyro = _gyro_warning(None if means is None else means[:3], gyro_white, 'gyro' in counts)
    if gyro:
        out.append(UnitFinding('gyro', *gyro))
    return [f for f in out if f.quantity not in declared]


def first_look(rate_hz: float, samples: np.ndarray) -> list[UnitFinding]:
    """
    Find unit mistakes in the first samples of a record, before any other judgement.

    A deg/s gyro or an accelerometer in mg is otherwise judged moving (its noise and
    offsets are 57 or 1000 times what the motion thresholds expect).  A sensor whose
    axes are all constant is left to the frozen-axis check; a gyro whose variance is
    more than :data:`WHITE_RATIO_MAX` times that of white noise of the same first
    differences turned (a robot driving off), and is left to the motion check.

    Parameters
    ----------
    rate_hz : float
        Sample rate from the stamps [Hz] (0: unknown, the noise is not judged).
    samples : numpy.ndarray
        (n, 6) finite samples in AXES order as read [rad/s, m/s^2 if the units are
        right]; :data:`FIRST_LOOK_ROWS` give the noise within about 10 %.

    Returns
    -------
    list of UnitFinding
        As :func:`unit_findings`; the gyro noise is N = std(first differences) /
        sqrt(2 rate) (white noise of PSD N^2 has a per-sample variance N^2 rate, IEEE
        Std 952 C.1), not judged when the rate itself is implausible.

    """
    y = np.asarray(samples, dtype=np.float64)
    if y.shape[0] < 3:
        return []
    means = y.mean(axis=0)
    # Per axis: variance of the samples over that of white noise with these steps.
    half_step_var = np.var(np.diff(y, axis=0), axis=0) / 2.0
    varies = half_step_var > 0
    ratio = np.var(y, axis=0) / np.where(varies, half_step_var, 1.0)
    gyro_still = bool(varies[:3].any() and np.all(ratio[:3][varies[:3]] <= WHITE_RATIO_MAX))
    white = None
    if gyro_still and _rate_warning(rate_hz) is None and rate_hz > 0:
        white = np.sqrt(half_step_var[:3] / rate_hz)
    if not gyro_still:
        means[:3] = np.nan
    if not varies[3:].any():
        means[3:] = np.nan
    # Whole numbers that change: raw counts (an axis of a coarse sensor may hold one
    # count through the first samples, so one axis that changes is enough).
    counts = tuple(name for name, cols in (('gyro', slice(0, 3)), ('accel', slice(3, 6)))
                   if varies[cols].any() and np.all(y[:, cols] == np.round(y[:, cols])))
    return unit_findings(rate_hz, means, white, counts)


def unit_error(findings: list) -> str | None:
    """
    Return the one-line refusal of the findings that name a fix (None when none does).

    Parameters
    ----------
    findings : list of UnitFinding
        From :func:`unit_findings` or :func:`first_look`.

    Returns
    -------
    str or None
        The likely mistakes, what to rerun with, and how to confirm the values as they
        are (declaring the SI unit).

    """
    named = [f for f in findings if f.fix]
    if not named:
        return None
    fixes = ','.join(f.fix for f in named)
    confirm = ','.join(f'{f.quantity}={SI_UNITS[f.quantity]}' for f in named)
    return ('unit mistake: ' + '; '.join(f.text for f in named)
            + f'; rerun with --units {fixes} (or confirm the values as they are with '
            f'--units {confirm})')


def _rate_warning(rate_hz: float) -> tuple | None:
    """Return (text, fix) for an implausible rate, or None."""
    lo, hi = RATE_HZ
    if not (math.isfinite(rate_hz) and rate_hz > 0) or \
            lo * (1 - RATE_SLACK) <= rate_hz <= hi * (1 + RATE_SLACK):
        return None
    head = f'sample rate {rate_hz:.4g} Hz is outside {lo:g} Hz-{hi / 1e3:g} kHz'
    if rate_hz < lo:
        # Times k times too far apart: a unit k times smaller read as seconds.
        unit, k = _likeliest(rate_hz, (('ms', 1e3), ('us', 1e6), ('ns', 1e9)))
        if unit:
            return (f'{head}: the times look like {unit} read as seconds (the rate '
                    f'would be {rate_hz * k:.4g} Hz; declare --units time={unit})',
                    f'time={unit}')
        return f'{head}: are the times in seconds?', ''
    if 1e9 / rate_hz <= 1.5:
        return (f'{head}: the stamps are 1 ns apart, a sample counter or a time unit far '
                'too large stored as nanoseconds (declare it with --units time=...)', '')
    # Stamps k times too close: a unit k times larger stored as nanoseconds.
    unit, k = _likeliest(rate_hz, (('us', 1e-3), ('ms', 1e-6)))
    if unit:
        return (f'{head}: the stamps look {1 / k:g}x too close together, {unit} stored as '
                f'ns? (the rate would be {rate_hz * k:.4g} Hz; declare --units time={unit})',
                f'time={unit}')
    return f'{head}: the stamps look too close together for an IMU', ''


def _likeliest(rate_hz: float, fixes: tuple) -> tuple:
    """Return the (unit, factor) whose rate is plausible and nearest 100 Hz, or ('', 0)."""
    lo, hi = RATE_HZ
    ok = [(abs(math.log10(rate_hz * k / 100.0)), unit, k) for unit, k in fixes
          if lo <= rate_hz * k <= hi]
    return min(ok)[1:] if ok else ('', 0.0)


def _accel_warning(norm: float, counts: bool) -> tuple | None:
    """Return (text, fix) for an accelerometer that does not read gravity, or None."""
    lo, hi = ACCEL_NORM_M_S2
    if lo <= norm <= hi:
        return None
    head = (f'the still accelerometer reads {norm:.4g} "m/s^2" in magnitude, not gravity '
            f'({G0_M_S2:.2f} m/s^2)')
    for unit, scale in (('g', G0_M_S2), ('mg', G0_M_S2 * 1e-3)):
        if lo <= norm * scale <= hi:
            return (f'{head}: the accelerometer looks like {unit} (declare --units '
                    f'accel={unit})', f'accel={unit}')
    if counts:
        return (f'{head}: its values are whole numbers, raw counts? (declare the value of '
                'one count, the LSB of the range set: e.g. --units accel=0.061mg for an '
                'MPU-6050 at +-2 g, accel=3.33mg for an ADIS16405)', 'accel=<value of one count>')
    if norm < 0.1 * lo:
        return f'{head}: gravity was removed from this output, or it is not in m/s^2', ''
    return f'{head}: a unit or scale mistake?', ''


def _gyro_warning(bias: np.ndarray | None, white: np.ndarray | None,
                  counts: bool) -> tuple | None:
    """Return (text, fix) for a gyro too noisy or too offset for rad/s, or None."""
    reasons = []
    sure = False        # a reason that names the fix (refuses the record)
    if white is not None and np.isfinite(white).any():
        n = float(np.nanmedian(white))
        sure = n > GYRO_WHITE_REFUSE
        if n > GYRO_WHITE_MAX:
            reasons.append(f'its white noise {n:.3g} rad/s/sqrt(Hz) is above '
                           f'{GYRO_WHITE_MAX:g} (noisier than any MEMS gyro; {n / _DEG:.3g} '
                           'if the values are deg/s)')
    if bias is not None and np.isfinite(bias).all():
        b = float(np.max(np.abs(bias)))
        if b > GYRO_BIAS_MAX:
            sure = True
            reasons.append(f'its still bias {b:.3g} rad/s is above {GYRO_BIAS_MAX:g} rad/s')
    if counts and not sure:
        # A still gyro in rad/s (or deg/s) does not step by whole units.
        sure = True
        reasons.append('its values step by whole units (57 deg/s)')
    if not reasons:
        return None
    if counts:
        return ('the gyro does not look like rad/s: ' + '; '.join(reasons)
                + ': its values are whole numbers, raw counts? (declare the value of one '
                'count, the LSB of the range set: e.g. --units gyro=0.00763deg/s for an '
                'MPU-6050 at +-250 deg/s, gyro=0.05deg/s for an ADIS16405)',
                'gyro=<value of one count>')
    return ('the gyro does not look like rad/s: ' + '; '.join(reasons)
            + ': deg/s? (declare --units gyro=deg/s), or the IMU moved',
            'gyro=deg/s' if sure else '')


def stamps_ns(times: np.ndarray, scale_s: float) -> np.ndarray:
    """
    Return times as int64 nanoseconds; a time beyond what they hold is one line.

    Parameters
    ----------
    times : numpy.ndarray
        (n,) float64 times in a unit of ``scale_s`` seconds (a CSV's t column).
    scale_s : float
        Seconds per unit of ``times`` (1 unless ``--units time=...`` was declared).

    Returns
    -------
    numpy.ndarray
        (n,) int64 [ns].

    Raises
    ------
    UnitMistake
        When a time lies beyond MAX_TIME_S: integer ms, us or ns since 1970 read as
        seconds (the unit that brings it within range is named) would overflow.

    """
    t_s = times * scale_s
    worst = float(np.abs(t_s).max()) if t_s.size else 0.0
    if worst > MAX_TIME_S:
        unit = next((u for u, k in (('ms', 1e-3), ('us', 1e-6), ('ns', 1e-9))
                     if worst * k <= MAX_TIME_S), '')
        hint = (f': the times look like {unit} read as seconds; rerun with --units '
                f'time={unit}') if unit else ''
        raise UnitMistake(f'unit mistake: time {worst:.4g} s is beyond what '
                          f'nanosecond stamps hold (the year 2262){hint}')
    return np.round(t_s * 1e9).astype(np.int64)
