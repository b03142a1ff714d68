"""
A slow deterministic drift against a random walk, without a temperature.

A random walk's increments over disjoint blocks are independent: the differences d of
neighbouring block means carry its power K^2 L at every frequency alike (a flat
spectrum, IEEE Std 952 C.1), while a smooth drift (a warming, a slow temperature cycle)
puts its power into the lowest few.  The Allan curve reads a random walk at its longest
taus, the lowest frequencies of the record, where the two look the same.

The test compares the random walk's level in the smooth part of the differences with
its level in the rest.  The smooth part is the span of the first m cosines of the
differences (a DCT-II basis; the first, a constant, is a rate ramp of the means), m
each of :data:`imu_allan.core.rules.DRIFT_SMOOTH` (a warming, a cycle); the rest is
what a restricted likelihood (REML) leaves once they are projected out, so that the
Gaussian log-likelihood splits exactly into l(K) = l_smooth(K) + l_rest(K), in the axis'
own noise model (the generalised covariances of its terms, as the ramp and thermal
tests use; the random walk's share K^2 free).  The statistic is the likelihood ratio
of two levels against one,

    2 (max l_smooth + max l_rest - max l),

signed + where the smooth part's level is the higher.  Its null distribution is drawn
by a parametric bootstrap (seeded, in the model's eigenbasis, K at the level the whole
record fits and re-fitted in every draw); the two m are combined by the smaller of
their p-values, itself calibrated on the same draws.  A record whose combined p-value
lies below :data:`imu_allan.core.rules.DRIFT_ALPHA` has more random walk in its
smooth part than its rest allows: a drift.  A record too short (or too noisy) for a
random walk to show outside the smooth part gives a small statistic under both and
names none.  False alarms and power: ``bench/drift_power.py``, docs/thermal.md.
"""

import math
from typing import NamedTuple

import numpy as np

from imu_allan.core.rules import DRIFT_ALPHA, DRIFT_BLOCKS, DRIFT_SIMS, DRIFT_SMOOTH
from imu_allan.core.search.thermal import _BlockModel

#: Grid of the scaled K^2 (the data scaled to unit variance): e^-14 to e^6, step 0.25.
_LOG_K2 = np.arange(-14.0, 6.0 + 1e-9, 0.25)


class DriftCheck(NamedTuple):
    """
    Result of :func:`drift_test`.

    Attributes
    ----------
    statistic : tuple of float
        The signed likelihood ratio per m of DRIFT_SMOOTH [-].
    p_value : float
        The combined p-value (the smaller of the two, calibrated on the same draws).
    k_full : float
        Random-walk level the whole record fits (ML) [unit/s^0.5].
    k_rest : float
        The level of the rest, outside the smooth part of the larger m [unit/s^0.5].
    named : bool
        p_value < :data:`imu_allan.core.rules.DRIFT_ALPHA`: a drift, not a random walk.

    """

    statistic: tuple
    p_value: float
    k_full: float
    k_rest: float
    named: bool


def smooth_basis(n: int, n_smooth: int) -> np.ndarray:
    """
    Return the first DCT-II cosines of length n, shape (n, n_smooth), columns unit norm.

    cos(pi k (i + 1/2) / n), k = 0 .. n_smooth - 1: the smoothest functions of the
    differences (k = 0, a constant, is a rate ramp of the means).
    """
    i = np.arange(n) + 0.5
    x = np.cos(np.pi * np.outer(i, np.arange(n_smooth)) / n)
    return x / np.linalg.norm(x, axis=0)


def _profile(z: np.ndarray, lam: np.ndarray, xr: np.ndarray | None) -> np.ndarray:
    """
    Return the (restricted) log-likelihood at K = 0 and every grid K^2, (grid + 1, cols).

    ``z`` (n, cols) in the eigenbasis, variances lam + K^2; ``xr`` (n, m) the rotated
    regressors projected out (None: none).
    """
    out = np.empty((_LOG_K2.size + 1, z.shape[1]))
    zz = z * z
    for g, v in enumerate(np.r_[-np.inf, _LOG_K2]):
        w = 1.0 / (lam + math.exp(v))
        ll = -0.5 * (w @ zz - float(np.sum(np.log(w))))
        if xr is not None:
            xw = xr * w[:, None]
            a = xw.T @ xr
            b = xw.T @ z
            sol = np.linalg.solve(a, b)
            ll += 0.5 * (np.einsum('ms,ms->s', b, sol) - float(np.linalg.slogdet(a)[1]))
        out[g] = ll
    return out


def _statistic(full: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """
    Return the signed ratio 2 (max l_smooth + max l_rest - max l) per column.

    l_smooth = l - l_rest (REML splits the likelihood exactly); + where the smooth
    part's best level is above the rest's.
    """
    smooth = full - rest
    gap = 2.0 * (rest.max(axis=0) + smooth.max(axis=0) - full.max(axis=0))
    return np.where(np.argmax(smooth, axis=0) > np.argmax(rest, axis=0), gap, -gap)


def _upper_p(null: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Return the share of ``null`` at least each of ``x`` (x's p-values)."""
    srt = np.sort(null)
    return (srt.size - np.searchsorted(srt, x - 1e-9, 'left')) / srt.size


def drift_test(y, rate_hz: float, terms: list, n_blocks: int = DRIFT_BLOCKS,
               smooth: tuple = DRIFT_SMOOTH, sims: int = DRIFT_SIMS,
               seed: int = 0) -> DriftCheck | None:
    """
    Test whether an axis' random walk is a smooth drift (module docstring).

    Parameters
    ----------
    y : array_like
        Shape (n,), the axis' samples (raw or block-averaged) [unit].
    rate_hz : float
        Their rate [Hz].
    terms : list of (str, float, tuple)
        The axis' noise terms (:func:`imu_allan.core.search.thermal.model_terms`); the
        random walk's level is re-fitted.
    n_blocks : int
        Blocks the record is cut into.
    smooth : tuple of int
        Cosines of the differences taken as the smooth part, one test per entry.
    sims : int
        Bootstrap draws of the null distribution.
    seed : int
        Their seed (the test is deterministic).

    Returns
    -------
    DriftCheck or None
        None when the record is too short (fewer than 8 blocks per smooth cosine), or
        its block means are not finite or all equal.

    """
    y = np.asarray(y, dtype=np.float64)
    n_blocks = min(int(n_blocks), y.size // 2)
    if n_blocks < 8 * max(smooth):
        return None
    per = y.size // n_blocks
    means = y[:per * n_blocks].reshape(n_blocks, per).mean(axis=1)
    if not np.all(np.isfinite(means)) or np.ptp(means) == 0:
        return None
    model = _BlockModel(np.diff(means), terms, per / float(rate_hz))
    lam, z = model.lam, model.z[:, None]
    full = _profile(z, lam, None)[:, 0]
    g_full = int(np.argmax(full))
    k2_full = 0.0 if g_full == 0 else math.exp(_LOG_K2[g_full - 1])
    rng = np.random.default_rng(seed)
    zs = np.concatenate((z, rng.standard_normal((lam.size, int(sims)))
                         * np.sqrt(lam + k2_full)[:, None]), axis=1)
    prof = _profile(zs, lam, None)
    stats, p_each, g_rest = [], [], 0
    for m in smooth:
        rest = _profile(zs, lam, model.rotate(smooth_basis(lam.size, m)))
        stat = _statistic(prof, rest)
        stats.append(float(stat[0]))
        p_each.append(_upper_p(stat[1:], stat))
        g_rest = int(np.argmax(rest[:, 0]))
    # The smaller p-value of the two, itself calibrated on the same draws.
    min_p = np.min(p_each, axis=0)
    p = float(np.mean(min_p[1:] <= min_p[0] + 1e-12))

    def si(g: int) -> float:
        """Return the grid index's K in SI [unit/s^0.5]."""
        return 0.0 if g == 0 else math.sqrt(math.exp(_LOG_K2[g - 1]) / model.rw_scale)
    return DriftCheck(tuple(stats), p, si(g_full), si(g_rest), bool(p < DRIFT_ALPHA))
