"""
Equivalent degrees of freedom (Greenhall) and chi-square confidence bounds.

C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based on finite
differences", PTTI 2003; bounds by NIST SP 1065 eq. 45.  Part of
:mod:`imu_allan.core.allan`.
"""

from functools import lru_cache
import math

import numpy as np

from imu_allan.core.allan.quantiles import chi2_ppf
from imu_allan.core.allan.taus import _check_method, _DIFF_ORDER
from imu_allan.errors import InputError


# Greenhall & Riley 2003, table 2: (a0, a1) of 1/edf ~ (a0 - a1 / r) / r for the
# unmodified variances, by alpha (rows) and d = 1, 2, 3 (columns); None = divergent.
_GH_TABLE2: dict[int, tuple] = {
    2: ((1.5, 0.5), (35.0 / 18.0, 1.0), (2.31, 1.5)),
    1: ((78.6, 25.2), (790.0, 410.0), (9950.0, 6520.0)),
    0: ((2.0 / 3.0, 1.0 / 6.0), (2.0 / 3.0, 1.0 / 3.0), (7.0 / 9.0, 0.5)),
    -1: (None, (0.852, 0.375), (0.997, 0.617)),
    -2: (None, (1.079, 0.368), (1.033, 0.607)),
    -3: (None, None, (1.053, 0.553)),
    -4: (None, None, (1.302, 0.535)),
}

# Greenhall & Riley 2003, table 3: (b0, b1) of sz(0) ~ b0 + b1 ln m for alpha = 1.
_GH_TABLE3 = ((6.0, 4.0), (15.23, 12.0), (47.8, 40.0))

_GH_J_MAX = 100


def _gh_sw(t: np.ndarray, alpha: int) -> np.ndarray:
    """Greenhall's generalised autocovariance sw(t) of the power-law phase (eq. 7)."""
    # -|t|, t^2 ln|t|, |t|^3, t^4 ln|t|, |t|^5, t^6 ln|t|, |t|^7 for alpha = 2 .. -4.
    at = np.abs(t)
    if alpha == 2:
        return -at
    if alpha % 2 == 0:
        return at ** (3 - alpha)
    with np.errstate(divide='ignore', invalid='ignore'):
        val = at ** (3 - alpha) * np.log(at)
    return np.where(at == 0, 0.0, val)


def _gh_sx(t: np.ndarray, f: float, alpha: int) -> np.ndarray:
    """Autocovariance after the frequency pre-filter of factor F (eq. 8)."""
    if math.isinf(f):
        return _gh_sw(t, alpha + 2)
    h = np.longdouble(1.0) / np.longdouble(f)
    ff = np.longdouble(f) ** 2
    return ff * (2 * _gh_sw(t, alpha) - _gh_sw(t - h, alpha) - _gh_sw(t + h, alpha))


def _gh_sz(t: np.ndarray, f: float, alpha: int, d: int) -> np.ndarray:
    """Autocovariance of the d-th difference (eq. 9): binomial combination of sx."""
    t = np.asarray(t, dtype=np.longdouble)
    acc = np.zeros_like(t)
    for k in range(-d, d + 1):
        acc += (-1) ** k * math.comb(2 * d, d + k) * _gh_sx(t + k, f, alpha)
    return acc


def _gh_basic_sum(j_n: int, m_n: float, s: float, f: float, alpha: int, d: int) -> float:
    """Greenhall's basic sum (eq. 10), vectorised over the lag j."""
    if alpha == 2 and s > 1:
        # White PM: sx vanishes beyond 1/F of an integer, so sz(j/S) is zero except
        # next to multiples of S; summing only those keeps huge J cheap.
        near = np.arange(1, d + 2)[:, None] * int(s) + np.array([-1, 0, 1])
        j = np.unique(near[(near >= 1) & (near < j_n)]).astype(np.longdouble)
    else:
        j = np.arange(1, j_n, dtype=np.longdouble)
    sz0 = _gh_sz(np.zeros(1), f, alpha, d)[0]
    szj = _gh_sz(np.array([j_n / s], dtype=np.longdouble), f, alpha, d)[0]
    body = _gh_sz(j / np.longdouble(s), f, alpha, d) if j.size else np.zeros(0)
    total = (sz0 ** 2 + (1 - j_n / m_n) * szj ** 2
             + 2 * np.sum((1 - j / np.longdouble(m_n)) * body ** 2))
    return float(total)


@lru_cache(maxsize=4096)
def _edf_greenhall_scalar(alpha: int, d: int, m: int, n_phase: int,
                          overlapping: bool) -> float:
    """Greenhall's EDF algorithm for the unmodified variances (F = m), one point."""
    f = float(m)
    s = float(m) if overlapping else 1.0
    span = 1 + m * d  # L = m / F + m d: phase points spanned by one term
    if n_phase < span:
        return math.nan
    m_n = 1 + math.floor(s * (n_phase - span) / m)  # number of terms
    j_n = int(min(m_n, (d + 1) * s))
    r = m_n / s
    jm = _GH_J_MAX
    if alpha == 2:
        if math.ceil(r) > d:
            a0 = math.comb(4 * d, 2 * d) / math.comb(2 * d, d) ** 2
            inv = (a0 - d / 2.0 / r) / m_n
        else:
            # So few terms that the closed form does not hold: the exact basic sum.
            sz0 = float(_gh_sz(np.zeros(1), f, 2, d)[0])
            inv = _gh_basic_sum(j_n, m_n, s, f, 2, d) / (m_n * sz0 ** 2)
    elif alpha == 1:
        b0, b1 = _GH_TABLE3[d - 1]
        if j_n <= jm:
            sz0 = float(_gh_sz(np.zeros(1), f, 1, d)[0])
            inv = _gh_basic_sum(j_n, m_n, s, f, 1, d) / (m_n * sz0 ** 2)
        elif r > d + 1:
            a0, a1 = _GH_TABLE2[1][d - 1]
            inv = (a0 - a1 / r) / (r * (b0 + b1 * math.log(m)) ** 2)
        else:
            mp = jm / r
            inv = _gh_basic_sum(jm, jm, mp, mp, 1, d) / (jm * (b0 + b1 * math.log(m)) ** 2)
    else:
        if j_n <= jm:
            fp = f if m * (d + 1) <= jm else math.inf
            sz0 = float(_gh_sz(np.zeros(1), fp, alpha, d)[0])
            inv = _gh_basic_sum(j_n, m_n, s, fp, alpha, d) / (m_n * sz0 ** 2)
        elif r > d + 1:
            a0, a1 = _GH_TABLE2[alpha][d - 1]
            inv = (a0 - a1 / r) / r
        else:
            mp = jm / r
            sz0 = float(_gh_sz(np.zeros(1), math.inf, alpha, d)[0])
            inv = _gh_basic_sum(jm, jm, mp, math.inf, alpha, d) / (jm * sz0 ** 2)
    return 1.0 / inv if inv > 0 else math.nan


def edf_greenhall(alpha, m, n_samples, d: int = 2, overlapping: bool = True) -> np.ndarray:
    """
    Equivalent degrees of freedom of an unmodified difference variance (Greenhall).

    Greenhall & Riley 2003 (also NIST SP 1065 section 5.2.3 and Stable32): the exact
    "basic sum" (their eq. 10) for up to 100 lags, the tabulated large-sample forms
    (their tables 2 and 3) beyond.

    Parameters
    ----------
    alpha : array_like of int
        Power-law exponent of S_y(f), in 2 .. -2 (down to -4 when d = 3).
    m : array_like of int
        Cluster sizes [samples]; broadcast with ``alpha`` and ``n_samples``.
    n_samples : array_like of int
        Number of rate samples M (M + 1 phase points).
    d : int
        Order of the phase difference: 2 Allan, 3 Hadamard.
    overlapping : bool
        True for the fully overlapping estimators (stride 1 sample).

    Returns
    -------
    np.ndarray
        EDF, the broadcast shape of the inputs; NaN where undefined.

    """
    a, mm, nn = np.broadcast_arrays(np.asarray(alpha, dtype=np.int64),
                                    np.asarray(m, dtype=np.int64),
                                    np.asarray(n_samples, dtype=np.int64))
    lo = -2 * d + 2
    if a.size and (a.max() > 2 or a.min() < lo):
        raise ValueError(f'alpha must lie in {lo} .. 2 for a difference of order {d}')
    out = np.empty(a.shape)
    for idx in np.ndindex(a.shape):
        out[idx] = _edf_greenhall_scalar(int(a[idx]), d, int(mm[idx]), int(nn[idx]) + 1,
                                         bool(overlapping))
    return out


def edf_overlapping(alpha, m, n_samples) -> np.ndarray:
    """
    EDF of the overlapping Allan variance (Greenhall's algorithm, d = 2).

    Parameters
    ----------
    alpha : array_like of int
        Noise exponent of S_y(f), in {2, 1, 0, -1, -2}.
    m : array_like of int
        Cluster sizes [samples].
    n_samples : array_like of int
        Number of rate samples M.

    Returns
    -------
    np.ndarray
        EDF, the broadcast shape of the inputs.

    """
    return edf_greenhall(alpha, m, n_samples, d=2, overlapping=True)


def edf_nonoverlapping(alpha, m, n_samples) -> np.ndarray:
    """
    EDF of the non-overlapping Allan variance (Greenhall's algorithm, d = 2).

    Parameters
    ----------
    alpha : array_like of int
        Noise exponent of S_y(f), in {2, 1, 0, -1, -2}.
    m : array_like of int
        Cluster sizes [samples].
    n_samples : array_like of int
        Number of rate samples M.

    Returns
    -------
    np.ndarray
        EDF, the broadcast shape of the inputs.

    """
    return edf_greenhall(alpha, m, n_samples, d=2, overlapping=False)


def edf_hadamard(alpha, m, n_samples) -> np.ndarray:
    """
    EDF of the overlapping Hadamard variance (Greenhall's algorithm, d = 3).

    Parameters
    ----------
    alpha : array_like of int
        Noise exponent of S_y(f), in {2, 1, 0, -1, -2, -3, -4}.
    m : array_like of int
        Cluster sizes [samples].
    n_samples : array_like of int
        Number of rate samples M.

    Returns
    -------
    np.ndarray
        EDF, the broadcast shape of the inputs.

    """
    return edf_greenhall(alpha, m, n_samples, d=3, overlapping=True)


def edf_for_method(alpha, m, n_samples, method: str = 'overlapping') -> np.ndarray:
    """
    EDF of the estimator ``method`` ('overlapping', 'nonoverlapping', 'hadamard').

    Parameters
    ----------
    alpha : array_like of int
        Noise exponent of S_y(f).
    m : array_like of int
        Cluster sizes [samples].
    n_samples : array_like of int
        Number of rate samples M.
    method : str
        Estimator name.

    Returns
    -------
    np.ndarray
        EDF, the broadcast shape of the inputs.

    """
    _check_method(method)
    return edf_greenhall(alpha, m, n_samples, d=_DIFF_ORDER[method],
                         overlapping=method != 'nonoverlapping')


def confidence_bounds(avar, edf, confidence: float) -> tuple[np.ndarray, np.ndarray]:
    """
    Chi-square confidence bounds on the deviation (NIST SP 1065 eq. 45).

    edf * avar / var ~ chi2(edf), so the two-sided interval at level p is
    var in [edf avar / chi2_{(1+p)/2}, edf avar / chi2_{(1-p)/2}].

    Parameters
    ----------
    avar : array_like
        Variance estimates [unit^2].
    edf : array_like
        Equivalent degrees of freedom, broadcast with ``avar``.
    confidence : float
        Two-sided confidence level in (0, 1), e.g. 0.683.

    Returns
    -------
    adev_lo, adev_hi : np.ndarray
        Lower and upper deviation bounds [unit], the broadcast shape; NaN where the
        EDF is not positive and finite.

    """
    if not 0.0 < confidence < 1.0:
        raise InputError(f'confidence must lie strictly between 0 and 1, got {confidence}')
    avar, edf = np.broadcast_arrays(np.asarray(avar, dtype=np.float64),
                                    np.asarray(edf, dtype=np.float64))
    ok = np.isfinite(edf) & (edf > 0)
    e = np.where(ok, edf, 1.0)
    chi_hi = chi2_ppf(0.5 * (1.0 + confidence), e)
    chi_lo = chi2_ppf(0.5 * (1.0 - confidence), e)
    with np.errstate(all='ignore'):
        lo = np.sqrt(e * avar / chi_hi)
        hi = np.sqrt(e * avar / chi_lo)
    return np.where(ok, lo, np.nan), np.where(ok, hi, np.nan)


def avar_upper(avar: np.ndarray, edf: np.ndarray) -> np.ndarray:
    """
    Each point's one-sided upper limit of the true AVAR, jointly at 95 % over the points.

    The measured AVAR scatters about the true one as chi-square with the point's EDF
    (NIST SP 1065 sec. 5.3), most at the longest taus (EDF of a few), so the minimum of
    a curve picks its lowest-lying point, which can lie far below the truth.  A bound
    read off a minimum (the random walk's, the floor's) therefore takes each point at
    AVAR edf / chi2_a(edf) with a = 0.05 / k over the k points (Bonferroni).  A point's
    EDF is taken as at most that of any shorter tau: for every power-law noise the EDF
    falls as tau grows (NIST SP 1065 table 5), and the curve's own EDF, from the noise
    type read off the local slope, can jump at the longest taus where a low-lying point
    steepens that slope.

    Parameters
    ----------
    avar : np.ndarray
        Shape (k,), measured AVAR [unit^2], shortest tau first.
    edf : np.ndarray
        Shape (k,), equivalent degrees of freedom of each point.

    Returns
    -------
    np.ndarray
        Shape (k,), the upper limits [unit^2].

    """
    edf = np.minimum.accumulate(np.maximum(np.asarray(edf, dtype=np.float64), 1e-3))
    return np.asarray(avar, dtype=np.float64) * edf / chi2_ppf(0.05 / max(edf.size, 1), edf)


def curve_k_bound(tau: np.ndarray, avar: np.ndarray, edf: np.ndarray) -> float:
    """
    95 % upper bound of K from the curve alone: min over tau of sqrt(3 AVAR_hi / tau).

    A random walk alone gives AVAR = K^2 tau / 3 (IEEE Std 952 C.1 slope +1/2) and every
    other term only adds to it, so K^2 <= 3 AVAR(tau) / tau at every tau, for the true
    AVAR; AVAR_hi is each point's joint upper limit (:func:`avar_upper`).

    Parameters
    ----------
    tau : np.ndarray
        Shape (k,), averaging times [s].
    avar : np.ndarray
        Shape (k,), measured AVAR [unit^2].
    edf : np.ndarray
        Shape (k,), equivalent degrees of freedom of each point.

    Returns
    -------
    float
        The bound [unit/s^0.5].

    """
    return float(np.sqrt(np.min(3.0 * avar_upper(avar, edf) / tau)))


def curve_n_bound(tau: np.ndarray, avar: np.ndarray, edf: np.ndarray) -> float:
    """
    95 % upper bound of N from the curve alone: min over tau of sqrt(AVAR_hi tau).

    White noise alone gives AVAR = N^2 / tau (IEEE Std 952 C.1 slope -1/2) and every
    other term but a sensor's filter only adds to it, so N^2 <= AVAR(tau) tau at every
    tau past the filter; AVAR_hi is each point's joint upper limit (:func:`avar_upper`).

    Parameters
    ----------
    tau : np.ndarray
        Shape (k,), averaging times past the sensor's filter [s].
    avar : np.ndarray
        Shape (k,), measured AVAR [unit^2].
    edf : np.ndarray
        Shape (k,), equivalent degrees of freedom of each point.

    Returns
    -------
    float
        The bound [unit*s^0.5].

    """
    return float(np.sqrt(np.min(avar_upper(avar, edf) * tau)))


def floor_b_bound(avar: np.ndarray, edf: np.ndarray) -> float:
    """
    95 % upper bound of B from a curve's floor: min sqrt(AVAR_hi) / 0.664.

    Every term only adds to AVAR, and a bias instability of level B alone peaks at
    ADEV 0.664 B (IEEE Std 952-1997 annex C), so 0.664 B <= ADEV(tau) at its peak's tau:
    a bound for a bias instability whose peak lies within the curve (the range the fit
    searches T_B in); AVAR_hi is each point's joint upper limit (:func:`avar_upper`).

    Parameters
    ----------
    avar : np.ndarray
        Shape (k,), measured AVAR past the sensor's filter [unit^2].
    edf : np.ndarray
        Shape (k,), equivalent degrees of freedom of each point.

    Returns
    -------
    float
        The bound [unit].

    """
    return float(np.sqrt(np.min(avar_upper(avar, edf))) / 0.664)
