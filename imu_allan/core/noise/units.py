"""
Units of IMU noise parameters: parse the units people quote, format customary ones.

Every parameter is stored in SI units of the axis' samples (``unit`` = rad/s for a
gyro, m/s^2 for an accelerometer).  :func:`to_si` turns a number or a string such as
``'0.007 deg/s/sqrt(Hz)'`` into SI after checking that the unit has the dimension the
key needs for that sensor; :func:`quoted` gives the customary unit for summaries.

=========  ================  ==========================  ===========================
key        SI (gyro / accel)  accepted, e.g. (gyro)        accepted, e.g. (accel)
=========  ================  ==========================  ===========================
N          rad/s^0.5,        rad/s/sqrt(Hz), deg/sqrt(h), m/s^2/sqrt(Hz), m/s^1.5,
           m/s^1.5           deg/s/sqrt(Hz),              ug/sqrt(Hz), mg/sqrt(Hz),
                             deg/h/sqrt(Hz)               m/s/sqrt(h)
B, A,      rad/s, m/s^2      rad/s, deg/s, deg/h          m/s^2, ug, mg, g
bias
K          rad/s^1.5,        rad/s/sqrt(s), deg/h/sqrt(h), m/s^2/sqrt(s), m/s^2.5,
           m/s^2.5           deg/s/sqrt(s)                ug/sqrt(s), m/s/h/sqrt(h),
                                                          m/s/h^1.5
Q          rad, m/s          rad, deg, arcsec             m/s, mm/s
R          rad/s^2, m/s^3    rad/s^2, deg/h^2, deg/h/h    m/s^3, ug/s, ug/h
T_B, T     s                 s, min, h                    s, min, h
f0_hz      Hz                Hz                           Hz
=========  ================  ==========================  ===========================

Each key's dimension and customary unit come from the term registry (the unit template
and ``keys`` of each entry of :data:`imu_allan.core.noise.terms.TERMS`); the tables
here show them.  Customary units used by :func:`quoted` (summaries; the files and JSON
stay SI):

* gyro: N deg/sqrt(h), B deg/h, K deg/h/sqrt(h), Q arcsec, R deg/h^2, A deg/h,
  bias deg/s.
* accel: N ug/sqrt(Hz), B ug, K ug/sqrt(s) (chosen over m/s/h^1.5 so that N, B and K
  read on the same micro-g scale; 1 ug/sqrt(s) = 9.80665e-6 m/s^2.5), Q mm/s,
  R ug/h, A ug, bias m/s^2.
* T_B, T in s; f0_hz in Hz.

Grammar of a unit: names joined by ``/`` (divides the next factor only, so
``deg/h/h`` = deg/h^2), ``*``, ``·`` or a space; powers ``^2``, ``^1.5``, ``^-1``,
``^(3/2)``, ``**2``, ``²``, ``³``; square roots ``sqrt(Hz)``, ``sqrt Hz``, ``rtHz``,
``rt(Hz)``, ``rt-hr``, ``√Hz``; parentheses.  Names (case-insensitive): rad, deg
(degree, °), arcsec, arcmin, dps (= deg/s), m, cm, g (standard gravity 9.80665
m/s^2), s (sec), min, h (hr, hour), Hz; prefixes m (milli), u / µ / μ (micro),
n (nano), case-sensitive, on rad, deg, m, g, s and Hz.
"""

from fractions import Fraction
import math
import re

from imu_allan.core.noise.terms import TERMS
from imu_allan.errors import InputError

#: Standard gravity [m/s^2] (CGPM 1901), used for g, mg and ug.
STANDARD_GRAVITY = 9.80665

# A dimension is (angle, length, time) exponents; angle is tracked separately from
# "dimensionless" so that a gyro value cannot be given in accelerometer units.
_Dim = tuple[Fraction, ...]
_ZERO = (Fraction(0), Fraction(0), Fraction(0))


def _dim(angle: float, length: float, time: float) -> _Dim:
    return (Fraction(angle), Fraction(length), Fraction(time))


_DEG = math.pi / 180.0
# Base names: factor to SI and dimension.
_NAMES = {
    'rad': (1.0, _dim(1, 0, 0)),
    'deg': (_DEG, _dim(1, 0, 0)),
    'degree': (_DEG, _dim(1, 0, 0)),
    'degrees': (_DEG, _dim(1, 0, 0)),
    '°': (_DEG, _dim(1, 0, 0)),
    'arcsec': (_DEG / 3600.0, _dim(1, 0, 0)),
    'asec': (_DEG / 3600.0, _dim(1, 0, 0)),
    'arcmin': (_DEG / 60.0, _dim(1, 0, 0)),
    'dps': (_DEG, _dim(1, 0, -1)),
    'm': (1.0, _dim(0, 1, 0)),
    'cm': (0.01, _dim(0, 1, 0)),
    'g': (STANDARD_GRAVITY, _dim(0, 1, -2)),
    's': (1.0, _dim(0, 0, 1)),
    'sec': (1.0, _dim(0, 0, 1)),
    'min': (60.0, _dim(0, 0, 1)),
    'h': (3600.0, _dim(0, 0, 1)),
    'hr': (3600.0, _dim(0, 0, 1)),
    'hour': (3600.0, _dim(0, 0, 1)),
    'hours': (3600.0, _dim(0, 0, 1)),
    'hz': (1.0, _dim(0, 0, -1)),
}
_PREFIXES = {'m': 1e-3, 'u': 1e-6, 'µ': 1e-6, 'μ': 1e-6, 'n': 1e-9}
_PREFIXABLE = ('rad', 'deg', 'm', 'g', 's', 'hz')

#: SI unit of the samples, per sensor.
SAMPLE_UNITS = {'gyro': 'rad/s', 'accel': 'm/s^2'}
# SI text of the unit templates of the registry ('u' = the sample unit) where plain
# substitution reads badly.
_SI_TEXT = {('u*s^0.5', 'gyro'): 'rad/s/sqrt(Hz)', ('u*s^0.5', 'accel'): 'm/s^2/sqrt(Hz)',
            ('u/s^0.5', 'gyro'): 'rad/s/sqrt(s)', ('u/s^0.5', 'accel'): 'm/s^2/sqrt(s)',
            ('u*s', 'gyro'): 'rad', ('u*s', 'accel'): 'm/s',
            ('u/s', 'gyro'): 'rad/s^2', ('u/s', 'accel'): 'm/s^3'}
# Keys that are no term's parameter: the constant offset.
_OTHER_KEYS = {'bias': ('u', ('deg/s', 'm/s^2'))}


def _key_table() -> dict:
    """Return {file key: (unit template, (customary gyro, customary accel))}."""
    table = dict(_OTHER_KEYS)
    for term in TERMS.values():
        for template, key in zip(term.units, term.keys):
            if key.name:
                table.setdefault(key.name, (template, key.customary))
    return table


def keys() -> tuple:
    """Return every key that carries a unit (the registry's file keys and bias)."""
    return tuple(_key_table())


def _entry(key: str):
    entry = _key_table().get(key)
    if entry is None:
        raise ValueError(f'unknown parameter key {key!r}')
    return entry


def si_unit(key: str, sensor: str) -> str:
    """Return the SI unit of a key for a sensor, e.g. 'rad/s/sqrt(Hz)' for N of a gyro."""
    sensor = sensor_of(sensor)
    template = _entry(key)[0]
    if not template.startswith('u'):
        return template
    return _SI_TEXT.get((template, sensor), SAMPLE_UNITS[sensor] + template[1:])


def customary_unit(key: str, sensor: str) -> str:
    """Return the customary unit of a key for a sensor (:func:`quoted`), e.g. 'deg/h'."""
    sensor = sensor_of(sensor)
    custom = _entry(key)[1][0 if sensor == 'gyro' else 1]
    return custom or si_unit(key, sensor)


_NUMBER = re.compile(r'\s*([+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?)\s*(.*)\s*$', re.S)
_TOKEN = re.compile(r'\s*(\*\*|√|[A-Za-zµμ°]+|\d+(?:\.\d*)?|\.\d+|[/*·^()\-+²³])')


def sensor_of(axis_or_sensor: str) -> str:
    """
    Return 'gyro' or 'accel' for an axis name ('gyro_x' ...) or a sensor name.

    Parameters
    ----------
    axis_or_sensor : str
        'gyro', 'accel' or an axis name starting with one of them.

    Returns
    -------
    str
        'gyro' or 'accel'.

    """
    for sensor in ('gyro', 'accel'):
        if axis_or_sensor.startswith(sensor):
            return sensor
    raise ValueError(f'unknown sensor {axis_or_sensor!r}: expected gyro or accel')


def expected_dim(key: str, sensor: str) -> _Dim:
    """Dimension (angle, length, time exponents) that ``key`` must have for ``sensor``."""
    return parse_unit(si_unit(key, sensor))[1]


class _Parser:
    """Recursive-descent parser of a unit expression into (factor, dimension)."""

    def __init__(self, text: str):
        self.text = text
        self.tokens = []
        pos = 0
        while pos < len(text):
            if text[pos:].strip() == '':
                break
            match = _TOKEN.match(text, pos)
            if not match:
                raise InputError(f'cannot read unit {text!r} (at {text[pos:]!r})')
            self.tokens.extend(self._split_name(match.group(1)))
            pos = match.end()
        self.i = 0

    @staticmethod
    def _split_name(tok: str) -> list[str]:
        # 'sqrtHz', 'rtHz', 'rthr' -> ['√', 'hz'] (only when the rest is a unit name).
        low = tok.lower()
        if low in ('sqrt', 'rt'):
            return ['√']
        for head in ('sqrt', 'rt'):
            if low.startswith(head) and _lookup(low[len(head):]) is not None:
                return ['√', low[len(head):]]
        return [tok]

    def peek(self) -> str | None:
        return self.tokens[self.i] if self.i < len(self.tokens) else None

    def take(self) -> str:
        tok = self.peek()
        if tok is None:
            raise InputError(f'unit {self.text!r} ends unexpectedly')
        self.i += 1
        return tok

    def parse(self) -> tuple[float, _Dim]:
        if not self.tokens:
            return 1.0, _ZERO
        value = self.product()
        if self.peek() is not None:
            raise InputError(f'cannot read unit {self.text!r} (unexpected {self.peek()!r})')
        return value

    def product(self) -> tuple[float, _Dim]:
        factor, dim = self.power()
        while self.peek() not in (None, ')'):
            op = self.peek()
            if op in ('/', '*', '·'):
                self.take()
            sign = -1 if op == '/' else 1
            f2, d2 = self.power()
            factor *= f2 ** sign
            dim = tuple(a + sign * b for a, b in zip(dim, d2))
        return factor, dim

    def power(self) -> tuple[float, _Dim]:
        factor, dim = self.atom()
        tok = self.peek()
        exponent = None
        if tok in ('^', '**'):
            self.take()
            exponent = self.exponent()
        elif tok in ('²', '³'):
            self.take()
            exponent = Fraction(2 if tok == '²' else 3)
        if exponent is None:
            return factor, dim
        return factor ** float(exponent), tuple(exponent * d for d in dim)

    def exponent(self) -> Fraction:
        paren = self.peek() == '('
        if paren:
            self.take()
        sign = 1
        if self.peek() in ('-', '+'):
            sign = -1 if self.take() == '-' else 1
        num = self._number()
        if paren and self.peek() == '/':
            self.take()
            num = num / self._number()
        if paren and self.take() != ')':
            raise InputError(f'unit {self.text!r}: missing ")" in an exponent')
        return sign * num

    def _number(self) -> Fraction:
        tok = self.take()
        try:
            return Fraction(tok)
        except ValueError:
            raise InputError(f'unit {self.text!r}: expected a number, got {tok!r}') from None

    def atom(self) -> tuple[float, _Dim]:
        tok = self.take()
        if tok == '(':
            value = self.product()
            if self.take() != ')':
                raise InputError(f'unit {self.text!r}: missing ")"')
            return value
        if tok == '√':
            if self.peek() == '-':  # 'rt-hr', 'sqrt-Hz'
                self.take()
            factor, dim = self.atom()
            return math.sqrt(factor), tuple(d / 2 for d in dim)
        found = _lookup(tok)
        if found is None:
            raise InputError(f'unknown unit {tok!r} in {self.text!r}')
        return found


def _lookup(name: str) -> tuple[float, _Dim] | None:
    """Factor and dimension of a (possibly prefixed) unit name, or None."""
    low = name.lower()
    if low in _NAMES:
        return _NAMES[low]
    # Prefixes are case-sensitive: 'MHz' must not read as milli-hertz.
    if len(name) > 1 and name[0] in _PREFIXES and name[1:].lower() in _PREFIXABLE:
        factor, dim = _NAMES[name[1:].lower()]
        return _PREFIXES[name[0]] * factor, dim
    return None


def parse_unit(unit: str) -> tuple[float, _Dim]:
    """
    Parse a unit expression.

    Parameters
    ----------
    unit : str
        E.g. 'deg/s/sqrt(Hz)' ('' is the dimensionless unit 1).

    Returns
    -------
    factor : float
        SI value of one of this unit.
    dim : tuple of Fraction
        Exponents of (angle, length, time).

    """
    return _Parser(unit).parse()


def _dim_text(dim: _Dim) -> str:
    parts = []
    for name, e in zip(('rad', 'm', 's'), dim):
        if e:
            parts.append(name if e == 1 else f'{name}^{float(e):g}')
    return '*'.join(parts) or '1'


def to_si(value, key: str, sensor: str) -> float:
    """
    Convert a parameter value to SI, checking its unit's dimension.

    Parameters
    ----------
    value : float, int or str
        A number (already SI) or a string 'number [unit]', e.g. '10 deg/h'.
    key : str
        Parameter key: N, B, K, Q, R, A, bias, T_B, T or f0_hz.
    sensor : str
        'gyro', 'accel' or an axis name.

    Returns
    -------
    float
        The value in SI units of that key (see the module table).

    Raises
    ------
    InputError
        Non-numeric text, an unknown unit, or a unit of the wrong dimension.

    """
    sensor = sensor_of(sensor)
    want = expected_dim(key, sensor)
    if isinstance(value, bool):
        raise InputError(f'expected a number, got {value!r}')
    if isinstance(value, (int, float)):
        return float(value)
    if not isinstance(value, str):
        raise InputError(f'expected a number or a string with a unit, got {value!r}')
    match = _NUMBER.match(value)
    if not match:
        raise InputError(f'expected a number with an optional unit, got {value!r}')
    number, unit = float(match.group(1)), match.group(2).strip()
    if not unit:  # a bare number in a string (YAML reads '1e-4' as text): SI
        return number
    factor, dim = parse_unit(unit)
    if dim != want:
        examples = dict.fromkeys((si_unit(key, sensor), customary_unit(key, sensor)))
        article = 'an' if sensor == 'accel' else 'a'
        raise InputError(
            f'unit {unit!r} is {_dim_text(dim)}, but {key} of {article} {sensor} needs '
            f'{_dim_text(want)}, e.g. {" or ".join(examples)}')
    return number * factor


def quoted(key: str, sensor: str, value_si: float) -> tuple[float, str]:
    """
    Express an SI value in the customary unit of its key (module docstring).

    Parameters
    ----------
    key : str
        Parameter key: N, B, K, Q, R, A, bias, T_B, T or f0_hz.
    sensor : str
        'gyro', 'accel' or an axis name.
    value_si : float
        Value in SI units.

    Returns
    -------
    value : float
        Value in the customary unit.
    unit : str
        The customary unit, e.g. 'deg/sqrt(h)'.

    """
    unit = customary_unit(key, sensor)
    factor, _ = parse_unit(unit)
    return value_si / factor, unit


def format_quoted(key: str, sensor: str, value_si: float, digits: int = 4) -> str:
    """Return e.g. '0.42 deg/sqrt(h)' for a summary line (``digits`` significant)."""
    value, unit = quoted(key, sensor, value_si)
    return f'{value:.{digits}g} {unit}'
