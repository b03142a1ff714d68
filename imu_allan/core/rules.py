"""
Every threshold the fit and the effect search decide by, each with its reason, once.

The fit (:mod:`imu_allan.core.fit`) and the search (:mod:`imu_allan.core.search`) read
these and define none of their own; numerical tolerances of the solvers (step sizes,
iteration limits) are not decisions and stay with their solvers.
"""

# ---------------------------------------------------------------- is the model enough

#: A model whose GLS chi-square p-value is at least this explains its curve: the search
#: adds nothing, the fit is consistent, and its profile intervals are plain
#: likelihood-ratio intervals.  Below it the model is rejected.
P_CONSISTENT = 1e-3
#: ... or one inside the curve's 95 % band (or within 5 %) at this share of the taus
#: (a long curve's chi-square rejects a good model on tiny covariance errors).
FOLLOW_SHARE = 0.85

# ------------------------------------------------------------ what a term must buy

#: Penalty per parameter for keeping a term of the base model (AIC): a term the paper's
#: model holds stays when it lowers the chi-square by more than 2 per parameter.
KEEP_PENALTY = 2.0
#: Drop of the criterion, beyond BIC's ln(k) per parameter, that an effect must buy to
#: be named (bench/search_power.py: no false effect on 78 clean axes); models within it
#: of the chosen one on the same criterion are rivals that fit about as well.
DELTA_MIN = 10.0
#: A nonlinear parameter within this factor of an end of its search range is not
#: identified by the taus: the fit reshaping the curve, not a measurement.
PIN_MARGIN = 1.02
#: The shortest taus must fall at least this steeply (ADEV slope) for quantization to
#: be a candidate (quantization alone falls as -1).
QUANTIZATION_SLOPE = -0.75
#: A filter time constant below this share of the shortest fitted tau is not identified.
FILTER_MIN_TAU_SHARE = 0.2

# --------------------------------------------------------------------- the search

#: Most effects the search adds per axis.
MAX_STEPS = 4
#: Rival effects re-fitted (IRLS) and compared by their full likelihood at each step.
N_RIVALS = 3
#: A rival structure (the runner-up effect of a step in its place) within this many
#: units of -2 ln L + BIC of the chosen model fits about equally well: the margin an
#: effect must buy (:data:`DELTA_MIN`).
RIVAL_DELTA = DELTA_MIN
#: Grid points over the range of T_B (log-spaced) when its profile is searched for rival
#: minima.
GRID_POINTS = 8
#: A likelihood ratio (or chi-square drop) at least this large, yet short of what naming
#: an effect needs, is "cannot tell from this record" rather than "not supported".
CANNOT_TELL_LR = 4.0

# -------------------------------------------------------------- time-domain evidence

#: A sinusoid's amplitude from the curve and from the periodogram agree within this.
AMPLITUDE_FACTOR = 3.0
#: False-alarm probability of a periodogram line over the band searched.
LINE_FALSE_ALARM = 1e-3
#: Blocks the record is cut into for the ramp test (the covariance is blocks^2).
RAMP_BLOCKS = 256
#: Likelihood-ratio statistic a ramp must exceed: chi2(1) at about 1e-5, since the
#: search asks this of every axis (few false ramps over a fleet of axes).
RAMP_LR_MIN = 19.5
#: A plan's time longer than this many times the record it came from is a lower limit:
#: the fitted model has only seen taus up to a fraction of the record, and a term that
#: surfaces at longer taus (B flattening, K rising) adds width, so the true time is longer
#: (the ADIS16405's 2-min plan said K in 22 min, its 2.78 h record 17 h).
LOWER_LIMIT_RATIO = 3.0
