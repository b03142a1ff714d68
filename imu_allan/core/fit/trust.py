"""
No confident wrong number: judge a fitted axis and fall back to the curve where needed.

A fit is not trusted when the final model does not follow its curve
(:func:`imu_allan.core.fit.judge.follows_curve`), when a nonlinear parameter sits at an
end of its search range (``AxisFit.pinned``), or when its N differs from the curve's
white region (:func:`imu_allan.core.fit.judge.white_region`) beyond both intervals.
Then every output uses conservative values read off the measured curve instead of the
distorted fit's:

- N: the white region's level, its 95 % range widened to take in the fit's (an
  estimate: the record cannot tell which is right where they disagree); without a white
  region, the curve's own bound min sqrt(AVAR tau) as an upper bound;
- B: the ADEV floor's 95 % upper limit over 0.664 (IEEE Std 952-1997 annex C) as an
  upper bound (the floor holds every term's share), each AVAR at its joint upper
  limit (:func:`imu_allan.core.allan.edf.avar_upper`: the measured floor is its
  lowest-lying point);
- K: the curve's own bound min sqrt(3 AVAR / tau) (IEEE Std 952 C.1 slope +1/2) as
  an upper bound, each AVAR at its upper chi-square limit
  (:func:`imu_allan.core.allan.edf.curve_k_bound`);
- every other parameter (T_B, T_f, further processes): not identified.
"""

from dataclasses import replace
import math

import numpy as np

from imu_allan.core.allan.edf import curve_k_bound, curve_n_bound, floor_b_bound
from imu_allan.core.allan.quantiles import chi2_ppf
from imu_allan.core.fit.axis import filter_cut
from imu_allan.core.fit.judge import follows_curve, white_region, white_share
from imu_allan.core.fit.result import AxisFit, Param
from imu_allan.core.noise.values import AxisNoise


def trust_problems(fit: AxisFit, consistent: bool) -> list:
    """
    Return why a fit's numbers are not to be trusted ([] when they are).

    Parameters
    ----------
    fit : AxisFit
        The final fit of the axis.
    consistent : bool
        Whether the model follows its curve (:func:`follows_curve`).

    Returns
    -------
    list of str
        One phrase per problem.

    """
    problems = []
    if not consistent:
        problems.append(f'the model does not follow its curve (chi2 {fit.chi2:.1f} for '
                        f'{fit.dof} dof)')
    if fit.pinned:
        problems.append(f'{", ".join(fit.pinned)} at the end of its search range')
    got = _white(fit)
    n_fit = fit.optimised.get('N')
    if got is not None and n_fit is not None and n_fit.kind == 'estimate':
        value, (lo, hi) = got
        if n_fit.ci95[1] < lo or n_fit.ci95[0] > hi:
            problems.append(f'N {n_fit.value:.3g} differs from the white region of the curve '
                            f'({value:.3g}, 95 % {lo:.3g}-{hi:.3g}) beyond its interval')
    return problems


def _unfiltered(fit: AxisFit) -> int:
    """
    Index of the first fitted tau past the sensor's filter (the one rule of fit_axis).

    Where the fit saw the filter's bend end, there; else the rule runs again on the
    fitted taus (a bend that may reach past them: filter and floor not told apart).
    """
    if math.isfinite(fit.filter_end_s):
        return int(np.searchsorted(fit.tau_s, fit.filter_end_s * (1.0 - 1e-9)))
    if fit.tau_s.size < 4:
        return 0
    return filter_cut(fit.tau_s, fit.avar_meas, 1.0 / fit.tau_s[0], fit.edf).first


def _white(fit: AxisFit, trusted_model: bool = True):
    """
    Return N and its range from the white region past the filter (None without one).

    The region is where the model's white share is >= 0.8, else the first run of at
    least two consecutive steps (an octave at the fit's spacing) where the measured
    ADEV falls with a slope of -1/2 +- 0.1: white noise carries the short end of a
    curve (before its first rise), and a single white-like step further out is as
    likely a bump turning over.  With ``trusted_model`` False (the conservative value
    of a fit already judged untrusted) the model's shares are the distorted fit's: they
    count only in the curve's first descent, past the filter-bent taus.
    """
    share = white_share(fit)
    if share is None or fit.tau_s.size < 2:
        return None
    # With the filter in the model its share already says where white noise carries
    # the curve; with plain white noise the filter-bent leading taus are no region.
    i = 0 if trusted_model and 'filtered_white' in fit.terms else _unfiltered(fit)
    tau, avar, edf = fit.tau_s[i:], fit.avar_meas[i:], fit.edf[i:]
    got = None
    if tau.size >= 2:
        slope = 0.5 * np.diff(np.log(avar)) / np.diff(np.log(tau))
        # White noise carries the curve's first descent: past its first rise a -1/2
        # step is a bump turning over, and an untrusted model's shares there are the
        # distorted fit's.
        rise = np.flatnonzero(slope >= 0.0)
        descent = np.arange(tau.size) <= (rise[0] if rise.size else tau.size)
        got = white_region(tau, avar, edf, share[i:] * (descent | trusted_model))
        if got is None and tau.size >= 3:
            steps = (np.abs(slope + 0.5) <= 0.1) & descent[:-1]
            pairs = np.flatnonzero(steps[:-1] & steps[1:])
            if pairs.size:
                first = int(pairs[0])
                last = first + 1
                while last + 1 < steps.size and steps[last + 1]:
                    last += 1
                white = np.zeros(tau.size)
                white[first:last + 2] = 1.0
                got = white_region(tau, avar, edf, white)
    return got


def b_floor(fit: AxisFit) -> Param | None:
    """
    B read off the ADEV floor: ADEV_min / 0.664 (IEEE Std 952-1997 annex C), 95 %.

    The minimum is taken over the fitted taus past the sensor's filter (a low-pass
    lowers the shortest taus below any floor); the interval is that point's chi-square
    interval (NIST SP 1065 sec. 5.3).  None without a fitted curve.
    """
    if not fit.tau_s.size or 'B' not in fit.optimised:
        return None
    i = _unfiltered(fit)
    adev = np.sqrt(fit.avar_meas[i:])
    j = int(np.argmin(adev))
    e = max(float(fit.edf[i + j]), 1.0)
    lo = adev[j] * math.sqrt(e / float(chi2_ppf(0.975, e))) / 0.664
    hi = adev[j] * math.sqrt(e / float(chi2_ppf(0.025, e))) / 0.664
    return Param(float(adev[j] / 0.664), (float(lo), float(hi)), 'estimate',
                 fit.optimised['B'].unit)


def _floor_bound(fit: AxisFit) -> float:
    """
    95 % upper bound of B from the floor: min sqrt(AVAR_hi) / 0.664 past the filter.

    The floor of the *measured* curve (:func:`b_floor`) is its lowest-lying point, on a
    long record often a last tau with an EDF of one or two; the bound takes every point
    at its joint upper limit (:func:`imu_allan.core.allan.edf.avar_upper`).  NaN without a
    fitted curve.
    """
    if not fit.tau_s.size:
        return math.nan
    i = _unfiltered(fit)
    return floor_b_bound(fit.avar_meas[i:], fit.edf[i:])


def conservative(fit: AxisFit, problems: list) -> AxisFit:
    """
    Return the fit with conservative values in ``optimised`` (see the module doc).

    The fitted values that were replaced move to ``fit_values``; ``model`` becomes
    N, B (flicker at the floor) and K, so the noise-model file is conservative too.
    """
    if not problems:
        return fit
    opt = dict(fit.optimised)
    unit_n, unit_b, unit_k = (opt[s].unit for s in ('N', 'B', 'K'))
    tau, avar = fit.tau_s, fit.avar_meas
    got = _white(fit, trusted_model=False)
    why = 'fit not trusted: ' + '; '.join(problems)
    n_fit = opt['N']
    if got is not None:
        # The value is the white region's; its range reaches to the fit's as well: where
        # the two disagree (a plateau of sinusoids read as the region, a fit distorted by
        # the record's end) which is right the record cannot tell.
        lo, hi = got[1]
        if n_fit.kind == 'estimate':
            lo, hi = min(lo, n_fit.ci95[0]), max(hi, n_fit.ci95[1])
        n_new = Param(got[0], (lo, hi), 'estimate', unit_n, 'curve',
                      f'{why}: the white region of the curve')
    else:
        # No white region: the descending part of the curve past the filter bounds N
        # from above (every other term only adds to AVAR tau there).
        i = _unfiltered(fit)
        j = i + int(np.argmin(avar[i:]))
        bound = float(np.sqrt(np.max(avar[i:j + 1] * tau[i:j + 1])))
        # No tighter than white noise alone allows at each tau past the filter, each
        # point at its joint upper limit: the largest of the descent alone ran up to 8x
        # above the curve where a bias instability lifts its end (AVAR tau grows).
        bound = min(bound, curve_n_bound(tau[i:], avar[i:], fit.edf[i:]))
        n_new = Param(bound, (0.0, bound), 'upper_bound', unit_n, 'curve',
                      f"{why}: the curve's own bound")
    # Within what the whole curve allows (AxisFit.caps), so the model file agrees.
    b_value = min(_floor_bound(fit), fit.caps.B)
    b_new = Param(b_value, (0.0, b_value), 'upper_bound', unit_b, 'curve',
                  f'{why}: the ADEV floor')
    k_bound = min(curve_k_bound(tau, avar, fit.edf), fit.caps.K)
    k_new = Param(k_bound, (0.0, k_bound), 'upper_bound', unit_k, 'curve',
                  f"{why}: the curve's own bound")
    new = {'N': n_new, 'B': b_new, 'K': k_new}
    replaced = {}
    for sym, p in opt.items():
        if sym in new:
            replaced[sym] = p
            opt[sym] = new[sym]
        elif p.kind != 'not_identified':
            replaced[sym] = p
            opt[sym] = Param(math.nan, (math.nan, math.nan), 'not_identified', p.unit,
                             'curve', why)
    model = AxisNoise(N=n_new.value, B=b_value if math.isfinite(b_value) else 0.0,
                      K=k_bound)
    notes = list(fit.notes) + [
        f'not trusted: {"; ".join(problems)}: N from the white region of the curve, '
        "B from the ADEV floor (upper bound), K the curve's own bound, the rest not "
        'identified']
    return replace(fit, optimised=opt, fit_values=replaced, model=model,
                   trust=tuple(problems), notes=tuple(notes))


def judge_fit(fit: AxisFit, problems: tuple = ()) -> AxisFit:
    """
    Judge a final fit: set ``model_consistent`` and fall back where it is not trusted.

    ``problems`` are further reasons found by the caller (the search: a filter that
    bends the curve beyond the taus it may leave out).
    """
    consistent = follows_curve(fit.avar_meas, fit.edf, fit.avar_fit, fit.chi2, fit.dof)
    fit = replace(fit, model_consistent=consistent, b_floor=None)
    fit = replace(fit, b_floor=b_floor(fit))
    return conservative(fit, list(problems) + trust_problems(fit, consistent))
