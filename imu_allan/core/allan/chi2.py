"""
Chi-square quantiles in numpy alone: the Allan curve's bounds without scipy's import.

``imu-allan adev`` needs 2 quantiles per tau; scipy.special's import (0.3 s) cost more
than the whole curve.  The quantile x of chi2(df) at probability q solves
P(a, x / 2) = q with a = df / 2, P the regularised lower incomplete gamma function,
by safeguarded Newton steps.

P itself (agrees with scipy.special to about 1e-14, checked in test_model.py):

* a < 20: its power series for x < a + 1, else the continued fraction of Q = 1 - P
  (Abramowitz & Stegun 6.5.29 and 6.5.31);
* a >= 20: the exact integral in Temme's variable eta, eta^2 / 2 = lambda - 1 -
  ln(lambda), lambda = x / a (N. M. Temme, SIAM J. Math. Anal. 10, 1979): with
  s = eta sqrt(a),
  P = e^{-c(a)} [Phi(s) + (2 pi)^{-1/2} int_{-inf}^{s} e^{-u^2/2} (g(u / sqrt(a)) - 1) du],
  g(eta) = eta / (lambda - 1), c(a) the Stirling remainder of ln Gamma(a).  The
  leading term is the normal CDF; the smooth remainder is integrated by Gauss-Legendre
  panels over 12 units of u, where e^{-u^2/2} has fallen below 1e-31.
"""

import math

import numpy as np

#: a at and above which P comes from the eta integral.
_A_LARGE = 20.0
#: Gauss-Legendre panels of one unit of u, ten nodes each.
_PANELS = 12
_GL_X, _GL_W = np.polynomial.legendre.leggauss(10)
_MAX_SERIES = 500
_MAX_NEWTON = 60
_EPS = float(np.finfo(np.float64).eps)

_ERFC = np.frompyfunc(math.erfc, 1, 1)
_LGAMMA = np.frompyfunc(math.lgamma, 1, 1)


def _erfc(x: np.ndarray) -> np.ndarray:
    return np.asarray(_ERFC(x), dtype=np.float64)


def _lgamma(x: np.ndarray) -> np.ndarray:
    return np.asarray(_LGAMMA(x), dtype=np.float64)


def _stirling_remainder(a: np.ndarray) -> np.ndarray:
    """Return ln Gamma(a) - ((a - 1/2) ln a - a + ln(2 pi) / 2), a >= 20 (Bernoulli series)."""
    r = 1.0 / (a * a)
    return (1.0 / 12.0 - r * (1.0 / 360.0 - r * (1.0 / 1260.0 - r * (
        1.0 / 1680.0 - r / 1188.0)))) / a


def _mu_minus_log1p(mu: np.ndarray) -> np.ndarray:
    """
    Return mu - ln(1 + mu) without cancellation.

    Where |mu| < 0.1, with t = mu / (2 + mu) and ln(1 + mu) = 2 atanh(t):
    mu - ln(1 + mu) = mu^2 / (2 + mu) - 2 (t^3 / 3 + t^5 / 5 + ...); |t| < 0.053, so
    eight terms reach 1e-19 of the result.
    """
    out = mu - np.log1p(mu)
    small = np.abs(mu) < 0.1
    if small.any():
        m = mu[small]
        t = m / (2.0 + m)
        t2 = t * t
        acc = np.zeros_like(m)
        for k in range(17, 1, -2):     # Horner over t^2: 1/3 + t^2/5 + ... + t^14/17
            acc = acc * t2 + 1.0 / k
        out[small] = m * m / (2.0 + m) - 2.0 * t * t2 * acc
    return out


def _mu_of_eta(eta: np.ndarray) -> np.ndarray:
    """Return mu = lambda - 1 (the sign of eta) solving mu - ln(1 + mu) = eta^2 / 2 (Newton)."""
    half = 0.5 * eta * eta
    # Starts: the series near 0, lambda ~ exp(-1 - eta^2 / 2) far left, the dominant
    # balance far right.
    mu = eta * (1.0 + eta * (1.0 / 3.0 + eta * (1.0 / 36.0 - eta / 270.0)))
    left = eta < -1.0
    mu[left] = np.exp(-1.0 - half[left]) - 1.0
    right = eta > 1.0
    mu[right] = half[right] + np.log1p(half[right]) + np.log1p(
        np.log1p(half[right]) / (1.0 + half[right]))
    for _ in range(_MAX_NEWTON):
        step = (_mu_minus_log1p(mu) - half) * (1.0 + mu) / mu
        new = mu - step
        # Keep lambda > 0.
        new = np.where(new <= -1.0, 0.5 * (mu - 1.0), new)
        done = np.abs(new - mu) <= 1e-13 * np.abs(new)   # quadratic: the next step is 0
        mu = new
        if done.all():
            break
    return mu


def _p_large(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """P(a, x) for a >= 20 from the eta integral (module docstring)."""
    lam_m1 = x / a - 1.0
    eta = np.sign(lam_m1) * np.sqrt(2.0 * _mu_minus_log1p(lam_m1))
    sqa = np.sqrt(a)
    s = eta * sqa
    lower = s <= 0.0
    # Integrate toward the near tail: [s - 12, s] for P, [s, s + 12] for Q.
    start = np.where(lower, s - _PANELS, s)
    u = (start[:, None, None] + np.arange(_PANELS)[None, :, None] + 0.5
         + 0.5 * _GL_X[None, None, :]).reshape(s.size, -1)
    w = np.tile(0.5 * _GL_W, _PANELS)
    e = u / sqa[:, None]
    safe = np.abs(e) > 1e-300
    mu = _mu_of_eta(np.where(safe, e, 1.0).ravel()).reshape(e.shape)
    g1 = np.where(safe, e / mu - 1.0, 0.0)
    rest = (np.exp(-0.5 * u * u) * g1) @ w / math.sqrt(2.0 * math.pi)
    tail = 0.5 * _erfc(np.abs(s) / math.sqrt(2.0))
    scale = np.exp(-_stirling_remainder(a))
    p_low = scale * (tail + rest)              # P when s <= 0
    q_up = scale * (tail + rest)               # Q when s > 0
    return np.where(lower, p_low, 1.0 - q_up)


def _p_small(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """P(a, x) for a < 20: power series or continued fraction (A&S 6.5.29, 6.5.31)."""
    out = np.empty_like(x)
    log_x = np.log(np.maximum(x, 1e-300))
    lg = _lgamma(a)
    series = x < a + 1.0
    if series.any():
        aa, xx = a[series], x[series]
        term = 1.0 / aa
        total = term.copy()
        n = aa.copy()
        for _ in range(_MAX_SERIES):
            n = n + 1.0
            term = term * xx / n
            total += term
            if np.all(np.abs(term) < 1e-17 * total):
                break
        out[series] = np.exp(aa * log_x[series] - xx - lg[series]) * total
    cf = ~series
    if cf.any():
        aa, xx = a[cf], x[cf]
        tiny = 1e-300
        b = xx + 1.0 - aa
        c = np.full_like(xx, 1.0 / tiny)
        d = 1.0 / b
        h = d.copy()
        for i in range(1, _MAX_SERIES):
            an = -i * (i - aa)
            b = b + 2.0
            d = an * d + b
            d = np.where(np.abs(d) < tiny, tiny, d)
            c = b + an / c
            c = np.where(np.abs(c) < tiny, tiny, c)
            d = 1.0 / d
            delta = d * c
            h = h * delta
            # Converged when a step changes h by at most one rounding (a bound below
            # the machine epsilon is met only by delta == 1 exactly, often never).
            if np.all(np.abs(delta - 1.0) <= _EPS):
                break
        out[cf] = 1.0 - np.exp(aa * log_x[cf] - xx - lg[cf]) * h
    return out


def gamma_p(a, x) -> np.ndarray:
    """
    Regularised lower incomplete gamma function P(a, x).

    Parameters
    ----------
    a : array_like
        Shape parameter (> 0), broadcast with ``x``.
    x : array_like
        Argument (>= 0).

    Returns
    -------
    np.ndarray
        P(a, x), the broadcast shape (float64).

    """
    a, x = np.broadcast_arrays(np.asarray(a, np.float64), np.asarray(x, np.float64))
    flat_a, flat_x = a.ravel(), x.ravel()
    out = np.zeros(flat_x.shape)
    pos = flat_x > 0
    big = pos & (flat_a >= _A_LARGE)
    small = pos & ~big
    if big.any():
        out[big] = _p_large(flat_a[big], flat_x[big])
    if small.any():
        out[small] = _p_small(flat_a[small], flat_x[small])
    return out.reshape(a.shape)


def _normal_quantile_rough(q: np.ndarray) -> np.ndarray:
    """Return the standard normal quantile to about 4.5e-4 (A&S 26.2.23), a start for Newton."""
    p = np.minimum(q, 1.0 - q)
    t = np.sqrt(-2.0 * np.log(p))
    z = t - (2.515517 + t * (0.802853 + t * 0.010328)) / (
        1.0 + t * (1.432788 + t * (0.189269 + t * 0.001308)))
    return np.where(q < 0.5, -z, z)


def chi2_ppf(q, df) -> np.ndarray:
    """
    Return the chi-square quantile: x with P(X <= x) = q for X ~ chi2(df).

    Parameters
    ----------
    q : float or array_like
        Probability in (0, 1), broadcast with ``df``.
    df : float or array_like
        Degrees of freedom (real, > 0).

    Returns
    -------
    np.ndarray or np.float64
        The quantile, the broadcast shape (a scalar for scalar inputs); NaN where q or
        df is out of range.

    """
    q, df = np.broadcast_arrays(np.asarray(q, np.float64), np.asarray(df, np.float64))
    shape = q.shape
    q, df = q.ravel().copy(), df.ravel().copy()
    ok = (q > 0) & (q < 1) & (df > 0) & np.isfinite(df)
    out = np.full(q.shape, np.nan)
    if not ok.any():
        return out.reshape(shape)[()]
    qq, a = q[ok], 0.5 * df[ok]
    # Start: Wilson-Hilferty, or the small-x form P ~ x^a / Gamma(a + 1) for small a.
    z = _normal_quantile_rough(qq)
    v = 1.0 / (9.0 * a)
    x = a * np.maximum(1.0 - v + z * np.sqrt(v), 0.05) ** 3
    lg_a1 = _lgamma(a + 1.0)
    tiny = a < 1.0
    x[tiny] = np.exp((np.log(qq[tiny]) + lg_a1[tiny]) / a[tiny])
    lg_a = lg_a1 - np.log(a)
    todo = np.arange(x.size)    # the quantiles still moving: only they take a step
    for _ in range(_MAX_NEWTON):
        xt, at = x[todo], a[todo]
        pdf = np.exp((at - 1.0) * np.log(xt) - xt - lg_a[todo])
        step = (gamma_p(at, xt) - qq[todo]) / np.maximum(pdf, 1e-300)
        new = np.clip(xt - step, 0.1 * xt, 10.0 * xt)
        x[todo] = new
        todo = todo[np.abs(new - xt) > 1e-12 * new]    # quadratic: the next step is noise
        if todo.size == 0:
            break
    out[ok] = 2.0 * x
    return out.reshape(shape)[()]
