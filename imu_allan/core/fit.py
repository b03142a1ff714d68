"""
Fit the IMU noise model to an Allan curve, with honest 95 % intervals.

Two methods are run on every curve and both are reported.

Nominal (IEEE Std 952-1997 annex C read-off, what most tools do): N is the line of
slope -1/2 through the curve point whose log-log slope is closest to -1/2, read at
tau = 1 s; K the line of slope +1/2 read at tau = 3 s; B = min ADEV / 0.664 and
T_B = tau at the minimum / 1.89.  Its intervals are the chi-square bounds of the one
point each value is read from; they ignore the read-off's bias (a minimum that sits
on the white-noise or random-walk flank, a slope that never reaches +-1/2), so
they are shown for comparison, not trusted.

Optimised (generalised least squares on the Allan variance, GMWM-style):

* Model: AVAR(tau) = sum_j c_j s_j(tau; phi_j), one term per entry of
  :data:`imu_allan.core.model.TERMS`; linear in the coefficients c_j (S_N = N^2, S_B,
  S_K = K^2, ...) for fixed nonlinear parameters phi (T_B, sinusoid frequency), as in
  the paper's section 3.2 (Maia, Silva, De Lima, Meneses).  The c_j are solved by
  non-negative least squares, phi by a grid and a bounded 1-D (or Nelder-Mead)
  search (variable projection).  Interchangeable terms are ordered (the first
  Gauss-Markov label has the shortest T).
* Weights: the full covariance matrix Sigma of the Allan estimates at all fitted tau,
  computed exactly (for Gaussian terms) from the model: the overlapping estimator is a
  quadratic form in the phase, so Cov(avar_p, avar_q) = 2 sum_{k,l} gamma_pq(l-k)^2 /
  (4 tau_p^2 tau_q^2 n_p n_q), with gamma the covariance between second differences at
  cluster sizes m_p and m_q, built from each term's generalised covariance
  (:class:`imu_allan.core.model.Term`).  The lag sum is exact near the kinks and
  Gauss-Legendre far from them; test_fit.py checks Sigma against Monte Carlo.  It
  carries the chi-square spread of each point (its EDF, for the noise mix at that tau)
  and the correlation of neighbouring tau (about 0.5 at octave spacing).  A sinusoid
  adds the spread of its beat with the noise.  Sigma is iterated (re-weighted GLS):
  first the paper's weights 2 avar^2 / edf, then the *expected* Sigma (Sigma(theta)
  averaged over the GLS uncertainty of the coefficients, which keeps a record's own
  low long-tau points from raising their own weight) to convergence, and a last step
  at the plug-in Sigma(theta) of that solution (:meth:`_Fitter.irls`).
* Term selection: every subset of the candidate terms is fitted with the weights of the
  full model; the subset minimising J + 2 p (AIC; J the GLS chi-square, p the number
  of parameters) is what the data support (``AxisFit.terms``).
* Values and intervals come from the supported terms plus the paper's core terms
  (white, bias instability, random walk), so that a weak term still takes its share
  of the curve.  Each interval is a profile interval: the set of values v for which the
  GLS chi-square, minimised over all other parameters with this one held at v, stays
  within chi2(0.95; 1) = 3.84 of its minimum (likelihood-ratio interval with a known
  covariance; Bates & Watts, nonlinear regression), or within F(0.95; 1, dof) x
  J_min / dof when the model fits worse than its covariance allows (J_min > dof: a
  missing effect, or a Sigma evaluated at an estimate whose long-tau points run low).
* A core or requested term the data do not support is reported as a one-sided 95 %
  upper bound: its coefficient c0 at which the GLS estimate would fall below the
  observed one with 5 % probability, the covariance evaluated under c0 and the term's
  own part treated as a scaled chi-square (:func:`_upper_bound`).

Validation: bench/validate_fit.py (3 h records of the two example IMUs, 50 seeds; it
also fits the real ADIS16405 runs with ``--adis``).  Speed: bench/bench_fit.py.

B convention (paper eq. 8): B is the ADEV floor / 0.664; the Gauss-Markov driving PSD
is S_B = 2 B^2 ln2 / (pi 0.4365^2 T_B).
"""

from dataclasses import dataclass, replace
from itertools import combinations
import math
from typing import NamedTuple, Sequence

import numpy as np
from scipy.optimize import brentq, minimize, minimize_scalar, nnls
from scipy.special import ndtr
from scipy.stats import chi2
from scipy.stats import f as fdist

from imu_allan.core.allan import _single_thread_blas, AllanCurve
from imu_allan.core.model import (base_name, FLICKER_AVAR, GM_PEAK_TAU, noise_from_terms, Term,
                                  TERMS)
from imu_allan.core.noise_params import AxisNoise
from imu_allan.errors import InputError

#: Candidate terms when ``terms`` is not given; the fit keeps those the data support.
DEFAULT_TERMS = ('quantization', 'white', 'bias_instability', 'random_walk')
#: Parameters always reported, with the term they belong to.
CORE_PARAMS = {'N': 'white', 'B': 'bias_instability', 'T_B': 'bias_instability',
               'K': 'random_walk'}
#: The paper's model: always part of the fit that yields the reported intervals.
_CORE_TERMS = ('white', 'filtered_white', 'bias_instability', 'random_walk')
#: Symbols reported without a term prefix (others become '<term>.<symbol>').
_PLAIN = {'quantization': ('Q',), 'white': ('N',), 'filtered_white': ('N', 'T_f'),
          'flicker': ('B',),
          'bias_instability': ('B', 'T_B'), 'random_walk': ('K',), 'rate_ramp': ('R',)}
#: Kinds of a reported parameter.
KINDS = ('estimate', 'upper_bound', 'lower_bound', 'not_identified')
#: Penalty per parameter of the information criterion (AIC).
IC_PENALTY = 2.0
Z95 = 1.959963984540054
Z95_ONE_SIDED = 1.6448536269514722

# Lag-sum quadrature: lags within _EXACT of a kink are summed exactly, the rest is
# integrated with Gauss-Legendre on pieces that double in size away from the kinks.
# (8, 4 points) keeps Sigma within 3e-4 (relative to its diagonal) of (24, 8 points) on
# 3 h, 100 Hz octave and dense curves and a short 10 Hz one, for T_B from 3 s to
# 3000 s, with half the nodes (bench/bench_fit.py: the fit's main cost).
_EXACT = 8
_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)
_STENCIL = ((0, 1.0), (1, -2.0), (2, 1.0))


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

    """

    value: float
    ci95: tuple[float, float]
    kind: str
    unit: str

    def to_json(self) -> dict:
        """Return {'value', 'ci95', 'kind', 'unit'}; NaN and inf become None."""
        return {'value': json_num(self.value), 'ci95': [json_num(v) for v in self.ci95],
                'kind': self.kind, 'unit': self.unit}


def json_num(x):
    """Return x as a float for strict JSON, or None where it is None, NaN or infinite."""
    return float(x) if x is not None and math.isfinite(x) else None


def json_floats(a) -> list:
    """Return the values of an array as a list for strict JSON (None for NaN/inf)."""
    return [json_num(v) for v in np.asarray(a, dtype=np.float64).ravel()]


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

    """

    nominal: dict
    optimised: dict
    model: AxisNoise
    terms: tuple
    notes: tuple
    chi2: float = math.nan
    dof: int = 0
    tau_s: np.ndarray = None
    avar_fit: np.ndarray = None
    avar_sd: np.ndarray = None
    avar_meas: np.ndarray = None
    edf: np.ndarray = None
    components: tuple = ()
    effects: tuple = ()
    model_consistent: bool | None = None

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

    def to_json(self) -> dict:
        """
        Return the JSON-ready result of the axis.

        Returns
        -------
        dict
            ``{'params': {P: {value, ci95, kind, unit}}, 'nominal': {...},
            'terms': [...], 'notes': [...], 'gof': {'chi2', 'dof', 'p_value'}}``;
            ``params`` is the optimised fit (DESIGN.md result contract).

        """
        p_value = float(chi2.sf(self.chi2, self.dof)) if self.dof > 0 else None
        return {'params': {k: v.to_json() for k, v in self.optimised.items()},
                'nominal': {k: v.to_json() for k, v in self.nominal.items()},
                'terms': list(self.terms), 'notes': list(self.notes),
                'effects': [dict(e, chi2_drop=json_num(e['chi2_drop']))
                            for e in self.effects],
                'model_consistent': self.model_consistent,
                'gof': {'chi2': json_num(self.chi2), 'dof': int(self.dof),
                        'p_value': p_value}}


# ----------------------------------------------------------------------- nominal method

def _chi2_factors(edf: float) -> tuple[float, float]:
    """Multipliers (lo, hi) of an ADEV estimate for a 95 % chi-square interval."""
    edf = max(float(edf), 1e-3)
    return (math.sqrt(edf / chi2.ppf(0.975, edf)), math.sqrt(edf / chi2.ppf(0.025, edf)))


def nominal_fit(tau_s: np.ndarray, avar: np.ndarray, edf: np.ndarray,
                unit: str = 'unit') -> dict:
    """
    IEEE Std 952 read-off of N, B, K and T_B (the nominal method).

    N from the -1/2 slope line at tau = 1 s, K from the +1/2 slope line at tau = 3 s,
    each through the point whose forward log-log slope is closest to the target;
    B = min ADEV / 0.664, T_B = tau at the minimum / 1.89.  A slope more than 0.25 away
    from its target makes the value an upper bound (the line then only bounds the
    term from above).  Intervals: chi-square bounds of the read point (its EDF); for
    T_B the range of tau whose interval overlaps the minimum's, / 1.89.

    Parameters
    ----------
    tau_s : np.ndarray
        Shape (k,), averaging times [s], increasing.
    avar : np.ndarray
        Shape (k,), Allan variance [unit^2].
    edf : np.ndarray
        Shape (k,), equivalent degrees of freedom of each estimate.
    unit : str
        Unit of the samples, e.g. 'rad/s'.

    Returns
    -------
    dict of str to Param
        N, B, K, T_B.

    """
    tau = np.asarray(tau_s, dtype=np.float64)
    adev = np.sqrt(np.asarray(avar, dtype=np.float64))
    edf = np.asarray(edf, dtype=np.float64)
    out = {}
    if tau.size < 2:
        nan = Param(math.nan, (math.nan, math.nan), 'not_identified', '')
        return {k: nan._replace(unit=_unit(u, unit)) for k, u in
                (('N', 'u*s^0.5'), ('B', 'u'), ('K', 'u/s^0.5'), ('T_B', 's'))}
    slope = np.diff(np.log(adev)) / np.diff(np.log(tau))
    for sym, target, tau_read, u in (('N', -0.5, 1.0, 'u*s^0.5'), ('K', 0.5, 3.0, 'u/s^0.5')):
        i = int(np.argmin(np.abs(slope - target)))
        # The line through (tau_i, adev_i) with slope target, read at tau_read.
        value = adev[i] * (tau_read / tau[i]) ** target
        lo, hi = _chi2_factors(edf[i])
        kind = 'estimate' if abs(slope[i] - target) <= 0.25 else 'upper_bound'
        ci = (value * lo, value * hi) if kind == 'estimate' else (0.0, value * hi)
        out[sym] = Param(float(value), ci, kind, _unit(u, unit))
    i = int(np.argmin(adev))
    lo, hi = _chi2_factors(edf[i])
    out['B'] = Param(float(adev[i] / FLICKER_AVAR ** 0.5),
                     (adev[i] * lo / FLICKER_AVAR ** 0.5, adev[i] * hi / FLICKER_AVAR ** 0.5),
                     'estimate', _unit('u', unit))
    # Taus whose interval reaches down to the minimum's upper bound: where the minimum
    # could as well be.
    lo_all = adev * np.array([_chi2_factors(e)[0] for e in edf])
    near = np.flatnonzero(lo_all <= adev[i] * hi)
    t_lo = tau[near].min() / GM_PEAK_TAU
    t_hi = tau[near].max() / GM_PEAK_TAU
    out['T_B'] = Param(float(tau[i] / GM_PEAK_TAU), (float(t_lo), float(t_hi)),
                       'estimate', 's')
    return {k: out[k] for k in ('N', 'B', 'K', 'T_B')}


def _unit(template: str, unit: str) -> str:
    """Replace the sample-unit placeholder 'u' of a Term unit template."""
    if template == 's' or template == 'Hz':
        return template
    return unit + template[1:]


# ------------------------------------------------------------- covariance of the curve

class _LagQuadrature:
    """
    Quadrature of sum_{k<n_p} sum_{l<n_q} f(l - k) for every pair p <= q of taus.

    For each pair the lag axis is cut at the stencil kinks i m_p - j m_q (i, j in 0..2)
    and at the kinks of the pair-count weight w(h); lags within ``_EXACT`` of a cut are
    summed exactly, the rest is integrated (sum_{h=s}^{e} f(h) ~ int_{s-1/2}^{e+1/2})
    with 8-point Gauss-Legendre on pieces graded geometrically away from the cuts.
    """

    def __init__(self, m: np.ndarray, n_terms: np.ndarray, reach: np.ndarray):
        k = m.size
        hs, ws, pair_ids, pairs = [], [], [], []
        for p in range(k):
            for q in range(p, k):
                h, w = self._nodes(int(m[p]), int(m[q]), int(n_terms[p]), int(n_terms[q]),
                                   int(reach[p] + reach[q]))
                pair_ids.append(np.full(h.size, len(pairs), dtype=np.int64))
                pairs.append((p, q))
                hs.append(h)
                ws.append(w)
        self.h = np.concatenate(hs)
        self.weight = np.concatenate(ws)
        self.pair = np.concatenate(pair_ids)
        self.starts = np.concatenate([[0], np.cumsum([h.size for h in hs])[:-1]])
        self.pairs = np.array(pairs, dtype=np.int64)
        self.m1 = m[self.pairs[self.pair, 0]].astype(np.float64)
        self.m2 = m[self.pairs[self.pair, 1]].astype(np.float64)
        # Inner kink range of each node's pair: polynomial terms vanish outside it.
        self.kmin = -2.0 * self.m2
        self.kmax = 2.0 * self.m1
        self.k = k

    @staticmethod
    def _nodes(m1: int, m2: int, n1: int, n2: int, reach: int):
        kinks = sorted({i * m1 - j * m2 for i in range(3) for j in range(3)})
        lo = max(kinks[0] - reach, -(n1 - 1))
        hi = min(kinks[-1] + reach, n2 - 1)
        cuts = sorted({c for c in kinks + [0, n2 - n1, lo, hi] if lo <= c <= hi})
        zones: list[list[int]] = []
        for c in cuts:
            s, e = max(lo, c - _EXACT), min(hi, c + _EXACT)
            if zones and s <= zones[-1][1] + 1:
                zones[-1][1] = max(zones[-1][1], e)
            else:
                zones.append([s, e])
        hs = [np.arange(s, e + 1, dtype=np.float64) for s, e in zones]
        ws = [np.ones(e + 1 - s) for s, e in zones]
        for (_, e0), (s1, _) in zip(zones[:-1], zones[1:]):
            edges = _graded(e0 + 0.5, s1 - 0.5, float(_EXACT))
            half = 0.5 * np.diff(edges)
            mid = 0.5 * (edges[1:] + edges[:-1])
            hs.append((mid[:, None] + half[:, None] * _GL_X).ravel())
            ws.append((half[:, None] * _GL_W).ravel())
        h = np.concatenate(hs)
        w_pairs = np.clip(np.minimum(n1, n2 - h) - np.maximum(0.0, -h), 0.0, None)
        return h, np.concatenate(ws) * w_pairs

    def gamma(self, term: Term, nonlinear: tuple, dt: float) -> np.ndarray:
        """Covariance of the second differences per unit coefficient at every node."""
        inside = (self.h >= self.kmin) & (self.h <= self.kmax)
        reach = (np.zeros(self.h.size) if term.reach is None
                 else term.reach(self.m1, self.m2, dt, *nonlinear))
        direct = (inside if term.tail is not None else
                  (self.h >= self.kmin - reach) & (self.h <= self.kmax + reach))
        g = np.zeros(self.h.size)
        h, m1, m2 = self.h[direct], self.m1[direct], self.m2[direct]
        for i, ai in _STENCIL:
            for j, aj in _STENCIL:
                g[direct] += ai * aj * term.gcov(dt * (i * m1 - j * m2 - h), *nonlinear)
        if term.tail is not None:
            beyond = np.where(self.h > self.kmax, self.h - self.kmax, self.kmin - self.h)
            tail = ~inside & (beyond <= reach)
            g[tail] = term.tail(beyond[tail], self.m1[tail], self.m2[tail], dt, *nonlinear)
        return g

    def blocks(self, gammas: list, scale: np.ndarray) -> np.ndarray:
        """C[a, b] (k, k) = sum of weight * gamma_a * gamma_b per pair, times scale."""
        n = len(gammas)
        out = np.zeros((n, n, self.k, self.k))
        if n == 0:
            return out
        p, q = self.pairs[:, 0], self.pairs[:, 1]
        a_idx, b_idx = np.triu_indices(n)
        g = np.stack(gammas)
        wg = g * self.weight
        # The nodes are stored pair by pair, so each pair's sum is one reduceat segment.
        sums = np.add.reduceat(wg[a_idx] * g[b_idx], self.starts, axis=1) * scale[p, q]
        for s, a, b in zip(sums, a_idx, b_idx):
            out[a, b, p, q] = s
            out[a, b, q, p] = s
            out[b, a] = out[a, b]
        return out


def _lru_get(cache: dict, key, size: int, make):
    """Return cache[key], computed by ``make()`` when absent; drops the oldest entries."""
    value = cache.pop(key, None)
    if value is None:
        value = make()
    cache[key] = value
    while len(cache) > size:
        cache.pop(next(iter(cache)), None)
    return value


def _graded(a: float, b: float, first: float) -> np.ndarray:
    """Edges of pieces covering [a, b], sizes first, 2 first, 4 first ... from both ends."""
    left, right = [a], [b]
    size = first
    while right[-1] - left[-1] > 2.0 * size:
        left.append(left[-1] + size)
        right.append(right[-1] - size)
        size *= 2.0
    return np.array(left + right[::-1])


class _CurveCovariance:
    """Sigma(c, phi) of the overlapping Allan estimates of one curve (module docstring)."""

    def __init__(self, m: np.ndarray, n_terms: np.ndarray, dt: float, n_samples: int):
        self.m, self.n_terms, self.dt = m, n_terms, dt
        tau = m * dt
        self.scale = 2.0 / (4.0 * np.outer(tau ** 2, tau ** 2) * np.outer(n_terms, n_terms))
        self.n_samples = n_samples
        self._quad: dict[int, _LagQuadrature] = {}
        self._gammas: dict = {}     # second-difference covariances at the nodes
        self._blocks: dict = {}     # per-pair blocks of a term combination (small)

    def _quadrature(self, tails: bool) -> _LagQuadrature:
        # Without tails (polynomial covariances) the lags stop at the kinks; with them
        # (Gauss-Markov, flicker) they run over the whole record, graded, so that one
        # set of nodes serves every correlation time.
        if tails not in self._quad:
            reach = np.full(self.m.size, int(self.n_terms.max()) if tails else 0)
            self._quad[tails] = _LagQuadrature(self.m, self.n_terms, reach)
        return self._quad[tails]

    def blocks(self, terms: Sequence[Term], nonlinear: Sequence[tuple]) -> tuple:
        """
        Per-pair covariance blocks of a model's random terms.

        Parameters
        ----------
        terms : sequence of Term
            The model's terms; deterministic ones (gcov None) are skipped.
        nonlinear : sequence of tuple
            Each term's nonlinear parameter values.

        Returns
        -------
        blocks : np.ndarray
            Shape (n_active, n_active, k, k): Sigma = sum_ab c_a c_b blocks[a, b]
            [unit^4 per unit coefficients].
        active : list of int
            Index into ``terms`` of each block row.

        """
        active = [i for i, t in enumerate(terms) if t.gcov is not None]
        quad = self._quadrature(any(terms[i].reach is not None for i in active))
        gammas, keys = [], []
        for i in active:
            # Sigma varies slowly with T: a grid of 2^(1/32) steps lets the IRLS steps,
            # profiles and bounds share the work.
            t, nl = terms[i], tuple(2.0 ** (round(32.0 * math.log2(v)) / 32.0)
                                    for v in nonlinear[i])
            key = (id(quad), t.name, nl)
            gamma = _lru_get(self._gammas, key, 24, lambda: quad.gamma(t, nl, self.dt))
            gammas.append(gamma)
            keys.append(key)
        blocks = _lru_get(self._blocks, tuple(keys), 256,
                          lambda: quad.blocks(gammas, self.scale))
        return blocks, active

    def sigma(self, terms: Sequence[Term], coef: np.ndarray, nonlinear: Sequence[tuple],
              coef_cov: np.ndarray | None = None):
        """
        Covariance matrix of the Allan estimates under a model.

        Sigma is quadratic in the coefficients, Sigma = sum_ab c_a c_b blocks[a, b]; with
        ``coef_cov`` the product c_a c_b is replaced by its expectation
        c_a c_b + cov(c_a, c_b) over uncertain coefficients.

        Parameters
        ----------
        terms : sequence of Term
            The model's terms; deterministic ones (gcov None) add nothing.
        coef : np.ndarray
            Shape (n_terms,), linear coefficients.
        nonlinear : sequence of tuple
            Each term's nonlinear parameter values.
        coef_cov : np.ndarray, optional
            Shape (n_terms, n_terms), covariance of the coefficients (same units).

        Returns
        -------
        np.ndarray
            Shape (k, k), covariance [unit^4].

        """
        blocks, active = self.blocks(terms, nonlinear)
        c = np.asarray(coef, dtype=np.float64)[active]
        moment = np.outer(c, c)
        if coef_cov is not None:
            moment = moment + np.asarray(coef_cov, dtype=np.float64)[np.ix_(active, active)]
        return np.einsum('ab,abij->ij', moment, blocks)


_COV_CACHE: dict = {}
#: Curves whose covariance machinery is kept: the six axes of one Allan curve share the
#: taus and term counts, so their quadrature nodes and the Sigma blocks of the terms
#: without nonlinear parameters are built once (about a third of a fit's time).  One
#: curve: its nodes and cached covariances take some 10-50 MB on a 3 h, 100 Hz record.
_COV_CACHE_SIZE = 1


def _shared_covariance(m: np.ndarray, n_terms: np.ndarray, dt: float,
                       n_samples: int) -> _CurveCovariance:
    """Return the cached :class:`_CurveCovariance` of a curve geometry (small LRU)."""
    key = (m.tobytes(), n_terms.tobytes(), float(dt), int(n_samples))
    cov = _COV_CACHE.pop(key, None)
    if cov is None:
        cov = _CurveCovariance(m, n_terms, dt, n_samples)
    _COV_CACHE[key] = cov            # most recent last
    while len(_COV_CACHE) > _COV_CACHE_SIZE:
        _COV_CACHE.pop(next(iter(_COV_CACHE)))
    return cov


# ------------------------------------------------------------------------- the GLS fit

@dataclass(frozen=True)
class _Slot:
    """One term of a model: its label, registry entry and nonlinear search bounds."""

    label: str
    term: Term
    bounds: tuple  # ((lo, hi), ...) per nonlinear parameter


class _Solution(NamedTuple):
    coef: np.ndarray       # (p,) linear coefficients (scaled units)
    phi: tuple             # per slot, tuple of nonlinear values
    j: float               # GLS chi-square


class _Data:
    """The curve in scaled units and the whitening of the current weight matrix."""

    def __init__(self, tau: np.ndarray, avar: np.ndarray, scale: float):
        self.tau = tau
        self.y = avar / scale
        self.scale = scale
        self.chol = None
        self.inv = None
        self.yw = None

    def set_sigma(self, sigma_scaled: np.ndarray) -> None:
        """Whiten with Sigma (scaled units); a tiny relative ridge keeps it definite."""
        s = 0.5 * (sigma_scaled + sigma_scaled.T)
        d = np.diag(s).copy()
        s = s + np.diag(1e-9 * d + 1e-300)
        for ridge in (0.0, 1e-7, 1e-5, 1e-3):
            try:
                self.chol = np.linalg.cholesky(s + np.diag(ridge * d))
                break
            except np.linalg.LinAlgError:
                continue
        else:
            self.chol = np.diag(np.sqrt(d))
        # numpy, not scipy.linalg: numpy's BLAS is held to one thread during a fit.
        self.inv = np.linalg.solve(self.chol, np.eye(d.size))
        self.yw = self.inv @ self.y

    def whiten(self, a: np.ndarray) -> np.ndarray:
        """Return L^-1 a for Sigma = L L^T."""
        return self.inv @ a


def _design(slots: Sequence[_Slot], tau: np.ndarray, phi: Sequence[tuple]) -> np.ndarray:
    """Design matrix (k, p): AVAR shape of each slot per unit coefficient."""
    return np.column_stack([s.term.shape(tau, *nl) for s, nl in zip(slots, phi)])


def _solve_linear(data: _Data, a: np.ndarray, fixed: np.ndarray | None = None):
    """Non-negative GLS coefficients for a fixed design; returns (coef, chi-square)."""
    aw = data.whiten(a)
    yw = data.yw if fixed is None else data.yw - data.whiten(fixed)
    norm = np.sqrt((aw ** 2).sum(axis=0))
    norm[norm == 0] = 1.0
    coef, rnorm = nnls(aw / norm, yw, maxiter=50 * a.shape[1] + 50)
    return coef / norm, rnorm ** 2


class _Fix(NamedTuple):
    """A parameter held fixed while the rest is fitted (profile intervals)."""

    slot: int              # index of the slot
    symbol: str            # the slot's reported symbol: its level or a nonlinear name
    value: float           # SI value of that symbol


def _families(slots: Sequence[_Slot]) -> list:
    """Group the interchangeable slots (two Gauss-Markov terms, two sinusoids)."""
    groups: dict[str, list[int]] = {}
    for i, s in enumerate(slots):
        if s.bounds:
            key = 'gm' if s.term.name in ('gauss_markov', 'bias_instability') else s.term.name
            groups.setdefault(key, []).append(i)
    return [g for g in groups.values() if len(g) > 1]


def _fit_fixed_w(data: _Data, slots: Sequence[_Slot], phi0: Sequence[tuple] | None = None,
                 fix: _Fix | None = None, local: bool = False,
                 grid_slots: Sequence[int] | None = None) -> _Solution:
    """
    Fit one model at the current weights: NNLS inside a search over phi.

    With ``fix`` one parameter is held at a value: a nonlinear one leaves the search, a
    level fixes that slot's coefficient (through ``Term.to_coef``, which depends on the
    slot's nonlinear parameters, e.g. S_B from B and T) and the other coefficients are
    fitted to the rest of the curve.  Interchangeable terms keep their order (first
    label, shortest T), so a profile cannot swap their roles.  ``local`` skips the grid
    and searches near ``phi0`` only (profiles move in small steps).  ``grid_slots``
    limits the grid sweeps to those slots' parameters (a term added to a fitted model:
    the others start where they are and move in the polish).
    """
    fixed_nl = {}
    fixed_level = None
    if fix is not None:
        term = slots[fix.slot].term
        if fix.symbol in term.nonlinear:
            fixed_nl[(fix.slot, term.nonlinear.index(fix.symbol))] = fix.value
        else:
            fixed_level = fix
    nl_all = [(i, j) for i, s in enumerate(slots) for j in range(len(s.bounds))]
    nl_index = [ij for ij in nl_all if ij not in fixed_nl]
    bounds = np.log(np.array([slots[i].bounds[j] for i, j in nl_index])).reshape(-1, 2)

    def unpack(x):
        vals = [list(p) for p in (phi0 if phi0 is not None else
                                  [[0.0] * len(s.bounds) for s in slots])]
        for (i, j), v in zip(nl_index, np.exp(np.clip(x, bounds[:, 0], bounds[:, 1]))):
            vals[i][j] = float(v)
        for (i, j), v in fixed_nl.items():
            vals[i][j] = float(v)
        return tuple(tuple(v) for v in vals)

    # Columns depend only on their own slot's nonlinear parameters: a search that moves
    # one of them (grid sweeps, profiles) reuses the others.
    columns: dict = {}

    def design(phi):
        cols = []
        for s, nl in zip(slots, phi):
            key = (s.label, nl)
            col = columns.get(key)
            if col is None:
                col = s.term.shape(data.tau, *nl)
                if len(columns) < 4096:
                    columns[key] = col
            cols.append(col)
        return np.column_stack(cols)

    def solve(phi):
        a = design(phi)
        if fixed_level is None:
            return _solve_linear(data, a)
        i = fixed_level.slot
        c_i = slots[i].term.to_coef(fixed_level.value, *phi[i]) / data.scale
        rest = [k for k in range(len(slots)) if k != i]
        coef_rest, j = _solve_linear(data, a[:, rest], fixed=a[:, i] * c_i)
        coef = np.empty(len(slots))
        coef[rest], coef[i] = coef_rest, c_i
        return coef, j

    if not nl_index:
        phi = unpack(np.zeros(0))
        coef, j = solve(phi)
        return _Solution(coef, phi, j)

    families = _families(slots)

    def objective(x):
        phi = unpack(x)
        for fam in families:
            t = [phi[i][0] for i in fam]
            if any(a > b for a, b in zip(t[:-1], t[1:])):
                return 1e300
        return solve(phi)[1]

    if phi0 is not None:
        x = np.log([phi0[i][j] for i, j in nl_index])
    else:
        x = bounds.mean(axis=1)
    x = np.clip(x, bounds[:, 0], bounds[:, 1])
    if local and phi0 is not None:
        if len(nl_index) == 1:
            lo, hi = max(x[0] - 1.5, bounds[0, 0]), min(x[0] + 1.5, bounds[0, 1])
            x[0] = _polish_1d(objective, lo, hi, x[0], objective(x))
        else:
            x = _polish_nd(objective, x, bounds)
        phi = unpack(x)
        coef, j = solve(phi)
        return _Solution(coef, phi, j)
    # Coordinate grid sweeps, then a local polish.
    sweep = [d for d, (i, _) in enumerate(nl_index) if grid_slots is None or i in grid_slots]
    for _ in range(1 if len(nl_index) == 1 or grid_slots is not None else 2):
        for d in sweep:
            grid = np.linspace(bounds[d, 0], bounds[d, 1], 41)
            vals = []
            for g in grid:
                x[d] = g
                vals.append(objective(x))
            best = int(np.argmin(vals))
            x[d] = grid[best]
            if len(nl_index) == 1:
                lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
                if hi > lo:
                    x[d] = _polish_1d(objective, lo, hi, x[d], vals[best])
    if len(nl_index) > 1:
        x = _polish_nd(objective, x, bounds)
    phi = unpack(x)
    coef, j = solve(phi)
    if fix is None:
        coef, phi = _canonical(slots, coef, phi)
    return _Solution(coef, phi, j)


def _polish_1d(objective, lo: float, hi: float, x0: float, f0: float) -> float:
    """Bounded 1-D minimisation of objective on [lo, hi]; keep x0 unless it improves on f0."""
    res = minimize_scalar(lambda v: objective(np.array([v])), bounds=(lo, hi),
                          method='bounded', options={'xatol': 1e-4})
    return float(res.x) if res.fun <= f0 else x0


def _polish_nd(objective, x: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Nelder-Mead from x, clipped to bounds (k, 2); keep x unless it improves."""
    # fatol in chi-square units: 1e-6 is far below what moves an interval or a choice.
    res = minimize(objective, x, method='Nelder-Mead',
                   options={'xatol': 1e-3, 'fatol': 1e-6, 'maxiter': 400})
    return np.clip(res.x, bounds[:, 0], bounds[:, 1]) if res.fun <= objective(x) else x


def _canonical(slots: Sequence[_Slot], coef: np.ndarray, phi: tuple) -> tuple:
    """
    Order interchangeable terms by their nonlinear parameter.

    Two Gauss-Markov terms (or two sinusoids) fit the same curve either way round; by
    convention the first label gets the shortest correlation time (the lowest
    frequency), so 'bias_instability' is the fastest Gauss-Markov term.
    """
    coef, phi = coef.copy(), list(phi)
    for members in _families(slots):
        order = sorted(members, key=lambda i: phi[i][0])
        new_coef = [coef[i] for i in order]
        new_phi = [phi[i] for i in order]
        for dst, c, p in zip(members, new_coef, new_phi):
            coef[dst], phi[dst] = c, p
    return coef, tuple(phi)


def _profile_interval(data: _Data, slots: Sequence[_Slot], sol: _Solution, slot: int,
                      symbol: str, value: float, threshold: float,
                      hard: tuple = (0.0, math.inf)) -> tuple[float, float]:
    """
    95 % profile interval of one parameter at fixed weights: {v : J(v) - J_min <= thr}.

    J(v) is the GLS chi-square minimised over every other parameter with this one held
    at v (non-negative coefficients, nonlinear parameters searched again), so the
    interval follows the curvature and the bounds of the real problem, not a quadratic
    approximation.  ``threshold`` is F(0.95; 1, dof) times the dispersion
    max(1, J_min / dof) (see :func:`fit_axis`).  ``hard`` are the limits of the
    parameter (a search range for nonlinear ones); a side that reaches one returns it.
    """
    target = sol.j + threshold

    last = {'phi': sol.phi}

    def excess(v):
        fit = _fit_fixed_w(data, slots, last['phi'], _Fix(slot, symbol, v), local=True)
        last['phi'] = fit.phi
        return fit.j - target

    def crossing(a: float, fa: float, b: float, fb: float) -> float:
        # Illinois regula falsi in log(v) (or v when the bracket touches 0), from the
        # bracket values already known: robust where the profile, found by local
        # searches, is not exactly monotone, and ~5 evaluations to 0.2 %.
        logs = a > 0 and b > 0
        xa, xb = (math.log(a), math.log(b)) if logs else (a, b)
        side = 0
        for _ in range(12):
            xc = xb - fb * (xb - xa) / (fb - fa) if fb != fa else 0.5 * (xa + xb)
            fc = excess(math.exp(xc) if logs else xc)
            if fc > 0:
                xb, fb = xc, fc
                if side == 1:
                    fa *= 0.5
                side = 1
            else:
                xa, fa = xc, fc
                if side == -1:
                    fb *= 0.5
                side = -1
            if abs(xb - xa) < (2e-3 if logs else 2e-3 * max(abs(xa), abs(xb))):
                break
        x = 0.5 * (xa + xb)
        return math.exp(x) if logs else x

    ends = []
    for direction in (-1.0, 1.0):
        last['phi'] = sol.phi
        inner, f_inner = value, -threshold
        limit = hard[0] if direction < 0 else hard[1]
        end = limit
        for _ in range(60):
            outer = inner * 1.3 ** direction
            if (direction < 0 and outer <= limit) or (direction > 0 and outer >= limit):
                if math.isfinite(limit):
                    f_limit = excess(limit) if limit > 0 else excess(0.0)
                    if f_limit > 0:
                        end = crossing(inner, f_inner, limit, f_limit)
                break
            f_outer = excess(outer)
            if f_outer > 0:
                end = crossing(inner, f_inner, outer, f_outer)
                break
            inner, f_inner = outer, f_outer
        ends.append(float(end))
    return ends[0], ends[1]


class _Fitter:
    """Everything a fit of one curve needs: data, covariance model, candidate slots."""

    def __init__(self, tau, avar, edf, m, n_terms, dt, n_samples, method):
        scale = float(np.median(avar))
        self.data = _Data(tau, avar, scale)
        self.edf = edf
        self.edf0 = np.clip(edf, 1.0, np.maximum(1.5 * n_terms / m, 1.0))
        self.cov = _shared_covariance(m, n_terms, dt, n_samples)
        self.method = method

    def sigma(self, slots, sol: _Solution, expected: bool = False) -> np.ndarray:
        """
        Model covariance of the curve (scaled units) at a solution.

        ``expected``: average Sigma over the coefficients' GLS uncertainty at the
        current weights (:meth:`_coef_cov`); used for the re-weighting steps.

        A coefficient fitted at zero sits on the edge of the parameter space, not at a
        certainty: in the covariance it keeps a floor of 10 % of the data at the tau
        where that term is largest relative to them.  Without it a random walk fitted at
        zero in a first step would make the long-tau points look exact, and the
        re-weighted fit would swing between models.
        """
        a = _design(slots, self.data.tau, sol.phi)
        floor = 0.1 * np.min(self.data.y[:, None] / np.maximum(a, 1e-300), axis=0)
        coef = np.maximum(sol.coef, floor)
        cov = self._coef_cov(a) * self.data.scale ** 2 if expected else None
        s = self.cov.sigma([x.term for x in slots], coef * self.data.scale, sol.phi, cov)
        s = s / self.data.scale ** 2 + self._sinusoid_cross(slots, sol)
        model = _design(slots, self.data.tau, sol.phi) @ sol.coef
        floor = 2.0 * (1e-3 * np.maximum(model, 1e-300)) ** 2
        if self.method == 'nonoverlapping':
            # Correlations of the overlapping model, variances from the given EDF.
            sd = np.sqrt(np.maximum(np.diag(s), 1e-300))
            want = model * np.sqrt(2.0 / self.edf)
            s = s / np.outer(sd, sd) * np.outer(want, want)
        return s + np.diag(floor)

    def _coef_cov(self, a: np.ndarray) -> np.ndarray:
        """
        GLS covariance (A^T Sigma^-1 A)^-1 of the coefficients at the current weights.

        Used for the *expected* covariance of the curve (:meth:`sigma`): the Sigma of
        the data is Sigma(c_true), and c_hat is uncertain.  A weight matrix built from
        c_hat alone follows its errors (a record whose long-tau points run low gets a
        small K, hence small variances there, hence more pull from those same low
        points); averaging Sigma over the coefficients' uncertainty breaks that loop.
        """
        aw = self.data.whiten(a)
        return np.linalg.pinv(aw.T @ aw)

    def _sinusoid_cross(self, slots, sol: _Solution) -> np.ndarray:
        """
        Spread a sinusoid adds by beating with the noise (scaled units).

        avar_p contains 2 mean_k(d_noise d_sin) / (2 tau_p^2); averaged over the random
        phase its covariance is, for records long against the lags (edge effects left
        out), 16 A^2 s_p^2 s_q^2 S_X(f0) / (pi^2 f0^2 dt tau_p^2 tau_q^2 max(n_p, n_q))
        with s = sin^2(pi f0 tau) and S_X the noise's two-sided phase PSD at f0.  The
        sinusoid's own part is deterministic up to edge effects and left out.
        """
        k = self.data.tau.size
        out = np.zeros((k, k))
        sines = [(i, s) for i, s in enumerate(slots) if s.term.name == 'sinusoid']
        if not sines:
            return out
        tau, dt = self.data.tau, self.cov.dt
        n = self.cov.n_terms.astype(np.float64)
        for i, s in sines:
            amp2, f0 = sol.coef[i], sol.phi[i][0]
            if amp2 <= 0:
                continue
            s_x = sum(c * x.term.psd_phase(f0, dt, *nl) for x, c, nl in
                      zip(slots, sol.coef, sol.phi) if x.term.psd_phase is not None)
            sp2 = np.sin(math.pi * f0 * tau) ** 4 / tau ** 2
            out += (16.0 * amp2 * s_x / (math.pi ** 2 * f0 ** 2 * dt) * np.outer(sp2, sp2)
                    / np.maximum.outer(n, n))
        return out

    def irls(self, slots, phi0=None, sigma0: np.ndarray | None = None,
             max_iter: int = 8, local: bool = False) -> tuple[_Solution, np.ndarray]:
        """
        Fit one model by iteratively re-weighted GLS; return the fit and Sigma at it.

        The first step uses the paper's weights 2 avar^2 / edf with the EDF capped at the
        white-noise value 1.5 n_terms / m (a long-tau EDF from a misidentified noise type
        would otherwise pin the fit to one point), or ``sigma0`` when given (the
        covariance of a related model already fitted).  Then the *expected* Sigma
        (Sigma(theta) averaged over the GLS uncertainty of the coefficients,
        :meth:`_coef_cov`) until the fitted curve moves by less than 1 % of its standard
        deviation at every tau.  The plug-in Sigma(theta) weights a record by its own
        estimate: where the long-tau points run low, K comes out small, their variances
        small and their pull large, so errors feed back.  On the u-blox accelerometer
        example (3 h, 50 seeds, bench/validate_fit.py) the expected Sigma brought the
        median error of K from 0.31 to 0.24 and of B from 0.067 to 0.052.  The returned
        Sigma, used for term selection and the profile intervals, is the plug-in one at
        the solution (the profile accounts for the parameters' uncertainty itself).
        """
        y = self.data.y
        self.data.set_sigma(np.diag(2.0 * y ** 2 / self.edf0) if sigma0 is None else sigma0)
        # local: the nonlinear parameters start at a fitted model's (an effect search
        # step) and are polished, not searched again over their whole ranges.
        sol = _fit_fixed_w(self.data, slots, phi0, local=local and phi0 is not None)
        for it in range(max_iter):
            if not np.any(sol.coef > 0):
                break
            sigma = self.sigma(slots, sol, expected=True)
            self.data.set_sigma(sigma)
            new = _fit_fixed_w(self.data, slots, sol.phi, local=local)
            before = _design(slots, self.data.tau, sol.phi) @ sol.coef
            after = _design(slots, self.data.tau, new.phi) @ new.coef
            sol = new
            if np.all(np.abs(after - before) < 0.01 * np.sqrt(np.diag(sigma))):
                break
        sigma = self.sigma(slots, sol) if np.any(sol.coef > 0) else np.diag(
            2.0 * y ** 2 / self.edf0)
        self.data.set_sigma(sigma)
        return sol, sigma


def _slot(label: str, tau: np.ndarray, rate_hz: float) -> _Slot:
    base = base_name(label)
    term = TERMS[base]
    bounds = []
    for name in term.nonlinear:
        if name in ('T', 'T_B'):
            # The bump (at 1.89 T) must fall inside the record: a shorter T is white
            # noise to the curve, a longer one random walk.
            bounds.append((2.0 * tau.min(), tau.max()))
        elif name == 'T_f':
            # The sensor's filter: from a tiny fraction of a sample period to a few.
            bounds.append((0.01 / rate_hz, 4.0 / rate_hz))
        elif name == 'f0_hz':
            bounds.append((0.371 / (2.0 * tau.max()), min(0.742 / tau.min(), 0.5 * rate_hz)))
        else:  # pragma: no cover - a registry entry without search bounds
            raise InputError(f'no search range for parameter {name} of term {label}')
    return _Slot(label, term, tuple(bounds))


def _n_params(slots: Sequence[_Slot]) -> int:
    return sum(1 + len(s.bounds) for s in slots)


def _symbols(slots: Sequence[_Slot]) -> dict:
    """Map every (label, symbol) pair of the candidate slots to its reported name."""
    out, used = {}, set()
    for s in slots:
        base = base_name(s.label)
        for sym in s.term.symbols:
            plain = sym in _PLAIN.get(base, ()) and s.label == base
            name = sym if plain and sym not in used else f'{s.label}.{sym}'
            used.add(name)
            out[(s.label, sym)] = name
    return out


def _check_inputs(tau, avar, edf, rate_hz, n_samples):
    tau = np.atleast_1d(np.asarray(tau, dtype=np.float64))
    avar = np.atleast_1d(np.asarray(avar, dtype=np.float64))
    edf = np.atleast_1d(np.asarray(edf, dtype=np.float64))
    if not (tau.shape == avar.shape == edf.shape and tau.ndim == 1):
        raise InputError('tau, avar and edf must be 1-D arrays of the same length, got '
                         f'{tau.shape}, {avar.shape}, {edf.shape}')
    if not (isinstance(rate_hz, (int, float, np.integer, np.floating))
            and math.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
    if int(n_samples) != n_samples or n_samples < 4:
        raise InputError(f'number of samples must be an integer >= 4, got {n_samples!r}')
    ok = np.isfinite(tau) & np.isfinite(avar) & np.isfinite(edf) & (avar > 0) & (edf > 0)
    order = np.argsort(tau[ok])
    return tau[ok][order], avar[ok][order], edf[ok][order]


def _thin(tau: np.ndarray, per_octave: float = 2.0) -> np.ndarray:
    """Return the indices that keep at most ``per_octave`` points per octave of tau."""
    keep, last = [], -np.inf
    for i, t in enumerate(np.log2(tau)):
        if t - last >= 1.0 / per_octave - 1e-9:
            keep.append(i)
            last = t
    return np.array(keep, dtype=np.int64)


def _filtered_start(tau: np.ndarray, avar: np.ndarray, rate_hz: float) -> int:
    """
    Return the index of the first tau to fit: leading taus bent by the sensor's filter.

    Real IMUs low-pass filter (anti-aliasing, decimation) before they output samples, so
    at the first few cluster sizes neighbouring samples are correlated and the curve is
    flatter than the white-noise slope of -1/2 (no noise term of the model does that:
    quantization is steeper).  Those points carry the largest EDF, so left in they
    would pull N below the density that matters at longer tau and recruit a fast
    Gauss-Markov term to bridge the bend.  Leading points whose ADEV slope to the next
    point is above -0.48 are dropped, at most those below 64 sample periods; a white
    record keeps them all (its slope noise there is ~0.003).
    """
    first = 0
    slope = 0.5 * np.diff(np.log(avar)) / np.diff(np.log(tau))
    while (first < slope.size and tau[first] * rate_hz < 64.0 and slope[first] > -0.48
           and tau.size - first > 3):
        first += 1
    return first


def fit_axis(curve_tau_s, avar, edf, rate_hz: float, n_samples: int, *,
             terms: Sequence[str] | None = None, unit: str = 'unit',
             method: str = 'overlapping', select: bool = True,
             phi0: dict | None = None, sigma0: np.ndarray | None = None) -> AxisFit:
    """
    Fit the noise model of one axis to its Allan curve (nominal and optimised).

    Parameters
    ----------
    curve_tau_s : array_like
        Shape (k,), averaging times [s], multiples of 1 / rate_hz.
    avar : array_like
        Shape (k,), overlapping Allan variance [unit^2].
    edf : array_like
        Shape (k,), equivalent degrees of freedom of each estimate (the nominal
        intervals and the first weights; the optimised fit then uses the model's own
        covariance).
    rate_hz : float
        Sample rate [Hz].
    n_samples : int
        Number of samples the curve was computed from.
    terms : sequence of str, optional
        Candidate terms (names of :data:`imu_allan.core.model.TERMS`, numbered for repeats:
        'gauss_markov', 'gauss_markov_2', 'sinusoid' ...).  Default
        :data:`DEFAULT_TERMS`.  The fit keeps the subset the data support.
    unit : str
        Unit of the samples ('rad/s', 'm/s^2'), used in the parameter units.
    method : str
        Estimator of the curve: 'overlapping' (exact covariance) or 'nonoverlapping'
        (overlapping correlations, variances from ``edf``).
    select : bool
        True: keep the subset of ``terms`` the data support (AIC over every subset).
        False: ``terms`` were already selected (:mod:`imu_allan.core.search`); fit them
        all, and report a term whose coefficient comes out zero as a bound.
    phi0 : dict of str to tuple, optional
        Starting nonlinear parameters per term label (the search's values); a
        sinusoid's frequency then stays within 20 % of its start (a line the
        periodogram confirmed).
    sigma0 : np.ndarray, optional
        Shape (k, k), covariance of the thinned curve to start the re-weighting from
        (the search's last one, in the fit's scaled units), instead of the paper's
        diagonal weights.

    Returns
    -------
    AxisFit
        Nominal and optimised parameters with 95 % intervals, the selected model and
        notes.

    Raises
    ------
    InputError
        Mismatched arrays, a bad rate, an unknown term, or fewer than 3 usable taus.

    """
    # The matrices are tiny (k ~ 20-30 taus): OpenBLAS threads only add overhead and
    # oversubscribe a busy machine (measured: 2-3x slower wall time with them).
    with _single_thread_blas():
        return _fit_axis(curve_tau_s, avar, edf, rate_hz, n_samples, terms, unit, method,
                         select, phi0, sigma0)


def _fit_axis(curve_tau_s, avar, edf, rate_hz, n_samples, terms, unit, method,
              select=True, phi0=None, sigma0=None) -> AxisFit:
    """Body of :func:`fit_axis` (same arguments)."""
    tau, avar, edf = _check_inputs(curve_tau_s, avar, edf, rate_hz, n_samples)
    if method not in ('overlapping', 'nonoverlapping'):
        raise InputError(f'the fit needs an Allan curve (overlapping or nonoverlapping), '
                         f'got method {method!r}')
    candidates = tuple(DEFAULT_TERMS if terms is None else terms)
    for label in candidates:
        try:
            base_name(label)
        except KeyError:
            raise InputError(f'unknown noise term {label!r}; known: '
                             f'{", ".join(sorted(TERMS))}') from None
    if len(set(candidates)) != len(candidates):
        raise InputError('each term may appear once; number repeats, e.g. gauss_markov_2')
    nominal = nominal_fit(tau, avar, edf, unit)
    keep = _thin(tau)
    tau, avar, edf = tau[keep], avar[keep], edf[keep]
    notes: list[str] = []
    # With the filtered_white term the filter is part of the model, not cut away.
    first = 0 if 'filtered_white' in candidates else _filtered_start(tau, avar, rate_hz)
    if first:
        notes.append(f'tau < {tau[first]:.3g} s left out: flatter than white noise there '
                     "(the sensor's low-pass filter)")
        tau, avar, edf = tau[first:], avar[first:], edf[first:]
    if tau.size < 3:
        raise InputError(f'the fit needs at least 3 averaging times, got {tau.size}')
    dt = 1.0 / float(rate_hz)
    m = np.maximum(np.round(tau * rate_hz), 1).astype(np.int64)
    n_terms = np.maximum(int(n_samples) + 1 - 2 * m, 1)
    fitter = _Fitter(tau, avar, edf, m, n_terms, dt, int(n_samples), method)
    slots_all = [_slot(lbl, tau, rate_hz) for lbl in candidates]
    start = None
    if phi0:
        start = [tuple(phi0.get(s.label, [math.sqrt(lo * hi) for lo, hi in s.bounds]))
                 for s in slots_all]
        slots_all = [replace(s, bounds=((p[0] / 1.2, p[0] * 1.2),))
                     if s.term.name == 'sinusoid' and s.label in phi0 else s
                     for s, p in zip(slots_all, start)]
    symbols = _symbols(slots_all)

    # Full candidate model, then every subset at its weights (AIC).
    if sigma0 is not None and np.shape(sigma0) != (tau.size, tau.size):
        sigma0 = None
    full_sol, full_sigma = fitter.irls(slots_all, phi0=start, sigma0=sigma0,
                                       local=start is not None)
    fitter.data.set_sigma(full_sigma)
    phi_full = dict(zip([s.label for s in slots_all], full_sol.phi))
    best = None
    if not select:
        kept = tuple(i for i, c in enumerate(full_sol.coef) if c > 0)
        best = (0.0, kept) if kept else None
    for r in range(1, len(slots_all) + 1 if select else 1):
        for subset in combinations(range(len(slots_all)), r):
            slots = [slots_all[i] for i in subset]
            if _n_params(slots) >= tau.size:
                continue
            sol = _fit_fixed_w(fitter.data, slots, [phi_full[s.label] for s in slots])
            if np.any(sol.coef <= 0):
                continue  # a zero term: the same fit as a smaller subset
            ic = sol.j + IC_PENALTY * _n_params(slots)
            if best is None or ic < best[0]:
                best = (ic, subset)
    if best is None:
        raise InputError('no noise term fits this curve (all coefficients zero)')
    supported = {slots_all[i].label for i in best[1]}
    # Values and intervals come from the supported terms plus the paper's core terms
    # (white, bias instability, random walk) even where the data do not support them:
    # a weak random walk dropped from the fit would push B and T_B up and make their
    # intervals too narrow.  Other unsupported candidates (quantization, say) are left
    # out, since keeping them only blurs N.  The selection decides what is reported as
    # an estimate and what as an upper bound.
    slots = [s for s in slots_all if s.label in supported or s.term.name in _CORE_TERMS]
    if len(slots) == len(slots_all):
        sol, sigma = full_sol, full_sigma
        fitter.data.set_sigma(sigma)
    else:
        sol, sigma = fitter.irls(slots, phi0=[phi_full[s.label] for s in slots],
                                 sigma0=full_sigma)
    # J at exactly these weights (from the search's model: a polish, not a new search).
    sol = _fit_fixed_w(fitter.data, slots, sol.phi, local=start is not None)
    chi2_value = float(sol.j)
    dof = int(tau.size - _n_params(slots))
    # Sigma is the model's own covariance of the curve (checked against Monte Carlo in
    # test_fit.py), so the scale is known and the threshold is the chi-square quantile
    # (likelihood-ratio interval, Bates & Watts 1988).  Where the model fits worse than
    # that covariance allows (J / dof > 1: an effect the model lacks, or a Sigma too
    # small because it was evaluated at an estimate whose long-tau points run low), the
    # observed dispersion scales the threshold up, with the F quantile for a dispersion
    # that is itself estimated.
    dispersion = chi2_value / dof if dof > 0 else 0.0
    if dispersion > 1.0:
        threshold = fdist.ppf(0.95, 1, dof) * dispersion
    else:
        threshold = chi2.ppf(0.95, 1)

    optimised: dict[str, Param] = {}
    values: dict[str, dict] = {}
    for i, s in enumerate(slots):
        if s.label not in supported:
            continue
        c_si = sol.coef[i] * fitter.data.scale
        params = s.term.to_params(c_si, *sol.phi[i])
        values[s.label] = params
        for sym, template in zip(s.term.symbols, s.term.units):
            v = params[sym]
            kind = 'estimate'
            if sym not in s.term.nonlinear:
                ci = _profile_interval(fitter.data, slots, sol, i, sym, v, threshold)
            else:
                lo_b, hi_b = s.bounds[s.term.nonlinear.index(sym)]
                ci = _profile_interval(fitter.data, slots, sol, i, sym, v, threshold,
                                       (lo_b, hi_b))
                if ci[1] >= hi_b * 0.999:
                    kind, ci = 'lower_bound', (ci[0], math.inf)
                    notes.append(f'{symbols[(s.label, sym)]}: may exceed the longest tau '
                                 'of the record; only a lower bound')
                elif ci[0] <= lo_b * 1.001:
                    notes.append(f'{symbols[(s.label, sym)]}: may lie below the shortest '
                                 'tau; poorly identified')
            optimised[symbols[(s.label, sym)]] = Param(
                float(v), (float(ci[0]), float(ci[1])), kind, _unit(template, unit))

    # Candidates the data do not support: an upper bound for core or requested terms.
    for s in slots_all:
        if s.label in supported:
            continue
        if s.term.name not in _CORE_TERMS and terms is None:
            notes.append(f'{s.label}: not supported by the data (left out)')
            continue
        others = [i for i, x in enumerate(slots) if x.label != s.label]
        rest = _Solution(sol.coef[others], tuple(sol.phi[i] for i in others), sol.j)
        if s.label not in [x.label for x in slots]:    # a requested extra term
            others, rest = list(range(len(slots))), sol
        bound = _upper_bound(fitter, [slots[i] for i in others], rest, s)
        lin_sym = s.term.symbols[0]
        name = symbols[(s.label, lin_sym)]
        if math.isfinite(bound) and bound > 0:
            optimised[name] = Param(bound, (0.0, bound), 'upper_bound',
                                    _unit(s.term.units[0], unit))
            notes.append(f'{name}: not supported by the data (too small or the record too '
                         'short); 95 % upper bound')
        else:
            # A degenerate bound (0 or inf): the record cannot constrain the term at all.
            optimised[name] = Param(math.nan, (math.nan, math.nan), 'not_identified',
                                    _unit(s.term.units[0], unit))
            notes.append(f'{name}: the record cannot constrain it (too short); no bound')
        for sym, template in zip(s.term.symbols[1:], s.term.units[1:]):
            optimised[symbols[(s.label, sym)]] = Param(
                math.nan, (math.nan, math.nan), 'not_identified', _unit(template, unit))
    for sym, base in CORE_PARAMS.items():
        if sym not in optimised:
            units = dict(zip(TERMS[base].symbols, TERMS[base].units))
            optimised[sym] = Param(math.nan, (math.nan, math.nan), 'not_identified',
                                   _unit(units.get(sym, 'u'), unit))
            if base not in [base_name(x) for x in candidates]:
                notes.append(f'{sym}: not modelled (term {base} not among the candidates)')
    if dof > 0 and chi2.sf(chi2_value, dof) < 1e-3:
        notes.append(f'the model does not explain the curve (chi2 {chi2_value:.1f} for '
                     f'{dof} dof): a missing effect? (imu-allan diagnose)')
    order = ['N', 'B', 'T_B', 'K']
    rest = sorted(k for k in optimised if k not in order)
    optimised = {k: optimised[k] for k in order + rest}
    # The model keeps the core terms reported as bounds at their point estimates: it is
    # the curve the data support best, e.g. for simulation and diagnosis.
    for i, s in enumerate(slots):
        if s.label not in values and s.term.name in _CORE_TERMS:
            values[s.label] = s.term.to_params(sol.coef[i] * fitter.data.scale, *sol.phi[i])
    avar_fit = _design(slots, tau, sol.phi) @ sol.coef * fitter.data.scale
    components = tuple((s.label, float(c * fitter.data.scale), tuple(p))
                       for s, c, p in zip(slots, sol.coef, sol.phi) if c > 0)
    return AxisFit(nominal=nominal, optimised=optimised, model=noise_from_terms(values),
                   terms=tuple(s.label for s in slots if s.label in supported),
                   notes=tuple(notes), chi2=chi2_value, dof=dof, tau_s=tau,
                   avar_fit=avar_fit, avar_sd=np.sqrt(np.diag(sigma)) * fitter.data.scale,
                   avar_meas=avar, edf=edf, components=components)


def _upper_bound(fitter: _Fitter, slots: list, sol: _Solution, extra: _Slot) -> float:
    """
    One-sided 95 % upper bound of an unsupported term's level (its first symbol).

    The selected model plus the term is fitted by unconstrained GLS at the selected
    model's weights, so the term's coefficient is a fixed linear combination
    c_hat = g^T avar of the Allan estimates.  The bound is the coefficient c0 at which
    P(c_hat <= observed | c0) = 5 %, with the covariance evaluated *under* c0 (a bound
    computed with the covariance of a model without the term would be far too tight):
    c_hat = c0 X + e, X ~ chi2_nu / nu for the term's own part (nu = 2 c0^2 / its
    variance, Satterthwaite) and e Gaussian with the rest of the variance.  A term with
    a nonlinear parameter (Gauss-Markov T) takes the largest bound over a grid of it
    within the observed tau range.
    """
    tau = fitter.data.tau
    grid: list = [()]
    if extra.bounds:
        lo, hi = extra.bounds[0]
        if extra.term.name in ('gauss_markov', 'bias_instability'):
            lo, hi = tau.min() / GM_PEAK_TAU, tau.max() / GM_PEAK_TAU
        grid = [(float(g),) for g in np.geomspace(lo, hi, 6)]
    base = _design(slots, tau, sol.phi)
    best = 0.0
    for nl in grid:
        a = np.column_stack([base, extra.term.shape(tau, *nl)])
        aw = fitter.data.whiten(a)
        g = np.linalg.pinv(aw)[-1] @ fitter.data.inv      # c_hat = g @ y (scaled units)
        c_obs = float(g @ fitter.data.y)
        terms = [s.term for s in slots] + [extra.term]
        blocks, active = fitter.cov.blocks(terms, list(sol.phi) + [nl])
        quad = np.einsum('i,abij,j->ab', g, blocks, g)
        coef = np.append(sol.coef, 0.0)[active]
        x = len(terms) - 1
        v0 = float(coef @ quad @ coef)
        if x in active:
            ix = active.index(x)
            v1 = float(coef @ quad[:, ix])
            v2 = float(quad[ix, ix])
        else:
            v1 = v2 = 0.0
        c_ub = _one_sided_bound(c_obs, v0, v1, v2)
        if not math.isfinite(c_ub):
            return math.inf
        value = extra.term.to_params(c_ub * fitter.data.scale, *nl)[extra.term.symbols[0]]
        best = max(best, value)
    return float(best)


def _one_sided_bound(c_obs: float, v0: float, v1: float, v2: float) -> float:
    """Smallest c0 with P(c0 X + e <= c_obs) <= 5 % (see :func:`_upper_bound`)."""
    v0 = max(v0, 0.0)
    if v2 <= 0.0:
        return max(c_obs, 0.0) + Z95_ONE_SIDED * math.sqrt(v0)
    nu = 2.0 / v2
    u = (np.arange(256) + 0.5) / 256.0
    x = chi2.ppf(u, nu) / nu

    def prob(c0: float) -> float:
        s_e = math.sqrt(max(v0 + 2.0 * c0 * v1, 1e-300))
        return float(np.mean(ndtr((c_obs - c0 * x) / s_e)))

    scale = max(abs(c_obs), math.sqrt(v0), 1e-300)
    lo, hi = 0.0, scale
    if prob(lo) <= 0.05:
        return 0.0
    while prob(hi) > 0.05:
        lo, hi = hi, hi * 4.0
        if hi > 1e8 * scale:
            return math.inf
    return float(brentq(lambda c: prob(c) - 0.05, lo, hi, xtol=1e-6 * hi))


def fit_curve(curve: AllanCurve, axis_index: int, n_samples: int | None = None, *,
              terms: Sequence[str] | None = None, unit: str | None = None) -> AxisFit:
    """
    Fit one axis of an :class:`~imu_allan.core.allan.AllanCurve` (batch or streaming).

    Parameters
    ----------
    curve : AllanCurve
        The curve; ``curve.method`` must be 'overlapping' or 'nonoverlapping'.
    axis_index : int
        Column of ``curve.avar`` to fit.
    n_samples : int, optional
        Number of samples behind the curve; default from the shortest tau's term count
        (n_terms + 2 m - 1 for the overlapping estimator, (n_terms + 1) m otherwise).
    terms : sequence of str, optional
        Candidate terms, see :func:`fit_axis`.
    unit : str, optional
        Unit of the samples; default from ``imu_allan.AXIS_UNITS`` when the curve has
        the six contract axes, else 'unit'.

    Returns
    -------
    AxisFit
        See :func:`fit_axis`.

    """
    from imu_allan import AXES, AXIS_UNITS

    avar = np.asarray(curve.avar)
    if avar.ndim == 1:
        avar = avar[:, None]
    edf = np.asarray(curve.edf)
    if edf.ndim == 1:
        edf = edf[:, None]
    if not 0 <= axis_index < avar.shape[1]:
        raise InputError(f'axis index {axis_index} outside 0..{avar.shape[1] - 1}')
    if curve.method not in ('overlapping', 'nonoverlapping'):
        raise InputError(f'the fit needs an Allan curve (overlapping or nonoverlapping), '
                         f'got a {curve.method} curve')
    if n_samples is None:
        m0, n0 = int(np.asarray(curve.m)[0]), int(np.asarray(curve.n_terms)[0])
        n_samples = n0 + 2 * m0 - 1 if curve.method == 'overlapping' else (n0 + 1) * m0
    if unit is None:
        unit = AXIS_UNITS[AXES[axis_index]] if avar.shape[1] == len(AXES) else 'unit'
    return fit_axis(curve.tau_s, avar[:, axis_index], edf[:, axis_index], curve.rate_hz,
                    n_samples, terms=terms, unit=unit, method=curve.method)
