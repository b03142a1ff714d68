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
  :data:`imu_allan.core.noise.model.TERMS`; linear in the coefficients c_j (S_N = N^2, S_B,
  S_K = K^2, ...) for fixed nonlinear parameters phi (T_B, sinusoid frequency), as in
  the paper's section 3.2 (Maia, Silva, De Lima, Meneses).  The c_j are solved by
  non-negative least squares, phi by a grid and then a bounded 1-D search or a
  projected Levenberg-Marquardt on the variable-projection residual (Golub & Pereyra
  1973, Kaufman's Jacobian).  Interchangeable terms are ordered (the first
  Gauss-Markov label has the shortest T).
* Weights: the full covariance matrix Sigma of the Allan estimates at all fitted tau,
  computed exactly (for Gaussian terms) from the model: the overlapping estimator is a
  quadratic form in the phase, so Cov(avar_p, avar_q) = 2 sum_{k,l} gamma_pq(l-k)^2 /
  (4 tau_p^2 tau_q^2 n_p n_q), with gamma the covariance between second differences at
  cluster sizes m_p and m_q, built from each term's generalised covariance
  (:class:`imu_allan.core.noise.model.Term`).  The lag sum is exact near the kinks and
  Gauss-Legendre far from them; test_fit.py checks Sigma against Monte Carlo.  It
  carries the chi-square spread of each point (its EDF, for the noise mix at that tau)
  and the correlation of neighbouring tau (about 0.5 at octave spacing).  A sinusoid
  adds the spread of its beat with the noise.  Sigma is iterated (re-weighted GLS):
  first the paper's weights 2 avar^2 / edf, then the *expected* Sigma (Sigma(theta)
  averaged over the GLS uncertainty of the coefficients, which keeps a record's own
  low long-tau points from raising their own weight) to convergence, and a last step
  at the plug-in Sigma(theta) of that solution (:meth:`Fitter.irls`).
* Term selection: every subset of the candidate terms is fitted with the weights of the
  full model; the subset minimising J + 2 p (AIC; J the GLS chi-square, p the number
  of parameters; the one selection rule and its penalties:
  :mod:`imu_allan.core.fit.criterion`) is what the data support (``AxisFit.terms``).
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

import importlib
from typing import TYPE_CHECKING

from imu_allan.core.fit.result import AxisFit, json_floats, json_num, KINDS, Param

if TYPE_CHECKING:
    from imu_allan.core.fit.axis import DEFAULT_TERMS, fit_axis, fit_curve, Z95
    from imu_allan.core.fit.nominal import nominal_fit
    from imu_allan.core.fit.params import CORE_PARAMS, Z95_ONE_SIDED

#: The fitting machinery (scipy.optimize) is imported on first use: a process that only
#: reports fits made elsewhere (``imu-allan analyze``'s main process) never loads it.
_LAZY = {'DEFAULT_TERMS': 'axis', 'fit_axis': 'axis', 'fit_curve': 'axis', 'Z95': 'axis',
         'nominal_fit': 'nominal', 'CORE_PARAMS': 'params', 'Z95_ONE_SIDED': 'params'}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f'{__name__}.{_LAZY[name]}'), name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')


__all__ = ['AxisFit', 'CORE_PARAMS', 'DEFAULT_TERMS', 'fit_axis', 'fit_curve',
           'json_floats', 'json_num', 'KINDS', 'nominal_fit', 'Param', 'Z95', 'Z95_ONE_SIDED']
