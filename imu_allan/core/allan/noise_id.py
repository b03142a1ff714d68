"""
Power-law noise identification per tau: lag-1 autocorrelation, B1 and R(n), slopes.

Riley and Greenhall, "Power law noise identification using the lag 1 autocorrelation"
(EFTF 2004); Barnes' B1 ratio with the R(n) ratio (NIST SP 1065 sec. 5.6).  Part of
:mod:`imu_allan.core.allan`.
"""

import math

import numpy as np

from imu_allan.core.allan.taus import _check_method, _DIFF_ORDER


#: Fewest cluster averages for the lag-1 autocorrelation noise identification
#: (Riley & Greenhall 2004 recommend at least 30).
MIN_ACF_POINTS = 30

#: Fewest cluster averages for the B1 ratio; with 2 or 3 averages B1 carries no
#: information (it is 1 for every noise type at N = 2).
MIN_B1_POINTS = 4

# Lowest alpha for which each variance converges (alpha + 2 d > 1).
_ALPHA_MIN = {'overlapping': -2, 'nonoverlapping': -2, 'hadamard': -4}

# Most cluster averages fed to the lag-1 autocorrelation test (see _identify_axis).
_ACF_MAX_POINTS = 1 << 16

# Marker of an alpha that the data could not decide (too few clusters).
_ALPHA_UNKNOWN = -99

# Boundaries on the local slope mu of log AVAR against log tau between neighbouring
# alphas 2 | 1 | 0 | -1 | -2 | -3 | -4.  White PM falls as tau^-2; flicker PM as
# tau^-2 times a log factor, which makes its local slope -1.33 .. -1.88 at
# m = 1 .. 1000 (f_h = 1 / (2 tau0)); white FM -1, flicker FM 0, random-walk FM +1
# (NIST SP 1065 table 1).
_SLOPE_EDGES = np.array([-1.9, -1.35, -0.5, 0.5, 1.5, 2.5])


def alpha_from_slope(tau_s, avar, method: str = 'overlapping',
                     n_clusters=None) -> np.ndarray:
    """
    Integer noise exponent per point from the local log-log slope of the curve.

    For when raw data are not at hand (the streaming accumulator): mu = d ln AVAR /
    d ln tau from neighbouring points (one-sided at the ends), then alpha = -mu - 1
    with the boundaries of ``_SLOPE_EDGES`` (white and flicker PM both fall as
    tau^-2; the flicker log factor flattens its slope to -1.3 .. -1.9).

    Where fewer than ``MIN_ACF_POINTS`` clusters fit in the record, the slope is that
    of points with a few degrees of freedom: one low-lying point makes it steep enough
    to read as phase noise, whose EDF is tens to thousands of times that of the
    frequency noises (Greenhall), and the point then looks exact.  For rate data phase
    noise means quantization, at the shortest taus; there the exponent is held at most
    0 (white FM).  For the same reason phase noise is read only in the curve's leading
    descent: past its first point of frequency noise the exponent is at most 0.

    Parameters
    ----------
    tau_s : array_like
        Shape (k,), averaging times [s], increasing.
    avar : array_like
        Shape (k,) or (k, n_axes), variances [unit^2].
    method : str
        'hadamard' allows alpha down to -4, the Allan variances down to -2.
    n_clusters : array_like, optional
        Shape (k,) or broadcastable to ``avar``: non-overlapping clusters of each tau in
        the record (M // m); unknown when not given (no cap).

    Returns
    -------
    np.ndarray
        int64 alpha, the shape of ``avar``; 0 (white FM) where the slope is undefined.

    """
    tau_s = np.asarray(tau_s, dtype=np.float64)
    avar = np.asarray(avar, dtype=np.float64)
    a2 = avar[:, None] if avar.ndim == 1 else avar
    alpha = np.zeros(a2.shape, dtype=np.int64)
    if tau_s.size >= 2:
        with np.errstate(divide='ignore', invalid='ignore'):
            mu = np.gradient(np.log(a2), np.log(tau_s), axis=0)
        labels = np.array([2, 1, 0, -1, -2, -3, -4])
        idx = np.searchsorted(_SLOPE_EDGES, np.nan_to_num(mu, nan=-1.0))
        alpha = np.where(np.isfinite(mu), labels[idx], 0)
    alpha = np.clip(alpha, _ALPHA_MIN[_check_method(method)], 2)
    # Phase noise in rate data is quantization, which carries the short end of the
    # curve: past its first point of frequency noise, a steep fall is a deterministic
    # feature (a sinusoid's turn, held values, a filter) whose points would look exact
    # (their EDF as phase noise ran 3-140 times their neighbours').
    past = np.logical_or.accumulate(alpha <= 0, axis=0)
    alpha = np.where(past, np.minimum(alpha, 0), alpha)
    if n_clusters is not None:
        few = np.asarray(n_clusters, dtype=np.float64).reshape(-1, 1) < MIN_ACF_POINTS
        alpha = np.where(few, np.minimum(alpha, 0), alpha)
    return alpha[:, 0] if avar.ndim == 1 else alpha


def _detrended(z: np.ndarray) -> np.ndarray:
    """Remove the least-squares line from z (n,): a frequency drift (Riley 2004)."""
    n = z.size
    t = np.arange(n, dtype=np.float64)
    t -= 0.5 * (n - 1)
    e = z - z.mean()
    tt = float(np.dot(t, t))
    if tt > 0:
        e -= (float(np.dot(t, e)) / tt) * t
    return e


def _lag1_alpha(z: np.ndarray, d_max: int) -> int:
    """
    Lag-1 autocorrelation noise identification of cluster averages z (Riley 2004).

    r1 is the lag-1 autocorrelation and delta = r1 / (1 + r1); while delta >= 0.25 and
    fewer than d_max differences were taken, difference z once more.  Then
    alpha = -round(2 delta) - 2 d for frequency data.
    """
    e = _detrended(z)
    d = 0
    while True:
        e = e - e.mean()
        den = float(np.dot(e, e))
        r1 = float(np.dot(e[:-1], e[1:])) / den if den > 0 else 0.0
        delta = r1 / (1.0 + r1) if r1 > -1.0 else -1.0
        if delta < 0.25 or d >= d_max:
            return int(-round(2.0 * delta)) - 2 * d
        e = np.diff(e)
        d += 1


def _b1_theory(n: int, mu: int) -> float:
    """Return the B1 ratio (N-sample / 2-sample variance) expected for AVAR ~ tau^mu."""
    if mu == 0:
        return n * math.log(n) / (2.0 * (n - 1) * math.log(2.0))
    return n * (1.0 - n ** mu) / (2.0 * (n - 1) * (1.0 - 2.0 ** mu))


def _mvar_ratio(x_row: np.ndarray, m: int) -> float:
    """
    R(n) = MVAR / AVAR at cluster size m from one phase row X (n,) (NIST SP 1065).

    Only a noise-type decision rests on it, so for m >= 64 the terms are taken at a
    stride of m / 16 (still 16 per cluster) from block sums, one pass over X.
    """
    n = x_row.size
    step = m // 16 if m >= 64 and m % 16 == 0 else 1
    blocks = n // step
    # P[q] = sum of X over the first q * step points (prefix sums at the stride).
    p = np.zeros(blocks + 1)
    np.cumsum(x_row[:blocks * step].reshape(blocks, step).sum(axis=1), out=p[1:])
    ms = m // step
    k = blocks - 3 * ms + 1
    if k < 1:
        return math.nan
    inner = p[3 * ms:3 * ms + k] - 3 * p[2 * ms:2 * ms + k] + 3 * p[ms:ms + k] - p[:k]
    mvar = float(np.dot(inner, inner)) / (2.0 * m ** 4 * k)
    xs = x_row[::step]
    d = xs[2 * ms:] - 2 * xs[ms:-ms] + xs[:-2 * ms]
    avar = float(np.dot(d, d)) / (2.0 * m ** 2 * d.size)
    return mvar / avar if avar > 0 else math.nan


def _rn_theory(m: int, alpha: int) -> float:
    """Return the R(n) expected for white PM (1/m) or flicker PM (f_h = 0.5 / tau0)."""
    if alpha == 2:
        return 1.0 / m
    return 3.0 * math.log(256.0 / 27.0) / (2.0 * (1.038 + 3.0 * math.log(math.pi * m)))


def _b1_alpha(z: np.ndarray, phase, m: int, alpha_min: int) -> int:
    """
    B1-ratio noise identification of n cluster averages z (n,), 4 <= n < 30.

    phase() returns the running sum X (M + 1,), needed only to split phase noises.
    """
    n = z.size
    dz = np.diff(z)
    avar = 0.5 * float(np.dot(dz, dz)) / dz.size
    if avar <= 0:
        return 0
    b1 = float(np.var(z, ddof=1)) / avar
    mus = list(range(-2, -alpha_min))  # mu = -alpha - 1 for alpha <= 0; -2 for PM
    expected = [_b1_theory(n, mu) for mu in mus]
    mu = mus[-1]
    for i in range(len(mus) - 1):
        edge = math.sqrt(expected[i] * expected[i + 1])
        if b1 < edge:
            mu = mus[i]
            break
    if mu > -2:
        return -mu - 1
    # Phase noise: white and flicker PM share mu = -2; the R(n) ratio separates them.
    rn = _mvar_ratio(phase(), m)
    if not math.isfinite(rn) or rn <= 0:
        return 1
    r_white, r_flicker = _rn_theory(m, 2), _rn_theory(m, 1)
    return 2 if abs(math.log(rn / r_white)) < abs(math.log(rn / r_flicker)) else 1


def _identify_axis(cluster_means, m: np.ndarray, method: str, phase) -> np.ndarray:
    """
    Alpha per cluster size for one axis, shape (k,).

    cluster_means(j) returns the first min(_ACF_MAX_POINTS, M // m[j]) non-overlapping
    cluster averages [unit] and phase() the running sum X (M + 1,) of the axis.  The
    lag-1 test uses at most _ACF_MAX_POINTS averages: r1 then has a standard error of
    0.004, well inside the decision margins, and the test stays cheap at m = 1 on long
    records.  ``_ALPHA_UNKNOWN`` where fewer than ``MIN_B1_POINTS`` clusters exist.
    """
    alpha_min = _ALPHA_MIN[method]
    d_max = _DIFF_ORDER[method]
    out = np.full(m.size, _ALPHA_UNKNOWN, dtype=np.int64)
    for j, mj in enumerate(m):
        z = cluster_means(j)
        if z.size >= MIN_ACF_POINTS:
            out[j] = max(alpha_min, min(2, _lag1_alpha(z, d_max)))
        elif z.size >= MIN_B1_POINTS:
            out[j] = max(alpha_min, min(2, _b1_alpha(z, phase, int(mj), alpha_min)))
    return out


def _fill_unknown(alpha: np.ndarray, tau_s: np.ndarray, var: np.ndarray,
                  method: str) -> np.ndarray:
    """Replace ``_ALPHA_UNKNOWN`` entries (under 4 clusters) by the local-slope estimate."""
    unknown = alpha == _ALPHA_UNKNOWN
    if unknown.any():
        # Under 4 clusters: at most white FM, as alpha_from_slope holds it below 30.
        alpha = np.where(unknown, np.minimum(alpha_from_slope(tau_s, var, method), 0), alpha)
    return alpha
