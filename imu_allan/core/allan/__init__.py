"""
Batch Allan curves: overlapping, non-overlapping (octave) and Hadamard variance.

All estimators take rate samples ``y`` (gyro rad/s, accel m/s^2, or fractional
frequency) at a constant sample period ``tau0 = 1 / rate_hz``.  Formulas follow
NIST SP 1065 (Riley, Handbook of Frequency Stability Analysis, 2008):

- overlapping Allan variance, NIST SP 1065 eq. 14 (phase form);
- non-overlapping Allan variance of the octave procedure of the Japanese text
  (m = 1, 2, 4, ... N/2, plain non-overlapping clusters), NIST SP 1065 eq. 12;
- overlapping Hadamard variance, NIST SP 1065 eq. 20 (insensitive to linear drift).

Confidence intervals use equivalent degrees of freedom (EDF) from Greenhall's
algorithm (C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based
on finite differences", PTTI 2003) with chi-square bounds (NIST SP 1065 eq. 45).  The
power-law noise type per tau is identified like Stable32 does: the lag-1
autocorrelation method (W. J. Riley and C. A. Greenhall, "Power law noise
identification using the lag 1 autocorrelation", EFTF 2004) when at least 30 cluster
averages exist, else the B1 ratio (Barnes) with the R(n) ratio to split white and
flicker phase noise, else the local log-log slope of the curve.

Alpha is the exponent of the frequency PSD, S_y(f) ~ f^alpha: 2 white PM (quantisation),
1 flicker PM, 0 white FM (angle/velocity random walk), -1 flicker FM (bias
instability), -2 random-walk FM (rate random walk); the Hadamard variance also
converges for -3 and -4.

Modules: :mod:`.taus` (cluster sizes), :mod:`.kernels` (the variance sums),
:mod:`.edf` (degrees of freedom, bounds), :mod:`.noise_id` (alpha per tau),
:mod:`.curve` (:func:`allan_curve`), :mod:`.sums` (the difference sums).
"""

from imu_allan.core.allan.curve import allan_curve, AllanCurve
from imu_allan.core.allan.edf import (confidence_bounds, edf_for_method, edf_greenhall,
                                      edf_hadamard, edf_nonoverlapping, edf_overlapping)
from imu_allan.core.allan.kernels import (hadamard_var, identify_alpha, nonoverlapping_avar,
                                          overlapping_avar)
from imu_allan.core.allan.noise_id import alpha_from_slope, MIN_ACF_POINTS, MIN_B1_POINTS
from imu_allan.core.allan.taus import (cluster_sizes, DENSE_PER_DECADE, max_cluster_size,
                                       METHODS, tau_grid, TAU_KINDS, terms_count)

__all__ = ['alpha_from_slope', 'allan_curve', 'AllanCurve', 'cluster_sizes',
           'confidence_bounds', 'DENSE_PER_DECADE', 'edf_for_method', 'edf_greenhall',
           'edf_hadamard', 'edf_nonoverlapping', 'edf_overlapping', 'hadamard_var',
           'identify_alpha', 'max_cluster_size', 'METHODS', 'MIN_ACF_POINTS', 'MIN_B1_POINTS',
           'nonoverlapping_avar', 'overlapping_avar', 'TAU_KINDS', 'tau_grid', 'terms_count']
