"""
The white + random-walk pair whose Allan variance covers a whole fitted model.

Kalibr, OpenVINS, VINS, ORB-SLAM3 and most EKFs model an IMU axis as white noise
(density N) plus a bias random walk (density K).  A real sensor also has bias
instability (flicker or Gauss-Markov), further Gauss-Markov terms, lines and ramps, and
on a short record K is only a 95 % upper bound.  Given only the fitted N and K, such a
filter under-states how far the bias wanders over seconds to minutes and becomes
over-confident; the usual cure is an inflation factor guessed between 10 and 50.

This module derives it instead.  For the averaging times an estimator cares about,
tau in [tau_min, tau_max] (default: the sample period to 100 s), it finds the pair
(N_c, K_c) whose Allan variance (IEEE Std 952 C.1)::

    AVAR_c(tau) = N_c^2 / tau + K_c^2 tau / 3

lies on or above the fitted model's Allan variance at every tau of the horizon, and
among those pairs the one that over-states the model least in the worst case
(minimises max_tau AVAR_c / envelope, a linear programme in N_c^2 and K_c^2; the
envelope is the model's running maximum over +-0.15 decade, which ignores the nulls of a
sinusoid's AVAR; solved by a search on N_c^2, numpy only, so the process that writes the
reports needs no scipy).  The
model covered is every fitted term; a core term reported only as a 95 % upper bound
(N or K on a record too short to see it) enters at that bound.  The factors N_c / N and
K_c / K are the inflation, per axis, with the horizon that justifies them.

A random-walk filter whose AVAR covers the sensor's is conservative on every averaging
time within the horizon, which is what its bias covariance has to be over a VIO window
(seconds) or a GNSS outage (minutes); docs/outputs.md shows the consistency it gives.
"""

import math
from typing import NamedTuple, Sequence

import numpy as np

from imu_allan import AXES
from imu_allan.core.noise.model import avar_model
from imu_allan.core.noise.values import AxisNoise
from imu_allan.errors import InputError

#: Default upper end of the horizon [s]: a GNSS/INS outage or a long VIO drift.
DEFAULT_HORIZON_S = 100.0
#: Taus per decade on which the cover is enforced (log-spaced).
TAUS_PER_DECADE = 100
#: Half-width of the envelope the over-statement is measured against [decades]: a
#: sinusoid's AVAR has nulls (tau = k / f0) where any smooth pair over-states it without
#: bound, so the ratio is taken against the model's running maximum over +-0.15 decade.
ENVELOPE_DECADES = 0.15
#: Steps of the ternary search on N_c^2 (each keeps 2/3 of the interval).
SEARCH_STEPS = 120
#: Weight of the mean over-statement beside the worst one in the search (a tie-break).
TIE_BREAK = 1e-3


class AxisCover(NamedTuple):
    """
    Fitted and covering white / random-walk densities of one axis.

    Attributes
    ----------
    N_fit, K_fit : float
        The fitted N [unit*s^0.5] and K [unit/s^0.5] (either at its 95 % bound where it
        is only a bound); 0.0 where the model has no such term.
    N_cover, K_cover : float
        The covering pair, same units.
    factor_N, factor_K : float or None
        N_cover / N_fit and K_cover / K_fit; None where the fitted value is 0.
    horizon_s : tuple of float
        (tau_min, tau_max) [s] over which AVAR_c >= AVAR_model holds.
    worst_ratio : float
        max over the horizon of AVAR_c / the model's envelope (>= 1): how conservative
        the pair is at its most conservative tau.

    """

    N_fit: float
    K_fit: float
    N_cover: float
    K_cover: float
    factor_N: float | None
    factor_K: float | None
    horizon_s: tuple
    worst_ratio: float

    def to_json(self) -> dict:
        """Return the pair as a JSON-ready dict (SI units)."""
        return {'fitted': {'N': self.N_fit, 'K': self.K_fit},
                'covering': {'N': self.N_cover, 'K': self.K_cover},
                'factor': {'N': self.factor_N, 'K': self.factor_K},
                'horizon_s': list(self.horizon_s), 'worst_ratio': self.worst_ratio}


def horizon_taus(horizon_s: Sequence[float]) -> np.ndarray:
    """
    Log-spaced taus of a horizon, :data:`TAUS_PER_DECADE` per decade, ends included.

    Parameters
    ----------
    horizon_s : sequence of two floats
        (tau_min, tau_max) [s], 0 < tau_min < tau_max.

    Returns
    -------
    np.ndarray
        Shape (k,), k >= 2, taus [s].

    """
    lo, hi = (float(v) for v in horizon_s)
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
        raise InputError(f'covering horizon must be 0 < tau_min < tau_max seconds, got '
                         f'{lo!r}, {hi!r}')
    n = max(2, int(math.ceil(TAUS_PER_DECADE * math.log10(hi / lo))) + 1)
    return np.geomspace(lo, hi, n)


def _fitted(source) -> tuple[float, float]:
    """N and K of a source, at the 95 % bound where only a bound; 0.0 where absent."""
    if isinstance(source, AxisNoise):
        return float(source.N), float(source.K)
    values = []
    for sym in ('N', 'K'):
        p = source.optimised.get(sym)
        ok = (p is not None and math.isfinite(p.value)
              and p.kind in ('estimate', 'upper_bound'))
        values.append(float(p.value) if ok else 0.0)
    return values[0], values[1]


def model_avar(source, tau_s: np.ndarray) -> np.ndarray:
    """
    Allan variance to cover: the whole fitted model, N and K at least at their bounds.

    Parameters
    ----------
    source : AxisNoise or imu_allan.core.fit.AxisFit
        A model, or a fit (every fitted term, :meth:`AxisFit.avar_at`).
    tau_s : np.ndarray
        Shape (k,), averaging times [s].

    Returns
    -------
    np.ndarray
        Shape (k,), AVAR [unit^2].

    """
    if isinstance(source, AxisNoise):
        return avar_model(tau_s, source)
    if not hasattr(source, 'avar_at'):
        raise InputError(f'expected an AxisNoise or an AxisFit, got {type(source).__name__}')
    avar = np.asarray(source.avar_at(tau_s), dtype=np.float64)
    # The fit's own curve holds N and K at their point estimates; where either is only
    # an upper bound, cover the bound (the record could not rule it out).
    n_fit, k_fit = _fitted(source)
    n_model, k_model = source.model.N, source.model.K
    avar = avar + max(0.0, n_fit ** 2 - n_model ** 2) / tau_s
    return avar + max(0.0, k_fit ** 2 - k_model ** 2) * tau_s / 3.0


def _envelope(values: np.ndarray) -> np.ndarray:
    """Return the running maximum over +-ENVELOPE_DECADES of a curve on the taus grid."""
    half = int(round(ENVELOPE_DECADES * TAUS_PER_DECADE))
    padded = np.pad(values, half, mode='edge')
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1)
    return windows.max(axis=1)


def cover_axis(source, horizon_s: Sequence[float]) -> AxisCover | None:
    """
    Find the white + random-walk pair covering one axis' model over a horizon.

    Solves min t subject to AVAR_c(tau) >= AVAR_model(tau) and AVAR_c(tau) <= t E(tau)
    at every tau of :func:`horizon_taus`, with AVAR_c = N_c^2 / tau + K_c^2 tau / 3 and E
    the model's envelope.  This is a linear programme in x = N_c^2, y = K_c^2, t: for a
    given x the smallest covering y(x) is the largest (AVAR_model - x / tau) 3 / tau
    (convex in x, a maximum of lines), and t(x) = max (x / tau + y(x) tau / 3) / E is
    convex too, so a ternary search on x finds the optimum.  Among pairs with the same
    t, the one with the least mean over-statement of the model is taken.

    Parameters
    ----------
    source : AxisNoise or imu_allan.core.fit.AxisFit
        The axis model or fit.
    horizon_s : sequence of two floats
        (tau_min, tau_max) [s].

    Returns
    -------
    AxisCover or None
        None when the model has no noise on the horizon (an empty model).

    """
    tau = horizon_taus(horizon_s)
    m = model_avar(source, tau)
    if not np.all(np.isfinite(m)) or not np.all(m > 0):
        return None
    env = _envelope(m)
    # Scale the unknowns so both are O(1): x = N_c^2 / x0, y = K_c^2 / y0.
    x0, y0 = float(np.max(m * tau)), float(np.max(3.0 * m / tau))
    a, b = x0 / (tau * m), y0 * tau / (3.0 * m)
    ea, eb = a * m / env, b * m / env

    def y_of(x: float) -> float:
        return max(0.0, float(np.max((1.0 - a * x) / b)))

    def t_of(x: float) -> float:
        # The worst over-statement, and a thousandth of the mean one to choose among
        # pairs of the same worst case (the envelope lets several reach it).
        y = y_of(x)
        return float(np.max(ea * x + eb * y) + TIE_BREAK * np.mean(a * x + b * y))

    # x = 1 covers every tau with y = 0 (x0 is the largest AVAR tau), so x is in [0, 1].
    lo, hi = 0.0, 1.0
    for _ in range(SEARCH_STEPS):
        m1, m2 = lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0
        if t_of(m1) <= t_of(m2):
            hi = m2
        else:
            lo = m1
    x = 0.5 * (lo + hi)
    y = y_of(x)
    # Round-off of the search: restore the cover exactly (scale up by the worst shortfall).
    short = float(np.max(1.0 / np.maximum(a * x + b * y, 1e-300)))
    x, y = x * max(short, 1.0), y * max(short, 1.0)
    n_c, k_c = math.sqrt(x * x0), math.sqrt(y * y0)
    n_fit, k_fit = _fitted(source)
    ratio = float(np.max((n_c ** 2 / tau + k_c ** 2 * tau / 3.0) / env))
    return AxisCover(N_fit=n_fit, K_fit=k_fit, N_cover=n_c, K_cover=k_c,
                     factor_N=(n_c / n_fit if n_fit > 0 else None),
                     factor_K=(k_c / k_fit if k_fit > 0 else None),
                     horizon_s=(float(tau[0]), float(tau[-1])), worst_ratio=ratio)


def default_horizon(rate_hz: float, tau_max_s: float = DEFAULT_HORIZON_S) -> tuple:
    """
    Return (1 / rate_hz, tau_max_s): the sample period to the longest tau of interest.

    Parameters
    ----------
    rate_hz : float
        Sample rate [Hz].
    tau_max_s : float
        Upper end [s].

    Returns
    -------
    tuple of float
        (tau_min, tau_max) [s].

    """
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f'sample rate must be a positive number of Hz, got {rate_hz!r}')
    if not tau_max_s > 1.0 / rate_hz:
        raise InputError(f'the covering horizon must end after one sample period '
                         f'({1.0 / rate_hz:g} s), got {tau_max_s!r} s')
    return (1.0 / float(rate_hz), float(tau_max_s))


def cover_axes(sources, horizon_s: Sequence[float]) -> dict:
    """
    :func:`cover_axis` of every axis.

    Parameters
    ----------
    sources : mapping of str to AxisNoise or AxisFit
        Per axis name (AXES).
    horizon_s : sequence of two floats
        (tau_min, tau_max) [s].

    Returns
    -------
    dict of str to AxisCover or None
        Per axis, in AXES order.

    """
    return {a: cover_axis(sources[a], horizon_s) for a in AXES if a in sources}


def sensor_cover(covers: dict, axes: Sequence[str]) -> tuple[float | None, float | None]:
    """
    One covering (N_c, K_c) for a sensor's three axes: the largest of each.

    The largest covers every axis (each axis' pair covers its own model, and raising
    either density only raises the pair's AVAR).

    Parameters
    ----------
    covers : dict of str to AxisCover or None
        From :func:`cover_axes`.
    axes : sequence of str
        The sensor's axes.

    Returns
    -------
    tuple
        (N_c, K_c), None where no axis has a pair.

    """
    got = [covers[a] for a in axes if covers.get(a) is not None]
    if not got:
        return None, None
    return max(c.N_cover for c in got), max(c.K_cover for c in got)
