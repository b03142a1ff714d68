"""
Noise parameters of one IMU axis, shared by the model, the fit and the simulator.

Every value is in SI units of the axis' samples (``unit`` = rad/s for a gyro,
m/s^2 for an accelerometer).  B follows the paper's convention (Maia et al. eq. 8):
B is the bias instability read off the Allan deviation floor, ADEV_min = 0.664 B
for flicker noise, and for a first-order Gauss-Markov term with correlation time T
the driving PSD is S_B = 2 B^2 ln2 / (pi 0.4365^2 T), which puts the Gauss-Markov
ADEV peak (0.4365 sqrt(S_B T) at tau = 1.89 T) on the same floor 0.664 B.

Parameter files (YAML) are read by :func:`load_params` / :func:`parse_params` and
written by :func:`dump_params` / :func:`save_params`::

    name: Example IMU            # optional
    axes:
      gyro:   {N: 0.007 deg/s/sqrt(Hz), B: 10 deg/h, T_B: 80.0, K: 2.0e-6}
      accel:  {N: 60 ug/sqrt(Hz), B: 30 ug, T_B: 60.0}
      accel_z: {bias: 9.80665}
      gyro_z: {sinusoid: [{A: 1e-4, f0_hz: 0.011}], gauss_markov: [{B: 1e-4, T: 5.0}]}

``gyro`` and ``accel`` set all three axes of that sensor; an entry for one axis
overrides the group's keys one by one (a per-axis ``gauss_markov`` or ``sinusoid``
list replaces the group's list).  Values are SI numbers or strings with a unit
(``imu_allan.core.noise.units``).  N, B, K, Q, T_B, A, T and f0_hz must be finite and >= 0
(T_B, T and f0_hz > 0); R and bias may be negative.  T_B absent or null makes B
flicker noise.
"""

from dataclasses import dataclass, field
import math
from pathlib import Path

from imu_allan import AXES
from imu_allan.core.noise.units import quoted, sensor_of, to_si
from imu_allan.errors import InputError

#: 0.4365: peak of the Gauss-Markov ADEV in units of q sqrt(T) (IEEE Std 952 C.1).
GM_PEAK_FACTOR = 0.4365
#: 0.664 = sqrt(2 ln2 / pi): flicker ADEV floor per unit of B (IEEE Std 952 C.1).
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


@dataclass(frozen=True)
class GaussMarkov:
    """
    A first-order Gauss-Markov term.

    Attributes
    ----------
    B : float
        Bias-instability level [unit] (paper convention, see module docstring).
    T : float
        Correlation time [s].

    """

    B: float
    T: float

    @property
    def psd(self) -> float:
        """Driving white-noise PSD S_B [unit^2/s] (paper eq. 8)."""
        return 2.0 * self.B ** 2 * math.log(2.0) / (math.pi * GM_PEAK_FACTOR ** 2 * self.T)

    @property
    def q(self) -> float:
        """Driving noise density q = sqrt(S_B) [unit/s^0.5]."""
        return math.sqrt(self.psd)

    @property
    def sigma(self) -> float:
        """Stationary standard deviation sqrt(S_B T / 2) [unit]."""
        return math.sqrt(self.psd * self.T / 2.0)

    @classmethod
    def from_psd(cls, psd: float, T: float) -> 'GaussMarkov':
        """Build from the driving PSD q^2 [unit^2/s] and correlation time T [s]."""
        return cls(B=math.sqrt(psd * math.pi * GM_PEAK_FACTOR ** 2 * T / (2.0 * math.log(2.0))),
                   T=T)


@dataclass(frozen=True)
class Sinusoid:
    """
    A sinusoidal error A sin(2 pi f0 t + phase).

    Attributes
    ----------
    A : float
        Amplitude [unit].
    f0_hz : float
        Frequency [Hz].

    """

    A: float
    f0_hz: float


@dataclass(frozen=True)
class AxisNoise:
    """
    Stochastic error model of one axis; a term set to 0 (or None) is absent.

    Attributes
    ----------
    N : float
        White noise density (angle / velocity random walk) [unit*s^0.5].
    B : float
        Bias instability [unit]: a Gauss-Markov term with ``T_B`` when T_B is set
        (the paper's model), otherwise flicker (1/f) noise.
    T_B : float or None
        Correlation time of the bias-instability Gauss-Markov term [s].
    K : float
        Rate random walk [unit/s^0.5].
    Q : float
        Quantization noise [unit*s] (AVAR 3 Q^2 / tau^2).
    R : float
        Rate ramp [unit/s] (AVAR R^2 tau^2 / 2).
    gauss_markov : tuple of GaussMarkov
        Further Gauss-Markov terms.
    sinusoids : tuple of Sinusoid
        Sinusoidal errors.
    bias : float
        Constant offset [unit], e.g. 9.80665 on an upward accelerometer axis.

    """

    N: float = 0.0
    B: float = 0.0
    T_B: float | None = None
    K: float = 0.0
    Q: float = 0.0
    R: float = 0.0
    gauss_markov: tuple[GaussMarkov, ...] = field(default_factory=tuple)
    sinusoids: tuple[Sinusoid, ...] = field(default_factory=tuple)
    bias: float = 0.0

    def all_gauss_markov(self) -> tuple[GaussMarkov, ...]:
        """Every Gauss-Markov term: the bias-instability one (if T_B is set) first."""
        head = (GaussMarkov(self.B, self.T_B),) if self.B > 0 and self.T_B else ()
        return head + tuple(self.gauss_markov)

    @property
    def has_flicker(self) -> bool:
        """Return True when B is modelled as flicker (1/f) noise, i.e. T_B is not set."""
        return self.B > 0 and not self.T_B


@dataclass(frozen=True)
class NoiseSpec:
    """
    Noise model of a whole six-axis IMU.

    Attributes
    ----------
    name : str
        Free-text name of the IMU ('' when not given).
    axes : dict of str to AxisNoise
        One entry per name in ``imu_allan.AXES`` (absent axes are ``AxisNoise()``).

    """

    name: str
    axes: dict[str, AxisNoise]


#: Scalar keys of an axis entry, in file order.
SCALAR_KEYS = ('N', 'B', 'T_B', 'K', 'Q', 'R', 'bias')
#: List keys of an axis entry and the keys of their items.
LIST_KEYS = {'gauss_markov': ('B', 'T'), 'sinusoid': ('A', 'f0_hz')}
_GROUPS = {'gyro': AXES[:3], 'accel': AXES[3:]}
_MAY_BE_NEGATIVE = ('R', 'bias')
_MUST_BE_POSITIVE = ('T_B', 'T', 'f0_hz')


def _value(raw, key: str, sensor: str, where: str) -> float:
    """Convert and validate one value; errors name ``where`` (file, axis, key)."""
    try:
        value = to_si(raw, key, sensor)
    except InputError as exc:
        raise InputError(f'{where}: {exc}') from None
    if not math.isfinite(value):
        raise InputError(f'{where}: must be finite, got {raw!r}')
    if key in _MUST_BE_POSITIVE and value <= 0:
        raise InputError(f'{where}: must be > 0, got {raw!r}')
    if key not in _MAY_BE_NEGATIVE and value < 0:
        raise InputError(f'{where}: must be >= 0, got {raw!r}')
    return value


def _entry(raw, entry: str, sensor: str, prefix: str) -> dict:
    """Parse one ``axes.<entry>`` mapping into SI values (only the keys present)."""
    here = f'{prefix}axes.{entry}'
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise InputError(f'{here}: expected a mapping of terms, got {type(raw).__name__}')
    out: dict[str, object] = {}
    for key, val in raw.items():
        where = f'{here}.{key}'
        if key in ('sinusoids',):  # the AxisNoise field name, accepted as an alias
            key = 'sinusoid'
        if key in SCALAR_KEYS:
            if key == 'T_B' and val is None:
                out[key] = None
            else:
                out[key] = _value(val, key, sensor, where)
        elif key in LIST_KEYS:
            out[key] = _items(val, key, sensor, where)
        else:
            raise InputError(f'{where}: unknown key (expected one of '
                             f'{", ".join(SCALAR_KEYS + tuple(LIST_KEYS))})')
    return out


def _items(raw, key: str, sensor: str, where: str) -> tuple:
    """Parse a ``gauss_markov`` or ``sinusoid`` list."""
    if raw is None:
        return ()
    if isinstance(raw, dict):
        raw = [raw]
    if not isinstance(raw, list):
        raise InputError(f'{where}: expected a list of mappings, got {type(raw).__name__}')
    names = LIST_KEYS[key]
    items = []
    for i, item in enumerate(raw):
        at = f'{where}[{i}]'
        if not isinstance(item, dict):
            raise InputError(f'{at}: expected a mapping with keys {", ".join(names)}')
        unknown = [k for k in item if k not in names]
        if unknown:
            raise InputError(f'{at}.{unknown[0]}: unknown key (expected {", ".join(names)})')
        missing = [k for k in names if k not in item]
        if missing:
            raise InputError(f'{at}: missing key {missing[0]}')
        a, b = (_value(item[k], k, sensor, f'{at}.{k}') for k in names)
        items.append(GaussMarkov(B=a, T=b) if key == 'gauss_markov' else Sinusoid(A=a, f0_hz=b))
    return tuple(items)


def _axis_noise(terms: dict) -> AxisNoise:
    kwargs = {k: terms[k] for k in SCALAR_KEYS if k in terms}
    if 'gauss_markov' in terms:
        kwargs['gauss_markov'] = terms['gauss_markov']
    if 'sinusoid' in terms:
        kwargs['sinusoids'] = terms['sinusoid']
    return AxisNoise(**kwargs)


def parse_params(mapping, source: str = '') -> NoiseSpec:
    """
    Build a :class:`NoiseSpec` from a parsed parameter file (module docstring).

    Parameters
    ----------
    mapping : dict
        The file's content, e.g. from ``yaml.safe_load``.
    source : str
        File name used in error messages ('' for none).

    Returns
    -------
    NoiseSpec
        All six axes in SI; axes not mentioned get ``AxisNoise()``.

    Raises
    ------
    InputError
        One line naming the file, the entry (``axes.<axis or group>.<key>``) and the
        problem: unknown or missing keys, negative or non-finite values, T_B <= 0,
        f0_hz <= 0, units of the wrong dimension, non-numeric text.

    """
    prefix = f'{source}: ' if source else ''
    if not isinstance(mapping, dict):
        raise InputError(f'{prefix}expected a mapping with keys name, axes')
    unknown = [k for k in mapping if k not in ('name', 'axes')]
    if unknown:
        raise InputError(f'{prefix}{unknown[0]}: unknown key (expected name, axes)')
    if 'axes' not in mapping:
        raise InputError(f'{prefix}missing key axes (noise terms per axis or per sensor)')
    name = mapping.get('name') or ''
    if not isinstance(name, str):
        raise InputError(f'{prefix}name: expected text, got {name!r}')
    axes_raw = mapping['axes']
    if axes_raw is None:
        axes_raw = {}
    if not isinstance(axes_raw, dict):
        raise InputError(f'{prefix}axes: expected a mapping of axis or sensor names')
    for entry in axes_raw:
        if entry not in _GROUPS and entry not in AXES:
            raise InputError(f'{prefix}axes.{entry}: unknown axis (expected gyro, accel or '
                             f'one of {", ".join(AXES)})')
    terms: dict[str, dict] = {axis: {} for axis in AXES}
    for group, members in _GROUPS.items():  # groups first, then per-axis overrides
        if group in axes_raw:
            parsed = _entry(axes_raw[group], group, group, prefix)
            for axis in members:
                terms[axis].update(parsed)
    for axis in AXES:
        if axis in axes_raw:
            terms[axis].update(_entry(axes_raw[axis], axis, sensor_of(axis), prefix))
    return NoiseSpec(name=name, axes={axis: _axis_noise(terms[axis]) for axis in AXES})


def load_params(path) -> NoiseSpec:
    """
    Read a parameter YAML file.

    Parameters
    ----------
    path : str or os.PathLike
        File to read.

    Returns
    -------
    NoiseSpec
        The parsed, validated model in SI.

    Raises
    ------
    InputError
        Unreadable file, invalid YAML or invalid content (one line).

    """
    import yaml  # allowed in noise_params; imported here so the module stays light

    path = Path(path)
    try:
        text = path.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f'cannot read params file {path}: '
                         f'{getattr(exc, "strerror", None) or exc}') from None
    try:
        mapping = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        line = f' (line {mark.line + 1})' if mark is not None else ''
        problem = getattr(exc, 'problem', None) or 'invalid YAML'
        raise InputError(f'{path}: invalid YAML{line}: {problem}') from None
    if mapping is None:
        raise InputError(f'{path}: file is empty (expected keys name, axes)')
    return parse_params(mapping, source=str(path))


def _terms(noise: AxisNoise, sensor: str, with_units: bool) -> dict:
    """SI (or quoted-unit) mapping of the terms of one axis that are present."""
    def fmt(key, value):
        if not with_units:
            return float(value)
        v, unit = quoted(key, sensor, value)
        return f'{v:.6g} {unit}'

    out = {}
    for key in SCALAR_KEYS:
        value = getattr(noise, key)
        if value is not None and value != 0.0:
            out[key] = fmt(key, value)
    if noise.gauss_markov:
        out['gauss_markov'] = [{'B': fmt('B', g.B), 'T': fmt('T', g.T)}
                               for g in noise.gauss_markov]
    if noise.sinusoids:
        out['sinusoid'] = [{'A': fmt('A', s.A), 'f0_hz': fmt('f0_hz', s.f0_hz)}
                           for s in noise.sinusoids]
    return out


def dump_params(spec: NoiseSpec, with_units: bool = False) -> dict:
    """
    Express a :class:`NoiseSpec` as a parameter-file mapping (inverse of parse_params).

    Three identical axes of a sensor are written once as its group (``gyro`` /
    ``accel``); zero terms are left out.

    Parameters
    ----------
    spec : NoiseSpec
        The model.
    with_units : bool
        False: plain SI floats (exact round trip).  True: strings in the customary
        units of ``imu_allan.core.noise.units.quoted`` with 6 significant digits
        (e.g. '0.41253 deg/sqrt(h)'), for people; they round-trip to 5e-6 relative.

    Returns
    -------
    dict
        ``{'name': ..., 'axes': {...}}``, ready for ``yaml.safe_dump``.

    """
    axes = {}
    for group, members in _GROUPS.items():
        per_axis = [_terms(spec.axes.get(a, AxisNoise()), group, with_units) for a in members]
        # Terms equal on all three axes go to the group entry, the rest per axis.
        common = {k: v for k, v in per_axis[0].items()
                  if all(k in t and t[k] == v for t in per_axis[1:])}
        if common:
            axes[group] = common
        for axis, terms in zip(members, per_axis):
            rest = {k: v for k, v in terms.items() if k not in common}
            if rest:
                axes[axis] = rest
    out: dict[str, object] = {'name': spec.name} if spec.name else {}
    out['axes'] = axes
    return out


def save_params(spec: NoiseSpec, path, with_units: bool = False, header: str = '') -> None:
    """
    Write a :class:`NoiseSpec` as a parameter YAML file.

    Parameters
    ----------
    spec : NoiseSpec
        The model.
    path : str or os.PathLike
        Output file.
    with_units : bool
        See :func:`dump_params`.
    header : str
        Optional comment text, written as '# ' lines at the top.

    """
    import yaml

    lines = ''.join(f'# {line}\n'.replace('# \n', '#\n') for line in header.splitlines())
    body = yaml.safe_dump(dump_params(spec, with_units), sort_keys=False,
                          default_flow_style=None, allow_unicode=True, width=99)
    Path(path).write_text(lines + body, encoding='utf-8')
