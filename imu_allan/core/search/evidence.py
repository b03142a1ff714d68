"""
Time-domain evidence for the effect search, where the Allan curve blurs it.

- :class:`RawKeeper` (from :mod:`imu_allan.core.allan.raw`): a bounded, block-averaged copy
  of the samples (the node, the offline reader and the diagnosis keep one beside the
  Allan accumulator);
- :func:`periodogram_peak`: a spectral line (a sinusoid) and its significance;
- :func:`ramp_test`: a likelihood-ratio test of a rate ramp against the correlated
  noise model (white, Gauss-Markov, flicker, random walk), on the differences of block
  means, whose covariance the model fixes exactly (the generalised covariances of
  :data:`imu_allan.core.noise.model.TERMS`).  A random walk alone also drifts; the test asks
  whether a straight line in the rate explains the record better than more random walk.
"""

import math
from typing import NamedTuple, Sequence

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.optimize import minimize_scalar

from imu_allan.core.noise.terms import TERMS
from imu_allan.core.rules import LINE_FALSE_ALARM, RAMP_BLOCKS, RAMP_LR_MIN


class PeakCheck(NamedTuple):
    """
    A periodogram peak.

    Attributes
    ----------
    f0_hz : float
        Frequency of the peak (interpolated) [Hz].
    amplitude : float
        Amplitude of a pure line at the peak, 2 |X(f)| / sum(w) [unit].
    band_amplitude : float
        Amplitude sqrt(2 var) of the power within +-max(5 bins, 5 %) of the peak above
        the background, which also counts a line spread by drift [unit].
    ratio : float
        Peak power over the median power of its neighbourhood [-].
    threshold : float
        Ratio a peak needs to count (false-alarm probability 1e-3 over the band).
    bin_hz : float
        Frequency resolution 1 / T [Hz].
    significant : bool
        ratio >= threshold.

    """

    f0_hz: float
    amplitude: float
    band_amplitude: float
    ratio: float
    threshold: float
    bin_hz: float
    significant: bool


def periodogram_peak(y, rate_hz: float, f_lo: float, f_hi: float) -> PeakCheck | None:
    """
    Find the strongest line of a Hann-windowed periodogram within [f_lo, f_hi].

    The record is detrended (a line: bias and ramp).  Noise power in one bin is about
    exponentially distributed around the local mean; the peak counts when its power
    exceeds the neighbourhood median (frequencies within a factor 2, the peak's own
    +-3 bins left out) by ln(n_bins / 1e-3) / ln 2 (false-alarm 1e-3 over the n_bins
    searched).  Amplitude A = 2 |X(f)| / sum(w) at the interpolated peak (Hann window,
    parabolic interpolation of the log power).

    Parameters
    ----------
    y : array_like
        Shape (n,), samples [unit].
    rate_hz : float
        Their rate [Hz].
    f_lo, f_hi : float
        Search range [Hz].

    Returns
    -------
    PeakCheck or None
        None when the range holds no resolvable frequency.

    """
    y = np.asarray(y, dtype=np.float64)
    n = y.size
    if n < 16:
        return None
    t = np.arange(n)
    y = y - np.polyval(np.polyfit(t, y, 1), t)
    w = np.hanning(n)
    spec = np.fft.rfft(y * w)
    power = np.abs(spec) ** 2
    freqs = np.fft.rfftfreq(n, 1.0 / rate_hz)
    bin_hz = rate_hz / n
    lo, hi = max(f_lo, 3.0 * bin_hz), min(f_hi, 0.45 * rate_hz)
    sel = np.flatnonzero((freqs >= lo) & (freqs <= hi))
    if sel.size == 0:
        return None
    k = int(sel[np.argmax(power[sel])])
    nb = np.flatnonzero((freqs >= freqs[k] / 2.0) & (freqs <= freqs[k] * 2.0)
                        & (np.abs(np.arange(freqs.size) - k) > 3) & (freqs > 0))
    background = float(np.median(power[nb])) if nb.size else float(np.median(power[1:]))
    ratio = float(power[k] / max(background, 1e-300))
    threshold = math.log(max(sel.size, 1) / LINE_FALSE_ALARM) / math.log(2.0)
    shift = 0.0
    if 0 < k < power.size - 1:
        a, b, c = np.log(np.maximum(power[k - 1:k + 2], 1e-300))
        den = a - 2.0 * b + c
        if den < 0:
            shift = float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))
    # Hann window: the main lobe at offset d bins scales the amplitude by
    # sinc(d) / (1 - d^2); undo it at the interpolated offset.
    gain = np.sinc(shift) / (1.0 - shift * shift)
    amp = 2.0 * abs(spec[k]) / w.sum() / max(gain, 1e-3)
    # Parseval with the window: sum (y w)^2 = (2 / n) sum_{k > 0} |X_k|^2, and
    # E sum (y w)^2 = var(y) sum w^2 for a stationary signal.
    half = max(5, int(math.ceil(0.05 * k)))
    band = slice(max(k - half, 1), k + half + 1)
    excess = np.clip(power[band] - background / math.log(2.0), 0.0, None).sum()
    var = 2.0 / n * excess / float(np.sum(w * w))
    return PeakCheck(float((k + shift) * bin_hz), float(amp), float(math.sqrt(2.0 * var)),
                     ratio, float(threshold), float(bin_hz), ratio >= threshold)


# ----------------------------------------------------------------- rate-ramp evidence


class RampCheck(NamedTuple):
    """
    Result of :func:`ramp_test`.

    Attributes
    ----------
    lr : float
        2 (log-likelihood with the ramp - without it), each maximised over the random
        walk's level [-].
    slope : float
        Fitted ramp R [unit/s].
    k_without, k_with : float
        Random-walk level K that maximises each likelihood [unit/s^0.5].
    significant : bool
        lr >= :data:`RAMP_LR_MIN`.

    """

    lr: float
    slope: float
    k_without: float
    k_with: float
    significant: bool


def _stencil_cov(terms: Sequence[tuple], lag_s: float, n: int) -> np.ndarray:
    """
    Covariance (n, n) of d_i = (X_{i+2} - 2 X_{i+1} + X_i) / lag_s, X the phase.

    ``terms`` are (name, coefficient in SI, nonlinear parameters) of noise terms with a
    generalised covariance; the stencil annihilates linear functions, as those need.
    """
    lags = np.arange(n, dtype=np.float64)
    gamma = np.zeros(n)
    for name, coef, nonlinear in terms:
        g = TERMS[name].gcov
        if g is None or coef <= 0:
            continue
        for da, wa in ((0, 1.0), (1, -2.0), (2, 1.0)):
            for db, wb in ((0, 1.0), (1, -2.0), (2, 1.0)):
                gamma += coef * wa * wb * g((lags + da - db) * lag_s, *nonlinear)
    gamma /= lag_s * lag_s
    idx = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    return gamma[idx]


def ramp_test(y, rate_hz: float, terms: Sequence[tuple], n_blocks: int = RAMP_BLOCKS
              ) -> RampCheck | None:
    """
    Test a rate ramp against the correlated-noise model in the time domain.

    The record is cut into ``n_blocks`` blocks; the differences of neighbouring block
    means d_i are Gaussian with a covariance Sigma(K) that the noise model fixes (the
    random walk's share K^2 is left free) and a mean R L (L the block length) under a
    ramp R.  Both likelihoods are maximised over K (and R in closed form, GLS), and
    twice their difference is compared with :data:`RAMP_LR_MIN`: a likelihood-ratio
    test of the ramp against more random walk (NIST SP 1065 sec. 5.12 treats drift as
    deterministic; here it must beat the stochastic explanation).

    Parameters
    ----------
    y : array_like
        Shape (n,), samples (raw or block-averaged) [unit].
    rate_hz : float
        Their rate [Hz].
    terms : sequence of (str, float, tuple)
        The fitted noise terms: (TERMS name, coefficient in SI, nonlinear parameters);
        a 'random_walk' entry gives the starting K^2, deterministic terms are ignored.
    n_blocks : int
        Number of blocks.

    Returns
    -------
    RampCheck or None
        None when the record is too short for the test (fewer than 8 blocks).

    """
    y = np.asarray(y, dtype=np.float64)
    n_blocks = min(int(n_blocks), y.size // 4)
    if n_blocks < 8:
        return None
    per = y.size // n_blocks
    means = y[:per * n_blocks].reshape(n_blocks, per).mean(axis=1)
    lag_s = per / float(rate_hz)
    d = np.diff(means)
    fixed = [t for t in terms if t[0] != 'random_walk']
    c_rw = sum(t[1] for t in terms if t[0] == 'random_walk')
    base = _stencil_cov(fixed, lag_s, d.size)
    unit_rw = _stencil_cov([('random_walk', 1.0, ())], lag_s, d.size)
    scale = max(float(np.mean(d * d)), 1e-300)
    ones = np.ones(d.size)

    def loglik(log_c: float, with_ramp: bool) -> tuple[float, float]:
        cov = (base + math.exp(log_c) * unit_rw) / scale
        try:
            cf = cho_factor(cov + 1e-12 * np.eye(d.size) * np.trace(cov) / d.size)
        except np.linalg.LinAlgError:
            return -math.inf, 0.0
        x = d / math.sqrt(scale)
        mu = 0.0
        if with_ramp:
            w = cho_solve(cf, ones)
            mu = float(w @ x / (w @ ones))
        r = x - mu
        logdet = 2.0 * float(np.sum(np.log(np.diag(cf[0]))))
        return -0.5 * (float(r @ cho_solve(cf, r)) + logdet), mu * math.sqrt(scale)

    # K^2 from 1e-6 to 1e6 times its fitted value (or the data's own scale without one).
    c0 = c_rw if c_rw > 0 else scale * lag_s
    bounds = (math.log(c0) - 14.0, math.log(c0) + 14.0)
    best = {}
    for with_ramp in (False, True):
        res = minimize_scalar(lambda v: -loglik(v, with_ramp)[0], bounds=bounds,
                              method='bounded', options={'xatol': 1e-3})
        best[with_ramp] = (-float(res.fun), float(res.x))
    lr = 2.0 * (best[True][0] - best[False][0])
    slope = loglik(best[True][1], True)[1] / lag_s
    return RampCheck(float(lr), float(slope), math.sqrt(math.exp(best[False][1])),
                     math.sqrt(math.exp(best[True][1])), lr >= RAMP_LR_MIN)
