"""
The one decision of what every output reports for an axis.

The search (:mod:`imu_allan.core.search`) and the trust judgement
(:mod:`imu_allan.core.fit.trust`) leave each axis' parameters in ``AxisFit.optimised``:
value, 95 % interval, kind, where it came from (``Param.source``) and why it is not a
plain estimate (``Param.reason``).  :func:`report_axis` turns them, once, into the
:class:`AxisReport` that every consumer file, topic, summary line and the Kalman model
read; none of them computes a value of its own.  The rules, each stated here only:

* **White noise** (what a filter's measurement noise R uses): N at its value, an upper
  bound at its bound, plus the white-noise role of every registry term without a field
  of its own (``Term.kalman == 'white'``, e.g. white noise seen through the sensor's
  filter).
* **Random walk** (what a bias random-walk state uses): K at its value, an upper bound
  at its bound (a filter that under-states a bias's wander becomes over-confident, one
  that over-states it converges a little slower); where the record could not constrain
  K at all, the measured curve's own 95 % bound min sqrt(3 AVAR_hi / tau) (IEEE Std 952
  C.1, :func:`imu_allan.core.allan.edf.curve_k_bound`); never 0 where a curve exists.
* **Gauss-Markov state** (b_gm of the paper's model, Maia et al. eq. 8): B (value or
  bound) with T_B where T_B is identified (an estimate, or a lower bound used at the
  fit's value: B was fitted with it, and at the interval's lower end with that B the
  state's ADEV peak would move to short taus and lie over the curve).  A B without an
  identified T_B has no state: it is listed in ``left_out``, never given an invented
  correlation time.
* **Left out**: every term of the model without a slot in the white + Gauss-Markov +
  random-walk filter (flicker, further Gauss-Markov processes, sinusoids, quantization,
  ramp) is named, so a file that holds this model says what it leaves out.
* Random-walk-only consumers (Kalibr, VINS, OpenVINS) get the covering pair of
  :mod:`imu_allan.core.outputs.covering`, derived from this report: it covers every
  term, and is never below the reported white noise and random walk.
"""

from dataclasses import dataclass, field
import math
from typing import Any, NamedTuple

import numpy as np

from imu_allan.core.allan.edf import curve_k_bound
from imu_allan.core.noise.model import avar_model
from imu_allan.core.noise.terms import TERMS, terms_of
from imu_allan.core.noise.values import AxisNoise
from imu_allan.core.rules import FLOOR_SPREAD_MAX
from imu_allan.errors import InputError

#: The parameters every axis reports, in the order people quote them.
CORE_SYMBOLS = ('N', 'B', 'T_B', 'K')
#: Kinds of a consumer value, from the strongest to the weakest.
CONSUMER_KINDS = ('estimate', 'upper_bound', 'curve_bound', 'absent')


class ConsumerValue(NamedTuple):
    """
    One density a consumer uses, with how it was decided.

    Attributes
    ----------
    value : float
        The density [unit*s^0.5 for white noise, unit/s^0.5 for a random walk]; 0.0
        when absent.
    kind : str
        'estimate', 'upper_bound' (a 95 % bound, used at the bound), 'curve_bound' (the
        measured curve's own 95 % bound: the record could not constrain the term) or
        'absent' (no value: no term and no curve).
    reason : str
        Why it is not a plain estimate ('' for an estimate).

    """

    value: float
    kind: str
    reason: str = ''


class Floor(NamedTuple):
    """
    The lowest point of the measured ADEV: a datasheet's in-run bias stability.

    Attributes
    ----------
    adev : float
        ADEV at the minimum [unit].
    ci95 : tuple of float
        Its 95 % interval (NIST SP 1065 sec. 5.3) [unit].
    tau_s : float
        Where it lies [s].
    b_floor : float
        The IEEE Std 952 read-off of B, adev / 0.664 [unit].

    """

    adev: float
    ci95: tuple
    tau_s: float
    b_floor: float


class GaussMarkovState(NamedTuple):
    """
    The bias-instability state of the paper's model, as a filter takes it.

    Attributes
    ----------
    B : float
        Level [unit] (paper eq. 8 convention: ADEV peak 0.664 B).
    T_B : float
        Correlation time [s].
    S_B : float
        Driving PSD 2 B^2 ln2 / (pi 0.4365^2 T_B) (paper eq. 8) [unit^2/s].
    kind : str
        'estimate', or 'upper_bound' where B is only bounded (used at the bound).

    """

    B: float
    T_B: float
    S_B: float
    kind: str


@dataclass(frozen=True)
class AxisReport:
    """
    What every output reports for one axis (:func:`report_axis`).

    Attributes
    ----------
    axis : str
        Axis name ('' when unnamed).
    params : dict of str to imu_allan.core.fit.Param
        Every reported parameter (N, B, T_B, K first; then the symbols of the further
        terms), each with its interval, kind, source and reason.
    white : ConsumerValue
        The white-noise density a filter's measurement noise uses [unit*s^0.5].
    random_walk : ConsumerValue
        The random-walk density a filter's bias random walk uses [unit/s^0.5].
    gauss_markov : GaussMarkovState or None
        The Gauss-Markov bias state, None where the model has none a filter can hold.
    left_out : tuple of str
        Terms of the model the white + Gauss-Markov + random-walk filter leaves out,
        each with a word on why.
    trust : tuple of str
        Why the fitted numbers were replaced by conservative ones read off the curve
        (empty when they are used as fitted).
    floor : Floor or None
        The lowest ADEV where the curve measures it (:data:`FLOOR_SPREAD_MAX`), else
        None: the summary then shows no floor at all.
    source : object
        The AxisFit or AxisNoise this report was decided from (the covering pair reads
        the whole model's Allan variance from it).

    """

    axis: str
    params: dict
    white: ConsumerValue
    random_walk: ConsumerValue
    gauss_markov: GaussMarkovState | None
    left_out: tuple = ()
    trust: tuple = ()
    floor: Floor | None = None
    source: object = field(default=None, repr=False, compare=False)

    @property
    def trusted(self) -> bool:
        """Whether the fitted numbers are reported as fitted."""
        return not self.trust

    def model_avar(self, tau_s: np.ndarray) -> np.ndarray:
        """
        Allan variance of the whole model, with N and K at least at their reported values.

        Every term counts (also those ``left_out``); where N or K is reported above the
        model's point value (an upper bound, the curve's bound), the difference is added
        as white noise (AVAR N^2 / tau) or random walk (K^2 tau / 3), IEEE Std 952 C.1.

        Parameters
        ----------
        tau_s : np.ndarray
            Shape (k,), averaging times [s].

        Returns
        -------
        np.ndarray
            Shape (k,), AVAR [unit^2].

        """
        tau = np.asarray(tau_s, dtype=np.float64)
        src: Any = self.source
        model = src if isinstance(src, AxisNoise) else _model_of(src)
        if getattr(src, 'components', None):
            avar = np.asarray(src.avar_at(tau), dtype=np.float64)
        else:
            avar = avar_model(tau, model)
        d_n = self.white.value ** 2 - _role_density(model, 'white')
        d_k = self.random_walk.value ** 2 - _role_density(model, 'b_rw')
        return avar + max(d_n, 0.0) / tau + max(d_k, 0.0) * tau / 3.0

    def to_json(self) -> dict:
        """Return the consumer values and what is left out (SI units; None for NaN)."""
        def num(x: float):
            return float(x) if math.isfinite(x) else None

        gm = self.gauss_markov
        return {'white_N': {'value': num(self.white.value), 'kind': self.white.kind,
                            'reason': self.white.reason},
                'random_walk_K': {'value': num(self.random_walk.value),
                                  'kind': self.random_walk.kind,
                                  'reason': self.random_walk.reason},
                'gauss_markov': None if gm is None else {
                    'B': num(gm.B), 'T_B': num(gm.T_B), 'S_B': num(gm.S_B), 'kind': gm.kind},
                'left_out': list(self.left_out)}


def _role_density(model: AxisNoise, role: str) -> float:
    """Sum of the coefficients of the model's terms of one Kalman role [unit^2 s^(+-1)]."""
    total = 0.0
    for _, name, params in terms_of(model):
        term = TERMS[name]
        if term.kalman == role:
            nonlinear = [params[s] for s in term.nonlinear]
            total += term.to_coef(params[term.symbols[0]], *nonlinear)
    return total


def _extra_density(model: AxisNoise | None, role: str) -> float:
    """Return what the terms without a field of their own add to one role."""
    if model is None or not model.extra:
        return 0.0
    return _role_density(AxisNoise(extra=model.extra), role)


def _model_of(source) -> AxisNoise:
    model = getattr(source, 'model', None)
    return model if isinstance(model, AxisNoise) else AxisNoise()


def _usable(p: Any) -> tuple[float, str] | None:
    """Return (value, kind) of a Param a consumer can use (estimate or upper bound), or None."""
    if (p is not None and p.kind in ('estimate', 'upper_bound') and math.isfinite(p.value)
            and p.value > 0):
        return float(p.value), str(p.kind)
    return None


def _white(params: dict, model: AxisNoise | None, source) -> ConsumerValue:
    got = _usable(params.get('N'))
    extra = _extra_density(model, 'white')
    if got is None and extra <= 0:
        bound = _curve_bound(source, 'N')
        if bound > 0:
            return ConsumerValue(bound, 'curve_bound',
                                 "N not identified: the measured curve's own 95 % bound")
        return ConsumerValue(0.0, 'absent', 'no white-noise value')
    value = math.sqrt((got[0] ** 2 if got else 0.0) + extra)
    if got and got[1] == 'upper_bound':
        return ConsumerValue(value, 'upper_bound', 'N used at its 95 % upper bound')
    return ConsumerValue(value, 'estimate')


def _random_walk(params: dict, model: AxisNoise | None, source) -> ConsumerValue:
    p = params.get('K')
    got = _usable(p)
    extra = _extra_density(model, 'b_rw')
    if got is not None or extra > 0:
        value = math.sqrt((got[0] ** 2 if got else 0.0) + extra)
        if got and got[1] == 'upper_bound':
            why = getattr(p, 'reason', '')
            return ConsumerValue(value, 'upper_bound', 'K used at its 95 % upper bound'
                                 + (f' ({why})' if why else ''))
        return ConsumerValue(value, 'estimate')
    bound = _curve_bound(source, 'K')
    if bound > 0:
        return ConsumerValue(bound, 'curve_bound', "K not identified: the measured curve's "
                             'own 95 % bound')
    return ConsumerValue(0.0, 'absent', 'K not identified and no curve to bound it')


def _curve_bound(source, symbol: str) -> float:
    """
    Bound of N or K that the measured curve itself sets, 0.0 without a curve.

    No term can exceed the whole AVAR at any tau: N^2 / tau <= AVAR(tau) past the
    sensor's filter, and K^2 tau / 3 <= AVAR(tau) (IEEE Std 952 C.1 slopes), so
    N <= min sqrt(AVAR tau) over the fitted points; K's bound, with each point at its
    joint 95 % upper limit, is the fit's
    :attr:`~imu_allan.core.fit.result.AxisFit.caps` (read once off every point past the
    filter), or from the points a fit keeps where it has none
    (:func:`imu_allan.core.allan.edf.curve_k_bound`).
    """
    tau, avar = getattr(source, 'tau_s', None), getattr(source, 'avar_meas', None)
    if tau is None or avar is None or not np.size(tau):
        return 0.0
    tau, avar = np.asarray(tau, dtype=np.float64), np.asarray(avar, dtype=np.float64)
    if symbol == 'N':
        return float(np.sqrt(np.min(avar * tau)))
    caps = getattr(source, 'caps', None)
    if caps is not None and math.isfinite(caps.K):
        return float(caps.K)
    edf = getattr(source, 'edf', None)
    if edf is not None and np.size(edf) == tau.size:
        return curve_k_bound(tau, avar, np.asarray(edf, dtype=np.float64))
    return float(np.sqrt(np.min(3.0 * avar / tau)))


def _gauss_markov(params: dict) -> GaussMarkovState | None:
    b, t_b = _usable(params.get('B')), params.get('T_B')
    if (b is None or t_b is None or t_b.kind not in ('estimate', 'lower_bound')
            or not math.isfinite(t_b.value) or t_b.value <= 0):
        return None
    s_b = TERMS['bias_instability'].to_coef(b[0], t_b.value)
    return GaussMarkovState(b[0], float(t_b.value), float(s_b), b[1])


def _left_out(model: AxisNoise | None, params: dict,
              gm: GaussMarkovState | None) -> tuple:
    out = []
    if gm is None and _usable(params.get('B')):
        out.append('bias instability B without an identified T_B (no Gauss-Markov state; '
                   'b_gm frozen)')
    for label, name, _ in terms_of(model or AxisNoise()):
        role = TERMS[name].kalman
        if role in ('white', 'b_rw', 'b_gm'):
            continue
        out.append(f'{label} ({TERMS[name].title})')
    return tuple(dict.fromkeys(out))


def _params_of_noise(noise: AxisNoise) -> dict:
    """Return the parameters of a bare model: N, B, T_B, K as estimates (or absent)."""
    from imu_allan.core.fit.result import Param   # the one Param type of the package
    nan = (math.nan, math.nan)
    out = {}
    for sym in CORE_SYMBOLS:
        v = getattr(noise, sym)
        ok = v is not None and math.isfinite(v) and v > 0
        out[sym] = (Param(float(v), (float(v), float(v)), 'estimate', '', 'model') if ok
                    else Param(math.nan, nan, 'not_identified', '', 'model',
                               'not in the model'))
    return out


def _floor(fit) -> Floor | None:
    """Return the lowest ADEV of a fit where the curve measures it (FLOOR_SPREAD_MAX)."""
    b = getattr(fit, 'b_floor', None)
    if b is None or not b.ci95[0] > 0 or b.ci95[1] / b.ci95[0] > FLOOR_SPREAD_MAX:
        return None
    # b_floor is ADEV_min / 0.664 over the taus past the sensor's filter (fit.trust).
    adev = np.sqrt(np.maximum(np.asarray(fit.avar_meas, float), 0.0))
    j = int(np.argmin(np.abs(adev / 0.664 - b.value)))
    if j >= adev.size - 1:          # still falling at the last tau: no floor measured
        return None
    return Floor(float(adev[j]), (0.664 * b.ci95[0], 0.664 * b.ci95[1]),
                 float(fit.tau_s[j]), float(b.value))


def report_axis(source, axis: str = '') -> AxisReport:
    """
    Decide what every output reports for one axis (the rules of the module docstring).

    Parameters
    ----------
    source : AxisReport, imu_allan.core.fit.AxisFit or AxisNoise
        The final fit of the axis (after the search and the trust judgement), a bare
        model (the simulator's, a parameter file's), or a report already made (returned
        as it is).
    axis : str
        Axis name for labels.

    Returns
    -------
    AxisReport

    Raises
    ------
    InputError
        Anything else.

    """
    if isinstance(source, AxisReport):
        return source
    model = source if isinstance(source, AxisNoise) else _model_of(source)
    if isinstance(source, AxisNoise):
        params, trust = _params_of_noise(source), ()
    elif hasattr(source, 'optimised'):
        params, trust = dict(source.optimised), tuple(getattr(source, 'trust', ()))
    else:
        raise InputError(f'expected an AxisNoise or an AxisFit, got {type(source).__name__}')
    gm = _gauss_markov(params)
    if isinstance(source, AxisNoise) and source.B > 0 and source.T_B:
        gm = GaussMarkovState(float(source.B), float(source.T_B),
                              float(TERMS['bias_instability'].to_coef(source.B, source.T_B)),
                              'estimate')
    return AxisReport(axis=axis, params=params, white=_white(params, model, source),
                      random_walk=_random_walk(params, model, source), gauss_markov=gm,
                      left_out=_left_out(model, params, gm), trust=trust,
                      floor=_floor(source), source=source)


def report_axes(sources) -> dict:
    """
    :func:`report_axis` of every axis.

    Parameters
    ----------
    sources : mapping of str to AxisReport, AxisFit, AxisNoise or None
        Per axis name; None (an axis that could not be fitted) becomes an empty model.

    Returns
    -------
    dict of str to AxisReport
        Same keys and order.

    """
    return {a: report_axis(AxisNoise() if s is None else s, a) for a, s in sources.items()}


def unsettled(fit) -> list:
    """
    Return what keeps an axis' status from 'ok' ([] when N and B are settled).

    N and B must be estimates whose 95 % intervals span at most 1.5x and 4x.
    """
    problems = []
    for sym, max_ratio in (('N', 1.5), ('B', 4.0)):
        p = fit.optimised.get(sym)
        if p is None or p.kind != 'estimate':
            problems.append(f'{sym} not identified yet')
        elif not (p.ci95[0] > 0 and p.ci95[1] / p.ci95[0] <= max_ratio):
            problems.append(f'{sym} interval still wide')
    return problems
