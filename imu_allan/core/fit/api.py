"""
The fit's public building blocks, for the effect search (:mod:`imu_allan.core.search`).

The search grows a model term by term on one curve: it validates and thins the curve
as the fit does, builds one slot per term label, scores candidates at fixed weights
and re-weights (IRLS) with the same :class:`Fitter`.  These names are the fit's
interface for that; their bodies live in :mod:`.axis` and :mod:`.solver`.
"""

from imu_allan.core.fit.axis import (_check_inputs, _filtered_start, _n_params,
                                     _profile_threshold, _slot, _thin, filter_identified)
from imu_allan.core.fit.covariance import _CurveCovariance
from imu_allan.core.fit.solver import _fit_fixed_w, _Fitter, _Fix, _Slot, _Solution

#: ``check_curve(tau, avar, edf, rate_hz, n_samples) -> (tau, avar, edf)``: the usable
#: points of a curve, sorted by tau (InputError for bad arrays, rate or length).
check_curve = _check_inputs
#: ``filtered_start(tau_s, avar, rate_hz) -> int``: the first tau the sensor's low-pass
#: filter does not bend (the one rule for the filter's taus on every axis).
filtered_start = _filtered_start
#: ``thin(tau_s, per_octave=2.0) -> indices``: at most that many points per octave.
thin = _thin
#: ``term_slot(label, tau_s, rate_hz) -> Slot``: a term label with its registry entry
#: and the search range of its nonlinear parameters over these taus.
term_slot = _slot
#: ``n_params(slots) -> int``: parameters of a model (one level plus the nonlinear ones
#: per slot).
n_params = _n_params
#: ``fit_fixed_weights(data, slots, phi0=None, fix=None, local=False, grid_slots=None)
#: -> Solution``: one model at the fitter's current weights (NNLS inside a search over
#: the nonlinear parameters).
fit_fixed_weights = _fit_fixed_w
#: ``Fitter(tau, avar, edf, m, n_terms, dt, n_samples, method)``: one curve with its
#: covariance model; ``.irls(slots, ...)`` re-weights, ``.data`` holds the weights.
Fitter = _Fitter
#: One term label of a model (label, registry term, bounds of its nonlinear parameters).
Slot = _Slot
#: A fit at fixed weights: coefficients (scaled), nonlinear parameters, chi-square J.
Solution = _Solution
#: Nonlinear parameters held fixed in a fit at fixed weights.
Fix = _Fix
#: ``profile_threshold(...)``: the chi-square rise that bounds a profile interval.
profile_threshold = _profile_threshold
#: ``CurveCovariance(m, n_terms, dt, n_samples)``: the exact covariance of the Allan
#: estimates of one curve geometry under a model (the planner scales it to longer records).
CurveCovariance = _CurveCovariance

__all__ = ['check_curve', 'CurveCovariance', 'filter_identified', 'filtered_start', 'Fix',
           'fit_fixed_weights', 'Fitter', 'n_params', 'profile_threshold', 'Slot', 'Solution',
           'term_slot', 'thin']
