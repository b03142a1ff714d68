"""
Result types of the fit: one parameter with its interval, one axis' fit.

Part of :mod:`imu_allan.core.fit` (see its docstring for the method).
"""

from dataclasses import dataclass, field
import math
from typing import NamedTuple

import numpy as np

from imu_allan.core.allan.quantiles import chi2_sf
from imu_allan.core.noise.terms import base_name, TERMS
from imu_allan.core.noise.values import AxisNoise

#: Kinds of a reported parameter.
KINDS = ('estimate', 'upper_bound', 'lower_bound', 'not_identified')


class Param(NamedTuple):
    """
    One reported parameter.

    Attributes
    ----------
    value : float
        Estimate [unit]; for an upper bound, the bound itself; NaN when not identified.
    ci95 : tuple of float
        (lo, hi), the 95 % interval [unit]; (0, bound) for an upper bound, (lo, inf)
        for a lower bound, (nan, nan) when not identified.
    kind : str
        'estimate', 'upper_bound', 'lower_bound' or 'not_identified'.
    unit : str
        SI unit, e.g. 'rad/s*s^0.5'.
    source : str
        Where the value came from: 'fitted' (the GLS fit and its profile), 'curve'
        (read off the measured curve: the conservative value of a fit not trusted) or
        'model' (a bare noise model, not a fit).
    reason : str
        Why it is not a plain estimate, in a user's words ('' for an estimate).

    """

    value: float
    ci95: tuple[float, float]
    kind: str
    unit: str
    source: str = 'fitted'
    reason: str = ''

    def to_json(self) -> dict:
        """Return {'value', 'ci95', 'kind', 'unit', 'source', 'reason'}; NaN, inf: None."""
        return {'value': json_num(self.value), 'ci95': [json_num(v) for v in self.ci95],
                'kind': self.kind, 'unit': self.unit, 'source': self.source,
                'reason': self.reason}


def json_num(x):
    """Return x as a float for strict JSON, or None where it is None, NaN or infinite."""
    return float(x) if x is not None and math.isfinite(x) else None


def json_floats(a) -> list:
    """Return the values of an array as a list for strict JSON (None for NaN/inf)."""
    return [json_num(v) for v in np.asarray(a, dtype=np.float64).ravel()]


class CurveCaps(NamedTuple):
    """
    The largest N, B and K a measured curve allows, jointly at 95 % over its points.

    Every term of the model but a sensor's filter only adds to the Allan variance, so a
    random walk's line K^2 tau / 3 (IEEE Std 952 C.1 slope +1/2), a bias
    instability's peak 0.664^2 B^2 (annex C) and, past the filter, white noise's line
    N^2 / tau each lie under the true AVAR at every tau; each point is taken at its joint
    upper limit (:func:`imu_allan.core.allan.edf.avar_upper`).  N is capped only where
    the curve showed the filter's bend end (:class:`imu_allan.core.fit.axis.FilterCut`):
    a filter whose bend runs past its cut lowers the curve below N's line.  Made by
    :func:`imu_allan.core.fit.caps.curve_caps` from the points past the filter.

    Attributes
    ----------
    B : float
        min sqrt(AVAR_hi) / 0.664 [unit]; inf without a curve (no cap).
    K : float
        min sqrt(3 AVAR_hi / tau) [unit / s^0.5].
    N : float
        min sqrt(AVAR_hi tau) [unit * s^0.5]; inf where the filter's end is not seen.

    """

    B: float = math.inf
    K: float = math.inf
    N: float = math.inf


def _no_curve() -> np.ndarray:
    """Return the curve arrays of a fit made without one: empty."""
    return np.empty(0)


# Long because it is the one record of a fit every output reads: its fields, their
# JSON and the trust verdict stay together.
@dataclass(frozen=True)
class AxisFit:
    """
    Result of :func:`fit_axis` for one axis.

    Attributes
    ----------
    nominal : dict of str to Param
        IEEE Std 952 read-off: N, B, K, T_B.
    optimised : dict of str to Param
        GLS fit: N, B, T_B, K always (estimate, upper bound or not identified), plus
        the symbols of every further selected or requested term (Q, R, '<term>.<sym>').
    model : AxisNoise
        The optimised model, SI: the supported terms plus the core terms (N, B/T_B, K)
        at their GLS point estimates even where those are reported as upper bounds
        (the best-fitting curve, e.g. for simulation); use ``optimised`` for values
        with their status.
    terms : tuple of str
        Terms the data support (the selected model).
    notes : tuple of str
        Human one-liners, e.g. 'K: not supported by the data (too small or the record
        too short); 95 % upper bound'.
    chi2 : float
        GLS chi-square of the fitted model (supported plus core terms) at its own
        covariance [-].
    dof : int
        Number of fitted tau minus number of fitted parameters.
    tau_s : np.ndarray
        Shape (k,), the averaging times used [s].
    avar_fit : np.ndarray
        Shape (k,), Allan variance of ``model`` at ``tau_s`` [unit^2].
    avar_sd : np.ndarray
        Shape (k,), standard deviation of each Allan estimate under that model [unit^2].
    avar_meas, edf : np.ndarray
        Shape (k,), the measured Allan variance [unit^2] and its EDF at ``tau_s``.
    components : tuple of (str, float, tuple)
        The fitted model exactly: (term label, coefficient in SI, nonlinear parameters)
        per term (:meth:`avar_at` evaluates it at any tau).
    effects : tuple of dict
        Effects the search added (:mod:`imu_allan.core.search`), in order.
    model_consistent : bool or None
        Whether the final model explains the curve (chi-square p >= 1e-3); None when no
        search ran.
    pinned : tuple of str
        Nonlinear parameters whose estimate sits at an end of its search range (not
        identified by the taus).
    trust : tuple of str
        Why the fitted numbers are not to be trusted (empty when they are): the model
        does not follow its curve, a parameter sits at a bound, or N differs from the
        curve's white region beyond its interval.  ``optimised`` then holds the
        conservative values every output uses (N from the white region with its
        interval, B from the ADEV floor as an upper bound, K the curve's own bound,
        every other parameter not identified) and ``fit_values`` the fitted ones.
    fit_values : dict of str to Param
        The fitted parameters that ``optimised`` replaced (empty when trusted).
    b_floor : Param or None
        B read off the ADEV floor past the sensor's filter, ADEV_min / 0.664 (IEEE Std
        952-1997 annex C), with that point's 95 % interval; reported beside B, which is
        the level of the fitted Gauss-Markov (or flicker) term.
    rivals : tuple of dict
        Rival models that fit about as well (:mod:`imu_allan.core.search.choice`):
        'model' (what differs), 'criterion_rise' (chi-square or -2 ln L + BIC above
        the chosen model) and their N, B, T_B, K [SI].
    caps : CurveCaps
        What the measured curve allows of N, B and K: no upper bound in ``optimised``
        lies above them (:func:`imu_allan.core.fit.params.cap_fit`).
    filter_end_s : float
        The first tau past the sensor's filter [s], where the curve showed its bend end
        (:func:`imu_allan.core.fit.axis.filter_cut`); NaN where it did not.
    p_value : float or None
        Chi-square p-value of ``chi2`` on ``dof`` (None without degrees of freedom);
        computed where the fit is made, so a process that only reports it needs no scipy.

    """

    nominal: dict
    optimised: dict
    model: AxisNoise
    terms: tuple
    notes: tuple
    chi2: float = math.nan
    dof: int = 0
    tau_s: np.ndarray = field(default_factory=_no_curve)
    avar_fit: np.ndarray = field(default_factory=_no_curve)
    avar_sd: np.ndarray = field(default_factory=_no_curve)
    avar_meas: np.ndarray = field(default_factory=_no_curve)
    edf: np.ndarray = field(default_factory=_no_curve)
    components: tuple = ()
    effects: tuple = ()
    model_consistent: bool | None = None
    pinned: tuple = ()
    trust: tuple = ()
    fit_values: dict = field(default_factory=dict)
    b_floor: Param | None = None
    rivals: tuple = ()
    caps: CurveCaps = CurveCaps()
    filter_end_s: float = math.nan
    p_value: float | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        p_value = float(chi2_sf(self.chi2, self.dof)) if self.dof > 0 else None
        object.__setattr__(self, 'p_value', p_value)

    def avar_at(self, tau_s) -> np.ndarray:
        """
        Allan variance of the fitted model (every term) at any taus.

        Parameters
        ----------
        tau_s : array_like
            Shape (k,), averaging times [s].

        Returns
        -------
        np.ndarray
            Shape (k,), AVAR [unit^2].

        """
        tau = np.asarray(tau_s, dtype=np.float64)
        out = np.zeros(tau.shape)
        for label, c_si, phi in self.components:
            out += c_si * TERMS[base_name(label)].shape(tau, *phi)
        return out

    @property
    def trusted(self) -> bool:
        """Whether the fitted numbers are used as fitted (no :attr:`trust` problem)."""
        return not self.trust

    def trust_comment(self, axis: str = '') -> str:
        """One line for consumer files: what is wrong and which values are used ('')."""
        if not self.trust:
            return ''
        used = ', '.join(f'{k} {"<= " if p.kind == "upper_bound" else ""}{p.value:.4g}'
                         for k, p in self.optimised.items()
                         if k in ('N', 'B', 'K') and p.kind in ('estimate', 'upper_bound'))
        where = f'{axis}: ' if axis else ''
        return (f'{where}fit not trusted ({"; ".join(self.trust)}); conservative values '
                f'used: {used} (SI units)')

    def to_json(self) -> dict:
        """
        Return the JSON-ready result of the axis.

        Returns
        -------
        dict
            ``{'params': {P: {value, ci95, kind, unit}}, 'nominal': {...},
            'terms': [...], 'notes': [...], 'gof': {'chi2', 'dof', 'p_value'}}``;
            ``params`` is the optimised fit (docs/contracts.md result contract).

        """
        return {'params': {k: v.to_json() for k, v in self.optimised.items()},
                'nominal': {k: v.to_json() for k, v in self.nominal.items()},
                'terms': list(self.terms), 'notes': list(self.notes),
                'effects': [dict(e, chi2_drop=json_num(e['chi2_drop']))
                            for e in self.effects],
                'model_consistent': self.model_consistent,
                'b_floor': None if self.b_floor is None else self.b_floor.to_json(),
                'trusted': self.trusted, 'trust_problems': list(self.trust),
                'fit_values': {k: v.to_json() for k, v in self.fit_values.items()},
                'rivals': [{k: (v if isinstance(v, str) else json_num(v))
                            for k, v in r.items()} for r in self.rivals],
                'gof': {'chi2': json_num(self.chi2), 'dof': int(self.dof),
                        'p_value': self.p_value}}


def _unit(template: str, unit: str) -> str:
    """Replace the sample-unit placeholder 'u' of a Term unit template."""
    if template == 's' or template == 'Hz':
        return template
    return unit + template[1:]
