"""
Parameter files of a noise model (the values themselves: :mod:`.values`, re-exported).

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

The keys come from the term registry (each term's ``keys``, ``list_key`` and
``signed``, :mod:`imu_allan.core.noise.terms`): a term held in its own AxisNoise fields
has scalar keys, a term that may repeat (and every term added later) a list entry
named by its ``list_key`` (its name by default) whose items carry its keys.
"""

import math
from pathlib import Path

from imu_allan import AXES
from imu_allan.core.noise.terms import Term, TERMS
from imu_allan.core.noise.units import quoted, sensor_of, to_si
from imu_allan.core.noise.values import AxisNoise, NoiseSpec
from imu_allan.errors import InputError

_GROUPS = {'gyro': AXES[:3], 'accel': AXES[3:]}


def list_key(term: Term) -> str:
    """Return the list entry of a term in files ('' for a term with scalar keys)."""
    return term.list_key or (term.name if term.read is None else '')


def scalar_keys() -> tuple:
    """Return the scalar keys of an axis entry (AxisNoise fields), in file order."""
    keys = [k.name for t in TERMS.values() if not list_key(t) for k in t.keys if k.name]
    return tuple(dict.fromkeys(keys)) + ('bias',)


def list_keys() -> dict:
    """Return each list entry of an axis entry with its term: {key: Term}."""
    return {list_key(t): t for t in TERMS.values() if list_key(t)}


def _sign_rules() -> tuple:
    """Return the keys that may be negative and the keys that must be positive."""
    signed, positive = {'bias'}, set()
    for t in TERMS.values():
        for sym, key in zip(t.symbols, t.keys):
            if sym in t.signed:
                signed.add(key.name)
            if sym in t.nonlinear:
                positive.add(key.name)
    return signed, positive - {''}


def _value(raw, key: str, sensor: str, where: str) -> float:
    """Convert and validate one value; errors name ``where`` (file, axis, key)."""
    try:
        value = to_si(raw, key, sensor)
    except InputError as exc:
        raise InputError(f'{where}: {exc}') from None
    if not math.isfinite(value):
        raise InputError(f'{where}: must be finite, got {raw!r}')
    signed, positive = _sign_rules()
    if key in positive and value <= 0:
        raise InputError(f'{where}: must be > 0, got {raw!r}')
    if key not in signed and value < 0:
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
    scalars, lists = scalar_keys(), list_keys()
    for key, val in raw.items():
        where = f'{here}.{key}'
        if key in ('sinusoids',):  # the AxisNoise field name, accepted as an alias
            key = 'sinusoid'
        if key in scalars:
            if key == 'T_B' and val is None:
                out[key] = None
            else:
                out[key] = _value(val, key, sensor, where)
        elif key in lists:
            out[key] = _items(val, lists[key], sensor, where)
        else:
            raise InputError(f'{where}: unknown key (expected one of '
                             f'{", ".join(scalars + tuple(lists))})')
    return out


def _items(raw, term: Term, sensor: str, where: str) -> tuple:
    """Parse a list entry (``gauss_markov``, ``sinusoid`` ...) into value tuples."""
    if raw is None:
        return ()
    if isinstance(raw, dict):
        raw = [raw]
    if not isinstance(raw, list):
        raise InputError(f'{where}: expected a list of mappings, got {type(raw).__name__}')
    names = tuple(k.name for k in term.keys)
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
        items.append(tuple(_value(item[k], k, sensor, f'{at}.{k}') for k in names))
    return tuple(items)


def _axis_noise(terms: dict) -> AxisNoise:
    kwargs = {k: terms[k] for k in scalar_keys() if k in terms}
    kwargs.update(gauss_markov=[], sinusoids=[], extra=[])
    for key, term in list_keys().items():
        for values in terms.get(key, ()):
            term.put(kwargs, values)
    for key in ('gauss_markov', 'sinusoids', 'extra'):
        kwargs[key] = tuple(kwargs[key])
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
    for key in scalar_keys():
        value = getattr(noise, key)
        if value is not None and value != 0.0:
            out[key] = fmt(key, value)
    for key, term in list_keys().items():
        items = [{k.name: fmt(k.name, v) for k, v in zip(term.keys, values)}
                 for values in term.instances(noise)]
        if items:
            out[key] = items
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
