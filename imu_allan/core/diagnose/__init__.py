"""
Diagnosis: where the fitted model and the measurement disagree, and what is missing.

The seed paper (Maia, Silva, De Lima, Meneses; its figures 2-5 and table 3) validates
a noise model by simulating its discrete state-space form (eqs. 14-23) and comparing
the simulated Allan deviation with the measured one.  This module closes that loop
for one axis at a time:

1. fit the base model (default: white noise, the paper's Gauss-Markov bias
   instability, random walk) with :func:`imu_allan.core.fit.fit_axis`;
2. simulate the fitted model (``n_replicas`` replicas, each term by its registry
   entry's generator: the Gauss-Markov and random-walk states by the exact
   discretisation of the paper's state-space form, eqs. 18-23) and take the
   replica-mean Allan variance as the model's curve;
3. measure the **gap** (defined once, used everywhere)::

       z(tau) = (ln ADEV_meas(tau) - ln ADEV_model(tau)) / s(tau),
       gap = sqrt(mean over tau of z^2),

   where s(tau) = sqrt(psi_1(edf / 2)) / 2 is the standard deviation of ln ADEV of
   an estimate with ``edf`` equivalent degrees of freedom (AVAR ~ avar chi2_edf / edf,
   and Var ln(chi2_nu) = psi_1(nu / 2), the trigamma function; Johnson, Kotz &
   Balakrishnan, Continuous Univariate Distributions vol. 1, ch. 18).  About 1 means
   consistent; the replica mean adds its own spread, a factor sqrt(1 + 1/n_replicas)
   on a consistent gap.  The taus are those of the base fit (at most two per octave,
   leading taus bent by the sensor's low-pass filter left out, as in the fit);
4. find the tau bands where |z| > 2 (beyond 95 % confidence) and their shape
   ('level', 'slope', 'bump', 'oscillation');
5. try every effect not yet in the model (:data:`EFFECTS`), refit with it, and keep
   the one that lowers the penalised criterion most: the GLS chi-square of the fit
   plus ``ln(k)`` per parameter (BIC, k the number of fitted taus) plus a margin
   :data:`DELTA_MIN` that keeps clean data free of invented effects (calibrated with
   bench/diagnose_cases.py).  A sinusoid must also show as a peak in a periodogram of
   the raw samples near the fitted frequency (when raw samples are given);
6. re-simulate, report the gap before and after the step, and repeat until the model
   is consistent (gap <= :data:`GAP_OK` and the fit's chi-square acceptable) or
   nothing more is supported.

Effect names are the names of the terms they add (docs/contracts.md): quantization
(Q), white (N), flicker (B; called bias_instability before, still accepted), gauss_markov
(a further first-order Gauss-Markov process, B and T), random_walk (K), rate_ramp (R),
sinusoid (A, f0_hz).  The base model is given by term names (default white,
bias_instability, random_walk; the old base name gauss_markov is still accepted for
bias_instability).  B follows the paper's convention (eq. 8, see noise.values).

Modules: :mod:`.gap` (the gap and its bands), :mod:`.replicas` (the model's simulated
curve), :mod:`.engine` (the steps above), :mod:`.result` (what is reported).
"""

from imu_allan.core.allan.raw import RawKeeper
from imu_allan.core.diagnose.engine import (base_terms, DEFAULT_BASE, diagnose_axis,
                                            diagnose_curve, diagnose_session, EFFECTS)
from imu_allan.core.diagnose.gap import (Band, find_bands, gap, GAP_OK, gap_z, ln_adev_stderr,
                                         P_INCONSISTENT, Z_BAND)
from imu_allan.core.diagnose.replicas import N_REPLICAS, simulate_fit_avar
from imu_allan.core.diagnose.result import AxisDiagnosis, DiagnoseResult, Finding, summary_line
from imu_allan.core.noise.generators import filtered_white_noise

__all__ = ['AxisDiagnosis', 'Band', 'base_terms', 'DEFAULT_BASE', 'diagnose_axis',
           'diagnose_curve', 'diagnose_session', 'DiagnoseResult', 'EFFECTS',
           'filtered_white_noise',
           'find_bands', 'Finding', 'gap', 'GAP_OK', 'gap_z', 'ln_adev_stderr', 'N_REPLICAS',
           'P_INCONSISTENT', 'RawKeeper', 'simulate_fit_avar', 'summary_line', 'Z_BAND']
