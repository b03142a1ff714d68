"""
The term registry: every noise term, and everything the package does with it.

:data:`TERMS` is the only place that knows the terms.  Each :class:`Term` carries its
Allan variance (``shape``, with what the fit's covariance needs), its simulator, its
parameter names and units, its name in parameter files, its effect name, its role in
the Kalman model and its search range; the fit, the search, the diagnosis, the
simulator, parameter files, quoted units and the Kalman outputs loop over it.  Adding a
term is adding an entry here plus its tests (checklist in docs/architecture.md).

Vocabulary, one name per thing (docs/architecture.md, "Noise terms"):

* **term**: an entry of :data:`TERMS`, by name; a fit numbers repeats of one term
  (``gauss_markov_2``): its *labels*.  ``bias_instability`` is the paper's
  Gauss-Markov floor (B, T_B); ``gauss_markov`` a further Gauss-Markov process (B, T);
  ``flicker`` flicker (1/f) noise of level B, which has no correlation time.
* **effect**: a term the search may add to a model; its effect name *is* its term name.
  The effect that was called ``bias_instability`` before is ``flicker``
  (:data:`EFFECT_ALIASES` accepts the old name for one release).
* **base model**: term names (default white, bias_instability, random_walk); the base
  name ``gauss_markov`` used before for the paper's floor is accepted as an alias
  (:data:`BASE_ALIASES`) for one release.
"""

from dataclasses import dataclass
import math
import re
from typing import Callable, NamedTuple

import numpy as np

from imu_allan.core.noise import generators as gen
from imu_allan.core.noise.shapes import (_as_tau, _gcov_flicker, _gcov_quantization,
                                         _gcov_random_walk, _gcov_white, _gm_shape,
                                         _PSD_PHASE, _reach_flicker, _reach_gauss_markov,
                                         _tail_gauss_markov, FLICKER_AVAR, gcov_gauss_markov,
                                         GM_PSD_FACTOR)
from imu_allan.core.noise.values import AxisNoise, GaussMarkov, Sinusoid, TermValue
from imu_allan.errors import InputError

#: Kalman roles: white measurement noise (R), the bias state b_gm (a Gauss-Markov
#: process with its correlation time), the bias state b_rw (a random walk); '' = not
#: in Q or R.
KALMAN_ROLES = ('white', 'b_gm', 'b_rw', '')


class Key(NamedTuple):
    """
    One parameter as files and summaries name it.

    Attributes
    ----------
    name : str
        Its key in parameter files ('' when files do not hold it).
    customary : tuple of str
        Customary unit for summaries (gyro, accel); ('', '') for the SI unit.

    """

    name: str
    customary: tuple = ('', '')


@dataclass(frozen=True)
class Term:
    """
    One noise term: AVAR = c * shape(tau, nonlinear...), and its place in the package.

    Attributes
    ----------
    name : str
        Registry name, e.g. 'white', 'gauss_markov'.
    symbols : tuple of str
        Symbols of the reported parameters, the linear one first (e.g. ('B', 'T')).
    nonlinear : tuple of str
        Names of the nonlinear parameters of ``shape`` (e.g. ('T',)), a suffix of
        ``symbols``.
    shape : callable
        ``shape(tau_s (k,), *nonlinear) -> (k,)``: AVAR per unit coefficient.
    gcov : callable or None
        Generalised covariance of the phase per unit coefficient,
        ``gcov(u_s, *nonlinear)`` [s^2 per unit coefficient], such that
        Cov(sum a_i X(t_i), sum b_j X(s_j)) = c sum a_i b_j gcov(t_i - s_j) for
        stencils a, b that annihilate linear functions.  None for deterministic terms
        (ramp, sinusoid), whose spread the fit neglects.
    to_params : callable
        ``to_params(c, *nonlinear) -> dict`` of the reported parameters (SI).
    to_coef : callable
        Inverse of ``to_params`` for the linear parameter:
        ``to_coef(value, *nonlinear) -> c``.
    units : tuple of str
        Unit of each symbol with 'u' for the sample unit (rad/s or m/s^2).
    keys : tuple of Key
        Each symbol in parameter files and summaries (name, customary units).
    simulate : callable
        ``simulate(params, rate_hz, n_samples, rng) -> (n_samples,)`` samples [unit]
        of one instance, ``params`` the dict of ``to_params``.
    title : str
        What the term is, for summaries ('white noise').
    noun : str
        Its short name in a user's words ('sinusoid', 'extra Gauss-Markov'), which
        :func:`imu_allan.core.noise.words.spoken` puts where the label would be.
    plain : bool
        The fit reports its symbols without the '<term>.' prefix (N, B, T_B, K ...).
    state_space : bool
        Part of the paper's discrete state-space model (eqs. 14-23: white measurement
        noise, Gauss-Markov and random-walk states), through which the diagnosis
        simulates a fit (:func:`imu_allan.core.noise.simulate.simulate_state_space`).
    kalman : str
        Role in the Kalman model (:data:`KALMAN_ROLES`): 'white' adds c to the white
        PSD S_N, 'b_gm' is the Gauss-Markov bias state (its c is S_B, its nonlinear
        parameter T_B), 'b_rw' adds c to the random-walk PSD S_K, '' is not in Q or R.
    effect : bool
        The term is an effect: the search and the diagnosis may add it.
    search_rank : int or None
        Position in the search's default try order (ties keep the first); None: the
        search tries it only when asked.
    repeats : int
        Instances of it the search may add (numbered labels beyond the first).
    exclusive : tuple of str
        Terms it cannot join (one model has white or filtered_white).
    list_key : str
        For terms that may occur several times in one axis: their list entry in
        parameter files (items keyed by ``keys``); '' for scalar keys.
    read : callable or None
        ``read(noise) -> list of tuple``: each instance's parameter values (symbol order)
        in an AxisNoise; None: its instances in ``AxisNoise.extra``.
    write : callable or None
        ``write(kw, values)``: put one instance into AxisNoise keyword arguments
        (``kw`` has the lists 'gauss_markov', 'sinusoids', 'extra'); None: into extra.
    bounds : callable or None
        ``bounds(tau_s, rate_hz) -> tuple of (lo, hi)``: the search range of each
        nonlinear parameter over a fit's averaging times (None when there is none).
    signed : tuple of str
        Symbols that may be negative (a ramp's slope).
    describe : callable or None
        ``describe(params, units) -> str`` for a summary line (None: the title with
        every symbol, value and unit).
    discrete : bool
        True when ``gcov`` is a Kronecker delta (lags are integers, no integration).
    reach : callable or None
        ``reach(m1, m2, dt, *nonlinear) -> lags``: how far beyond the outermost
        stencil kink the second-difference covariance of two cluster sizes is non-zero;
        None for polynomial covariances, which vanish there exactly.
    tail : callable or None
        ``tail(d, m1, m2, dt, *nonlinear)``: that covariance d >= 0 lags beyond the
        outermost kink in closed form (None: evaluate ``gcov`` directly).
    psd_phase : callable or None
        ``psd_phase(f_hz, dt, *nonlinear)``: two-sided PSD of the phase per unit
        coefficient [s^3 per unit coefficient], S_y(f) / (2 pi f)^2; used for the
        spread a sinusoid adds by beating with the noise.  None for deterministic terms.

    """

    name: str
    symbols: tuple[str, ...]
    nonlinear: tuple[str, ...]
    shape: Callable[..., np.ndarray]
    gcov: Callable[..., np.ndarray] | None
    to_params: Callable[..., dict]
    to_coef: Callable[..., float]
    units: tuple[str, ...]
    keys: tuple[Key, ...] = ()
    simulate: Callable[..., np.ndarray] | None = None
    title: str = ''
    noun: str = ''
    plain: bool = False
    state_space: bool = False
    kalman: str = ''
    effect: bool = False
    search_rank: int | None = None
    repeats: int = 1
    exclusive: tuple[str, ...] = ()
    list_key: str = ''
    read: Callable[..., list] | None = None
    write: Callable[..., None] | None = None
    bounds: Callable[..., tuple] | None = None
    signed: tuple[str, ...] = ()
    describe: Callable[..., str] | None = None
    discrete: bool = False
    reach: Callable[..., np.ndarray] | None = None
    tail: Callable[..., np.ndarray] | None = None
    psd_phase: Callable[..., float] | None = None

    def samples(self, params: dict, rate_hz: float, n_samples: int,
                rng: np.random.Generator) -> np.ndarray:
        """Return (n_samples,) samples [unit] of one instance (``simulate``)."""
        if self.simulate is None:
            raise InputError(f'the term {self.name} has no simulator')
        return self.simulate(params, rate_hz, n_samples, rng)

    def instances(self, noise: AxisNoise) -> list:
        """Return each instance's parameter values (symbol order) held by ``noise``."""
        if self.read is not None:
            return self.read(noise)
        return [v.values for v in noise.extra if v.term == self.name]

    def put(self, kw: dict, values: tuple) -> None:
        """Put one instance (values in symbol order) into AxisNoise keyword arguments."""
        if self.write is not None:
            self.write(kw, tuple(values))
        else:
            kw['extra'].append(TermValue(self.name, tuple(float(v) for v in values)))

    def summary(self, params: dict, units: dict) -> str:
        """Return the summary text of one instance, e.g. 'white noise (N 1e-3 rad/s*s^0.5)'."""
        if self.describe is not None:
            return self.describe(params, units)
        shown = ', '.join(f'{s} {params[s]:.2g} {units[s]}' for s in self.symbols)
        return f'{self.title} ({shown})'


def _gm_b(c: float, T: float) -> float:
    """Level B [unit] of a Gauss-Markov term with driving PSD c and time T (eq. 8)."""
    return math.sqrt(max(c, 0.0) * T / GM_PSD_FACTOR)


def _sqrt(c: float) -> float:
    return math.sqrt(max(c, 0.0))


def _ramp(p: dict, rate_hz: float, n: int) -> np.ndarray:
    return gen.rate_ramp(p['R'], np.arange(n) / float(rate_hz))


def _gm_range(tau: np.ndarray, rate_hz: float) -> tuple:
    # The bump (at 1.89 T) must fall inside the record: a shorter T is white noise to
    # the curve, a longer one random walk.
    return ((2.0 * tau.min(), tau.max()),)


def _scalar(*fields: str) -> tuple:
    """read/write of a term held in scalar AxisNoise fields (present when the first is)."""
    def read(noise: AxisNoise) -> list:
        values = tuple(getattr(noise, f) for f in fields)
        return [values] if values[0] else []

    def write(kw: dict, values: tuple) -> None:
        kw.update(zip(fields, values))
    return read, write


def _read_flicker(noise: AxisNoise) -> list:
    return [(noise.B,)] if noise.B > 0 and not noise.T_B else []


def _write_flicker(kw: dict, values: tuple) -> None:
    # AxisNoise has one B: with a Gauss-Markov floor already there, flicker takes B and
    # the Gauss-Markov process joins the further ones.
    if not values[0] > 0:
        return
    if kw.get('T_B'):
        kw['gauss_markov'].insert(0, GaussMarkov(kw['B'], kw.pop('T_B')))
    kw['B'] = values[0]


def _read_floor(noise: AxisNoise) -> list:
    return [(noise.B, noise.T_B)] if noise.B > 0 and noise.T_B else []


def _write_floor(kw: dict, values: tuple) -> None:
    if not values[0] > 0:      # T_B is kept only with a positive level
        return
    if kw.get('B') and not kw.get('T_B'):     # flicker holds B (see _write_flicker)
        kw['gauss_markov'].insert(0, GaussMarkov(*values))
    else:
        kw['B'], kw['T_B'] = values


_GYRO_ACCEL = {'N': ('deg/sqrt(h)', 'ug/sqrt(Hz)'), 'B': ('deg/h', 'ug'),
               'K': ('deg/h/sqrt(h)', 'ug/sqrt(s)'), 'Q': ('arcsec', 'mm/s'),
               'R': ('deg/h^2', 'ug/h'), 'A': ('deg/h', 'ug')}


def _key(name: str) -> Key:
    return Key(name, _GYRO_ACCEL.get(name, ('', '')))


#: Every term, by name.  Adding a term is adding an entry here (docs/architecture.md).
#: The order (IEEE Std 952's, by slope) is that of the simulator's random draws, of the
#: diagnosis' effects and of the docs' table.
TERMS: dict[str, Term] = {
    'quantization': Term(
        'quantization', ('Q',), (), lambda tau: 3.0 / _as_tau(tau) ** 2,
        _gcov_quantization, lambda c: {'Q': _sqrt(c)}, lambda v: v * v, ('u*s',),
        keys=(_key('Q'),),
        simulate=lambda p, f, n, rng: gen.quantization_noise(p['Q'], f, n, rng),
        title='quantization', noun='quantization', plain=True, effect=True, search_rank=3,
        read=_scalar('Q')[0], write=_scalar('Q')[1], discrete=True,
        psd_phase=_PSD_PHASE['quantization']),
    'white': Term(
        'white', ('N',), (), lambda tau: 1.0 / _as_tau(tau), _gcov_white,
        lambda c: {'N': _sqrt(c)}, lambda v: v * v, ('u*s^0.5',), keys=(_key('N'),),
        simulate=lambda p, f, n, rng: gen.white_noise(p['N'], f, n, rng),
        title='white noise', noun='white noise',
        plain=True, state_space=True, kalman='white', effect=True,
        exclusive=('filtered_white',), read=_scalar('N')[0], write=_scalar('N')[1],
        psd_phase=_PSD_PHASE['white']),
    # White noise seen through the sensor's own low-pass filter (anti-aliasing,
    # decimation): first-order filtered white noise is a Gauss-Markov process of time
    # constant T_f, so its AVAR is the Gauss-Markov shape scaled to N^2, white noise of
    # density N for tau >> T_f.  T_f is a nuisance parameter of at most a few sample
    # periods; N is the density a Kalman filter running at the output rate sees.
    'filtered_white': Term(
        'filtered_white', ('N', 'T_f'), ('T_f',),
        lambda tau, T: _gm_shape(_as_tau(tau) / T) / T,
        lambda u, T: gcov_gauss_markov(u, T) / (T * T),
        lambda c, T: {'N': _sqrt(c), 'T_f': T}, lambda v, T: v * v, ('u*s^0.5', 's'),
        keys=(_key('N'), Key('')),
        simulate=lambda p, f, n, rng: gen.filtered_white_noise(p['N'], p['T_f'], f, n, rng),
        title="white noise through the sensor's filter", noun='filtered white noise',
        plain=True, kalman='white',
        exclusive=('white',), read=lambda noise: [], write=lambda kw, v: kw.update(N=v[0]),
        bounds=lambda tau, rate_hz: ((0.01 / rate_hz, 4.0 / rate_hz),),
        reach=_reach_gauss_markov,
        tail=lambda d, m1, m2, dt, T: _tail_gauss_markov(d, m1, m2, dt, T) / (T * T),
        psd_phase=lambda f, dt, T: _PSD_PHASE['gauss_markov'](f, dt, T) / (T * T)),
    'flicker': Term(
        'flicker', ('B',), (), lambda tau: np.full(_as_tau(tau).shape, FLICKER_AVAR),
        _gcov_flicker, lambda c: {'B': _sqrt(c)}, lambda v: v * v, ('u',),
        keys=(_key('B'),), simulate=lambda p, f, n, rng: gen.flicker_noise(p['B'], f, n, rng),
        title='flicker bias instability', noun='flicker noise',
        plain=True, effect=True, search_rank=2,
        read=_read_flicker, write=_write_flicker, reach=_reach_flicker,
        psd_phase=_PSD_PHASE['flicker']),
    # The paper's Gauss-Markov floor (Maia et al. eq. 8): level B, correlation time T_B.
    'bias_instability': Term(
        'bias_instability', ('B', 'T_B'), ('T_B',),
        lambda tau, T: T * _gm_shape(_as_tau(tau) / T), gcov_gauss_markov,
        lambda c, T: {'B': _gm_b(c, T), 'T_B': T}, lambda v, T: GM_PSD_FACTOR * v * v / T,
        ('u', 's'), keys=(_key('B'), Key('T_B')),
        simulate=lambda p, f, n, rng: gen.gauss_markov_noise(
            GaussMarkov(p['B'], p['T_B']), f, n, rng),
        title='Gauss-Markov bias instability', noun='bias instability',
        plain=True, state_space=True, kalman='b_gm',
        read=_read_floor, write=_write_floor, bounds=_gm_range, reach=_reach_gauss_markov,
        tail=_tail_gauss_markov, psd_phase=_PSD_PHASE['gauss_markov']),
    'gauss_markov': Term(
        'gauss_markov', ('B', 'T'), ('T',), lambda tau, T: T * _gm_shape(_as_tau(tau) / T),
        gcov_gauss_markov, lambda c, T: {'B': _gm_b(c, T), 'T': T},
        lambda v, T: GM_PSD_FACTOR * v * v / T, ('u', 's'), keys=(_key('B'), Key('T')),
        simulate=lambda p, f, n, rng: gen.gauss_markov_noise(
            GaussMarkov(p['B'], p['T']), f, n, rng),
        title='a further Gauss-Markov process', noun='extra Gauss-Markov',
        state_space=True, effect=True, search_rank=1,
        repeats=2, list_key='gauss_markov',
        read=lambda noise: [(g.B, g.T) for g in noise.gauss_markov if g.B],
        write=lambda kw, v: kw['gauss_markov'].append(GaussMarkov(*v)),
        bounds=_gm_range, reach=_reach_gauss_markov, tail=_tail_gauss_markov,
        psd_phase=_PSD_PHASE['gauss_markov']),
    'random_walk': Term(
        'random_walk', ('K',), (), lambda tau: _as_tau(tau) / 3.0, _gcov_random_walk,
        lambda c: {'K': _sqrt(c)}, lambda v: v * v, ('u/s^0.5',), keys=(_key('K'),),
        simulate=lambda p, f, n, rng: gen.random_walk_noise(p['K'], f, n, rng),
        title='rate random walk', noun='random walk',
        plain=True, state_space=True, kalman='b_rw', effect=True,
        read=_scalar('K')[0], write=_scalar('K')[1], psd_phase=_PSD_PHASE['random_walk']),
    'rate_ramp': Term(
        'rate_ramp', ('R',), (), lambda tau: _as_tau(tau) ** 2 / 2.0, None,
        lambda c: {'R': _sqrt(c)}, lambda v: v * v, ('u/s',), keys=(_key('R'),),
        simulate=lambda p, f, n, rng: _ramp(p, f, n), title='rate ramp', noun='rate ramp',
        plain=True,
        effect=True, search_rank=4, read=_scalar('R')[0], write=_scalar('R')[1],
        signed=('R',)),
    'sinusoid': Term(
        'sinusoid', ('A', 'f0_hz'), ('f0_hz',),
        lambda tau, f0: (np.sin(math.pi * f0 * _as_tau(tau)) ** 2
                         / (math.pi * f0 * _as_tau(tau))) ** 2,
        None, lambda c, f0: {'A': _sqrt(c), 'f0_hz': f0}, lambda v, f0: v * v, ('u', 'Hz'),
        keys=(_key('A'), Key('f0_hz')),
        simulate=lambda p, f, n, rng: gen.sinusoid(p['A'], p['f0_hz'], np.arange(n) / float(f),
                                                   rng),
        title='sinusoid', noun='sinusoid',
        effect=True, search_rank=0, repeats=2, list_key='sinusoid',
        read=lambda noise: [(s.A, s.f0_hz) for s in noise.sinusoids if s.A],
        write=lambda kw, v: kw['sinusoids'].append(Sinusoid(*v)),
        bounds=lambda tau, rate_hz: ((0.371 / (2.0 * tau.max()),
                                      min(0.742 / tau.min(), 0.5 * rate_hz)),),
        describe=lambda p, u: (f'sinusoid at {p["f0_hz"]:.2g} Hz (period '
                               f'{1.0 / p["f0_hz"]:.3g} s, amplitude {p["A"]:.2g} {u["A"]})')),
}

#: Old effect names still accepted for one release: the effect 'bias_instability' was
#: flicker noise (the term 'bias_instability' is the paper's Gauss-Markov floor).
EFFECT_ALIASES = {'bias_instability': 'flicker'}
#: Old base-model names still accepted for one release: the base 'gauss_markov' was the
#: paper's Gauss-Markov floor, the term 'bias_instability'.
BASE_ALIASES = {'gauss_markov': 'bias_instability'}

_SUFFIX = re.compile(r'^(?P<base>[a-z_]+?)(?:_(?P<num>\d+))?$')


def base_name(term_name: str) -> str:
    """
    Return the registry name of a possibly numbered term ('gauss_markov_2' -> 'gauss_markov').

    Parameters
    ----------
    term_name : str
        A term name, optionally with a ``_<number>`` suffix.

    Returns
    -------
    str
        The key of :data:`TERMS`; KeyError when unknown.

    """
    if term_name in TERMS:
        return term_name
    match = _SUFFIX.match(term_name)
    if match and match.group('base') in TERMS:
        return match.group('base')
    raise KeyError(term_name)


def effect_names() -> tuple:
    """Return the names of every effect (terms with ``effect``), registry order."""
    return tuple(name for name, t in TERMS.items() if t.effect)


def search_effects() -> tuple:
    """Return the effects the search tries by default, in its order (``search_rank``)."""
    ranked = [(t.search_rank, name) for name, t in TERMS.items() if t.search_rank is not None]
    return tuple(name for _, name in sorted(ranked))


def effect_name(name: str) -> str:
    """Return the effect's current name (old names of :data:`EFFECT_ALIASES` mapped)."""
    return EFFECT_ALIASES.get(name, name)


def file_key(term: Term, symbol: str) -> str:
    """Return the parameter-file key of one of a term's symbols ('' when not in files)."""
    return term.keys[term.symbols.index(symbol)].name


def terms_of(noise: AxisNoise) -> list:
    """
    Every term instance an axis model holds, registry order.

    Parameters
    ----------
    noise : AxisNoise
        The axis model, SI units.

    Returns
    -------
    list of (str, str, dict)
        (label, term name, parameters by symbol); a term held once is labelled by its
        name, several instances ``<name>_1``, ``<name>_2``, ...

    """
    out = []
    for name, term in TERMS.items():
        found = term.instances(noise)
        for i, values in enumerate(found):
            label = name if len(found) == 1 else f'{name}_{i + 1}'
            out.append((label, name, dict(zip(term.symbols, values))))
    return out


def noise_from_terms(values: dict, bias: float = 0.0) -> AxisNoise:
    """
    Build an AxisNoise from per-term parameter dicts (as reported by the fit).

    Parameters
    ----------
    values : dict of str to dict
        Term label (possibly numbered) -> {symbol: value} in SI, e.g.
        {'white': {'N': 1e-4}, 'bias_instability': {'B': 5e-5, 'T_B': 80.0}}.
    bias : float
        Constant offset [unit].

    Returns
    -------
    AxisNoise
        The model; terms missing from ``values`` are absent.

    """
    kw: dict = {'gauss_markov': [], 'sinusoids': [], 'extra': []}
    for label, params in values.items():
        term = TERMS[base_name(label)]
        term.put(kw, tuple(params[s] for s in term.symbols))
    for key in ('gauss_markov', 'sinusoids', 'extra'):
        kw[key] = tuple(kw[key])
    return AxisNoise(bias=bias, **kw)
